"""Linearization, decoupling, checks and LQR: closed forms, Riccati residuals, the coupled verdict."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadctl.design import design, lqr, riccati_residual
from quadctl.errors import ArgumentError, DesignError
from quadctl.layout import INPUT_INDEX, INPUT_NAMES, REPORT_PARTITION, STATE_NAMES
from quadctl.linear import stability
from quadctl.linear.analysis import check
from quadctl.linear.decouple import DROP_RTOL, decouple


def test_linear_model_report_entries(forward):
    """Entries a hand derivation gives at the report's trim (docs/model.md equations)."""
    _, trim, linear, _, _ = forward
    theta = trim.x[7]
    i = STATE_NAMES.index
    g, m = 9.81, 0.068
    assert linear.A[i("u"), i("theta")] == pytest.approx(-g * math.cos(theta))
    assert linear.A[i("w"), i("theta")] == pytest.approx(-g * math.sin(theta))
    assert linear.A[i("u"), i("u")] == pytest.approx(-trim.u[0] * 0.22 / m)
    assert linear.B[i("w"), 0] == pytest.approx(-1 / m)
    assert linear.B[i("p"), 1] == pytest.approx(1 / 0.69e-4)
    assert linear.A[i("pD"), i("theta")] == pytest.approx(-1.0)  # pitching tilts the velocity
    # translation invariance: nothing depends on position
    assert not np.any(linear.A[:, :3])


def test_decouple_keeps_blocks_and_lists_what_it_drops(forward):
    _, _, linear, dec, _ = forward
    alt = dec["altitude"]
    np.testing.assert_array_equal(alt.A, linear.A[np.ix_([2, 5], [2, 5])])
    np.testing.assert_array_equal(alt.B[:, 0], linear.B[[2, 5], 0])
    guid = dec["guidance"]
    np.testing.assert_array_equal(guid.B, linear.A[np.ix_([0, 1], [3, 8])])  # inputs u, psi from A
    names = {d.name: d for d in dec.dropped}
    assert names["d(u)/d(T)"].value == pytest.approx(linear.B[3, 0])
    assert "d(w)/d(theta)" in names and "d(pD)/d(theta)" in names
    # kept + dropped = the whole model
    dropped_a = np.zeros_like(linear.A)
    for d in dec.dropped:
        if d.matrix == "A":
            dropped_a[STATE_NAMES.index(d.row), STATE_NAMES.index(d.column)] = d.value
    np.testing.assert_allclose(dec.A_kept + dropped_a, linear.A, atol=1e-12)


def test_decouple_drops_exactly_the_entries_no_subsystem_uses(forward):
    """What decouple says it drops, against the partition read here: an entry of ``A`` is used when its
    row and column are states of one subsystem, or its row is a state and its column a state the
    subsystem takes as an input (guidance's ``u``, ``psi``); an entry of ``B`` when its row is a state
    and its column an input of one subsystem. The dropped terms are every other entry above
    ``DROP_RTOL`` of its matrix's largest, with its value."""
    _, _, linear, dec, _ = forward
    used = {"A": set(), "B": set()}
    for spec in REPORT_PARTITION.values():
        for row in spec["states"]:
            used["A"].update((row, col) for col in spec["states"])
            used["A"].update((row, i) for i in spec["inputs"] if i in STATE_NAMES)
            used["B"].update((row, i) for i in spec["inputs"] if i in INPUT_NAMES)
    expected = {}
    for label, mat, columns in (("A", linear.A, STATE_NAMES), ("B", linear.B, INPUT_NAMES)):
        scale = np.abs(mat).max()
        for i, row in enumerate(STATE_NAMES):
            for j, col in enumerate(columns):
                if (row, col) not in used[label] and abs(mat[i, j]) > DROP_RTOL * scale:
                    expected[(label, row, col)] = mat[i, j]
    assert {(d.matrix, d.row, d.column): d.value for d in dec.dropped} == expected
    assert ("A", "pN", "u") not in expected and ("A", "u", "theta") not in expected  # guidance's, pitch's


def test_every_report_subsystem_controllable_and_observable(forward):
    _, _, linear, dec, _ = forward
    for sub in dec.subsystems:
        c = check(sub.A, sub.B, sub.C, sub.states)
        assert c.controllable and c.observable and c.ctrb.rank == c.n, sub.name
        assert c.ctrb.tolerance > 0
    full = check(linear.A, linear.B)
    assert full.controllable and full.ctrb.rank == 12


