"""References: setpoints and waypoint missions, their shapes against the closed forms, the
flatness feedforward against finite differences and the trim, the closed loop flying them (a
position step settling as its slowest pole says, the bundled mission), and every runner agreeing."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest
from _paths import ROOT
from _solve import without_compiler

from quadctl import config, pipeline, run_summary
from quadctl.errors import ConfigError
from quadctl.linear.trim import solve_trim
from quadctl.physics import trajectory
from quadctl.physics.model import Vehicle, build_model
from quadctl.physics.reference_rows import ROW_HALF, SPLIT_ROUNDOFF, FlownReference, in_force
from quadctl.present import mission
from quadctl.present.mission import mission_text
from quadctl.setup import setup_of
from quadctl.sim.run import simulate

HOVER_HOLD = ROOT / "docs" / "configs" / "hover-hold.yaml"
"""Hover holding position: the square mission's design, without the mission."""


@pytest.fixture(scope="module")
def square():
    """(setup, loop) of the bundled square mission (the hover-hold design)."""
    setup = setup_of(config.load("square"))
    trim = pipeline.trim_of(setup)
    linear = pipeline.linear_of(setup, trim)
    des = pipeline.design_of(setup, pipeline.decoupled_of(setup, linear), linear)
    return setup, pipeline.loop_of(setup, linear, des)


@pytest.mark.parametrize("kind, closed_form", [
    ("minimum-jerk", lambda s: 10 * s**3 - 15 * s**4 + 6 * s**5),
    ("minimum-snap", lambda s: 35 * s**4 - 84 * s**5 + 70 * s**6 - 20 * s**7),
])
def test_rest_to_rest_legs_are_the_closed_forms(kind, closed_form):
    start, target = np.array([0.5, -1.0, -1.0]), np.array([3.5, 3.0, -2.0])
    ref = trajectory.mission_reference([{"position": target}], start, 0.0, 1.5, 0.1, kind)
    leg = ref.legs[0]
    t = np.linspace(0.0, leg.end, 1001)
    pos = ref.flat(t).position
    tau = t / leg.end
    expected = start + np.outer(closed_form(tau), target - start)
    assert np.abs(pos[0] - expected).max() < 1e-12
    # the peak speed is the configured speed, at mid-leg
    assert np.linalg.norm(pos[1], axis=1).max() == pytest.approx(1.5, rel=1e-12)
    # rest to rest: velocity, acceleration (and for the septic jerk) vanish at both ends
    ends = ref.flat([0.0, leg.end]).position
    assert np.abs(ends[1:3 if kind == "minimum-jerk" else 4]).max() < 1e-12


def test_feedforward_is_the_trim_at_constant_velocity_and_consistent_along_a_path():
    from quadctl.physics.flatness import feedforward

    vehicle = Vehicle()
    ref = trajectory.setpoint_reference([{"t": 1.0, "velocity": [1.0, 0.5, -0.2], "yaw": 0.3}],
                                        [0, 0, -1], [0, 0, 0], 0.0)
    x, u = feedforward(ref.flat([2.0]), vehicle.vector())
    trim = solve_trim([1.0, 0.5, -0.2], 0.3, [0, 0, 0], vehicle)
    assert np.abs(x[0, 3:] - trim.x[3:]).max() < 1e-10 and np.abs(u[0] - trim.u).max() < 1e-10
    # along a minimum-snap mission, f(x_ref, u_ref) is d x_ref / dt (central differences)
    path = trajectory.mission_reference([{"position": [2, 1, -1.5], "yaw": 0.5}], [0, 0, -1], 0.0, 2.0, 0.1,
                                        "minimum-snap")
    t, h = np.linspace(0.05, path.end - 0.05, 40), 1e-5
    x, u = feedforward(path.flat(t), vehicle.vector())
    ahead, behind = (feedforward(path.flat(t + k * h), vehicle.vector())[0] for k in (1, -1))
    slope = (ahead - behind) / (2 * h)
    f = np.asarray(build_model().f.map(len(t))(x.T, u.T, vehicle.vector())).T
    assert np.abs(f).max() > 0.1 and np.abs(slope - f).max() < 1e-7


