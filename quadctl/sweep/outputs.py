"""What a sweep reports: sweep.csv, the sweep.json summary, the trade-off plot, Monte Carlo bands."""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from quadctl.errors import SweepError
from quadctl.sweep.gates import TRACKING_ERRORS, column_units
from quadctl.sweep.rows import MC_PERCENTILES, MC_POINTS, mc_grid
from quadctl.sweep.runner import SweepResult
from quadctl.sweep.spec import SweepSpec

WORST_SHOWN = 10
BEST_SHOWN = 5

MC_FILES = ("montecarlo.png", "montecarlo.npz")


@dataclass(frozen=True)
class MonteCarloBands:
    """Percentile bands of a Monte Carlo's trajectories against time.

    Attributes
    ----------
    t : (P,) ndarray
        s, the grid (:func:`mc_grid`).
    percentiles : tuple of float
        The levels, :data:`MC_PERCENTILES`.
    bands : (len(percentiles), P, S) ndarray
        At each level, time and state: the deviation from the reference in state units (m, m/s,
        rad, rad/s), over the cases at that time (numpy's linear interpolation between cases).
    states : tuple of str
        The S states, in state order.
    cases : (N,) int ndarray
        The cases the bands are over, in order.
    traces : (N, P, S) float32 ndarray
        Their trajectories.
    left_out : tuple of int
        Cases of the sweep without a trajectory (they did not simulate to the end).
    """

    t: np.ndarray
    percentiles: tuple
    bands: np.ndarray
    states: tuple
    cases: np.ndarray
    traces: np.ndarray
    left_out: tuple = ()


def montecarlo_bands(traces: dict, states, duration: float, cases: Iterable[int] = ()) -> MonteCarloBands:
    """The percentile bands of trajectories on the Monte Carlo grid.

    Parameters
    ----------
    traces : dict
        Case number -> (MC_POINTS, len(states)) deviations (:func:`~quadctl.sweep.rows.resample_deviation`).
    states : sequence of str
    duration : float
        s, the run's length (the grid's end).
    cases : iterable of int, optional
        Every case of the sweep: those without a trajectory are listed as left out.

    Raises
    ------
    SweepError
        No trajectory at all, or one of another shape.

    Examples
    --------
    >>> b = montecarlo_bands({0: np.zeros((MC_POINTS, 1)), 1: np.ones((MC_POINTS, 1))}, ["pD"], 1.0)
    >>> float(b.bands[2, 0, 0])  # the median of 0 and 1
    0.5
    """
    shape = (MC_POINTS, len(states))
    if not traces:
        raise SweepError("no case of the Monte Carlo simulated to the end, so there are no bands; "
                         "see the reasons in sweep.csv")
    for case, trace in traces.items():
        if np.shape(trace) != shape:
            raise SweepError(f"case {case}: trajectory of shape {np.shape(trace)}, expected {shape} "
                             f"({MC_POINTS} times of {', '.join(states)})")
    order = sorted(traces)
    stack = np.stack([np.asarray(traces[k], dtype=np.float32) for k in order])
    bands = np.percentile(stack.astype(np.float64), MC_PERCENTILES, axis=0)
    return MonteCarloBands(t=mc_grid(duration), percentiles=tuple(float(p) for p in MC_PERCENTILES),
                           bands=bands, states=tuple(states), cases=np.array(order, dtype=np.int64),
                           traces=stack, left_out=tuple(int(c) for c in cases if c not in traces))


def montecarlo_png(bands: MonteCarloBands, cfg, varied=()) -> bytes:
    """The Monte Carlo figure (:func:`quadctl.plots.montecarlo_figure`) as PNG bytes; ``varied``: the
    parameters' key paths, named in the title."""
    from quadctl import plots  # matplotlib: loaded by the runs that draw

    groups = {name: [s for s in sub.states if s in bands.states]
              for name, sub in cfg.partition().items() if sub.regulate}
    fig = plots.montecarlo_figure(bands, groups, title=cfg.name, varied=tuple(varied))
    return plots.png_bytes(fig, plots.DPI)


def to_csv(result: SweepResult) -> str:
    """The table as CSV: empty cells for missing values, ``true``/``false`` for flags."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(result.columns)
    for row in result.rows:
        writer.writerow([_cell(row.get(c)) for c in result.columns])
    return buf.getvalue()


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ""
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return str(value)


def summarize(result: SweepResult, cfg, spec: SweepSpec) -> dict:
    """The summary of a sweep: counts (by status, and by ``path``: designed in the batched solve, or
    one by one and why), each gate's failures, the worst and best cases.

    Deterministic (no timings), so the same sweep gives the same sweep.json apart from ``created``.
    """
    rows = result.rows
    statuses: dict[str, int] = {}
    paths: dict[str, int] = {}
    for row in rows:
        statuses[row["status"]] = statuses.get(row["status"], 0) + 1
        if row.get("path"):
            paths[row["path"]] = paths.get(row["path"], 0) + 1
    gates = {}
    for gate in spec.gates:
        values = [r.get(gate.metric) for r in rows]
        numbers = [v for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]
        gates[gate.metric] = {
            "min": gate.min, "max": gate.max, "equals": gate.equals, "rule": gate.describe(),
            "failed": sum(not gate.passes(v) for v in values),
            "observed_min": min(numbers) if numbers else None,
            "observed_max": max(numbers) if numbers else None,
        }
    ranked = result.ranked()
    return {
        "sweep": {"file": spec.label, "mode": spec.mode, "samples": spec.samples, "seed": spec.seed,
                  "parameters": {p.path: p.spec for p in spec.parameters},
                  "set": {path: value for path, _, value in spec.fixed}, "require_ok": spec.require_ok},
        "cases": len(rows),
        "passed": sum(r["pass"] for r in rows),
        "failed": sum(not r["pass"] for r in rows),
        "statuses": statuses,
        "paths": paths,
        "unstable": sum(r.get("stable") is False for r in rows),
        "gates": gates,
        "worst": [r for r in ranked[:WORST_SHOWN] if not r["pass"]] or ranked[:min(WORST_SHOWN, len(ranked))],
        "best": list(reversed(ranked[-BEST_SHOWN:])),
        "columns": result.columns,
        "units": {**dict(spec.parameter_units), **column_units(result.columns)},
        "ok": all(r["pass"] for r in rows),
    }


def tradeoff_axes(result: SweepResult) -> tuple[str, str]:
    """The plot's (x, y) metrics: a peak input against how well the loop did, the gated ones first: a
    settling time, or a mission's tracking error (a mission's settling times measure nothing it asks);
    else a gated margin (a sweep that judges its margins only), else the first settling time."""
    gated = [g.metric for g in result.gates]
    xs = [m for m in gated if m.startswith("peak.")] + ["peak.T"]
    ys = [m for m in gated if m.startswith("settling_time.") or m in TRACKING_ERRORS] + \
         [m for m in gated if m.startswith("margin.")] + \
         [c for c in result.columns if c in TRACKING_ERRORS] + \
         [c for c in result.columns if c.startswith("settling_time.")]
    return xs[0], (ys[0] if ys else "cost")


def tradeoff_png(result: SweepResult, cfg) -> bytes:
    """The trade-off figure as PNG bytes."""
    from quadctl import plots  # matplotlib: loaded by the runs that draw

    x, y = tradeoff_axes(result)
    fig = plots.sweep_tradeoff_figure(result.rows, x, y, result.gates, title=cfg.name)
    return plots.png_bytes(fig, plots.DPI)