def test_uncontrollable_mode_is_found_by_pbh():
    A = np.diag([1.0, -2.0])
    B = np.array([[0.0], [1.0]])
    c = check(A, B, names=["a", "b"])
    assert not c.controllable and not c.stabilizable
    bad = c.unstabilizable_modes
    assert len(bad) == 1 and bad[0].eigenvalue == 1.0 and bad[0].states == ("a",)
    assert check(np.diag([-1.0, -2.0]), B).stabilizable  # uncontrollable but stable


@pytest.mark.parametrize("order", [(1.0, 1.0 + 1e-10), (1.0 + 1e-10, 1.0)])
def test_a_mode_next_to_a_controllable_one_is_tested_at_its_own_eigenvalue(order):
    """Two unstable modes 1e-10 apart, one of them out of the input's reach: at the stated rank
    tolerance they are two modes (the SVD of ``[lambda I - A, B]`` at the unreached one has rank 1),
    and the Kalman matrix has rank 1; the verdict is not controllable, not stabilizable."""
    A = np.diag(order)
    reached = int(np.argmin(order))  # the input reaches the mode at 1
    B = np.eye(2)[:, [reached]]
    unreached = order[1 - reached]
    assert np.linalg.matrix_rank(np.hstack([unreached * np.eye(2) - A, B])) == 1
    assert np.linalg.matrix_rank(np.hstack([B, A @ B])) == 1
    c = check(A, B, names=["a", "b"])
    assert not c.controllable and not c.stabilizable
    assert [m.eigenvalue for m in c.unstabilizable_modes] == [unreached]
    assert c.unstabilizable_modes[0].states == ("ab"[1 - reached],)


@pytest.mark.parametrize("factor, controllable", [(1.2, True), (0.8, False)])
def test_a_nearly_unreached_mode_is_decided_by_the_stated_tolerance(factor, controllable):
    """``A = diag(-1, 1)``, ``B = [1; delta]``: the mode at 1 is reached through ``delta`` alone. The
    PBH matrix at 1 has singular values ``~sqrt(5)`` and ``2 delta / sqrt(5)``; the verdict flips where
    the smaller crosses ``tol = max(shape) eps sigma_max`` (docs/model.md, "Checks"), here at delta ~ 1.7e-15."""
    A = np.diag([-1.0, 1.0])
    pencil = np.hstack([np.eye(2) - A, [[1.0], [0.0]]])
    tol = 3 * np.finfo(float).eps * np.linalg.norm(pencil, 2)
    delta = factor * tol * math.sqrt(5) / 2  # sigma_min = factor * tol, to first order in delta
    B = np.array([[1.0], [delta]])
    sv = np.linalg.svd(np.hstack([np.eye(2) - A, B]), compute_uv=False)
    assert (sv[-1] > tol) == controllable
    c = check(A, B)
    assert c.controllable == controllable and c.stabilizable == controllable
    assert c.pbh_ctrb[[m.eigenvalue for m in c.pbh_ctrb].index(1.0)].rank == (2 if controllable else 1)


def test_a_mode_no_input_reaches_is_found_from_an_eigenvalue_off_by_round_off(monkeypatch):
    """``A = diag(-1, 1)``, ``B = [1; 0]``, its eigenvalues computed 1e-14 off (45 ``eps ||A||``, within the
    round-off an eigensolver leaves on an eigenvalue of condition number up to 100): at
    ``lambda = 1 + 1e-14`` the smallest singular value of ``[lambda I - A, B]`` is 1e-14, above the rank
    tolerance (1.5e-15), but the mode no input reaches is exactly there, and one Newton step on that
    singular value finds it."""
    eig = np.linalg.eig

    def off_by_round_off(a):
        w, v = eig(a)
        return w + 1e-14, v

    monkeypatch.setattr(np.linalg, "eig", off_by_round_off)
    c = check(np.diag([-1.0, 1.0]), np.array([[1.0], [0.0]]), np.array([[1.0, 1.0]]), names=["a", "b"])
    assert not c.controllable and not c.stabilizable and c.observable
    assert [(m.eigenvalue, m.states) for m in c.unstabilizable_modes] == [(1.0 + 1e-14, ("b",))]


