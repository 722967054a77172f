"""Controllability, observability and their PBH forms, with a stated numerical rank tolerance.

Ranks are numerical: the number of singular values above
``tol = max(shape) * eps * sigma_max`` (the tolerance of ``numpy.linalg.matrix_rank``),
reported with every result. The Kalman matrices of these models are badly scaled
(inputs enter through ``1/J ~ 1e4``), so the verdicts come from the PBH test,
``rank [lambda I - A, B] = n`` at each eigenvalue, which needs no matrix powers, and from the
orthogonal staircase (:mod:`quadctl.linear.staircase`), which needs no eigenvalues: a mode either
finds out of reach is out of reach.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.linear import stability
from quadctl.linear.staircase import staircase

RICCATI_RTOL = 1e-8
"""Largest accepted relative residual of a Riccati solution, continuous or discrete: the residual's
1-norm over the sum of its terms' 1-norms (:func:`quadctl.design.riccati.riccati_residuals`,
:func:`quadctl.design.riccati.dare_residuals`), for every solution quadctl uses (:mod:`quadctl.design.riccati`)."""


@dataclass(frozen=True)
class Rank:
    """A numerical rank.

    Attributes
    ----------
    rank : int
    singular_values : (k,) ndarray
    tolerance : float
        Singular values above this count.
    """

    rank: int
    singular_values: np.ndarray
    tolerance: float


@dataclass(frozen=True)
class ModeTest:
    """PBH test at one eigenvalue: ``rank [lambda I - A, B]`` (or ``[lambda I - A; C]``)."""

    eigenvalue: complex
    rank: int
    passed: bool
    states: tuple[str, ...]
    """The states the mode's eigenvector lives in most (largest components first)."""


@dataclass(frozen=True)
class LostMode:
    """A mode the staircase finds out of reach of every input (or out of sight of every output): an eigenvalue
    of its block ``A_uu`` (:func:`quadctl.linear.staircase.staircase`)."""

    eigenvalue: complex
    states: tuple[str, ...]
    """The states its direction no input reaches (no output sees) lives in most, largest components first."""


@dataclass(frozen=True)
class Checks:
    """Controllability and observability of one system.

    ``controllable``/``observable`` hold when PBH passes at every eigenvalue and the staircase finds
    every state reached (seen); ``stabilizable``/``detectable`` when every mode either finds out of
    reach (sight) is stable. ``ctrb``/``obsv`` are the Kalman matrices' ranks, reported for comparison
    with the report.
    """

    n: int
    ctrb: Rank
    obsv: Rank
    controllable: bool
    observable: bool
    stabilizable: bool
    detectable: bool
    pbh_ctrb: tuple[ModeTest, ...]
    pbh_obsv: tuple[ModeTest, ...]
    controllable_dim: int
    """The dimension of the controllable subspace, by the staircase of ``(A, B)``."""
    observable_dim: int
    """The dimension of the observable subspace, by the staircase of ``(A^T, C^T)``."""
    lost_ctrb: tuple[LostMode, ...]
    """The staircase's modes no input reaches (``n - controllable_dim`` of them)."""
    lost_obsv: tuple[LostMode, ...]
    """The staircase's modes no output sees (``n - observable_dim`` of them)."""

    @property
    def unstabilizable_modes(self) -> tuple[ModeTest | LostMode, ...]:
        """The modes out of reach that are not stable: PBH's, else the staircase's (PBH names a mode at an
        eigenvalue of ``A`` itself; the staircase finds those whose eigenvalue is too far off for PBH)."""
        return _not_stable(self.pbh_ctrb, self.lost_ctrb)

    @property
    def undetectable_modes(self) -> tuple[ModeTest | LostMode, ...]:
        """The modes out of sight that are not stable: PBH's, else the staircase's."""
        return _not_stable(self.pbh_obsv, self.lost_obsv)


def _not_stable(tests: tuple[ModeTest, ...], lost: tuple[LostMode, ...]) -> tuple[ModeTest | LostMode, ...]:
    failed = tuple(m for m in tests if not m.passed and not stability.is_stable(m.eigenvalue))
    return failed or tuple(m for m in lost if not stability.is_stable(m.eigenvalue))


