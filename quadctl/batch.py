"""Vectorized numerics for many designs at once: Riccati solves and metrics.

Each function here is the batched twin of a one-case function elsewhere in quadctl and is
tested against it: :func:`care` against ``scipy.linalg.solve_continuous_are`` (and
:func:`quadctl.lqr.lqr`), :func:`summarize_run` against
:func:`quadctl.metrics.summarize`. The batched forms exist because a sweep designs thousands
of 2- and 3-state subsystems, where SciPy's per-call overhead (input checks, balancing, a QZ
of a 2n x 2n pencil: about 0.8 ms a call) dwarfs the arithmetic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl.analysis import RICCATI_RTOL, STABILITY_MARGIN
from quadctl.layout import INPUT_NAMES, POSITION_STATES, STATE_NAMES
from quadctl.metrics import ERROR_FLOOR, SETTLING_BAND

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


def coupled_stability(A_cl, K) -> tuple[list[np.ndarray], np.ndarray]:
    """:func:`quadctl.lqr.closed_loop_stability` of stacked coupled closed loops.

    Parameters
    ----------
    A_cl : (N, 12, 12) array_like
        ``A - B K`` of each case.
    K : (N, 4, 12) array_like

    Returns
    -------
    core : list of (k,) complex ndarray
        Per case, the eigenvalues without the marginal position modes (unregulated positions
        that nothing depends on: their zero eigenvalues are expected, not unstable).
    stable : (N,) bool ndarray
        Every core eigenvalue is in the open left half-plane (``STABILITY_MARGIN``).
    """
    A_cl = np.asarray(A_cl, dtype=float)
    K = np.asarray(K, dtype=float)
    positions = [STATE_NAMES.index(s) for s in POSITION_STATES]
    free = ~np.any(K[:, :, positions] != 0, axis=1) & ~np.any(A_cl[:, :, positions] != 0, axis=1)
    core: list = [None] * len(A_cl)
    stable = np.zeros(len(A_cl), dtype=bool)
    for pattern in {tuple(row) for row in free.tolist()}:
        members = np.nonzero((free == pattern).all(axis=1))[0]
        keep = [i for i in range(len(STATE_NAMES))
                if i not in [p for p, m in zip(positions, pattern) if m]]
        eig = np.linalg.eigvals(A_cl[np.ix_(members, keep, keep)])
        ok = np.all(eig.real < -STABILITY_MARGIN * np.maximum(1.0, np.abs(eig)), axis=1)
        for j, k in enumerate(members):
            core[k] = eig[j]
            stable[k] = ok[j]
    return core, stable


# ---------------------------------------------------------------------------------------
# Metrics


def summarize_run(t, x, u, x_ref, u_trim, Q, R, regulated_states, status) -> dict:
    """:func:`quadctl.metrics.summarize` of one run, vectorized over the states.

    Same definitions and the same numbers (the cost integral to round-off: its quadratic forms
    are summed term by term over the nonzeros of ``Q`` and ``R`` instead of by ``einsum``),
    several times faster on 10 000 samples. Works on the state-major transposes, where every
    reduction runs along contiguous memory, and calls no BLAS (whose threads would fight the
    sweep's worker processes for the cores).

    Parameters
    ----------
    t : (r,) ndarray
        s.
    x : (r, 12) ndarray
        Any memory layout; ``x.T`` contiguous is fastest.
    x_ref : (r, 12) ndarray, or a pair ``(x_trim (12,), x_rate (12,))``
        The reference, or what makes it: ``x_trim + x_rate t`` (cheaper than building it).
    u : (r, 4) ndarray
    u_trim : (4,) ndarray
    Q : (12, 12) ndarray
    R : (4, 4) ndarray
    regulated_states : iterable of str
    status : str

    Returns
    -------
    dict
        The keys of :func:`quadctl.metrics.summarize`.
    """
    t = np.asarray(t, dtype=float)
    if isinstance(x_ref, tuple):
        x_trim, x_rate = (np.asarray(a, dtype=float) for a in x_ref)
        err = np.asarray(x).T - x_trim[:, None]           # (12, r)
        for i in np.nonzero(x_rate)[0]:
            err[i] -= x_rate[i] * t
    else:
        err = np.asarray(x).T - np.asarray(x_ref).T      # (12, r)
    du = np.asarray(u).T - np.asarray(u_trim)[:, None]   # (4, r)
    n = err.shape[1]
    mag = np.abs(err)
    peak = mag.max(axis=1)
    regulated = set(regulated_states)
    out: dict = {"settling_time": {}, "overshoot": {}, "peak_error": {}, "final_error": {}}
    band = np.maximum(SETTLING_BAND * peak, ERROR_FLOOR)
    outside = mag > band[:, None]
    any_out = outside.any(axis=1)
    last = n - 1 - np.argmax(outside[:, ::-1], axis=1)
    e0 = err[:, 0]
    # max(-sign(e0) e) without the product: -min(e) where e0 > 0, max(e) where e0 < 0 (exact)
    past = np.where(e0 > 0, -err.min(axis=1), np.where(e0 < 0, err.max(axis=1), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        over = np.maximum(0.0, past) / np.abs(e0) * 100.0
    for i, name in enumerate(STATE_NAMES):
        out["peak_error"][name] = float(peak[i])
        out["final_error"][name] = float(err[i, -1])
        if name in regulated:
            if peak[i] <= ERROR_FLOOR or not any_out[i]:
                settle = 0.0
            elif last[i] == n - 1:
                settle = None
            else:
                settle = float(t[last[i] + 1])
            out["settling_time"][name] = settle
            out["overshoot"][name] = None if abs(e0[i]) <= ERROR_FLOOR else float(over[i])
    out["peak"] = {name: float(v) for name, v in zip(INPUT_NAMES, np.abs(np.asarray(u).T).max(axis=1))}
    with np.errstate(all="ignore"):
        integrand = _quadratic(err, np.asarray(Q, dtype=float)) + _quadratic(du, np.asarray(R, dtype=float))
        cost = float(np.sum((integrand[1:] + integrand[:-1]) * np.diff(t)) / 2) if n > 1 else 0.0
    out["cost"] = cost if math.isfinite(cost) else None
    out["status"] = status
    return out


def _quadratic(vT: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``v_k^T M v_k`` for each column ``v_k`` of ``vT`` (n, r), summed over the nonzeros of ``M``."""
    acc = np.zeros(vT.shape[1])
    term = np.empty(vT.shape[1])
    for i, j in zip(*np.nonzero(M)):
        np.multiply(vT[i], vT[j], out=term)
        term *= M[i, j]
        acc += term
    return acc