def _staircase(rng):
    """A random ``(A, B)`` with ``nc`` of its ``n`` states reachable, in a random orthonormal basis: the
    reachable ones ``[A11, A12; 0, A22]``, ``B = [B1; 0]`` (Kalman's decomposition), so ``A22``'s modes are
    the ones no input reaches, exactly but for the round-off of the change of basis."""
    n, m = int(rng.integers(2, 7)), int(rng.integers(1, 3))
    nc = int(rng.integers(1, n + 1))
    A = rng.normal(size=(n, n))
    A[:nc, :nc] *= 10 ** rng.uniform(-1, 2)
    A[nc:, :nc] = 0.0
    B = np.vstack([rng.normal(size=(nc, m)), np.zeros((n - nc, m))])
    Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    return Q @ A @ Q.T, Q @ B, nc, np.linalg.eigvals(A[nc:, nc:])


def test_random_systems_in_a_rotated_kalman_decomposition_get_its_verdicts():
    """600 systems built in Kalman's decomposition and rotated (``_staircase``): controllable when every
    state is reachable, stabilizable when the unreachable block is stable; observable and detectable the
    same for ``(A', B')``. PBH at the computed eigenvalues alone gave one of them (case 244) the wrong
    verdict, and 9 in 2000 of a like set: the smallest singular value 1.1 to 9 times the tolerance at the
    computed eigenvalue, ~1e-16 within 3e-14 of it."""
    rng = np.random.default_rng(1)
    wrong = []
    for k in range(600):
        A, B, nc, lost = _staircase(rng)
        n = len(A)
        stable = bool(np.all(stability.is_stable(lost)))
        c = check(A, B)
        d = check(A.T, np.zeros((n, 1)), B.T)
        if (c.controllable, c.stabilizable, d.observable, d.detectable) != (nc == n, stable, nc == n, stable):
            wrong.append((k, n, nc))
    assert not wrong, f"systems given the wrong verdict (case, n, reachable): {wrong}"


def _subspace_states(basis, names) -> tuple[str, ...]:
    """The names of the rows of an orthonormal ``basis`` above a tenth of the largest row, largest first."""
    weight = np.linalg.norm(basis, axis=1)
    return tuple(names[i] for i in np.argsort(-weight) if weight[i] > 0.1 * weight.max())


@pytest.mark.parametrize("dual", [False, True], ids=["unreachable", "unobservable"])
def test_a_lost_mode_is_named_by_the_states_of_the_subspace_the_svd_leaves_out(dual):
    """Not a diagonal ``A``: ``a`` drives ``b`` (controllability), or ``b`` drives ``a`` (observability),
    and only ``b`` is actuated or measured. The states no input reaches span the left null space of the
    Kalman matrix; those no output sees, the null space of the observability matrix (both by SVD). The
    mode at s = 1 is named by them (``a``), not by its eigenvector on the other side (``b`` and ``a``)."""
    names = ["a", "b"]
    A = np.array([[1.0, 0.0], [5.0, -2.0]])
    b = np.array([[0.0], [1.0]])
    if dual:
        A = A.T
        c = check(A, np.zeros((2, 1)), b.T, names)
        u, sv, vh = np.linalg.svd(np.vstack([b.T, b.T @ A]))
        lost = vh[np.sum(sv > 1e-12):].T
        modes = c.pbh_obsv
    else:
        c = check(A, b, names=names)
        u, sv, _ = np.linalg.svd(np.hstack([b, A @ b]))
        lost = u[:, np.sum(sv > 1e-12):]
        modes = c.pbh_ctrb
    assert lost.shape == (2, 1)
    failed = [m for m in modes if not m.passed]
    assert [m.eigenvalue for m in failed] == [1.0]
    assert failed[0].states == _subspace_states(lost, names) == ("a",)


def test_scalar_integrator_closed_form():
    q, r = 9.0, 4.0
    K, P, E = lqr([[0.0]], [[1.0]], [[q]], [[r]])
    assert P[0, 0] == pytest.approx(math.sqrt(q * r))
    assert K[0, 0] == pytest.approx(math.sqrt(q / r))
    assert E[0] == pytest.approx(-math.sqrt(q / r))


