"""The LQR of decoupled subsystems, one case or many: one engine, a case is a stack of one.

:func:`solve_subsystems` solves a stack of same-shape subsystem problems at once: the rotors' lag
(:mod:`quadctl.design.lag`) and the integrators (:mod:`quadctl.design.integral`) augmented, the ZOH
plant and ``lqrd`` weights for a discrete design (:mod:`quadctl.design.discrete`), the CARE or DARE
batched (:func:`~quadctl.design.riccati.care_batch`, :func:`~quadctl.design.riccati.dare_batch`),
each answer residual-checked. An entry without a certified answer is marked not ok, never raised:
the one-case design (:func:`quadctl.design.design`) solves its one problem here and, where it is not
ok, asks :func:`quadctl.design.riccati.solve` for SciPy's answer or the named reason.
:func:`solve_problems` groups stacks of many cases' subsystem problems by shape for it, :func:`block_gains`
assembles the subsystems' gains into the (4, 12) block gains, :func:`coupled_verdicts` checks them
on the coupled model (a sweep's designs, :func:`quadctl.sweep.batched.design_all`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.design import discrete, integral, linear_loop
from quadctl.design.riccati import care_batch, dare_batch
from quadctl.layout import INPUT_INDEX, N_INPUTS, N_STATES
from quadctl.linear import stability


@dataclass(frozen=True)
class SubsystemSolutions:
    """``N`` solutions of same-shape subsystem problems (:func:`solve_subsystems`).

    Attributes
    ----------
    gain : (N, m, n + nl + ni) ndarray
        The whole gain on ``[x; v; z]``: ``K``, ``Kv``, ``Ki`` side by side.
    K : (N, m, n) ndarray
        On the subsystem's states.
    Kv : (N, m, m) ndarray or None
        On the lag states ``v`` (a design with the rotors' lag), else None.
    Ki : (N, m, ni) ndarray
        On the integrators.
    Q : (N, n + nl + ni, n + nl + ni) ndarray
        The continuous weight of ``[x; v; z]`` (zero on ``v``).
    P : (N, n + nl + ni, n + nl + ni) ndarray
        The Riccati solutions (of the sampled problem for a discrete design).
    eigenvalues : (N, n + nl + ni) complex ndarray
        rad/s: of the closed loop, or the ``s``-equivalents ``ln(z) / Ts`` of ``eigenvalues_z``.
    eigenvalues_z : (N, n + nl + ni) complex ndarray or None
        A discrete design's closed-loop eigenvalues ``z``.
    residual : (N,) ndarray
        Relative Riccati residuals.
    ok : (N,) bool ndarray
        Certified: valid weights, a finite sampled problem, a residual within ``RICCATI_RTOL`` and
        a stable loop.
    problem : tuple of ndarray
        The Riccati problems solved, ``(A, B, Q, R, N)`` of the augmented (and sampled) plants:
        for the one-case design to hand an entry that is not ok to the one-case solver.
    """

    gain: np.ndarray
    K: np.ndarray
    Kv: np.ndarray | None
    Ki: np.ndarray
    Q: np.ndarray
    P: np.ndarray
    eigenvalues: np.ndarray
    eigenvalues_z: np.ndarray | None
    residual: np.ndarray
    ok: np.ndarray
    problem: tuple = ()


def solve_subsystems(A, B, Q, R, C=None, sample_time: float | None = None, *, plant_of=None,
                     lag_time_constant: float | None = None, weight_maps=None,
                     compiled: bool = False) -> SubsystemSolutions:
    """LQR (MATLAB ``lqr``, ``lqi``; ``lqrd`` with a sample time) of ``N`` same-shape subsystem problems at once.

    Parameters
    ----------
    A : (P, n, n) array_like
    B : (P, n, m) array_like
        The distinct continuous plants the problems are posed on.
    Q : (N, n + ni, n + ni) array_like
        Each problem's continuous weight of ``[x; z]`` (the config's).
    R : (N, m, m) array_like
    C : (ni, n) or (N, ni, n) array_like, optional
        Selects the integrated states (:func:`quadctl.design.integral.selector`); None: none.
    sample_time : float, optional
        s: a discrete design, the ZOH plant and the cost integrated over a sample (``lqrd``).
    plant_of : (N,) array_like of int, optional
        The plant each problem is on; default: the one plant (``P = 1``) or one each (``P = N``).
    lag_time_constant : float, optional
        s: the inputs lag through ``1 / (tau s + 1)`` (:func:`quadctl.design.lag.lagged`), the gain
        feeds back the lag states too; ``Q`` is zero on them.
    weight_maps : sequence of LqrdWeightMap, optional
        Per plant, its :class:`~quadctl.design.discrete.LqrdWeightMap` at ``sample_time`` (of the
        lagged plant with a lag): the sampled weights by a matrix product, where a sweep keeps the
        maps of its plants. None: one Van Loan exponential per problem.
    compiled : bool
        The DARE's doubling steps in C (:func:`~quadctl.design.riccati.dare_batch`).

    Returns
    -------
    SubsystemSolutions

    Examples
    --------
    Scalar integrators ``x' = u``, one case or three: ``K = sqrt(q / r)``.

    >>> sol = solve_subsystems([[[0.0]]], [[[1.0]]], [[[4.0]], [[9.0]], [[16.0]]], [[[1.0]]] * 3)
    >>> sol.K.ravel().round(12).tolist(), sol.ok.tolist()
    ([2.0, 3.0, 4.0], [True, True, True])
    """
    A, B, Q, R = (np.asarray(M, dtype=float) for M in (A, B, Q, R))
    N, (n, m) = len(Q), B.shape[1:]
    C = np.zeros((0, n)) if C is None else np.asarray(C, dtype=float)
    if plant_of is None:
        plant_of = np.zeros(N, dtype=int) if len(A) == 1 else np.arange(N)
    plant_of = np.asarray(plant_of, dtype=int)
    nl = 0
    if lag_time_constant is not None:
        A, B = _lagged(A, B, lag_time_constant)
        nl = m
        Q = _lag_weight(Q, n, nl)
        C = np.concatenate([C, np.zeros((*C.shape[:-1], nl))], axis=-1)
    nx = n + nl  # the plant's states: [x; v]
    ok = np.ones(N, dtype=bool)
    if sample_time is None:
        Aa, Ba = integral.augment(_rows(A, plant_of), _rows(B, plant_of), C)
        problem = (Aa, Ba, Q, R, np.zeros((N, *Ba.shape[1:])))
        res = care_batch(*problem)
        eig_s, eig_z = res.E, None
    else:
        Ad, Bd, Qd, Rd, Nd = _sampled(A, B, Q[:, :nx, :nx], R, sample_time, plant_of, weight_maps)
        ok = np.all(np.isfinite(Qd), axis=(1, 2)) & np.all(np.isfinite(Ad), axis=(1, 2))
        Aa, Ba = integral.augment_discrete(Ad, Bd, C, sample_time)
        Qa, Na = integral.discrete_weights(Qd, Nd, Q, sample_time)
        problem = (Aa, Ba, Qa, Rd, Na)
        res = dare_batch(*problem, compiled=compiled)
        eig_z = res.E
        eig_s = discrete.s_equivalent(eig_z, sample_time)
    K = res.K
    return SubsystemSolutions(gain=K, K=K[:, :, :n], Kv=K[:, :, n:nx] if nl else None, Ki=K[:, :, nx:], Q=Q,
                              P=res.P, eigenvalues=eig_s, eigenvalues_z=eig_z, residual=res.residual,
                              ok=ok & res.ok, problem=problem)


def _rows(M, plant_of):
    """Each problem's plant matrix: the one plant broadcast (no copy), else one row per problem."""
    return np.broadcast_to(M, (len(plant_of), *M.shape[1:])) if len(M) == 1 else M[plant_of]


