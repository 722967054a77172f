"""The one-case Riccati solvers (lqr, dlqr, lqrd): weights refused with their reason, stabilizability
without the Kalman matrix, large systems, the cross term, and the refusals that name their cause."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
from _solve import bundled_subsystems
from hypothesis import given, settings
from hypothesis import strategies as st

from quadctl.design import discrete, integral, lqr, riccati, riccati_residual
from quadctl.design.discrete import dlqr, lqrd
from quadctl.design.riccati import ROUNDOFF_RTOL, SEMIDEFINITE_RTOL, WeightCheck, care_batch, dare_batch
from quadctl.errors import ArgumentError, DesignError
from quadctl.linear import analysis, stability

AGREEMENT = 1e-8
"""Relative difference of ``P`` allowed against SciPy's on well-posed problems: both are certified
to a relative residual of 1e-8 (seen: 1e-12 and below)."""

# a double integrator, continuous and sampled at 10 Hz
A_C, B_C = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])
A_D, B_D = np.array([[1.0, 0.1], [0.0, 1.0]]), np.array([[0.005], [0.1]])


def _lqr(Q, R, N=None, **kw):
    return lqr(A_C, B_C, Q, R, N, **kw)


def _dlqr(Q, R, N=None, **kw):
    return dlqr(A_D, B_D, Q, R, N, **kw)


def _lqrd(Q, R, N=None, **kw):
    return lqrd(A_C, B_C, Q, R, 0.1, N, **kw)


SOLVERS = pytest.mark.parametrize("solve", [_lqr, _dlqr, _lqrd], ids=["lqr", "dlqr", "lqrd"])

INVALID = {
    "non-symmetric Q": (([[1.0, 2.0], [0.0, 1.0]], [[1.0]], None),
                        r"sys: Q is not symmetric: Q\[0, 1\] = 2 but Q\[1, 0\] = 0 \(\|Q - Q'\|_1 = 2, "
                        r"tolerance .*\); make it symmetric, e.g. \(Q \+ Q'\) / 2"),
    "indefinite Q": (([[1.0, 0.0], [0.0, -1.0]], [[1.0]], None),
                     r"sys: Q is not positive semidefinite: its most negative eigenvalue is -1 \(largest 1\), "
                     r"so the cost would reward some deviations; make Q positive semidefinite, e.g. C' C"),
    "zero R": ((np.eye(2), [[0.0]], None),
               r"sys: R is not positive definite: its smallest eigenvalue is 0 \(largest 0\); every input "
               r"needs a positive weight: make R symmetric positive definite"),
    "negative R": ((np.eye(2), [[-1.0]], None), r"sys: R is not positive definite: its smallest eigenvalue is -1"),
    "NaN in Q": (([[1.0, 0.0], [np.nan, 1.0]], [[1.0]], None),
                 r"sys: Q has a non-finite entry \(nan at \[1, 0\]\); every entry of A, B, Q, R and N must be "
                 r"a finite number"),
    "inf in N": ((np.eye(2), [[1.0]], [[np.inf], [0.0]]), r"sys: N has a non-finite entry \(inf at \[0, 0\]\)"),
    "N too large": ((np.eye(2), [[1.0]], [[2.0], [0.0]]),
                    r"sys: \[\[Q, N\], \[N', R\]\] is not positive semidefinite: its most negative eigenvalue is -1 "
                    r"\(largest 3\): the cross weight N is too large for Q and R .*; shrink N, or raise Q or R"),
    "N shape": ((np.eye(2), [[1.0]], [[1.0, 0.0]]), r"sys: N has shape \(1, 2\), expected \(2, 1\)"),
}


@SOLVERS
@pytest.mark.parametrize("case", INVALID, ids=list(INVALID))
def test_invalid_weights_are_refused_naming_the_matrix_what_was_found_and_the_fix(solve, case):
    (Q, R, N), message = INVALID[case]
    with pytest.raises(ArgumentError if case == "N shape" else DesignError, match=message):
        solve(Q, R, N, name="sys")


def test_a_matrix_that_is_not_numeric_is_named():
    with pytest.raises(ArgumentError, match=r"sys: A is not a numeric matrix \(.*\); give an array of numbers"):
        lqr([[0.0, 1.0], [0.0]], B_C, np.eye(2), [[1.0]], name="sys")


@pytest.mark.parametrize("missing", ["A", "B", "Q", "R"])
def test_a_matrix_left_out_is_named_not_a_key_error(missing):
    """``lqr(None, B, Q, R)`` raised ``KeyError: 'A'`` from inside; only ``N`` may be left out."""
    args = {"A": [[0.0, 1.0], [0.0, 0.0]], "B": B_C, "Q": np.eye(2), "R": [[1.0]]} | {missing: None}
    with pytest.raises(ArgumentError, match=rf"^sys: {missing} is None; give an array of numbers$"):
        lqr(**args, name="sys")


def test_a_1d_input_matrix_is_refused_saying_to_give_the_column():
    """``B = [0, 1]`` for one input (read as a row, as SciPy and python-control read it) was refused as
    'shape (1, 2), expected (2, 2)', an m of 2 nobody wrote."""
    with pytest.raises(ArgumentError, match=r"^sys: B has shape \(2,\), a 1-D array read as the row \(1, 2\); for "
                                          r"one input give the column, shape \(2, 1\)"):
        lqr([[0.0, 1.0], [0.0, 0.0]], [0.0, 1.0], np.eye(2), [[1.0]], name="sys")


@pytest.mark.parametrize("which, value, message", [
    ("Q", [1.0, 1.0], r"Q has shape \(2,\), a 1-D array; give the \(2, 2\) matrix: np.diag\(Q\) for a diagonal "
                      r"weight$"),
    ("R", [1.0, 2.0], r"R has shape \(2,\), a 1-D array; give the \(2, 2\) matrix: np.diag\(R\) for a diagonal "
                      r"weight$"),
    ("Q", [1.0, 1.0, 1.0], r"Q has shape \(3,\), a 1-D array; give the \(2, 2\) matrix$"),
    ("A", [0.0, 1.0], r"A has shape \(2,\), a 1-D array; give the \(n, n\) state matrix$"),
])
def test_a_1d_weight_is_refused_with_the_shape_it_was_given(which, value, message):
    """A diagonal given as a vector (MATLAB and python-control take matrices) was refused as 'Q has shape
    (1, 2), expected (2, 2)': a shape nobody wrote, read after padding the vector to a row."""
    args = {"A": [[0.0, 1.0], [0.0, 0.0]], "B": [[0.0, 0.0], [1.0, 1.0]], "Q": np.eye(2), "R": np.eye(2)}
    args[which] = value
    with pytest.raises(ArgumentError, match=rf"^sys: {message}"):
        lqr(**args, name="sys")