def test_a_position_step_settles_as_its_slowest_pole_predicts():
    setup = setup_of(config.load(HOVER_HOLD))
    trim = pipeline.trim_of(setup)
    linear = pipeline.linear_of(setup, trim)
    loop = pipeline.loop_of(setup, linear, pipeline.design_of(setup, pipeline.decoupled_of(setup, linear), linear))
    path = trajectory.setpoint_reference([{"t": 0.0, "position": [1.0, 0.0, -1.0]}], trim.x[:3], [0, 0, 0], 0.0)
    slowest = loop.eigenvalues[np.argmax(loop.eigenvalues.real)]
    sigma, zeta = -slowest.real, -slowest.real / abs(slowest)
    # a dominant pair's step error stays under its envelope exp(-sigma t) / sqrt(1 - zeta^2): 2 % at
    predicted = np.log(1 / (0.02 * np.sqrt(1 - zeta**2))) / sigma
    assert abs(slowest.imag) > 0 and 2.0 < predicted < 3.0
    sim = simulate(loop, loop.x_trim, 1.5 * predicted, reference=FlownReference(path, setup.vehicle.vector()))
    err = np.abs(sim.x[:, 0] - 1.0)
    outside = sim.t[err > 0.02]
    assert sim.status == "ok" and err[0] == pytest.approx(1.0)
    assert outside.max() < predicted, (outside.max(), predicted)


@pytest.fixture(scope="module")
def square_run(square):
    """The configured run of the square mission."""
    setup, loop = square
    return pipeline.simulation_of(setup, loop)


def test_the_square_mission_passes_every_waypoint_in_order_and_holds_the_last(square, square_run):
    setup, loop = square
    sim = square_run
    summary = run_summary.tracking_summary(setup, sim)
    reached = [w["reached"] for w in summary["waypoints"]]
    assert sim.status == "ok" and summary["all_reached"] and len(reached) == 4
    assert all(a < b for a, b in zip(reached, reached[1:]))
    last = np.array(setup.reference.legs[-1].position)
    after = sim.t >= reached[-1]
    assert np.linalg.norm(sim.x[after, :3] - last, axis=1).max() <= setup.reference.tolerance
    assert np.abs(sim.x[-1, 3:6]).max() < 1e-3  # at rest on the last waypoint


@pytest.mark.parametrize("reached, said", [
    ([1.785, 5.497, 8.409, 12.12], "4 of 4 reached within 0.05 m, at 1.785 s, 5.497 s, 8.409 s, 12.120 s"),
    ([1.785, None, 8.409, None], "2 of 4 reached within 0.05 m: waypoints[0] at 1.785 s, waypoints[2] at 8.409 s"),
    ([None] * 4, "none of 4 reached within 0.05 m"),
])
def test_the_waypoints_line_names_the_times_of_those_reached(reached, said):
    tracking = {"position_error": {"rms": 0.01, "peak": 0.1, "final": 0.0}, "tolerance": 0.05,
                "mission_end": 12.75, "waypoints": [{"position": [0.0, 0.0, -1.0], "reached": r} for r in reached]}
    assert mission.tracking_lines(tracking)[0] == f"waypoints: {said} (mission ends at 12.75 s)"


def test_a_mission_flown_outside_a_tight_tolerance_reaches_none(square, square_run):
    setup, _ = square
    ref = replace(setup.reference, tolerance=1e-9)
    tracking = run_summary.tracking_of(ref, square_run.t, square_run.x, square_run.x_ref)
    assert mission.tracking_lines(tracking)[0].startswith("waypoints: none of 4 reached within 1e-09 m (mission ")
    tracking.update(run_summary.mission_check(tracking, duration=setup.duration))
    said = mission_text(tracking)
    assert said.startswith("simulation.reference.waypoints[0] [") and "loosen simulation.reference.tolerance" in said
    assert "lengthen" not in said  # the run outlasts the mission: its length is not the cause


