"""LQR gains from the continuous algebraic Riccati equation, per subsystem and assembled.

MATLAB ``lqr`` conventions: ``u = -K x``, ``K = R^-1 B^T P``, ``P`` the stabilizing solution of
``A^T P + P A - P B R^-1 B^T P + Q = 0``. The Riccati solvers, the weight checks and the refusals
live in :mod:`quadctl.design.riccati`; :func:`lqr` is its one-case continuous entry point.

With a controller rate, :func:`design` solves the discrete problem instead (MATLAB ``lqrd``, see
:mod:`quadctl.design.discrete`); with ``integral`` states, each subsystem is augmented with their
integrals first (MATLAB ``lqi``, see :mod:`quadctl.design.integral`). With a rotor time constant
(``controller.rotor_lag: include``), each subsystem is first augmented with the lag of its inputs
(:mod:`quadctl.design.lag`): the gain then also feeds back the achieved virtual inputs ``v``, ``u = -K x -
Kv (v - u_trim) - Ki z``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from quadctl.design import discrete, integral, lag, linear_loop, stacked
from quadctl.design.riccati import LqrResult, real_array, require_stabilizable, solve
from quadctl.layout import INPUT_INDEX, N_INPUTS, N_STATES
from quadctl.linear import stability
from quadctl.linear.decouple import Decoupled


def lqr(A, B, Q, R, N=None, *, name: str = "system", state_names=None) -> LqrResult:
    """Continuous-time LQR (MATLAB ``lqr``): ``u = -K x`` minimizing ``integral x'Qx + u'Ru + 2 x'Nu dt``.

    ``K = R^-1 (B'P + N')``, ``P`` the stabilizing solution of
    ``A'P + PA - (PB + N) R^-1 (B'P + N') + Q = 0``. Solved by :func:`quadctl.design.riccati.solve`:
    weights validated; quadctl's own residual-checked solver first (stable Hamiltonian
    eigenvectors and Newton-Kleinman, numpy only, up to ``KRONECKER_MAX_N`` states; Laub's Schur
    method and Bartels-Stewart Newton steps above, several times faster than SciPy), SciPy's
    ``solve_continuous_are`` where it has no answer within ``RICCATI_RTOL`` and a stable loop.

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    Q : (n, n) array_like
        Symmetric positive semidefinite state weight.
    R : (m, m) array_like
        Symmetric positive definite input weight.
    N : (n, m) array_like, optional
        Cross weight; ``[[Q, N], [N', R]]`` positive semidefinite.
    name : str
        Names the system in errors.
    state_names : sequence of str, optional
        Names the states of a refused mode in errors.

    Returns
    -------
    LqrResult
        ``K`` (m, n), ``P`` (n, n), ``E`` (n,) closed-loop eigenvalues (rad/s), ``residual``.

    Raises
    ------
    DesignError
        Invalid weights (the matrix and what is wrong are named), ``(A, B)`` not stabilizable
        (the mode is named), a marginal mode invisible to ``Q``, or an ill-conditioned equation.
    ArgumentError
        A matrix that is not real numbers (complex, text, None, ragged), of a shape that does not fit
        the others, or a problem with no state or no input (the matrix is named; a ``ValueError``).

    Examples
    --------
    A scalar integrator ``x' = u`` with ``Q = q``, ``R = r`` has ``P = sqrt(q r)``, ``K = sqrt(q / r)``:

    >>> K, P, E = lqr([[0.0]], [[1.0]], [[4.0]], [[1.0]])
    >>> round(float(K[0, 0]), 12), round(float(P[0, 0]), 12), complex(np.round(E[0], 12))
    (2.0, 2.0, (-2+0j))
    """
    return solve(A, B, Q, R, N, name=name, state_names=state_names)


@dataclass(frozen=True, eq=False)
class SubsystemDesign:
    """LQR of one regulated subsystem.

    ``K`` is the state gain (m, n). With integral action, ``Ki`` (m, ni) is the gain on the
    integrators of ``integral`` and ``Q``, ``P`` are those of the augmented ``[x; z]``. For a
    discrete design, ``eigenvalues`` are the ``s``-equivalents ``ln(z) / Ts`` of ``eigenvalues_z``.
    A design with the rotors' lag has ``Kv`` (m, m), the gain on the lag states ``v`` of the inputs
    (:mod:`quadctl.design.lag`); ``Q``, ``P`` are then those of ``[x; v; z]`` (``Q`` zero on ``v``).
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
    Kv: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
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
    Kv_block : (4, 4) ndarray
        ``u -= Kv_block (v - u_trim)``: the gain on the rotors' lag states, the achieved virtual
        inputs ``v`` (zero unless the design includes the lag).
    lag_time_constant : float or None
        s of the rotors' lag the design model includes (``controller.rotor_lag: include``); None:
        instantaneous rotors. With it, ``full_eigenvalues`` are those of ``[x; v; z]``.

    Examples
    --------
    >>> import quadctl as qc
    >>> design = qc.Stages(qc.setup_of(qc.load_config("hover"))).design
    >>> design.K_block.shape, design.stable, [s.name for s in design.subsystems]
    ((4, 12), True, ['altitude', 'roll', 'pitch', 'yaw'])
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
    """``full_eigenvalues`` without the marginal modes (:mod:`quadctl.linear.stability`): what ``stable`` is about."""
    Kv_block: np.ndarray = field(default_factory=lambda: np.zeros((N_INPUTS, N_INPUTS)))
    lag_time_constant: float | None = None

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
           integral: dict | None = None, lag_time_constant: float | None = None) -> Design:
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
        ``subsystem name -> states`` to integrate (LQI); see :mod:`quadctl.design.integral`.
    lag_time_constant : float, optional
        s. Given: every subsystem's inputs lag through ``1 / (tau s + 1)`` in the design model
        (:func:`quadctl.design.lag.lagged`; ZOH of that for a discrete design), and the gain feeds back the
        lag states too (``Kv``); the coupled check is on the lagged ``(A, B)``.

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
    Kv_block = np.zeros((N_INPUTS, N_INPUTS))
    Q_block = np.zeros((N_STATES, N_STATES))
    R_block = np.zeros((N_INPUTS, N_INPUTS))
    ki_columns: list[np.ndarray] = []
    integral_states: list[str] = []
    subs = []
    for sub in decoupled.regulated:
        Q, R = (np.atleast_2d(np.asarray(m, dtype=float)) for m in weights[sub.name])
        ints = tuple(integral.get(sub.name, ()))
        K, Kv, Ki, P, eig_s, eig_z, residual = solve_subsystem(sub, Q, R, ints, Ts, lag_time_constant)
        rows = [INPUT_INDEX[i] for i in sub.inputs]
        if Kv is not None:
            Kv_block[np.ix_(rows, rows)] = Kv
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
        subs.append(SubsystemDesign(name=sub.name, states=sub.states, inputs=sub.inputs,
                                    Q=_lag_weight(Q, n, 0 if Kv is None else Kv.shape[1]), R=R,
                                    K=K, P=P, eigenvalues=eig_s, residual=residual, integral=ints,
                                    Ki=Ki if ints else None, eigenvalues_z=eig_z, Kv=Kv))
    Ki_block = np.array(ki_columns).T.reshape(N_INPUTS, len(ki_columns))
    A_cl = linear_loop.matrix(A, B, K_block, Ki_block, tuple(integral_states), Ts,
                              Kv=Kv_block if lag_time_constant is not None else None,
                              lag_time_constant=lag_time_constant)
    verdict = stability.assess(A_cl, K_block, sample_time=Ts)
    return Design(subsystems=tuple(subs), K_block=K_block, Q_block=Q_block, R_block=R_block,
                  full_eigenvalues=verdict.eigenvalues, marginal_states=verdict.marginal, stable=verdict.stable,
                  rate=rate, Ki_block=Ki_block, integral_states=tuple(integral_states),
                  full_eigenvalues_z=verdict.eigenvalues_z, core_eigenvalues=verdict.core,
                  Kv_block=Kv_block, lag_time_constant=lag_time_constant)


def solve_subsystem(sub, Q, R, ints, Ts, tau=None):
    """(K, Kv or None, Ki, P, eigenvalues s, eigenvalues z or None, residual) of one subsystem.

    Solved as a stack of one by :func:`quadctl.design.stacked.solve_subsystems`, the engine a sweep's
    designs take too; where its answer is not certified, :func:`_certified_or_refused` asks the
    one-case Riccati solver for SciPy's answer to the same problem, or the reason there is none.
    """
    label = f"subsystem {sub.name}"
    size = len(sub.states) + len(ints)
    Q = real_array(Q, "Q", name=label, ndim=2, shape=(size, size))
    R = real_array(R, "R", name=label, ndim=2, shape=(sub.B.shape[1],) * 2)
    sol = stacked.solve_subsystems(sub.A[None], sub.B[None], Q[None], R[None], integral.selector(sub.states, ints),
                                   Ts, lag_time_constant=tau)
    if not sol.ok[0]:
        sol = _certified_or_refused(sub, sol, ints, Ts, tau)
    return (sol.K[0], None if sol.Kv is None else sol.Kv[0], sol.Ki[0], sol.P[0], sol.eigenvalues[0],
            None if sol.eigenvalues_z is None else sol.eigenvalues_z[0], float(sol.residual[0]))


def _certified_or_refused(sub, sol, ints, Ts, tau=None) -> stacked.SubsystemSolutions:
    """The problem the engine posed (``sol.problem``, a stack of one) by the one-case Riccati solver
    (:func:`quadctl.design.riccati.solve`): SciPy's certified answer, or the
    :class:`~quadctl.errors.DesignError` that names the reason (for a discrete design, first a mode no
    input reaches in the continuous plant, or a sampled problem that overflows)."""
    n, m = sub.B.shape
    nl = m if tau is not None else 0
    lags = (f"lag of {i}" for i in sub.inputs) if nl else ()  # (the full design's plant has no inputs named)
    names = [*sub.states, *lags, *(f"integral of {s}" for s in ints)]
    label = f"subsystem {sub.name}"
    problem = [M[0] for M in sol.problem]
    if Ts is not None:
        A, B = lag.lagged(sub.A, sub.B, tau)
        C = np.hstack([integral.selector(sub.states, ints), np.zeros((len(ints), nl))])
        require_stabilizable(*integral.augment(A, B, C), label, names)
        if not all(np.all(np.isfinite(M)) for M in problem):
            raise discrete.overflow(label, Ts)
    res = solve(*problem, discrete=Ts is not None, name=label, state_names=names)
    eig_z = None if Ts is None else res.E
    K = res.K[None]
    return replace(sol, gain=K, K=K[:, :, :n], Kv=K[:, :, n:n + nl] if nl else None, Ki=K[:, :, n + nl:],
                   P=res.P[None], eigenvalues=(res.E if Ts is None else discrete.s_equivalent(eig_z, Ts))[None],
                   eigenvalues_z=None if eig_z is None else eig_z[None], residual=np.array([res.residual]),
                   ok=np.ones(1, dtype=bool))


def _lag_weight(Q, n: int, nl: int) -> np.ndarray:
    """``Q`` of ``[x; z]`` as the weight of ``[x; v; z]``: zero rows and columns for the ``nl`` lag states."""
    if not nl:
        return Q
    keep = [*range(n), *range(n + nl, Q.shape[0] + nl)]
    out = np.zeros((Q.shape[0] + nl,) * 2)
    out[np.ix_(keep, keep)] = Q
    return out
