"""The control law flies any heading: the horizontal position error taken in the reference's heading
frame and the yaw error wrapped, so a design made at the trim's yaw holds at every yaw. Checked
against the model's symmetry (a mission turned about the vertical flies the turned trajectory),
against the law written out in NumPy, and on every runner."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from _solve import cfg_dict, max_rel_diff, run, solve, without_compiler

from quadctl import pipeline, run_summary, sweep
from quadctl.layout import N_STATES, STATE_INDEX
from quadctl.physics import trajectory
from quadctl.physics.reference_rows import FlownReference
from quadctl.sim.builder import heading_frame, wrap_angle
from quadctl.sim.run import simulate

PN, PE, PSI = STATE_INDEX["pN"], STATE_INDEX["pE"], STATE_INDEX["psi"]
TURN_TOL = 1e-9
"""m (and rad): a mission turned about the vertical against the mission, turned back. The runs differ
only by the round-off of the rotation (1e-16 relative) carried through a stable loop over a few
thousand steps, ~1e-13 measured; 1e-9 leaves margin for any CPU's sin and cos."""


def _turn(vectors, angle: float, about=(0.0, 0.0)):
    """``vectors`` (..., >= 2): their first two entries (north, east) turned by ``angle`` about ``about``."""
    out = np.array(vectors, dtype=float, copy=True)
    c, s = math.cos(angle), math.sin(angle)
    n, e = out[..., 0] - about[0], out[..., 1] - about[1]
    out[..., 0], out[..., 1] = about[0] + c * n - s * e, about[1] + s * n + c * e
    return out


@pytest.fixture(scope="module")
def square():
    """(setup, loop) of the bundled square mission (the hover-hold design, made at yaw 0)."""
    setup, _, linear, _, des = solve(cfg_dict("square"))
    return setup, pipeline.loop_of(setup, linear, des)


# ---------------------------------------------------------------------------------------------
# the frame itself


@pytest.mark.parametrize("angle, wrapped", [(0.3, 0.3), (-0.3, -0.3), (math.pi, math.pi), (-math.pi, math.pi),
                                            (3.5, 3.5 - 2 * math.pi), (-3.5, 2 * math.pi - 3.5),
                                            (0.25 + 6 * math.pi, 0.25), (-0.25 - 10 * math.pi, -0.25)])
def test_a_yaw_error_is_wrapped_into_minus_pi_to_pi(angle, wrapped):
    x = ca.SX.sym("x")
    for got in (wrap_angle(angle), float(ca.Function("w", [x], [wrap_angle(x, ca)])(angle))):
        assert -math.pi < got <= math.pi and got == pytest.approx(wrapped, abs=1e-13)


def test_an_angle_inside_the_range_is_kept_bit_for_bit():
    rng = np.random.default_rng(4)
    angles = rng.uniform(-3.14, 3.14, 1000)
    assert np.array_equal(wrap_angle(angles), angles)


@pytest.mark.parametrize("offset", [0.0, 0.4, math.pi / 2, math.pi, -2.5])
def test_the_heading_frame_turns_the_position_error_by_minus_the_offset(offset):
    """An error along the reference's nose is an error along the design's nose; across it, across;
    the body velocities, attitudes and rates are left as they are (the model's symmetry)."""
    rng = np.random.default_rng(1)
    dx = rng.standard_normal(N_STATES)
    nose, side = np.array([math.cos(offset), math.sin(offset)]), np.array([-math.sin(offset), math.cos(offset)])
    dx[PN], dx[PE] = 0.7 * nose + 0.2 * side
    got = heading_frame(dx, offset, lib=np)
    np.testing.assert_allclose(got[[PN, PE]], [0.7, 0.2], rtol=0, atol=1e-15)
    others = [i for i in range(N_STATES) if i not in (PN, PE)]
    np.testing.assert_array_equal(got[others], dx[others])  # psi's ~1 rad error: inside the range, kept
    symbols = ca.SX.sym("dx", N_STATES)
    emitted = ca.Function("h", [symbols], [heading_frame(symbols, offset)])  # what the builder takes
    np.testing.assert_array_equal(np.asarray(emitted(dx)).ravel(), got)
    if offset == 0.0:
        np.testing.assert_array_equal(got, dx)


# ---------------------------------------------------------------------------------------------
# the loop: the symmetry of the model, and the law written out