@pytest.mark.parametrize("solve", [lqr, dlqr])
@pytest.mark.parametrize("names, given", [(["a"], "has 1 names"), (["a", "b", "c"], "has 3 names"),
                                          ("ab", "is one string")])
def test_state_names_that_are_not_one_a_state_are_refused_before_solving(solve, names, given):
    """Too few names failed with an IndexError while naming a refused mode, and only then (a plant quadctl
    solved never read them)."""
    with pytest.raises(ArgumentError, match=rf"^sys: state_names {given} for 2 states; give a name a state"):
        solve(np.diag([1.0, 0.5]), [[0.0], [1.0]], np.eye(2), [[1.0]], name="sys", state_names=names)


def test_an_unstabilizable_system_of_the_callers_own_is_told_a_fix_it_can_make():
    """qc.lqr on the caller's own (A, B) was told to 'change the partition', a config's notion it has no
    part in; a config's subsystem still is (docs/reference/errors.md)."""
    A, B = [[1.0, 0.0], [0.0, -1.0]], [[0.0], [1.0]]
    with pytest.raises(DesignError, match=r"^sys: not stabilizable: .* no input reaches it; give B an input that "
                                          r"drives those states, or leave that mode out of A$"):
        lqr(A, B, np.eye(2), [[1.0]], name="sys")
    with pytest.raises(DesignError, match=r"; change the partition so an input drives those states$"):
        lqr(A, B, np.eye(2), [[1.0]], name="subsystem roll")


