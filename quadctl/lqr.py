"""LQR gains from the continuous algebraic Riccati equation, per subsystem and assembled.

MATLAB ``lqr`` conventions: ``u = -K x``, ``K = R^-1 B^T P``, ``P`` the stabilizing solution of
``A^T P + P A - P B R^-1 B^T P + Q = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from quadctl.analysis import check, is_stable
from quadctl.decouple import Decoupled
from quadctl.errors import DesignError
from quadctl.layout import INPUT_INDEX, N_INPUTS, N_STATES, POSITION_STATES, STATE_INDEX, STATE_NAMES

RICCATI_RTOL = 1e-8
"""Largest accepted ``|CARE residual| / (|Q| + |A^T P| + |P B R^-1 B^T P|)`` (relative)."""


@dataclass(frozen=True)
class LqrResult:
    """``K, P, E = lqr(A, B, Q, R)``: gain (m, n), Riccati solution (n, n), closed-loop eigenvalues (n,)."""

    K: np.ndarray
    P: np.ndarray
    E: np.ndarray
    residual: float

    def __iter__(self):
        return iter((self.K, self.P, self.E))


def riccati_residual(A, B, Q, R, P) -> float:
    """Relative residual of the CARE at ``P`` (0 for an exact solution)."""
    BRB = B @ np.linalg.solve(R, B.T)
    terms = (A.T @ P, P @ A, P @ BRB @ P, Q)
    res = terms[0] + terms[1] - terms[2] + terms[3]
    scale = sum(np.linalg.norm(t, 1) for t in terms) or 1.0
    return float(np.linalg.norm(res, 1) / scale)


def lqr(A, B, Q, R, *, name: str = "system", state_names=None) -> LqrResult:
    """Continuous-time LQR (MATLAB ``lqr``).

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    Q : (n, n) array_like
        Symmetric positive semidefinite state weight.
    R : (m, m) array_like
        Symmetric positive definite input weight.
    name : str
        Names the system in errors.
    state_names : sequence of str, optional
        Names the states of an unstabilizable mode in errors.

    Returns
    -------
    LqrResult

    Raises
    ------
    DesignError
        ``(A, B)`` is not stabilizable (the mode is named), or the Riccati solve fails.

    Examples
    --------
    A scalar integrator ``x' = u`` with ``Q = q``, ``R = r`` has ``P = sqrt(q r)``, ``K = sqrt(q / r)``:

    >>> K, P, E = lqr([[0.0]], [[1.0]], [[4.0]], [[1.0]])
    >>> float(K[0, 0]), float(P[0, 0]), complex(E[0])
    (2.0, 2.0, (-2+0j))
    """
    A, B, Q, R = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (A, B, Q, R))
    checks = check(A, B, names=state_names)
    if not checks.stabilizable:
        mode = checks.unstabilizable_modes[0]
        raise DesignError(
            f"{name}: not stabilizable: the mode at eigenvalue {_fmt_eig(mode.eigenvalue)} "
            f"(in {', '.join(mode.states)}) is unstable and no input reaches it; "
            "change the partition so an input drives those states")
    try:
        P = scipy.linalg.solve_continuous_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise DesignError(f"{name}: the Riccati solve failed ({exc}); "
                          "check that Q makes every unstable mode visible (detectable)") from None
    if not np.all(np.isfinite(P)):
        raise DesignError(f"{name}: the Riccati solution is not finite; check the weights")
    P = (P + P.T) / 2
    K = np.linalg.solve(R, B.T @ P)
    E = np.linalg.eigvals(A - B @ K)
    residual = riccati_residual(A, B, Q, R, P)
    if residual > RICCATI_RTOL or not all(is_stable(e) for e in E):
        raise DesignError(
            f"{name}: the Riccati solution is not stabilizing (residual {residual:.1e}); "
            "an unstable or marginal mode is invisible to Q: give weight to the states it lives in")
    return LqrResult(K=K, P=P, E=E, residual=residual)


@dataclass(frozen=True)
class SubsystemDesign:
    """LQR of one regulated subsystem."""

    name: str
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    Q: np.ndarray
    R: np.ndarray
    K: np.ndarray
    P: np.ndarray
    eigenvalues: np.ndarray
    residual: float


@dataclass(frozen=True)
class Design:
    """The assembled decoupled design, checked on the full coupled linear model.

    Attributes
    ----------
    subsystems : tuple of SubsystemDesign
    K_block : (4, 12) ndarray
        ``u = u_trim - K_block (x - x_trim)``, columns in ``STATE_NAMES`` order.
    Q_block : (12, 12) ndarray
        The subsystems' Q assembled (zero for unregulated states): the cost the design minimizes.
    R_block : (4, 4) ndarray
    full_eigenvalues : (12,) ndarray
        Eigenvalues of ``A - B K_block`` on the coupled model.
    marginal_states : tuple of str
        Unregulated position states: their exact zero eigenvalues are expected, not unstable.
    stable : bool
        Every other eigenvalue of the coupled closed loop is in the open left half-plane.
    """

    subsystems: tuple[SubsystemDesign, ...]
    K_block: np.ndarray
    Q_block: np.ndarray
    R_block: np.ndarray
    full_eigenvalues: np.ndarray
    marginal_states: tuple[str, ...]
    stable: bool

    def __getitem__(self, name: str) -> SubsystemDesign:
        for sub in self.subsystems:
            if sub.name == name:
                return sub
        raise KeyError(name)


def design(decoupled: Decoupled, A, B, weights: dict) -> Design:
    """LQR per regulated subsystem, assembled into a block gain and checked on ``(A, B)``.

    Parameters
    ----------
    decoupled : Decoupled
    A : (12, 12) array_like
        The full coupled model the block gain is checked on.
    B : (12, 4) array_like
    weights : dict
        ``subsystem name -> (Q, R)`` as (n, n) and (m, m) arrays.

    Returns
    -------
    Design

    Raises
    ------
    DesignError
        A subsystem is not stabilizable or its Riccati solve fails.
    """
    K_block = np.zeros((N_INPUTS, N_STATES))
    Q_block = np.zeros((N_STATES, N_STATES))
    R_block = np.zeros((N_INPUTS, N_INPUTS))
    subs = []
    for sub in decoupled.regulated:
        Q, R = (np.atleast_2d(np.asarray(m, dtype=float)) for m in weights[sub.name])
        res = lqr(sub.A, sub.B, Q, R, name=f"subsystem {sub.name}", state_names=sub.states)
        rows = [INPUT_INDEX[i] for i in sub.inputs]
        cols = sub.state_index
        K_block[np.ix_(rows, cols)] = res.K
        Q_block[np.ix_(cols, cols)] = Q
        R_block[np.ix_(rows, rows)] = R
        subs.append(SubsystemDesign(name=sub.name, states=sub.states, inputs=sub.inputs, Q=Q, R=R,
                                    K=res.K, P=res.P, eigenvalues=res.E, residual=res.residual))
    eig, marginal, stable = closed_loop_stability(np.asarray(A) - np.asarray(B) @ K_block, K_block)
    return Design(subsystems=tuple(subs), K_block=K_block, Q_block=Q_block, R_block=R_block,
                  full_eigenvalues=eig, marginal_states=marginal, stable=stable)


def closed_loop_stability(A_cl, K) -> tuple[np.ndarray, tuple[str, ...], bool]:
    """Eigenvalues of the coupled closed loop, and whether it is stable.

    Position states that no gain feeds back and that nothing depends on (zero columns of
    ``A_cl``: translation invariance) add exact zero eigenvalues; they are reported as
    marginal and excluded from the verdict. Every other eigenvalue must be stable.
    """
    A_cl = np.asarray(A_cl, dtype=float)
    eig = np.linalg.eigvals(A_cl)
    marginal = tuple(s for s in POSITION_STATES
                     if not np.any(K[:, STATE_INDEX[s]]) and not np.any(A_cl[:, STATE_INDEX[s]]))
    keep = [i for i, s in enumerate(STATE_NAMES) if s not in marginal]
    core = np.linalg.eigvals(A_cl[np.ix_(keep, keep)])
    return eig, marginal, bool(all(is_stable(e) for e in core))


def _fmt_eig(e: complex) -> str:
    return f"{e.real:.4g}" if abs(e.imag) < 1e-12 else f"{e.real:.4g}{e.imag:+.4g}j"
