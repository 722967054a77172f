"""Loops that fly a gain schedule (quadctl.sim.builder, "Gain schedule") against independent references.

- The law's gain at a scheduling value is the table's (:meth:`GainTable.at`, SciPy's layout evaluated
  in NumPy), at many values, at the breaks and outside the grid, for every interpolation.
- A schedule whose points all hold one design flies that fixed design.
- The SIMD lanes against the one-case loop, and the compiled loop against CasADi's virtual machine.
- The table the tests build point by point is the schedule stage's, which ``simulate`` flies.
- The bundled transition: the fixed hover design leaves the model's valid range, saturating its
  rotors; the schedule flies the whole transition within them.

The Jacobian of a scheduled loop at a frozen reference is in tests/sim/test_closed_loop.py.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from _solve import cfg_dict, designed_table, solve

from quadctl import config, pipeline
from quadctl.design.gain_table import GainTable
from quadctl.layout import N_STATES, STATE_INDEX
from quadctl.setup import setup_of
from quadctl.sim.builder import build
from quadctl.sim.loop_spec import LoopSpec
from quadctl.sim.run import simulate

AGREE = 1e-12
"""The schedule's coefficients are selected exactly (one nonzero term of a sum) and evaluated by the
same Horner sequence as GainTable.at: the same double operations; compiled and interpreted round alike."""
TRANSITION = "crazyflie-speed-schedule"


def _law_gain(loop, x_ref_row, t: float = 0.0):
    """(4, nx) the law's Jacobian ``du/dX`` at time ``t`` at ``X = [x_ref; 0...]``, the reference there being
    ``x_ref_row``: ``-G(v)`` on the states (and the integrators), the loop's generated law differentiated
    by CasADi."""
    import casadi as ca

    spec = loop.spec()
    fns = build(spec)
    c = loop.constants(1.0 / loop.rate if loop.rate else None)
    X = ca.SX.sym("X", spec.nx)
    u, _ = fns.law(X, t, c, ca.DM.zeros(spec.n_exo, 1))
    return np.asarray(ca.Function("J", [X], [ca.jacobian(u, X)])(loop.initial_loop_state(x_ref_row)))


@pytest.mark.parametrize("name, interpolation", [("hover", "cubic"), ("hover", "nearest"),
                                                 ("mambo-200hz", "linear"), ("mambo-200hz", "cubic")])
def test_the_laws_gain_is_the_tables_at_every_value(name, interpolation):
    """hover: continuous, state gain only; mambo-200hz: sampled, rotors, and the integrator's gain in
    the table (13 columns). The reference is set to fly north at ``v`` (level, heading 0, so the
    scheduling value is ``v`` exactly), at values across the grid, its breaks and beyond its ends."""
    values = [0.0, 1.5, 3.0, 4.5]
    table = designed_table(name, values, interpolation)
    setup, _, linear, _, des = solve(cfg_dict(name))
    loop = replace(pipeline.loop_of(setup, linear, des), schedule=table)
    degree = {"nearest": 0, "linear": 1, "cubic": 3}[interpolation]
    assert loop.spec().schedule == ("speed", len(table.breaks) - 1, table.gains.shape[2], degree)
    probes = np.concatenate([np.linspace(-1.0, 5.5, 53), table.breaks, np.nextafter(table.breaks, -np.inf)])
    worst = 0.0
    for v in probes:
        row = np.zeros(N_STATES)
        row[STATE_INDEX["u"]] = v
        J = _law_gain(replace(loop, x_trim=row, x_rate=np.zeros(N_STATES)), row)
        G = table.at(v)
        got = -J[:, :G.shape[1]]
        worst = max(worst, np.abs(got - G).max() / np.abs(G).max())
    assert worst < AGREE, f"{name} {interpolation}: max rel diff {worst:.3e}"


def test_the_gain_follows_the_heading_a_speed_is_measured_along():
    """Flying at 3 m/s on a heading of 0.7 rad, with the table measuring speed along 0.7 rad: the gain
    at 3 m/s; along north instead (heading 0), at 3 cos(0.7) m/s."""
    table = designed_table("hover", [0.0, 2.0, 4.0], "linear")
    setup, _, linear, _, des = solve(cfg_dict("hover"))
    row = np.zeros(N_STATES)
    row[STATE_INDEX["u"]], row[STATE_INDEX["psi"]] = 3.0, 0.7
    for heading, speed in ((0.7, 3.0), (0.0, 3.0 * np.cos(0.7))):
        loop = replace(pipeline.loop_of(setup, linear, des), schedule=table, schedule_heading=heading,
                       x_trim=row, x_rate=np.zeros(N_STATES))
        got = -_law_gain(loop, row)[:, :N_STATES]
        assert np.abs(got - table.at(speed)).max() < 1e-12 * np.abs(table.at(speed)).max()


def test_the_gain_moves_with_the_reference():
    """A reference speeding up north at 1 m/s^2 from hover (``x_rate`` on ``u``): at t = 1.3 s and
    3.1 s the law's gain is the table's at 1.3 and 3.1 m/s, not at the trim's 0."""
    table = designed_table("hover", [0.0, 2.0, 4.0], "cubic")
    setup, _, linear, _, des = solve(cfg_dict("hover"))
    rate = np.zeros(N_STATES)
    rate[STATE_INDEX["u"]] = 1.0
    loop = replace(pipeline.loop_of(setup, linear, des), schedule=table, x_rate=rate)
    for t in (1.3, 3.1):
        got = -_law_gain(loop, loop.x_trim + rate * t, t)[:, :N_STATES]
        assert np.abs(got - table.at(t)).max() < AGREE * np.abs(table.at(t)).max()


