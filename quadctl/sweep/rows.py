"""A sweep case's row: its columns from its design and its run, or why it has none; the verdicts of the law
that flies (a PID cascade's stability, the loops' margins); and, in a Monte Carlo, its trajectory kept beside it.

Both paths of a chunk (:mod:`quadctl.sweep.evaluate`, one by one; :mod:`quadctl.sweep.lane_rows`, batched)
build their rows here, so the rows of the two are alike column for column.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from quadctl import pipeline, run_summary
from quadctl.errors import QuadctlError
from quadctl.layout import STATE_INDEX
from quadctl.present.mission import mission_text
from quadctl.present.stages import unstable_cascade_gate
from quadctl.sweep.batched import CaseDesign, core_extremes
from quadctl.sweep.gates import MARGIN_COLUMNS, margin_columns
from quadctl.sweep.prepare import Prepared

MC_POINTS = 201
"""A Monte Carlo case keeps its regulated states at this many evenly spaced times (float32): with
the ten regulated states of ``mambo-200hz``, 8 kB a case in memory and in the journal, whatever the
duration and step (10 000 seeds: 80 MB). At 10 s, a point every 50 ms."""
MC_PERCENTILES = (5, 25, 50, 75, 95)
"""The percentiles a Monte Carlo reports at every time (the bands 5-95 and 25-75, the median)."""


def failed_row(head: dict, status: str, reason: str) -> dict:
    """The row of a case with no run: its head, ``status`` (why: :data:`quadctl.sweep.gates.CASE_STATUSES`) and
    ``reason`` (the sentence), its design and run columns empty."""
    row = dict(head)
    row.update({"stable": None, "eig.fastest": None, "eig.slowest": None, "status": status,
                "dt": None, "steps": 0, "reason": reason, "path": "", "noise_limited": []})
    return row


def case_row(head: dict, stable: bool, core_eigs, plan, summary: dict | None, steps: int, reason: str = "",
             path: str = "", flat: tuple | None = None) -> dict:
    """A case's row: its head, design verdict, metrics and run. ``core_eigs``: the core eigenvalues,
    or a :class:`~quadctl.sweep.batched.CaseDesign` (its :meth:`eig_extremes`). The metrics from
    ``summary`` (the dict of :func:`quadctl.metrics.summarize`) or ``flat``, (column names, values)
    as :func:`quadctl.sim.lane_metrics.row_values` gives them (the same columns)."""
    row = dict(head)
    row["stable"] = bool(stable)

    row["eig.fastest"], row["eig.slowest"] = (core_eigs.eig_extremes() if isinstance(core_eigs, CaseDesign)
                                              else core_extremes(core_eigs))
    if flat is not None:
        row.update(zip(*flat))
    elif summary is not None:
        for kind in ("settling_time", "overshoot", "peak"):
            values = summary[kind]
            row.update(zip(_columns(kind, tuple(values)), values.values()))
        row["cost"] = summary["cost"]
        row["status"] = summary["status"]
        row["noise_limited"] = summary["noise_limited"]
    row.setdefault("noise_limited", [])
    row["dt"] = plan.dt if plan is not None else None
    row["steps"] = int(steps)
    row["reason"] = reason
    row["path"] = path
    return row


@lru_cache(maxsize=32)
def _columns(kind: str, names: tuple[str, ...]) -> tuple[str, ...]:
    """Row keys of a metric's values: ``settling_time.phi``, ... (the same few for every row)."""
    return tuple(f"{kind}.{name}" for name in names)


def mission_reason(setup, reached, status: str) -> str:
    """A row's ``reason`` for a mission (``setup.reference`` with waypoints) whose waypoints were
    ``reached`` (s each, or None) in a run that ended ``status``: the sentence ``simulate`` fails with
    (:func:`quadctl.present.mission.mission_text`), or empty (reached; a run that did not finish says
    so itself). A sweep's lanes keep no final error: only the missed waypoints count here."""

    ref = setup.reference
    if ref is None or not ref.legs or status != "ok":
        return ""
    tracking = {"waypoints": [{"position": list(leg.position), "reached": r} for leg, r in zip(ref.legs, reached)],
                "tolerance": ref.tolerance, "mission_end": ref.end}
    tracking.update(run_summary.mission_check(tracking, status=status,
                                              unregulated=run_summary.unregulated_positions(setup),
                                              duration=setup.duration))
    return mission_text(tracking) or ""


def judge_cascade(row: dict, stages: pipeline.Stages) -> None:
    """With ``controller.flies: pid``, a case's ``stable`` is the cascade's that flies, as ``simulate`` checks it
    (:attr:`quadctl.sim.cascade_lift.Lifted.stable`: its closed loop about hover, lifted to its frame), not the
    LQR design's; ``eig.slowest`` is the rate of its slowest mode, ln(spectral radius) / frame (rad/s), and
    ``eig.fastest`` is empty (the frame map's poles at 0, the held samples', have no rate)."""
    if row.get("stable") is None:  # no design: the case did not fly
        return
    lift = stages.pid_lift
    radius = float(np.abs(lift.poles).max())
    row["stable"] = lift.stable
    row["eig.fastest"], row["eig.slowest"] = None, float(np.log(radius)) / lift.frame_time
    if not lift.stable:
        row["instability"] = unstable_cascade_gate(radius, lift.frame_time)


def add_margins(row: dict, prep: Prepared, stages: pipeline.Stages) -> None:
    """A designed case's :data:`~quadctl.sweep.gates.MARGIN_COLUMNS` (None where it has no design): of the law
    that flies, as ``quadctl margins`` reports them (``controller.flies: pid``: the cascade's loops)."""

    row.update(dict.fromkeys(MARGIN_COLUMNS))
    if row.get("stable") is None:  # no design
        return
    try:
        found = stages.pid_margins if prep.setup.law == "pid" else \
            pipeline.margins_of(prep.setup, prep.plant.linear, prep.plant.decoupled, stages.design)
    except QuadctlError as exc:
        row["margins_missing"] = f"no margins: {exc}"
        return
    row.update(margin_columns(found))
    if row[MARGIN_COLUMNS[0]] is None:
        row["margins_missing"] = "a loop is unstable"


def mc_grid(duration: float) -> np.ndarray:
    """The Monte Carlo time grid: (MC_POINTS,) evenly spaced times from 0 to ``duration`` s."""
    return np.linspace(0.0, float(duration), MC_POINTS)


def resample_deviation(t, x, x_ref, states, duration: float) -> np.ndarray:
    """Deviation of ``states`` from the reference, linearly interpolated onto :func:`mc_grid`.

    Parameters
    ----------
    t : (N,) array_like
        s, increasing (a simulation's records).
    x, x_ref : (N, 12) array_like
        State and reference (state units: m, m/s, rad, rad/s).
    states : sequence of str
    duration : float
        s, the end of the grid.

    Returns
    -------
    (MC_POINTS, len(states)) float32 ndarray
        ``x - x_ref`` at the grid's times. float32 keeps seven digits, far below the noise a Monte
        Carlo measures, at half the memory.
    """
    grid = mc_grid(duration)
    index = [STATE_INDEX[s] for s in states]
    dev = np.asarray(x)[:, index] - np.asarray(x_ref)[:, index]
    return np.stack([np.interp(grid, t, dev[:, j]) for j in range(len(index))], axis=1).astype(np.float32)