def test_double_integrator_closed_form():
    """x'' = u, Q = diag(q1, q2), R = r: K = [sqrt(q1/r), sqrt(q2/r + 2 sqrt(q1/r))]."""
    q1, q2, r = 50.0, 3.0, 2.0
    K, P, _ = lqr([[0, 1], [0, 0]], [[0], [1]], np.diag([q1, q2]), [[r]])
    np.testing.assert_allclose(K[0], [math.sqrt(q1 / r), math.sqrt(q2 / r + 2 * math.sqrt(q1 / r))], rtol=1e-12)


def test_riccati_residuals_of_the_report_design(forward):
    *_, des = forward
    for s in des.subsystems:
        assert s.residual < 1e-10, s.name
        assert all(e.real < 0 for e in s.eigenvalues)
        np.testing.assert_allclose(s.P, s.P.T)
        assert np.linalg.eigvalsh(s.P).min() > 0


def test_the_assembled_weights_are_the_cost_each_loops_riccati_solution_prices(forward):
    """Q_block and R_block are the cost the design minimizes: on each subsystem's closed loop
    ``Ac = A - B K``, its ``P`` is the cost to go of ``x' Q_block x + u' R_block u`` from ``x``, the solution of
    ``Ac' P + P Ac + Q + K' R K = 0`` with the blocks at its states and inputs; nothing outside the blocks is
    weighed. Relative residual (the 1-norms of the equation's terms) at round-off of the Riccati solve."""
    *_, dec, des = forward
    Q_seen, R_seen = np.zeros_like(des.Q_block, dtype=bool), np.zeros_like(des.R_block, dtype=bool)
    for sub in des.subsystems:
        plant = dec[sub.name]
        cols = plant.state_index
        rows = [INPUT_INDEX[i] for i in sub.inputs]
        Q, R = des.Q_block[np.ix_(cols, cols)], des.R_block[np.ix_(rows, rows)]
        Q_seen[np.ix_(cols, cols)], R_seen[np.ix_(rows, rows)] = True, True
        Ac = plant.A - plant.B @ sub.K
        terms = (Ac.T @ sub.P, sub.P @ Ac, Q, sub.K.T @ R @ sub.K)
        residual = np.abs(terms[0] + terms[1] + terms[2] + terms[3]).sum(axis=0).max()
        assert residual <= 1e-10 * sum(np.abs(t).sum(axis=0).max() for t in terms), sub.name
    assert not np.any(des.Q_block[~Q_seen]) and not np.any(des.R_block[~R_seen])


def test_report_design_values(forward):
    """The report's loops: altitude K = [-sqrt(50), .], fast rate poles near -B/J."""
    *_, des = forward
    assert des["altitude"].K[0, 0] == pytest.approx(-math.sqrt(50))  # b < 0: thrust pushes up
    assert des["yaw"].K[0, 0] == pytest.approx(math.sqrt(50))
    assert min(e.real for e in des["roll"].eigenvalues) == pytest.approx(-14492.75, rel=1e-4)
    assert des.stable and des.marginal_states == ("pN", "pE")
    # the block gain holds each loop's K at its states
    assert des.K_block[1, STATE_NAMES.index("phi")] == des["roll"].K[0, 1]
    assert np.count_nonzero(des.K_block) == 10


def test_riccati_residual_detects_a_wrong_solution():
    A, B, Q, R = np.array([[0.0]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[1.0]])
    assert riccati_residual(A, B, Q, R, np.array([[1.0]])) < 1e-15
    assert riccati_residual(A, B, Q, R, np.array([[1.5]])) > 0.1


def test_not_stabilizable_subsystem_names_the_mode():
    with pytest.raises(DesignError, match=r"sys: not stabilizable: the mode at eigenvalue 1 \(in a\)"):
        lqr(np.diag([1.0, -2.0]), [[0.0], [1.0]], np.eye(2), [[1.0]], name="sys", state_names=["a", "b"])


def test_design_on_report_partition_is_stable_on_hover(forward):
    from quadctl import config, pipeline
    from quadctl.setup import setup_of

    setup = setup_of(config.load("hover"))
    linear = pipeline.linear_of(setup, pipeline.trim_of(setup))
    des = design(decouple(linear.A, linear.B, REPORT_PARTITION), linear.A, linear.B, setup.weights)
    assert des.stable


