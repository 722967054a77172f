"""Rotor mixing, saturation, and the bundled mambo-200hz design against the Mambo's motor limits."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from _solve import cfg_dict, run

from quadctl import config, pipeline, run_summary
from quadctl.errors import ConfigError, SaturationFailed
from quadctl.layout import INPUT_INDEX
from quadctl.physics import motors
from quadctl.setup import setup_of

MAMBO = motors.Motors()
MG = 0.068 * 9.81


@pytest.mark.parametrize("layout", ["x", "+"])
def test_mixing_round_trip(layout):
    m = motors.Motors(layout=layout)
    np.testing.assert_allclose(m.mixer() @ m.effectiveness(), np.eye(4), atol=1e-12)
    u = np.array([[0.7, 0.01, -0.02, 0.001], [MG, 0.0, 0.0, 0.0], [0.2, -0.005, 0.003, -0.0004]])
    f = u @ m.mixer().T
    np.testing.assert_allclose(f @ m.effectiveness().T, u, rtol=1e-12, atol=1e-15)


def test_x_layout_signs_and_the_mambo_torque_authority():
    """Hover splits m g evenly; +A (right wing down) loads the left rotors, +E (nose up) the front
    ones, +R (nose right) the counter-clockwise ones (1, 3); the Mambo reaches ~0.03 N m of roll."""
    mix = MAMBO.mixer()
    np.testing.assert_allclose(mix @ [MG, 0, 0, 0], [MG / 4] * 4, rtol=1e-12)
    d = 0.0624 / math.sqrt(2)
    roll = mix @ [0, 1e-3, 0, 0]
    np.testing.assert_allclose(roll, np.array([-1, -1, 1, 1]) * 1e-3 / (4 * d), rtol=1e-12)
    pitch = mix @ [0, 0, 1e-3, 0]
    np.testing.assert_allclose(pitch, np.array([1, -1, -1, 1]) * 1e-3 / (4 * d), rtol=1e-12)
    yaw = mix @ [0, 0, 0, 1e-3]
    np.testing.assert_allclose(yaw, np.array([1, -1, 1, -1]) * 1e-3 / (4 * 0.00241), rtol=1e-12)
    act = motors.actuators_of(MAMBO)
    room = motors.headroom(act, [MG, 0, 0, 0])
    # two rotors to the limit, two to zero around hover: 4 d (0.33 - m g / 4)
    assert room["A"][1] == pytest.approx(4 * d * (0.33 - MG / 4), rel=1e-12)
    assert 0.025 < room["A"][1] < 0.03 and room["R"][1] < 2e-3


@pytest.mark.parametrize("rotors", [MAMBO, motors.Motors(layout="+"),
                                    motors.Motors(xy=((0.05, 0.08), (-0.06, 0.07), (-0.06, -0.07), (0.05, -0.08)))])
@pytest.mark.parametrize("u_trim", [[MG, 0.0, 0.0, 0.0], [0.5, 0.004, -0.003, 3e-4], [0.9, -0.006, 0.002, -5e-4]])
def test_the_headroom_takes_each_input_to_the_first_rotor_limit_each_way(rotors, u_trim):
    """headroom's (down, up) of an input: moved that far from the trim (the others held), every rotor is
    within [min_thrust, max_thrust] and one is on a limit, so a step past it leaves them. The rotors'
    thrusts are the mixer's, each way on its own (the rotors of a trim with torques are not alike)."""
    act = motors.actuators_of(rotors)
    base = act.commands(u_trim)
    assert np.all((act.lo <= base) & (base <= act.hi))
    tol = 1e-12 * act.hi.max()  # round-off of a thrust of at most max_thrust
    for name, (down, up) in motors.headroom(act, u_trim).items():
        for sign, room in ((-1.0, down), (1.0, up)):
            moved = np.asarray(u_trim, dtype=float).copy()
            moved[INPUT_INDEX[name]] += sign * room
            thrust = act.commands(moved)
            assert np.all((act.lo - tol <= thrust) & (thrust <= act.hi + tol)), (name, sign, thrust)
            assert np.min(np.minimum(thrust - act.lo, act.hi - thrust)) <= tol, (name, sign, thrust)


def test_plus_layout_rolls_with_the_side_rotors_only():
    roll = motors.Motors(layout="+").mixer() @ [0, 1e-3, 0, 0]
    assert roll[0] == pytest.approx(0, abs=1e-15) and roll[2] == pytest.approx(0, abs=1e-15)
    assert roll[1] < 0 < roll[3]


def test_a_trim_the_rotors_cannot_hold_is_refused():
    """Hover needs m g / 4 = 0.068 * 9.81 / 4 = 0.1668 N per rotor, above max_thrust = 0.1 N."""
    data = cfg_dict("hover", motors={"max_thrust": 0.1})
    setup = setup_of(config.from_dict(data))
    linear = pipeline.linear_of(setup, pipeline.trim_of(setup))
    with pytest.raises(ConfigError, match=r"motors.max_thrust = 0.1: the trim needs rotor 1 = 0.1668 N, outside "
                                          r"the limits \[0, 0.1\] N, .*; raise motors.max_thrust above 0.1668 N, "
                                          r"or trim for a slower or lighter flight$"):
        pipeline.closed_loop_of(setup, linear, np.zeros((4, 12)))


