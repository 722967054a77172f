"""Instructions per simulated case-step: the sweep's lanes against the hand-written C ceiling, counted.

    python benchmarks/instructions.py                 # plain, flying, mission lanes and the ceiling
    python benchmarks/instructions.py --only plain ceiling

Timings on a shared 2-core VM move by a fifth between runs; instruction counts do not. Each part runs
in its own process under Valgrind's callgrind (Debian: ``apt install valgrind``), after a warm run
outside it has compiled the lanes' library, and the instructions of the compiled functions are
summed by what they do, per simulated step of one case:

- **step**: the RK4 step and the law (``qc_run_at`` with the generated step inlined, ``qc_law``,
  ``qc_plant``, the exogenous rows' lookups; the ceiling's ``rhs`` and its RK4 stage sums);
- **sines and cosines**: glibc's vector ``sin`` and ``cos`` (libmvec), called from the step;
- **metrics**: what the lanes sum at every record (``qc_metric``, ``qc_quadratic``, ``qc_ref``;
  :mod:`quadctl.sim.lane_metrics`), which the ceiling does not do.

The lanes are one group of :data:`quadctl.sim.engine.LANES` cases of each sweep (the benchmark's
sweep files, ``jobs=1``); the ceiling is :data:`bench.CEILING_SOURCE` on 64 cases, one thread.
Not a timing: an instruction of a vector divide costs more than one of an add, and a step that runs
fewer instructions can still wait longer on memory. It shows where a case-step's work is, the same on
every run. About five minutes.

``--whole`` counts each whole sweep instead (``sweep.run``, ``jobs=1``: the designs, the loops, the
references, the rows, Python and numpy included), per simulated step: the sweep at two case counts
(:data:`WHOLE_CASES`), each in its own process under callgrind, the difference of their totals over
the difference of their steps, so the imports and the warm run cancel. Its ratios are bench.py's
steps/s ratios at one instruction per instruction: the lanes' part the same on every run, Python's
within a few instructions a step. About 20 minutes.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench  # noqa: E402  (the ceiling's source and the sweep files)

from quadctl.native.compile import MARCH_ENV  # noqa: E402

SWEEPS = {"plain": ("forward", bench.SWEEP_FILE), "flying": ("mambo-200hz", bench.FLYING_SWEEP_FILE),
          "mission": ("square", bench.MISSION_SWEEP_FILE)}
"""The lanes counted: a group of each benchmark sweep (config, sweep file)."""
PARTS = {"step": re.compile(r"^(qc_run_at|qc_law|qc_plant|qc_step|qc_etd|qc_rem|qc_exo_|rhs$|ceiling)"),
         "sin, cos": re.compile(r"^_ZGV\w+_(sin|cos)"),
         "metrics": re.compile(r"^(qc_metric|qc_quadratic|qc_ref)")}
"""Function names (callgrind's, ``.constprop.0`` and such suffixes aside) by the part they count in."""
CEILING_CASES = 64
CEILING_STEPS = 10_000
WHOLE_CASES = {"plain": (64, 192), "flying": (128, 384), "mission": (8, 16)}
"""``--whole``: the two case counts of each sweep (the mission's cases are 434 783 steps each)."""


def _has_avx512() -> bool:
    """Whether this CPU has AVX-512 (Linux's /proc/cpuinfo; False where there is none)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return False
    return any(line.startswith("flags") and " avx512f" in line for line in text.splitlines())


def child(name: str, cases: int | None = None) -> dict:
    """Run one part (in the process callgrind watches); its simulated case-steps. ``cases``: the
    whole sweep of that many cases, after a warm run of one group of lanes (else that group alone)."""
    from quadctl import config, sweep
    from quadctl.sim.engine import LANES

    if name == "ceiling":
        cfg = config.load("forward")
        spec = dataclasses.replace(sweep.load(bench.SWEEP_FILE, cfg), samples=CEILING_CASES)
        run, _, _ = bench.the_ceiling(cfg, spec)  # checks itself against quadctl's RK4 over 2000 steps
        run(CEILING_STEPS)
        return {"case_steps": CEILING_CASES * (2000 + CEILING_STEPS)}
    cfg_name, path = SWEEPS[name]
    cfg = config.load(cfg_name)
    spec = sweep.load(path, cfg)
    if cases is not None:
        sweep.run(cfg, dataclasses.replace(spec, samples=LANES), jobs=1)  # warm: the plants, caches, first calls
    spec = dataclasses.replace(spec, samples=cases or LANES)
    return {"case_steps": int(sweep.run(cfg, spec, jobs=1).stats["steps"])}


def counted(name: str, tmp: Path, cases: int | None = None) -> dict:
    """Per part, and in all (``"all"``), the instructions of ``name`` (:func:`child`'s ``cases``), and
    its simulated case-steps (``"case_steps"``), counted by callgrind."""
    tag = f"{name}-{cases}" if cases else name
    out, steps = tmp / f"{tag}.callgrind", tmp / f"{tag}.json"
    argv = [sys.executable, __file__, "--child", name, str(steps), *([str(cases)] if cases else [])]
    subprocess.run(argv, check=True)  # warm: compiles
    ran = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", *argv], capture_output=True,
                         text=True)
    if ran.returncode != 0:
        lines = [re.sub(r"^==\d+== ?", "", line).strip() for line in ran.stderr.splitlines()]
        said = [line for line in lines if "unhandled instruction" in line or "Illegal" in line] or \
            [line for line in lines if line]
        sys.exit(f"instructions.py: {name} under callgrind exited {ran.returncode}: "
                 f"{said[-1] if said else 'no message'}")
    report = subprocess.run(["callgrind_annotate", "--inclusive=no", "--threshold=100", str(out)],
                            check=True, capture_output=True, text=True).stdout
    totals = dict.fromkeys(PARTS, 0)
    for line in report.splitlines():
        whole = re.match(r"\s*([\d,]+)\s+\([\s\d.]+%\)\s+PROGRAM TOTALS", line)
        if whole:
            totals["all"] = int(whole.group(1).replace(",", ""))
            continue
        match = re.match(r"\s*([\d,]+)\s+\([\s\d.]+%\)\s+\S*:(\S+)", line)
        if not match:
            continue
        function = match.group(2).split(".")[0]
        for part, pattern in PARTS.items():
            if pattern.match(function):
                totals[part] += int(match.group(1).replace(",", ""))
                break
    return {**totals, "case_steps": json.loads(steps.read_text())["case_steps"]}


def per_step(name: str, tmp: Path) -> dict:
    """Per part, instructions per simulated case-step of one group of ``name``'s lanes."""
    got = counted(name, tmp)
    return {part: got[part] / got["case_steps"] for part in PARTS}


def whole_sweep(name: str, tmp: Path) -> dict:
    """Instructions per simulated case-step of the whole sweep ``name`` (``"all"``), and of it the
    compiled lanes (the parts of :data:`PARTS`): differenced between :data:`WHOLE_CASES`' counts."""
    few, many = (counted(name, tmp, cases) for cases in WHOLE_CASES[name])
    steps = many["case_steps"] - few["case_steps"]
    lanes = sum(many[part] - few[part] for part in PARTS)
    return {"all": (many["all"] - few["all"]) / steps, "lanes": lanes / steps}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=[*SWEEPS, "ceiling"], metavar="PART",
                        help=f"count only these: {', '.join([*SWEEPS, 'ceiling'])} (default: all)")
    parser.add_argument("--whole", action="store_true",
                        help="count each whole sweep (designs, loops, rows, Python) per simulated step, and its "
                             "ratio to the plain sweep's (about 20 minutes)")
    parser.add_argument("--child", nargs="+", metavar="PART OUT [CASES]", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        name, out, *cases = args.child
        Path(out).write_text(json.dumps(child(name, int(cases[0]) if cases else None)))
        return
    if shutil.which("valgrind") is None or shutil.which("callgrind_annotate") is None:
        sys.exit("instructions.py needs Valgrind's callgrind (Debian: apt install valgrind)")
    names = args.only or [*SWEEPS, "ceiling"]
    if MARCH_ENV not in os.environ and _has_avx512():  # Valgrind 3.19 runs no AVX-512: the lanes and ceiling for AVX2
        os.environ[MARCH_ENV] = "x86-64-v3"
        print(f"this CPU has AVX-512, which callgrind does not run: the lanes and the ceiling are compiled for "
              f"{MARCH_ENV}=x86-64-v3 (AVX2) here, and counted so\n")
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ["OMP_NUM_THREADS"] = "1"  # the ceiling on one thread: callgrind runs threads one at a time
    if args.whole:
        names = [name for name in names if name in SWEEPS]
        if "plain" not in names:
            names.insert(0, "plain")  # the ratios' reference
        with tempfile.TemporaryDirectory() as tmp:
            counts = {name: whole_sweep(name, Path(tmp)) for name in names}
        plain = counts["plain"]["all"]
        print("Instructions per simulated step of one case, the whole sweep (callgrind, jobs=1; the lanes' counts "
              "are the same on every run, Python's around them move by a few)\n")
        print(bench.table("", ["sweep", "all", "in the lanes", "around them", "against plain"],
                          [[f"{name} ({SWEEPS[name][0]})", f"{c['all']:,.0f}", f"{c['lanes']:,.0f}",
                            f"{c['all'] - c['lanes']:,.0f}", f"{plain / c['all']:.2f}"]
                           for name, c in counts.items()]).lstrip("\n"))
        print("\n'against plain': the plain sweep's instructions a step over the sweep's, its steps/s against the "
              "plain sweep's at one instruction per instruction")
        return
    with tempfile.TemporaryDirectory() as tmp:
        rows = {name: per_step(name, Path(tmp)) for name in names}
    what = {name: f"{name} lanes ({SWEEPS[name][0]})" for name in SWEEPS}
    what["ceiling"] = f"C ceiling ({CEILING_CASES} cases)"
    print("Instructions per simulated step of one case (callgrind; the same on every run)\n")
    print(bench.table("", ["what ran", *PARTS, "total"],
                      [[what[name], *(f"{v:,.0f}" if v else "-" for v in row.values()), f"{sum(row.values()):,.0f}"]
                       for name, row in rows.items()]).lstrip("\n"))


if __name__ == "__main__":
    main()
