"""The unit slips a new vehicle's author makes, each named by the key that slipped with the right
fix, and each a failed check (exit 1) unless the config accepts it; a design at its rotor limits most
of the run fails too, unless accepted."""

from __future__ import annotations

import re

import pytest
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app
from quadctl.config import notices, overrides
from quadctl.config import template as starter
from quadctl.errors import ConfigError

runner = CliRunner()
IRIS = starter.config_text("slip", "iris", "hover")
"""A 1.5 kg, 0.2555 m arm vehicle (PX4's Iris), the F450 class: J = diag(0.029125, 0.029125, 0.055225) kg m^2,
7.0664 N per rotor."""

SLIPS = {
    "arm in mm": ("arm_length: 0.2555", "arm_length: 255.5", "motors.arm_length",
                  r"^c\.yaml: motors\.arm_length = 255\.5 m is 1\.33e\+03 times the radius of gyration sqrt\(Jzz/m\) = "
                  r"0\.192 m of vehicle\.inertia = .* and vehicle\.mass = 1\.5 kg \(a quadcopter's arm is 0\.5 to 10 "
                  r"times its radius of gyration\); is motors\.arm_length in mm\? 255\.5 mm is 0\.2555 m$"),
    "arm in cm": ("arm_length: 0.2555", "arm_length: 25.55", "motors.arm_length",
                  r"; is motors\.arm_length in cm\? 25\.55 cm is 0\.2555 m$"),
    "thrust in grams-force": ("max_thrust: 7.0664", "max_thrust: 720.6", "motors.max_thrust",
                              r"^c\.yaml: motors\.max_thrust = 720\.6 N per rotor with vehicle\.mass = 1\.5 kg is a "
                              r"thrust-to-weight ratio of 196 .*; is motors\.max_thrust in grams-force\? 720\.6 gf is "
                              r"7\.07 N$"),
    "mass in grams": ("mass: 1.5", "mass: 1500", "vehicle.mass",
                      r"^c\.yaml: vehicle\.mass = 1500 kg with .*; is vehicle\.mass in grams\? 1500 g is 1\.5 kg$"),
    "inertia in kg mm^2": ("inertia: [0.029125, 0.029125, 0.055225]", "inertia: [29125, 29125, 55225]",
                           "vehicle.inertia", r"^c\.yaml: vehicle\.inertia = \[29125, 29125, 55225\] kg m\^2 .*; is "
                           r"it in kg mm\^2\? that is \[0\.029125, 0\.029125, 0\.055225\] kg m\^2$"),
    "controller rate in kHz": ("rate: null", "rate: 0.25", "controller.rate",
                               r"^c\.yaml: controller\.rate = 0\.25 Hz is below 20 Hz, slower than any attitude loop a "
                               r"flight computer closes \(they run at 100 Hz to 8 kHz\); "
                               r"is controller\.rate in kHz\? 0\.25 kHz is 250 Hz$"),
}


def _slipped(name: str) -> str:
    old, new, _, _ = SLIPS[name]
    assert old in IRIS
    return IRIS.replace(old, new)


@pytest.mark.parametrize("name", SLIPS)
def test_each_slip_is_named_by_its_key_with_the_right_fix(name):
    _, _, key, pattern = SLIPS[name]
    found = [n for n in notices.notices(config.parse(_slipped(name), "c.yaml"), "c.yaml") if n.level == "warning"]
    assert found and {n.key for n in found} == {key}, [n.message for n in found]
    assert re.search(pattern, found[0].message), found[0].message
    assert not any("raise motors.max_thrust" in n.message for n in found)
    assert not any(re.search(r"\b[A-Z][A-Z0-9]*_[A-Z0-9_]*[A-Z0-9]\b", n.message) for n in found)  # no code's names


def test_the_original_vehicle_earns_no_warning():
    assert notices.notices(config.parse(IRIS, "c.yaml"), "c.yaml") == []


