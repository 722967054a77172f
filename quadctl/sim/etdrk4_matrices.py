"""The matrices of one step of the exponential integrator (ETDRK4, :mod:`quadctl.sim.builder`).

The φ-functions of the loop's linear part ``L`` by scaling and squaring (:func:`phi_functions`, and
:func:`expm` alone), carried from step to step up a ladder of steps ``h_min 2^j`` by doubling
(:func:`phi_ladder`), weighted into the stage and step matrices of :data:`quadctl.sim.loop_layout.PHI_LAYOUT`
(:func:`step_matrices`) and laid out as the block that ends the loop's constants (:func:`phi_constants`).
The steps themselves are planned in :mod:`quadctl.sim.etdrk4_plan`.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from quadctl.sim.loop_layout import PHI_LAYOUT

PHI_ACCURACY = 1e-15
"""The φ-functions come from scaling and squaring (:func:`phi_functions`, as :func:`expm` of a block
matrix): the matrix scaled by ``2^-s`` to a 1-norm of at most 1/8, Taylor's series to degree
:data:`TAYLOR_DEGREE` (truncation below ``(1/8)^11 / 11! = 2.9e-18`` relative, under round-off),
doubled ``s`` times; the forward error of each entry is round-off
times the exponential's condition number (tested against SciPy's ``expm`` and the φ-functions'
closed forms to 1e-12)."""
TAYLOR_DEGREE = 10
TAYLOR_NORM = 0.125


def expm(M) -> np.ndarray:
    """``e^M`` by scaling and squaring with a degree-10 Taylor polynomial (:data:`PHI_ACCURACY`); ``M``
    (n, n), or a stack (N, n, n), each matrix scaled and squared by its own norm (the same numbers as
    alone).

    Written here, not SciPy's, so a simulation does not import SciPy (about 0.3 s of a command).
    """
    M = np.asarray(M, dtype=float)
    if M.ndim == 2:
        return expm(M[None])[0]
    norm = np.abs(M).sum(axis=-2).max(axis=-1) if M.size else np.zeros(len(M))
    with np.errstate(divide="ignore"):
        s = np.where(norm > TAYLOR_NORM, np.ceil(np.log2(np.maximum(norm, TAYLOR_NORM) / TAYLOR_NORM)), 0)
    s = s.astype(int)
    A = M / (2.0 ** s)[:, None, None]
    eye = np.eye(M.shape[-1])
    E = np.broadcast_to(eye, M.shape).copy()
    for k in range(TAYLOR_DEGREE, 0, -1):  # Horner: I + A/1 (I + A/2 (I + ...))
        E = eye + (A @ E) / k
    for level in range(int(s.max()) if s.size else 0):
        more = s > level
        E[more] = E[more] @ E[more]
    return E


def phi_functions(L, h: float, order: int = 3) -> list[np.ndarray]:
    """``[e^(hL), φ_1(hL), ..., φ_order(hL)]``, ``φ_k(Z) = sum_j Z^j / (j + k)!``, by scaling and
    squaring carried to the φ-functions (accuracy :data:`PHI_ACCURACY`): ``Z = hL`` scaled by ``2^-s``
    to a 1-norm of at most :data:`TAYLOR_NORM`, each ``φ_k`` its Taylor polynomial of degree
    :data:`TAYLOR_DEGREE` by Horner's rule (the ``order + 1`` of them in one stack), then doubled ``s``
    times (:func:`doubled`). The same arithmetic as :func:`expm` of the block matrix ``[[hL, I, 0..],
    [0, 0, I, ..], ..., [0 .. 0]]``, whose first block row is these (Al-Mohy and Higham, SIAM J. Sci.
    Comput. 33, 2011, Thm 2.1): its squaring is the doubling, its Horner steps the φ's, on ``n x n``
    blocks (on the loop's 12 x 12, a sixteenth of the 48 x 48's flops). One BLAS thread: on matrices
    this small, BLAS's threads only cost (on a loaded 2-core machine, 20 ms against 0.1 ms for a
    48 x 48 exponential).

    Parameters
    ----------
    L : (n, n) array_like, or a stack (N, n, n)
        Each matrix of a stack scaled by its own norm (the same numbers as alone).
    h : float
        s.
    order : int

    Returns
    -------
    list of (n, n) ndarray (or (N, n, n), of each matrix of the stack)
    """
    L = np.asarray(L, dtype=float)
    n = L.shape[-1]
    Z = (h * L).reshape(-1, n, n)
    norm = np.abs(Z).sum(axis=-2).max(axis=-1) if Z.size else np.zeros(len(Z))
    with np.errstate(divide="ignore"):
        s = np.where(norm > TAYLOR_NORM, np.ceil(np.log2(np.maximum(norm, TAYLOR_NORM) / TAYLOR_NORM)), 0)
    s = s.astype(int)
    A = Z / (2.0 ** s)[:, None, None]
    eye = np.eye(n)
    coefficient = np.array([[1 / math.factorial(j + k) for j in range(TAYLOR_DEGREE + 1)] for k in range(order + 1)])
    with _blas().limit(limits=1, user_api="blas"):
        P = np.broadcast_to(eye * coefficient[:, TAYLOR_DEGREE, None, None, None], (order + 1, *Z.shape))
        for j in range(TAYLOR_DEGREE - 1, -1, -1):  # φ_k = 1/k! + A (1/(k+1)! + A (...))
            P = A @ P + eye * coefficient[:, j, None, None, None]
        phis = list(P)
        for level in range(int(s.max()) if s.size else 0):
            more = s > level
            if more.all():
                phis = doubled(phis)
            else:
                for old, new in zip(phis, doubled([M[more] for M in phis])):
                    old[more] = new
    return [M.reshape(L.shape) for M in phis]


@lru_cache(maxsize=1)
def _blas():
    """The process's thread pools (numpy's BLAS), found once (a search costs about a millisecond)."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def doubled(phis: list[np.ndarray]) -> list[np.ndarray]:
    """``[e^(2Z), φ_1(2Z), ..., φ_k(2Z)]`` from the same of ``Z`` (the squaring of scaling and
    squaring, carried to the φ-functions; Skaflestad and Wright, Appl. Numer. Math. 59, 2009)::

        φ_k(2Z) = 2^-k (e^Z φ_k(Z) + sum_{j=1..k} φ_j(Z) / (k - j)!)
    """
    E = phis[0]
    out = [E @ E]
    for k in range(1, len(phis)):
        acc = E @ phis[k]
        for j in range(1, k + 1):
            acc = acc + (phis[j] if k - j < 2 else phis[j] / math.factorial(k - j))
        out.append(acc / 2 ** k)
    return out