def test_the_feedforward_tracks_a_flat_reference_to_the_tabulation_error(square):
    """From x_ref(0), no noise: the feedback sees only the error of tabulating the reference on the
    5 ms exogenous clock (it shrinks with the clock); a moving setpoint alone (position and velocity,
    the trim's attitude and input: no feedforward) lags by centimetres."""
    from quadctl.layout import STATE_INDEX

    setup, loop = square
    flown = setup.flown_reference
    attitude = [STATE_INDEX[s] for s in ("phi", "theta", "p", "q", "r")]

    class SetpointOnly(FlownReference):
        @classmethod
        def rows_of(cls, references, js, periods):  # every reference row is tabulated here
            out = super().rows_of(references, js, periods)
            for rows in out:
                for half in (0, ROW_HALF):  # each of a row's two expansions
                    for block in range(3):  # x_ref, its rate and curvature: the trim's attitude and rates
                        rows[:, [half + 1 + block * 12 + i for i in attitude]] = (0.0 if block
                                                                                  else loop.x_trim[attitude])
                    rows[:, half + ROW_HALF - 8:half + ROW_HALF] = np.r_[loop.u_trim, np.zeros(4)]
            return out

    def peak(ref):
        sim = simulate(loop, flown.exact([0.0])[0][0], setup.duration, reference=ref)
        return np.linalg.norm(sim.x[:, :3] - sim.x_ref[:, :3], axis=1).max()

    with_ff, without = peak(flown), peak(SetpointOnly(flown.path, flown.params))
    assert with_ff < 5e-5 and without > 0.02 and with_ff < 1e-3 * without, (with_ff, without)


def _derivative_bounds(flown, t_end, knots, h):
    """(12,), (4,): the largest third derivative of the exact reference state and second of its input
    on ``[0, t_end]``, from finite differences of :meth:`FlownReference.exact` on steps of ``h`` (s),
    over the stencils no knot cuts (each smooth piece on its own)."""
    grid = np.arange(0.0, t_end + h, h)
    x, u = flown.exact(grid)
    out = []
    for v, order in ((x, 3), (u, 2)):
        cut = np.array([((knots > a) & (knots < b)).any() for a, b in zip(grid[:-order], grid[order:])])
        out.append(np.abs(np.diff(v, n=order, axis=0)[~cut]).max(axis=0) / h ** order)
    return out


def test_the_tabulated_reference_is_the_trajectory_to_the_row_taylor_remainder_across_leg_ends(square):
    """The rows the loop reads, evaluated on a fine grid and just either side of every knot (a leg's
    start and end, where the snap and so the torques step), against the flatness map of the
    trajectory itself: within the remainder of each row's expansion over a row spacing ``h`` (the
    exogenous period), ``5/12 h^3 max |x^(3)|`` for the state's quadratic (value and slope at the row's
    start, slope carried to its end) and ``h^2 / 8 max |u^(2)|`` for the input's chord, the derivatives
    bounded by finite differences of the trajectory within each smooth piece."""
    from quadctl.sim.exogenous import ExoStream

    setup, loop = square
    flown = setup.flown_reference
    h = ExoStream(None, None, loop.rate or setup.timing.rate).period
    knots = flown.path.knots
    assert len(knots) >= 7 and np.any(np.abs(knots / h - np.round(knots / h)) > 1e-3)  # leg ends off the grid
    near = np.concatenate([knots + d for d in (-1e-7, 1e-7, 1e-4, 0.3 * h, 0.7 * h)])
    t = np.sort(np.concatenate([np.linspace(0.0, setup.duration, 6007), near[near < setup.duration]]))
    rows = flown.rows(np.floor(t / h + 1e-9).astype(np.int64), h)
    x, u = flown.flown(rows, t)
    x_exact, u_exact = flown.exact(t)
    third, second = _derivative_bounds(flown, setup.duration, knots, h / 16)
    scale = np.abs(np.hstack([x_exact, u_exact])).max(axis=0)
    allowed = 2 * np.r_[5 / 12 * h ** 3 * third, h ** 2 / 8 * second] + 1e-9 * scale  # 2: the bounds' own error
    error = np.abs(np.hstack([x - x_exact, u - u_exact]))
    worst = np.argmax((error / allowed).max(axis=1))
    assert (error <= allowed).all(), (t[worst], np.max(error / allowed), error[worst], allowed)