def _iris_with_rotors_at(factor: float) -> str:
    """IRIS with its rotors given as positions (PX4's order, as its numbering), in m over ``factor``."""
    at = [[0.1807, 0.1807], [-0.1807, -0.1807], [0.1807, -0.1807], [-0.1807, 0.1807]]
    text = IRIS.replace("positions: null", f"positions: {[[round(v / factor, 6) for v in xy] for xy in at]}")
    text = re.sub(r"\n  numbering: px4 .*", "", text.replace("spin: null", "spin: [ccw, ccw, cw, cw]"))
    assert "spin: [ccw" in text and "positions: [[" in text and "numbering:" not in text
    return text


@pytest.mark.parametrize(("factor", "pattern"), [
    (1e-3, r"^c\.yaml: motors\.positions puts the rotors 256 m from the centre on average, 1\.33e\+03 times the "
           r"radius of gyration sqrt\(J/m\) = 0\.192 m of vehicle\.inertia and vehicle\.mass \(a quadcopter's arm is "
           r"0\.5 to 10 times its radius of gyration\); are motors\.positions in mm\? 256 mm is 0\.256 m: give "
           r"each rotor's \[x, y\] in m$"),
    (1e-2, r"; are motors\.positions in cm\? 25\.6 cm is 0\.256 m: give each rotor's \[x, y\] in m$"),
    (1.0, None)])
def test_rotor_positions_in_mm_or_cm_are_named_as_the_slip_and_in_m_pass(factor, pattern):
    """An arm in mm was a warning and exit 1; the same rotors given as motors.positions in mm flew a 1.5 kg
    vehicle with rotors 256 m out."""
    found = [n for n in notices.notices(config.parse(_iris_with_rotors_at(factor), "c.yaml"), "c.yaml")
             if n.level == "warning"]
    if pattern is None:
        assert found == []
        return
    assert [n.key for n in found] == ["motors.positions"], [n.message for n in found]
    assert re.search(pattern, found[0].message), found[0].message


@pytest.mark.parametrize("name", ["arm in mm", "thrust in grams-force", "mass in grams", "inertia in kg mm^2",
                                  "controller rate in kHz"])
