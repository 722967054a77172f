"""Discrete LQR (lqrd/dlqr) against hand-derived cases and SciPy, the controller rate, the ZOH simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
from _solve import cfg_dict, run, solve

from quadctl import pipeline
from quadctl.design import discrete, lqr, riccati
from quadctl.errors import StepSizeError
from quadctl.present.stages import rate_warning
from quadctl.sim.plan import plan_held_step

RESIDUAL_TOL = 1e-10
"""Riccati residuals of well-scaled small problems are at round-off level (relative)."""


@pytest.mark.parametrize("q, r, Ts", [(1.0, 1.0, 1.0), (4.0, 0.5, 0.01), (50.0, 1.0, 0.005)])
def test_dlqr_sampled_integrator_matches_the_hand_derived_riccati_root(q, r, Ts):
    """x[k+1] = x[k] + Ts u[k]: the DARE reduces to P^2 Ts^2 = q r + q Ts^2 P (positive root)."""
    P_hand = (q * Ts**2 + math.sqrt(q**2 * Ts**4 + 4 * q * r * Ts**2)) / (2 * Ts**2)
    K_hand = Ts * P_hand / (r + Ts**2 * P_hand)
    K, P, E = discrete.dlqr([[1.0]], [[Ts]], [[q]], [[r]])
    assert P[0, 0] == pytest.approx(P_hand, rel=1e-12)
    assert K[0, 0] == pytest.approx(K_hand, rel=1e-12)
    assert E[0] == pytest.approx(1 - Ts * K_hand, rel=1e-12)


def test_lqrd_weights_of_the_integrator_are_the_hand_integrals():
    """x' = u, ZOH: x(tau) = x + tau u, so Qd = q Ts, Nd = q Ts^2/2, Rd = r Ts + q Ts^3/3."""
    q, r, Ts = 3.0, 2.0, 0.3
    Ad, Bd, Qd, Rd, Nd = discrete.lqrd_weights([[0.0]], [[1.0]], [[q]], [[r]], Ts)
    assert (Ad[0, 0], Bd[0, 0]) == pytest.approx((1.0, Ts), rel=1e-14)
    assert Qd[0, 0] == pytest.approx(q * Ts, rel=1e-13)
    assert Nd[0, 0] == pytest.approx(q * Ts**2 / 2, rel=1e-13)
    assert Rd[0, 0] == pytest.approx(r * Ts + q * Ts**3 / 3, rel=1e-13)


def test_c2d_double_integrator_is_exact():
    Ts = 0.05
    Ad, Bd = discrete.c2d([[0, 1], [0, 0]], [[0], [1]], Ts)
    np.testing.assert_allclose(Ad, [[1, Ts], [0, 1]], atol=1e-15)
    np.testing.assert_allclose(Bd, [[Ts**2 / 2], [Ts]], atol=1e-15)


def test_dlqr_with_cross_term_agrees_with_solve_discrete_are_and_matlab_gain_formula():
    rng = np.random.default_rng(7)
    A = rng.normal(size=(4, 4)) * 0.6
    B = rng.normal(size=(4, 2))
    M = rng.normal(size=(6, 6))
    W = M @ M.T + 0.1 * np.eye(6)  # [[Q, N], [N', R]] positive definite
    Q, N, R = W[:4, :4], W[:4, 4:], W[4:, 4:]
    K, P, E = discrete.dlqr(A, B, Q, R, N)
    P_scipy = scipy.linalg.solve_discrete_are(A, B, Q, R, s=N)
    np.testing.assert_allclose(P, P_scipy, rtol=1e-10)
    np.testing.assert_allclose(K, np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A + N.T), rtol=1e-10)
    assert riccati.dare_residual(A, B, Q, R, P, N) < RESIDUAL_TOL
    assert np.all(np.abs(E) < 1)


def test_dlqr_matches_python_control():
    control = pytest.importorskip("control")
    A = np.array([[1.0, 0.01], [0.0, 0.98]])
    B = np.array([[0.0], [0.01]])
    Q, R = np.diag([10.0, 1.0]), np.array([[0.1]])
    K, P, _ = discrete.dlqr(A, B, Q, R)
    K_ct, P_ct, _ = control.dlqr(A, B, Q, R)
    np.testing.assert_allclose(K, K_ct, rtol=1e-9)
    np.testing.assert_allclose(P, P_ct, rtol=1e-9)


def test_lqrd_tends_to_the_continuous_gain_as_the_sample_time_shrinks():
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    B = np.array([[0.0], [1.0]])
    Q, R = np.diag([4.0, 1.0]), np.array([[1.0]])
    K_c = lqr(A, B, Q, R).K
    errors = [np.abs(discrete.lqrd(A, B, Q, R, Ts).K - K_c).max() for Ts in (1e-2, 1e-3)]
    assert 8 < errors[0] / errors[1] < 12  # the gap is first order in Ts (order 2 would give 100)
    assert errors[1] < 1e-3 * np.abs(K_c).max() * 2


