"""Step-response metrics of a simulation run: settling, overshoot, peaks, cost.

All are computed on the error ``e = x - x_ref(t)`` of each state against the reference
the controller regulates to.
"""

from __future__ import annotations

import math

import numpy as np

from quadctl.layout import INPUT_NAMES, STATE_NAMES

SETTLING_BAND = 0.02
"""Settled once ``|e|`` stays within 2 % of the state's largest ``|e|`` over the run."""
ERROR_FLOOR = 1e-9
"""Errors below this (state units) count as zero: a state that never moves settles at t = 0."""


OVERSHOOT_FLOOR = 1e-6
"""Excursions past zero below this fraction of the initial error are round-off: overshoot 0."""


def settling_time(t, err) -> float | None:
    """Time after which ``|err|`` stays within ``SETTLING_BAND`` of its peak (s); None if it never does."""
    mag = np.abs(err)
    peak = float(mag.max()) if mag.size else 0.0
    if peak <= ERROR_FLOOR:
        return 0.0
    band = max(SETTLING_BAND * peak, ERROR_FLOOR)
    outside = np.nonzero(mag > band)[0]
    if outside.size == 0:
        return 0.0
    last = int(outside[-1])
    if last == len(t) - 1:
        return None
    return float(t[last + 1])


def overshoot(err) -> float | None:
    """Largest excursion past zero, in % of the initial error; None when the initial error is ~0."""
    e0 = float(err[0])
    if abs(e0) <= ERROR_FLOOR:
        return None
    excursion = max(0.0, float(np.max(-np.sign(e0) * err))) / abs(e0)
    return 0.0 if excursion < OVERSHOOT_FLOOR else excursion * 100.0


def lqr_cost(t, err, du, Q, R) -> float:
    """``integral of e' Q e + du' R du dt`` by the trapezoid rule."""
    integrand = np.einsum("ki,ij,kj->k", err, Q, err) + np.einsum("ki,ij,kj->k", du, R, du)
    return float(np.sum((integrand[1:] + integrand[:-1]) * np.diff(t)) / 2) if len(t) > 1 else 0.0


def summarize(sim, u_trim, Q, R, regulated_states) -> dict:
    """Metrics of a run, as plain JSON-ready data.

    Parameters
    ----------
    sim : SimResult
    u_trim : (4,) array_like
    Q : (12, 12) array_like
    R : (4, 4) array_like
    regulated_states : iterable of str
        States that get settling and overshoot figures.

    Returns
    -------
    dict
        ``settling_time`` (s), ``overshoot`` (%), ``peak_error``, ``final_error`` per state;
        ``peak`` per input (max |u|, N or N m); ``cost``; ``status``.
    """
    err = sim.x - sim.x_ref
    du = sim.u - np.asarray(u_trim)
    out: dict = {"settling_time": {}, "overshoot": {}, "peak_error": {}, "final_error": {}}
    for i, name in enumerate(STATE_NAMES):
        out["peak_error"][name] = float(np.abs(err[:, i]).max())
        out["final_error"][name] = float(err[-1, i])
        if name in regulated_states:
            out["settling_time"][name] = settling_time(sim.t, err[:, i])
            out["overshoot"][name] = overshoot(err[:, i])
    out["peak"] = {name: float(np.abs(sim.u[:, j]).max()) for j, name in enumerate(INPUT_NAMES)}
    cost = lqr_cost(sim.t, err, du, np.asarray(Q), np.asarray(R))
    out["cost"] = cost if math.isfinite(cost) else None
    out["status"] = sim.status
    return out
