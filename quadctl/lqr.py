"""LQR gains from the continuous algebraic Riccati equation, per subsystem and assembled.

MATLAB ``lqr`` conventions: ``u = -K x``, ``K = R^-1 B^T P``, ``P`` the stabilizing solution of
``A^T P + P A - P B R^-1 B^T P + Q = 0``.

With a controller rate, :func:`design` solves the discrete problem instead (MATLAB ``lqrd``, see
:mod:`quadctl.discrete`); with ``integral`` states, each subsystem is augmented with their
integrals first (MATLAB ``lqi``, see :mod:`quadctl.integral`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from quadctl import discrete, integral, stability
from quadctl._lazy import lazy_import
from quadctl.analysis import RICCATI_RTOL, check, is_stable
from quadctl.batch import care as care_stacked
from quadctl.decouple import Decoupled
from quadctl.errors import DesignError
from quadctl.layout import INPUT_INDEX, N_INPUTS, N_STATES, STATE_NAMES

scipy = lazy_import("scipy")  # loaded on first use (then scipy.linalg on access): quadctl._lazy

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


NEWTON_REFINEMENTS = 2
"""Newton-Kleinman steps :func:`lqr` takes when SciPy's solution misses ``RICCATI_RTOL``: each
solves one Lyapunov equation and squares the error (seen: a mode at -7e-7 rad/s left SciPy's
Schur solution at 6e-8; one step took it to 1.6e-10)."""


def _refine(A, B, Q, R, P):
    """``(P, K, E, residual)`` of a CARE solution, refined by Newton-Kleinman while the residual
    exceeds ``RICCATI_RTOL`` and the closed loop is stable (the condition for a Newton step)."""
    for step in range(NEWTON_REFINEMENTS + 1):
        K = np.linalg.solve(R, B.T @ P)
        closed = A - B @ K
        E = np.linalg.eigvals(closed)
        residual = riccati_residual(A, B, Q, R, P)
        if residual <= RICCATI_RTOL or step == NEWTON_REFINEMENTS or not all(is_stable(e) for e in E):
            return P, K, E, residual
        P_new = scipy.linalg.solve_continuous_lyapunov(closed.T, -(Q + K.T @ R @ K))
        if not np.all(np.isfinite(P_new)):
            return P, K, E, residual
        P = (P_new + P_new.T) / 2


def lqr(A, B, Q, R, *, name: str = "system", state_names=None) -> LqrResult:
    """Continuous-time LQR (MATLAB ``lqr``).

    Solved by :func:`quadctl.batch.care` (stable Hamiltonian eigenvectors, then Newton-Kleinman
    to round-off); where that has no answer within ``RICCATI_RTOL`` and a stable loop, by
    ``scipy.linalg.solve_continuous_are`` (balanced, then unbalanced, then Newton-refined). Both
    are residual-checked; they agree to round-off (``tests/test_core_design.py``).

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
    _check_shapes(A, B, Q, R, name)
    require_stabilizable(A, B, name, state_names)
    # quadctl's own solver first (eigenvectors and Newton-Kleinman, numpy only, residual-checked:
    # a design needs no SciPy import); SciPy's Schur solver where it has no answer
    own = care_stacked(A[None], B[None], Q[None], R[None])
    if own.ok[0]:
        return LqrResult(K=own.K[0], P=own.P[0], E=own.E[0], residual=float(own.residual[0]))
    # SciPy balances the Hamiltonian first; entries near the underflow limit can spoil that
    # balancing (seen: a 5.6e-301 entry gave residual 0.5), so an inaccurate answer is retried
    # without it. The verdict comes from the best of the answers, not the last.
    answers, failure = [], None
    for balanced in (True, False):
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                P = scipy.linalg.solve_continuous_are(A, B, Q, R, balanced=balanced)
        except (np.linalg.LinAlgError, ValueError) as exc:  # balancing itself can overflow
            failure = exc
            continue
        if not np.all(np.isfinite(P)):
            continue
        P, K, E, residual = _refine(A, B, Q, R, (P + P.T) / 2)
        stable = all(is_stable(e) for e in E)
        if residual <= RICCATI_RTOL and stable:
            return LqrResult(K=K, P=P, E=E, residual=residual)
        answers.append((not stable, residual, E))
    if not answers:
        if failure is not None:
            raise DesignError(f"{name}: the Riccati solve failed ({failure}); "
                              "check that Q makes every unstable mode visible (detectable)")
        raise DesignError(f"{name}: the Riccati solution is not finite; check the weights")
    unstable, residual, E = min(answers, key=lambda a: (a[0], a[1]))
    if unstable:
        raise DesignError(
            f"{name}: the Riccati solution is not stabilizing (residual {residual:.1e}); "
            "an unstable or marginal mode is invisible to Q: give weight to the states it lives in")
    slowest = E[int(np.argmin(np.abs(E.real)))]
    raise DesignError(
        f"{name}: the Riccati equation is too ill-conditioned to solve to {RICCATI_RTOL:g} "
        f"(residual {residual:.1e}); its slowest closed-loop mode is at {slowest.real:.3g} rad/s: "
        "weight the states of that mode, or rescale units so the entries of A, B, Q, R are comparable")