def _turned_run(square, angle: float, turns: int = 0):
    """The square mission and its start turned by ``angle`` about the start, flown by the design made at
    yaw 0, from the configured start turned likewise (0.3 m off north, 0.2 m east, 0.1 rad of yaw), its
    yaw ``turns`` whole turns away from the reference's."""
    setup, loop = square
    start = np.asarray(loop.x_trim[:3])
    legs = setup.reference.legs
    waypoints = [{"position": _turn(leg.position, angle, start[:2]), "yaw": leg.yaw + angle, "hold": leg.hold}
                 for leg in legs]
    path = trajectory.mission_reference(waypoints, start, loop.x_trim[PSI] + angle, 2.0, 0.05, "minimum-snap")
    x0 = loop.x_trim.copy()
    x0[PN] += 0.3
    x0[PE] += 0.2
    x0[PSI] += 0.1
    x0 = _turn(x0, angle, start[:2])
    x0[PSI] += angle + 2 * math.pi * turns
    return simulate(loop, x0, 13.0, setup.dt, noise=None, reference=FlownReference(path, setup.vehicle.vector()))


@pytest.mark.parametrize("angle", [math.pi / 2, math.pi, -2.5, 0.7 + 2 * math.pi])
def test_a_mission_turned_about_the_vertical_flies_the_turned_trajectory(square, angle):
    """The heading is a symmetry of the vehicle: the mission turned by any angle about its start (the
    waypoints, their yaws and the start) flies the mission's trajectory turned by that angle, whatever
    the heading the design was made at."""
    setup, loop = square
    straight, turned = _turned_run(square, 0.0), _turned_run(square, angle)
    assert straight.status == turned.status == "ok" and len(straight.t) == len(turned.t)
    back = _turn(turned.x[:, :2], -angle, loop.x_trim[:2])
    position = np.abs(back - straight.x[:, :2]).max()
    assert position <= TURN_TOL, f"max |p - R(-a) p_turned| = {position:.3e} m"
    yaw = np.abs(wrap_angle(turned.x[:, PSI] - angle - straight.x[:, PSI])).max()
    body = np.abs(np.delete(turned.x - straight.x, [PN, PE, PSI], axis=1)).max()
    assert max(yaw, body) <= TURN_TOL, f"max |dpsi| = {yaw:.3e}, max |d(body states)| = {body:.3e}"
    np.testing.assert_allclose(turned.u, straight.u, rtol=0, atol=TURN_TOL)
    reached = run_summary.tracking_of(replace_legs(setup.reference, angle, loop.x_trim[:2]), turned.t, turned.x,
                                   turned.x_ref)
    assert reached["all_reached"]


@pytest.mark.parametrize("turns", [-1, 2])
def test_a_yaw_whole_turns_from_the_references_is_flown_as_the_same_heading(square, turns):
    """The yaw error is wrapped: a vehicle that starts whole turns from the reference's yaw flies as one
    at that yaw, and does not spin back."""
    same, away = _turned_run(square, math.pi), _turned_run(square, math.pi, turns)
    assert same.status == away.status == "ok"
    np.testing.assert_allclose(away.x[:, [PN, PE]], same.x[:, [PN, PE]], rtol=0, atol=TURN_TOL)
    np.testing.assert_allclose(away.x[:, PSI] - 2 * math.pi * turns, same.x[:, PSI], rtol=0, atol=TURN_TOL)
    np.testing.assert_allclose(away.u, same.u, rtol=0, atol=TURN_TOL)


def replace_legs(ref, angle: float, about):
    """``ref`` (a mission) with its waypoints turned by ``angle`` about ``about`` (for its reached times)."""
    from dataclasses import replace

    return replace(ref, legs=tuple(replace(leg, position=tuple(_turn(leg.position, angle, about)))
                                   for leg in ref.legs))


def test_the_law_is_the_gain_on_the_error_in_the_references_heading_frame(square):
    """The run's inputs are ``u_ref - K e`` with ``e`` the recorded ``x - x_ref`` turned by the reference's
    yaw (less the trim's) and its yaw error wrapped: the law written out in NumPy, on the square's legs
    flown at yaw pi/2 (no actuator limits: nothing clips)."""
    setup, loop = square
    sim = pipeline.simulation_of(setup, loop)
    assert sim.status == "ok" and loop.actuators is None
    offset = sim.x_ref[:, PSI] - loop.x_trim[PSI]
    assert offset.max() == pytest.approx(1.5708)  # a quarter of the mission flown turned
    expected = sim.u_ref - heading_frame(sim.x - sim.x_ref, offset, lib=np) @ loop.K.T
    scale = (np.abs(sim.u_ref) + np.abs(sim.x - sim.x_ref) @ np.abs(loop.K).T).max()
    worst = np.abs(sim.u - expected).max()
    assert worst <= 1e-12 * scale, f"max |u - (u_ref - K e)| = {worst:.3e}"
    earth = sim.u_ref - (sim.x - sim.x_ref) @ loop.K.T  # the error in the earth frame: not what flew
    assert np.abs(sim.u - earth).max() > 1e6 * worst


