"""One stability predicate and one rule for marginal modes, for one closed loop or a stack of them.

**Stable.** A continuous eigenvalue is stable when ``Re(s) < -STABILITY_MARGIN * max(1, |s|)``;
a discrete one when ``|z| < 1 - UNIT_CIRCLE_MARGIN``. Every verdict in quadctl (design, check,
margins, sweep rows, the RK4 step plan) comes from :func:`is_stable`.

**Marginal.** A position state that no gain feeds back and that nothing depends on (translation
invariance: its column of ``A - B K`` is zero, or the unit column of a discrete loop) adds an
exact eigenvalue at ``s = 0`` (``z = 1``). That mode is expected, not unstable: the vehicle
holds its velocity and heading and lets its position drift. :func:`marginal_states` names those
states; :func:`assess` leaves them out of the verdict and reports them.
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


def marginal_states(A_cl, K, *, discrete: bool = False) -> tuple[str, ...]:
    """Position states whose mode is marginal by design (see the module docstring).

    Parameters
    ----------
    A_cl : (n, n) array_like
        Closed loop of ``[x; z]`` (12 plant states, then any integrators).
    K : (m, 12) array_like
        The state gain.
    discrete : bool
        ``A_cl`` is a discrete loop (a free position has a unit column).
    """
    A_cl = np.asarray(A_cl, dtype=float)
    drift = A_cl - np.eye(len(A_cl)) if discrete else A_cl
    K = np.asarray(K, dtype=float)
    return tuple(s for s in POSITION_STATES
                 if not np.any(K[:, STATE_INDEX[s]]) and not np.any(drift[:, STATE_INDEX[s]]))


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
    return [Assessment(eigenvalues=_as_s(e, sample_time), eigenvalues_z=e if sample_time is not None else None,
                       core=core, marginal=marginal, stable=stable)
            for e, (core, marginal, stable) in zip(all_eig, verdicts)]


def verdict_stack(A_cl, K, *, sample_time: float | None = None) -> list[tuple[np.ndarray, tuple[str, ...], bool]]:
    """The verdict part of :func:`assess_stack` (``core``, ``marginal``, ``stable`` per loop), without
    the whole spectrum: what a sweep's rows need of each design."""
    A_cl = np.asarray(A_cl, dtype=float)
    K = np.asarray(K, dtype=float)
    N, n = A_cl.shape[0], A_cl.shape[1]
    discrete = sample_time is not None
    positions = [STATE_INDEX[s] for s in POSITION_STATES]
    drift = A_cl - np.eye(n) if discrete else A_cl
    free = ~np.any(K[:, :, positions] != 0, axis=1) & ~np.any(drift[:, :, positions] != 0, axis=1)
    finite = np.all(np.isfinite(A_cl), axis=(1, 2))
    safe = _finite_or_zero(A_cl)
    out: list = [None] * N
    for pattern in {tuple(row) for row in free.tolist()}:
        members = np.nonzero((free == pattern).all(axis=1))[0]
        marginal = tuple(s for s, m in zip(POSITION_STATES, pattern) if m)
        keep = [i for i in range(n) if i >= N_STATES or STATE_NAMES[i] not in marginal]
        core = np.linalg.eigvals(safe[np.ix_(members, keep, keep)])
        ok = np.all(is_stable(core, discrete=discrete), axis=1) & finite[members]
        for j, k in enumerate(members):
            out[k] = (_as_s(core[j], sample_time), marginal, bool(ok[j]))
    return out


def _finite_or_zero(A_cl: np.ndarray) -> np.ndarray:
    """The stack with every loop that has a non-finite entry zeroed (LAPACK refuses them)."""
    finite = np.all(np.isfinite(A_cl), axis=(1, 2))
    return A_cl if finite.all() else np.where(finite[:, None, None], A_cl, 0.0)


def _as_s(e: np.ndarray, sample_time: float | None) -> np.ndarray:
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
