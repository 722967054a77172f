"""The orthogonal controllability staircase (quadctl.linear.staircase) and the verdicts check takes from it.

References are systems built in Kalman's decomposition, ``[[A_cc, A_cu], [0, A_uu]]``, ``[[B_c], [0]]``, and
turned by a random orthogonal matrix: their controllable dimension and their uncontrollable eigenvalues
are known by construction, whatever the staircase and the eigensolver make of them.
"""

from __future__ import annotations

import numpy as np
import pytest

from quadctl.linear import stability
from quadctl.linear.analysis import check, pbh
from quadctl.linear.staircase import staircase

EPS = np.finfo(float).eps
JORDAN_GAP = 1e-12
"""The two eigenvalues of a nearly defective block ``[[a, 1], [0, a + JORDAN_GAP]]``."""
JORDAN_EIG_ATOL = 1e-4
"""A nearly defective pair's eigenvalues are fixed to ``~sqrt(eps ||A||)`` times their condition only
(up to 1.7e-5 seen over 3000 random systems); their sum, the block's trace, to round-off."""


def _rotated(rng, A, B):
    """``(Q A Q^T, Q B)`` for a random orthogonal ``Q``."""
    Q, _ = np.linalg.qr(rng.normal(size=A.shape))
    return Q @ A @ Q.T, Q @ B


def _kalman_form(rng, nc, m, A_uu, *, coupled=True):
    """A random controllable ``(A_cc, B_c)`` of ``nc`` states and ``m`` inputs above ``A_uu``, with a random
    ``A_cu`` (zero when not ``coupled``); ``A``, ``B`` in Kalman's form."""
    nu = len(A_uu)
    A = np.zeros((nc + nu, nc + nu))
    A[:nc, :nc] = rng.normal(size=(nc, nc)) * 10 ** rng.uniform(-1, 2)
    A[:nc, nc:] = rng.normal(size=(nc, nu)) if coupled else 0.0
    A[nc:, nc:] = A_uu
    B = np.vstack([rng.normal(size=(nc, m)), np.zeros((nu, m))])
    return A, B


def _nearly_defective(rng):
    """A random system with a nearly defective block ``[[a, 1], [0, a + 1e-12]]`` out of reach (and, half
    the time, one more mode out of reach), coupled to the reached states: ``(A, B, nc, lost eigenvalues)``,
    turned by a random orthogonal matrix."""
    a = rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(-1, 1)
    A_uu = np.array([[a, 1.0], [0.0, a + JORDAN_GAP]])
    if rng.integers(0, 2):
        A_uu = np.block([[A_uu, rng.normal(size=(2, 1))], [np.zeros((1, 2)), rng.normal(size=(1, 1))]])
    nc = int(rng.integers(1, 5))
    A, B = _kalman_form(rng, nc, int(rng.integers(1, 3)), A_uu)
    return (*_rotated(rng, A, B), nc, np.linalg.eigvals(A_uu))


def _eigenvalues_off(monkeypatch, by: float = 6e-4) -> None:
    """Every eigenvalue NumPy's eigensolver returns moved by ``by`` (6e-4: a nearly defective pair's error seen),
    its eigenvectors kept: what PBH then tests at."""
    eig = np.linalg.eig

    def off(a):
        w, v = eig(a)
        return w + by, v

    monkeypatch.setattr(np.linalg, "eig", off)


def _matched(found, exact) -> np.ndarray:
    """``|found - exact|`` pairing each exact eigenvalue with its nearest found one (a multiset match)."""
    from scipy.optimize import linear_sum_assignment

    cost = np.abs(np.asarray(found)[:, None] - np.asarray(exact)[None, :])
    rows, cols = linear_sum_assignment(cost)
    return cost[rows, cols]