def test_the_square_missions_peak_roll_torque_is_its_feedforwards(square, square_run):
    """Flown from the reference's start, the loop adds to the feedforward only what the tabulation and
    the decoupled design leave: the commanded roll torque stays of the order of the feedforward's
    largest (the trajectory's own, from the flatness map), with no kick where a leg ends."""
    setup, _ = square
    grid = np.linspace(0.0, setup.duration, 30001)
    feedforward = np.abs(setup.flown_reference.exact(grid)[1][:, 1]).max()
    peak = np.abs(square_run.u[:, 1]).max()
    assert peak < 1.5 * feedforward, (peak, feedforward)


def _brute_approach(t, x, leg_start, after, waypoint, tolerance):
    """(reached, closest, closest_at) sample by sample, in plain Python: the span from the leg's start
    and not before ``after``."""
    reached, best = None, (math.inf, None)
    for ti, p in zip(t, x[:, :3]):
        if ti < leg_start or ti < after:
            continue
        d = math.dist(p, waypoint)
        if reached is None and d <= tolerance:
            reached = float(ti)
        best = min(best, (d, float(ti)), key=lambda b: b[0])
    return reached, *(best if best[1] is not None else (None, None))


@pytest.mark.parametrize("duration, tolerance", [(15.0, 0.05), (6.0, 0.05), (15.0, 1e-9), (15.0, 1.0)])
def test_each_waypoints_reach_and_closest_approach_are_the_samples(square, square_run, duration, tolerance):
    """Against a sample-by-sample reading of the run: the first time within the tolerance and the
    least distance over the same span; a leg the run never began has neither (the 6 s cut)."""
    setup, _ = square
    keep = square_run.t <= duration
    t, x = square_run.t[keep], square_run.x[keep]
    ref = replace(setup.reference, tolerance=tolerance)
    got = trajectory.waypoint_approaches(ref, t, x[:, :3])
    after = -math.inf
    for leg, a in zip(ref.legs, got):
        expected = _brute_approach(t, x, leg.start, after, leg.position, tolerance)
        for value, want in zip((a.reached, a.closest, a.closest_at), expected):
            assert value == want or math.isclose(value, want, rel_tol=1e-12, abs_tol=1e-15), (leg, value, want)
        if a.reached is not None:
            assert a.closest <= tolerance and a.closest_at >= leg.start
            after = a.reached
        elif a.closest is not None:
            assert a.closest > tolerance
    if duration == 6.0:  # the third leg starts at 6.6 s: not flown, nor the fourth
        assert [a.closest for a in got[2:]] == [None, None]
    if tolerance == 0.05 and duration == 15.0:  # the last waypoint is held: closest at most the final error
        assert got[-1].closest <= np.linalg.norm(x[-1, :3] - ref.legs[-1].position)


def test_the_waypoint_table_says_where_when_and_how_close():
    wps = [{"position": [2.0, 0.0, -1.0], "yaw": 0.0, "leg_end": 2.188, "reached": 1.785, "closest": 4.65e-8,
            "closest_at": 2.174},
           {"position": [2.0, 2.0, -1.5], "yaw": 1.5708, "leg_end": 6.124, "reached": None, "closest": 0.31,
            "closest_at": 6.0},
           {"position": [0.0, 2.0, -1.5], "yaw": 1.5708, "leg_end": 8.811, "reached": None, "closest": None,
            "closest_at": None}]
    tracking = {"position_error": {"rms": 0.0123, "peak": 0.31, "final": 0.3}, "tolerance": 0.05,
                "mission_end": 8.811, "waypoints": wps}
    table = mission.waypoints_table(tracking)
    assert table.title == "Waypoints, reached within 0.05 m (simulation.reference.tolerance)"
    assert table.columns == ("waypoint", "position N, E, D (m)", "yaw (rad)", "reference arrives (s)",
                             "reached at (s)", "closest approach (m)")
    assert table.rows == (
        ("waypoints[0]", "2, 0, -1", "0 (0 deg)", "2.188", "1.785", "4.65e-08 at 2.174 s"),
        ("waypoints[1]", "2, 2, -1.5", "1.571 (90 deg)", "6.124", "never", "0.31 at 6 s"),
        ("waypoints[2]", "0, 2, -1.5", "1.571 (90 deg)", "8.811", "never", "leg not flown"))
    assert [r[4].kind for r in table.rows] == ["ok", "fail", "fail"]
    assert mission.tracking_lines(tracking) == [
        "waypoints: 1 of 3 reached within 0.05 m: waypoints[0] at 1.785 s (mission ends at 8.811 s)",
        "tracking error |p - p_ref|: rms 0.0123 m, peak 0.31 m, final 0.3 m"]
    assert mission.tracking_lines(tracking)[0].kind == "fail"
    setpoints = {"position_error": tracking["position_error"]}
    assert mission.waypoints_table(setpoints) is None and len(mission.tracking_lines(setpoints)) == 1


