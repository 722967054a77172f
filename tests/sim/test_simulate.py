"""RK4 simulation: step choice, refusal of unstable steps, compiled vs interpreted, convergence."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from quadctl import pipeline
from quadctl.errors import StepSizeError
from quadctl.layout import STATE_INDEX
from quadctl.sim.cases import record_rows
from quadctl.sim.loop import ClosedLoop
from quadctl.sim.plan import (
    ACCURACY_STEP,
    max_stable_step,
    max_stable_steps,
    plan_step,
    record_stride,
    rk4_amplification,
)
from quadctl.sim.run import simulate


@pytest.fixture(scope="module")
def loop(forward):
    setup, trim, linear, _, des = forward
    return setup, pipeline.loop_of(setup, linear, des)


def test_rk4_real_axis_limit():
    """RK4 is stable on the negative real axis up to h lambda = -2.785293563 (a known constant)."""
    assert max_stable_step(-1.0) == pytest.approx(2.785293563, rel=1e-8)
    assert max_stable_step(-100.0) == pytest.approx(0.02785293563, rel=1e-8)
    assert max_stable_step(0.0) == math.inf
    h = max_stable_step(-3 + 4j)
    assert rk4_amplification(h * (-3 + 4j)) == pytest.approx(1.0, abs=1e-9)
    assert rk4_amplification(1.01 * h * (-3 + 4j)) > 1.0


def test_the_real_axis_limit_is_the_bisections():
    """A real eigenvalue takes REAL_AXIS without bisecting: the value the bisection finds off the axis
    by a hair, and the scan of max_stable_step on it, and RK4's amplification crosses 1 + 1e-12 there."""
    from quadctl.sim.plan import REAL_AXIS

    assert max_stable_steps(np.array([-2.0]))[0] == REAL_AXIS / 2
    nearby = max_stable_steps(np.array([-1.0 + 1e-300j]))[0]  # not on the axis: bisected
    assert nearby == REAL_AXIS == max_stable_step(-1.0)
    assert rk4_amplification(-REAL_AXIS) <= 1.0 + 1e-12 < rk4_amplification(-np.nextafter(REAL_AXIS, 3.0))


def test_auto_step_is_stable_and_accurate(loop):
    _, cl = loop
    plan = plan_step(cl.eigenvalues, cl.owners, 10.0, "auto")
    assert plan.auto and plan.dt * abs(plan.fastest_eigenvalue) <= ACCURACY_STEP + 1e-12
    assert plan.dt < plan.max_stable_dt
    assert plan.n_steps * plan.dt == pytest.approx(10.0)
    assert plan.fastest_owner == "roll"  # 1/Jxx is the largest input gain


def test_unstable_user_step_is_refused_with_eigenvalue_subsystem_and_limit(loop):
    _, cl = loop
    with pytest.raises(StepSizeError, match=r"simulation.dt = 0.001 s is unstable for RK4: the closed-loop "
                       r"eigenvalue -14492.8 rad/s \(subsystem roll\) needs dt <= 0.000192\d* s"):
        plan_step(cl.eigenvalues, cl.owners, 10.0, 1e-3)
    ok = plan_step(cl.eigenvalues, cl.owners, 1.0, 1.9e-4)
    assert ok.dt == 1.9e-4 and not ok.auto


