"""The metrics a sweep case reports, and the gates on them: thresholds, verdicts, ranking."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

from quadctl.design.margins import least_margins
from quadctl.layout import INPUT_NAMES, INPUT_UNITS, STATE_NAMES
from quadctl.metrics import NOISE_LIMITED_WORDS

CASE_STATUSES = ("ok", "diverged", "left_valid_range", "invalid_config", "no_trim", "design_failed", "step_refused",
                 "failed")
"""Every ``status`` a case's row can have: how its run ended (:data:`quadctl.sim.run.STATUS_WORDS`), or why it has
no run (:mod:`quadctl.sweep.evaluate`, :mod:`quadctl.sweep.lane_rows`); what a gate ``status: {equals: ...}`` may
name."""


@dataclass(frozen=True)
class Gate:
    """A threshold on one metric: ``min <= value <= max``, or ``value == equals``."""

    metric: str
    min: float | None = None
    max: float | None = None
    equals: Any = None

    def passes(self, value) -> bool:
        """A missing value (never settled, no design) fails every gate."""
        if self.equals is not None:
            return value == self.equals
        if value is None or isinstance(value, (bool, str)):
            return False
        if self.min is not None and not value >= self.min:
            return False
        if self.max is not None and not value <= self.max:
            return False
        return True

    def slack(self, value) -> float:
        """How far inside the gate ``value`` is, relative to the threshold (negative: outside)."""
        if self.equals is not None:
            return 0.0 if value == self.equals else -math.inf
        if value is None or isinstance(value, (bool, str)) or not math.isfinite(value):
            return -math.inf
        slack = math.inf
        for bound, sign in ((self.max, 1.0), (self.min, -1.0)):
            if bound is not None:
                slack = min(slack, sign * (bound - value) / max(abs(bound), 1e-12))
        return slack

    def describe(self) -> str:
        if self.equals is not None:
            return f"{self.metric} == {json.dumps(self.equals)}"
        parts = ([f"{self.min:g} <="] if self.min is not None else []) + [self.metric] + \
                ([f"<= {self.max:g}"] if self.max is not None else [])
        return " ".join(parts)


def metric_columns(cfg) -> list[str]:
    """The metric columns of a sweep of ``cfg``, in table order.

    ``stable`` (coupled linear closed loop), ``eig.fastest`` / ``eig.slowest`` (most negative and
    largest real part of its eigenvalues, marginal position modes left out; rad/s; with
    ``controller.flies: pid``, the cascade's lifted loop: ``quadctl.sweep.rows.judge_cascade``), then per
    regulated state ``settling_time.<state>`` (s, 2 % band) and ``overshoot.<state>`` (%), per
    input ``peak.<input>`` (max ``|u|``: N or N m), ``cost`` (the LQR cost integral), ``status``
    (the simulation's: ok, diverged, left_valid_range; or why the case has no simulation),
    ``dt`` (s) and ``steps``; with ``simulation.reference``, after the peaks, :data:`TRACKING_COLUMNS`
    (a mission's, with ``waypoints.reached``).
    """
    states = regulated_states(cfg)
    ref = cfg.simulation.reference
    tracking = [] if ref is None else list(TRACKING_COLUMNS[:3 if ref.waypoints is not None else 2])
    return (["stable", "eig.fastest", "eig.slowest"] + [f"settling_time.{s}" for s in states]
            + [f"overshoot.{s}" for s in states] + [f"peak.{i}" for i in INPUT_NAMES] + tracking
            + ["cost", "status", "dt", "steps"])


MARGIN_COLUMNS = ("margin.gain_db", "margin.phase_deg")
"""Columns of a sweep that gates on them (computed only then: a design's margins cost more than its run's
metrics): the least gain margin of any regulated loop, dB on its nearer side (``min(-lower, upper)``), and
the least phase margin, deg, over the design-model and coupled loops as ``quadctl margins`` reports them
(:func:`quadctl.pipeline.margins_of`: the rotors' lag, the delay and the gyro filter in them); None, which fails
every gate, when one of them is unstable (:func:`quadctl.design.margins.least_margins`). A gate
``margin.gain_db: {min: 6}`` and ``margin.phase_deg: {min: 30}`` is the thin-margins check
(:data:`quadctl.design.margins.THIN_GAIN_MARGIN_DB`, :data:`~quadctl.design.margins.THIN_PHASE_MARGIN_DEG`)."""


def margin_columns(found) -> dict:
    """:data:`MARGIN_COLUMNS` of a design's :class:`~quadctl.design.margins.LoopMargins`."""

    return dict(zip(MARGIN_COLUMNS, least_margins(found)))


def gated_margins(gates) -> bool:
    """Whether a gate reads :data:`MARGIN_COLUMNS` (the sweep then computes them)."""
    return any(g.metric in MARGIN_COLUMNS for g in gates)


TRACKING_ERRORS = ("tracking.rms", "tracking.peak")
"""m: the position error flying a reference, its RMS and its peak."""
WAYPOINTS_REACHED = "waypoints.reached"
"""A mission's column: its waypoints reached in order within its tolerance (a count)."""
TRACKING_COLUMNS = (*TRACKING_ERRORS, WAYPOINTS_REACHED)
"""Columns of a case that flies a reference: the position tracking error's RMS and peak (m), and
a mission's waypoints reached in order within its tolerance (a count)."""


METRIC_UNITS: dict[str, str] = {
    "eig.fastest": "rad/s", "eig.slowest": "rad/s", "settling_time.": "s", "overshoot.": "%",
    **{f"peak.{i}": INPUT_UNITS[i] for i in INPUT_NAMES}, "cost": "1", "dt": "s", "steps": "1",
    "tracking.rms": "m", "tracking.peak": "m", WAYPOINTS_REACHED: "1",
    MARGIN_COLUMNS[0]: "dB", MARGIN_COLUMNS[1]: "deg",
}
"""The unit of each numeric metric column (``1``: a count or a pure number); a key ending in ``.`` is the unit of
every column it begins (``settling_time.pD``: s). ``stable`` and ``status`` are not numbers."""


def column_units(columns) -> dict[str, str]:
    """The unit of each metric column among ``columns`` (:data:`METRIC_UNITS`); the rest (``case``, the
    parameters, whose units are :attr:`~quadctl.sweep.spec.SweepSpec.parameter_units`, flags and text) left out.

    >>> column_units(["case", "vehicle.mass", "stable", "settling_time.pD", "peak.A", "cost"])
    {'settling_time.pD': 's', 'peak.A': 'N m', 'cost': '1'}
    """
    out = {}
    for column in columns:
        unit = METRIC_UNITS.get(column) or METRIC_UNITS.get(column.partition(".")[0] + ".")
        if unit is not None:
            out[column] = unit
    return out


def tracking_columns(tracking: dict | None) -> dict:
    """:data:`TRACKING_COLUMNS` from :func:`quadctl.run_summary.tracking_of` (none without a reference)."""
    if tracking is None:
        return {}
    out = {"tracking.rms": tracking["position_error"]["rms"], "tracking.peak": tracking["position_error"]["peak"]}
    if "waypoints" in tracking:
        out[WAYPOINTS_REACHED] = sum(w["reached"] is not None for w in tracking["waypoints"])
    return out


def regulated_states(cfg) -> list[str]:
    """The states of the config's regulated subsystems, in state order."""
    regulated = {s for sub in cfg.partition().values() if sub.regulate for s in sub.states}
    return [s for s in STATE_NAMES if s in regulated]


def noise_limited_reason(states) -> str:
    """A row's ``reason`` for its noise-limited settling times (``states``; their columns are empty)."""
    return f"settling noise-limited: {', '.join(states)} ({NOISE_LIMITED_WORDS})"


def judge(row: dict, gates, require_ok: bool) -> tuple[bool, list[str]]:
    """Whether a row passes, and what it fails (gate descriptions, or why it has no result; a
    settling time the row's ``noise_limited`` lists shows as ``noise-limited``, a missing margin the
    row's ``margins_missing``: ``none: a loop is unstable``)."""
    failed = []
    if require_ok:
        if row.get("status") != "ok":
            failed.append(f"status {row.get('status')}")
        elif row.get("stable") is False:  # the LQR design on the coupled model, or the cascade that flies
            failed.append(row.get("instability") or "unstable on the coupled model")
    for gate in gates:
        if not gate.passes(row.get(gate.metric)):
            value = row.get(gate.metric)
            shown = "none" if value is None else (f"{value:.4g}" if isinstance(value, float) else str(value))
            if value is None and gate.metric.startswith("settling_time.") \
                    and gate.metric.split(".", 1)[1] in row.get("noise_limited", ()):
                shown = "noise-limited"
            elif value is None and gate.metric in MARGIN_COLUMNS and row.get("margins_missing"):
                shown = f"none: {row['margins_missing']}"  # the design's loop, not a run that stopped
            failed.append(f"{gate.describe()} (got {shown})")
    return not failed, failed


def margin(row: dict, gates, require_ok: bool) -> float:
    """How well a row passes: the smallest relative slack over its gates (-inf: no result).

    Without gates, the negative LQR cost (lower cost ranks better).
    """
    if require_ok and (row.get("status") != "ok" or row.get("stable") is False):
        return -math.inf
    if not gates:
        cost = row.get("cost")
        return -cost if isinstance(cost, (int, float)) and math.isfinite(cost) else -math.inf
    return min(g.slack(row.get(g.metric)) for g in gates)