@pytest.mark.parametrize("reached", [(1.785, 5.497, 8.409, 12.12), (1.785, None, 8.409, None), None])
def test_the_path_figure_marks_each_waypoint_reached_or_missed(square, square_run, reached):
    from quadctl import plots

    setup, _ = square
    positions = [leg.position for leg in setup.reference.legs]
    fig = plots.path_figure(square_run, positions, reached=reached, tolerance=0.05, title="square")
    plane, altitude = fig.axes
    marked = [(line.get_marker(), float(line.get_xdata()[0]), float(line.get_ydata()[0]))
              for line in plane.lines if line.get_marker() in ("s", "X")]
    expected = ["s" if reached is None or r is not None else "X" for r in (reached or [None] * 4)]
    assert marked == [(m, p[1], p[0]) for m, p in zip(expected, positions)]  # east right, north up
    assert [a.get_text() for a in plane.texts] == ["0", "1", "2", "3"]
    when = [(float(line.get_xdata()[0]), float(line.get_ydata()[0])) for line in altitude.lines
            if line.get_marker() == "s"]
    assert when == [(r, -p[2]) for r, p in zip(reached or (), positions) if r is not None]
    labels = plane.get_legend_handles_labels()[1]
    assert ("reached within 0.05 m" in labels) == (reached is not None)
    assert ("missed" in labels) == (reached is not None and None in reached)
    count = "" if reached is None else f", {sum(r is not None for r in reached)} of 4 waypoints reached"
    assert fig._suptitle.get_text() == f"square: path{count}"


def test_a_flown_reference_has_its_path_and_error_figures(square_run):
    from quadctl import plots

    figs = plots.simulation_figures(square_run, {}, title="square")
    assert {"path", "tracking"} <= set(figs)
    plane, altitude = figs["path"].axes
    assert (plane.get_xlabel(), plane.get_ylabel(), altitude.get_ylabel()) == ("east [m]", "north [m]",
                                                                                "altitude -pD [m]")
    north = plane.lines[1].get_ydata()  # the flown path: east right, north up
    assert np.allclose(north, square_run.x[:, 0])


def _short(setup, loop):
    return FlownReference(trajectory.mission_reference([{"position": [1.0, 0.5, -1.2], "yaw": 0.4}],
                                                       loop.x_trim[:3], 0.0, 2.0, 0.05, "minimum-jerk"),
                          setup.vehicle.vector())