def test_a_sparse_matrix_is_refused_saying_to_give_the_dense_one():
    """SciPy's sparse matrices became a 0-d object array: 'A is not a numeric matrix (dtype object)'."""
    import scipy.sparse

    with pytest.raises(ArgumentError, match=r"^sys: A is a sparse matrix \(csr_matrix\); give the dense one, "
                                            r"A\.toarray\(\)$"):
        lqr(scipy.sparse.csr_matrix([[0.0, 1.0], [0.0, 0.0]]), [[0.0], [1.0]], np.eye(2), [[1.0]], name="sys")


def test_carex_2_5_is_refused_not_solved():
    """The regression: CAREX 2.5 at eps = 0 returned K = [3.00000004, 2.00000004] and a 'stable' loop."""
    with pytest.raises(DesignError, match=r"carex: Q is not positive semidefinite: its most negative eigenvalue "
                                          r"is -13\.2 \(largest 0\.227\)"):
        lqr([[3, 1], [4, 2]], [[1], [1]], [[-11, -5], [-5, -2]], [[1]], name="carex")


def test_symmetry_and_semidefiniteness_are_judged_to_round_off_not_exactly():
    """SciPy's tolerance (100 ulp of the 1-norm) for symmetry; SEMIDEFINITE_RTOL of the cost's scale
    for definiteness: round-off passes, a real defect of the same shape does not."""
    v = np.array([[1.0], [1 / 3]])
    Q = v @ v.T                              # rank one: its zero eigenvalue comes out at +-1e-17
    Q[0, 1] += 1e-16                         # and its symmetry is off by round-off
    assert np.linalg.eigvalsh((Q + Q.T) / 2)[0] != 0
    assert _lqr(Q, [[1.0]]).residual < 1e-12
    with pytest.raises(DesignError, match="Q is not symmetric"):
        _lqr(Q + [[0.0, 1e-10], [0.0, 0.0]], [[1.0]])
    with pytest.raises(DesignError, match="Q is not positive semidefinite"):
        _lqr(Q - 1e-10 * np.eye(2), [[1.0]])


def test_quadctls_own_discrete_weights_are_semidefinite_far_inside_the_tolerance():
    """Van Loan's integrals of every bundled config's subsystems (with an integrator, as integral.py
    augments them) at 50 Hz to 10 kHz: their most negative eigenvalue, against the cost's scale, is
    round-off, and WeightCheck accepts them all."""
    worst = 0.0
    for setup, sub in bundled_subsystems():
        Q, R = (np.atleast_2d(w) for w in setup.weights[sub.name])
        n = len(sub.states)
        Qa = np.eye(n + 1)
        Qa[:n, :n] = Q[:n, :n]
        for rate in (50.0, 200.0, 1e3, 1e4):
            Ad, Bd, Qd, Rd, Nd = discrete.lqrd_weights(sub.A, sub.B, Qa[:n, :n], R, 1 / rate)
            Aa, Ba = integral.augment_discrete(Ad, Bd, integral.selector(sub.states, sub.states[:1]), 1 / rate)
            Qda, Nda = integral.discrete_weights(Qd, Nd, Qa, 1 / rate)
            assert WeightCheck(Aa[None], Ba[None], Qda[None], Rd[None], Nda[None]).ok[0], (setup.name, sub.name, rate)
            W = np.block([[Qda, Nda], [Nda.T, Rd]])
            lam = np.linalg.eigvalsh(W)
            worst = min(worst, np.linalg.eigvalsh(Qda)[0] / np.abs(lam).max(), lam[0] / np.abs(lam).max())
    assert worst > -1e-3 * SEMIDEFINITE_RTOL, f"worst relative eigenvalue {worst:.3e}"


