"""ETDRK4, the exponential integrator beside RK4 (quadctl.sim.builder.etdrk4, quadctl.sim.etdrk4_plan,
quadctl.sim.etdrk4_matrices), against independent references.

- The φ-functions from one matrix exponential equal their closed forms on a diagonalizable matrix,
  and the step ladder (doublings between direct exponentials) equals direct exponentials.
- On a linear system with an affine-in-time forcing, ETDRK4 with the system's matrix as its linear
  part is exact: the matrix exponential's solution to round-off, at any step, stiff or not.
- Fourth order on a smooth nonlinear system: the error falls ~16x when the step halves (reference:
  SciPy's DOP853 at rtol 1e-13).
- The loop's linear part (ClosedLoop.linear_part, quadctl.design.lqg_loop.simulated) is the Jacobian of
  the builder's own right-hand side at the reference (CasADi), with rotors, a lag model, LQI, LQG.
- On every bundled config with continuous feedback, ETDRK4 at dt: auto agrees with RK4 at a small
  step to 1e-9 (short runs); with noise and wind too (their rows indexed by time on the graded grid).
- The schedule: contiguous segments of doubling steps, each starting on a multiple of its step,
  within the step the rule allows, dividing the exogenous period; deterministic.
- Compiled and interpreted runners agree; configs and sweeps that cannot take it say so.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
from _solve import cfg_dict, solve
from scipy.integrate import solve_ivp

from quadctl import config, pipeline
from quadctl.errors import ConfigError, StepSizeError
from quadctl.setup import setup_of
from quadctl.sim import engine, etdrk4_matrices, etdrk4_plan
from quadctl.sim.builder import build, etdrk4
from quadctl.sim.loop_layout import PHI_LAYOUT
from quadctl.sim.run import simulate

ca = pytest.importorskip("casadi")


def _phi_closed(z: np.ndarray, k: int) -> np.ndarray:
    """φ_k(z) of scalars: the closed form ``(e^z - sum_{j<k} z^j/j!) / z^k`` where it does not cancel
    (|z| >= 1), else the series ``sum_j z^j / (j + k)!`` (40 terms)."""
    z = np.asarray(z, dtype=float)
    partial = sum(z ** j / math.factorial(j) for j in range(k))
    with np.errstate(all="ignore"):
        closed = (np.exp(z) - partial) / z ** k
    series = sum(z ** j / math.factorial(j + k) for j in range(40))
    return np.where(np.abs(z) >= 1, closed, series)


def test_phi_functions_equal_their_closed_forms():
    rng = np.random.default_rng(1)
    lam = np.array([-3e4, -250.0, -3.0, -0.7])
    V = rng.standard_normal((4, 4)) + 3 * np.eye(4)
    L = V @ np.diag(lam) @ np.linalg.inv(V)
    h = 1e-3
    got = etdrk4_matrices.phi_functions(L, h)
    for k in range(4):
        ref = V @ np.diag(np.exp(h * lam) if k == 0 else _phi_closed(h * lam, k)) @ np.linalg.inv(V)
        assert np.abs(got[k] - ref).max() < 1e-12 * max(1.0, np.abs(ref).max()), k


@pytest.mark.parametrize("scale", [1e-3, 1.0, 30.0, 3e4])
def test_the_exponential_is_scipys(scale):
    """quadctl's scaling and squaring against SciPy's expm (Pade 13): stable, non-normal, up to stiff
    (a 1-norm of 5e5: nineteen squarings)."""
    rng = np.random.default_rng(4)
    V = np.eye(12) + np.triu(rng.standard_normal((12, 12)), 1)  # non-normal: V far from orthogonal
    D = np.diag(-scale * np.linspace(0.05, 5.0, 12))
    M = V @ D @ np.linalg.inv(V)
    ref = scipy.linalg.expm(M)
    assert np.abs(etdrk4_matrices.expm(M) - ref).max() < 1e-12 * max(1.0, np.abs(ref).max())
    exact = V @ np.diag(np.exp(np.diag(D))) @ np.linalg.inv(V)
    assert np.abs(etdrk4_matrices.expm(M) - exact).max() < 1e-11 * max(1.0, np.abs(exact).max())


def test_the_ladder_equals_direct_exponentials():
    rng = np.random.default_rng(2)
    L = rng.standard_normal((6, 6)) * 50 - 2000 * np.diag(rng.random(6))
    steps = [1e-6 * 2 ** j for j in range(12)]
    ladder = etdrk4_matrices.phi_ladder(L, steps)
    for h in steps[::3]:
        half, full = etdrk4_matrices.phi_functions(L, h / 2), etdrk4_matrices.phi_functions(L, h)
        ref = etdrk4_matrices.step_matrices(L, h, half, full)
        assert set(ref) == set(PHI_LAYOUT)
        for name, M in ref.items():
            assert np.abs(ladder[h][name] - M).max() < 1e-13 * max(1.0, np.abs(M).max()), (h, name)
    with pytest.raises(ValueError, match="not .* times a power of two"):
        etdrk4_matrices.phi_ladder(L, [1e-6, 3e-6])


def _etdrk4_function(rhs, n: int, L: np.ndarray):
    """CasADi function (X, t, h) -> one builder ETDRK4 step of ``rhs`` with linear part ``L``, its
    matrices computed per ``h`` in Python (the order test calls it with a few steps)."""
    X, t, h = ca.SX.sym("X", n), ca.SX.sym("t"), ca.SX.sym("h")
    mats = {name: ca.SX.sym(name, n, n) for name in PHI_LAYOUT}
    fn = ca.Function("etd", [X, t, h, *mats.values()], [etdrk4(rhs, X, t, h, mats)])

    def step(x, tt, hh):
        ladder = etdrk4_matrices.phi_ladder(L, [hh])[hh]
        return np.asarray(fn(x, tt, hh, *[ladder[name] for name in PHI_LAYOUT])).ravel()

    return step


@pytest.mark.compiler
@pytest.mark.parametrize("method", ["etdrk4", "rk4"])
def test_a_loop_started_at_its_trim_stays_there(method):
    """The hover loop started exactly at its trim, 10 000 steps of 0.1 ms: no step moves it (RK4 adds
    ``h k`` with ``k`` the trim's residual). ETDRK4 written as ``e^(hL) X + A N(X) + ...`` drifted by
    5e-11 here, the round-off of ``e^(hL) - 1 = A L`` times ``X`` at every step; written about the
    step's start (:func:`quadctl.sim.builder.etdrk4`) it adds ``A rhs(X)`` like RK4."""
    setup, _, linear, _, des = solve(cfg_dict("hover"))
    loop = pipeline.loop_of(setup, linear, des)
    run = simulate(loop, loop.x_trim, 1.0, 1e-4, method=method)
    assert np.abs(run.x[-1] - loop.x_trim).max() < 1e-14


def test_exact_on_a_linear_loop_with_affine_forcing():
    """``x' = A x + b + c t``, ``A`` stiff (eigenvalues -2e4 .. -0.5, a complex pair): ETDRK4 with
    ``L = A`` gives the exact solution, ``expm`` of the augmented system ``[x; 1; t]``, to round-off
    whatever the step (here 50 steps of 0.02 s, 400 times RK4's stability limit). Round-off here is
    the φ-functions' forward error, about ``expm_cond(h A) eps`` each (487 eps at this step), a few
    of them combined per step, added over the steps: the bound allows 100 of them a step (the BLAS
    kernels of two x86 machines gave 5e-11 and under 1e-11)."""
    rng = np.random.default_rng(3)
    V = rng.standard_normal((4, 4)) + 4 * np.eye(4)
    D = np.array([[-2e4, 0, 0, 0], [0, -0.5, 3.0, 0], [0, -3.0, -0.5, 0], [0, 0, 0, -40.0]])
    A = V @ D @ np.linalg.inv(V)
    b, c = rng.standard_normal(4), rng.standard_normal(4)
    step = _etdrk4_function(lambda X, t: ca.DM(A) @ X + ca.DM(b) + ca.DM(c) * t, 4, A)
    x0 = rng.standard_normal(4)
    x, h = x0.copy(), 0.02
    for k in range(50):
        x = step(x, k * h, h)
    aug = np.zeros((6, 6))
    aug[:4, :4], aug[:4, 4], aug[:4, 5], aug[5, 4] = A, b, c, 1.0
    exact = (scipy.linalg.expm(aug * 1.0) @ np.concatenate([x0, [1.0, 0.0]]))[:4]
    bound = 50 * 100 * scipy.linalg.expm_cond(A * h) * np.finfo(float).eps  # about 5e-10
    assert np.abs(x - exact).max() < bound * max(1.0, np.abs(exact).max())  # RK4: unstable here


def test_fourth_order_on_a_smooth_nonlinear_system():
    """A damped oscillator with a quadratic and a sine coupling, linear part its Jacobian at 0: the
    final error after 1 s falls by ~2^4 each time the step halves."""
    L = np.array([[-1.0, 4.0, 0.0], [-4.0, -1.0, 1.0], [0.0, 0.0, -3.0]])

    def f_np(t, x):
        return L @ x + np.array([0.5 * x[1] ** 2, np.sin(x[0]) - x[0], -x[0] * x[1]]) + np.array([0, 0, np.cos(t)])

    def f_ca(X, t):
        return ca.DM(L) @ X + ca.vertcat(0.5 * X[1] ** 2, ca.sin(X[0]) - X[0], -X[0] * X[1]) \
            + ca.vertcat(0, 0, ca.cos(t))

    x0 = np.array([0.8, -0.5, 0.3])
    ref = solve_ivp(f_np, (0, 1), x0, method="DOP853", rtol=1e-13, atol=1e-15).y[:, -1]
    # the nonlinear part only: ETDRK4's linear part leaves out a part of the Jacobian, so the
    # remainder N is not small (a real test of the nonlinear stages)
    step = _etdrk4_function(f_ca, 3, L)
    errors = []
    for n in (10, 20, 40):
        x, h = x0.copy(), 1.0 / n
        for k in range(n):
            x = step(x, k * h, h)
        errors.append(np.abs(x - ref).max())
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    assert all(12 < r < 20 for r in ratios), (errors, ratios)


def _builder_jacobian(loop, e):
    """d X'/dX of the builder's continuous loop at the reference (d/dh at h = 0 of its RK4 step's
    Jacobian: each RK4 stage is the right-hand side there)."""
    spec = loop.spec(noise=False, wind=True)
    fns = build(spec)
    X, h = ca.SX.sym("X", spec.nx), ca.SX.sym("h")
    J = ca.jacobian(fns.step(X, 0.0, h, loop.constants(None), ca.DM(e))[0], X)
    dJ = ca.reshape(ca.jacobian(ca.vec(J), h), J.shape[0], J.shape[1])
    return np.asarray(ca.Function("J", [X, h], [dJ])(loop.initial_loop_state(loop.x_trim), 0.0))


def _variant(name: str) -> dict:
    if name == "hover+rotors+lag model+LQI":
        data = cfg_dict("hover", motors={"time_constant": 0.02})
        data["controller"]["rotor_lag"] = "include"
        data["lqr"]["altitude"].update(Q=[50, 1, 1], integral=["pD"])
        return data
    if name == "hover+LQG":
        data = cfg_dict("hover")
        data["simulation"]["noise"] = {"seed": 3, "force": [0.005] * 3, "torque": [2e-5] * 3,
                                       "sensor": dict.fromkeys(("pN", "pE", "pD", "phi", "theta", "psi", "p", "q",
                                                                "r"), 0.01)}
        data["estimator"] = {"measure": ["imu", "mocap"]}
        return data
    if name.startswith("hover+noise") or name == "hover+wind":
        data = cfg_dict("hover")
        if "noise" in name:
            data["simulation"]["noise"] = {"seed": 5, "force": [0.01] * 3, "torque": [5e-5] * 3,
                                           "sensor": {"phi": 0.01, "p": 0.05}}
        if "wind" in name:
            data["simulation"]["wind"] = {"steady": [1.0, -0.5, 0.0], "turbulence": {"intensity": "light", "seed": 2}}
        return data
    if name.startswith("mambo+"):
        data = cfg_dict("mambo-200hz")
        if "delay" in name:
            data["controller"]["delay"] = 0.01  # two samples
        if "rotors" in name:
            data["motors"]["time_constant"] = 0.02
            data["controller"]["rotor_lag"] = "include"
        if "LQG" in name:
            data["estimator"] = {"measure": ["imu", "mocap"]}
            data["simulation"]["noise"]["sensor"].update(pN=0.01, pE=0.01)
        return data
    return cfg_dict(name)


LINEAR_PARTS = ["forward", "hover+rotors+lag model+LQI", "hover+LQG"]


@pytest.mark.parametrize("name", LINEAR_PARTS)
def test_the_linear_part_is_the_builders_jacobian(name):
    setup, _, linear, _, des = solve(_variant(name))
    loop = pipeline.loop_of(setup, linear, des)
    from dataclasses import replace

    loop = replace(loop, params=setup.vehicle.vector())  # the design model (the linear part's plant)
    J = _builder_jacobian(loop, setup.trim_wind)
    L = loop.linear_part()
    assert L.shape == J.shape
    assert np.abs(L - J).max() < 1e-9 * max(1.0, np.abs(J).max())


CONTINUOUS = [n for n in config.bundled_names() if config.load(n).controller.rate is None]
HELD = [n for n in config.bundled_names() if config.load(n).controller.rate is not None]


def _default_run(names, chosen=("forward", "square", "mambo-200hz", "crazyflie-wind")):
    """``names`` as parameters, the bundled configs not ``chosen`` marked slow (more configs, one path)."""
    return [n if n in chosen or n not in config.bundled_names() else pytest.param(n, marks=pytest.mark.slow)
            for n in names]


NOISE_AGREE = 1e-8
"""ETDRK4 against RK4 with noise: each noise sample (every 5 ms here) steps the sensor noise and
re-excites the fast modes, which the schedule grades for at t = 0 only: measured 2.0e-9 on 0.2 s of
hover with noise and wind at tolerance 1e-12 (without noise: below 1e-9)."""


@pytest.mark.compiler
@pytest.mark.parametrize("name", _default_run([*CONTINUOUS, "hover+wind", "hover+noise+wind"]))
def test_etdrk4_agrees_with_rk4_at_a_small_step(name):
    """0.2 s from the configured offset: ETDRK4 at dt: auto (tolerance 1e-12) against RK4 at 2.5e-5 s
    (a step that divides the exogenous period, so both see the exogenous rows change at the same times)."""
    setup, _, linear, _, des = solve(_variant(name))
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(loop.x_trim)
    kw = dict(noise=setup.noise, wind=setup.wind, reference=setup.flown_reference)
    rk4 = simulate(loop, x0, 0.2, 2.5e-5, **kw)
    etd = simulate(loop, x0, 0.2, "auto", method="etdrk4", tolerance=1e-12, **kw)
    assert etd.status == rk4.status == "ok"
    assert etd.t[-1] == pytest.approx(0.2, abs=1e-15)
    assert np.abs(etd.x[-1] - rk4.x[-1]).max() < (NOISE_AGREE if setup.noise is not None else 1e-9)
    if setup.wind is not None:  # the wind felt, by time, on the graded grid
        assert np.all(np.diff(etd.t) > 0)
        assert np.abs(np.interp(0.1, etd.t, etd.wind[:, 0]) - np.interp(0.1, rk4.t, rk4.wind[:, 0])) < 0.05


@pytest.mark.compiler
def test_a_free_run_meets_its_tolerance_with_room():
    """A free run (no noise, wind or reference) is graded with FREE_SAFETY: on forward over 1 s at
    tolerance 1e-9, within a tenth of it of RK4 at 1e-5 s (2.3e-11 at FREE_SAFETY 2; 1.4e-10 at 4,
    2.0e-9 at 8), in fewer steps than SAFETY's grading."""
    setup, _, linear, _, des = solve(cfg_dict("forward"))
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(loop.x_trim)
    rk4 = simulate(loop, x0, 1.0, 1e-5)
    etd = simulate(loop, x0, 1.0, "auto", method="etdrk4", tolerance=1e-9)
    assert np.abs(etd.x[-1] - rk4.x[-1]).max() < 1e-10
    eig = np.linalg.eigvals(loop.linear_part())
    excited = etdrk4_plan.plan_schedule(eig, ["loop"] * len(eig), 1.0, tolerance=1e-9, period=0.01)
    assert etd.steps < excited.n_steps


@pytest.mark.compiler
def test_a_mission_agrees_with_rk4_at_a_small_step():
    """The bundled ``square`` mission, its whole 15 s (the reference's rows and its pieces' ends, where
    its higher derivatives jump): ETDRK4 at dt: auto, tolerance 1e-10, against RK4 at 2.5e-5 s (a step
    that divides the rows' period), in a quarter of RK4's steps at its own stable step. (Cox and Matthews'
    four-stage ETDRK4 on this loop: 3e-5; its order falls at steps past the fast modes.)"""
    setup, _, linear, _, des = solve(cfg_dict("square"))
    loop = pipeline.loop_of(setup, linear, des)
    x0, ref = setup.initial_state(loop.x_trim), setup.flown_reference
    T = setup.duration
    rk4 = simulate(loop, x0, T, 2.5e-5, reference=ref)
    etd = simulate(loop, x0, T, "auto", method="etdrk4", tolerance=1e-10, reference=ref)
    assert etd.status == rk4.status == "ok"
    assert np.abs(etd.x[-1] - rk4.x[-1]).max() < 1e-9
    assert np.abs(etd.x_ref[-1] - rk4.x_ref[-1]).max() < 1e-12  # the same reference, flown
    assert etd.steps * 4 < simulate(loop, x0, T, "auto", reference=ref).steps


MISSION_SPAN = 15.0
"""s of the ``square`` mission :func:`test_a_missions_largest_error_is_within_its_tolerance` flies: the
whole of it (four legs, a climb and turns to 90 and 180 deg of heading)."""


@pytest.fixture(scope="module")
def mission_truth():
    """(loop, x0, reference, RK4 run) of the ``square`` mission's first MISSION_SPAN s, RK4 at 1/2000 of the
    rows' period recorded once a row, its own largest error bounded by its difference from RK4 at
    1/1000 (RK4's error falls 16-fold a halving: the finer's is a fifteenth of the difference). Both
    steps divide 1/8000 s, of which the square's leg times are multiples: every knot of its reference
    (where the feedforward's torques step) is a step's end, so no step integrates across one."""
    setup, _, linear, _, des = solve(cfg_dict("square"))
    loop = pipeline.loop_of(setup, linear, des)
    x0, ref = setup.initial_state(loop.x_trim), setup.flown_reference
    knots = ref.path.knots * 8000
    assert np.abs(knots - np.round(knots)).max() < 1e-6
    rows = round(MISSION_SPAN / 0.005)
    fine, coarse = (simulate(loop, x0, MISSION_SPAN, 0.005 / k, reference=ref, max_samples=rows + 1)
                    for k in (2000, 1000))
    assert np.array_equal(fine.t, coarse.t) and len(fine.t) == rows + 1
    assert np.abs(fine.x - coarse.x).max() < 6e-11  # the reference's own error: about 4e-12 at most
    return loop, x0, ref, fine


@pytest.mark.compiler
@pytest.mark.parametrize("tolerance", [1e-8, 1e-10])
def test_a_missions_largest_error_is_within_its_tolerance(mission_truth, tolerance):
    """ETDRK4 at dt: auto, its largest error over the whole run (every row's start, not only the end)
    within ``simulation.tolerance`` of the reference integrator on the same closed loop. Graded on
    ``tolerance^(1/4)`` as for the initial transient, it was 1.4e-8 at 1e-8 here: the method's order
    falls to about 3 on a mission (:func:`quadctl.sim.etdrk4_plan.forced_step`). Written as
    ``e^(hL) X + ...`` rather than about the step's start (:func:`quadctl.sim.builder.etdrk4`), it was
    1.8e-10 at 1e-10, whatever the step: the drift of that form's round-off."""
    loop, x0, ref, truth = mission_truth
    etd = simulate(loop, x0, MISSION_SPAN, "auto", method="etdrk4", tolerance=tolerance, reference=ref,
                   max_samples=10**6)
    at = np.searchsorted(etd.t, truth.t - 1e-12)
    np.testing.assert_allclose(etd.t[at], truth.t, rtol=0, atol=1e-12)
    err = np.abs(etd.x[at] - truth.x).max(axis=1)
    assert etd.status == "ok" and err.max() < tolerance, f"Max diff is {err.max():.4E} at t = {truth.t[err.argmax()]}"
    assert err[len(err) // 2:].max() > tolerance / 1e3  # the error is measured where the mission moves


@pytest.mark.compiler
def test_setpoint_steps_are_graded_like_the_start(monkeypatch):
    """Each setpoint steps the reference and kicks the fast loops as the initial offset does, so dt: auto
    grades again from each (Reference.knots): the report's forward loop, velocity steps at 0.5 and 1 s,
    within the tolerance 1e-8 of RK4 at 1/256 of the rows' period. Graded from t = 0 only, the steps
    after a setpoint are too long for the kicked rate loops: over 1e-6."""
    from quadctl.physics.trajectory import Reference

    data = cfg_dict("forward")
    data["simulation"]["reference"] = {"setpoints": [{"t": 0.5, "velocity": [2.0, 0.0, 0.0]},
                                                     {"t": 1.0, "velocity": [3.0, 1.0, 0.0]}]}
    setup, _, linear, _, des = solve(data)
    loop = pipeline.loop_of(setup, linear, des)
    x0, ref = setup.initial_state(loop.x_trim), setup.flown_reference
    assert ref.path.jumps == (0.5, 1.0)
    truth = simulate(loop, x0, 1.5, 0.005 / 256, reference=ref)
    etd = simulate(loop, x0, 1.5, "auto", method="etdrk4", tolerance=1e-8, reference=ref)
    assert etd.status == truth.status == "ok"
    assert np.abs(etd.x[-1] - truth.x[-1]).max() < 1e-8
    finest = etd.plan.schedule[0].dt
    for kick in (0.5, 1.0):  # reached on the kicks' own finest step (graded from just before it)
        assert next(s.dt for s in etd.plan.schedule if s.start < kick <= s.end) == finest / 2 ** etdrk4_plan.KICK_LEVELS
    monkeypatch.setattr(Reference, "knots", ())
    once = simulate(loop, x0, 1.5, "auto", method="etdrk4", tolerance=1e-8, reference=ref)
    assert once.steps < etd.steps and np.abs(once.x[-1] - truth.x[-1]).max() > 1e-6


def test_a_reference_jumps_where_its_position_velocity_or_yaw_steps():
    """Setpoints and step legs jump; a shaped leg's ends (where only jerk and snap change) do not."""
    from quadctl.physics.trajectory import mission_reference, setpoint_reference

    steps = setpoint_reference([{"t": 0.0, "velocity": [1.0, 0, 0]}, {"t": 1.0, "yaw": 0.5},
                                {"t": 2.0, "velocity": [1.0, 0, 0]}, {"t": 3.0, "position": [5.0, 0, 0]}],
                               (0, 0, -1), (0, 0, 0), 0.0)
    assert steps.jumps == (1.0, 3.0)  # at 2 s the velocity given is the one flown: no step
    waypoints = [{"position": [2.0, 0, -1]}, {"position": [2.0, 2.0, -1], "hold": 1.0}, {"position": [0, 0, -1]}]
    assert mission_reference(waypoints, (0, 0, -1), 0.0, 1.0, 0.1, "minimum-snap").jumps == ()
    legs = mission_reference(waypoints, (0, 0, -1), 0.0, 1.0, 0.1, "step")
    assert legs.jumps == tuple(p.t0 for p in legs.pieces[1:])


@pytest.mark.compiler
@pytest.mark.parametrize("name", _default_run([*HELD, "mambo+delay", "mambo+rotors+lag model", "mambo+LQG"]))
def test_a_sampled_controller_agrees_with_rk4_at_a_small_step(name):
    """1 s of each bundled sampled controller (and the held loop's delay, rotor lag with the lag model,
    Kalman filter), noise and wind as configured: ETDRK4 at dt: auto, tolerance 1e-10, against RK4 at
    a fortieth of the controller period. The law runs at the same samples: the inputs agree too, and
    every segment starts on a sample."""
    setup, _, linear, _, des = solve(_variant(name))
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(loop.x_trim)
    Ts = 1.0 / loop.rate
    kw = dict(noise=setup.noise, wind=setup.wind, reference=setup.flown_reference)
    rk4 = simulate(loop, x0, 1.0, Ts / 40, max_samples=10**6, **kw)
    etd = simulate(loop, x0, 1.0, "auto", method="etdrk4", tolerance=1e-10, max_samples=10**6, **kw)
    assert etd.status == rk4.status == "ok"
    assert np.abs(etd.x[-1] - rk4.x[-1]).max() < 1e-9
    k = np.round(etd.t / (Ts / 40)).astype(int)
    assert np.abs(etd.u - rk4.u[k]).max() < 1e-9
    for seg in etd.plan.schedule:
        assert seg.start / Ts == pytest.approx(round(seg.start / Ts), abs=1e-9)
        assert Ts / seg.dt == round(Ts / seg.dt)


def test_a_sampled_controllers_given_step_divides_its_period():
    setup, _, linear, _, des = solve(cfg_dict("mambo-200hz"))
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(loop.x_trim)
    sim = simulate(loop, x0, 0.05, 0.0025, method="etdrk4")
    assert sim.plan.hold == 2 and sim.steps == 20
    with pytest.raises(StepSizeError, match=r"^simulation\.dt = 0\.003 s does not divide the controller period "
                                            r"1/rate = 0\.005 s \(controller\.rate = 200 Hz\); use dt: auto or "
                                            r"0\.0025 s$"):  # RK4's words (plan.steps_per_sample), one rule
        simulate(loop, x0, 0.05, 0.003, method="etdrk4")


def test_a_reference_caps_the_step_and_keeps_its_rows():
    """With a reference, the schedule's steps divide the rows' period (a step never straddles a row's
    boundary, where the reference's curvature jumps), and the largest is the forced step the tolerance
    allows; without one, the largest is MAX_STEP."""
    setup, _, linear, _, des = solve(cfg_dict("square"))
    eig = np.linalg.eigvals(pipeline.loop_of(setup, linear, des).linear_part())
    slowest = np.abs(eig)[np.abs(eig) > 0].min()
    for tol in (1e-8, 1e-10):
        plan = etdrk4_plan.plan_schedule(eig, ["loop"] * len(eig), 15.0, tolerance=tol, period=0.005, forced=True)
        top = plan.schedule[-1].dt
        assert 0.005 / top == round(0.005 / top)
        assert top <= etdrk4_plan.FORCED_SAFETY * tol ** (1 / 3) / slowest < 2 * top
    free = etdrk4_plan.plan_schedule(eig, ["loop"] * len(eig), 15.0, tolerance=1e-10, period=0.005)
    assert free.schedule[-1].dt == 0.005 and free.n_steps < plan.n_steps


def test_the_schedule_grades_and_aligns():
    setup, _, linear, _, des = solve(cfg_dict("forward"))
    loop = pipeline.loop_of(setup, linear, des)
    eig = np.linalg.eigvals(loop.linear_part())
    for period in (None, 0.005):
        plan = etdrk4_plan.plan_schedule(eig, ["loop"] * len(eig), 10.0, tolerance=1e-8, period=period)
        assert plan == etdrk4_plan.plan_schedule(eig, ["loop"] * len(eig), 10.0, tolerance=1e-8, period=period)
        segs = plan.schedule
        assert segs[0].start == 0.0 and segs[-1].end == pytest.approx(10.0, rel=1e-12)
        assert sum(s.n for s in segs) == plan.n_steps
        for a, b in zip(segs, segs[1:]):  # contiguous, coarser by powers of two
            assert a.end == b.start and b.dt / a.dt == 2 ** round(np.log2(b.dt / a.dt)) >= 2
        safety = etdrk4_plan.FREE_SAFETY if period is None else etdrk4_plan.SAFETY  # no exogenous inputs: a free run
        assert segs[0].dt > etdrk4_plan.auto_step(0.0, eig, 1e-8, safety) / 2  # the largest the rule allows
        for s in segs:
            assert s.dt <= etdrk4_plan.auto_step(s.start, eig, 1e-8, safety) * (1 + 1e-12)  # within the rule
        if period is not None:
            top = max(s.dt for s in segs)
            assert period / top == pytest.approx(round(period / top), abs=1e-9)
        assert segs[0].dt < 1e-6 * safety and segs[-1].dt == min(etdrk4_plan.MAX_STEP, period or 1.0)  # graded
    plan = etdrk4_plan.plan_schedule(eig, ["loop"] * len(eig), 10.0, tolerance=1e-8)
    tighter = etdrk4_plan.plan_schedule(eig, ["loop"] * len(eig), 10.0, tolerance=1e-10)
    assert tighter.n_steps > plan.n_steps and tighter.schedule[0].dt < plan.schedule[0].dt


def test_short_segments_merge_into_the_finer_step(monkeypatch):
    """A coarser segment that would save at most MERGE_STEPS steps is run at the finer step: fewer
    segments, at most MERGE_STEPS more steps for each segment fewer, the same span and alignment
    (at 64, where the rule merges several of the forward loop's; the default merges only those that
    save no step whole)."""
    setup, _, linear, _, des = solve(cfg_dict("forward"))
    eig = np.linalg.eigvals(pipeline.loop_of(setup, linear, des).linear_part())
    for period in (None, 0.005):
        monkeypatch.setattr(etdrk4_plan, "MERGE_STEPS", 64)
        merged = etdrk4_plan.plan_schedule(eig, ["loop"] * len(eig), 10.0, tolerance=1e-8, period=period)
        monkeypatch.setattr(etdrk4_plan, "MERGE_STEPS", 0)
        every = etdrk4_plan.plan_schedule(eig, ["loop"] * len(eig), 10.0, tolerance=1e-8, period=period)
        monkeypatch.setattr(etdrk4_plan, "MERGE_STEPS", 64)
        fewer = len(every.schedule) - len(merged.schedule)
        assert fewer >= 3
        assert every.n_steps < merged.n_steps <= every.n_steps + etdrk4_plan.MERGE_STEPS * fewer
        assert merged.schedule[0] == every.schedule[0] and merged.schedule[-1].end == every.schedule[-1].end
        for seg in merged.schedule:
            assert seg.k0 == round(seg.k0) and seg in every.schedule or seg.dt < every.schedule[-1].dt


def test_records_are_equally_spaced():
    """Metrics and plots take the records as equally spaced (time averages are plain means): the
    graded schedule records at multiples of its largest step only, and the end."""
    setup, _, linear, _, des = solve(cfg_dict("forward"))
    loop = pipeline.loop_of(setup, linear, des)
    sim = simulate(loop, setup.initial_state(loop.x_trim), 2.0, "auto", method="etdrk4", max_samples=101)
    gaps = np.diff(sim.t)
    assert len(sim.t) <= 101 and len(sim.plan.schedule) > 5
    assert np.allclose(gaps, gaps[0], rtol=1e-9, atol=0) and gaps[0] >= sim.plan.dt
    assert sim.t[-1] == pytest.approx(2.0, rel=1e-12)


def test_a_given_step_is_uniform():
    setup, _, linear, _, des = solve(cfg_dict("forward"))
    loop = pipeline.loop_of(setup, linear, des)
    sim = simulate(loop, setup.initial_state(loop.x_trim), 0.1, 1e-3, method="etdrk4")
    assert sim.plan.schedule == (etdrk4_plan.Segment(1e-3, 100, 0),) and sim.steps == 100
    assert np.allclose(np.diff(sim.t), 1e-3)


@pytest.mark.compiler
@pytest.mark.parametrize("name", ["hover+noise+wind", "square", "mambo+rotors+lag model"])
def test_compiled_and_interpreted_etdrk4_agree(monkeypatch, name):
    setup, _, linear, _, des = solve(_variant(name))
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(loop.x_trim)
    kw = dict(noise=setup.noise, wind=setup.wind, method="etdrk4", reference=setup.flown_reference)
    compiled = simulate(loop, x0, 0.05, "auto", **kw)
    monkeypatch.setenv("QUADCTL_NO_COMPILE", "1")
    engine.runner.cache_clear()
    try:
        with pytest.warns(engine.CompilerNotice):
            interpreted = simulate(loop, x0, 0.05, "auto", **kw)
    finally:
        engine.runner.cache_clear()
    assert compiled.backend == "compiled" and interpreted.backend == "casadi"
    assert compiled.steps == interpreted.steps and np.array_equal(compiled.t, interpreted.t)
    assert np.abs(compiled.x - interpreted.x).max() < 1e-12 and np.abs(compiled.x[-1] - x0).max() > 1e-6
    assert np.abs(compiled.u - interpreted.u).max() < 1e-12


def test_the_phi_pattern_keeps_a_decoupled_loops_blocks():
    """The forward design is decoupled: its loop's exponential has exact zeros, baked into the code."""
    setup, _, linear, _, des = solve(cfg_dict("forward"))
    loop = pipeline.loop_of(setup, linear, des)
    L = loop.linear_part()
    pattern = etdrk4_matrices.phi_pattern(etdrk4_matrices.phi_ladder(L, [1e-3]))
    assert 0 < sum(pattern) < len(pattern)
    spec = loop.spec(method="etdrk4", phi_pattern=pattern)
    assert spec.n_phi == len(PHI_LAYOUT) * spec.nx ** 2 and "method=etdrk4" in spec.key()


def test_a_tolerance_without_etdrk4_is_refused():
    data = cfg_dict("hover")
    data["simulation"]["tolerance"] = 1e-9
    with pytest.raises(ConfigError, match=r"simulation\.tolerance.*method: etdrk4"):
        config.from_dict(data, "<test>")
    data["simulation"].update(method="etdrk4", dt=0.001)
    with pytest.raises(ConfigError, match=r"simulation\.tolerance = 1e-09: sets the step schedule of dt: auto"):
        config.from_dict(data, "<test>")


def test_a_sweep_runs_one_method():
    from quadctl.errors import SweepError
    from quadctl.sweep.sweep_file import from_dict

    cfg = config.load("hover")
    with pytest.raises(SweepError, match=r"parameters\.simulation\.method: a sweep runs one integrator"):
        from_dict({"parameters": {"simulation.method": ["rk4", "etdrk4"]}}, cfg)


SWEEPS = {
    "forward": ({"lqr.roll.Q[1]": [10, 200], "lqr.altitude.R[0]": [0.3, 3.0], "vehicle.mass": [0.06, 0.075]},
                {"simulation.duration": 0.5}),
    "mambo-200hz": ({"lqr.roll.R[0]": [20000, 80000], "lqr.altitude.Q[2]": [0.5, 2.0],
                     "simulation.noise.seed": [1, 2]}, {"simulation.duration": 0.5}),
    "square": ({"lqr.roll.Q[2]": [20, 50, 80], "lqr.pitch.R[0]": [0.5, 2.0]}, {"simulation.duration": 3.0}),
}


@pytest.mark.compiler
@pytest.mark.parametrize("name", list(SWEEPS))
def test_a_sweep_in_the_lanes_matches_the_one_case_runs(name):
    """``quadctl sweep`` with etdrk4: the lanes' rows (each case on its own schedule, the φ-functions of
    the stack of linear parts) are the one-by-one path's (``simulate`` per case), steps and all."""
    from _solve import max_rel_diff

    from quadctl import sweep

    cfg = config.load(name)
    parameters, fixed = SWEEPS[name]
    spec = sweep.from_dict({"parameters": parameters, "set": {**fixed, "simulation.method": "etdrk4"}}, cfg, "t.yaml")
    fast = sweep.run(cfg, spec, jobs=1)
    slow = sweep.run(cfg, spec, jobs=1, fast=False)
    assert fast.stats["backend"] == ["compiled-simd"] and slow.stats["backend"] == ["compiled"]
    assert {r["status"] for r in fast.rows} == {"ok"}
    assert len({r["steps"] for r in fast.rows}) > 1  # the cases ran their own schedules
    tracking = tuple(k for k in fast.rows[0] if k.startswith("tracking."))  # m, near zero: absolute
    worst, where = max_rel_diff(fast.rows, slow.rows, skip=("path", *tracking))
    assert worst < 1e-9, f"Max diff is {worst:.4E} at {where}"
    for a, b in zip(fast.rows, slow.rows):
        for key in tracking:
            assert a[key] == pytest.approx(b[key], abs=1e-12), key


def test_a_run_without_a_tolerance_aims_at_the_configs_default():
    """One default, the schema's: the setup resolves an absent ``simulation.tolerance`` to it, and a
    run planned without a config aims at it too."""
    from quadctl.config.simulation_schema import ETDRK4_TOLERANCE

    assert setup_of(config.load("forward")).tolerance == ETDRK4_TOLERANCE
    eig, owners = np.array([-1.0, -50.0, -400.0]), ["loop"] * 3
    plan = etdrk4_plan.plan_schedule(eig, owners, 1.0)
    assert plan == etdrk4_plan.plan_schedule(eig, owners, 1.0, tolerance=ETDRK4_TOLERANCE)
    assert plan != etdrk4_plan.plan_schedule(eig, owners, 1.0, tolerance=ETDRK4_TOLERANCE * 100)


def test_the_method_enters_the_digest_only_when_used():
    """A config without the new keys keeps its digest (tests/house/test_reference_runs.py holds the old
    ones); choosing etdrk4 or a tolerance changes it (a run folder of RK4 is not reused)."""
    base = config.from_dict(cfg_dict("hover"), "<test>")
    data = cfg_dict("hover")
    data["simulation"]["method"] = "rk4"
    assert config.from_dict(data, "<test>").digest() == base.digest()
    data["simulation"]["method"] = "etdrk4"
    etd = config.from_dict(data, "<test>").digest()
    data["simulation"]["tolerance"] = 1e-9
    assert len({base.digest(), etd, config.from_dict(data, "<test>").digest()}) == 3


@pytest.mark.compiler
def test_lanes_equal_the_one_case_loop():
    """Eleven designs (gains scaled, so each has its own linear part and schedule; two groups of
    eight lanes, the last padded) in the SIMD lanes, each against its own one-case run."""
    from dataclasses import replace

    from quadctl.sim.stack import simulate_stack

    setup, _, linear, _, des = solve(cfg_dict("forward"))
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(loop.x_trim)
    loops = [replace(loop, K=loop.K * (1.0 + 0.1 * k)) for k in range(11)]
    _, _, lanes = simulate_stack(loops, [x0] * len(loops), 0.3, method="etdrk4", tolerance=1e-8)
    worst, schedules = 0.0, set()
    for one_loop, (done, t, xs, us) in zip(loops, lanes):
        one = simulate(one_loop, x0, 0.3, "auto", method="etdrk4", tolerance=1e-8)
        assert done == one.steps and np.array_equal(t, one.t)
        worst = max(worst, np.abs(xs[:, :12] - one.x).max(), np.abs(us - one.u).max())
        schedules.add(one.plan.schedule)
    assert len(schedules) > 1  # the lanes really ran different schedules
    assert worst < 1e-12, f"Max diff is {worst:.4E}"
    with pytest.raises(ValueError, match="one structure"):
        K = loop.K.copy()
        K[0, 0] = 1.0 if K[0, 0] == 0 else 0.0
        simulate_stack([loop, replace(loop, K=K)], [x0, x0], 0.1, method="etdrk4")


@pytest.mark.compiler
def test_lanes_fly_a_reference_as_the_one_case_loop():
    """Nine designs of the ``square`` mission (gains scaled) flying its reference in the lanes, each
    against its own one-case run: the same steps, the same reference rows, to 1e-12."""
    from dataclasses import replace

    from quadctl.sim.stack import simulate_stack

    setup, _, linear, _, des = solve(cfg_dict("square"))
    loop = pipeline.loop_of(setup, linear, des)
    x0, ref = setup.initial_state(loop.x_trim), setup.flown_reference
    loops = [replace(loop, K=loop.K * (1.0 + 0.05 * k)) for k in range(9)]
    _, _, lanes = simulate_stack(loops, [x0] * len(loops), 0.5, method="etdrk4", tolerance=1e-8, reference=ref)
    worst = 0.0
    for one_loop, (done, t, xs, us) in zip(loops, lanes):
        one = simulate(one_loop, x0, 0.5, "auto", method="etdrk4", tolerance=1e-8, reference=ref)
        assert done == one.steps and np.array_equal(t, one.t)
        worst = max(worst, np.abs(xs[:, :12] - one.x).max(), np.abs(us - one.u).max())
    assert np.abs(lanes[0][2][-1, :2] - x0[:2]).max() > 0.01  # they flew
    assert worst < 1e-12, f"Max diff is {worst:.4E}"


@pytest.mark.compiler
def test_lanes_run_a_sampled_controller_as_the_one_case_loop():
    """Nine designs of mambo-200hz (gains scaled; noise, LQI, rotor limits) in the lanes, each against
    its own one-case run: the same steps and samples, to 1e-12."""
    from dataclasses import replace

    from quadctl.sim.stack import simulate_stack

    setup, _, linear, _, des = solve(cfg_dict("mambo-200hz"))
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(loop.x_trim)
    loops = [replace(loop, K=loop.K * (1.0 + 0.05 * k), eigenvalues=loop.eigenvalues * (1.0 + 0.2 * k))
             for k in range(9)]  # scaled modes: each its own schedule
    _, _, lanes = simulate_stack(loops, [x0] * len(loops), 0.5, method="etdrk4", tolerance=1e-8,
                                 noise=setup.noise)
    worst, schedules = 0.0, set()
    for one_loop, (done, t, xs, us) in zip(loops, lanes):
        one = simulate(one_loop, x0, 0.5, "auto", method="etdrk4", tolerance=1e-8, noise=setup.noise)
        assert done == one.steps and np.array_equal(t, one.t)
        worst = max(worst, np.abs(xs[:, :12] - one.x).max(), np.abs(us - one.u).max())
        schedules.add(one.plan.schedule)
    assert len(schedules) > 1
    assert worst < 1e-12, f"Max diff is {worst:.4E}"


def test_the_presenter_names_the_method_and_its_schedule():
    from quadctl.present import flight

    setup, _, linear, _, des = solve(cfg_dict("forward"))
    loop = pipeline.loop_of(setup, linear, des)
    sim = simulate(loop, setup.initial_state(loop.x_trim), 1.0, "auto", method="etdrk4")
    text = flight.step_text(sim)
    assert flight.integrator_name(sim) == "ETDRK4"
    assert f"in {len(sim.plan.schedule)} segments (auto; RK4 would be stable up to 0.0001922 s" in text


@pytest.mark.compiler
@pytest.mark.parametrize("lanes", [1, 8])
def test_a_graded_stack_runs_compiled_as_interpreted(lanes):
    """A stack of ETDRK4 cases (each its own graded schedule: several segments, the last group of lanes
    padded) in the compiled runner (qc_run_segments: every segment of every lane in one C call) and in
    CasADi's VM (a call a segment): the same steps and times, the records to round-off; with a lane that
    leaves its bounds in its third segment (it stops there, the others run on)."""
    from dataclasses import replace

    from quadctl.sim.interpreted import InterpretedRunner
    from quadctl.sim.stack import stack_of

    setup, _, linear, _, des = solve(cfg_dict("forward"))
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(loop.x_trim)
    loops = [replace(loop, K=loop.K * (1.0 + 0.1 * k)) for k in range(lanes + 3 if lanes > 1 else 1)]
    stack = stack_of(loops, [x0] * len(loops), 0.3, method="etdrk4", tolerance=1e-8, max_samples=400)
    cases = stack.cases
    if lanes > 1:  # case 1's north bound where it flies (at the trim's speed) in the middle of its third segment
        middle = cases.dt[2, 1] * (cases.k0[2, 1] + cases.n[2, 1] / 2)
        hi = cases.hi.copy()
        hi[1, 0] = x0[0] + loop.x_rate[0] * middle
        cases = replace(cases, hi=hi)
    assert cases.segments > 1
    walked = engine.runner(stack.spec, lanes).run(cases)
    called = InterpretedRunner(stack.spec).run(cases)
    assert len({tuple(cases.n[:, i]) for i in range(len(loops))}) > 1 or lanes == 1
    worst = 0.0
    for (done, t, xs, us), (done_c, t_c, xs_c, us_c) in zip(walked, called):
        assert done == done_c and np.array_equal(t, t_c)
        worst = max(worst, np.abs(xs - xs_c).max(), np.abs(us - us_c).max())
    assert worst < 1e-12, f"Max diff is {worst:.4E}"
    if lanes > 1:
        assert cases.n[:2, 1].sum() < walked[1][0] < cases.n[:3, 1].sum()  # stopped in its third
        assert walked[0][0] == cases.n[:, 0].sum()


def test_a_loop_keeps_its_exponential_stack():
    """A second run of a loop with the same settings takes the setup it kept (no plan or φ-functions
    computed again) and gives the same numbers; other settings get their own; a pickled loop carries none."""
    import pickle

    from quadctl.sim.etdrk4_stack import kept_exponential_stack

    setup, _, linear, _, des = solve(cfg_dict("forward"))
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(loop.x_trim)
    first = simulate(loop, x0, 0.2, "auto", method="etdrk4", tolerance=1e-8)
    kept = kept_exponential_stack(loop, 0.2, tolerance=1e-8)
    assert kept_exponential_stack(loop, 0.2, tolerance=1e-8) is kept
    assert kept_exponential_stack(loop, 0.2, tolerance=1e-9) is not kept
    again = simulate(loop, x0, 0.2, "auto", method="etdrk4", tolerance=1e-8)
    assert np.array_equal(first.x, again.x) and np.array_equal(first.t, again.t) and first.plan == again.plan
    fresh = pickle.loads(pickle.dumps(loop))
    assert loop.kept and not fresh.kept
    assert kept_exponential_stack(fresh, 0.2, tolerance=1e-8).plans == kept.plans


@pytest.mark.parametrize("name", ["hover+noise+wind", "square"])
def test_a_long_run_in_chunks_is_the_one_call_run(monkeypatch, name):
    """A run past the runner's chunk (segment after segment, each in chunks, the exogenous rows drawn as
    it goes) gives the one-call run's records (the whole run's rows at once) to round-off."""
    from quadctl.sim import stack_run as stack_module

    setup, _, linear, _, des = solve(_variant(name))
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(loop.x_trim)
    kw = dict(noise=setup.noise, wind=setup.wind, method="etdrk4", reference=setup.flown_reference)
    once = simulate(loop, x0, 0.3, "auto", **kw)
    monkeypatch.setattr(stack_module, "CHUNK_STEPS", {"compiled": 40, "casadi": 40})
    chunked = simulate(loop, x0, 0.3, "auto", **kw)
    assert once.steps == chunked.steps > 40 and np.array_equal(once.t, chunked.t)
    assert len(once.plan.schedule) > 1
    worst = max(np.abs(once.x - chunked.x).max(), np.abs(once.u - chunked.u).max())
    assert worst < 1e-12, f"Max diff is {worst:.4E}"