def test_design_at_a_rate_is_lqrd_per_subsystem_and_stable_in_z():
    data = cfg_dict("forward", controller={"rate": 200.0})
    setup, _, linear, dec, des = solve(data)
    assert des.rate == 200.0 and des.stable
    roll = dec["roll"]
    Q, R = setup.weights["roll"]
    np.testing.assert_allclose(des["roll"].K, discrete.lqrd(roll.A, roll.B, Q, R, 1 / 200).K, rtol=1e-12)
    z = des.full_eigenvalues_z
    core = z[np.abs(z - 1) > 1e-9]  # pN, pE: z = 1 exactly
    assert np.all(np.abs(core) < 1)
    # the report's weights at 200 Hz: the rate loops saturate to near-deadbeat, gains ~58x smaller
    assert des["roll"].K[0, 1] < solve(cfg_dict("forward"))[4]["roll"].K[0, 1] / 50


S_EQUIVALENT_RTOL = 1e-2
"""Relative gap allowed between a 1 kHz design's s-equivalent poles and the continuous design's: lqrd's
gain tends to lqr's to first order in ``Ts`` (test above), so the poles to about ``Ts |s| = 0.012`` at
the altitude loop's -12 rad/s; seen: 1.3e-5."""


def test_a_fast_rate_designs_s_plane_eigenvalues_are_the_continuous_designs_poles():
    """A discrete design reports each subsystem's poles on the continuous scale, ``s = ln(z) / Ts``:
    ``exp(s Ts)`` gives back its ``z``, and at 1 kHz, far above the altitude loop's bandwidth, they are
    the continuous LQR's poles (rad/s), which an independent ``lqr`` of the same subsystem gives."""
    Ts = 1e-3
    setup, _, _, dec, des = solve(cfg_dict("hover", controller={"rate": 1 / Ts}))
    alt = des["altitude"]
    np.testing.assert_allclose(np.exp(alt.eigenvalues * Ts), alt.eigenvalues_z, rtol=1e-12)
    sub = dec["altitude"]
    continuous = np.sort_complex(np.linalg.eigvals(sub.A - sub.B @ lqr(sub.A, sub.B, *setup.weights["altitude"]).K))
    np.testing.assert_allclose(np.sort_complex(alt.eigenvalues), continuous, rtol=S_EQUIVALENT_RTOL)


def test_check_warns_which_loop_is_too_fast_for_the_rate_and_by_how_much():
    setup, _, linear, dec, _ = solve(cfg_dict("forward"))
    warnings = {w.loop: w for w in pipeline.rate_warnings_of(setup, dec, linear, 200.0)}
    assert set(warnings) == {"roll", "pitch", "yaw", "coupled"}  # altitude's 12 rad/s is realizable
    roll = warnings["roll"]
    limit = 2 * math.pi * 200 / discrete.SAMPLES_PER_POLE
    assert roll.factor == pytest.approx(14492.75 / limit, rel=1e-4)
    assert not roll.sampled_stable
    assert "roll: closed-loop pole -14493 rad/s is 115x faster than 200 Hz realizes" in rate_warning(roll, 200)


def test_held_step_divides_the_controller_period_and_a_bad_step_is_refused():
    eig = np.array([0.0, -2.1, -2.1])
    plan = plan_held_step(eig, 200.0, 1.0)
    assert plan.hold * plan.dt == pytest.approx(1 / 200, rel=1e-12) and plan.hold == 5
    assert plan_held_step(eig, 200.0, 1.0, 0.0025).hold == 2
    with pytest.raises(StepSizeError, match=r"simulation.dt = 0.003 s does not divide the controller period "
                                            r"1/rate = 0.005 s \(controller.rate = 200 Hz\); use dt: auto or 0.0025 s"):
        plan_held_step(eig, 200.0, 1.0, 0.003)


def test_zero_order_hold_simulation_follows_the_discrete_linear_loop():
    """Tiny offset: the nonlinear ZOH run at the samples equals (Ad - Bd K)^k dx0 to second order."""
    data = cfg_dict("forward", controller={"rate": 100.0})
    data["simulation"] = {"duration": 0.5, "dt": "auto",
                          "initial_offset": {"pD": 1e-4, "phi": 1e-4, "theta": -1e-4, "psi": 2e-4}}
    setup, des, loop, sim = run(data)
    _, trim, linear, _, _ = solve(data)
    assert sim.plan.hold >= 1 and sim.status == "ok"
    # the input is held: constant within each controller period
    k = np.arange(len(sim.t) - 1)
    same_period = (k % sim.plan.hold) != 0
    assert np.all(sim.u[1:-1][same_period[1:]] == sim.u[:-2][same_period[1:]])
    Ad, Bd = discrete.c2d(linear.A, linear.B, 1 / 100)
    Acl = Ad - Bd @ des.K_block
    dx = setup.initial_offset.copy()
    samples = np.arange(0, len(sim.t), sim.plan.hold)
    worst = 0.0
    for i in samples:
        err = sim.x[i] - sim.x_ref[i] - dx
        worst = max(worst, np.abs(err).max())
        dx = Acl @ dx
    # second-order terms of a 2e-4 offset are ~1e-8; RK4 error at 2 ms on the 2 rad/s plant ~1e-12
    assert worst < 1e-6, f"Max diff is {worst:.4E}"


