"""One LQR on the full coupled model, for comparison with the decoupled design.

The full design minimizes the decoupled design's cost (the subsystems' Q and R, and integrator
weights, assembled) on the coupled 12-state model, so on the linear model it is never worse;
:func:`compare` measures it on the nonlinear one. Positions nothing weighs or depends on are left out
of it; weighted ones are regulated about the moving reference ``x_trim + x_rate t``. See
docs/internals.md ("The coupled design").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.design import discrete, integral, linear_loop
from quadctl.design.decoupled import solve_subsystem
from quadctl.layout import INPUT_NAMES, N_INPUTS, N_STATES, STATE_INDEX, STATE_NAMES
from quadctl.linear import stability

scipy = lazy_import("scipy")  # loaded on first use (then scipy.linalg on access): quadctl._lazy


@dataclass(frozen=True, eq=False)
class FullDesign:
    """A 12-state (LQI: 12 + nz) LQR on the coupled model.

    Attributes
    ----------
    K : (4, 12) ndarray
        State gain (zero columns for the left-out positions).
    Ki : (4, nz) ndarray
        Integrator gain, columns as ``integral_states``.
    integral_states : tuple of str
    states : tuple of str
        The states in the LQR.
    left_out : tuple of str
        Positions with no weight and no dynamics, left out (see the module notes).
    Q : ndarray
        Weight of ``[states; integrals]``.
    R : (4, 4) ndarray
    P : ndarray
        Riccati solution (continuous or discrete).
    eigenvalues : ndarray
        Of the coupled closed loop (rad/s; ``ln(z) / Ts`` for a discrete design).
    core_eigenvalues : ndarray
        ``eigenvalues`` without the marginal modes (:mod:`quadctl.linear.stability`): what ``stable`` is about.
    stable : bool
    rate : float or None
    residual : float
    """

    K: np.ndarray
    Ki: np.ndarray
    integral_states: tuple[str, ...]
    states: tuple[str, ...]
    left_out: tuple[str, ...]
    Q: np.ndarray
    R: np.ndarray
    P: np.ndarray
    eigenvalues: np.ndarray
    core_eigenvalues: np.ndarray
    stable: bool
    rate: float | None
    residual: float


def assembled_weights(design) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """``Q`` of ``[x (12); z (nz)]`` and ``R`` (4, 4) assembled from the subsystems of ``design``."""
    names = (*STATE_NAMES, *design.integral_states)
    Q = np.zeros((len(names), len(names)))
    R = np.zeros((N_INPUTS, N_INPUTS))
    z_at = {s: N_STATES + i for i, s in enumerate(design.integral_states)}
    for sub in design.subsystems:
        idx = [STATE_INDEX[s] for s in sub.states] + [z_at[s] for s in sub.integral]
        Q[np.ix_(idx, idx)] = sub.Q
        rows = [INPUT_NAMES.index(i) for i in sub.inputs]
        R[np.ix_(rows, rows)] = sub.R
    return Q, R, names


def full_design(design, A, B) -> FullDesign:
    """One LQR on the coupled ``(A, B)`` with the decoupled design's cost, integrators and rate.

    Parameters
    ----------
    design : quadctl.design.Design
        The decoupled design whose weights, integral states and rate are reused.
    A : (12, 12) array_like
    B : (12, 4) array_like

    Raises
    ------
    DesignError
        The Riccati solve fails.
    """
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    Q_all, R, _ = assembled_weights(design)
    left_out = stability.free_positions(A, reads=(Q_all,), integral_states=design.integral_states)
    keep = [i for i in range(N_STATES) if STATE_NAMES[i] not in left_out]
    states = tuple(STATE_NAMES[i] for i in keep)
    nz = len(design.integral_states)
    qidx = keep + list(range(N_STATES, N_STATES + nz))
    Q = Q_all[np.ix_(qidx, qidx)]
    plant = SimpleNamespace(A=A[np.ix_(keep, keep)], B=B[keep], states=states, name="full")
    K_red, _, Ki, P, _, _, residual = solve_subsystem(plant, Q, R, design.integral_states, design.sample_time)
    K = np.zeros((N_INPUTS, N_STATES))
    K[:, keep] = K_red
    Ki = Ki.reshape(N_INPUTS, nz)
    A_cl = linear_loop.matrix(A, B, K, Ki, design.integral_states, design.sample_time)
    verdict = stability.assess(A_cl, K, sample_time=design.sample_time)
    return FullDesign(K=K, Ki=Ki, integral_states=design.integral_states, states=states, left_out=left_out,
                      Q=Q, R=R, P=P, eigenvalues=verdict.eigenvalues, core_eigenvalues=verdict.core,
                      stable=verdict.stable, rate=design.rate, residual=residual)


def linear_cost(A, B, K, Ki, design, dx0) -> float:
    """The cost ``J`` of gain ``[K, Ki]`` on the coupled linear model from offset ``dx0`` (integrators 0).

    Continuous: ``dx0' X dx0`` with ``A_cl' X + X A_cl + Q + K' R K = 0``. Discrete (``design.rate``):
    the same with the sampled cost of :func:`quadctl.design.discrete.lqrd_weights` and a discrete
    Lyapunov equation. The weights are :func:`assembled_weights` of ``design``; positions that
    neither design feeds back are left out. Infinite when the loop is unstable.
    """
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    Q_all, R, _ = assembled_weights(design)
    nz = len(design.integral_states)
    Ka = np.hstack([np.asarray(K, dtype=float), np.asarray(Ki, dtype=float).reshape(N_INPUTS, nz)])
    ints = design.integral_states
    free = [STATE_INDEX[s] for s in stability.free_positions(A, reads=(Q_all, K), integral_states=ints)]
    keep = [i for i in range(N_STATES + nz) if i not in free]
    C = integral.selector(STATE_NAMES, design.integral_states)
    x0 = np.concatenate([np.asarray(dx0, dtype=float), np.zeros(nz)])[keep]
    Ts = design.sample_time
    if Ts is None:
        Aa, Ba = integral.augment(A, B, C)
        Aa, Ba, Ka_r, Qa = Aa[np.ix_(keep, keep)], Ba[keep], Ka[:, keep], Q_all[np.ix_(keep, keep)]
        Acl = linear_loop.close(Aa, Ba, Ka_r)
        if not np.all(stability.is_stable(np.linalg.eigvals(Acl))):
            return math.inf
        X = scipy.linalg.solve_continuous_lyapunov(Acl.T, -(Qa + Ka_r.T @ R @ Ka_r))
    else:
        n_keep_x = [i for i in keep if i < N_STATES]
        Ad, Bd, Qd, Rd, Nd = discrete.lqrd_weights(A[np.ix_(n_keep_x, n_keep_x)], B[n_keep_x],
                                                   Q_all[np.ix_(n_keep_x, n_keep_x)], R, Ts, name="full")
        Cr = C[:, n_keep_x]
        Aa, Ba = integral.augment_discrete(Ad, Bd, Cr, Ts)
        qidx = n_keep_x + list(range(N_STATES, N_STATES + nz))
        Qa, Na = integral.discrete_weights(Qd, Nd, Q_all[np.ix_(qidx, qidx)], Ts)
        Ka_r = Ka[:, keep]
        Acl = linear_loop.close(Aa, Ba, Ka_r)
        if not np.all(stability.is_stable(np.linalg.eigvals(Acl), discrete=True)):
            return math.inf
        stage = Qa + Ka_r.T @ Rd @ Ka_r - Na @ Ka_r - Ka_r.T @ Na.T
        X = scipy.linalg.solve_discrete_lyapunov(Acl.T, stage)
    return float(x0 @ X @ x0)


def compare(named_runs: dict, regulated_states) -> dict:
    """Which design does better on the nonlinear model, and by how much.

    Parameters
    ----------
    named_runs : dict
        ``label -> metrics`` (:func:`quadctl.metrics.summarize` of each run) with the extra key
        ``linear_cost``.
    regulated_states : iterable of str

    Returns
    -------
    dict
        Per label: ``settling`` (s, the slowest regulated state; None if one never settles),
        ``peak_input`` per input, ``cost`` (nonlinear run), ``linear_cost``; and ``better``:
        criterion -> ``{"winner", "ratio"}`` (ratio = loser / winner, > 1).
    """
    regulated = list(regulated_states)
    table = {}
    for label, met in named_runs.items():
        settle = [met["settling_time"].get(s) for s in regulated]
        table[label] = {
            "settling": None if any(v is None for v in settle) else max(settle),
            "peak_input": dict(met["peak_delta"]),
            "cost": met["cost"], "linear_cost": met["linear_cost"], "status": met["status"],
            "backend": met.get("backend"),
        }
    labels = list(table)
    better = {}
    criteria = [("settling", lambda r: r["settling"]), ("cost", lambda r: r["cost"]),
                ("linear_cost", lambda r: r["linear_cost"])]
    criteria += [(f"peak_{name}", lambda r, name=name: r["peak_input"][name]) for name in INPUT_NAMES]
    for crit, get in criteria:
        vals = {lab: get(table[lab]) for lab in labels}
        if any(v is None for v in vals.values()):
            finite = [lab for lab, v in vals.items() if v is not None]
            better[crit] = {"winner": finite[0] if len(finite) == 1 else None, "ratio": None}
            continue
        win = min(vals, key=vals.get)
        lose = max(vals, key=vals.get)
        ratio = vals[lose] / vals[win] if vals[win] > 0 else (math.inf if vals[lose] > 0 else 1.0)
        better[crit] = {"winner": win if ratio > 1 + 1e-9 else None, "ratio": ratio}
    return {"designs": table, "better": better}
