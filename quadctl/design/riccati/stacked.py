"""Stacked Riccati solvers: ``batch`` same-shape problems at once, one LAPACK call per step.

:func:`care_batch` (the stable eigenvectors of the stacked Hamiltonians) and :func:`dare_batch`
(structure-preserving doubling), each followed by Newton steps in defect-correction form, and the
residuals that certify every answer. An entry without an accurate stabilizing answer is marked not
ok, never raised: the one-case solver (:mod:`quadctl.design.riccati.single`) says why.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.design.riccati.doubling import ROUNDOFF_STEPS, doubling
from quadctl.design.riccati.weights import WeightCheck, as_problem, as_stack, neutral, norm1
from quadctl.errors import DesignError
from quadctl.linear import stability
from quadctl.linear.analysis import RICCATI_RTOL

scipy = lazy_import("scipy")  # loaded on first use (then scipy.linalg on access): quadctl._lazy

NEWTON_STEPS = 2
"""Newton steps after the initial solution; both the stacked solvers and the one-case polish
(:func:`quadctl.design.riccati.single.solve`) stop early once the residual is round-off (``ROUNDOFF_RTOL``).
Each squares the relative error of ``P``: two take an eigenvector solution good to 1e-6 to round-off
(seen: a mode at -7e-7 rad/s left SciPy's Schur solution at 6e-8; one step took it to 1.6e-10)."""
KRONECKER_MAX_N = 7
"""Largest ``n`` whose Newton steps solve the Lyapunov/Stein equation as one ``n^2 x n^2`` linear
system (batched over the stack, numpy only); larger ``n`` use Bartels-Stewart
(``scipy.linalg.solve_continuous_lyapunov``, ``solve_discrete_lyapunov``) one entry at a time.
Measured CPU time per entry and step, 1000-entry stacks, one BLAS thread: n = 6: 18 us
(Kronecker) against 40 us; n = 8: 54 against 45; n = 10: 161 against 53 (the Kronecker system
costs n^6, and n = 100 needs 800 MB). One case alone: n = 6: 26 against 45 us, n = 8: 46 against
49. :func:`solve` also takes it as the size above which Laub's Schur method replaces the
eigenvectors for one case (and SciPy is loaded)."""
ROUNDOFF_RTOL = 100 * np.finfo(float).eps
"""A relative residual below this (2.2e-14) is round-off: the stacked solvers, whose Newton steps
are cheap batched calls, stop polishing there. The one-case polish
(:func:`quadctl.design.riccati.single.solve`) stops at ``n`` times this: the worst-case rounding of the
residual's own ``n``-term products (``gamma_n = n eps``, Higham, *Accuracy and Stability of
Numerical Algorithms*, 3.1), where each step is a Bartels-Stewart solve costing a quarter of the
solve (seen: polishing 6.7e-14 at n = 10 to 5e-15 took lqr from 0.40 to 0.57 ms; SciPy: 0.56 ms)."""
SDA_STEPS = 40
"""Doubling steps :func:`dare_batch` takes at most. After ``k`` steps the error of ``P`` shrinks like
``rho^(2^k)``, ``rho`` the closed-loop spectral radius: 40 steps reach round-off for every
``rho <= 1 - UNIT_CIRCLE_MARGIN`` (``2^40 * 1e-9 > 1000``). Stacks stop when every entry is done."""
@dataclass(frozen=True)
class BatchLqr:
    """``batch`` LQR solutions of the same shape (:func:`care_batch`, :func:`dare_batch`).

    Attributes
    ----------
    K : (batch, m, n) ndarray
        Gains, ``u = -K x``.
    P : (batch, n, n) ndarray
        Stabilizing Riccati solutions (symmetric).
    E : (batch, n) complex ndarray
        Eigenvalues of ``A - B K`` (``s`` in rad/s, or ``z`` for the discrete solver).
    residual : (batch,) ndarray
        Relative residual, as :func:`riccati_residuals` (or :func:`dare_residuals`) defines it.
    ok : (batch,) bool ndarray
        The weights are valid, the solution is finite, its residual is at most ``RICCATI_RTOL``
        and its closed loop is stable. Entries that are not ok hold garbage: solve them one by one
        (:func:`quadctl.design.lqr`, :func:`quadctl.design.discrete.dlqr`), which raises the reason.
    """

    K: np.ndarray
    P: np.ndarray
    E: np.ndarray
    residual: np.ndarray
    ok: np.ndarray


def riccati_residuals(A, B, Q, R, P, N=None) -> np.ndarray:
    """Relative CARE residuals of stacked problems, ``(batch,)`` (NaN where ``P`` is not finite).

    ``|A'P + PA - G R^-1 G' + Q|_1 / (|A'P|_1 + |PA|_1 + |G R^-1 G'|_1 + |Q|_1)`` with
    ``G = PB + N`` and ``|.|_1`` the matrix 1-norm.
    """
    A, B, Q, R, N = as_stack(A, B, Q, R, N, name="riccati_residuals")
    with np.errstate(all="ignore"):
        return _relative(*_residual(False, A, B, Q, R, N, np.asarray(P, dtype=float)))


def dare_residuals(A, B, Q, R, P, N=None) -> np.ndarray:
    """Relative DARE residuals of stacked problems, ``(batch,)`` (NaN where ``P`` is not finite).

    ``|A'PA - P - G (R + B'PB)^-1 G' + Q|_1 / (|A'PA|_1 + |P|_1 + |G (R + B'PB)^-1 G'|_1 + |Q|_1)``
    with ``G = A'PB + N``.
    """
    A, B, Q, R, N = as_stack(A, B, Q, R, N, name="dare_residuals")
    with np.errstate(all="ignore"):
        return _relative(*_residual(True, A, B, Q, R, N, np.asarray(P, dtype=float)))


def _residual(discrete: bool, A, B, Q, R, N, P):
    """The residual matrices of stacked ``P`` and their four terms (for the relative norm)."""
    At = A.transpose(0, 2, 1)
    if discrete:
        G = At @ P @ B + N
        terms = (At @ P @ A, P, G @ _solve(R + B.transpose(0, 2, 1) @ P @ B, G.transpose(0, 2, 1))[0], Q)
        return terms[0] - terms[1] - terms[2] + terms[3], terms
    G = P @ B + N
    terms = (At @ P, P @ A, G @ _solve(R, G.transpose(0, 2, 1))[0], Q)
    return terms[0] + terms[1] - terms[2] + terms[3], terms


def riccati_residual(A, B, Q, R, P, N=None) -> float:
    """Relative CARE residual at ``P`` (0 for an exact solution): :func:`riccati_residuals` of one problem.

    Examples
    --------
    >>> riccati_residual([[0.0]], [[1.0]], [[1.0]], [[1.0]], [[1.0]])  # x' = u, q = r = 1: P = 1
    0.0
    """
    A, B, Q, R, N = as_problem(A, B, Q, R, N, name="riccati_residual")
    return float(riccati_residuals(A[None], B[None], Q[None], R[None], np.atleast_2d(P)[None], N[None])[0])


def dare_residual(A, B, Q, R, P, N=None) -> float:
    """Relative DARE residual at ``P`` (0 for an exact solution): :func:`dare_residuals` of one problem."""
    A, B, Q, R, N = as_problem(A, B, Q, R, N, name="dare_residual")
    return float(dare_residuals(A[None], B[None], Q[None], R[None], np.atleast_2d(P)[None], N[None])[0])


def _relative(res, terms) -> np.ndarray:
    """``|res|_1 / sum |term|_1`` per stacked entry."""
    scale = sum(norm1(t) for t in terms)
    return norm1(res) / np.where(scale > 0, scale, 1.0)


def care_batch(A, B, Q, R, N=None) -> BatchLqr:
    """Solve ``batch`` continuous algebraic Riccati equations at once (MATLAB ``lqr`` conventions).

    The ``n`` stable eigenvectors ``[U1; U2]`` of each Hamiltonian ``[[A~, -S], [-Q~, -A~']]``
    (``S = B R^-1 B'``, ``A~``, ``Q~`` without the cross term) give ``P = U2 U1^-1``; then up to
    :data:`NEWTON_STEPS` Newton-Kleinman steps in defect-correction form (:func:`newton_correction`).
    Each step is one batched LAPACK call over the stack (Lyapunov equations by their Kronecker form
    up to :data:`KRONECKER_MAX_N` states, by Bartels-Stewart above).

    Parameters
    ----------
    A : (batch, n, n) array_like
    B : (batch, n, m) array_like
    Q : (batch, n, n) array_like
        Symmetric positive semidefinite.
    R : (batch, m, m) array_like
        Symmetric positive definite.
    N : (batch, n, m) array_like, optional
        Cross weight; ``[[Q, N], [N', R]]`` positive semidefinite.

    Returns
    -------
    BatchLqr
        Check ``ok``: invalid weights, a Hamiltonian with eigenvalues on the imaginary axis (an
        unstabilizable or undetectable mode) or a defective one leave an entry not ok.

    Raises
    ------
    ArgumentError
        A matrix is not numeric, or the shapes do not stack (named).
    DesignError
        The stack does not fit in memory.

    Examples
    --------
    Scalar integrators ``x' = u``: ``P = sqrt(q r)``, ``K = sqrt(q / r)``.

    >>> res = care_batch([[[0.0]]] * 2, [[[1.0]]] * 2, [[[4.0]], [[9.0]]], [[[1.0]]] * 2)
    >>> res.P.ravel().round(12).tolist(), res.ok.tolist()
    ([2.0, 3.0], [True, True])
    """
    A, B, Q, R, N = as_stack(A, B, Q, R, N, name="care_batch")
    if len(B) == 0:
        return _empty(*B.shape[1:])
    valid = WeightCheck(A, B, Q, R, N).ok
    try:
        return care_checked(*neutral(valid, A, B, Q, R, N), valid)
    except MemoryError as exc:
        raise _out_of_memory("care_batch", B.shape, exc) from None


def care_checked(A, B, Q, R, N, valid) -> BatchLqr:
    """:func:`care_batch` of checked stacks (``valid``: the entries whose weights passed)."""
    n = B.shape[1]
    with np.errstate(all="ignore"):
        At, Qt, RinvBt, solved = without_cross(A, B, Q, R, N)
        H, finite = _finite(np.block([[At, -B @ RinvBt], [-Qt, -At.transpose(0, 2, 1)]]))
        (w, V), converged = _each_eig(np.linalg.eig, H)
        finite &= converged
        order = np.argsort(w.real, axis=1)[:, :n]                     # the n most stable
        U = np.take_along_axis(V, order[:, None, :], axis=2)
        ok = valid & solved & finite & (stability.in_open_left_half_plane(w).sum(axis=1) == n)
        Pt, solved = _solve(U[:, :n].transpose(0, 2, 1), U[:, n:].transpose(0, 2, 1))
        P = _sym(Pt.transpose(0, 2, 1).real)
        return _finish(False, A, B, Q, R, N, P, ok & solved)


def dare_batch(A, B, Q, R, N=None, *, compiled: bool = False) -> BatchLqr:
    """Solve ``batch`` discrete algebraic Riccati equations at once (MATLAB ``dlqr`` conventions).

    Structure-preserving doubling on the problem without cross term: from ``A0 = A~``,
    ``G0 = B R^-1 B'``, ``H0 = Q~``, with ``W = I + Gk Hk``::

        A(k+1) = Ak W^-1 Ak,   G(k+1) = Gk + Ak W^-1 Gk Ak',   H(k+1) = Hk + Ak' Hk W^-1 Ak,

    ``Hk`` converges quadratically to ``P`` (``W`` is never singular: ``Gk Hk`` has no negative
    eigenvalue). Then up to :data:`NEWTON_STEPS` Newton-Hewer steps in defect-correction form
    (:func:`newton_correction`), each a Stein equation (Kronecker form up to
    :data:`KRONECKER_MAX_N` states, SciPy's ``solve_discrete_lyapunov`` above).

    Parameters
    ----------
    A : (batch, n, n) array_like
        Discrete state matrices.
    B : (batch, n, m) array_like
    Q : (batch, n, n) array_like
        Symmetric positive semidefinite.
    R : (batch, m, m) array_like
        Symmetric positive definite.
    N : (batch, n, m) array_like, optional
        Cross weight; ``[[Q, N], [N', R]]`` positive semidefinite.
    compiled : bool
        Take the doubling steps in compiled C when a C compiler is at hand
        (:mod:`quadctl.design.riccati.doubling`: a tenth of numpy's time on 2- and 3-state problems; the
        same ``P`` to round-off). A sweep's designs do; a one-case design keeps numpy's steps, so
        its numbers (and the order LAPACK gives its loop's eigenvalues) stay those of earlier runs.

    Returns
    -------
    BatchLqr
        ``E`` holds the eigenvalues ``z`` of ``A - B K``; ``residual`` is :func:`dare_residuals`.

    Raises
    ------
    ArgumentError
        A matrix is not numeric, or the shapes do not stack (named).
    DesignError
        The stack does not fit in memory.

    Examples
    --------
    The sampled integrator ``x[k+1] = x[k] + u[k]`` with ``q = r = 1``: ``P`` is the golden ratio.

    >>> res = dare_batch([[[1.0]]], [[[1.0]]], [[[1.0]]], [[[1.0]]])
    >>> round(float(res.P[0, 0, 0]), 12), res.ok.tolist()
    (1.61803398875, [True])
    """
    A, B, Q, R, N = as_stack(A, B, Q, R, N, name="dare_batch")
    if len(B) == 0:
        return _empty(*B.shape[1:])
    valid = WeightCheck(A, B, Q, R, N).ok
    try:
        return dare_checked(*neutral(valid, A, B, Q, R, N), valid, compiled)
    except MemoryError as exc:
        raise _out_of_memory("dare_batch", B.shape, exc) from None


def _out_of_memory(who: str, shape, exc) -> DesignError:
    batch, n, m = shape
    return DesignError(f"{who}: out of memory for {batch} problems of {n} states and {m} inputs ({exc}); "
                       "solve them in smaller stacks")


def dare_checked(A, B, Q, R, N, valid, compiled: bool = False) -> BatchLqr:
    """:func:`dare_batch` of checked stacks (``valid``: the entries whose weights passed)."""
    n = B.shape[1]
    with np.errstate(all="ignore"):
        Ak, Hk, RinvBt, solved = without_cross(A, B, Q, R, N)
        Gk = _sym(B @ RinvBt)
        ok = valid & solved
        stepped = doubling(Ak, Gk, Hk, SDA_STEPS) if compiled else None
        if stepped is not None:
            Hk = stepped
        else:
            eye = np.eye(n)
            for _ in range(SDA_STEPS):
                X, _ = _solve(eye + Gk @ Hk, np.concatenate([Ak, Gk], axis=2))
                X1, X2 = X[:, :, :n], X[:, :, n:]
                At = Ak.transpose(0, 2, 1)
                step = At @ Hk @ X1
                Hk = _sym(Hk + step)
                Gk = _sym(Gk + Ak @ X2 @ At)
                Ak = Ak @ X1
                # done when every step is round-off of H (a NaN entry has failed: decided after the loop)
                if not np.any(np.abs(step).max(axis=(1, 2))
                              > ROUNDOFF_STEPS * np.finfo(float).eps * np.abs(Hk).max(axis=(1, 2))):
                    break
        Hk, finite = _finite(Hk)
        return _finish(True, A, B, Q, R, N, Hk, ok & finite)


def _finish(discrete: bool, A, B, Q, R, N, P, ok) -> BatchLqr:
    """Newton steps from ``P``, then gains, loop eigenvalues, residuals and the ``ok`` verdict."""
    K, F, residual, solved = gain_and_residual(discrete, A, B, Q, R, N, P)
    for _ in range(NEWTON_STEPS):
        if np.all(residual <= ROUNDOFF_RTOL):  # nothing left to polish (NaN: not finished)
            break
        D, done = newton_correction(discrete, A, B, K, F)
        P_next = P + D
        good = done & np.all(np.isfinite(P_next), axis=(1, 2))
        P = np.where(good[:, None, None], P_next, P)
        K, F, residual, solved = gain_and_residual(discrete, A, B, Q, R, N, P)
    A_cl, finite = _finite(A - B @ K)
    E, converged = _each_eig(np.linalg.eigvals, A_cl)
    E = E.astype(complex, copy=False)  # as documented: NumPy gives floats when every eigenvalue is real
    finite &= converged
    finite &= np.all(np.isfinite(P), axis=(1, 2))
    ok = ok & solved & finite & all_stable(discrete, E) & (residual <= RICCATI_RTOL)
    return BatchLqr(K=K, P=P, E=E, residual=residual, ok=ok)


def all_stable(discrete: bool, E) -> np.ndarray:
    """Whether every eigenvalue of each row of ``E`` (..., n) is stable (:func:`quadctl.linear.stability.is_stable`)."""
    return np.all(stability.is_stable(E, discrete=discrete), axis=-1)


def gain_and_residual(discrete: bool, A, B, Q, R, N, P):
    """Of stacked ``P``: the gain ``K``, the residual matrix ``F``, the relative residual, and
    which gains were solved."""
    K, solved = _gain(discrete, A, B, R, N, P)
    F, terms = _residual(discrete, A, B, Q, R, N, P)
    return K, F, _relative(F, terms), solved


def newton_correction(discrete: bool, A, B, K, F):
    """The Newton correction ``D`` (Kleinman, or Hewer for the DARE) of stacked solutions whose gain
    is ``K`` and residual matrix ``F``, and which were solved.

    Defect-correction form: ``Ac' D + D Ac + F = 0`` (or ``D = Ac' D Ac + F``) with
    ``Ac = A - B K``, then ``P + D``. Mathematically the step of Kleinman's
    ``Ac' P_next + P_next Ac + Q + K'RK - NK - K'N' = 0``, but the equation's conditioning then
    limits only the small correction, not ``P`` (seen: CAREX 4.4, whose lightly damped modes make
    the Lyapunov equation nearly singular, stalls at 6e-8 in Kleinman's form, reaches 2e-11 in this).
    """
    Ac, finite = _finite(A - B @ K)
    F, residual_finite = _finite(_sym(F))
    D, done = (_stein if discrete else _lyapunov)(Ac, F)
    return _sym(D), finite & residual_finite & done


def without_cross(A, B, Q, R, N):
    """``A - B R^-1 N'``, ``Q - N R^-1 N'``, ``R^-1 B'`` and which ``R`` were solved."""
    n = B.shape[1]
    X, solved = _solve(R, np.concatenate([B, N], axis=1).transpose(0, 2, 1))
    RinvBt, RinvNt = X[:, :, :n], X[:, :, n:]
    return A - B @ RinvNt, _sym(Q - N @ RinvNt), RinvBt, solved


def _gain(discrete: bool, A, B, R, N, P):
    """``K`` of stacked solutions ``P``, and which were solved."""
    Bt = B.transpose(0, 2, 1)
    if discrete:
        return _solve(R + Bt @ P @ B, Bt @ P @ A + N.transpose(0, 2, 1))
    return _solve(R, Bt @ P + N.transpose(0, 2, 1))


def _lyapunov(Ac, W):
    """Stacked solutions of ``Ac' X + X Ac + W = 0``, and which were solved."""
    batch, n, _ = Ac.shape
    if n <= KRONECKER_MAX_N:
        # vec(Ac' X + X Ac) = (I kron Ac' + Ac' kron I) vec(X), vec stacking columns
        eye, Act = np.eye(n), Ac.transpose(0, 2, 1)
        L = (np.einsum("ij,bkl->bikjl", eye, Act) + np.einsum("bij,kl->bikjl", Act, eye)).reshape(batch, n * n, n * n)
        vec, solved = _solve(L, -W.transpose(0, 2, 1).reshape(batch, n * n, 1))
        return vec.reshape(batch, n, n).transpose(0, 2, 1), solved
    return _each(lambda a, w: scipy.linalg.solve_continuous_lyapunov(a.T, -w), Ac, W)


def _stein(Ac, W):
    """Stacked solutions of ``X = Ac' X Ac + W``, and which were solved."""
    batch, n, _ = Ac.shape
    if n <= KRONECKER_MAX_N:
        # vec(Ac' X Ac) = (Ac' kron Ac') vec(X)
        Act = Ac.transpose(0, 2, 1)
        L = np.eye(n * n) - np.einsum("bij,bkl->bikjl", Act, Act).reshape(batch, n * n, n * n)
        vec, solved = _solve(L, W.transpose(0, 2, 1).reshape(batch, n * n, 1))
        return vec.reshape(batch, n, n).transpose(0, 2, 1), solved
    return _each(lambda a, w: scipy.linalg.solve_discrete_lyapunov(a.T, w), Ac, W)


def _each(solve_one, Ac, W):
    """``solve_one`` per stacked entry (Bartels-Stewart); NaN and not solved where it fails."""
    out = np.full(W.shape, np.nan)
    solved = np.zeros(len(W), dtype=bool)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # SciPy's near-singularity warnings: the residual check decides
        for k in range(len(W)):
            try:
                out[k] = solve_one(Ac[k], W[k])
                solved[k] = True
            except (np.linalg.LinAlgError, ValueError):
                pass
    return out, solved


def _empty(n: int, m: int) -> BatchLqr:
    return BatchLqr(np.zeros((0, m, n)), np.zeros((0, n, n)), np.zeros((0, n), complex), np.zeros(0),
                    np.zeros(0, dtype=bool))


def _sym(M):
    return (M + M.transpose(0, 2, 1)) / 2


def _finite(M) -> tuple[np.ndarray, np.ndarray]:
    """A stack with its non-finite members zeroed (LAPACK refuses NaN), and which were finite."""
    finite = np.all(np.isfinite(M), axis=(-2, -1))
    return (M if finite.all() else np.where(finite[:, None, None], M, 0.0)), finite


def _each_eig(eig, M):
    """``eig(M)`` of a stack that survives members whose QR iteration does not converge: (the
    results, with NaN for those members, and which converged). numpy refuses the whole stack."""
    try:
        return eig(M), np.ones(len(M), dtype=bool)
    except np.linalg.LinAlgError:
        converged = np.ones(len(M), dtype=bool)
        parts = []
        for k in range(len(M)):
            try:
                parts.append(eig(M[k]))
            except np.linalg.LinAlgError:
                converged[k] = False
                parts.append(eig(np.zeros_like(M[k])))
        if isinstance(parts[0], tuple):
            out = tuple(np.stack([p[i] for p in parts]).astype(complex) for i in range(2))
            out[0][~converged] = np.nan
        else:
            out = np.stack(parts).astype(complex)
            out[~converged] = np.nan
        return out, converged


def _solve(M, rhs) -> tuple[np.ndarray, np.ndarray]:
    """Stacked ``solve(M, rhs)`` that survives singular members: (solutions, which were solved).

    numpy refuses the whole stack when one matrix is singular; then each is solved alone and a
    singular one gets NaN (its entry is then not ok, and the one-case solver explains why).
    """
    try:
        return np.linalg.solve(M, rhs), np.ones(len(M), dtype=bool)
    except np.linalg.LinAlgError:
        out = np.full(np.broadcast_shapes(M.shape[:-2], rhs.shape[:-2]) + rhs.shape[-2:],
                      np.nan, dtype=np.result_type(M, rhs))
        solved = np.zeros(len(M), dtype=bool)
        for k in range(len(M)):
            try:
                out[k] = np.linalg.solve(M[k], rhs[k])
                solved[k] = True
            except np.linalg.LinAlgError:
                pass
        return out, solved


