"""Where a sweep case's CPU time goes, stage by stage: the plain sweep and the flying one, on one core.

    python benchmarks/case_stages.py            # about 10 s

Each sweep of bench.py (the plain ``forward`` one of ``random-1000.yaml``, and the flying
``mambo-200hz`` one of ``mambo-1000.yaml`` at its 2 s and at the config's own 10 s) runs in this
process on one core (``jobs=1``, one BLAS thread), its stages wrapped in CPU-time counters: the
cases' setups, the batched designs, the cases' loops and plans (``loops_of``), the lanes (the
compiled calls, and the Python that feeds and reads them), the rows read back from the lanes' sums,
and the rest of a chunk. Best of five runs, after a warm-up; microseconds of CPU time per case.

The counters are wrapped around the functions the sweep calls by name (in the modules of
:mod:`quadctl.sweep` that define them, and :class:`quadctl.sim.native.NativeRunner`), so they time
what a sweep runs and nothing else; they add ~1 µs a case.
"""

from __future__ import annotations

import collections
import dataclasses
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # read when BLAS loads: one thread, as a sweep's workers

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench  # noqa: E402  (the sweep files)

STAGES = {
    "setups": "each case's config and Setup, from the sweep's values",
    "design_all": "the batched designs and their checks on the coupled model",
    "loops_of": "each case's closed loop, step plan and constants",
    "lanes (compiled)": "the compiled lane calls",
    "lanes (Python)": "feeding the lanes and reading their sums back per case",
    "_summed_rows": "the rows (metrics, verdicts) from the lanes' sums",
}


def _counted(acc: collections.Counter):
    """Wrap the sweep's stages in CPU-time counters adding into ``acc``; returns the undo."""
    from quadctl.sim import native
    from quadctl.sweep import batched, evaluate, lane_jobs, lane_rows, prepare

    undo = []

    def wrap(owner, name, key, generator=False):
        original = getattr(owner, name)

        def timed(*args, **kwargs):
            start = time.process_time()
            try:
                return original(*args, **kwargs)
            finally:
                acc[key] += time.process_time() - start

        def timed_generator(*args, **kwargs):
            it = original(*args, **kwargs)
            while True:
                start = time.process_time()
                try:
                    item = next(it)
                except StopIteration:
                    acc[key] += time.process_time() - start
                    return
                acc[key] += time.process_time() - start
                yield item

        setattr(owner, name, timed_generator if generator else timed)
        undo.append(lambda: setattr(owner, name, original))

    original_all = prepare.CaseSetups.all

    def setups(self, cases):
        start = time.process_time()
        out = list(original_all(self, cases))
        acc["setups"] += time.process_time() - start
        return out

    prepare.CaseSetups.all = setups
    undo.append(lambda: setattr(prepare.CaseSetups, "all", original_all))
    wrap(batched, "design_all", "design_all")
    wrap(lane_jobs, "loops_of", "loops_of")
    wrap(lane_rows, "_summed_rows", "_summed_rows")
    wrap(batched, "summarize_all", "lanes", generator=True)
    wrap(native.NativeRunner, "_call", "lanes (compiled)")
    wrap(evaluate, "_evaluate_chunk", "chunk")
    return lambda: [u() for u in reversed(undo)]


def stages(cfg, spec, runs: int = 5) -> tuple[float, dict[str, float], int]:
    """(CPU µs a case in all, {stage: µs a case}, steps a case) of ``spec``'s sweep on one core, best of
    ``runs``."""
    from quadctl import sweep

    sweep.run(cfg, dataclasses.replace(spec, samples=16), jobs=1)  # warm: imports, lane library
    acc: collections.Counter = collections.Counter()
    undo = _counted(acc)
    try:
        best = None
        for _ in range(runs):
            acc.clear()
            start = time.process_time()
            result = sweep.run(cfg, spec, jobs=1)
            total = time.process_time() - start
            if best is None or total < best[0]:
                best = (total, dict(acc), max(r["steps"] for r in result.rows))
    finally:
        undo()
    total, got, steps = best
    n = spec.samples
    per = {key: 1e6 * value / n for key, value in got.items()}
    per["lanes (Python)"] = per.pop("lanes") - per["lanes (compiled)"]
    chunk = per.pop("chunk")
    per["the rest of a chunk"] = chunk - sum(per[k] for k in STAGES)
    per["outside the chunks"] = 1e6 * total / n - chunk
    return 1e6 * total / n, per, steps


def main() -> None:
    from quadctl import config, sweep

    plain_cfg = config.load("forward")
    flying_cfg = config.load("mambo-200hz")
    short = sweep.load(bench.FLYING_SWEEP_FILE, flying_cfg)
    whole = dataclasses.replace(short, fixed=tuple(f for f in short.fixed if f[0] != "simulation.duration"))
    runs = [("plain (forward)", plain_cfg, sweep.load(bench.SWEEP_FILE, plain_cfg)),
            ("flying (mambo-200hz), 2 s", flying_cfg, short), ("flying (mambo-200hz), 10 s", flying_cfg, whole)]
    found = [(name, *stages(cfg, spec)) for name, cfg, spec in runs]
    names = [*STAGES, "the rest of a chunk", "outside the chunks"]
    head = ["stage (µs of CPU a case, one core)", *(name for name, *_ in found)]
    rows = [["steps a case", *(f"{steps:,}" for *_, steps in found)],
            *([name, *(f"{per[name]:.1f}" for _, _, per, _ in found)] for name in names),
            ["all", *(f"{total:.1f}" for _, total, _, _ in found)],
            ["around the lanes", *(f"{total - per['lanes (compiled)']:.1f}" for _, total, per, _ in found)],
            ["ns a step", *(f"{1e3 * total / steps:.1f}" for _, total, _, steps in found)]]
    print(bench.table("Where a sweep case's CPU time goes (jobs=1, one BLAS thread, best of 5 runs)", head, rows))
    print("\n" + "\n".join(f"- {name}: {what}" for name, what in STAGES.items()))


if __name__ == "__main__":
    main()
