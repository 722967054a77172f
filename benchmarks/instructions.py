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

SWEEPS = {"plain": ("forward", bench.SWEEP_FILE), "flying": ("mambo-200hz", bench.FLYING_SWEEP_FILE),
          "mission": ("square", bench.MISSION_SWEEP_FILE)}
"""The lanes counted: a group of each benchmark sweep (config, sweep file)."""
PARTS = {"step": re.compile(r"^(qc_run_at|qc_law|qc_plant|qc_step|qc_etd|qc_rem|qc_exo_|rhs$|ceiling)"),
         "sin, cos": re.compile(r"^_ZGV\w+_(sin|cos)"),
         "metrics": re.compile(r"^(qc_metric|qc_quadratic|qc_ref)")}
"""Function names (callgrind's, ``.constprop.0`` and such suffixes aside) by the part they count in."""
CEILING_CASES = 64
CEILING_STEPS = 10_000


def child(name: str) -> dict:
    """Run one part (in the process callgrind watches); its simulated case-steps."""
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
    spec = dataclasses.replace(sweep.load(path, cfg), samples=LANES)
    return {"case_steps": int(sweep.run(cfg, spec, jobs=1).stats["steps"])}


def counted(name: str, tmp: Path) -> dict:
    """Per part, instructions per simulated case-step of ``name``, counted by callgrind."""
    out, steps = tmp / f"{name}.callgrind", tmp / f"{name}.json"
    subprocess.run([sys.executable, __file__, "--child", name, str(steps)], check=True)  # warm: compiles
    subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", sys.executable, __file__,
                    "--child", name, str(steps)], check=True, capture_output=True)
    case_steps = json.loads(steps.read_text())["case_steps"]
    report = subprocess.run(["callgrind_annotate", "--inclusive=no", "--threshold=100", str(out)],
                            check=True, capture_output=True, text=True).stdout
    totals = dict.fromkeys(PARTS, 0)
    for line in report.splitlines():
        match = re.match(r"\s*([\d,]+)\s+\([\s\d.]+%\)\s+\S*:(\S+)", line)
        if not match:
            continue
        function = match.group(2).split(".")[0]
        for part, pattern in PARTS.items():
            if pattern.match(function):
                totals[part] += int(match.group(1).replace(",", ""))
                break
    return {part: count / case_steps for part, count in totals.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=[*SWEEPS, "ceiling"], metavar="PART",
                        help=f"count only these: {', '.join([*SWEEPS, 'ceiling'])} (default: all)")
    parser.add_argument("--child", nargs=2, metavar=("PART", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        Path(args.child[1]).write_text(json.dumps(child(args.child[0])))
        return
    if shutil.which("valgrind") is None or shutil.which("callgrind_annotate") is None:
        sys.exit("instructions.py needs Valgrind's callgrind (Debian: apt install valgrind)")
    names = args.only or [*SWEEPS, "ceiling"]
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ["OMP_NUM_THREADS"] = "1"  # the ceiling on one thread: callgrind runs threads one at a time
    with tempfile.TemporaryDirectory() as tmp:
        rows = {name: counted(name, Path(tmp)) for name in names}
    what = {name: f"{name} lanes ({SWEEPS[name][0]})" for name in SWEEPS}
    what["ceiling"] = f"C ceiling ({CEILING_CASES} cases)"
    print("Instructions per simulated step of one case (callgrind; the same on every run)\n")
    print(bench.table("", ["what ran", *PARTS, "total"],
                      [[what[name], *(f"{v:,.0f}" if v else "-" for v in row.values()), f"{sum(row.values()):,.0f}"]
                       for name, row in rows.items()]).lstrip("\n"))


if __name__ == "__main__":
    main()