@pytest.mark.parametrize("n, m", [(2, 1), (3, 1), (4, 2)])
def test_the_weight_map_samples_any_weights_as_van_loan_does(n, m):
    """LqrdWeightMap (a sweep's cases of one plant) gives lqrd_weights_batch's numbers to round-off."""
    from quadctl.design.discrete import LqrdWeightMap, lqrd_weights_batch

    rng = np.random.default_rng(n * 10 + m)
    A, B, Ts, batch = rng.normal(size=(n, n)), rng.normal(size=(n, m)), 0.005, 40
    Q = rng.normal(size=(batch, n, n))
    Q = Q @ Q.transpose(0, 2, 1)
    R = rng.uniform(1.0, 10.0, size=(batch, m, 1)) * np.eye(m)
    N = 0.1 * rng.normal(size=(batch, n, m))
    Ad, Bd, Qd, Rd, Nd = lqrd_weights_batch(np.broadcast_to(A, (batch, n, n)), np.broadcast_to(B, (batch, n, m)),
                                            Q, R, Ts, N)
    weight_map = LqrdWeightMap(A, B, Ts)
    Qd_map, Rd_map, Nd_map = weight_map.weights(Q, R, N)
    for got, ref in ((weight_map.Ad, Ad[0]), (weight_map.Bd, Bd[0]), (Qd_map, Qd), (Rd_map, Rd), (Nd_map, Nd)):
        assert np.abs(got - ref).max() <= 1e-14 * np.abs(ref).max()
    np.testing.assert_array_equal(Qd_map, Qd_map.transpose(0, 2, 1))
    np.testing.assert_array_equal(Rd_map, Rd_map.transpose(0, 2, 1))


@pytest.mark.parametrize("Ts", [1.0, 10.0, 100.0])
def test_lqrd_weights_of_a_long_sample_are_the_integral(Ts):
    """A sample of seconds (a controller at 0.01-1 Hz): the weights are still the integral of the
    sampled cost, positive semidefinite (one Van Loan exponential over 10 s gave an indefinite Qd)."""
    import scipy.integrate

    setup, _, _, dec, _ = solve(cfg_dict("hover"))
    sub = next(s for s in dec.regulated if s.name == "roll")  # v, phi, p: ||A|| = g
    n, m = sub.B.shape
    Q, R = setup.weights["roll"]
    Q = Q[:n, :n]
    F = np.zeros((n + m, n + m))
    F[:n, :n], F[:n, n:] = sub.A, sub.B
    W = scipy.linalg.block_diag(Q, R)

    def integrand(t):
        E = scipy.linalg.expm(F * t)
        return E.T @ W @ E

    ref, _ = scipy.integrate.quad_vec(integrand, 0.0, Ts, epsrel=1e-12, epsabs=0.0)
    Ad, Bd, Qd, Rd, Nd = discrete.lqrd_weights(sub.A, sub.B, Q, R, Ts)
    got = np.block([[Qd, Nd], [Nd.T, Rd]])
    # the weights inherit the exponential's relative error, expm_cond(F Ts) eps to first order: 6e-9 at
    # 1 s, 3.5e-3 at 100 s, where the entries span 19 decades (three BLAS kernels gave 4e-13 to 1e-12 at
    # 1 s and 2.5e-8 to 1.9e-7 at 100 s)
    bound = scipy.linalg.expm_cond(F * Ts) * np.finfo(float).eps
    assert np.abs(got - ref).max() <= bound * np.abs(ref).max()
    assert np.linalg.eigvalsh(got).min() > -1e-12 * np.abs(got).max()
    zoh = scipy.linalg.expm(F * Ts)[:n]
    assert np.abs(np.block([[Ad, Bd]]) - zoh).max() <= 1e-12 * np.abs(zoh).max()


def test_a_sample_of_years_is_a_design_error_naming_the_rate():
    from quadctl.errors import DesignError

    with pytest.raises(DesignError, match=r"sampled every 1e\+09 s \(controller\.rate 1e-09 Hz\) its response "
                                          r"overflows double precision; use a faster controller\.rate"):
        solve(cfg_dict("hover", controller={"rate": 1e-9, "design": "discrete"}))