@pytest.mark.parametrize("section,key,line", [
    ("motors: {max_thrust: 0.1}\nallow: [implausible]", "motors.max_thrust = 0.1",  # a warned thrust-to-weight of 0.6
     "rotor 1 = 0.1668 N, outside the limits [0, 0.1] N, so the vehicle cannot hold this flight condition; "
     "raise motors.max_thrust above 0.1668 N, or trim for a slower or lighter flight"),
    ("limits: {T: [0, 0.5]}", "limits.T = [0, 0.5]",
     "T = 0.6671 N, outside the limits [0, 0.5] N, so the vehicle cannot hold this flight condition; "
     "widen limits.T to include 0.6671 N, or trim for a slower or lighter flight"),
], ids=["rotors", "box limits"])
def test_a_trim_outside_the_limits_names_the_file_key_value_and_fix(tmp_path, section, key, line):
    """The error comes from the simulate stage (numbers only): the command line puts the file in front, as
    it does for the other stage errors, and the sentence ends with the fix (it ended with "change trim:")."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    text = config.locate("hover").text.replace("simulation:", section + "\nsimulation:")
    (tmp_path / "c.yaml").write_text(text)
    res = CliRunner().invoke(app, ["run", "-c", str(tmp_path / "c.yaml"), "-o", str(tmp_path / "out")])
    assert res.exit_code == 2, res.output
    assert f"quadctl: error: {tmp_path / 'c.yaml'}: {key}: the trim needs {line}\n" in res.stderr


def test_box_limits_clip_the_inputs_and_are_reported():
    data = cfg_dict("forward", limits={"A": [-0.05, 0.05], "E": [-0.05, 0.05], "R": [-0.05, 0.05]})
    data["simulation"]["duration"] = 2.0
    cfg, _, loop, sim = run(data)
    assert sim.status == "ok"
    for name in "AER":
        assert np.abs(sim.u[:, INPUT_INDEX[name]]).max() <= 0.05 + 1e-15
    fractions = motors.saturation_fraction(loop.actuators, sim.u)
    assert fractions["T"] == 0.0 and fractions["R"] > 0.0  # the report's yaw gain asks for 1.4 N m


@pytest.mark.parametrize("mode, fractions, way_out", [
    ("motors", {"rotor 1": 0.2, "rotor 2": 0.9, "rotor 3": 0.0, "rotor 4": 0.0},
     "give the rotors the thrust they really have (motors.max_thrust)"),
    ("box", {"T": 0.0, "A": 0.3, "E": 0.0, "R": 1.0}, "give R the range the vehicle really has (limits.R)"),
])
def test_a_design_at_its_limits_most_of_the_run_is_told_the_key_of_those_limits(mode, fractions, way_out):
    worst = max(fractions, key=fractions.get)
    with pytest.raises(SaturationFailed, match=rf"^the design saturates: {worst} is at a limit .* initial offset, "
                                               rf"or {re.escape(way_out)}; --allow-saturation"):
        motors.require_within_limits(fractions, mode)
    motors.require_within_limits(fractions, mode, allowed=True)  # accepted: no failure
    motors.require_within_limits({k: min(v, 0.5) for k, v in fractions.items()}, mode)  # half the run: within


def test_the_reports_design_saturates_the_mambo_rotors_and_is_flagged():
    data = cfg_dict("forward", controller={"rate": 200.0}, motors={})
    setup, _, loop, sim = run(data)
    summary = run_summary.flight_summary(setup, loop, sim)
    sat = summary["saturation"]
    assert sat["saturates"] and max(sat["fraction"].values()) > motors.SATURATION_FLAG
    assert max(sat["peak_command"].values()) == pytest.approx(0.33, rel=1e-9)  # clipped at the limit


def test_mambo_200hz_stays_within_its_motor_limits():
    """The bundled realistic design: no rotor reaches a limit, torques far inside the authority."""
    data = cfg_dict("mambo-200hz")
    cfg, des, loop, sim = run(data)
    assert sim.status == "ok" and des.rate == 200.0 and sim.plan.hold == 5
    f = loop.actuators.commands(sim.u)
    assert f.min() > 0.05 and f.max() < 0.33 * 0.97, (f.min(), f.max())
    assert all(v == 0.0 for v in motors.saturation_fraction(loop.actuators, sim.u).values())
    peak = np.abs(sim.u - loop.u_trim).max(axis=0)
    room = motors.headroom(loop.actuators, loop.u_trim)
    for name in "AER":
        assert peak[INPUT_INDEX[name]] < 0.5 * min(room[name]), name
    # and it regulates: attitude errors settle to the noise floor
    err = sim.x - sim.x_ref
    late = sim.t > 8.0
    assert np.abs(err[late][:, [6, 7]]).max() < 0.01  # phi, theta within ~0.6 deg