@pytest.mark.parametrize("nc, m, A_uu", [
    (3, 1, np.array([[0.5]])),
    (2, 2, np.diag([-1.0, 2.0])),
    (4, 1, np.array([[0.5, 1.0], [0.0, 0.5 + JORDAN_GAP]])),
    (4, 2, np.array([[-0.5, 1.0], [0.0, -0.5 + JORDAN_GAP]])),
    (1, 1, np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])),  # a triple integrator out of reach
], ids=["one-unstable", "two-distinct", "jordan-unstable", "jordan-stable", "triple-integrator"])
def test_the_staircase_finds_the_constructed_form(nc, m, A_uu):
    """The controllable dimension is ``nc``; ``Q`` is orthogonal and brings ``(A, B)`` to the returned form,
    zero below the staircase; the eigenvalues of ``A_uu`` are the constructed ones (their sum to round-off);
    each direction out of reach is a left eigenvector of ``A`` that ``B`` does not reach."""
    rng = np.random.default_rng(3)
    A, B = _rotated(rng, *_kalman_form(rng, nc, m, A_uu))
    s = staircase(A, B)
    n = len(A)
    scale = np.linalg.norm(A, 2)
    assert s.controllable_dim == nc and sum(s.steps) == nc
    Q = s.transform
    np.testing.assert_allclose(Q.T @ Q, np.eye(n), atol=10 * n * EPS)
    assert np.all(s.A[nc:, :nc] == 0.0) and np.all(s.B[nc:] == 0.0)
    assert np.abs(Q.T @ A @ Q - s.A).max() <= max(s.tolerance)
    np.testing.assert_allclose(Q.T @ B, s.B, atol=10 * n * EPS * np.linalg.norm(B, 2))
    exact = np.linalg.eigvals(A_uu)
    assert _matched(s.uncontrollable_eigenvalues, exact).max() <= JORDAN_EIG_ATOL
    assert abs(s.uncontrollable_eigenvalues.sum() - np.trace(A_uu)) <= 1e3 * n * EPS * scale
    for lam, y in zip(s.uncontrollable_eigenvalues, s.uncontrollable_directions.T):
        assert np.linalg.norm(y.conj() @ B) <= 1e3 * EPS * np.linalg.norm(B, 2)
        assert np.linalg.norm(y.conj() @ A - lam * y.conj()) <= JORDAN_EIG_ATOL * max(1.0, scale)
    c = check(A, B)
    stable = bool(np.all(stability.is_stable(exact)))
    assert (c.controllable, c.stabilizable, c.controllable_dim) == (False, stable, nc)


def test_a_controllable_pair_has_no_block_out_of_reach():
    """``x' = A x + B u`` with ``A`` a chain ``x1 <- x2 <- x3`` and ``u`` at the end: three steps of one."""
    A = np.diag([2.0, 3.0], 1)
    s = staircase(A, [[0.0], [0.0], [1.0]])
    assert (s.controllable_dim, s.steps, s.uncontrollable_eigenvalues.size) == (3, (1, 1, 1), 0)
    assert s.uncontrollable_directions.shape == (3, 0)
    nc, Q, lost = s
    assert nc == 3 and Q.shape == (3, 3) and lost.size == 0


def test_no_input_reaches_nothing():
    """``B = 0``: every state is out of reach, ``A_uu`` is ``A`` itself (turned)."""
    A = np.array([[1.0, 2.0], [0.0, -3.0]])
    s = staircase(A, np.zeros((2, 1)))
    assert s.controllable_dim == 0 and s.steps == ()
    np.testing.assert_allclose(np.sort(s.uncontrollable_eigenvalues.real), [-3.0, 1.0])


@pytest.mark.parametrize("factor, reached", [(1.5, 2), (0.5, 1)])
def test_a_weak_coupling_is_decided_by_the_stated_tolerance(factor, reached):
    """``A = [[1, 0], [delta, 0]]``, ``B = [1; 0]``: ``x2`` is reached through ``delta`` alone. The first step
    keeps ``B``'s singular value 1 (tolerance ``(n + m) eps ||B|| = 3 eps``, drift ``3 eps / 1``); the second
    decides ``delta`` against ``||A|| (drift + (n + m) eps) = 6 eps``: reached above it, not below. The rule is
    relative to ``||A||``: with ``A = [[0, 0], [delta, 0]]`` (``||A|| = delta``) the same ``delta`` is reached."""
    n, m = 2, 1
    tol = (n + m) * EPS + (n + m) * EPS
    delta = factor * tol
    A = np.array([[1.0, 0.0], [delta, 0.0]])
    s = staircase(A, [[1.0], [0.0]])
    assert s.controllable_dim == reached
    assert s.tolerance == pytest.approx(((n + m) * EPS, tol), rel=1e-12)
    assert staircase(np.array([[0.0, 0.0], [delta, 0.0]]), [[1.0], [0.0]]).controllable_dim == 2