def test_lqrd_with_zero_state_weight_is_the_zero_gain():
    """Q = 0 integrates to round-off noise of R's size (Van Loan): accepted, and the answer is K = 0."""
    K, P, E = lqrd([[-1.0, 0.0], [0.0, -2.0]], [[1.0], [1.0]], np.zeros((2, 2)), [[1.0]], 0.01)
    assert np.abs(K).max() < 1e-12 and np.abs(P).max() < 1e-12


@st.composite
def invalid_problems(draw):
    """A random problem with one defect: indefinite Q, non-symmetric Q or singular R (and the words
    that must name it)."""
    n = draw(st.integers(1, 4))
    m = draw(st.integers(1, 2))
    entry = st.floats(-3, 3)

    def matrix(rows, cols):
        return np.array(draw(st.lists(entry, min_size=rows * cols, max_size=rows * cols))).reshape(rows, cols)

    A, B = matrix(n, n), matrix(n, m)
    V = np.linalg.qr(matrix(n, n) + 4 * np.eye(n))[0]
    lam = np.array(draw(st.lists(st.floats(0, 10), min_size=n, max_size=n)))
    L = matrix(m, m)
    R = L @ L.T + draw(st.floats(0.1, 10)) * np.eye(m)
    kind = draw(st.sampled_from(["indefinite Q", "non-symmetric Q", "singular R"] if n > 1 else
                                ["indefinite Q", "singular R"]))
    if kind == "indefinite Q":
        lam[draw(st.integers(0, n - 1))] = -draw(st.floats(1e-6, 10)) * max(1.0, lam.max(), np.abs(R).max())
        words = "Q is not positive semidefinite"
    Q = V @ np.diag(lam) @ V.T
    Q = (Q + Q.T) / 2
    if kind == "non-symmetric Q":
        i, j = draw(st.sampled_from([(i, j) for i in range(n) for j in range(n) if i != j]))
        Q[i, j] += draw(st.sampled_from([-1, 1])) * draw(st.floats(1e-9, 10)) * max(1.0, np.abs(Q).sum(axis=0).max())
        words = "Q is not symmetric"
    if kind == "singular R":
        u = matrix(m, 1)
        R = u @ u.T if m > 1 else np.zeros((1, 1))
        words = "R is not positive definite"
    return A, B, Q, R, words


@settings(max_examples=120, deadline=None)
@given(invalid_problems(), st.sampled_from(["lqr", "dlqr"]))
def test_random_invalid_weights_are_refused_and_never_certified(problem, which):
    A, B, Q, R, words = problem
    solve = lqr if which == "lqr" else dlqr
    with pytest.raises(DesignError, match=f"random: {words}"):
        solve(A, B, Q, R, name="random")


def test_batched_solvers_mark_invalid_entries_not_ok_and_the_one_case_solver_says_why():
    stack_Q = np.array([np.eye(2), np.diag([1.0, -1.0]), np.eye(2), [[1.0, 0.0], [np.nan, 1.0]], np.eye(2)])
    stack_R = np.array([[[1.0]], [[1.0]], [[0.0]], [[1.0]], [[2.0]]])
    reasons = [None, "Q is not positive semidefinite", "R is not positive definite", "Q has a non-finite entry", None]
    for batched, single, A, B in ((care_batch, lqr, A_C, B_C), (dare_batch, dlqr, A_D, B_D)):
        res = batched(np.array([A] * 5), np.array([B] * 5), stack_Q, stack_R)
        assert res.ok.tolist() == [r is None for r in reasons]
        for k, reason in enumerate(reasons):
            if reason is None:
                np.testing.assert_allclose(res.K[k], single(A, B, stack_Q[k], stack_R[k]).K, rtol=1e-12)
            else:
                with pytest.raises(DesignError, match=f"entry: {reason}"):
                    single(A, B, stack_Q[k], stack_R[k], name="entry")