RESEED = 5
"""Doublings (:func:`doubled`) between two direct :func:`phi_functions` on the ladder: each doubling
about doubles the relative error (measured on the ``forward`` loop: 3.5e-9 after 25), so 5 keep it
within 32 times expm's (1e-14 relative), while the direct exponentials, which cost most of a
simulation's setup, are one in five rungs."""


def phi_ladder(L, steps) -> dict[float, dict[str, np.ndarray]]:
    """The ETDRK4 matrices (:data:`quadctl.sim.loop_layout.PHI_LAYOUT`) of each step in ``steps``, which
    are ``h_min 2^j``: :func:`phi_functions` at ``h_min / 2``, then up the ladder by :func:`doubled`,
    from a direct :func:`phi_functions` every :data:`RESEED` doublings. ``L`` (n, n), or a stack
    (N, n, n) of linear parts: each matrix of the ladder is then the stack of theirs (the same numbers
    as each alone, computed together).

    Raises
    ------
    ValueError
        A step that is not ``h_min`` times a power of two.
    """
    steps = sorted(set(float(h) for h in steps))
    L = np.asarray(L, dtype=float)
    h = steps[0] / 2
    # the direct rungs (the first and every RESEED-th) in one stacked call: 2^level L at h is hL exactly
    seeds = range(0, max(0, math.ceil(math.log2(steps[-1] / h) - 1e-9)) + 1, RESEED)
    direct = phi_functions(np.stack([L * 2.0 ** level for level in seeds]), h)
    phis = [M[0] for M in direct]
    out: dict[float, dict[str, np.ndarray]] = {}
    level = 0
    for target in steps:
        while h < target * (1 - 1e-12):
            level += 1
            half, h = phis, 2 * h
            phis = [M[level // RESEED] for M in direct] if level % RESEED == 0 else doubled(phis)
            if h > target * (1 + 1e-12):
                raise ValueError(f"step {target!r} s is not {steps[0]!r} s times a power of two")
            if math.isclose(h, target, rel_tol=1e-12):
                out[target] = step_matrices(L, h, half, phis)
    return out


STAGE_WEIGHTS = np.array([
    # psi1   psi2   psi3  phi1  phi2  phi3        (each times h)
    [1 / 2, 0, 0, 0, 0, 0],                      # A21
    [1 / 2, -1, 0, 0, 0, 0],                     # A31
    [0, 1, 0, 0, 0, 0],                          # A32
    [0, 0, 0, 1, -2, 0],                         # A41
    [0, 0, 0, 0, 1, 0],                          # A42
    [1 / 2, -3 / 4, 1 / 2, 0, -1 / 4, 1],        # A51 = h psi1 / 2 - 2 A52 - A54
    [0, 1 / 2, -1 / 2, 0, 1 / 4, -1],            # A52
    [0, -1 / 4, 1 / 2, 0, -1 / 4, 1],            # A54 = h psi2 / 4 - A52
    [0, 0, 0, 1, -3, 4],                         # B1
    [0, 0, 0, 0, -1, 4],                         # B4
    [0, 0, 0, 0, 4, -8]])                        # B5
"""The stage and step weights of :data:`quadctl.sim.loop_layout.PHI_LAYOUT` after ``lin`` as rows of
coefficients of ``(psi1, psi2, psi3, phi1, phi2, phi3)`` (``psi_k = phi_k(hL/2)``), each times ``h``."""


def step_matrices(L, h: float, half: list[np.ndarray], full: list[np.ndarray]) -> dict[str, np.ndarray]:
    """The matrices of one ETDRK4 step ``h`` (:data:`quadctl.sim.loop_layout.PHI_LAYOUT`) from
    ``half = [e^(hL/2), φ_1, φ_2, φ_3 (hL/2)]`` and ``full``, the same of ``hL`` (each (n, n), or a
    stack): the weights :data:`STAGE_WEIGHTS` in one product."""
    weights = np.tensordot(h * STAGE_WEIGHTS, np.stack([*half[1:], *full[1:]]), axes=1)
    return dict(zip(PHI_LAYOUT, [np.asarray(L, dtype=float), *weights]))


def phi_constants(matrices: dict[str, np.ndarray], case: int | None = None) -> np.ndarray:
    """ETDRK4 matrices of one step as the block that ends the loop's ``c`` (column-major, in order);
    ``case``: of that matrix of a stacked ladder."""
    stack = np.stack([matrices[name] if case is None else matrices[name][case] for name in PHI_LAYOUT])
    return np.swapaxes(stack, -1, -2).ravel()


def phi_constant_rows(matrices: dict[str, np.ndarray]) -> np.ndarray:
    """(N, 12 n^2): :func:`phi_constants` of every matrix of a stacked ladder's step, at once."""
    stack = np.stack([matrices[name] for name in PHI_LAYOUT], axis=1)  # (N, 12, n, n): one copy, then one more
    return np.swapaxes(stack, -1, -2).reshape(len(stack), -1)


def phi_pattern(ladder: dict[float, dict[str, np.ndarray]]) -> tuple[bool, ...]:
    """The union of the nonzeros of every ETDRK4 matrix of the ladder (column-major; of every
    matrix of a stacked one)."""
    stack = np.concatenate([M.reshape(-1, *M.shape[-2:]) for mats in ladder.values() for M in mats.values()])
    return tuple((stack != 0).any(axis=0).ravel(order="F").tolist())