def test_scaling_the_inputs_changes_no_decision():
    """``B`` and ``1e4 B`` (inputs through ``1/J``): the same steps, the same ``Q`` up to round-off."""
    rng = np.random.default_rng(11)
    A, B = _rotated(rng, *_kalman_form(rng, 3, 2, np.array([[0.3, 1.0], [0.0, 0.3 + JORDAN_GAP]])))
    one, big = staircase(A, B), staircase(A, 1e4 * B)
    assert one.steps == big.steps and one.controllable_dim == big.controllable_dim == 3
    np.testing.assert_allclose(np.abs(one.transform.T @ big.transform)[:3, :3] @ np.ones(3), np.ones(3), atol=1e-9)


@pytest.mark.parametrize("shape_a, shape_b, match", [
    ((2, 3), (2, 1), r"A must be square; got shape \(2, 3\)"),
    ((2, 2), (3, 1), r"B must have 2 rows \(A is 2 x 2\); got shape \(3, 1\)"),
])
def test_shapes_are_refused_by_name(shape_a, shape_b, match):
    with pytest.raises(ValueError, match=match):
        staircase(np.zeros(shape_a), np.zeros(shape_b))


def test_a_mode_pbh_misses_in_a_nearly_defective_block_is_out_of_reach(monkeypatch):
    """A nearly defective block ``[[0.5, 1], [0, 0.5 + 1e-12]]`` no input reaches, coupled to two reached states:
    its computed eigenvalues may be off by ~sqrt(eps) (6e-4 seen), beyond PBH's Newton steps. With every
    eigenvalue the eigensolver returns moved by 6e-4, PBH alone calls the pair controllable; the staircase,
    which needs no eigenvalue for its dimension, finds the two states out of reach, so check does not, and
    the mode, unstable, makes it not stabilizable: named by the states of the direction no input reaches."""
    rng = np.random.default_rng(5)
    A_uu = np.array([[0.5, 1.0], [0.0, 0.5 + JORDAN_GAP]])
    A, B = _rotated(rng, *_kalman_form(rng, 2, 1, A_uu))
    names = ["a", "b", "c", "d"]
    _eigenvalues_off(monkeypatch)
    assert all(m.passed for m in pbh(A, B, names))
    c = check(A, B, names=names)
    assert not c.controllable and not c.stabilizable and c.controllable_dim == 2
    lost = c.unstabilizable_modes
    assert len(lost) == 2 and all(abs(m.eigenvalue - 0.5 - 6e-4) <= JORDAN_EIG_ATOL for m in lost)
    y = np.abs(staircase(A, B).uncontrollable_directions[:, 0])
    assert lost[0].states == tuple(names[i] for i in np.argsort(-y) if y[i] > 0.1 * y.max())


def test_random_nearly_defective_systems_out_of_reach_get_their_verdicts():
    """300 systems with a nearly defective block out of reach (``_nearly_defective``): the staircase finds
    every controllable dimension, and check calls each not controllable, stabilizable by the sign of ``a``.
    PBH at the computed eigenvalues alone gets some wrong (3 of these 300 on one machine; round-off decides
    which, so the count is in the message, not asserted)."""
    rng = np.random.default_rng(2)
    pbh_wrong, wrong = [], []
    for k in range(300):
        A, B, nc, lost = _nearly_defective(rng)
        stable = bool(np.all(stability.is_stable(lost)))
        modes = pbh(A, B, [f"x{i}" for i in range(len(A))])
        if (all(m.passed for m in modes), all(m.passed or stability.is_stable(m.eigenvalue) for m in modes)) != (
                False, stable):
            pbh_wrong.append(k)
        c = check(A, B)
        if (c.controllable, c.stabilizable, c.controllable_dim) != (False, stable, nc):
            wrong.append(k)
    assert not wrong, f"check wrong for {wrong}; PBH alone wrong for {pbh_wrong}"