@pytest.fixture(scope="module")
def transition():
    """(setup, fixed loop, table) of the bundled transition config, the table built apart from the pipeline's."""
    setup = setup_of(config.load(TRANSITION))
    stages = pipeline.Stages(setup)
    return setup, stages.loop, designed_table(TRANSITION, setup.schedule.values)


def _short_reference(setup, duration: float = 3.0):
    """The config's reference for ``duration`` s (3 s: hover, then 2, 4, 6 m/s north at 1, 2, 3 s)."""
    return setup.flown_reference, duration


@pytest.mark.compiler
@pytest.mark.parametrize("interpolation", ["linear", "cubic"])
def test_a_schedule_of_one_design_flies_that_design(transition, interpolation):
    setup, fixed, _ = transition
    gains = np.repeat(fixed.K[None], 4, axis=0)
    table = GainTable.of("speed", [0.0, 1.0, 2.0, 20.0], gains, interpolation)  # the run crosses three pieces
    ref, duration = _short_reference(setup)
    one = simulate(fixed, fixed.x_trim, duration, reference=ref)
    scheduled = simulate(pipeline.scheduled_loop(fixed, table, 0.0), fixed.x_trim, duration, reference=ref)
    assert one.status == scheduled.status == "ok" and np.ptp(one.x[:, STATE_INDEX["u"]]) > 2.5
    diff = max(np.abs(one.x - scheduled.x).max(), np.abs(one.u - scheduled.u).max())
    assert diff < AGREE, diff


@pytest.mark.compiler
def test_compiled_and_interpreted_loops_fly_a_schedule_alike(transition, monkeypatch):
    from quadctl.sim import engine

    setup, fixed, table = transition
    loop = pipeline.scheduled_loop(fixed, table, 0.0)
    ref, duration = _short_reference(setup, 1.5)
    compiled = simulate(loop, loop.x_trim, duration, reference=ref)
    monkeypatch.setenv("QUADCTL_NO_COMPILE", "1")
    engine.runner.cache_clear()
    try:
        with pytest.warns(engine.CompilerNotice):
            interpreted = simulate(loop, loop.x_trim, duration, reference=ref)
    finally:
        engine.runner.cache_clear()
    assert compiled.backend == "compiled" and interpreted.backend == "casadi"
    assert np.ptp(compiled.x[:, STATE_INDEX["u"]]) > 0.5
    diff = max(np.abs(compiled.x - interpreted.x).max(), np.abs(compiled.u - interpreted.u).max())
    assert diff < AGREE, diff