def _check_shapes(A, B, Q, R, name: str) -> None:
    """``A`` (n, n), ``B`` (n, m), ``Q`` (n, n), ``R`` (m, m), or a DesignError naming the matrix."""
    n, m = A.shape[0], B.shape[1] if B.ndim == 2 else 0
    for label, M, shape in (("A", A, (n, n)), ("B", B, (n, m)), ("Q", Q, (n, n)), ("R", R, (m, m))):
        if M.shape != shape:
            raise DesignError(f"{name}: {label} has shape {M.shape}, expected {shape} "
                              f"(A is n x n, B n x m, Q n x n, R m x m with n = {n}, m = {m})")


def require_stabilizable(A, B, name: str, state_names=None) -> None:
    """Raise DesignError naming the first unstable mode no input reaches (PBH)."""
    checks = check(A, B, names=state_names)
    if not checks.stabilizable:
        mode = checks.unstabilizable_modes[0]
        raise DesignError(
            f"{name}: not stabilizable: the mode at eigenvalue {_fmt_eig(mode.eigenvalue)} "
            f"(in {', '.join(mode.states)}) is unstable and no input reaches it; "
            "change the partition so an input drives those states")


@dataclass(frozen=True)
class SubsystemDesign:
    """LQR of one regulated subsystem.

    ``K`` is the state gain (m, n). With integral action, ``Ki`` (m, ni) is the gain on the
    integrators of ``integral`` and ``Q``, ``P`` are those of the augmented ``[x; z]``. For a
    discrete design, ``eigenvalues`` are the ``s``-equivalents ``ln(z) / Ts`` of ``eigenvalues_z``.
    """

    name: str
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    Q: np.ndarray
    R: np.ndarray
    K: np.ndarray
    P: np.ndarray
    eigenvalues: np.ndarray
    residual: float
    integral: tuple[str, ...] = ()
    Ki: np.ndarray | None = None
    eigenvalues_z: np.ndarray | None = None


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
        Every other eigenvalue of the coupled closed loop is in the open left half-plane
        (inside the unit circle for a discrete design).
    rate : float or None
        Hz of a discrete design (``lqrd`` at ``1 / rate``); None for a continuous one.
    Ki_block : (4, nz) ndarray
        ``u -= Ki_block z``: the integrator gains, one column per entry of ``integral_states``.
    integral_states : tuple of str
        The state each integrator integrates (``dz/dt = -(x_s - x_ref,s)``).
    full_eigenvalues_z : ndarray or None
        A discrete design's coupled eigenvalues ``z``; ``full_eigenvalues`` then holds ``ln(z) / Ts``.
    """

    subsystems: tuple[SubsystemDesign, ...]
    K_block: np.ndarray
    Q_block: np.ndarray
    R_block: np.ndarray
    full_eigenvalues: np.ndarray
    marginal_states: tuple[str, ...]
    stable: bool
    rate: float | None = None
    Ki_block: np.ndarray = field(default_factory=lambda: np.zeros((N_INPUTS, 0)))
    integral_states: tuple[str, ...] = ()
    full_eigenvalues_z: np.ndarray | None = None
    core_eigenvalues: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    """``full_eigenvalues`` without the marginal modes (:mod:`quadctl.stability`): what ``stable`` is about."""

    @property
    def sample_time(self) -> float | None:
        """s between controller samples (None: continuous)."""
        return None if self.rate is None else 1.0 / self.rate

    def __getitem__(self, name: str) -> SubsystemDesign:
        for sub in self.subsystems:
            if sub.name == name:
                return sub
        raise KeyError(name)


def design(decoupled: Decoupled, A, B, weights: dict, *, rate: float | None = None,
           integral: dict | None = None) -> Design:
    """LQR per regulated subsystem, assembled into a block gain and checked on ``(A, B)``.

    Parameters
    ----------
    decoupled : Decoupled
    A : (12, 12) array_like
        The full coupled model the block gain is checked on.
    B : (12, 4) array_like
    weights : dict
        ``subsystem name -> (Q, R)`` as (n, n) and (m, m) arrays; with integral action ``Q`` is
        (n + ni, n + ni), weighing ``[states; integrals]``.
    rate : float, optional
        Hz. Given: a discrete design at ``Ts = 1 / rate`` (MATLAB ``lqrd``: ZOH plant, weights
        integrated over a sample), checked on the ZOH discretization of ``(A, B)``.
    integral : dict, optional
        ``subsystem name -> states`` to integrate (LQI); see :mod:`quadctl.integral`.

    Returns
    -------
    Design

    Raises
    ------
    DesignError
        A subsystem is not stabilizable or its Riccati solve fails.
    """
    Ts = None if rate is None else 1.0 / rate
    integral = integral or {}
    K_block = np.zeros((N_INPUTS, N_STATES))
    Q_block = np.zeros((N_STATES, N_STATES))
    R_block = np.zeros((N_INPUTS, N_INPUTS))
    ki_columns: list[np.ndarray] = []
    integral_states: list[str] = []
    subs = []
    for sub in decoupled.regulated:
        Q, R = (np.atleast_2d(np.asarray(m, dtype=float)) for m in weights[sub.name])
        ints = tuple(integral.get(sub.name, ()))
        K, Ki, P, eig_s, eig_z, residual = _solve_subsystem(sub, Q, R, ints, Ts)
        rows = [INPUT_INDEX[i] for i in sub.inputs]
        cols = sub.state_index
        n = len(cols)
        K_block[np.ix_(rows, cols)] = K
        Q_block[np.ix_(cols, cols)] = Q[:n, :n]
        R_block[np.ix_(rows, rows)] = R
        for j, state in enumerate(ints):
            column = np.zeros(N_INPUTS)
            column[rows] = Ki[:, j]
            ki_columns.append(column)
            integral_states.append(state)
        subs.append(SubsystemDesign(name=sub.name, states=sub.states, inputs=sub.inputs, Q=Q, R=R,
                                    K=K, P=P, eigenvalues=eig_s, residual=residual, integral=ints,
                                    Ki=Ki if ints else None, eigenvalues_z=eig_z))
    Ki_block = np.array(ki_columns).T.reshape(N_INPUTS, len(ki_columns))
    A_cl = closed_loop_matrix(A, B, K_block, Ki_block, tuple(integral_states), Ts)
    verdict = stability.assess(A_cl, K_block, sample_time=Ts)
    return Design(subsystems=tuple(subs), K_block=K_block, Q_block=Q_block, R_block=R_block,
                  full_eigenvalues=verdict.eigenvalues, marginal_states=verdict.marginal, stable=verdict.stable,
                  rate=rate, Ki_block=Ki_block, integral_states=tuple(integral_states),
                  full_eigenvalues_z=verdict.eigenvalues_z, core_eigenvalues=verdict.core)


def _solve_subsystem(sub, Q, R, ints, Ts):
    """(K, Ki, P, eigenvalues s, eigenvalues z or None, residual) of one subsystem."""
    n = len(sub.states)
    C = integral.selector(sub.states, ints)
    names = [*sub.states, *(f"integral of {s}" for s in ints)]
    label = f"subsystem {sub.name}"
    Aa, Ba = integral.augment(sub.A, sub.B, C)
    if Ts is None:
        res = lqr(Aa, Ba, Q, R, name=label, state_names=names)
        eig_s, eig_z = res.E, None
    else:
        require_stabilizable(Aa, Ba, label, names)
        Ad, Bd, Qd, Rd, Nd = discrete.lqrd_weights(sub.A, sub.B, Q[:n, :n], R, Ts)
        Ada, Bda = integral.augment_discrete(Ad, Bd, C, Ts)
        Qda, Nda = integral.discrete_weights(Qd, Nd, Q, Ts)
        res = discrete.dlqr(Ada, Bda, Qda, Rd, Nda, name=label)
        eig_z = res.E
        eig_s = discrete.s_equivalent(eig_z, Ts)
    return res.K[:, :n], res.K[:, n:], res.P, eig_s, eig_z, res.residual


def closed_loop_matrix(A, B, K, Ki=None, integral_states=(), sample_time=None) -> np.ndarray:
    """The coupled closed loop of ``[x; z]`` under ``u = -K x - Ki z`` (deviations from trim).

    Continuous: ``[[A - B K, -B Ki], [-C, 0]]``. With ``sample_time`` (a discrete controller on
    the ZOH plant): ``[[Ad - Bd K, -Bd Ki], [-Ts C, I]]``. ``C`` selects ``integral_states``.
    """
    A, B, K = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (A, B, K))
    nz = len(integral_states)
    Ki = np.zeros((B.shape[1], 0)) if Ki is None else np.asarray(Ki, dtype=float).reshape(B.shape[1], nz)
    C = integral.selector(STATE_NAMES, integral_states)
    if sample_time is None:
        top = np.hstack([A - B @ K, -B @ Ki])
        bottom = np.hstack([-C, np.zeros((nz, nz))])
    else:
        Ad, Bd = discrete.c2d(A, B, sample_time)
        top = np.hstack([Ad - Bd @ K, -Bd @ Ki])
        bottom = np.hstack([-sample_time * C, np.eye(nz)])
    return np.vstack([top, bottom])


def _fmt_eig(e: complex) -> str:
    return f"{e.real:.4g}" if abs(e.imag) < 1e-12 else f"{e.real:.4g}{e.imag:+.4g}j"