@pytest.mark.parametrize("seed", range(4))
def test_random_controllable_systems_stay_controllable(seed):
    """No false alarm: 100 random ``(A, B)``, ``A`` scaled by 0.1 to 100, each input by 0.01 to 1e4 (the models'
    ``1/J``), and as many integrator chains with an input at the end through 1 to 1e5, some turned."""
    rng = np.random.default_rng(seed)
    for _ in range(50):
        n, m = int(rng.integers(2, 13)), int(rng.integers(1, 5))
        A = rng.normal(size=(n, n)) * 10 ** rng.uniform(-1, 2)
        B = rng.normal(size=(n, m)) * 10 ** rng.uniform(-2, 4, size=m)
        assert staircase(A, B).controllable_dim == n
        assert check(A, B).controllable
    for _ in range(50):
        k = int(rng.integers(2, 5))
        A = np.diag(10 ** rng.uniform(-1, 1.5, size=k - 1), 1) + np.diag(rng.uniform(-1, 0, size=k))
        B = np.zeros((k, 1))
        B[-1] = 10 ** rng.uniform(0, 5)
        if rng.integers(0, 2):
            A, B = _rotated(rng, A, B)
        assert staircase(A, B).controllable_dim == k
        assert check(A, B).controllable


def test_the_attitude_loop_inputs_through_inverse_inertia_are_no_false_alarm():
    """Pitch: ``u' = -0.23 u - 9.81 theta``, ``theta' = q``, ``q' = M / J_y`` with ``1/J_y = 6e4``
    (a Crazyflie's): controllable in three steps of one, however it is turned."""
    A = np.array([[-0.23, -9.81, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    B = np.array([[0.0], [0.0], [6.0e4]])
    assert staircase(A, B).steps == (1, 1, 1)
    rng = np.random.default_rng(2)
    assert staircase(*_rotated(rng, A, B)).steps == (1, 1, 1)


@pytest.mark.parametrize("name", ["hover", "forward", "crazyflie", "mambo-200hz"])
def test_the_bundled_configs_are_controllable_and_observable_by_the_staircase(name):
    """The regulated subsystems and the 12-state model of a bundled config (``import quadctl as qc``): every
    state reached and seen. A hover's guidance block (``pN``, ``pE``; ``u`` drives ``pN`` alone at zero yaw,
    ``A = 0``) has ``pE`` out of reach."""
    import quadctl as qc

    stages = qc.Stages(qc.setup_of(qc.load_config(name)))
    for sub in stages.decoupled.regulated:
        c = check(sub.A, sub.B, sub.C, sub.states)
        assert (c.controllable_dim, c.observable_dim) == (c.n, c.n), sub.name
    full = check(stages.linear.A, stages.linear.B)
    assert (full.controllable_dim, full.observable_dim, full.controllable) == (12, 12, True)
    if name == "hover":
        guidance = next(s for s in stages.decoupled.subsystems if s.name == "guidance")
        assert np.all(guidance.A == 0.0) and np.all(guidance.B[1] == 0.0)
        c = check(guidance.A, guidance.B, guidance.C, guidance.states)
        assert c.controllable_dim == 1 and [m.states for m in c.lost_ctrb] == [("pE",)]


@pytest.mark.parametrize("seed", range(3))
def test_observability_is_controllability_of_the_transpose(seed):
    """``(A, C)`` built in the dual Kalman form (``A^T``, ``C^T`` in Kalman's form, nearly defective block
    unseen): observable dimension, unobservable modes and verdicts are those of ``(A^T, C^T)``, and the
    constructed ones."""
    rng = np.random.default_rng(seed)
    At, Ct, no, lost = _nearly_defective(rng)
    A, C = At.T, Ct.T
    n = len(A)
    c = check(A, np.eye(n), C)
    d = check(At, Ct, np.eye(n))
    assert (c.observable, c.detectable, c.observable_dim) == (d.controllable, d.stabilizable, d.controllable_dim)
    assert (c.observable, c.observable_dim, c.detectable) == (False, no, bool(np.all(stability.is_stable(lost))))
    assert [m.eigenvalue for m in c.lost_obsv] == [m.eigenvalue for m in d.lost_ctrb]
    assert [m.states for m in c.lost_obsv] == [m.states for m in d.lost_ctrb]
    assert c.controllable and c.controllable_dim == n


def test_a_measured_set_that_leaves_a_nearly_defective_unstable_block_unseen_is_refused(monkeypatch):
    """The dual of the PBH miss above: ``(A, C)`` with a nearly defective unstable block no output sees, every
    computed eigenvalue moved by 6e-4. PBH alone sees every mode; the observability staircase does not, and the
    Kalman filter's check (``require_detectable``) refuses the measured set, naming the states of the unseen
    direction."""
    from quadctl.design.kalman import require_detectable
    from quadctl.errors import DesignError

    rng = np.random.default_rng(5)
    At, Ct = _rotated(rng, *_kalman_form(rng, 2, 1, np.array([[0.5, 1.0], [0.0, 0.5 + JORDAN_GAP]])))
    A, C = At.T, Ct.T
    names = ["a", "b", "c", "d"]
    unseen = np.abs(staircase(At, Ct).uncontrollable_directions)
    _eigenvalues_off(monkeypatch)
    assert all(m.passed for m in pbh(A, C, names, dual=True))
    expected = sorted({names[i] for col in unseen.T for i in range(4) if col[i] > 0.1 * col.max()}, key=names.index)
    with pytest.raises(DesignError, match=rf'^estimator.measure = \["y"\]: {", ".join(expected)} not observable '
                                          r"\(modes at s = .*, not stable\): measure "):
        require_detectable(A, C, ["y"], names=names)


def test_a_design_refuses_a_nearly_defective_unstable_block_no_input_reaches(monkeypatch):
    """The design's own check (``require_stabilizable``, before any Riccati solve) on the system PBH misses
    above: it refuses it as not stabilizable, naming the mode the staircase finds out of reach, where PBH
    alone let the solve go on to fail without saying why."""
    from quadctl.design.riccati import require_stabilizable, unstabilizable_mode
    from quadctl.errors import DesignError

    rng = np.random.default_rng(5)
    A, B = _rotated(rng, *_kalman_form(rng, 2, 1, np.array([[0.5, 1.0], [0.0, 0.5 + JORDAN_GAP]])))
    names = ["a", "b", "c", "d"]
    _eigenvalues_off(monkeypatch)
    assert all(m.passed for m in pbh(A, B, names))
    mode = unstabilizable_mode(A, B, names)
    assert mode is not None and abs(mode.eigenvalue - 0.5 - 6e-4) <= JORDAN_EIG_ATOL
    with pytest.raises(DesignError, match=r"^sys: not stabilizable: the mode at eigenvalue .* is unstable and no "
                                          r"input reaches it"):
        require_stabilizable(A, B, "sys", names)
    stable = _rotated(rng, *_kalman_form(rng, 2, 1, np.array([[-0.5, 1.0], [0.0, -0.5 + JORDAN_GAP]])))
    assert unstabilizable_mode(*stable, names) is None  # out of reach but stable: stabilizable


@pytest.mark.parametrize("dual", [False, True])
def test_pbh_names_the_state_no_input_reaches_at_a_repeated_eigenvalue(dual):
    """A hover's guidance block: two integrators (eigenvalue 0 twice), an input on pN alone. Any vector is an
    eigenvector of A = 0, so the eigensolver's first (pN) named the lost mode; the direction no input reaches
    (no output sees) is pE, which the staircase finds too."""
    A, M, names = np.zeros((2, 2)), np.array([[1.0], [0.0]]), ["pN", "pE"]
    tests = pbh(A, M.T if dual else M, names, dual=dual)
    assert len(tests) == 1 and not tests[0].passed and tests[0].states == ("pE",)
    lost = check(A, M, C=M.T, names=names)
    assert (lost.lost_obsv if dual else lost.lost_ctrb)[0].states == ("pE",)
