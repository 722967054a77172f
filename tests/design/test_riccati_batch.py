"""Batched discrete design (c2d_batch, lqrd_weights_batch, dare_batch) and the batched CARE above the
Kronecker size, against SciPy and the one-case functions they batch."""

from __future__ import annotations

import re

import numpy as np
import pytest
import scipy.linalg
from _carex import case
from _solve import bundled_subsystems

from quadctl.design import discrete, integral
from quadctl.design.riccati import KRONECKER_MAX_N, care_batch, dare_batch, dare_residual
from quadctl.errors import ArgumentError, DesignError

AGREEMENT = 1e-9
"""Relative difference (largest entry over the largest entry) allowed between the batched answers
and SciPy's or the one-case solver's: all are residual-checked to round-off on these problems."""


def _close(ours, reference, what):
    diff = np.abs(ours - reference).max() / np.abs(reference).max()
    assert diff <= AGREEMENT, f"{what}: Max diff is {diff:.4E}"


def _random_weights(rng, count, n, m, cross=True):
    M = rng.normal(size=(count, n + m, n + m))
    W = M @ M.transpose(0, 2, 1) + 0.1 * np.eye(n + m)
    Q, N, R = W[:, :n, :n], W[:, :n, n:], W[:, n:, n:]
    return Q, R, (N if cross else np.zeros_like(N))


def test_c2d_batch_is_c2d_per_entry_and_exact_for_the_double_integrator():
    rng = np.random.default_rng(1)
    A, B, Ts = rng.normal(size=(20, 3, 3)), rng.normal(size=(20, 3, 2)), rng.uniform(1e-3, 0.1, 20)
    Ad, Bd = discrete.c2d_batch(A, B, Ts)
    for k in range(20):
        one = discrete.c2d(A[k], B[k], Ts[k])
        np.testing.assert_array_equal(Ad[k], one[0])
        np.testing.assert_array_equal(Bd[k], one[1])
    Ts = np.array([0.01, 0.05, 0.2])
    Ad, Bd = discrete.c2d_batch(np.tile([[0.0, 1.0], [0.0, 0.0]], (3, 1, 1)), np.tile([[0.0], [1.0]], (3, 1, 1)), Ts)
    np.testing.assert_allclose(Ad[:, 0, 1], Ts, rtol=1e-14)
    np.testing.assert_allclose(Bd[:, :, 0], np.c_[Ts**2 / 2, Ts], rtol=1e-14)


def test_lqrd_weights_batch_is_lqrd_weights_per_entry_and_the_hand_integrals():
    rng = np.random.default_rng(2)
    A, B = rng.normal(size=(20, 3, 3)), rng.normal(size=(20, 3, 1))
    Q, R, N = _random_weights(rng, 20, 3, 1)
    out = discrete.lqrd_weights_batch(A, B, Q, R, 0.01, N)
    for k in range(20):
        for batched, one in zip(out, discrete.lqrd_weights(A[k], B[k], Q[k], R[k], 0.01, N[k])):
            np.testing.assert_array_equal(batched[k], one)
    # x' = u: Qd = q Ts, Nd = q Ts^2 / 2, Rd = r Ts + q Ts^3 / 3 (tests/design/test_discrete.py, per entry)
    q, r, Ts = np.array([3.0, 1.0]), np.array([2.0, 5.0]), np.array([0.3, 0.01])
    _, _, Qd, Rd, Nd = discrete.lqrd_weights_batch(np.zeros((2, 1, 1)), np.ones((2, 1, 1)), q[:, None, None],
                                                   r[:, None, None], Ts)
    np.testing.assert_allclose(Qd.ravel(), q * Ts, rtol=1e-13)
    np.testing.assert_allclose(Nd.ravel(), q * Ts**2 / 2, rtol=1e-13)
    np.testing.assert_allclose(Rd.ravel(), r * Ts + q * Ts**3 / 3, rtol=1e-13)


