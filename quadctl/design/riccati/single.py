"""One Riccati problem: validated, solved, certified, or refused with the reason.

:func:`solve` is behind :func:`quadctl.design.lqr` and :func:`quadctl.design.discrete.dlqr`: quadctl's own
solvers first (:mod:`quadctl.design.riccati.stacked` for few states, numpy only; Laub's Schur method,
:func:`care_schur`, for more), SciPy's where they have no certified answer, and a
:class:`~quadctl.errors.DesignError` that names the cause when nothing is certified.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.design.riccati.stacked import (
    KRONECKER_MAX_N,
    NEWTON_STEPS,
    ROUNDOFF_RTOL,
    all_stable,
    care_checked,
    dare_checked,
    gain_and_residual,
    newton_correction,
    without_cross,
)
from quadctl.design.riccati.weights import WeightCheck, as_problem
from quadctl.errors import ArgumentError, DesignError
from quadctl.linear import stability
from quadctl.linear.analysis import RICCATI_RTOL, pbh, staircase_modes
from quadctl.text.messages import eig_text

scipy = lazy_import("scipy")  # loaded on first use (then scipy.linalg on access): quadctl._lazy


@dataclass(frozen=True, eq=False)
class LqrResult:
    """One LQR solution; unpacks as ``K, P, E = lqr(...)`` (python-control's order).

    Attributes
    ----------
    K : (m, n) ndarray
        Gain, ``u = -K x``.
    P : (n, n) ndarray
        Stabilizing Riccati solution (symmetric).
    E : (n,) complex ndarray
        Eigenvalues of ``A - B K``: ``s`` (rad/s) for a continuous design, ``z`` for a discrete one.
    residual : float
        Relative residual (:func:`riccati_residual` or :func:`dare_residual`), at most ``RICCATI_RTOL``.

    Examples
    --------
    >>> import quadctl as qc
    >>> result = qc.lqr([[0.0]], [[1.0]], [[9.0]], [[1.0]])
    >>> K, S, E = result  # python-control's names: S is the Riccati solution, result.P
    >>> float(K[0, 0]), float(result.P[0, 0]), result.residual < 1e-12
    (3.0, 3.0, True)
    """

    K: np.ndarray
    P: np.ndarray
    E: np.ndarray
    residual: float

    def __iter__(self):
        return iter((self.K, self.P, self.E))


def care_schur(A, B, Q, R, N=None) -> np.ndarray:
    """Stabilizing CARE solution by Laub's method (no residual check: :func:`solve` does that).

    The ordered real Schur form ``H Z = Z T`` of the Hamiltonian ``[[A~, -S], [-Q~, -A~']]`` with the
    ``n`` eigenvalues of the open left half-plane leading ``T`` gives ``P = Z21 Z11^-1``. The states
    are first scaled by powers of two, ``x = D x_s``, chosen by balancing ``|H|`` and keeping the
    scaling symplectic (``diag(D, D^-1)``; Benner, "Symplectic balancing of Hamiltonian matrices",
    SIAM J. Sci. Comput. 22, 2001), which is exact in floating point. One ``2n x 2n`` Schur
    decomposition (SciPy's): several times faster than ``scipy.linalg.solve_continuous_are``'s QZ of
    the ``(2n + m)`` pencil (``benchmarks/bench.py``).

    Parameters
    ----------
    A, B, Q, R, N : array_like
        As for :func:`care_batch`, one problem: (n, n), (n, m), (n, n), (m, m), (n, m).

    Returns
    -------
    P : (n, n) ndarray

    Raises
    ------
    numpy.linalg.LinAlgError
        The Hamiltonian does not have ``n`` eigenvalues in the open left half-plane, or ``Z11`` is
        singular: there is no stabilizing solution this way.
    """
    A, B, Q, R, N = as_problem(A, B, Q, R, N, name="care_schur")
    n = A.shape[0]
    X = np.linalg.solve(R, np.vstack([B, N]).T)             # [R^-1 B', R^-1 N']
    At, Qt = A - B @ X[:, n:], Q - N @ X[:, n:]
    H = np.empty((2 * n, 2 * n))
    H[:n, :n], H[:n, n:], H[n:, :n], H[n:, n:] = At, -B @ X[:, :n], -(Qt + Qt.T) / 2, -At.T
    magnitude = np.abs(H)
    np.fill_diagonal(magnitude, 0.0)  # the diagonal does not change under a similarity scaling
    _, (scale, _) = scipy.linalg.matrix_balance(magnitude, permute=False, separate=True)
    log2 = np.log2(scale)
    d = 2.0 ** np.round((log2[:n] - log2[n:]) / 2)
    t = np.concatenate([d, 1 / d])                              # x = D x_s: H_s = T^-1 H T, T = diag(D, D^-1)
    H *= t / t[:, None]
    _, Z, stable = scipy.linalg.schur(H, output="real", sort="lhp")
    if stable != n:
        raise np.linalg.LinAlgError(f"the Hamiltonian has {stable} eigenvalues in the open left half-plane, "
                                    f"not {n}")
    P = np.linalg.solve(Z[:n, :n].T, Z[n:, :n].T).T / np.outer(d, d)   # P = D^-1 P_s D^-1
    return (P + P.T) / 2


def solve(A, B, Q, R, N=None, *, discrete: bool = False, name: str = "system", state_names=None) -> LqrResult:
    """One LQR problem: validated, solved, certified, or refused with the reason.

    The weights are checked first (:class:`WeightCheck`). Then the answers are tried in order until
    one has a residual within ``RICCATI_RTOL`` and a stable loop: quadctl's own (:func:`care_batch`
    or :func:`dare_batch` up to :data:`KRONECKER_MAX_N` states, numpy only; :func:`care_schur` or
    :func:`dare_batch` above), then SciPy's ``solve_continuous_are`` / ``solve_discrete_are``
    balanced and unbalanced (balancing can fail on entries near the underflow limit), each
    Newton-refined while its residual misses. A found stabilizing solution proves the pair
    stabilizable, so the slower diagnosis runs only when none is found.

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    Q : (n, n) array_like
    R : (m, m) array_like
    N : (n, m) array_like, optional
    discrete : bool
        Solve the DARE (``dlqr``) instead of the CARE (``lqr``).
    name : str
        Names the system in errors.
    state_names : sequence of str, optional
        Names the states a refused mode lives in.

    Returns
    -------
    LqrResult

    Raises
    ------
    DesignError
        Invalid weights; a mode no input reaches; a marginal mode ``Q`` does not see; an equation
        too ill-conditioned to certify; or the numerics failed (the reason is named).
    ArgumentError
        A matrix that is not real numbers, of a shape that does not fit, or a problem with no state
        or no input (:func:`~quadctl.design.riccati.weights.as_problem`); ``state_names`` not one a state.
    """
    A, B, Q, R, N = as_problem(A, B, Q, R, N, name=name)
    if state_names is not None and (isinstance(state_names, str) or len(state_names) != len(A)):
        given = "is one string" if isinstance(state_names, str) else f"has {len(state_names)} names"
        raise ArgumentError(f"{name}: state_names {given} for {len(A)} states; give a name a state, in the order "
                            "of A's rows")
    reason = WeightCheck(*(M[None] for M in (A, B, Q, R, N))).reason(0)
    if reason is not None:
        raise DesignError(f"{name}: {reason}")
    equation = "discrete Riccati equation" if discrete else "Riccati equation"
    try:
        return _solve_one(discrete, A, B, Q, R, N, name, state_names)
    except DesignError:
        raise
    except (np.linalg.LinAlgError, MemoryError, ValueError) as exc:
        raise DesignError(f"{name}: the {equation} could not be solved ({type(exc).__name__}: {exc}); "
                          "rescale units so the entries of A, B, Q, R are comparable") from None


def _solve_one(discrete, A, B, Q, R, N, name, state_names) -> LqrResult:
    n = A.shape[0]
    if n <= KRONECKER_MAX_N or discrete:
        own = _stacked_one(dare_checked if discrete else care_checked)
    else:
        own = care_schur
    answers, failures = [], []
    for method in (own, _scipy(discrete, True), _scipy(discrete, False)):
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")  # SciPy's ill-conditioning warnings: the residual decides
                found = method(A, B, Q, R, N)
                if isinstance(found, LqrResult):
                    return found
                if not np.all(np.isfinite(found)):
                    continue
                result = _refine(discrete, A, B, Q, R, N, found)
        except (np.linalg.LinAlgError, ValueError) as exc:
            failures.append(exc)
            continue
        if _certified(discrete, result):
            return result
        answers.append(result)
    raise _refusal(discrete, A, B, Q, R, N, answers, failures, name, state_names)


def _stacked_one(batched):
    def own(A, B, Q, R, N):
        res = batched(A[None], B[None], Q[None], R[None], N[None], np.ones(1, dtype=bool))
        if res.ok[0]:
            return LqrResult(K=res.K[0], P=res.P[0], E=res.E[0], residual=float(res.residual[0]))
        return res.P[0]
    return own


def _scipy(discrete: bool, balanced: bool):
    def run(A, B, Q, R, N):
        solver = scipy.linalg.solve_discrete_are if discrete else scipy.linalg.solve_continuous_are
        return solver(A, B, Q, R, s=N if np.any(N) else None, balanced=balanced)
    return run


def _refine(discrete, A, B, Q, R, N, P) -> LqrResult:
    """``P`` polished by Newton steps (:func:`newton_correction`, at most :data:`NEWTON_STEPS`) until its
    residual is round-off for its size (``n ROUNDOFF_RTOL``); a step that does not lower the residual
    is dropped."""
    args = tuple(M[None] for M in (A, B, Q, R, N))
    P = ((P + P.T) / 2)[None]
    K, F, residual, _ = gain_and_residual(discrete, *args, P)
    for _ in range(NEWTON_STEPS):
        if not residual[0] > len(A) * ROUNDOFF_RTOL:
            break
        D, done = newton_correction(discrete, args[0], args[1], K, F)
        if not done[0]:
            break
        K_next, F_next, residual_next, solved = gain_and_residual(discrete, *args, P + D)
        if not (solved[0] and residual_next[0] < residual[0]):
            break
        P, K, F, residual = P + D, K_next, F_next, residual_next
    K, P = K[0], P[0]
    E = np.linalg.eigvals(A - B @ K).astype(complex) if np.all(np.isfinite(K)) else np.full(len(A), np.nan + 0j)
    return LqrResult(K=K, P=P, E=E, residual=float(residual[0]) if np.isfinite(residual[0]) else np.inf)


def _stable(discrete: bool, E) -> bool:
    return bool(all_stable(discrete, E))


def _certified(discrete: bool, result: LqrResult) -> bool:
    return result.residual <= RICCATI_RTOL and _stable(discrete, result.E)


def _refusal(discrete, A, B, Q, R, N, answers, failures, name, state_names) -> DesignError:
    """The DesignError that says why no certified answer was found, checked in order of cause."""
    n = A.shape[0]
    names = list(state_names) if state_names is not None else [f"x{i}" for i in range(n)]
    mode = unstabilizable_mode(A, B, names, discrete=discrete, name=name)
    if mode is not None:
        return DesignError(_not_stabilizable(name, mode, discrete))
    # no stabilizing solution also when a mode on the stability boundary is invisible to the weight
    At, Qt, _, _ = (M[0] for M in without_cross(A[None], B[None], Q[None], R[None], N[None]))
    def on_boundary(e):
        return stability.on_boundary(e, discrete=discrete)

    unseen = [t for t in pbh(At, Qt, names, dual=True, keep=on_boundary) if not t.passed]
    equation = "discrete Riccati equation" if discrete else "Riccati equation"
    if unseen:
        return DesignError(
            f"{name}: the {equation} has no stabilizing solution: the marginal mode at eigenvalue "
            f"{_fmt(unseen[0].eigenvalue, discrete)} (in {', '.join(unseen[0].states)}) is invisible to Q; "
            "give weight to the states it lives in")
    if not answers:
        reason = failures[-1] if failures else "no finite solution"
        return DesignError(f"{name}: the {equation} solve failed ({reason}); "
                           "rescale units so the entries of A, B, Q, R are comparable")
    best = min(answers, key=lambda r: (not _stable(discrete, r.E), r.residual))
    E = best.E[np.isfinite(best.E)]
    slowest = E[int(np.argmax(np.abs(E) if discrete else E.real))] if E.size else complex("nan")
    where = _fmt(slowest, discrete, digits=3) + ("" if discrete else " rad/s")
    fix = "weight the states of that mode, or rescale units so the entries of A, B, Q, R are comparable"
    if best.residual > RICCATI_RTOL:
        return DesignError(f"{name}: the {equation} is too ill-conditioned to solve to {RICCATI_RTOL:g} "
                           f"(residual {best.residual:.1e}); its slowest closed-loop mode is at {where}: {fix}")
    margin = stability.criterion(discrete)
    return DesignError(f"{name}: the {equation} is too ill-conditioned to certify a stable loop "
                       f"(residual {best.residual:.1e}); its slowest closed-loop mode is at {where}, within "
                       f"the stability margin ({margin}): give an input more authority over that mode, "
                       "or weight its states")


def unstabilizable_mode(A, B, state_names=None, *, discrete: bool = False, name: str = "system"):
    """The first mode that is not stable and that no input reaches (PBH), or None.

    Only the modes that are not stable are tested (``rank [lambda I - A, B] = n``, one SVD each):
    a stable mode needs no input, and no Kalman matrix ``[B, AB, ...]`` is formed (its powers
    overflow for large or stiff ``A``). When PBH finds none, the staircase's modes out of reach
    (:func:`quadctl.linear.analysis.staircase_modes`): one inside a nearly defective block, whose
    computed eigenvalue is too far off for PBH, as :func:`quadctl.linear.analysis.check` decides.

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    state_names : sequence of str, optional
    discrete : bool
        Stable means inside the unit circle (:func:`quadctl.linear.stability.is_stable`) instead of the left half-plane.
    name : str
        Names the system if the test itself fails.

    Returns
    -------
    quadctl.linear.analysis.ModeTest or quadctl.linear.analysis.LostMode or None

    Raises
    ------
    DesignError
        The eigenvalue or singular value computation failed.
    """
    A = np.atleast_2d(np.asarray(A, dtype=float))
    names = list(state_names) if state_names is not None else [f"x{i}" for i in range(A.shape[0])]

    def unstable(lam):
        return not stability.is_stable(lam, discrete=discrete)

    try:
        found = next((t for t in pbh(A, B, names, keep=unstable) if not t.passed), None)
        if found is None:  # a mode out of reach whose computed eigenvalue is too far off for PBH
            found = next((m for m in staircase_modes(A, np.atleast_2d(np.asarray(B, dtype=float)), names)[1]
                          if unstable(m.eigenvalue)), None)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise DesignError(f"{name}: could not decide stabilizability ({exc}); "
                          "rescale units so the entries of A and B are comparable") from None
    return found


def require_stabilizable(A, B, name: str = "system", state_names=None, *, discrete: bool = False) -> None:
    """Raise a DesignError naming the first mode that is not stable and that no input reaches (PBH).

    Examples
    --------
    >>> require_stabilizable([[1.0, 0.0], [0.0, -2.0]], [[0.0], [1.0]], "sys", ["a", "b"])
    Traceback (most recent call last):
    ...
    quadctl.errors.DesignError: sys: not stabilizable: the mode at eigenvalue 1 (in a) is unstable and no input ...
    """
    mode = unstabilizable_mode(A, B, state_names, discrete=discrete, name=name)
    if mode is not None:
        raise DesignError(_not_stabilizable(name, mode, discrete))


def _not_stabilizable(name: str, mode, discrete: bool) -> str:
    # a config's subsystem is fixed by its partition; a caller's own (A, B) by B (qc.lqr has no partition)
    fix = ("change the partition so an input drives those states" if name.startswith("subsystem ")
           else "give B an input that drives those states, or leave that mode out of A")
    return (f"{name}: not stabilizable: the mode at eigenvalue {_fmt(mode.eigenvalue, discrete)} "
            f"(in {', '.join(mode.states)}) is unstable and no input reaches it; {fix}")


def _fmt(e: complex, discrete: bool = False, digits: int = 4) -> str:
    """``-2.147e-06``, ``-5e-13 + 1j`` (:func:`quadctl.text.messages.eig_text`); discrete: ``z = 0.99`` (10 significant
    digits near the unit circle)."""
    e = complex(e)
    digits = 10 if discrete and abs(abs(e) - 1) < 1e-3 else digits
    text = eig_text(e, digits)
    return f"z = {text}" if discrete else text