def test_a_rows_second_expansion_is_in_force_from_its_split_on():
    """in_force (and driver.c's qc_after, its rule in C, which the compiled-against-interpreted test below
    holds to it): a row split at t_b gives its first expansion before t_b and its second from t_b on (a
    time within round-off of t_b counts as on it); a row with no split (its second a copy of the first)
    gives its first throughout. The loop reads the one in force at t, then the one over the step."""
    from quadctl.sim.loop_layout import N_REFERENCE

    assert N_REFERENCE == 2 * ROW_HALF  # the loop's columns are the table's two expansions
    t_j, t_b = 0.005, 0.0075
    split = np.r_[t_j, np.full(ROW_HALF - 1, 1.0), t_b, np.full(ROW_HALF - 1, 2.0)]
    whole = np.r_[t_j, np.full(ROW_HALF - 1, 1.0), t_j, np.full(ROW_HALF - 1, 1.0)]
    t = np.array([t_j, t_b - 1e-6, t_b - 0.5 * SPLIT_ROUNDOFF * t_b, t_b, t_b + 1e-6, 0.0099])
    got = in_force(np.tile(split, (len(t), 1)), t)
    second = got[:, 1:ROW_HALF].mean(axis=1) == 2.0
    assert second.tolist() == [False, False, True, True, True, True]
    assert np.array_equal(got[:, :ROW_HALF], got[:, ROW_HALF:])  # over defaults to at
    at, over = np.array([0.006, 0.006]), np.array([0.007, 0.008])  # steps whose midpoints are before, after t_b
    got = in_force(np.tile(split, (2, 1)), at, over)
    assert got[:, 1].tolist() == [1.0, 1.0] and got[:, ROW_HALF + 1].tolist() == [1.0, 2.0]
    assert got[1, ROW_HALF] == t_b  # the step's expansion is anchored at the split
    rows = np.tile(whole, (len(t), 1))
    assert np.array_equal(in_force(rows, t)[:, :ROW_HALF], rows[:, :ROW_HALF])


@pytest.mark.compiler
def test_compiled_and_interpreted_loops_fly_a_reference_alike(square, monkeypatch):

    setup, loop = square
    ref = _short(setup, loop)
    x0 = loop.x_trim + 0.05
    compiled = simulate(loop, x0, 1.5, reference=ref)
    interpreted = without_compiler(monkeypatch, lambda: simulate(loop, x0, 1.5, reference=ref))
    assert compiled.backend == "compiled" and interpreted.backend == "casadi"
    assert np.ptp(compiled.x_ref[:, 0]) > 0.5
    diff = max(np.abs(compiled.x - interpreted.x).max(), np.abs(compiled.u - interpreted.u).max())
    assert diff < 1e-12, diff


@pytest.mark.compiler
def test_lanes_equal_the_one_case_loop_with_a_reference(square):
    from quadctl.sim import engine
    from quadctl.sim.cases import Cases
    from quadctl.sim.exogenous import ExoStream
    from quadctl.sim.plan import record_stride

    setup, loop = square
    ref = _short(setup, loop)
    variants = [(replace(loop, K=loop.K * (1 + 0.1 * k)), 1.5 - 0.1 * k) for k in range(3)]
    run = engine.runner(loop.spec(reference=True), engine.LANES)
    assert run.backend == "compiled-simd"
    jobs = []
    for vk, dur in variants:
        plan = vk.plan(dur)
        stream = ExoStream(None, None, None, ref)
        first, rows = stream.rows(0, plan.n_steps, plan.dt)
        jobs.append((plan, vk.constants(), vk.initial_loop_state(vk.x_trim), *vk.bounds(dur, ref), rows, first,
                     stream.period))
    cases = Cases.of(np.stack([j[2] for j in jobs]), np.stack([j[1] for j in jobs]), [j[0].dt for j in jobs],
                     [j[0].n_steps for j in jobs], [record_stride(j[0].n_steps, setup.max_samples) for j in jobs],
                     np.stack([j[3] for j in jobs]), np.stack([j[4] for j in jobs]), exo=[j[5] for j in jobs],
                     exo_first=[j[6] for j in jobs], exo_period=[j[7] for j in jobs])
    worst = 0.0
    for (vk, dur), (done, _, xs, us) in zip(variants, run.run(cases)):
        one = simulate(vk, vk.x_trim, dur, reference=ref, max_samples=setup.max_samples)
        assert done == one.steps
        worst = max(worst, np.abs(xs[:, :12] - one.x).max(), np.abs(us - one.u).max())
    assert worst < 1e-12, worst


BAD = [
    ("setpoints: [{t: 2.0, yaw: 0.5}, {t: 1.0, yaw: 0.0}]",
     r"simulation\.reference\.setpoints\[1\]\.t = 1.*list setpoints in increasing t"),
    ("{waypoints: [{position: [1, 0, -1], hold: -1}]}",
     r"simulation\.reference\.waypoints\[0\]\.hold = -1: must be at least 0"),
    ("{speed: 0, waypoints: [{position: [1, 0, -1]}]}",
     r"simulation\.reference\.speed = 0: must be greater than 0"),
    ("{waypoints: [{position: [1, 0, -1]}], setpoints: [{t: 0, yaw: 1}]}",
     r"simulation\.reference = \"both\": give either setpoints \(steps at times t\) or waypoints"),
    ("{waypoints: []}", r"simulation\.reference\.waypoints = \[\]: empty; list at least one"),
    ("{setpoints: [{t: 0}]}", r"simulation\.reference\.setpoints\[0\].*sets nothing"),
]