# ---------------------------------------------------------------------------------------------
# a fixed design holds a waypoint at any yaw, on every runner


def _hold(yaw: float) -> dict:
    """The hover-hold design told to hold (1, 0, -1) at ``yaw`` for 8 s (a 15 s run)."""
    data = cfg_dict("square")
    data["simulation"] = {**data["simulation"], "duration": 15.0,
                          "reference": {"waypoints": [{"position": [1.0, 0.0, -1.0], "yaw": yaw, "hold": 8.0}]}}
    return data


@pytest.mark.parametrize("yaw", [1.5708, 2.5, math.pi, -math.pi / 2])
def test_a_hover_hold_design_reaches_a_waypoint_at_any_yaw(yaw):
    """The design made at yaw 0 reaches and holds the waypoint at yaw pi/2 (2.54 m off, and drifting,
    with the error in the earth frame) and at pi (out of the valid range before)."""
    setup, _, loop, sim = run(_hold(yaw))
    tracking = run_summary.tracking_summary(setup, sim)
    assert sim.status == "ok" and tracking["all_reached"], sim.message
    assert tracking["position_error"]["final"] < 1e-3
    assert abs(wrap_angle(sim.x[-1, PSI] - yaw)) < 1e-3


@pytest.mark.compiler
def test_the_interpreted_runner_flies_the_turned_law_as_the_compiled_one(monkeypatch):

    data = _hold(math.pi)
    data["simulation"]["duration"] = 3.0  # s: the turn to pi and the leg (the VM is slow)
    setup, _, loop, compiled = run(data)
    interpreted = without_compiler(monkeypatch, lambda: pipeline.simulation_of(setup, loop))
    assert compiled.backend == "compiled" and interpreted.backend == "casadi"
    assert compiled.x_ref[:, PSI].max() > 1.0  # flown turned from the trim's heading
    diff = max(np.abs(compiled.x - interpreted.x).max(), np.abs(compiled.u - interpreted.u).max())
    assert diff < 1e-12, f"Max diff is {diff:.4E}"


@pytest.mark.compiler
def test_the_lanes_fly_a_waypoint_at_any_yaw_as_the_one_case_loop():
    """A sweep over the waypoint's yaw: every case reaches it, and the lanes' rows are the one-by-one path's."""
    from quadctl import config

    cfg = config.from_dict(_hold(0.0), "hold.yaml")
    spec = sweep.from_dict({"parameters": {"simulation.reference.waypoints[0].yaw": [0.0, 1.5708, 3.1416]}},
                           cfg, "yaws.yaml")
    fast = sweep.run(cfg, spec, jobs=1)
    slow = sweep.run(cfg, spec, jobs=1, fast=False)
    assert {r["path"] for r in fast.rows} == {"batched"}
    worst, where = max_rel_diff(fast.rows, slow.rows)
    assert worst < 1e-9, f"Max diff is {worst:.4E} at {where}"
    assert [r["waypoints.reached"] for r in fast.rows] == [1, 1, 1]
    assert [r["status"] for r in fast.rows] == ["ok"] * 3


def test_the_filters_estimate_is_turned_back_to_the_earth_frame():
    """An LQG loop's filter estimates the deviation in the heading frame; ``x_hat`` is turned back: on the
    square's leg flown at yaw pi/2 it is within the filter's error of ``x`` (not turned back: 6x off)."""
    data = cfg_dict("square", controller={"rate": 200, "design": "discrete"}, estimator={"measure": ["imu", "mocap"]})
    data["simulation"] = {**data["simulation"], "duration": 9.0,
                          "noise": {"seed": 3, "period": 0.002, "force": [0.005] * 3, "torque": [2e-5] * 3,
                                    "sensor": {"pN": 0.01, "pE": 0.01, "pD": 0.01, "phi": 0.002, "theta": 0.002,
                                               "psi": 0.005, "p": 0.005, "q": 0.005, "r": 0.005}}}
    setup, _, loop, sim = run(data)
    turned = sim.x_ref[:, PSI] > 1.5
    assert sim.status == "ok" and turned.sum() > 1000
    estimate = np.abs(sim.x_hat[turned][:, [PN, PE]] - sim.x[turned][:, [PN, PE]]).max()
    held = sim.x_ref + heading_frame(sim.x_hat - sim.x_ref, sim.x_ref[:, PSI], lib=np)  # the filter's own frame
    unturned = np.abs(held[turned][:, [PN, PE]] - sim.x[turned][:, [PN, PE]]).max()
    assert estimate < 0.005 and unturned > 2 * estimate, f"{estimate:.3e} m turned back, {unturned:.3e} m not"