def _lagged(A, B, tau: float):
    """:func:`quadctl.design.lag.lagged` of stacked plants: ``[[A, B], [0, -I / tau]]``, ``[[0], [I / tau]]``."""
    P, n, m = B.shape
    Al = np.zeros((P, n + m, n + m))
    Al[:, :n, :n], Al[:, :n, n:] = A, B
    Al[:, n:, n:] = -np.eye(m) / tau
    Bl = np.zeros((P, n + m, m))
    Bl[:, n:] = np.eye(m) / tau
    return Al, Bl


def _lag_weight(Q, n: int, nl: int) -> np.ndarray:
    """Stacked ``Q`` of ``[x; z]`` as the weight of ``[x; v; z]``: zero rows and columns for the ``nl`` lag states."""
    keep = [*range(n), *range(n + nl, Q.shape[-1] + nl)]
    out = np.zeros((len(Q), Q.shape[-1] + nl, Q.shape[-1] + nl))
    out[np.ix_(range(len(Q)), keep, keep)] = Q
    return out


def _sampled(A, B, Q, R, Ts: float, plant_of, weight_maps):
    """``(Ad, Bd, Qd, Rd, Nd)`` of each problem (``lqrd``): by its plant's weight map, or one exponential each."""
    if weight_maps is None:
        with np.errstate(all="ignore"):  # a plant sampled for hours overflows: not ok, the one-case design says so
            return discrete.lqrd_weights_batch(_rows(A, plant_of), _rows(B, plant_of), Q, R, Ts)
    N, n, m = len(Q), Q.shape[1], R.shape[1]
    Ad, Bd = np.empty((N, n, n)), np.empty((N, n, m))
    Qd, Rd, Nd = np.empty((N, n, n)), np.empty((N, m, m)), np.empty((N, n, m))
    if len(weight_maps) == 1:
        Ad[:], Bd[:] = weight_maps[0].Ad, weight_maps[0].Bd
        Qd[:], Rd[:], Nd[:] = weight_maps[0].weights(Q, R)
        return Ad, Bd, Qd, Rd, Nd
    for p, weight_map in enumerate(weight_maps):
        rows = np.flatnonzero(plant_of == p)
        Ad[rows], Bd[rows] = weight_map.Ad, weight_map.Bd
        Qd[rows], Rd[rows], Nd[rows] = weight_map.weights(Q[rows], R[rows])
    return Ad, Bd, Qd, Rd, Nd