def test_a_slip_is_a_failed_check_unless_the_config_accepts_it(tmp_path, name):
    key = SLIPS[name][2]
    path = tmp_path / "c.yaml"
    path.write_text(_slipped(name))
    res = runner.invoke(app, ["linearize", "-c", str(path), "-o", str(tmp_path / "out")])
    assert res.exit_code == 1, res.output
    last = res.stderr.splitlines()[-1]
    two = name == "mass in grams"  # its radius of gyration and its thrust-to-weight
    assert last == (f"quadctl: check failed: {path}: {key} implausible (the warning{'s' if two else ''} above "
                    f"give{'' if two else 's'} the likely slip and the fix); correct the value, or add "
                    "`allow: [implausible]` to the config if the vehicle really is so")
    assert "raise motors.max_thrust" not in res.stderr  # the mass slip once ended with the trim's wrong fix
    path.write_text(_slipped(name).replace("allow: []", "allow: [implausible]"))
    res = runner.invoke(app, ["linearize", "-c", str(path), "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert "quadctl: warning:" in res.stderr


def test_a_design_at_its_rotor_limits_most_of_the_run_fails_unless_accepted(tmp_path):
    """The inertia in kg mm^2, accepted as implausible: the rotors sit at a limit the whole run."""
    text = _slipped("inertia in kg mm^2").replace("allow: []", "allow: [implausible]")
    assert "duration: 10.0 " in text
    text = text.replace("duration: 10.0 ", "duration: 1.0 ")
    path = tmp_path / "c.yaml"
    path.write_text(text)
    out = str(tmp_path / "out")
    res = runner.invoke(app, ["simulate", "-c", str(path), "-o", out])
    assert res.exit_code == 1, res.output
    assert re.search(r"^quadctl: check failed: the design saturates: rotor \d is at a limit 100 % of "
                     r"the run, more than 50 %, so it flies its limits, not the design; lower the "
                     r"gains \(larger lqr R\) or the initial offset, or give the rotors the thrust they really have "
                     r"\(motors\.max_thrust\); --allow-saturation \(or allow: \[saturation\] in the config\) accepts "
                     r"it$", res.stderr, re.M), res.stderr
    assert "warning: the design saturates" not in res.stderr  # said once, as the failure
    assert (tmp_path / "out" / "sim.npz").exists()  # what was computed is saved
    res = runner.invoke(app, ["run", "-c", str(path), "-o", out, "--allow-saturation"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["report", "-c", str(path), "-o", out])  # the same check, the same option
    assert res.exit_code == 1 and "the design saturates: rotor" in res.stderr, res.output
    res = runner.invoke(app, ["report", "-c", str(path), "-o", out, "--allow-saturation"])
    assert res.exit_code == 0, res.output
    assert "--allow-saturation" in (tmp_path / "out" / "report" / "report.md").read_text()  # its command line
    path.write_text(text.replace("allow: [implausible]", "allow: [implausible, saturation]"))
    res = runner.invoke(app, ["simulate", "-c", str(path), "-o", out])
    assert res.exit_code == 0, res.output
    assert "quadctl: warning: the design saturates: rotor" in res.stderr


# -- a reference's units: yaws in degrees, positions in millimetres ---------------------------------

SQUARE = config.bundled("square")
WAYPOINT_YAW = r"simulation\.reference\.waypoints\[1\]\.yaw"
REFERENCE_SLIPS = {
    "waypoint yaw in degrees": (["simulation.reference.waypoints[1].yaw=90"],
                                rf"^--set: {WAYPOINT_YAW} = 90: that is 5157 deg, beyond 720 deg; angles are in rad: "
                                r"for 90 deg write 1\.571$"),
    "negative waypoint yaw in degrees": (["simulation.reference.waypoints[1].yaw=-30"],
                                         rf"^--set: {WAYPOINT_YAW} = -30: that is -1719 deg, beyond 720 deg; .* "
                                         r"for -30 deg write -0\.5236$"),
    "setpoint yaw in degrees": (["simulation.reference={setpoints: [{t: 1, yaw: 45}]}"],
                                r"^--set: simulation\.reference\.setpoints\[0\]\.yaw = 45: that is 2578 deg, beyond "
                                r"720 deg; angles are in rad: for 45 deg write 0\.7854$"),
    "yaw schedule in degrees": (["schedule={variable: yaw, values: [0, 45, 90]}"],
                                r"^--set: schedule\.values\[1\] = 45: that is 2578 deg, beyond 720 deg; angles are in "
                                r"rad: for 45 deg write 0\.7854$"),
    "waypoint 10 km away": (
        ["simulation.reference.waypoints[0].position=[10000, 0, -1]"],
        r"^--set: simulation\.reference\.waypoints\[0\]\.position = \[10000, 0, -1\]: 10000 m from the start along "
        r"the mission, more than 10 times the 30 m that simulation\.reference\.speed = 2 m/s covers in "
        r"simulation\.duration = 15 s; positions are in m: for millimetres write \[10, 0, -0\.001\], "
        r"else correct the slip, or raise the speed or the duration$"),
    "waypoints in millimetres": (
        [f"simulation.reference.waypoints[{i}].position={p}"
         for i, p in enumerate(("[2000, 0, -1000]", "[2000, 2000, -1500]"))],
        r"^--set: simulation\.reference\.waypoints\[0\]\.position = \[2000, 0, -1000\]: 2235\.6 m "
        r"from the start .*: for millimetres write \[2, 0, -1\], else correct the slip"),
    "a later waypoint out of reach along the mission": (
        ["simulation.reference.waypoints[2].position=[0, 400, -1.5]"],
        r"^--set: simulation\.reference\.waypoints\[2\]\.position = \[0, 400, -1\.5\]: 402\.07 m from the start "
        r"along the mission, more than 10 times the 30 m .*; positions are in m: for millimetres write "
        r"\[0, 0\.4, -0\.0015\]"),
    "a slipped waypoint whose next leg passes the reach": (  # the sum passes it at [2]: the slip is [1]'s
        ["simulation.reference.waypoints[1].position=[200, 2, -1.5]"],
        r"^--set: simulation\.reference\.waypoints\[1\]\.position = \[200, 2, -1\.5\]: 200\.01 m from the start, "
        r"the farthest waypoint of a mission 400\.01 m long by waypoints\[2\], more than 10 times the 30 m .*; "
        r"positions are in m: for millimetres write \[0\.2, 0\.002, -0\.0015\]"),
    "a position beyond any millimetre": (
        ["simulation.reference.waypoints[0].position=[5e5, 0, -1]"],
        r"^--set: simulation\.reference\.waypoints\[0\]\.position = \[500000, 0, -1\]: 5e\+05 m from the start "
        r".* s; positions are in m: correct the slip, or raise the speed or the duration$"),
    "a position past the unit's limit": (
        ["simulation.reference.waypoints[0].position=[1e300, 0, -1]"],
        r"^--set: simulation\.reference\.waypoints\[0\]\.position\[0\] = 1e\+300: must be at most 1e\+06 m in "
        r"magnitude$"),
}


@pytest.mark.parametrize("name", REFERENCE_SLIPS)
def test_a_reference_slip_is_refused_naming_its_key_and_the_fix(name):
    sets, pattern = REFERENCE_SLIPS[name]
    with pytest.raises(ConfigError, match=pattern):
        overrides.load(SQUARE, sets)


@pytest.mark.parametrize("sets", [
    ["simulation.reference.waypoints[1].yaw=12.5"],  # two turns, less a little: a mission may circle twice
    ["simulation.reference.waypoints[1].yaw=-12.5"],
    ["schedule={variable: yaw, values: [-6.2832, 0, 12.5]}"],
    ["simulation.reference={setpoints: [{t: 1, yaw: 12.5}]}"],
    # 10 times the 30 m the run can fly, along the legs (from [0, 0, -1]: 150 + 150 m), less a little
    ["simulation.reference.waypoints[0].position=[150, 0, -1]", "simulation.reference.waypoints[1].position=[0, 0, -1]",
     "simulation.reference.waypoints[2].position=[0, 0, -1]", "simulation.reference.waypoints[3].position=[0, 0, -1]"],
    ["simulation.reference.waypoints[0].position=[3000, 0, -1]", "simulation.duration=1500"],  # far, and flown long
])
def test_a_reference_within_its_ranges_is_taken(sets):
    overrides.load(SQUARE, sets)


def test_the_reach_is_counted_along_the_mission():
    """There and back, 150 m each way, is 300 m flown: one metre more is past the 300 m the rule allows. The
    error names the farthest waypoint (what a slip would have made far) and where the mission passed the bound."""
    sets = ["simulation.reference.waypoints[0].position=[150, 0, -1]",
            "simulation.reference.waypoints[1].position=[0, 0, -1]"]
    overrides.load(SQUARE, [*sets, "simulation.reference.waypoints[2].position=[0, 0, -1]"])
    with pytest.raises(ConfigError, match=r"waypoints\[0\]\.position = \[150, 0, -1\]: 150 m from the start, the "
                                          r"farthest waypoint of a mission 301 m long by waypoints\[2\], more than 10"):
        overrides.load(SQUARE, [*sets, "simulation.reference.waypoints[2].position=[0, 1, -1]"])


def test_a_reference_slip_is_one_line_and_exit_2(tmp_path):
    res = runner.invoke(app, ["simulate", "-c", "square", "-o", str(tmp_path / "out"),
                              "--set", "simulation.reference.waypoints[1].yaw=90"])
    assert res.exit_code == 2, res.output
    assert res.stderr.strip().splitlines() == [
        "quadctl: error: --set: simulation.reference.waypoints[1].yaw = 90: that is 5157 deg, beyond 720 deg; "
        "angles are in rad: for 90 deg write 1.571"]