@pytest.mark.parametrize("tiny", [5.59673574e-301, 2.22507386e-309])
def test_subnormal_entries_do_not_spoil_the_riccati_solve(tiny):
    """Found by hypothesis: SciPy's balancing fails on entries near the underflow limit."""
    A = np.array([[-1.0, tiny], [1.0, 0.0]])
    K, P, E = lqr(A, [[0.0], [1.0]], np.diag([1e-3, 1.0]), [[0.1]])
    assert riccati_residual(A, np.array([[0.0], [1.0]]), np.diag([1e-3, 1.0]), np.array([[0.1]]), P) < 1e-12
    assert all(e.real < 0 for e in E)


def test_a_slow_stable_mode_gets_a_newton_refined_riccati_solution():
    """Found by hypothesis: a mode at -7e-7 rad/s (B = 0, so P solves a Lyapunov equation) left
    SciPy's Schur solution at residual 6e-8, above RICCATI_RTOL; Newton-Kleinman fixes it."""
    import scipy.linalg

    A = np.array([[-1.5, 0.0, 0.03125], [-1.0, 0.0, 0.0], [0.0, 6.9e-5, -2.0]])
    B, Q = np.zeros((3, 3)), np.eye(3) * 1e-3
    R = np.array([[1.1, 2.0, 0.0], [2.0, 4.1, 0.0], [0.0, 0.0, 0.1]])
    scipy_alone = riccati_residual(A, B, Q, R, scipy.linalg.solve_continuous_are(A, B, Q, R))
    K, P, E = lqr(A, B, Q, R)
    assert riccati_residual(A, B, Q, R, P) < 1e-9 < scipy_alone
    np.testing.assert_allclose(A.T @ P + P @ A, -Q, atol=1e-9 * np.abs(P).max())