@pytest.mark.compiler
def test_lanes_equal_the_one_case_loop_with_a_schedule(transition):
    """Three lanes, each its own table (the coefficients scaled), one compiled structure."""
    from quadctl.sim import engine
    from quadctl.sim.cases import Cases
    from quadctl.sim.exogenous import ExoStream
    from quadctl.sim.plan import record_stride

    setup, fixed, table = transition
    ref, duration = _short_reference(setup)
    variants = []
    for k in range(3):
        scaled = replace(table, gains=table.gains * (1 + 0.05 * k), coefficients=table.coefficients * (1 + 0.05 * k))
        variants.append((pipeline.scheduled_loop(fixed, scaled, 0.0), duration - 0.2 * k))
    run = engine.runner(variants[0][0].spec(reference=True), engine.LANES)
    assert run.backend == "compiled-simd" and len({v.spec() for v, _ in variants}) == 1
    jobs = []
    for vk, dur in variants:
        plan = vk.plan(dur)
        stream = ExoStream(None, None, vk.rate, ref)
        first, rows = stream.rows(0, plan.n_steps, plan.dt)
        jobs.append((plan, vk.constants(plan.sample_time), vk.initial_loop_state(vk.x_trim), *vk.bounds(dur, ref),
                     rows, first, stream.period))
    cases = Cases.of(np.stack([j[2] for j in jobs]), np.stack([j[1] for j in jobs]), [j[0].dt for j in jobs],
                     [j[0].n_steps for j in jobs], [record_stride(j[0].n_steps, setup.max_samples) for j in jobs],
                     np.stack([j[3] for j in jobs]), np.stack([j[4] for j in jobs]),
                     hold=[j[0].hold for j in jobs], exo=[j[5] for j in jobs],
                     exo_first=[j[6] for j in jobs], exo_period=[j[7] for j in jobs])
    worst = 0.0
    for (vk, dur), (done, _, xs, us) in zip(variants, run.run(cases)):
        one = simulate(vk, vk.x_trim, dur, reference=ref, max_samples=setup.max_samples)
        assert done == one.steps and one.status == "ok"
        worst = max(worst, np.abs(xs[:, :N_STATES] - one.x).max(), np.abs(us - one.u).max())
    assert worst < AGREE, worst


def test_the_table_these_tests_build_is_the_schedule_stages(transition):
    """What ``simulate`` flies (quadctl.schedule.envelope.schedule_of) is what the tests above build apart."""
    from quadctl.schedule.envelope import schedule_of

    setup, _, table = transition
    made = schedule_of(setup).table
    assert made.variable == "speed" and made.interpolation == "linear"
    assert np.array_equal(made.values, table.values)
    assert np.abs(made.gains - table.gains).max() < 1e-9 * np.abs(table.gains).max()


@pytest.fixture(scope="module")
def flown_transition(transition):
    """The bundled transition flown with the schedule and with the fixed design (quadctl.schedule.transition)."""
    from quadctl.schedule.transition import fly_transition

    setup, _, table = transition
    return fly_transition(setup, table)


@pytest.mark.compiler
def test_the_fixed_design_leaves_the_valid_range_where_the_schedule_flies(transition, flown_transition):
    """The bundled transition: the hover design alone, asked for 2 m/s more each second, pitches past
    85 deg near 18 m/s with its rotors at a limit; the schedule completes the way up and back within them."""
    setup, result = transition[0], flown_transition
    fixed, scheduled = result.summary["fixed"], result.summary["scheduled"]
    assert fixed["status"] == "left_valid_range" and fixed["saturates"] and fixed["peak_attitude"] > 85
    assert scheduled["completed"] and not scheduled["saturates"] and scheduled["peak_attitude"] < 40
    assert scheduled["on_grid"] and scheduled["flown_range"][1] > 0.9 * setup.schedule.values[-1]
    assert result.scheduled.x[-1, STATE_INDEX["u"]] < 0.5  # back near hover
    assert fixed["flown_range"][1] > 15  # it failed at speed, not at the first step
    from quadctl.present.schedule import transition_lines

    scheduled_line, fixed_line = transition_lines(result.summary)  # in words, the range with its unit
    assert scheduled_line.startswith("scheduled: completed (25 s)") and scheduled_line.endswith(" m/s")
    assert fixed_line.startswith("fixed: left the valid range (10.6 s)") and " speed flown 0 to 17.8 m/s" in fixed_line


