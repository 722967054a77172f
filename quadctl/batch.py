"""Vectorized numerics for many designs at once: Riccati solves and metrics.

Each function here is the batched twin of a one-case function elsewhere in quadctl and is
tested against it: :func:`care` against ``scipy.linalg.solve_continuous_are`` (and
:func:`quadctl.lqr.lqr`), :func:`summarize_run` against
:func:`quadctl.metrics.summarize`. The batched forms exist because a sweep designs thousands
of 2- and 3-state subsystems, where SciPy's per-call overhead (input checks, balancing, a QZ
of a 2n x 2n pencil: about 0.8 ms a call) dwarfs the arithmetic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.analysis import RICCATI_RTOL, STABILITY_MARGIN

NEWTON_STEPS = 2
"""Newton-Kleinman refinements after the eigenvector solution: each squares the relative error
of ``P``, so two take an eigenvector solution good to 1e-6 to round-off."""


@dataclass(frozen=True)
class BatchLqr:
    """``N`` LQR solutions of the same shape.

    Attributes
    ----------
    K : (N, m, n) ndarray
        Gains, ``u = -K x``.
    P : (N, n, n) ndarray
        Stabilizing CARE solutions (symmetric).
    E : (N, n) ndarray
        Closed-loop eigenvalues of ``A - B K`` (complex).
    residual : (N,) ndarray
        Relative CARE residual, as :func:`quadctl.lqr.riccati_residual` defines it.
    ok : (N,) bool ndarray
        The solution is finite, its residual is at most ``RICCATI_RTOL`` and its closed loop
        is stable. Entries that are not ok hold garbage: solve them one by one with
        :func:`quadctl.lqr.lqr`, which raises the reason (not stabilizable, not detectable...).
    """

    K: np.ndarray
    P: np.ndarray
    E: np.ndarray
    residual: np.ndarray
    ok: np.ndarray


def care(A, B, Q, R) -> BatchLqr:
    """Solve ``N`` continuous algebraic Riccati equations at once (MATLAB ``lqr`` conventions).

    ``A^T P + P A - P B R^-1 B^T P + Q = 0`` for each stacked problem. Method: the ``n``
    stable eigenvectors ``[U1; U2]`` of the Hamiltonian ``[[A, -S], [-Q, -A^T]]``
    (``S = B R^-1 B^T``) give ``P = U2 U1^-1`` (Laub's method with eigenvectors instead of
    Schur vectors), then :data:`NEWTON_STEPS` Newton-Kleinman steps, each a Lyapunov solve
    ``Ac^T P + P Ac = -(Q + K^T R K)`` by its ``n^2 x n^2`` Kronecker form, polish ``P`` to
    round-off. Every step is one batched LAPACK call over the stack.

    Parameters
    ----------
    A : (N, n, n) array_like
    B : (N, n, m) array_like
    Q : (N, n, n) array_like
        Symmetric positive semidefinite.
    R : (N, m, m) array_like
        Symmetric positive definite.

    Returns
    -------
    BatchLqr
        Check ``ok``: the method has no answer for a Hamiltonian with eigenvalues on the
        imaginary axis (an undetectable or unstabilizable mode) or a defective one.

    Examples
    --------
    Scalar integrators ``x' = u``: ``P = sqrt(q r)``, ``K = sqrt(q / r)``.

    >>> res = care([[[0.0]]] * 2, [[[1.0]]] * 2, [[[4.0]], [[9.0]]], [[[1.0]]] * 2)
    >>> res.P.ravel().round(12).tolist(), res.ok.tolist()
    ([2.0, 3.0], [True, True])
    """
    A, B, Q, R = (np.asarray(m, dtype=float) for m in (A, B, Q, R))
    N, n, m = B.shape
    if A.shape != (N, n, n) or Q.shape != (N, n, n) or R.shape != (N, m, m):
        raise ValueError(f"care: shapes A {A.shape}, B {B.shape}, Q {Q.shape}, R {R.shape} "
                         "do not stack as (N, n, n), (N, n, m), (N, n, n), (N, m, m)")
    if N == 0:
        empty = np.zeros((0,))
        return BatchLqr(np.zeros((0, m, n)), np.zeros((0, n, n)), np.zeros((0, n), complex), empty,
                        empty.astype(bool))
    At = A.transpose(0, 2, 1)
    Bt = B.transpose(0, 2, 1)
    with np.errstate(all="ignore"):
        RinvBt, solved = _solve(R, Bt)                               # (N, m, n)
        S = B @ RinvBt
        H = np.block([[A, -S], [-Q, -At]])
        H, finite = _finite(H)
        w, V = np.linalg.eig(H)
        order = np.argsort(w.real, axis=1)[:, :n]                     # the n most stable
        n_stable = (w.real < 0).sum(axis=1)
        U = np.take_along_axis(V, order[:, None, :], axis=2)
        U1, U2 = U[:, :n, :], U[:, n:, :]
        ok = solved & finite & (n_stable == n)
        Pt, solved = _solve(U1.transpose(0, 2, 1), U2.transpose(0, 2, 1))
        ok &= solved
        P = Pt.transpose(0, 2, 1).real
        P = (P + P.transpose(0, 2, 1)) / 2
        eye = np.eye(n)
        for _ in range(NEWTON_STEPS):
            K = RinvBt @ P
            Ac = A - B @ K
            rhs = -(Q + K.transpose(0, 2, 1) @ R @ K)
            # vec(Ac^T P + P Ac) = (I kron Ac^T + Ac^T kron I) vec(P), vec stacking columns
            Act = Ac.transpose(0, 2, 1)
            L = (np.einsum("ij,nkl->nikjl", eye, Act) + np.einsum("nij,kl->nikjl", Act, eye))
            L = L.reshape(N, n * n, n * n)
            vec, solved = _solve(L, rhs.transpose(0, 2, 1).reshape(N, n * n, 1))
            P_new = vec.reshape(N, n, n).transpose(0, 2, 1)
            P_new = (P_new + P_new.transpose(0, 2, 1)) / 2
            good = solved & np.all(np.isfinite(P_new), axis=(1, 2))
            P = np.where(good[:, None, None], P_new, P)
        K = RinvBt @ P
        A_cl, finite = _finite(A - B @ K)
        E = np.linalg.eigvals(A_cl)
        ok &= finite
        residual = riccati_residuals(A, B, Q, R, P)
    finite = np.all(np.isfinite(P), axis=(1, 2)) & np.all(np.isfinite(K), axis=(1, 2))
    stable = np.all(E.real < -STABILITY_MARGIN * np.maximum(1.0, np.abs(E)), axis=1)
    ok = ok & finite & stable & (residual <= RICCATI_RTOL)
    return BatchLqr(K=K, P=P, E=E, residual=residual, ok=ok)


def _finite(M) -> tuple[np.ndarray, np.ndarray]:
    """A stack with its non-finite members zeroed (LAPACK refuses NaN), and which were finite."""
    finite = np.all(np.isfinite(M), axis=(-2, -1))
    return (M if finite.all() else np.where(finite[:, None, None], M, 0.0)), finite


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


def riccati_residuals(A, B, Q, R, P) -> np.ndarray:
    """Relative CARE residuals of stacked problems: :func:`quadctl.lqr.riccati_residual` per entry.

    ``|A^T P + P A - P S P + Q|_1 / (|A^T P|_1 + |P A|_1 + |P S P|_1 + |Q|_1)``, with ``|.|_1``
    the matrix 1-norm and ``S = B R^-1 B^T``. Returns ``(N,)``; NaN where ``P`` is not finite.
    """
    A, B, Q, R, P = (np.asarray(m, dtype=float) for m in (A, B, Q, R, P))
    BRB = B @ _solve(R, B.transpose(0, 2, 1))[0]
    terms = (A.transpose(0, 2, 1) @ P, P @ A, P @ BRB @ P, Q)
    res = terms[0] + terms[1] - terms[2] + terms[3]

    def norm1(M):
        return np.abs(M).sum(axis=1).max(axis=1)

    scale = sum(norm1(t) for t in terms)
    scale = np.where(scale > 0, scale, 1.0)
    return norm1(res) / scale
