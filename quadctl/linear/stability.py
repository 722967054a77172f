"""One stability predicate and one rule for marginal modes, for one closed loop or a stack of them.

Every verdict in quadctl comes from :func:`is_stable` (within :data:`STABILITY_MARGIN` of the
imaginary axis, :data:`UNIT_CIRCLE_MARGIN` of the unit circle), and every stability comparison is in
this module (a structure test keeps it so; :func:`on_boundary`, :func:`in_open_left_half_plane`).
:func:`free_positions` is the one rule for position states nothing reads, whose exact mode at
``s = 0`` is expected: :func:`assess` leaves them out of the verdict and names them
(:func:`marginal_states`). See docs/internals.md ("Stability").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.layout import N_STATES, POSITION_STATES, STATE_INDEX, STATE_NAMES

STABILITY_MARGIN = 1e-9
"""A continuous eigenvalue with ``Re >= -STABILITY_MARGIN * max(1, |lambda|)`` is not stable (rad/s)."""
UNIT_CIRCLE_MARGIN = 1e-9
"""A discrete eigenvalue with ``|z| >= 1 - UNIT_CIRCLE_MARGIN`` is not stable."""


def is_stable(eigenvalues, *, discrete: bool = False):
    """Whether each eigenvalue is stable: a bool for a scalar, else a bool array of the same shape.

    Parameters
    ----------
    eigenvalues : complex or array_like of complex
        ``s`` (rad/s) or, with ``discrete``, ``z``.
    discrete : bool
    """
    e = np.asarray(eigenvalues, dtype=complex)
    if discrete:
        out = np.abs(e) < 1.0 - UNIT_CIRCLE_MARGIN
    else:
        out = e.real < -STABILITY_MARGIN * np.maximum(1.0, np.abs(e))
    return bool(out) if out.ndim == 0 else out


def on_boundary(eigenvalue, *, discrete: bool = False) -> bool:
    """Whether an eigenvalue lies on the stability boundary, within the margins of :func:`is_stable`:
    ``|Re s| <= STABILITY_MARGIN max(1, |s|)``, or ``||z| - 1| <= UNIT_CIRCLE_MARGIN``."""
    e = complex(eigenvalue)
    if discrete:
        return abs(abs(e) - 1.0) <= UNIT_CIRCLE_MARGIN
    return abs(e.real) <= STABILITY_MARGIN * max(1.0, abs(e))


def criterion(discrete: bool = False) -> str:
    """The instability criterion of :func:`is_stable` as text, for messages."""
    return f"|z| >= 1 - {UNIT_CIRCLE_MARGIN:g}" if discrete else f"Re s >= -{STABILITY_MARGIN:g} max(1, |s|)"


def in_open_left_half_plane(eigenvalues) -> np.ndarray:
    """``Re s < 0`` exactly, without a margin: which eigenvalues of a Hamiltonian form its stable
    half (the Riccati solvers' invariant subspace), not a verdict on a loop (:func:`is_stable`)."""
    return np.asarray(eigenvalues).real < 0


def free_mask(A, *, reads=(), integral_states=(), discrete: bool = False) -> np.ndarray:
    """:func:`free_positions` of a stack, as a mask: ``(..., 3)`` bool, one per :data:`POSITION_STATES`.

    Parameters
    ----------
    A : (..., n, n) array_like
        Plant or closed loop; its first 12 states are :data:`quadctl.layout.STATE_NAMES`.
    reads : sequence of (..., r, >= 12) array_like
        Gains and weights whose columns read the states (a state gain ``K``, a weight ``Q``).
    integral_states : iterable of str
        States an integrator reads (through ``dz/dt = -x_s``, which ``A`` may not carry).
    discrete : bool
        ``A`` is a discrete map: a state nothing depends on has the unit column.
    """
    A = np.asarray(A, dtype=float)
    positions = [STATE_INDEX[s] for s in POSITION_STATES]
    cols = A[..., :, positions]
    if discrete:
        cols = cols - np.eye(A.shape[-1])[:, positions]
    free = ~np.any(cols != 0, axis=-2)  # nothing depends on it
    for M in reads:  # no gain or weight reads it
        free = free & ~np.any(np.asarray(M, dtype=float)[..., :, positions] != 0, axis=-2)
    integrated = np.array([s in tuple(integral_states) for s in POSITION_STATES])
    return free & ~integrated  # no integrator reads it


def free_positions(A, *, reads=(), integral_states=(), discrete: bool = False) -> tuple[str, ...]:
    """The position states that nothing reads and nothing depends on: the one rule for which
    positions a loop leaves free (see the module docstring).

    A position is free when its column of ``A`` is zero (of ``A - I`` when ``discrete``), its
    column of every matrix in ``reads`` is zero, and it is not in ``integral_states``.

    Parameters
    ----------
    A : (n, n) array_like
        A plant (12 states first) or a closed loop of ``[x; ...]``.
    reads : sequence of array_like
        Gains and weights (columns index the states: ``K`` (m, 12), ``Q`` (n, n)).
    integral_states : iterable of str
    discrete : bool

    Returns
    -------
    tuple of str
        In the order of :data:`quadctl.layout.POSITION_STATES`.

    Examples
    --------
    >>> import numpy as np
    >>> A = np.zeros((12, 12)); A[0, 3] = 1.0      # pN' = u: nothing reads pN, pE or pD
    >>> free_positions(A)
    ('pN', 'pE', 'pD')
    >>> A[3, 0] = -1.0                             # u' = -pN: u depends on pN
    >>> free_positions(A)
    ('pE', 'pD')
    """
    mask = free_mask(A, reads=reads, integral_states=integral_states, discrete=discrete)
    return tuple(s for s, m in zip(POSITION_STATES, mask.tolist()) if m)


def marginal_states(A_cl, K, *, discrete: bool = False) -> tuple[str, ...]:
    """Position states whose mode is marginal by design: :func:`free_positions` of a closed loop.

    Parameters
    ----------
    A_cl : (n, n) array_like
        Closed loop of ``[x; z]`` (12 plant states, then any integrators).
    K : (m, 12) array_like
        The state gain.
    discrete : bool
        ``A_cl`` is a discrete loop (a free position has a unit column).
    """
    return free_positions(A_cl, reads=(K,), discrete=discrete)


@dataclass(frozen=True)
class Assessment:
    """The stability of one closed loop.

    Attributes
    ----------
    eigenvalues : (n,) ndarray
        All eigenvalues, as ``s`` (rad/s; a discrete loop's ``ln(z) / Ts``).
    eigenvalues_z : (n,) ndarray or None
        A discrete loop's ``z``.
    core : (k,) ndarray
        The eigenvalues without the marginal modes, as ``s``: what the verdict is about.
    marginal : tuple of str
        See :func:`marginal_states`.
    stable : bool
    """

    eigenvalues: np.ndarray
    eigenvalues_z: np.ndarray | None
    core: np.ndarray
    marginal: tuple[str, ...]
    stable: bool


def assess(A_cl, K, *, sample_time: float | None = None) -> Assessment:
    """Eigenvalues and verdict of a closed loop, marginal positions left out.

    Parameters
    ----------
    A_cl : (n, n) array_like
        ``[x; z]`` closed loop; discrete when ``sample_time`` is given.
    K : (m, 12) array_like
    sample_time : float, optional
        s, of a discrete loop.
    """
    return assess_stack(np.asarray(A_cl, dtype=float)[None], np.asarray(K, dtype=float)[None],
                        sample_time=sample_time)[0]


def assess_stack(A_cl, K, *, sample_time: float | None = None) -> list[Assessment]:
    """:func:`assess` of stacked loops ``A_cl`` (N, n, n), ``K`` (N, m, 12), batched by marginal set."""
    A_cl = np.asarray(A_cl, dtype=float)
    verdicts = verdict_stack(A_cl, K, sample_time=sample_time)
    all_eig = np.linalg.eigvals(_finite_or_zero(A_cl))
    return [Assessment(eigenvalues=s_plane(e, sample_time), eigenvalues_z=e if sample_time is not None else None,
                       core=core, marginal=marginal, stable=stable)
            for e, (core, marginal, stable) in zip(all_eig, verdicts)]


def verdict_stack(A_cl, K, *, sample_time: float | None = None,
                  any_order: bool = False) -> list[tuple[np.ndarray, tuple[str, ...], bool]]:
    """The verdict part of :func:`assess_stack` (``core``, ``marginal``, ``stable`` per loop), without
    the whole spectrum: what a sweep's rows need of each design.

    ``any_order``: each ``core`` in whatever order is quickest (:func:`stack_eigenvalues` by the
    stack's diagonal blocks), for a caller that reads only its extremes and its verdict.
    """
    A_cl = np.asarray(A_cl, dtype=float)
    K = np.asarray(K, dtype=float)
    N, n = A_cl.shape[0], A_cl.shape[1]
    discrete = sample_time is not None
    free = free_mask(A_cl, reads=(K,), discrete=discrete)
    finite = np.all(np.isfinite(A_cl), axis=(1, 2))
    safe = _finite_or_zero(A_cl)
    out: list = [None] * N
    for pattern in {tuple(row) for row in free.tolist()}:
        members = np.nonzero((free == pattern).all(axis=1))[0]
        marginal = tuple(s for s, m in zip(POSITION_STATES, pattern) if m)
        keep = [i for i in range(n) if i >= N_STATES or STATE_NAMES[i] not in marginal]
        loops = safe[np.ix_(members, keep, keep)]
        core = stack_eigenvalues(loops) if any_order else np.linalg.eigvals(loops)
        ok = (np.all(is_stable(core, discrete=discrete), axis=1) & finite[members]).tolist()
        core_s = s_plane(core, sample_time)  # elementwise: the stack at once
        for j, k in enumerate(members.tolist()):
            out[k] = (core_s[j], marginal, ok[j])
    return out


def stack_eigenvalues(M: np.ndarray) -> np.ndarray:
    """The eigenvalues of a stack of matrices, by the diagonal blocks their common sparsity allows.

    The loops of one plant share their structural zeros (a decoupled design's gain leaves whole
    subsystems unread), so after a permutation each is block triangular with the same blocks: the
    strongly connected components of the graph of the stack's nonzero entries (:func:`diagonal_blocks`).
    The eigenvalues are those of the blocks, each block of the whole stack in one LAPACK call (a 1 x 1
    block is its entry): the same values as ``np.linalg.eigvals(M)`` to round-off, in another order,
    for less (the mambo-200hz loops, 11 x 11, are blocks of 6, 3 and 2 states: a sweep's verdicts
    took 7.3 us a loop against 9.1).

    Parameters
    ----------
    M : (N, n, n) ndarray
        Finite.

    Returns
    -------
    (N, n) complex ndarray
        Block by block, in the order of :func:`diagonal_blocks`.
    """
    blocks = diagonal_blocks(np.any(M != 0, axis=0))
    if len(blocks) == 1:
        return np.linalg.eigvals(M)
    parts = [M[:, b, b[0]].astype(complex) if len(b) == 1 else np.linalg.eigvals(M[:, b][:, :, b]) for b in blocks]
    return np.concatenate(parts, axis=1).astype(complex)


def diagonal_blocks(pattern: np.ndarray) -> list[list[int]]:
    """The strongly connected components of the directed graph whose edges are the ``True`` entries
    of ``pattern`` (n, n): the diagonal blocks of the block triangular form a permutation gives any
    matrix with that sparsity. Each a sorted list of indices; ordered by their first index."""
    n = len(pattern)
    reach = (np.asarray(pattern, dtype=bool) | np.eye(n, dtype=bool)).astype(np.int64)
    while True:  # transitive closure by squaring: log2(n) products at most
        wider = ((reach @ reach) > 0).astype(np.int64)
        if np.array_equal(wider, reach):
            break
        reach = wider
    both = (reach & reach.T).astype(bool)
    blocks, seen = [], np.zeros(n, dtype=bool)
    for i in range(n):
        if not seen[i]:
            members = np.flatnonzero(both[i])
            seen[members] = True
            blocks.append(members.tolist())
    return blocks


def _finite_or_zero(A_cl: np.ndarray) -> np.ndarray:
    """The stack with every loop that has a non-finite entry zeroed (LAPACK refuses them)."""
    finite = np.all(np.isfinite(A_cl), axis=(1, 2))
    return A_cl if finite.all() else np.where(finite[:, None, None], A_cl, 0.0)


def s_plane(e: np.ndarray, sample_time: float | None) -> np.ndarray:
    """Eigenvalues as ``s``: ``ln(z) / Ts`` for a discrete loop (``z = 0`` maps to ``-inf``)."""
    if sample_time is None:
        return e
    with np.errstate(divide="ignore", invalid="ignore"):  # log(0) = -inf, divided as complex
        return np.log(e.astype(complex)) / sample_time


def least_damping(eigenvalues, sample_time: float | None = None) -> float:
    """The smallest damping ratio ``zeta = -Re(s) / |s|`` of a loop's modes (``inf`` with none).

    Parameters
    ----------
    eigenvalues : array_like of complex
        ``s`` (rad/s), or with ``sample_time`` the ``z`` of a loop sampled every ``sample_time`` s,
        mapped to ``s = ln(z) / Ts`` (a mode at ``z = 0``, a pure delay, has no damping to lose and
        is skipped).

    Returns
    -------
    float
        In ``[-1, 1]``: negative for an unstable mode; ``1`` for a real stable one.

    >>> least_damping([-1 + 1j, -1 - 1j, -3])
    0.7071067811865475
    """
    e = np.asarray(eigenvalues, dtype=complex).ravel()
    if sample_time is not None:
        e = e[np.abs(e) > 1e-12]
        e = np.log(e) / sample_time
    e = e[np.abs(e) > 0]
    return float((-e.real / np.abs(e)).min()) if e.size else float("inf")


@dataclass(frozen=True)
class Damp:
    """Natural frequency, damping and time constant of each mode (MATLAB ``damp``), lowest natural frequency first.

    Attributes
    ----------
    s : (n,) complex ndarray
        The poles as ``s`` (rad/s); a discrete loop's ``ln(z) / Ts`` (``-inf`` for ``z = 0``).
    z : (n,) complex ndarray or None
        A discrete loop's poles.
    wn : (n,) ndarray
        Natural frequency ``|s|``, rad/s.
    zeta : (n,) ndarray
        Damping ratio ``-Re(s) / |s|`` (NaN for a pole at ``s = 0``; 1 for ``z = 0``).
    tau : (n,) ndarray
        Time constant ``-1 / Re(s)``, s (negative for an unstable mode, ``inf`` on the imaginary
        axis, 0 for ``z = 0``).
    """

    s: np.ndarray
    z: np.ndarray | None
    wn: np.ndarray
    zeta: np.ndarray
    tau: np.ndarray


def damp(eigenvalues, sample_time: float | None = None) -> Damp:
    """:class:`Damp` of a loop's poles: ``s`` (rad/s), or with ``sample_time`` its ``z``, read as
    ``s = ln(z) / Ts`` as MATLAB's ``damp`` reads a discrete system; sorted by ``wn``, then ``Im(s)``.

    >>> d = damp([-3 + 4j, -3 - 4j])
    >>> d.wn.tolist(), d.zeta.tolist(), d.tau.tolist()
    ([5.0, 5.0], [0.6, 0.6], [0.3333333333333333, 0.3333333333333333])
    """
    e = np.asarray(eigenvalues, dtype=complex).ravel()
    s = s_plane(e, sample_time)
    deadbeat = np.isinf(s.real)  # z = 0: ln(0) = -inf (its imaginary part NaN)
    s = np.where(deadbeat, complex(-np.inf, 0.0), s)
    with np.errstate(divide="ignore", invalid="ignore"):
        wn = np.abs(s)
        zeta = np.where(deadbeat, 1.0, -s.real / wn)
        tau = np.where(deadbeat, 0.0, np.where(s.real == 0, np.inf, -1.0 / s.real))
    order = np.lexsort((s.imag, wn))
    return Damp(s=s[order], z=None if sample_time is None else e[order], wn=wn[order], zeta=zeta[order],
                tau=tau[order])