def test_closed_loop_returns_to_trim(loop):
    setup, cl = loop
    sim = pipeline.simulation_of(setup, cl)
    assert sim.status == "ok" and sim.t[-1] == pytest.approx(setup.duration)
    err = sim.x[-1] - sim.x_ref[-1]
    regulated = [STATE_INDEX[s] for s in ("pD", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r")]
    assert np.abs(err[regulated]).max() < 1e-4
    # the unregulated north position keeps moving at the flight speed
    assert sim.x[-1, 0] == pytest.approx(setup.duration * 1.0, abs=0.5)


def test_rk4_is_fourth_order(loop):
    """Halving dt divides the global error by ~16 (reference: dt / 8)."""
    setup, cl = loop
    x0 = setup.initial_state(cl.x_trim)
    runs = [simulate(cl, x0, 0.01, h).x[-1] for h in (4e-5, 2e-5, 2.5e-6)]
    e1, e2 = np.abs(runs[0] - runs[2]).max(), np.abs(runs[1] - runs[2]).max()
    assert 12 < e1 / e2 < 24  # order 3 would give 8, order 5 would give 32


def test_divergence_stops_and_keeps_what_was_computed(loop):
    setup, cl = loop
    bad = ClosedLoop(**{**cl.__dict__, "K": -cl.K})  # positive feedback
    sim = simulate(bad, setup.initial_state(cl.x_trim), 5.0, 1e-4)
    assert sim.status in ("diverged", "left_valid_range")
    assert sim.steps < 50000 and len(sim.t) >= 2 and np.all(np.isfinite(sim.x[:-1]))
    assert "saved" in sim.message


def test_leaving_the_euler_range_is_reported(loop):
    setup, cl = loop
    free = ClosedLoop(**{**cl.__dict__, "K": np.zeros((4, 12)), "eigenvalues": np.zeros(12)})
    x0 = cl.x_trim.copy()
    x0[STATE_INDEX["q"]] = 3.0  # pitch up at 3 rad/s with no control
    sim = simulate(free, x0, 2.0, 1e-3)
    assert sim.status == "left_valid_range"
    assert "pitch" in sim.message and "Euler" in sim.message
    assert abs(sim.x[-2, STATE_INDEX["theta"]]) <= math.radians(85)


def test_chunked_runs_equal_one_long_call(loop, monkeypatch):
    """Chunk boundaries (for Ctrl-C) change nothing: t = k dt from the absolute step index."""
    import quadctl.sim.stack_run as stack_module

    setup, cl = loop
    x0 = setup.initial_state(cl.x_trim)
    whole = simulate(cl, x0, 0.05, 1e-5)
    monkeypatch.setattr(stack_module, "CHUNK_STEPS", {"compiled": 777, "casadi": 777})
    chunked = simulate(cl, x0, 0.05, 1e-5, max_samples=333)  # strides that do not divide the chunks
    again = simulate(cl, x0, 0.05, 1e-5, max_samples=333)
    np.testing.assert_array_equal(again.t, chunked.t)
    np.testing.assert_array_equal(whole.x[::chunked.stride], chunked.x[:-1])
    np.testing.assert_array_equal(whole.x[-1], chunked.x[-1])
    np.testing.assert_array_equal(whole.u[::chunked.stride], chunked.u[:-1])
    assert whole.steps == chunked.steps == 5000


def test_max_samples_sets_the_record_stride_and_keeps_the_last_step(loop):
    setup, cl = loop
    x0 = setup.initial_state(cl.x_trim)
    every = simulate(cl, x0, 0.01, 1e-5)  # 1000 steps, all kept
    few = simulate(cl, x0, 0.01, 1e-5, max_samples=70)
    assert every.stride == 1 and len(every.t) == 1001
    assert few.stride == 15 and len(few.t) == 1000 // 15 + 2 <= 70 and few.t[-1] == every.t[-1]
    np.testing.assert_array_equal(few.x[:-1], every.x[:-1:15])
    np.testing.assert_array_equal(few.x[-1], every.x[-1])
    for n in (1, 2, 3, 999, 1000, 1001, 289_856, 1_000_000):
        for cap in (2, 3, 69, 70, 1001, 20_000):
            stride = record_stride(n, cap)
            assert record_rows(0, n, stride) <= cap, (n, cap)
            assert stride == 1 or record_rows(0, n, stride - 1) > cap, (n, cap)  # the smallest


def test_vectorized_step_limits_agree_with_the_scan():
    rng = np.random.default_rng(3)
    eig = np.concatenate([rng.normal(size=300) * 10 ** rng.uniform(-2, 4, 300)
                          + 1j * rng.normal(size=300) * 10 ** rng.uniform(-2, 4, 300),
                          [-1.0, -14493.0, 0.0, 2.0, 1j, -1e-12 + 5j]])
    fast = max_stable_steps(eig)
    slow = np.array([max_stable_step(e) for e in eig])
    finite = np.isfinite(slow) & (slow > 0)
    assert np.array_equal(fast[~finite], slow[~finite])
    worst = np.max(np.abs(fast[finite] - slow[finite]) / slow[finite])
    assert worst < 1e-12, f"Max diff is {worst:.4E}"
    with pytest.raises(StepSizeError, match="is unstable for RK4"):  # limits given by a batch
        plan_step(eig[:3], ["x"] * 3, 2.0, 10.0, limits=fast[:3])


def test_an_absurd_step_count_is_refused_and_a_long_one_announced(loop):
    """An inertia in the wrong unit makes the loop 1e6 times faster: the plan says so before it runs."""
    from quadctl.errors import QuadctlNotice
    from quadctl.sim.plan import ANNOUNCE_STEPS, MAX_STEPS

    _, cl = loop
    fast = cl.eigenvalues * 1e6
    with pytest.raises(StepSizeError, match=r"simulation.duration = 10 s at an RK4 step of .* more than the 1e\+10 "
                                            r"quadctl runs .*check the units of vehicle.inertia"):
        plan_step(fast, cl.owners, 10.0)
    with pytest.raises(StepSizeError, match="more than the 1e\\+10"):
        plan_step(cl.eigenvalues, cl.owners, 1e300)
    step = plan_step(cl.eigenvalues, cl.owners, 1.0).dt
    with pytest.warns(QuadctlNotice, match=r"simulating 2e\+08 RK4 steps"):
        plan = plan_step(cl.eigenvalues, cl.owners, 2 * ANNOUNCE_STEPS * step)
    assert ANNOUNCE_STEPS < plan.n_steps < MAX_STEPS


@pytest.mark.parametrize("config_name", ["hover", "mambo-200hz"])  # continuous feedback; a sampled controller
@pytest.mark.parametrize("method", ["rk4", "etdrk4"])
@pytest.mark.parametrize("dt", [1e-300, 1e-12])
def test_a_step_too_small_to_run_is_refused_naming_simulation_dt(tmp_path, config_name, method, dt):
    """A tiny ``simulation.dt`` is the user's slip: the refusal names it and the way out, not the duration."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["simulate", "-c", config_name, "-o", str(out), "--set", f"simulation.dt={dt!r}",
                                   "--set", f"simulation.method={method}"])
    assert res.exit_code == 2, res.output
    assert res.stderr.strip().splitlines() == [
        f"quadctl: error: {config_name}.yaml with --set: simulation.dt = {dt:g} s makes simulation.duration = 10 s "
        f"{10 / dt:.3g} steps, more than the 1e+10 quadctl runs; use dt: auto, or a step of at least 1e-09 s"]
    assert not out.exists()  # the folder as it was: none (the one the lock made is gone again)


@pytest.mark.parametrize("duration, x0, match", [
    (-1.0, None, "duration must be a positive number of seconds, got -1.0"),
    (0.0, None, "duration must be a positive number of seconds, got 0.0"),
    (float("nan"), None, "duration must be a positive number of seconds, got nan"),
    ("3", None, "duration must be a positive number of seconds, got '3'"),
    (1.0, [0.0, 0.0, 0.0], r"x0 must be the 12 states pN, pE, .* got shape \(3,\)"),
    (1.0, [0.0, 0.0, float("nan")] + [0.0] * 9, r"x0 must be finite: x0\[2\] \(pD\) = nan; give every state"),
])
def test_the_python_call_refuses_a_run_that_cannot_be_flown(duration, x0, match):
    """Bad arguments of the public call give one clear ValueError, not a run 'ok' to t = -1 s, a division by
    zero, NumPy's broadcasting error or a run of NaN reported as 'diverged'."""
    import quadctl as qc

    stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    loop = stages.loop
    with pytest.raises(ValueError, match=match):
        qc.simulate(loop, loop.x_trim if x0 is None else x0, duration)


@pytest.mark.parametrize("dt", [-1e-3, 0.0, float("nan"), float("inf"), "fast", None, True])
@pytest.mark.parametrize("config_name", ["hover", "mambo-200hz"])  # continuous control, and held at 200 Hz
def test_the_python_call_refuses_a_step_that_is_not_a_positive_number_of_seconds(config_name, dt):
    """A negative ``dt`` ran backwards in time and reported 'ok'; text reached ``float()``: each is one
    ValueError naming ``dt`` and what it takes."""
    import quadctl as qc

    stages = qc.Stages(qc.setup_of(qc.load_config(config_name)))
    loop = stages.loop
    want = rf"^dt must be a positive number of seconds or 'auto', got {re.escape(repr(dt))}$"
    with pytest.raises(ValueError, match=want):
        qc.simulate(loop, loop.x_trim, 0.1, dt=dt)


@pytest.mark.parametrize("max_samples", [1, 0, -5, 2.5, "100", None, True])
def test_the_python_call_refuses_a_max_samples_below_two_or_not_whole(max_samples):
    """``max_samples=1`` divided by zero inside the record stride, and ``0`` returned the start alone for
    a whole run: each is one ValueError naming ``max_samples``, as the config's ``ge=2`` refuses it."""
    import quadctl as qc

    loop = qc.Stages(qc.setup_of(qc.load_config("hover"))).loop
    want = rf"^max_samples must be a whole number of at least 2 .*got {re.escape(repr(max_samples))}$"
    with pytest.raises(qc.ArgumentError, match=want):
        qc.simulate(loop, loop.x_trim, 0.1, max_samples=max_samples)
    assert qc.simulate(loop, loop.x_trim, 0.1, max_samples=2).t.tolist() == [0.0, 0.1]


def test_the_python_call_refuses_a_complex_start():
    """A complex ``x0`` lost its imaginary part to a ComplexWarning and flew the real one."""
    import quadctl as qc

    loop = qc.Stages(qc.setup_of(qc.load_config("hover"))).loop
    with pytest.raises(qc.ArgumentError, match=r"^x0 must be 12 real numbers, got dtype complex128$"):
        qc.simulate(loop, loop.x_trim + 0.1j, 0.1)


def test_the_python_call_refuses_what_is_not_a_closed_loop():
    """The design where the loop goes: a TypeError saying what to pass, not an AttributeError from inside."""
    import quadctl as qc

    stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    with pytest.raises(TypeError, match=r"^simulate takes a ClosedLoop, stages.loop of .*; got Design$"):
        qc.simulate(stages.design, stages.loop.x_trim, 1.0)


def test_each_stage_function_names_an_argument_of_another_kind():
    """quadctl.pipeline's stage functions (the reference's 'The stages') with a config for the setup or two
    stages swapped failed with an AttributeError from inside ('Config' object has no attribute
    'velocity_ned')."""
    import quadctl as qc
    from quadctl import pipeline

    cfg = qc.load_config("hover")
    stages = qc.Stages(qc.setup_of(cfg))
    setup, trim, linear, dec, des = stages.setup, stages.trim, stages.linear, stages.decoupled, stages.design
    for call, match in ((lambda: pipeline.trim_of(cfg), r"trim_of: setup must be a Setup .*got Config"),
                        (lambda: pipeline.linear_of(setup, linear), r"linear_of: trim must be a Trim .*got Linear"),
                        (lambda: pipeline.decoupled_of(setup, trim), r"decoupled_of: linear must be a LinearModel"),
                        (lambda: pipeline.design_of(setup, linear, dec), r"design_of: decoupled must be a Decoupled"),
                        (lambda: pipeline.loop_of(setup, linear, dec), r"loop_of: des must be a Design .*got Dec"),
                        (lambda: pipeline.simulation_of(setup, des), r"simulation_of: loop must be a ClosedLoop")):
        with pytest.raises(qc.ArgumentTypeError, match=rf"^{match}"):
            call()


def test_the_python_call_refuses_noise_wind_or_a_reference_of_another_kind():
    """The path (setup.reference) where the flown reference goes (setup.flown_reference), a mapping for the
    noise, a number for the wind: each failed with an AttributeError from inside the run."""
    import quadctl as qc

    setup = qc.setup_of(qc.load_config("square"))
    loop = qc.Stages(setup).loop
    for kwargs, match in (({"reference": setup.reference}, r"reference must be a FlownReference \(setup\."
                                                              r"flown_reference is the configured one\) or None, "
                                                              r"got Reference$"),
                          ({"noise": {"gyro": 0.01}}, r"noise must be a NoiseSpec .*got dict$"),
                          ({"wind": 3.0}, r"wind must be a WindSpec .*got float$")):
        with pytest.raises(qc.ArgumentTypeError, match=rf"^simulate: {match}"):
            qc.simulate(loop, loop.x_trim, 0.1, **kwargs)


@pytest.mark.parametrize("exo_rate", [-1.0, 0.0, "200"])
def test_the_python_call_refuses_an_exogenous_rate_that_is_not_a_positive_number(exo_rate):
    """A negative one failed in the wind's rows with an IndexError, text with Python's TypeError."""
    import quadctl as qc

    setup = qc.setup_of(qc.load_config("crazyflie-wind"))
    loop = qc.Stages(setup).loop
    with pytest.raises(qc.ArgumentError, match=rf"^exo_rate must be a positive number of Hz or None, "
                                               rf"got {re.escape(repr(exo_rate))}$"):
        qc.simulate(loop, loop.x_trim, 0.1, wind=setup.wind, exo_rate=exo_rate)


@pytest.mark.parametrize("tolerance", [-1.0, 0.0, float("nan"), "1e-6"])
def test_the_python_call_refuses_a_tolerance_that_is_not_a_positive_number(tolerance):
    """A negative one failed inside ETDRK4's planner with 'float() argument must be ... not complex'."""
    import quadctl as qc

    loop = qc.Stages(qc.setup_of(qc.load_config("hover"))).loop
    want = rf"^tolerance must be a positive number .*got {re.escape(repr(tolerance))}$"
    with pytest.raises(qc.ArgumentError, match=want):
        qc.simulate(loop, loop.x_trim, 0.1, method="etdrk4", tolerance=tolerance)


def test_the_chain_of_stages_names_what_it_takes_when_given_something_else():
    """A config where a setup goes, or a name where a config goes: one TypeError saying what to pass."""
    import quadctl as qc

    cfg = qc.load_config("hover")
    with pytest.raises(TypeError, match=r"Stages takes a Setup, .*got Config"):
        qc.Stages(cfg)
    with pytest.raises(TypeError, match=r"setup_of takes a validated Config, .*got str"):
        qc.setup_of("hover")
    stages = qc.Stages(qc.setup_of(cfg))  # a stage of another kind where one is given: not an AttributeError later
    for given, match in (({"trim": stages.trim.x}, r"trim must be a Trim .*got ndarray"),
                         ({"linear": stages.trim}, r"linear must be a LinearModel .*got Trim"),
                         ({"decoupled": stages.design}, r"decoupled must be a Decoupled .*got Design")):
        with pytest.raises(qc.ArgumentTypeError, match=rf"^Stages: {match}$"):
            qc.Stages(stages.setup, **given)


@pytest.mark.parametrize("x_trim", [[0.0] * 5, [[0.0] * 12]])
def test_the_configured_start_refuses_what_is_not_the_12_states(x_trim):
    """``setup.initial_state`` of the wrong shape was NumPy's broadcasting error, or a (1, 12) start that
    ``simulate`` then refused for a reason the caller did not write."""
    import quadctl as qc

    setup = qc.setup_of(qc.load_config("hover"))
    with pytest.raises(ValueError, match=r"^initial_state takes the 12 states of a trim \(a Trim's x, or a loop's "
                                         rf"x_trim\), got shape {re.escape(str(np.shape(x_trim)))}$"):
        setup.initial_state(x_trim)


def test_the_configured_start_names_a_trim_given_whole():
    """``setup.initial_state(stages.trim)``, the Trim where its ``x`` goes: float()'s TypeError."""
    import quadctl as qc

    stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    with pytest.raises(qc.ArgumentTypeError, match=r"^initial_state takes the 12 states of a trim \(a Trim's x, "
                                                   r"or a loop's x_trim\), got Trim$"):
        stages.setup.initial_state(stages.trim)


def test_a_vehicle_that_turns_over_is_a_diverged_run_not_a_completed_one(tmp_path):
    """The bundled crazyflie design, flown on the Crazyflie identified from its logs (the rotors' 65 ms lag, the
    identified inertia), rolls over and over and falls 16 m in 10 s: its roll and pitch loops are unstable with
    the lag, and the pitch stays under 85 deg. The run said "ok: completed 10000 steps" (exit 0) with a
    saturation warning; past 90 deg of roll it now stops as diverged, saying the vehicle turned over."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    res = CliRunner().invoke(app, ["simulate", "-c", "crazyflie", "--set", "motors.time_constant=0.0651", "--set",
                                   "simulation.plant.inertia=[1.4e-5, 1.481e-5, 2.881e-5]", "-o", str(tmp_path)])
    assert res.exit_code == 1, res.output
    assert re.search(r"^quadctl: check failed: diverged at t = \S+ s: roll -?9\d\.\d deg is 90 deg or more from the "
                     r"trim's: the vehicle turned over, its thrust no longer holds it up; saved \d+ steps$",
                     res.stderr.strip().splitlines()[-1]), res.stderr