def solve_problems(blocks, *, weight_map=None, compiled: bool = False) -> list[tuple[np.ndarray, np.ndarray]]:
    """Stacks of subsystem problems, grouped by shape and sample time, each group one :func:`solve_subsystems`.

    Parameters
    ----------
    blocks : sequence of (Subsystem, Q, R, integral, sample_time)
        A regulated subsystem (:class:`~quadctl.linear.decouple.Subsystem`: its ``A``, ``B`` and states),
        a stack of weights of ``[x; z]`` posed on it, Q (k, n + ni, n + ni) and R (k, m, m), the
        states it integrates and the design's sample time (s, or None). Blocks of one shape on
        several plants are solved in one stack; blocks on one subsystem object share its plant
        (and its weight map).
    weight_map : callable, optional
        ``weight_map(subsystem, sample_time)``: the :class:`~quadctl.design.discrete.LqrdWeightMap`
        of the subsystem's plant, for a caller that keeps them; None: each problem sampled alone.
    compiled : bool
        The DARE's doubling steps in C.

    Returns
    -------
    list of (gain (k, m, n + ni) ndarray, ok (k,) bool ndarray)
        Per block, its gains on ``[x; z]`` and which are certified (the one-case design says why
        the others are not).
    """
    groups: dict[tuple, list[int]] = {}
    for b, (sub, _, _, ints, Ts) in enumerate(blocks):
        groups.setdefault((Ts, len(sub.states), len(sub.inputs), len(ints)), []).append(b)
    out: list = [None] * len(blocks)
    for (Ts, *_), members in groups.items():
        subs: dict[int, int] = {}  # a subsystem object -> its plant's number
        plants, plant_of = [], []
        for b in members:
            sub = blocks[b][0]
            if id(sub) not in subs:
                subs[id(sub)] = len(plants)
                plants.append(sub)
            plant_of.append(np.full(len(blocks[b][1]), subs[id(sub)]))
        first_sub, first_ints = blocks[members[0]][0], blocks[members[0]][3]
        if all(blocks[b][3] == first_ints and blocks[b][0].states == first_sub.states for b in members):
            C = integral.selector(first_sub.states, first_ints)
        else:  # integrators on different states: one shape still, a selector each
            C = np.concatenate([np.repeat(integral.selector(blocks[b][0].states, blocks[b][3])[None],
                                          len(blocks[b][1]), axis=0) for b in members])
        maps = None if Ts is None or weight_map is None else [weight_map(sub, Ts) for sub in plants]
        one = len(members) == 1
        sol = solve_subsystems(np.stack([sub.A for sub in plants]), np.stack([sub.B for sub in plants]),
                               blocks[members[0]][1] if one else np.concatenate([blocks[b][1] for b in members]),
                               blocks[members[0]][2] if one else np.concatenate([blocks[b][2] for b in members]),
                               C, Ts, plant_of=np.concatenate(plant_of), weight_maps=maps, compiled=compiled)
        start = 0
        for b in members:
            stop = start + len(blocks[b][1])
            out[b] = (sol.gain[start:stop], sol.ok[start:stop])
            start = stop
    return out


