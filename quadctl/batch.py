"""Vectorized numerics for many designs at once: the coupled verdict and metrics.

Each function here is the batched twin of a one-case function elsewhere in quadctl and is
tested against it: :func:`coupled_stability` against :func:`quadctl.lqr.closed_loop_stability`,
:func:`summarize_run` against :func:`quadctl.metrics.summarize`. The batched Riccati solvers
moved to :mod:`quadctl.riccati` (:func:`~quadctl.riccati.care_batch`,
:func:`~quadctl.riccati.dare_batch`); ``care``, ``riccati_residuals``, ``BatchLqr`` and
``NEWTON_STEPS`` stay importable from here for the sweep.
"""

from __future__ import annotations

import math

import numpy as np

from quadctl.analysis import STABILITY_MARGIN
from quadctl.layout import INPUT_NAMES, POSITION_STATES, STATE_NAMES
from quadctl.metrics import ERROR_FLOOR, SETTLING_BAND
from quadctl.riccati import NEWTON_STEPS as NEWTON_STEPS  # re-exported for the sweep (quadctl.riccati's)
from quadctl.riccati import BatchLqr as BatchLqr
from quadctl.riccati import care_batch as care  # noqa: F401 (re-exported: quadctl.sweep calls batch.care)
from quadctl.riccati import riccati_residuals as riccati_residuals


def coupled_stability(A_cl, K) -> tuple[list[np.ndarray], np.ndarray]:
    """:func:`quadctl.lqr.closed_loop_stability` of stacked coupled closed loops.

    Parameters
    ----------
    A_cl : (N, 12, 12) array_like
        ``A - B K`` of each case.
    K : (N, 4, 12) array_like

    Returns
    -------
    core : list of (k,) complex ndarray
        Per case, the eigenvalues without the marginal position modes (unregulated positions
        that nothing depends on: their zero eigenvalues are expected, not unstable).
    stable : (N,) bool ndarray
        Every core eigenvalue is in the open left half-plane (``STABILITY_MARGIN``).
    """
    A_cl = np.asarray(A_cl, dtype=float)
    K = np.asarray(K, dtype=float)
    positions = [STATE_NAMES.index(s) for s in POSITION_STATES]
    free = ~np.any(K[:, :, positions] != 0, axis=1) & ~np.any(A_cl[:, :, positions] != 0, axis=1)
    core: list = [None] * len(A_cl)
    stable = np.zeros(len(A_cl), dtype=bool)
    for pattern in {tuple(row) for row in free.tolist()}:
        members = np.nonzero((free == pattern).all(axis=1))[0]
        keep = [i for i in range(len(STATE_NAMES))
                if i not in [p for p, m in zip(positions, pattern) if m]]
        eig = np.linalg.eigvals(A_cl[np.ix_(members, keep, keep)])
        ok = np.all(eig.real < -STABILITY_MARGIN * np.maximum(1.0, np.abs(eig)), axis=1)
        for j, k in enumerate(members):
            core[k] = eig[j]
            stable[k] = ok[j]
    return core, stable


# ---------------------------------------------------------------------------------------
# Metrics


def summarize_run(t, x, u, x_ref, u_trim, Q, R, regulated_states, status) -> dict:
    """:func:`quadctl.metrics.summarize` of one run, vectorized over the states.

    Same definitions and the same numbers (the cost integral to round-off: its quadratic forms
    are summed term by term over the nonzeros of ``Q`` and ``R`` instead of by ``einsum``),
    several times faster on 10 000 samples. Works on the state-major transposes, where every
    reduction runs along contiguous memory, and calls no BLAS (whose threads would fight the
    sweep's worker processes for the cores).

    Parameters
    ----------
    t : (r,) ndarray
        s.
    x : (r, 12) ndarray
        Any memory layout; ``x.T`` contiguous is fastest.
    x_ref : (r, 12) ndarray, or a pair ``(x_trim (12,), x_rate (12,))``
        The reference, or what makes it: ``x_trim + x_rate t`` (cheaper than building it).
    u : (r, 4) ndarray
    u_trim : (4,) ndarray
    Q : (12, 12) ndarray
    R : (4, 4) ndarray
    regulated_states : iterable of str
    status : str

    Returns
    -------
    dict
        The keys of :func:`quadctl.metrics.summarize`.
    """
    t = np.asarray(t, dtype=float)
    if isinstance(x_ref, tuple):
        x_trim, x_rate = (np.asarray(a, dtype=float) for a in x_ref)
        err = np.asarray(x).T - x_trim[:, None]           # (12, r)
        for i in np.nonzero(x_rate)[0]:
            err[i] -= x_rate[i] * t
    else:
        err = np.asarray(x).T - np.asarray(x_ref).T      # (12, r)
    du = np.asarray(u).T - np.asarray(u_trim)[:, None]   # (4, r)
    n = err.shape[1]
    mag = np.abs(err)
    peak = mag.max(axis=1)
    regulated = set(regulated_states)
    out: dict = {"settling_time": {}, "overshoot": {}, "peak_error": {}, "final_error": {}}
    band = np.maximum(SETTLING_BAND * peak, ERROR_FLOOR)
    outside = mag > band[:, None]
    any_out = outside.any(axis=1)
    last = n - 1 - np.argmax(outside[:, ::-1], axis=1)
    e0 = err[:, 0]
    # max(-sign(e0) e) without the product: -min(e) where e0 > 0, max(e) where e0 < 0 (exact)
    past = np.where(e0 > 0, -err.min(axis=1), np.where(e0 < 0, err.max(axis=1), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        over = np.maximum(0.0, past) / np.abs(e0) * 100.0
    for i, name in enumerate(STATE_NAMES):
        out["peak_error"][name] = float(peak[i])
        out["final_error"][name] = float(err[i, -1])
        if name in regulated:
            if peak[i] <= ERROR_FLOOR or not any_out[i]:
                settle = 0.0
            elif last[i] == n - 1:
                settle = None
            else:
                settle = float(t[last[i] + 1])
            out["settling_time"][name] = settle
            out["overshoot"][name] = None if abs(e0[i]) <= ERROR_FLOOR else float(over[i])
    out["peak"] = {name: float(v) for name, v in zip(INPUT_NAMES, np.abs(np.asarray(u).T).max(axis=1))}
    with np.errstate(all="ignore"):
        integrand = _quadratic(err, np.asarray(Q, dtype=float)) + _quadratic(du, np.asarray(R, dtype=float))
        cost = float(np.sum((integrand[1:] + integrand[:-1]) * np.diff(t)) / 2) if n > 1 else 0.0
    out["cost"] = cost if math.isfinite(cost) else None
    out["status"] = status
    return out


def _quadratic(vT: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``v_k^T M v_k`` for each column ``v_k`` of ``vT`` (n, r), summed over the nonzeros of ``M``."""
    acc = np.zeros(vT.shape[1])
    term = np.empty(vT.shape[1])
    for i, j in zip(*np.nonzero(M)):
        np.multiply(vT[i], vT[j], out=term)
        term *= M[i, j]
        acc += term
    return acc
