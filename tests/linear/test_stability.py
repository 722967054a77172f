"""The one stability predicate and the one marginal-mode rule (quadctl.linear.stability)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadctl.layout import STATE_INDEX
from quadctl.linear import stability


def test_unstable_coupled_loop_is_detected():
    """Two states each stable alone (-1), destabilized by couplings: eigenvalues -1 +- sqrt(50)."""
    A_cl = -np.eye(12)
    A_cl[3, 4], A_cl[4, 3] = 10.0, 5.0
    K = np.ones((4, 12))  # every state fed back: no marginal positions
    verdict = stability.assess(A_cl, K)
    assert not verdict.stable and verdict.marginal == ()
    assert max(e.real for e in verdict.eigenvalues) == pytest.approx(-1 + math.sqrt(50))


def test_free_positions_are_marginal_and_left_out_of_the_verdict():
    """pN and pE with zero columns and no gain: two exact zeros, reported, not counted."""
    A_cl = -np.eye(12)
    K = np.ones((4, 12))
    for s in ("pN", "pE"):
        A_cl[:, STATE_INDEX[s]] = 0.0
        K[:, STATE_INDEX[s]] = 0.0
    verdict = stability.assess(A_cl, K)
    assert verdict.marginal == ("pN", "pE") and verdict.stable
    assert len(verdict.core) == 10 and np.all(verdict.core.real == -1.0)
    # a gain on the position makes its mode count again
    K[0, STATE_INDEX["pN"]] = 1.0
    assert stability.assess(A_cl, K).marginal == ("pE",) and not stability.assess(A_cl, K).stable


def test_discrete_loops_use_the_unit_circle_and_report_s_equivalents():
    Ts = 0.01
    A_cl = np.eye(12) * 0.5
    K = np.ones((4, 12))
    verdict = stability.assess(A_cl, K, sample_time=Ts)
    assert verdict.stable
    np.testing.assert_allclose(verdict.eigenvalues, np.log(0.5) / Ts)
    np.testing.assert_allclose(verdict.eigenvalues_z, 0.5)
    A_cl[0, 0] = 1.0 + 1e-6
    assert not stability.assess(A_cl, K, sample_time=Ts).stable


@pytest.mark.parametrize("discrete", [False, True])
def test_the_predicate_has_a_margin_and_matches_on_arrays(discrete):
    edge = 1.0 if discrete else 0.0
    inside = 1.0 - 2e-9 if discrete else -2e-9
    assert not stability.is_stable(edge, discrete=discrete)
    assert stability.is_stable(inside, discrete=discrete)
    values = np.array([edge, inside, inside * 0.5])
    np.testing.assert_array_equal(stability.is_stable(values, discrete=discrete),
                                  [stability.is_stable(v, discrete=discrete) for v in values])


def test_stacked_assessment_equals_one_by_one():
    rng = np.random.default_rng(4)
    A = rng.normal(size=(20, 12, 12)) - 3 * np.eye(12)
    K = rng.normal(size=(20, 4, 12))
    A[:10, :, 0] = 0.0
    K[:10, :, 0] = 0.0  # half the stack with a free pN
    for got, k in zip(stability.assess_stack(A, K), range(20)):
        one = stability.assess(A[k], K[k])
        assert got.stable == one.stable and got.marginal == one.marginal
        np.testing.assert_allclose(np.sort_complex(got.core), np.sort_complex(one.core))


@pytest.mark.parametrize("sample_time", [None, 0.005])
def test_the_verdict_is_about_the_spectrum_without_the_free_positions(sample_time):
    """verdict_stack against loops built with known eigenvalues: a loop whose pE is free (no gain on
    it, nothing driving it) has pE's mode (s = 0, z = 1) left out, and its verdict is the rest's."""
    rng = np.random.default_rng(5)
    n = 13
    wanted = []
    A = np.empty((6, n, n))
    for k in range(6):
        # eigenvalues as s; a discrete loop gets z = exp(s Ts); loop 2 has one unstable mode
        s = -rng.uniform(1.0, 20.0, n) + 1j * 0
        if k == 2:
            s[4] = 3.0
        z = np.exp(s * sample_time) if sample_time else s
        V = np.eye(n) + 0.1 * rng.normal(size=(n, n))
        A[k] = (V @ np.diag(z.real) @ np.linalg.inv(V))
        wanted.append(np.sort(s.real))
    K = rng.normal(size=(6, 4, 12))
    pe = 1
    for k in range(3):  # the first three loops: pE free, its mode at s = 0 (z = 1) beside the others
        A[k, :, pe] = 0.0
        A[k, pe, :] = 0.0
        A[k, pe, pe] = 1.0 if sample_time else 0.0
        K[k, :, pe] = 0.0
        rest = [i for i in range(n) if i != pe]
        wanted[k] = np.sort(np.linalg.eigvals(A[k][np.ix_(rest, rest)]).real)
        wanted[k] = np.sort(np.log(wanted[k]) / sample_time) if sample_time else wanted[k]
    got = stability.verdict_stack(A, K, sample_time=sample_time)
    for k, (core, marginal, stable) in enumerate(got):
        assert marginal == (("pE",) if k < 3 else ()), k
        np.testing.assert_allclose(np.sort(core.real), wanted[k], rtol=1e-9, atol=1e-9)
        assert stable is (k != 2), k


def test_diagonal_blocks_are_the_strongly_connected_components():
    """A hand-made pattern: {0, 2} feed each other, 1 alone (it feeds 0 only), {3, 4, 5} a cycle
    fed by 2; the blocks are those sets whatever the order of the states."""
    pattern = np.zeros((6, 6), dtype=bool)
    for i, j in [(0, 2), (2, 0), (0, 1), (3, 2), (4, 3), (5, 4), (3, 5)]:
        pattern[i, j] = True  # entry (i, j): state i depends on state j
    assert stability.diagonal_blocks(pattern) == [[0, 2], [1], [3, 4, 5]]
    perm = np.array([4, 0, 5, 1, 3, 2])
    blocks = stability.diagonal_blocks(pattern[np.ix_(perm, perm)])
    assert sorted(sorted(perm[b].tolist()) for b in blocks) == [[0, 2], [1], [3, 4, 5]]


@pytest.mark.parametrize("coupled", [False, True])
def test_stack_eigenvalues_by_blocks_are_the_whole_matrices_eigenvalues(coupled):
    """Loops that share a block triangular sparsity (permuted): the eigenvalues by diagonal blocks
    are numpy's of each whole matrix, to 1e-12 (matched by sorting); a pattern with one block
    (``coupled``) is the plain call."""
    rng = np.random.default_rng(7)
    n, N = 9, 40
    pattern = np.zeros((n, n), dtype=bool)
    for block in ([0, 1, 2, 3], [4, 5, 6], [7], [8]):
        pattern[np.ix_(block, block)] = True
    pattern[0, 5] = pattern[4, 7] = pattern[7, 8] = True  # couplings one way only
    if coupled:
        pattern[8, 0] = True  # closes a cycle through every block
    perm = rng.permutation(n)
    M = rng.standard_normal((N, n, n)) * pattern[np.ix_(perm, perm)]
    got = stability.stack_eigenvalues(M)
    want = np.linalg.eigvals(M)
    assert got.shape == want.shape and got.dtype == complex
    for g, w in zip(got, want):
        np.testing.assert_allclose(np.sort_complex(g), np.sort_complex(w), rtol=0, atol=1e-12 * np.abs(w).max())
