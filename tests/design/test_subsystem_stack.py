"""The one engine of the decoupled design (quadctl.design.stacked.solve_subsystems), one case and many:
held to closed forms and to the Riccati residual of the problem built here by hand, never to another
path of its own. Every test runs a stack of one (the one-case design) and a stack of many (a sweep)."""

from __future__ import annotations

import numpy as np
import pytest
from _solve import bundled_subsystems

from quadctl.design import design, lag, stacked
from quadctl.design.riccati import dare_residual, riccati_residual
from quadctl.errors import DesignError

RTOL = 1e-10
"""Relative to the largest entry: the engine's answers are Newton-polished to round-off; the closed
forms below are well conditioned (q / r within 1e-2 .. 1e4)."""
SIZES = [1, 7]
"""A stack of one (the one-case design) and of many (a sweep's chunk)."""


def _close(ours, reference, what):
    diff = np.abs(np.asarray(ours) - reference).max() / np.abs(reference).max()
    assert diff <= RTOL, f"{what}: Max diff is {diff:.4E}"


def _weights(N, low=0.1, high=100.0):
    return np.geomspace(low, high, N) if N > 1 else np.array([4.0])


@pytest.mark.parametrize("N", SIZES)
def test_scalar_integrator_gain_is_sqrt_q_over_r(N):
    # x' = u: P = sqrt(q r), K = sqrt(q / r) (python-control's hand-derived case)
    q, r = _weights(N), np.linspace(0.5, 2.0, N)
    sol = stacked.solve_subsystems([[[0.0]]], [[[1.0]]], q[:, None, None], r[:, None, None])
    assert sol.ok.all()
    _close(sol.K.ravel(), np.sqrt(q / r), "K")
    _close(sol.P.ravel(), np.sqrt(q * r), "P")
    _close(sol.eigenvalues.ravel().real, -np.sqrt(q / r), "closed-loop eigenvalue")


@pytest.mark.parametrize("N", SIZES)
def test_double_integrator_gain_is_the_published_closed_form(N):
    # x1' = x2, x2' = u, Q = diag(q1, q2), R = r: K = [sqrt(q1 / r), sqrt(q2 / r + 2 sqrt(q1 / r))]
    # (Anderson & Moore, Optimal Control: Linear Quadratic Methods, the double integrator example)
    q1, q2, r = _weights(N), _weights(N, 1.0, 10.0)[::-1], np.full(N, 0.5)
    Q = np.zeros((N, 2, 2))
    Q[:, 0, 0], Q[:, 1, 1] = q1, q2
    sol = stacked.solve_subsystems([[[0.0, 1.0], [0.0, 0.0]]], [[[0.0], [1.0]]], Q, r[:, None, None])
    k1 = np.sqrt(q1 / r)
    _close(sol.K[:, 0, 0], k1, "position gain")
    _close(sol.K[:, 0, 1], np.sqrt(q2 / r + 2 * k1), "velocity gain")


@pytest.mark.parametrize("N", SIZES)
def test_lagged_integrator_gain_is_its_closed_form(N):
    # x' = v, v' = (u - v) / tau, Q = diag(q, 0): the return-difference closed form (lag.py)
    tau, q, r = 0.03, _weights(N), 1.0
    sol = stacked.solve_subsystems([[[0.0]]], [[[1.0]]], q[:, None, None], np.full((N, 1, 1), r),
                                   lag_time_constant=tau)
    assert sol.Kv is not None and sol.ok.all()
    gains = np.array([lag.scalar_integrator_gain(qk, r, tau) for qk in q])
    _close(sol.K[:, 0, 0], gains[:, 0], "k_x")
    _close(sol.Kv[:, 0, 0], gains[:, 1], "k_v")


def _augmented(A, B, C, Ts=None):
    """``[[A, 0], [-C, 0]]``, ``[[B], [0]]`` (continuous) or the forward-Euler accumulator on the ZOH
    plant, written out here (not integral.py's)."""
    import scipy.linalg

    n, m = B.shape
    ni = len(C)
    if Ts is not None:
        E = scipy.linalg.expm(np.block([[A, B], [np.zeros((m, n + m))]]) * Ts)
        A, B, C = E[:n, :n], E[:n, n:], C * Ts
    Aa = np.zeros((n + ni, n + ni))
    Aa[:n, :n], Aa[n:, :n] = A, -C
    if Ts is not None:
        Aa[n:, n:] = np.eye(ni)
    return Aa, np.vstack([B, np.zeros((ni, m))])