@pytest.mark.compiler
def test_the_transition_velocity_error_is_the_rate_of_the_position_error(flown_transition):
    """The peak velocity error is of the earth-frame velocities: the slope of ``p - p_ref`` (finite
    differences of the 2 ms records, within 1 %). It compared body velocities, each in its own attitude:
    the fixed design pitched 85 deg off the reference read as 14.7 m/s where the path's error is 4.9 m/s."""
    for label, sim in flown_transition.runs().items():
        slope = np.gradient(sim.x[:, :3] - sim.x_ref[:, :3], sim.t, axis=0)
        expected = np.linalg.norm(slope, axis=1).max()
        assert flown_transition.summary[label]["velocity_error"] == pytest.approx(expected, rel=0.01), label


@pytest.mark.compiler
def test_the_transition_figure_shows_both_runs_and_where_one_stopped(flown_transition):
    from quadctl import plots

    fig = plots.transition_figure(flown_transition, title=TRANSITION)
    speed, pitch, rotor = fig.axes
    labels = [line.get_label() for line in speed.get_lines()]
    assert "scheduled (completed)" in labels and "fixed (left the valid range)" in labels
    ends = [line for line in pitch.get_lines() if line.get_marker() == "x"]
    assert len(ends) == 1 and ends[0].get_xdata()[0] == pytest.approx(flown_transition.fixed.t[-1])
    assert ends[0].get_ydata()[0] < -85
    assert plots.png_bytes(fig)[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_transition_figure_without_rotors_plots_a_share_of_the_limits_or_the_thrust_in_newtons():
    """Box limits: the bottom panel is each input's share of its room from the reference to its limit (1 at
    the limit, a line there), so N and N m are never drawn on one axis; no limits: the thrust's change, in N."""
    from types import SimpleNamespace as NS

    from quadctl import plots

    t = np.linspace(0.0, 1.0, 5)
    x = np.zeros((5, 12))
    u = np.column_stack([np.linspace(0.3, 0.5, 5), np.linspace(0.0, -0.004, 5), np.zeros(5), np.zeros(5)])
    sim = NS(t=t, x=x, x_ref=x, u=u, u_ref=np.zeros((0, 4)), status="ok")
    table = NS(variable="speed", values=(0.0, 2.0), interpolation="linear")
    trim = np.array([0.3, 0.0, 0.0, 0.0])
    box = NS(mode="box", lo=np.array([0.0, -0.01, -0.01, -0.01]), hi=np.array([0.7, 0.01, 0.01, 0.01]))
    for act, label, want in ((box, "largest share of an\ninput's limit [1]", np.maximum(np.linspace(0, 0.5, 5),
                                                                                      np.linspace(0, 0.4, 5))),
                             (None, "thrust change\n|T - T_ref| [N]", np.linspace(0.0, 0.2, 5))):
        loop = NS(schedule=table, schedule_heading=0.0, actuators=act, u_trim=trim)
        flown = NS(runs=lambda: {"scheduled": sim, "fixed": sim}, loops={"scheduled": loop})
        bottom = plots.transition_figure(flown).axes[2]
        assert bottom.get_ylabel() == label
        np.testing.assert_allclose(bottom.get_lines()[0].get_ydata(), want, rtol=1e-12, atol=1e-15)
        limits = [line for line in bottom.get_lines() if line.get_label() == "at a limit"]
        assert len(limits) == (act is not None) and all(line.get_ydata()[0] == 1.0 for line in limits)


def test_a_schedule_takes_the_gain_columns_of_its_integrators(transition):
    _, fixed, _ = transition
    with pytest.raises(ValueError, match=r"^schedule: 13 gain columns; a loop with 0 integrators schedules 12"):
        LoopSpec.of_gain(fixed.K, schedule=("speed", 5, 13, 1))


SETPOINT_SPEEDS = (2.0, 4.0, 6.0, 8.0, 10.0)
"""m/s north at 1, 2, .. 5 s of a 6 s run: the bundled ``schedule`` config (continuous, the report's
stiff rate loops) flown across its values, hover to 10 m/s."""
SETPOINT_RUN = 6.0
"""s."""


@pytest.fixture(scope="module")
def speed_steps():
    """(loop on the schedule's gains, its schedule, reference, x0, RK4 at 1/256 of the rows' period:
    a step dividing it, so the reference's rows change at steps' starts)."""
    from quadctl.schedule.envelope import schedule_of

    data = cfg_dict("schedule")
    data["simulation"].update(duration=SETPOINT_RUN, reference={"setpoints": [
        {"t": 1.0 + i, "velocity": [v, 0.0, 0.0]} for i, v in enumerate(SETPOINT_SPEEDS)]})
    setup, _, linear, _, des = solve(data)
    sched = schedule_of(setup)
    loop = sched.flown_by(pipeline.loop_of(setup, linear, des))
    ref, x0 = setup.flown_reference, setup.initial_state(loop.x_trim)
    truth = simulate(loop, x0, SETPOINT_RUN, 0.005 / 256, reference=ref)
    return loop, sched, ref, x0, truth


@pytest.mark.compiler
def test_etdrk4_flies_a_gain_schedule_on_the_loop_closed_at_the_nearest_value(speed_steps):
    """ETDRK4 at dt: auto, tolerance 1e-8, against RK4 at a small step: each step's linear part is the
    loop closed at the schedule's value nearest the commanded speed (its Jacobians and gains there), so
    the rate loops the gains move stay in the exactly integrated part: 2.1e-9 (RK4 at its stable step:
    173 914 steps). On the trim's linear part alone (no schedule_jacobians) the remainder carries them:
    9.1e-9, four times that (2.3e-7 on steps graded on tolerance^(1/4), where a reference's largest
    step was 6.6 times as long: quadctl.sim.etdrk4_plan.forced_step)."""
    from quadctl.sim.etdrk4_plan import record_strides
    from quadctl.sim.etdrk4_stack import _linear_pieces, exponential_plan

    loop, sched, ref, x0, truth = speed_steps
    etd = simulate(loop, x0, SETPOINT_RUN, "auto", method="etdrk4", tolerance=1e-8, reference=ref)
    assert etd.status == truth.status == "ok" and truth.x[-1, STATE_INDEX["u"]] > 4
    err = np.abs(etd.x[-1] - truth.x[-1]).max()
    assert err < 1e-8, err
    trim_only = simulate(replace(loop, schedule_jacobians=None), x0, SETPOINT_RUN, "auto", method="etdrk4",
                         tolerance=1e-8, reference=ref)
    assert np.abs(trim_only.x[-1] - truth.x[-1]).max() > 3 * err
    _, plan = exponential_plan(loop, SETPOINT_RUN, tolerance=1e-8, reference=ref, exo_period=0.005)
    pieces = _linear_pieces(loop, plan, record_strides(plan, 10**6), ref)
    values = [float(sched.table.values[p]) for _, _, p in pieces]
    assert values[0] == 0.0 and values[-1] == SETPOINT_SPEEDS[-1] and set(values) == {0.0, 2.0, 4.0, 6.0, 8.0, 10.0}
    assert [s.k0 * s.dt for s, _, _ in pieces[1:]] == pytest.approx([s.end for s, _, _ in pieces[:-1]])
    assert sum(s.n for s, _, _ in pieces) == plan.n_steps


@pytest.mark.compiler
def test_etdrk4_flies_a_sampled_controllers_schedule(transition):
    """The transition config's 500 Hz schedule, its first 3 s (hover, then 2, 4, 6 m/s): ETDRK4 steps
    the plant between the samples at which the law takes G(v), as RK4 does at a fortieth of the period."""
    setup, fixed, table = transition
    loop = pipeline.scheduled_loop(fixed, table, 0.0)
    ref, duration = _short_reference(setup)
    Ts = 1.0 / loop.rate
    rk4 = simulate(loop, fixed.x_trim, duration, Ts / 40, reference=ref, max_samples=10**6)
    etd = simulate(loop, fixed.x_trim, duration, "auto", method="etdrk4", tolerance=1e-10, reference=ref,
                   max_samples=10**6)
    assert etd.status == rk4.status == "ok" and np.ptp(rk4.x[:, STATE_INDEX["u"]]) > 2.5
    assert np.abs(etd.x[-1] - rk4.x[-1]).max() < 1e-9
    k = np.round(etd.t / (Ts / 40)).astype(int)
    assert np.abs(etd.u - rk4.u[k]).max() < 1e-8


def test_the_linear_part_at_a_point_is_the_frozen_loop_there(speed_steps):
    """ClosedLoop.linear_part(p): the model's Jacobians at the p-th value closed with the table's gains
    there; its eigenvalues are the schedule's frozen-point check at that value."""
    loop, sched, *_ = speed_steps
    checks = sched.checks
    for p, v in enumerate(sched.table.values):
        got = np.sort_complex(np.linalg.eigvals(loop.linear_part(p)))
        row = checks.eigenvalues[list(checks.values).index(v)]
        assert np.abs(got - np.sort_complex(row[np.isfinite(row)])).max() < 1e-6 * np.abs(got).max()
    with pytest.raises(ValueError, match="no schedule_jacobians"):
        replace(loop, schedule_jacobians=None).linear_part(0)


@pytest.mark.compiler
def test_the_workspace_flies_a_continuous_schedule_by_etdrk4_on_its_points(tmp_path):
    """A config with schedule: and simulation.method: etdrk4 (the bundled continuous ``schedule`` config
    flown to 6 m/s): the run the workspace writes is within 1e-9 of RK4 at a small step (6e-11), which it
    is only on the loops closed at the schedule's values (on the trim's loop: 1.4e-8)."""
    from quadctl.workspace import Workspace

    data = cfg_dict("schedule")
    data["simulation"].update(method="etdrk4", duration=2.0,
                              reference={"setpoints": [{"t": 0.5, "velocity": [6.0, 0.0, 0.0]}]})
    cfg = config.from_dict(data)
    with Workspace(cfg, tmp_path) as ws:
        flown = ws.simulation
    assert flown.sim.status == "ok" and flown.sim.plan.method == "etdrk4"
    setup = setup_of(cfg)
    truth = simulate(flown.loop, setup.initial_state(flown.loop.x_trim), 2.0, 0.005 / 256,
                     reference=setup.flown_reference)
    err = np.abs(flown.sim.x[-1] - truth.x[-1]).max()
    assert err < 1e-9, err


@pytest.mark.compiler
def test_simulate_flies_the_schedule_and_sim_json_says_so(tmp_path):
    import json

    from quadctl.workspace import Workspace

    with Workspace(config.load(TRANSITION), tmp_path) as ws:
        flown = ws.simulation
    assert flown.loop.schedule is not None and flown.sim.status == "ok"
    payload = json.loads((tmp_path / "sim.json").read_text())
    saved = payload["gain_schedule"]
    assert payload["schedule"][0]["steps"] == flown.sim.steps  # the step schedule (RK4's one segment) stays
    assert saved["variable"] == "speed" and saved["values"] == [0, 4, 8, 12, 16, 20]
    assert saved["interpolation"] == "linear" and saved["scheduled_on"].startswith("the reference")


@pytest.mark.parametrize("variable", ["speed", "climb", "yaw"])
def test_scheduling_values_of_a_run_are_the_variable_row_by_row(variable):
    from quadctl.design.gain_table import scheduling_value, scheduling_values

    xs = np.random.default_rng(4).normal(size=(7, N_STATES))
    one_by_one = [scheduling_value(variable, x, 0.3) for x in xs]
    assert np.abs(scheduling_values(variable, xs, 0.3) - one_by_one).max() < 1e-14


def test_the_rk4_step_holds_every_frozen_loop_of_the_schedule():
    """A continuous scheduled loop's step is planned over the schedule's frozen loops too: a frozen
    eigenvalue faster than the design's own governs the step, named as the gain schedule's."""
    from quadctl.schedule.envelope import schedule_of

    setup = setup_of(config.load("schedule"))
    loop = pipeline.Stages(setup).loop
    sched = schedule_of(setup)
    own = loop.plan(setup.duration)
    scheduled = pipeline.scheduled_loop(loop, sched.table, sched.heading, sched.checks.eigenvalues)
    plan = scheduled.plan(setup.duration)
    frozen = sched.checks.eigenvalues[np.isfinite(sched.checks.eigenvalues)]
    assert np.all(np.abs(plan.dt * frozen) <= 0.5 + 1e-12)
    fast = pipeline.scheduled_loop(loop, sched.table, sched.heading, [10 * own.fastest_eigenvalue, np.nan])
    plan = fast.plan(setup.duration)
    assert plan.fastest_owner == "gain schedule"
    assert plan.dt == pytest.approx(own.dt / 10, rel=0.05)