def test_a_large_stiff_stable_system_needs_no_kalman_matrix(monkeypatch):
    """60 stable modes near -1e6 rad/s: [B, AB, ...] overflowed and numpy's SVD raised 'did not
    converge' through lqr; stable modes need no input, so nothing is tested for them."""
    rng = np.random.default_rng(0)
    A = np.diag(-1e6 * (1 + rng.random(60)))
    B = rng.normal(size=(60, 2))
    Q, R = np.eye(60), np.eye(2)

    def no_kalman(*args, **kwargs):
        raise AssertionError("the Kalman matrix was formed")

    monkeypatch.setattr(analysis, "ctrb", no_kalman)
    K, P, E = res = lqr(A, B, Q, R)
    assert res.residual < 1e-12 and all(stability.is_stable(e) for e in E)
    reference = scipy.linalg.solve_continuous_are(A, B, Q, R)
    diff = np.abs(P - reference).max() / np.abs(reference).max()
    assert diff < AGREEMENT, f"Max diff is {diff:.4E}"
    A[7, 7], B[7] = 3.0, 0.0  # one unstable mode no input reaches
    with pytest.raises(DesignError, match=r"big: not stabilizable: the mode at eigenvalue 3 \(in x7\) is unstable "
                                          r"and no input reaches it"):
        lqr(A, B, Q, R, name="big")


def test_unstabilizable_discrete_mode_is_named_as_z():
    with pytest.raises(DesignError, match=r"d: not stabilizable: the mode at eigenvalue z = 1\.5 \(in a\) is unstable "
                                          r"and no input reaches it"):
        dlqr(np.diag([1.5, 0.5]), [[0.0], [1.0]], np.eye(2), [[1.0]], name="d", state_names=["a", "b"])