@pytest.mark.parametrize("N", SIZES)
@pytest.mark.parametrize("rate", [None, 200.0])
def test_bundled_subsystems_with_integrators_solve_their_riccati_equation(N, rate):
    """quadctl's own subsystems, each integrating its first state, on several plants at once (plant_of):
    each gain solves the Riccati equation of the plant augmented by hand (and sampled by hand), and
    its loop is stable."""
    rng = np.random.default_rng(N)
    Ts = None if rate is None else 1 / rate
    by_shape: dict[tuple, list] = {}
    for _, sub in bundled_subsystems(("forward", "mambo-200hz")):
        by_shape.setdefault(sub.B.shape, []).append(sub)
    for (n, m), subs in by_shape.items():
        plant_of = rng.integers(0, len(subs), N)
        C = np.eye(n)[:1]
        Q = np.stack([np.diag(rng.uniform(0.5, 50.0, n + 1)) for _ in range(N)])
        R = np.stack([np.diag(rng.uniform(0.5, 5.0, m)) for _ in range(N)])
        sol = stacked.solve_subsystems(np.stack([s.A for s in subs]), np.stack([s.B for s in subs]), Q, R, C, Ts,
                                       plant_of=plant_of)
        assert sol.ok.all()
        for k, p in enumerate(plant_of):
            Aa, Ba = _augmented(subs[p].A, subs[p].B, C, Ts)
            if Ts is None:
                assert riccati_residual(Aa, Ba, Q[k], R[k], sol.P[k]) <= RTOL
            else:  # the sampled weights are lqrd's (discrete.py's own tests); the plant here is by hand
                Aq, Bq, Qq, Rq, Nq = (M[k] for M in sol.problem)
                _close(Aq, Aa, "sampled augmented A")
                _close(Bq, Ba, "sampled augmented B")
                assert dare_residual(Aa, Ba, Qq, Rq, sol.P[k], Nq) <= RTOL
            E = np.linalg.eigvals(Aa - Ba @ sol.gain[k])
            assert np.all(np.abs(E) < 1) if Ts is not None else np.all(E.real < 0)


def test_a_problem_without_a_stabilizing_solution_fails_alone_and_the_one_case_design_names_it():
    # x' = x with no input: unstabilizable; beside it a scalar integrator that is fine
    A = np.array([[[1.0, 0.0], [0.0, 0.0]]])
    B = np.array([[[0.0], [1.0]]])
    Q = np.stack([np.eye(2)] * 3)
    sol = stacked.solve_subsystems(np.concatenate([A, np.array([[[0.0, 1.0], [0.0, 0.0]]])]),
                                   np.concatenate([B, B]), Q, np.ones((3, 1, 1)), plant_of=[1, 0, 1])
    assert sol.ok.tolist() == [True, False, True]
    from types import SimpleNamespace

    sub = SimpleNamespace(name="roll", states=("phi", "p"), inputs=("A",), A=A[0], B=B[0], state_index=[3, 9])
    dec = SimpleNamespace(regulated=(sub,))  # what design reads of a partition
    with pytest.raises(DesignError, match=r"subsystem roll: not stabilizable: the mode at eigenvalue 1 \(in phi\)"):
        design(dec, np.zeros((12, 12)), np.zeros((12, 4)), {"roll": (np.eye(2), np.eye(1))})


def test_block_gains_put_each_subsystems_gain_where_its_inputs_and_states_are():
    subs = [s for _, s in bundled_subsystems(("mambo-200hz",))]
    ints = [(s.states[0],) if k == 0 else () for k, s in enumerate(subs)]
    gains = [np.arange(2 * len(s.inputs) * (len(s.states) + len(i)), dtype=float).reshape(
        2, len(s.inputs), len(s.states) + len(i)) + 1 for s, i in zip(subs, ints)]
    K, Ki, states = stacked.block_gains(subs, ints, gains)
    assert states == ints[0] and K.shape == (2, 4, 12) and Ki.shape == (2, 4, 1)
    from quadctl.layout import INPUT_INDEX, STATE_INDEX

    for sub, gain, i in zip(subs, gains, ints):
        for a, u in enumerate(sub.inputs):
            for b, x in enumerate(sub.states):
                assert (K[:, INPUT_INDEX[u], STATE_INDEX[x]] == gain[:, a, b]).all()
            if i:
                assert (Ki[:, INPUT_INDEX[u], 0] == gain[:, a, -1]).all()
    assert np.count_nonzero(K[0]) == sum(len(s.inputs) * len(s.states) for s in subs)
