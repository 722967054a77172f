"""The one stability predicate and the one marginal-mode rule (quadctl.stability)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadctl import stability
from quadctl.layout import STATE_INDEX


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
def test_the_verdicts_alone_are_the_assessments_verdicts(sample_time):
    rng = np.random.default_rng(5)
    A = rng.normal(size=(12, 13, 13)) * 0.1 + (np.eye(13) * (0.5 if sample_time else -3.0))
    K = rng.normal(size=(12, 4, 12))
    A[:6, :, 1] = np.eye(13)[:, 1] if sample_time else 0.0
    K[:6, :, 1] = 0.0  # half the stack with a free pE
    A[3, 2, 2] = np.nan  # a loop that blew up
    full = stability.assess_stack(A, K, sample_time=sample_time)
    alone = stability.verdict_stack(A, K, sample_time=sample_time)
    assert {a.marginal for a in full} == {(), ("pE",)}
    assert [a.stable for a in full].count(False) >= 1
    for a, (core, marginal, stable) in zip(full, alone):
        assert (marginal, stable) == (a.marginal, a.stable)
        np.testing.assert_array_equal(core, a.core)