@pytest.mark.parametrize("n", [10, 50, 100])
def test_larger_random_systems_agree_with_scipy(n):
    """Above KRONECKER_MAX_N states lqr takes Laub's Schur method and Bartels-Stewart Newton steps."""
    rng = np.random.default_rng(n)
    m = max(1, n // 5)
    A, B = rng.normal(size=(n, n)) / math.sqrt(n), rng.normal(size=(n, m))
    L = rng.normal(size=(n, n))
    Q, R = L @ L.T / n + 1e-3 * np.eye(n), np.eye(m)
    K, P, E = res = lqr(A, B, Q, R)
    # polished to the rounding of the residual's n-term products (well-posed: reached in two steps)
    assert res.residual <= n * ROUNDOFF_RTOL
    assert riccati_residual(A, B, Q, R, P) == pytest.approx(res.residual, rel=1e-9)
    reference = scipy.linalg.solve_continuous_are(A, B, Q, R)
    diff = np.abs(P - reference).max() / np.abs(reference).max()
    assert diff < AGREEMENT, f"n = {n}: Max diff is {diff:.4E}"


def test_numerical_failures_become_design_errors_with_the_reason(monkeypatch):
    from quadctl.design.riccati import single

    def out_of_memory(*args):
        raise MemoryError("Unable to allocate 2.4 GiB")

    monkeypatch.setattr(single, "care_schur", out_of_memory)
    rng = np.random.default_rng(1)
    with pytest.raises(DesignError, match=r"big: the Riccati equation could not be solved \(MemoryError: Unable to "
                                          r"allocate 2\.4 GiB\); rescale units"):
        lqr(rng.normal(size=(9, 9)), rng.normal(size=(9, 2)), np.eye(9), np.eye(2), name="big")


@pytest.mark.parametrize("solve, A, B, words", [
    (lqr, A_C, B_C, r"the Riccati equation has no stabilizing solution: the marginal mode at eigenvalue 0 \(in p\)"),
    (dlqr, A_D, B_D, r"the discrete Riccati equation has no stabilizing solution: the marginal mode at eigenvalue "
                     r"z = 1 \(in p\)"),
], ids=["lqr", "dlqr"])
def test_a_marginal_mode_invisible_to_q_is_named(solve, A, B, words):
    """The position of a double integrator, not weighed: its mode (0, or z = 1) stays on the boundary."""
    with pytest.raises(DesignError, match=f"sys: {words} is invisible to Q; give weight to the states it lives in"):
        solve(A, B, np.diag([0.0, 1.0]), [[1.0]], name="sys", state_names=["p", "v"])


def test_lqr_with_cross_term_agrees_with_scipy_and_python_control():
    control = pytest.importorskip("control")
    rng = np.random.default_rng(11)
    A, B = rng.normal(size=(4, 4)), rng.normal(size=(4, 2))
    M = rng.normal(size=(6, 6))
    W = M @ M.T + 0.1 * np.eye(6)
    Q, N, R = W[:4, :4], W[:4, 4:], W[4:, 4:]
    K, P, E = res = lqr(A, B, Q, R, N)
    np.testing.assert_allclose(P, scipy.linalg.solve_continuous_are(A, B, Q, R, s=N), rtol=1e-10)
    np.testing.assert_allclose(K, np.linalg.solve(R, B.T @ P + N.T), rtol=1e-12)
    K_ct, P_ct, _ = control.lqr(A, B, Q, R, N)
    np.testing.assert_allclose(K, K_ct, rtol=1e-9)
    assert res.residual < 1e-13 and riccati_residual(A, B, Q, R, P, N) == pytest.approx(res.residual, rel=1e-9)
    batched = care_batch(A[None], B[None], Q[None], R[None], N[None])
    assert batched.ok[0]
    np.testing.assert_allclose(batched.K[0], K, rtol=1e-10)


@pytest.mark.parametrize("solver", ["lqr", "lqr_schur", "dlqr", "lqrd", "care_batch", "dare_batch"])
def test_closed_loop_eigenvalues_are_complex_even_when_all_are_real(solver):
    """LqrResult.E and BatchLqr.E are documented complex (as python-control's E): NumPy's eigvals gave
    floats when every closed-loop eigenvalue was real, so E's dtype depended on the plant. The set is
    np.linalg.eigvals(A - B K)'s, to the loop's conditioning."""
    discrete_plant = solver in ("dlqr", "dare_batch")
    A = np.diag([1.5, 0.5]) if discrete_plant else np.array([[1.0, 2.0], [0.0, 3.0]])  # unstable, real loop poles
    B = np.array([[1.0], [1.0]]) if discrete_plant else np.array([[0.0], [1.0]])
    Q, R = np.eye(2), np.eye(1)
    if solver == "lqr_schur":  # above KRONECKER_MAX_N: Laub's method, then the one-case polish
        A, B, Q, R, solver = np.diag(np.arange(1.0, 9.0)), np.eye(8), np.eye(8), np.eye(8), "lqr"
    if solver in ("care_batch", "dare_batch"):
        batch = (care_batch if solver == "care_batch" else dare_batch)(A[None], B[None], Q[None], R[None])
        K, E = batch.K[0], batch.E[0]
    else:
        K, _, E = lqrd(A, B, Q, R, 0.1) if solver == "lqrd" else (dlqr if discrete_plant else lqr)(A, B, Q, R)
    Ad, Bd = discrete.c2d(A, B, 0.1) if solver == "lqrd" else (A, B)
    want = np.linalg.eigvals(Ad - Bd @ K)
    assert want.dtype == np.float64 and E.dtype == np.complex128 and np.all(E.imag == 0)
    tol = 1e-12 * np.linalg.cond(np.linalg.eig(Ad - Bd @ K)[1]) * np.abs(want).max()
    assert all(np.min(np.abs(e - want)) <= tol for e in E) and all(np.min(np.abs(w - E)) <= tol for w in want)


def test_lqr_and_dlqr_return_the_same_result_type():
    a, b = lqr(A_C, B_C, np.eye(2), [[1.0]]), dlqr(A_D, B_D, np.eye(2), [[1.0]])
    assert type(a) is type(b) is riccati.LqrResult
    K, P, E = b
    assert np.all(np.abs(E) < 1) and E is b.E