SAME_EIGENVALUE = 1e-9
"""Relative (to ``max(1, |lambda|)``): two computed eigenvalues this close are one mode's, for PBH."""
NEWTON_STEPS = 3
"""Newton steps a PBH test takes on its smallest singular value (:func:`pbh`)."""
NEWTON_REACH = 100
"""The steps stay within ``NEWTON_REACH * n * eps * ||A||_2`` of the computed eigenvalue: its error, an
eigensolver's backward error ``~ n eps ||A||`` times the eigenvalue's condition number, up to 100."""


def numerical_rank(mat: np.ndarray) -> Rank:
    """Rank by SVD with ``tol = max(shape) * eps * sigma_max``."""
    mat = np.atleast_2d(np.asarray(mat))
    return _rank_of(np.linalg.svd(mat, compute_uv=False), mat.shape)


def _rank_of(sv: np.ndarray, shape) -> Rank:
    tol = max(shape) * np.finfo(float).eps * (sv[0] if sv.size else 0.0)
    return Rank(rank=int((sv > tol).sum()), singular_values=sv, tolerance=float(tol))


def ctrb(A, B) -> np.ndarray:
    """Kalman controllability matrix ``[B, AB, ..., A^(n-1) B]``, shape (n, n m)."""
    A = np.asarray(A, dtype=float)
    blocks = [np.asarray(B, dtype=float)]
    for _ in range(A.shape[0] - 1):
        blocks.append(A @ blocks[-1])
    return np.hstack(blocks)


def obsv(A, C) -> np.ndarray:
    """Kalman observability matrix ``[C; CA; ...; C A^(n-1)]``, shape (n p, n)."""
    return ctrb(np.asarray(A).T, np.asarray(C).T).T


def pbh(A, M, names, *, dual: bool = False, keep=None) -> tuple[ModeTest, ...]:
    """PBH test at each distinct eigenvalue of ``A`` (or at those ``keep`` selects).

    Each test is an SVD of an ``n x (n + m)`` matrix; no matrix powers, so no overflow however
    large the entries of ``A``. Every eigenvalue is tested: two within :data:`SAME_EIGENVALUE` of
    each other are reported once, by the lower rank, since at the rank tolerance they can be two
    modes one input reaches and one it does not (``diag(1, 1 + 1e-10)``, ``B = [1; 0]``).

    A computed eigenvalue is off by the eigensolver's round-off, and at it the smallest singular
    value of ``[lambda I - A, B]`` is that error, not zero: a few times the rank tolerance for one
    system in a hundred that has a mode no input reaches. So each test also takes up to
    :data:`NEWTON_STEPS` Newton steps from the eigenvalue toward a zero of that singular value
    (``lambda <- lambda - sigma / (u^H [v_1..n])``, ``u, v`` its singular vectors), staying within
    its round-off (:data:`NEWTON_REACH`), and the rank is the least it finds.

    Parameters
    ----------
    A : (n, n) array_like
    M : array_like
        ``B`` (n, m) for controllability, or ``C`` (p, n) for observability (``dual=True``).
    names : sequence of str
        State names, to say where each mode lives.
    keep : callable, optional
        ``keep(eigenvalue) -> bool``: test only these modes (e.g. the unstable ones, for
        stabilizability: a stable mode needs no input). Default: every mode.
    """
    A = np.asarray(A, dtype=float)
    M = np.asarray(M, dtype=float)
    n = A.shape[0]
    eigvals, eigvecs = np.linalg.eig(A.T if not dual else A)
    reach = NEWTON_REACH * n * np.finfo(float).eps * (np.linalg.norm(A, 2) if n else 0.0)
    tests: list[ModeTest] = []
    for k, lam in enumerate(eigvals):
        if keep is not None and not keep(lam):
            continue
        r, lost = _pbh_rank(lam, A, M, dual, reach)
        vec = np.abs(eigvecs[:, k]) if lost is None else lost  # a lost mode: where no input reaches
        order = [i for i in np.argsort(-vec) if vec[i] > 0.1 * vec.max()]
        test = ModeTest(eigenvalue=complex(lam), rank=r, passed=r == n, states=tuple(names[i] for i in order))
        same = next((j for j, t in enumerate(tests)
                     if abs(lam - t.eigenvalue) <= SAME_EIGENVALUE * max(1.0, abs(lam))), None)
        if same is None:
            tests.append(test)
        elif r < tests[same].rank:
            tests[same] = test
    return tuple(tests)