def block_gains(regulated, integrators, gains) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """``N`` decoupled designs' subsystem gains assembled: ``u = u_trim - K (x - x_trim) - Ki z``.

    Parameters
    ----------
    regulated : sequence of Subsystem
        The regulated subsystems of one partition.
    integrators : sequence of tuple of str
        Per subsystem, the states it integrates.
    gains : sequence of (N, m, n + ni) array_like
        Per subsystem, the stack of its gains on ``[x; z]``.

    Returns
    -------
    K : (N, 4, 12) ndarray
    Ki : (N, 4, nz) ndarray
        One column per integrator, in the subsystems' order.
    integral_states : tuple of str
    """
    N = len(gains[0]) if len(gains) else 0
    states = tuple(state for ints in integrators for state in ints)
    K = np.zeros((N, N_INPUTS, N_STATES))
    Ki = np.zeros((N, N_INPUTS, len(states)))
    column = 0
    for sub, ints, gain in zip(regulated, integrators, gains):
        n = len(sub.states)
        rows = [INPUT_INDEX[i] for i in sub.inputs]
        K[np.ix_(range(N), rows, sub.state_index)] = gain[:, :, :n]
        Ki[:, rows, column:column + len(ints)] = gain[:, :, n:]
        column += len(ints)
    return K, Ki, states


def coupled_verdicts(A, B, K, Ki, integral_states, sample_time: float | None = None, *, any_order: bool = False):
    """Stacked block gains checked on the coupled model (:func:`quadctl.linear.stability.verdict_stack`).

    Parameters
    ----------
    A : (12, 12) array_like
    B : (12, 4) array_like
        The coupled plant, continuous, or its ZOH at ``sample_time`` (held already).
    K : (N, 4, 12) array_like
    Ki : (N, 4, nz) array_like
    integral_states : sequence of str
    sample_time : float, optional
        s.
    any_order : bool
        Each ``core`` in any order (for a caller that reads only its extremes).

    Returns
    -------
    list of (core, marginal, stable)
    """
    A_cl = linear_loop.stack(A, B, K, Ki, integral_states, sample_time)
    return stability.verdict_stack(A_cl, K, sample_time=sample_time, any_order=any_order)
