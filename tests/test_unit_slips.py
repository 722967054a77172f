"""The unit slips a new vehicle's author makes, each named by the key that slipped with the right
fix, and each a failed check (exit 1) unless the config accepts it; a design at its rotor limits most
of the run fails too, unless accepted."""

from __future__ import annotations

import re

import pytest
from typer.testing import CliRunner

from quadctl import config, notices, starter
from quadctl.cli.app import app

runner = CliRunner()
IRIS = starter.config_text("slip", "iris", "hover")
"""A 1.5 kg, 0.2555 m arm vehicle (PX4's Iris), the F450 class: J = diag(0.029125, 0.029125, 0.055225) kg m^2,
7.0664 N per rotor."""

SLIPS = {
    "arm in mm": ("arm_length: 0.2555", "arm_length: 255.5", "motors.arm_length",
                  r"^c\.yaml: motors\.arm_length = 255\.5 m is 1\.33e\+03 times the radius of gyration sqrt\(Jzz/m\) = "
                  r"0\.192 m of vehicle\.inertia = .* and vehicle\.mass = 1\.5 kg \(a quadcopter's arm is 0\.5 to 10 "
                  r"times it: GYRATION_TO_ARM\); is motors\.arm_length in mm\? 255\.5 mm is 0\.2555 m$"),
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
                               r"^c\.yaml: controller\.rate = 0\.25 Hz is below the 20 Hz of the slowest attitude loop "
                               r"a flight computer closes \(100 Hz to 8 kHz: CONTROLLER_RATES\); "
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


def test_the_original_vehicle_earns_no_warning():
    assert notices.notices(config.parse(IRIS, "c.yaml"), "c.yaml") == []


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
    text = _slipped("inertia in kg mm^2").replace("allow: []", "allow: [implausible]").replace(
        "duration: 10 ", "duration: 1 ")
    path = tmp_path / "c.yaml"
    path.write_text(text)
    out = str(tmp_path / "out")
    res = runner.invoke(app, ["simulate", "-c", str(path), "-o", out])
    assert res.exit_code == 1, res.output
    assert re.search(r"^quadctl: check failed: .*c\.yaml: the design saturates: rotor \d is at a limit 100 % of "
                     r"the run, more than 50 % \(SATURATION_FAIL\), so it flies its limits, not the design; lower the "
                     r"gains \(larger lqr R\) or the initial offset, or give the rotors the thrust they really have "
                     r"\(motors\.max_thrust\); --allow-saturation \(or allow: \[saturation\] in the config\) accepts "
                     r"it$", res.stderr, re.M), res.stderr
    assert "warning: the design saturates" not in res.stderr  # said once, as the failure
    assert (tmp_path / "out" / "sim.npz").exists()  # what was computed is saved
    res = runner.invoke(app, ["run", "-c", str(path), "-o", out, "--allow-saturation"])
    assert res.exit_code == 0, res.output
    path.write_text(text.replace("allow: [implausible]", "allow: [implausible, saturation]"))
    res = runner.invoke(app, ["simulate", "-c", str(path), "-o", out])
    assert res.exit_code == 0, res.output
    assert "quadctl: warning: the design saturates: rotor" in res.stderr