@pytest.mark.parametrize("block, message", BAD)
def test_bad_references_name_the_key(block, message):
    text = HOVER_HOLD.read_text()
    if block.startswith("setpoints"):
        block = "{" + block + "}"
    with pytest.raises(ConfigError, match=message):
        config.parse(text + f"  reference: {block}\n", "c.yaml")


def test_etdrk4_flies_a_reference():
    """The config takes ``simulation.method: etdrk4`` with a reference (tests/sim/test_exponential_integrator.py
    holds its agreement with RK4)."""
    data = config.load("square").model_dump(mode="json")
    data["simulation"]["method"] = "etdrk4"
    assert config.from_dict(data, "square.yaml").simulation.method == "etdrk4"


def _linear_and_design(setup):
    trim = pipeline.trim_of(setup)
    linear = pipeline.linear_of(setup, trim)
    return linear, pipeline.design_of(setup, pipeline.decoupled_of(setup, linear), linear)


@pytest.mark.parametrize("setpoints,key", [
    ("[{t: 1, velocity: [0, 600, 0]}]", "simulation.reference.setpoints[0].velocity"),
    ("[{t: 0.5, yaw: 0.1}, {t: 1, velocity: [0, 600, 0]}]", "simulation.reference.setpoints[1].velocity"),
    ("[{t: 1, velocity: [600, 0, 0]}, {t: 1.5, yaw: 0.1}]", "simulation.reference.setpoints[0].velocity"),
    ("[{t: 0.5, velocity: [0, 0, 1]}, {t: 1, velocity: [0, 600, 0]}, {t: 2, position: [0, 0, -1]}]",
     "simulation.reference.setpoints[1].velocity"),
])
def test_a_setpoint_velocity_no_attitude_holds_is_refused_naming_that_setpoint(setpoints, key):
    """A mission's fix (its speed) is no fix for setpoints, which have none: the refusal names the setpoint
    whose velocity is flown when the force balance fails."""
    cfg = config.parse(HOVER_HOLD.read_text() + f"  reference: {{setpoints: {setpoints}}}\n", "c.yaml")
    flown = FlownReference(setup_of(cfg).reference, setup_of(cfg).vehicle.vector())
    refusal = r"^simulation\.reference: at t = .* beyond the 80 deg of roll or pitch the Euler-angle model supports; "
    with pytest.raises(Exception, match=refusal + "lower " + re.escape(key) + ": no attitude holds that velocity "
                                        r"against the rotor drag$") as err:
        flown.exact(np.linspace(0.0, 3.0, 31))
    assert "simulation.reference.speed" not in str(err.value)


@pytest.mark.parametrize("t,key", [(0.0, "trim.velocity_ned"), (0.99, "trim.velocity_ned"),
                                   (1.0, "simulation.reference.setpoints[0].velocity"),
                                   (2.5, "simulation.reference.setpoints[0].velocity"),
                                   (3.0, "simulation.reference.setpoints[2].velocity")])
def test_each_time_is_flown_with_the_velocity_of_the_last_setpoint_that_gave_one(t, key):
    ref = trajectory.setpoint_reference([{"t": 1.0, "velocity": [1, 0, 0]}, {"t": 2.0, "yaw": 0.3},
                                         {"t": 3.0, "velocity": [0, 0, 0]}], [0, 0, -1], [0, 0, 0], 0.0)
    assert ref.remedy(t).startswith(f"lower {key}: ")
    mission = trajectory.mission_reference([{"position": [1, 0, -1]}], [0, 0, -1], 0.0, 1.0, 0.1)
    assert mission.remedy(t) == "lower simulation.reference.speed or space the waypoints further apart"