def test_a_barely_weighted_slow_mode_is_solved_to_its_exact_residual():
    """Found by hypothesis: a stable mode at -2e-6 rad/s that Q barely weighs. The residual of
    P S P formed as (P S) P read 2.4e-8 and the design was refused as ill-conditioned; the exact
    residual of the same P (rational arithmetic) is 4e-11, which the residual formed from G = P B,
    G R^-1 G', reports: the design is certified."""
    from fractions import Fraction

    A = np.array([[-1.0, 0.0, 0.03125], [-1.0, 0.0, 0.0], [0.0, 6.9e-5, -1.0]])
    B = np.array([[-1.0, 0.0, 0.03125], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    Q, R = np.eye(3) * 1e-3, np.eye(3) * 0.1
    K, P, E = res = lqr(A, B, Q, R)
    assert max(E.real) == pytest.approx(-2.1457e-6, rel=1e-4)

    def exact(M):
        return [[Fraction(float(v)) for v in row] for row in np.atleast_2d(M)]

    def mul(X, Y):
        return [[sum(X[i][k] * Y[k][j] for k in range(len(Y))) for j in range(len(Y[0]))] for i in range(len(X))]

    Ae, Be, Qe, Pe = exact(A), exact(B), exact(Q), exact(P)
    At, G = [list(r) for r in zip(*Ae)], mul(Pe, Be)
    quad = mul([[g / Fraction(0.1) for g in row] for row in G], [list(r) for r in zip(*G)])  # R = 0.1 I
    terms = (mul(At, Pe), mul(Pe, Ae), quad, Qe)
    residual = [[terms[0][i][j] + terms[1][i][j] - terms[2][i][j] + terms[3][i][j] for j in range(3)]
                for i in range(3)]

    def norm1(M):
        return max(sum(abs(float(M[i][j])) for i in range(3)) for j in range(3))

    truth = norm1(residual) / sum(norm1(t) for t in terms)
    assert truth < 1e-10 and res.residual == pytest.approx(truth, rel=1e-3)


def test_scipy_fallback_gives_the_same_design_as_quadctls_solver(forward, monkeypatch):
    """lqr solves with quadctl's batched solver and falls back to SciPy where it has no answer:
    both paths, on every report subsystem, give the same gain and pass the residual check."""
    import dataclasses

    from quadctl.design.riccati import single

    _, _, _, dec, des = forward
    weights = {s.name: (s.Q, s.R) for s in des.subsystems}
    own = {s.name: lqr(s.A, s.B, *weights[s.name]) for s in dec.regulated}

    solve = single.care_checked

    def no_answer(*args):
        res = solve(*args)
        return dataclasses.replace(res, ok=np.zeros_like(res.ok), P=np.full_like(res.P, np.nan))

    monkeypatch.setattr(single, "care_checked", no_answer)
    for sub in dec.regulated:
        fallback = lqr(sub.A, sub.B, *weights[sub.name])
        assert fallback.residual < 1e-12 and own[sub.name].residual < 1e-12, sub.name
        diff = np.abs(fallback.K - own[sub.name].K).max() / np.abs(own[sub.name].K).max()
        assert diff < 1e-9, f"{sub.name}: Max diff is {diff:.4E}"


def test_mismatched_shapes_are_an_argument_error_naming_the_matrix():
    with pytest.raises(ArgumentError, match=r"roll: R has shape \(2, 2\), expected \(1, 1\)"):
        lqr(np.eye(2), [[0.0], [1.0]], np.eye(2), np.eye(2), name="roll")


@pytest.mark.parametrize("solver", ["lqr", "dlqr", "lqrd", "care_batch", "dare_batch"])
@pytest.mark.parametrize("n, m", [(0, 1), (2, 0), (0, 0)])
def test_a_problem_with_no_state_or_no_input_is_an_argument_error(solver, n, m):
    """An empty A or B failed inside the weight check with NumPy's 'zero-size array to reduction
    operation maximum which has no identity' (a bare ValueError)."""
    import quadctl as qc
    from quadctl.design.riccati import care_batch, dare_batch

    A, B, Q, R = np.zeros((n, n)), np.zeros((n, m)), np.eye(n), np.eye(m)
    call = {"lqr": lambda: qc.lqr(A, B, Q, R), "dlqr": lambda: qc.dlqr(A, B, Q, R),
            "lqrd": lambda: qc.lqrd(A, B, Q, R, 0.1),
            "care_batch": lambda: care_batch(A[None], B[None], Q[None], R[None]),
            "dare_batch": lambda: dare_batch(A[None], B[None], Q[None], R[None])}[solver]
    with pytest.raises(ArgumentError, match=rf"the problem has {n} states and {m} inputs .*at least one of each"):
        call()


@pytest.mark.parametrize("design_kind, expected_mode", [("discrete", "discrete"), ("continuous", "emulated")])
def test_discrete_or_continuous_is_the_designs_own_property(design_kind, expected_mode):
    """The setup says what to design at; the design it gives carries its own sample time (as a
    python-control system carries its dt), and the chain's emulated-rate check runs only for a
    continuous design that a rate samples."""
    from _solve import cfg_dict

    from quadctl import config, pipeline
    from quadctl.setup import Timing, setup_of

    data = cfg_dict("mambo-200hz")
    data["controller"].update(design=design_kind, rate=20.0)  # slower than the continuous design's fast loops
    stages = pipeline.Stages(setup_of(config.from_dict(data)))
    assert stages.setup.timing.mode == expected_mode and stages.setup.timing.rate == 20
    assert stages.design.sample_time == (1 / 20 if design_kind == "discrete" else None)
    assert stages.design.rate == (20 if design_kind == "discrete" else None)
    assert (stages.rate_warnings == ()) == (design_kind == "discrete")  # 20 Hz cannot realize the fast loops
    continuous = pipeline.design_at(stages.setup, stages.decoupled, stages.linear, None)
    assert continuous.sample_time is None
    with pytest.raises(ValueError, match="design_rate 100 Hz: a discrete design is computed at the controller's"):
        Timing(rate=20.0, design_rate=100.0)


def test_a_newton_step_toward_infinity_ends_the_pbh_search_quietly(monkeypatch):
    """A singular vector pair whose slope is 1e-320 makes the next step 1e320, past the reach: the search stops
    there with the rank it found, and the overflow is not a RuntimeWarning (``quadctl check`` would print it)."""
    import warnings

    from quadctl.linear import analysis

    real = np.linalg.svd

    def svd(M, *args, **kwargs):  # [mu - a, b]: the right singular vector's first entry 1e-320
        if M.shape == (1, 2):
            return np.eye(1), np.array([1.0]), np.array([[1e-320, 1.0], [1.0, -1e-320]])
        return real(M, *args, **kwargs)

    monkeypatch.setattr(analysis.np.linalg, "svd", svd)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert analysis._pbh_rank(0.0, np.zeros((1, 1)), np.ones((1, 1)), False, 1e-12) == (1, None)
