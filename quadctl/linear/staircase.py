"""The controllable subspace by the orthogonal controllability staircase, with a stated rank tolerance.

An orthogonal ``Q`` brings ``(A, B)`` to ``Q^T A Q = [[A_cc, A_cu], [0, A_uu]]``, ``Q^T B = [[B_c], [0]]``
with ``(A_cc, B_c)`` controllable, by rank decisions on blocks of ``B`` and ``A`` alone (Van Dooren [1]_,
the algorithm of SLICOT's AB01ND and MATLAB's ``ctrbf``). No eigenvalue is computed to find the
controllable dimension, so a mode no input reaches is found even where its computed eigenvalue is far
off (a nearly defective block of ``A``), which the PBH test at that eigenvalue can miss.

References
----------
.. [1] P. Van Dooren, "The generalized eigenstructure problem in linear system theory", IEEE
   Transactions on Automatic Control 26(1), 111-129, 1981.
.. [2] P.-A. Wedin, "Perturbation bounds in connection with singular value decomposition", BIT 12,
   99-111, 1972.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Staircase:
    """The staircase form of ``(A, B)``; unpacks as ``nc, Q, eigenvalues``.

    Attributes
    ----------
    controllable_dim : int
        ``nc``, the dimension of the controllable subspace (the first ``nc`` columns of ``Q``).
    transform : (n, n) ndarray
        ``Q``, orthogonal.
    A : (n, n) ndarray
        ``Q^T A Q``, its block below the staircase (rows ``nc:``, columns ``:nc``) exactly zero.
    B : (n, m) ndarray
        ``Q^T B``, rows ``nc:`` exactly zero.
    steps : tuple of int
        The rank found at each step (``B``'s first, then each block of ``A``); they sum to ``nc``.
    tolerance : tuple of float
        Each step's rank tolerance (:func:`staircase`), the last step's too when it found no rank.
    uncontrollable_eigenvalues : (n - nc,) complex ndarray
        The eigenvalues of ``A_uu``: the modes no input reaches.
    uncontrollable_directions : (n, n - nc) ndarray
        Their left eigenvectors of ``A`` (``y^H A = lambda y^H``, ``y^H B = 0``), unit length, in the
        order of the eigenvalues.
    """

    controllable_dim: int
    transform: np.ndarray
    A: np.ndarray
    B: np.ndarray
    steps: tuple[int, ...]
    tolerance: tuple[float, ...]
    uncontrollable_eigenvalues: np.ndarray
    uncontrollable_directions: np.ndarray

    def __iter__(self):
        return iter((self.controllable_dim, self.transform, self.uncontrollable_eigenvalues))


def staircase(A, B) -> Staircase:
    """The orthogonal controllability staircase of ``(A, B)``.

    The first step takes the SVD of ``B``: its left singular vectors above the tolerance span the states
    the inputs drive directly. Each next step takes the SVD of the block of (the transformed) ``A`` that
    maps the states found by the last step into those not found yet, and adds the directions it reaches.
    The search ends when a step adds none (the rest is ``A_uu``) or every state is found.

    Each step's rank counts the singular values above a tolerance. ``B``'s is ``(n + m) eps ||B||_2``,
    the rule of :func:`quadctl.linear.analysis.numerical_rank` with ``max(shape)`` of ``[A, B]``. A block of
    ``A``'s is ``||A||_2 (d + (n + m) eps)``: ``(n + m) eps ||A||`` is the round-off of the block itself
    (the orthogonal transformations make it exact for an ``A + E``, ``||E|| ~ eps ||A||``), and ``d``, the
    drift, adds each earlier step's tolerance over the smallest singular value it kept: the basis found
    so far is off by up to that angle (Wedin's bound [2]_), and ``A`` carries that error into the next block.
    Without it, a weak earlier step (a singular value of ``1e-2 ||A||``) passes round-off ten times
    ``(n + m) eps ||A||`` as a rank, and states no input reaches are counted reached. A block's own largest
    singular value would not do as the scale either: a block of round-off alone would have rank 1 by it.
    Scaling the inputs (``B`` by ``c``) changes no decision.

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like

    Returns
    -------
    Staircase

    Raises
    ------
    ValueError
        When ``A`` is not square, or ``B`` has not ``n`` rows.

    Examples
    --------
    The second state of ``x1' = -x1 + u``, ``x2' = 2 x2`` is out of reach; its mode is 2:

    >>> nc, Q, lost = staircase([[-1.0, 0.0], [0.0, 2.0]], [[1.0], [0.0]])
    >>> nc, lost.tolist()
    (1, [(2+0j)])
    """
    A = np.array(A, dtype=float, ndmin=2)
    B = np.array(B, dtype=float, ndmin=2)
    n = A.shape[0]
    if A.shape != (n, n):
        raise ValueError(f"A must be square; got shape {A.shape}")
    if B.shape[0] != n:
        raise ValueError(f"B must have {n} rows (A is {n} x {n}); got shape {B.shape}")
    eps = np.finfo(float).eps
    factor = (n + B.shape[1]) * eps
    norm_a = np.linalg.norm(A, 2) if A.size else 0.0
    Q = np.eye(n)
    steps: list[int] = []
    tolerances: list[float] = []
    found, last = 0, 0  # states found so far; where the last step's begin
    block, tol, drift = B, factor * (np.linalg.norm(B, 2) if B.size else 0.0), 0.0
    while found < n:
        u, sv, _ = np.linalg.svd(block)
        rank = int((sv > tol).sum())
        tolerances.append(float(tol))
        if rank == 0:
            block[:] = 0.0  # A's block below the staircase (a view), or B
            break
        rest = slice(found, n)
        A[rest, :] = u.T @ A[rest, :]
        A[:, rest] = A[:, rest] @ u
        Q[:, rest] = Q[:, rest] @ u
        if not steps:
            B = u.T @ B
            B[rank:] = 0.0
        else:
            A[found + rank:, last:found] = 0.0
        steps.append(rank)
        drift += tol / sv[rank - 1]
        last, found = found, found + rank
        block, tol = A[found:, last:found], norm_a * (drift + factor)
    eigenvalues, left = np.linalg.eig(A[found:, found:].T)
    directions = Q[:, found:] @ left.conj()
    return Staircase(controllable_dim=found, transform=Q, A=A, B=B, steps=tuple(steps),
                     tolerance=tuple(tolerances), uncontrollable_eigenvalues=eigenvalues.astype(complex),
                     uncontrollable_directions=directions)