def _pbh_rank(lam: complex, A: np.ndarray, M: np.ndarray, dual: bool, reach: float) -> tuple[int, np.ndarray | None]:
    """The least rank of ``[mu I - A, M]`` (``[mu I - A; M]`` when ``dual``) at ``mu = lam`` and along
    Newton's steps toward a zero of its smallest singular value, within ``reach`` of ``lam`` (:func:`pbh`);
    and, below ``n``, how much of each state the directions no input reaches (no output sees) hold: the
    row norms of the null space's basis (the eigenvector of a repeated eigenvalue can lie anywhere in its
    eigenspace, the null space cannot)."""
    n = A.shape[0]
    mu, rank = lam, n
    for _ in range(NEWTON_STEPS + 1):
        pencil = mu * np.eye(n) - A
        stacked = np.vstack([pencil, M]) if dual else np.hstack([pencil, M])
        u, sv, vh = np.linalg.svd(stacked)
        rank = min(rank, _rank_of(sv, stacked.shape).rank)
        if rank < n:
            null = vh[rank:n].conj().T if dual else u[:, rank:n]  # y^H [mu I - A, B] = 0, or [mu I - A; C] v = 0
            return rank, np.sqrt(np.sum(np.abs(null) ** 2, axis=1))
        left, right = u[:, n - 1], vh[n - 1].conj()  # stacked @ right = sv[n - 1] * left
        slope = left[:n].conj() @ right if dual else left.conj() @ right[:n]
        if slope == 0:
            break
        with np.errstate(over="ignore", invalid="ignore"):  # a slope of 1e-310: a step to inf, beyond reach
            mu = mu - sv[n - 1] / slope
        if not abs(mu - lam) <= reach:
            break
    return rank, None


def check(A, B, C=None, names=None) -> Checks:
    """Controllability, observability, stabilizability and detectability of ``(A, B, C)``.

    Two tests, each able to miss what the other finds: PBH at every eigenvalue (:func:`pbh`), and the
    orthogonal staircases of ``(A, B)`` and ``(A^T, C^T)`` (:func:`quadctl.linear.staircase.staircase`),
    whose dimension needs no eigenvalue, so a mode out of reach inside a nearly defective block of ``A``
    (its computed eigenvalue off by ``~sqrt(eps)``, beyond PBH's Newton steps) is still found. A mode
    either finds out of reach (sight) makes the system not controllable (observable); it is
    stabilizable (detectable) when every such mode is stable.

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    C : (p, n) array_like, optional
        Default identity (every state measured).
    names : sequence of str, optional
        State names for the mode reports.

    Returns
    -------
    Checks
    """
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    C = np.eye(n) if C is None else np.asarray(C, dtype=float)
    names = list(names) if names is not None else [f"x{i}" for i in range(n)]
    ctrb_modes = pbh(A, B, names)
    obsv_modes = pbh(A, C, names, dual=True)
    reached, lost_ctrb = staircase_modes(A, B, names)
    seen, lost_obsv = staircase_modes(A.T, C.T, names)
    return Checks(
        n=n,
        ctrb=numerical_rank(ctrb(A, B)),
        obsv=numerical_rank(obsv(A, C)),
        controllable=all(m.passed for m in ctrb_modes) and reached == n,
        observable=all(m.passed for m in obsv_modes) and seen == n,
        stabilizable=not _not_stable(ctrb_modes, lost_ctrb),
        detectable=not _not_stable(obsv_modes, lost_obsv),
        pbh_ctrb=ctrb_modes,
        pbh_obsv=obsv_modes,
        controllable_dim=reached,
        observable_dim=seen,
        lost_ctrb=lost_ctrb,
        lost_obsv=lost_obsv,
    )


def staircase_modes(A: np.ndarray, B: np.ndarray, names) -> tuple[int, tuple[LostMode, ...]]:
    """The controllable dimension of ``(A, B)`` and the modes out of reach, each named by its direction no
    input reaches (components above a tenth of the largest, as :func:`pbh` names a mode)."""
    form = staircase(A, B)
    lost = []
    for lam, vec in zip(form.uncontrollable_eigenvalues, np.abs(form.uncontrollable_directions).T):
        order = [i for i in np.argsort(-vec) if vec[i] > 0.1 * vec.max()]
        lost.append(LostMode(eigenvalue=complex(lam), states=tuple(names[i] for i in order)))
    return form.controllable_dim, tuple(lost)