def test_batched_discretization_refuses_bad_shapes_and_sample_times():
    with pytest.raises(ArgumentError, match=r"c2d_batch: B has shape \(3, 1\); stack the problems"):
        discrete.c2d_batch(np.zeros((3, 3)), np.zeros((3, 1)), 0.1)
    with pytest.raises(ValueError, match=r"^c2d_batch: Ts = -0\.1: the sample time must be a positive finite number of "
                                         "seconds$"):
        discrete.c2d_batch(np.zeros((2, 1, 1)), np.ones((2, 1, 1)), [0.1, -0.1])


@pytest.mark.parametrize("Ts", ["0.1", True, None, b"1"])
def test_a_sample_time_that_is_not_a_number_is_refused_as_given(Ts):
    """Text and a bool went through float(): lqrd(..., "0.1") designed at 0.1 s and lqrd(..., True) at
    1 s; None was reported as 'Ts = nan'. Each is refused, quoting what was given."""
    want = rf"^lqrd: Ts = {re.escape(repr(Ts))}: the sample time must be a positive finite number of seconds$"
    with pytest.raises(ArgumentError, match=want):
        discrete.lqrd([[0.0]], [[1.0]], [[1.0]], [[1.0]], Ts, name="lqrd")
    with pytest.raises(ArgumentError, match=r"^c2d: Ts = "):
        discrete.c2d([[0.0]], [[1.0]], Ts)


def test_lqrd_in_matlabs_argument_order_says_where_the_sample_time_goes():
    """MATLAB's lqrd(A, B, Q, R, N, Ts) put N where Ts goes and Ts where N goes: it was refused as 'N has
    shape (1, 1), expected (2, 1)', about a matrix the caller gave right."""
    A, B, N = [[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[0.1], [0.0]]
    with pytest.raises(ArgumentError, match=r"^sys: Ts has shape \(2, 1\), a matrix, and N is 0\.1: lqrd takes "
                                            r"\(A, B, Q, R, Ts, N\), the sample time before the cross weight"):
        discrete.lqrd(A, B, np.eye(2), [[1.0]], N, 0.1, name="sys")
    ours = discrete.lqrd(A, B, np.eye(2), [[1.0]], 0.1, N)
    assert ours.residual < 1e-12 and np.all(np.abs(ours.E) < 1)


@pytest.mark.parametrize("n, m", [(1, 1), (2, 1), (3, 1), (3, 2), (4, 2), (9, 2)])
def test_dare_batch_agrees_with_scipy_and_dlqr(n, m):
    """Random discrete plants (spectral radius up to ~1.5) and weights with a cross term."""
    rng = np.random.default_rng(10 * n + m)
    count = 40
    A, B = rng.normal(size=(count, n, n)) * 0.7, rng.normal(size=(count, n, m))
    Q, R, N = _random_weights(rng, count, n, m)
    res = dare_batch(A, B, Q, R, N)
    assert res.ok.all()
    for k in range(count):
        P = scipy.linalg.solve_discrete_are(A[k], B[k], Q[k], R[k], s=N[k])
        _close(res.P[k], P, f"P[{k}] against SciPy")
        one = discrete.dlqr(A[k], B[k], Q[k], R[k], N[k])
        _close(res.K[k], one.K, f"K[{k}] against dlqr")
        np.testing.assert_allclose(res.K[k], np.linalg.solve(R[k] + B[k].T @ res.P[k] @ B[k],
                                                             B[k].T @ res.P[k] @ A[k] + N[k].T), rtol=1e-10)
        # the reported relative residual is the residual, to the round-off of computing one (4 n eps)
        assert res.residual[k] == pytest.approx(dare_residual(A[k], B[k], Q[k], R[k], res.P[k], N[k]),
                                                rel=1e-9, abs=4 * n * np.finfo(float).eps)
        assert np.all(np.abs(np.linalg.eigvals(A[k] - B[k] @ res.K[k])) < 1)
    assert res.residual.max() <= 1e-12


def test_dare_batch_sampled_integrator_closed_form():
    """x[k+1] = x[k] + Ts u[k]: P = (q Ts^2 + sqrt(q^2 Ts^4 + 4 q r Ts^2)) / (2 Ts^2)."""
    q, r, Ts = np.array([1.0, 4.0, 50.0]), np.array([1.0, 0.5, 1.0]), np.array([1.0, 0.01, 0.005])
    res = dare_batch(np.ones((3, 1, 1)), Ts[:, None, None], q[:, None, None], r[:, None, None])
    P = (q * Ts**2 + np.sqrt(q**2 * Ts**4 + 4 * q * r * Ts**2)) / (2 * Ts**2)
    np.testing.assert_allclose(res.P.ravel(), P, rtol=1e-13)
    np.testing.assert_allclose(res.K.ravel(), Ts * P / (r + Ts**2 * P), rtol=1e-13)


def _subsystem_problems(rates):
    """Every regulated subsystem of the bundled configs, with and without an integrator on its first
    state (as integral.py augments it), at each rate, with the config's weights scaled a little per
    problem (as a sweep varies them): the continuous plants, weights, selectors and sample times."""
    rng = np.random.default_rng(4)
    problems = []
    for setup, sub in bundled_subsystems():
        Q, R = (np.atleast_2d(w) for w in setup.weights[sub.name])
        n = len(sub.states)
        for ints in ((), sub.states[:1]):
            for rate in rates:
                Qa = np.eye(n + len(ints)) * rng.uniform(0.5, 2)
                Qa[:n, :n] = Q[:n, :n] * rng.uniform(0.5, 2, n)
                problems.append((sub.A, sub.B, Qa, R * rng.uniform(0.5, 2), integral.selector(sub.states, ints),
                                 1 / rate))
    return problems


def test_dare_batch_designs_quadctls_subsystems_as_lqrd_does():
    """The batched discrete design of quadctl's own 2- and 3-state subsystems (plus an integrator):
    lqrd_weights_batch, the augmentation of integral.py, dare_batch, against the one-case lqrd/dlqr
    and SciPy, stacked by shape."""
    problems = _subsystem_problems((100.0, 200.0, 1000.0))
    by_shape: dict[tuple, list] = {}
    for p in problems:
        by_shape.setdefault((p[1].shape, p[4].shape), []).append(p)
    for group in by_shape.values():
        A, B, Qa, R, C, Ts = (np.stack([p[k] for p in group]) if k != 5 else np.array([p[5] for p in group])
                              for k in range(6))
        n = A.shape[1]
        Ad, Bd, Qd, Rd, Nd = discrete.lqrd_weights_batch(A, B, Qa[:, :n, :n], R, Ts)
        augmented = [integral.augment_discrete(Ad[k], Bd[k], C[k], Ts[k]) for k in range(len(group))]
        weights = [integral.discrete_weights(Qd[k], Nd[k], Qa[k], Ts[k]) for k in range(len(group))]
        Aa, Ba = (np.stack([a[i] for a in augmented]) for i in range(2))
        Qda, Nda = (np.stack([w[i] for w in weights]) for i in range(2))
        res = dare_batch(Aa, Ba, Qda, Rd, Nda)
        assert res.ok.all()
        for k, (A1, B1, Qa1, R1, C1, Ts1) in enumerate(group):
            Ad1, Bd1, Qd1, Rd1, Nd1 = discrete.lqrd_weights(A1, B1, Qa1[:n, :n], R1, Ts1)
            Aa1, Ba1 = integral.augment_discrete(Ad1, Bd1, C1, Ts1)
            Qda1, Nda1 = integral.discrete_weights(Qd1, Nd1, Qa1, Ts1)
            one = discrete.dlqr(Aa1, Ba1, Qda1, Rd1, Nda1)
            _close(res.K[k], one.K, f"K of {A1.shape} at {1 / Ts1:g} Hz against dlqr")
            _close(res.P[k], one.P, f"P of {A1.shape} at {1 / Ts1:g} Hz against dlqr")
            P = scipy.linalg.solve_discrete_are(Aa1, Ba1, Qda1, Rd1, s=Nda1)
            _close(res.P[k], P, f"P of {A1.shape} at {1 / Ts1:g} Hz against SciPy")
            if not C1.size:
                _close(res.K[k], discrete.lqrd(A1, B1, Qa1, R1, Ts1).K, "K against lqrd")


def test_dare_batch_flags_what_has_no_stabilizing_solution():
    """An unstable mode no input reaches, and a unit-circle mode Q does not see: not ok, and dlqr says why."""
    A = np.array([np.diag([1.5, 0.5]), [[1.0, 0.1], [0.0, 1.0]]])
    B = np.array([[[0.0], [1.0]], [[0.005], [0.1]]])
    Q = np.array([np.eye(2), np.diag([0.0, 1.0])])
    res = dare_batch(A, B, Q, np.ones((2, 1, 1)))
    assert not res.ok.any()
    for k, words in enumerate(["not stabilizable", "no stabilizing solution"]):
        with pytest.raises(DesignError, match=words):
            discrete.dlqr(A[k], B[k], Q[k], np.ones((1, 1)))


def test_care_batch_above_the_kronecker_size_uses_bartels_stewart_and_agrees_with_scipy():
    n, m, count = KRONECKER_MAX_N + 2, 2, 10
    rng = np.random.default_rng(9)
    A, B = rng.normal(size=(count, n, n)) / 3, rng.normal(size=(count, n, m))
    Q, R, N = _random_weights(rng, count, n, m, cross=False)
    res = care_batch(A, B, Q, R)
    assert res.ok.all() and res.residual.max() <= 1e-12
    for k in range(count):
        _close(res.P[k], scipy.linalg.solve_continuous_are(A[k], B[k], Q[k], R[k]), f"P[{k}] against SciPy")


@pytest.mark.parametrize("number", ["3.2", "4.4"])
def test_care_batch_of_large_carex_cases_needs_no_kronecker_system(number):
    """The n^2 x n^2 Kronecker Newton step took 6.3 s at n = 64 (CAREX 3.2) and raised MemoryError
    at n = 421 (CAREX 4.4); above KRONECKER_MAX_N each step is a Bartels-Stewart solve."""
    c = case(number)
    res = care_batch(c.A[None], c.B[None], c.Q[None], c.R[None])
    assert res.ok[0] and res.residual[0] <= 1e-10


def test_empty_stacks_give_empty_results():
    for batched in (care_batch, dare_batch):
        res = batched(np.zeros((0, 2, 2)), np.zeros((0, 2, 1)), np.zeros((0, 2, 2)), np.zeros((0, 1, 1)))
        assert res.K.shape == (0, 1, 2) and res.ok.shape == (0,)


def test_a_member_whose_eigenvalues_do_not_converge_fails_alone(monkeypatch):
    """numpy refuses a whole stack when one member's QR iteration does not converge: that member
    alone is not ok (the one-case solver then says why), the others are answered."""
    eig = np.linalg.eig

    def eig_failing_on_a_marked_member(M):
        if M.ndim == 3 or np.any(np.abs(M) == 7.0):  # the Hamiltonian holds -Q
            raise np.linalg.LinAlgError("Eigenvalues did not converge")
        return eig(M)

    monkeypatch.setattr(np.linalg, "eig", eig_failing_on_a_marked_member)
    A = np.array([[[0.0, 1.0], [0.0, 0.0]]] * 3)
    Q = np.array([np.eye(2), np.eye(2) * 7.0, np.eye(2) * 2.0])
    res = care_batch(A, np.array([[[0.0], [1.0]]] * 3), Q, np.ones((3, 1, 1)))
    assert res.ok.tolist() == [True, False, True]
    monkeypatch.undo()
    np.testing.assert_allclose(res.K[2], care_batch(A[2:], np.array([[[0.0], [1.0]]]), Q[2:], np.ones((1, 1, 1))).K[0],
                               rtol=1e-12)


def test_a_stack_too_large_for_memory_is_a_design_error(monkeypatch):
    from quadctl.design.riccati import stacked

    def out_of_memory(*args):
        raise MemoryError("Unable to allocate 2.4 GiB")

    monkeypatch.setattr(stacked, "care_checked", out_of_memory)
    with pytest.raises(DesignError, match=r"care_batch: out of memory for 3 problems of 2 states and 1 inputs "
                                          r"\(Unable to allocate 2\.4 GiB\); solve them in smaller stacks"):
        care_batch(np.zeros((3, 2, 2)), np.ones((3, 2, 1)), np.ones((3, 1, 1)) * np.eye(2), np.ones((3, 1, 1)))


ROUNDOFF_AGREEMENT = 1e-12
"""Relative difference (largest entry over the largest entry) between the compiled doubling steps and
numpy's: the same steps, rounded in another order, each answer polished and residual-checked."""


@pytest.mark.compiler
@pytest.mark.parametrize("n, m", [(1, 1), (2, 1), (3, 1), (3, 2), (4, 2), (9, 2)])
def test_compiled_doubling_gives_numpys_solution_to_round_off(n, m):
    """dare_batch with its doubling steps in C (a sweep's designs) against numpy's stacked steps, on
    random plants with a cross term and on quadctl's own subsystems at 200 Hz (with an integrator):
    the same P and K to round-off, the same verdicts, and SciPy's P."""
    from quadctl.design.riccati import doubling

    assert doubling._compiled() is not None
    rng = np.random.default_rng(100 + 10 * n + m)
    A, B = rng.normal(size=(30, n, n)) * 0.7, rng.normal(size=(30, n, m))
    Q, R, N = _random_weights(rng, 30, n, m)
    stacks = [(A, B, Q, R, N)]
    for group in _shapes(_subsystem_problems((200.0,))).values():
        if group[0][1].shape == (n, m):
            stacks.append(_lqrd_stack(group))
    for A, B, Q, R, N in stacks:
        fast, slow = dare_batch(A, B, Q, R, N, compiled=True), dare_batch(A, B, Q, R, N)
        assert fast.ok.all() and slow.ok.all()
        for k in range(len(A)):
            assert np.abs(fast.P[k] - slow.P[k]).max() <= ROUNDOFF_AGREEMENT * np.abs(slow.P[k]).max()
            assert np.abs(fast.K[k] - slow.K[k]).max() <= ROUNDOFF_AGREEMENT * np.abs(slow.K[k]).max()
            _close(fast.P[k], scipy.linalg.solve_discrete_are(A[k], B[k], Q[k], R[k], s=N[k]), f"P[{k}] against SciPy")


@pytest.mark.compiler
def test_compiled_doubling_flags_what_has_no_stabilizing_solution():
    A = np.array([np.diag([1.5, 0.5]), [[1.0, 0.1], [0.0, 1.0]]])
    B = np.array([[[0.0], [1.0]], [[0.005], [0.1]]])
    Q = np.array([np.eye(2), np.diag([0.0, 1.0])])
    assert not dare_batch(A, B, Q, np.ones((2, 1, 1)), compiled=True).ok.any()


def _shapes(problems) -> dict:
    by_shape: dict[tuple, list] = {}
    for p in problems:
        by_shape.setdefault((p[1].shape, p[4].shape), []).append(p)
    return by_shape


def _lqrd_stack(group):
    """(Aa, Ba, Qa, Rd, Na) of a group of one shape, lqrd-sampled and augmented as a sweep stacks them."""
    A, B, Qa, R, C = (np.stack([p[k] for p in group]) for k in range(5))
    Ts = group[0][5]
    n = A.shape[1]
    Ad, Bd, Qd, Rd, Nd = discrete.lqrd_weights_batch(A, B, Qa[:, :n, :n], R, Ts)
    Aa, Ba = integral.augment_discrete(Ad, Bd, C[0], Ts)
    Qda, Nda = integral.discrete_weights(Qd, Nd, Qa, Ts)
    return Aa, Ba, Qda, Rd, Nda
