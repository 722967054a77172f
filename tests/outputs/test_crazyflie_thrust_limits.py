"""quadctl export --to crazyflie: the rotor thrusts the configured flight asks of the firmware, against the
thrusts the firmware gives (it stops a motor below ``THRUST_MIN``, clips one above ``THRUST_MAX`` in force mode).

The firmware is not here: its limits are :data:`quadctl.export.crazyflie.FIRMWARE`'s, and its force-torque
mixer is written out below from its documented convention (each motor a quarter of the thrust, plus or minus a
quarter of each torque over the arm's lever and over ``THRUST2TORQUE``), not taken from quadctl's mixer.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app
from quadctl.config import overrides
from quadctl.export import crazyflie, prepare
from quadctl.present.platform import flight_sentences, platform_sentences
from quadctl.setup import setup_of

FW = crazyflie.FIRMWARE
HIGH = "simulation.initial_offset.pD=-1.0"
"""crazyflie started 1 m above its trim: sinking back, its rotors drop to 0 N for the first samples."""
MIX_RTOL = 1e-9
"""Mixing to rotor thrusts and back is a 4 x 4 solve: round-off only."""


def _exp(*sets):
    return prepare(setup_of(overrides.load(config.locate("crazyflie"), sets)))


def _export(tmp_path, *args):
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "-o", str(tmp_path / "app"),
                                   *args])
    assert res.exit_code == 0, res.output
    return res.output


def _lines(output: str, level: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith(f"quadctl: {level}: the configured flight")]


def test_the_bundled_crazyflie_flight_stays_within_the_firmwares_rotor_thrusts(tmp_path):
    """The note gives the flight's lowest and highest rotor thrust (0.064 and 0.118 N, docs/guide/export.md),
    between the firmware's 0.0128 and 0.12 N: no warning. The thrusts are the design's rotors: mixed back, they
    are the inputs the run applied."""
    from quadctl.pipeline import simulation_of

    exp = _exp()
    flight = crazyflie.flight_thrusts(exp)
    run = simulation_of(exp.setup, exp.loop)
    back = flight.thrusts @ exp.loop.actuators.motors.effectiveness().T
    assert np.allclose(back, run.u, rtol=MIX_RTOL, atol=MIX_RTOL * np.abs(run.u).max()), np.abs(back - run.u).max()
    assert flight.ok and round(flight.lowest()[1], 3) == 0.064 and round(flight.highest()[1], 3) == 0.118
    out = _export(tmp_path)
    assert _lines(out, "note") == [
        "quadctl: note: the configured flight (quadctl simulate's run, 10 s) asks the firmware's motors for "
        f"{flight.lowest()[1]:.4g} N (M4) to {flight.highest()[1]:.4g} N (M2) in force mode: the firmware stops a "
        "motor below 0.01282 N and clips one above 0.12 N"]
    assert _lines(out, "warning") == []


def test_a_flight_that_drops_a_rotor_below_the_firmwares_least_thrust_is_warned_and_the_fix_named(tmp_path):
    """From 1 m high the rotors drop to 0 N, passing between 0 and the floor, where the firmware gives none of
    the thrust asked: warned, the share of the run counted on those samples (a thrust of exactly 0, the
    saturation's, is given as asked), exit 0; the fix the warning names (motors.min_thrust at the floor)
    removes the warning, as the design's saturation then asks no rotor for less."""
    flight = crazyflie.flight_thrusts(_exp(HIGH))
    floor = 0.012817578393224994
    lost = np.any((flight.thrusts > 1e-12) & (flight.thrusts < floor), axis=1)
    assert lost.sum() >= 2 and flight.lowest()[1] == pytest.approx(0.0, abs=1e-12)
    assert lost.sum() < np.any(flight.thrusts < floor, axis=1).sum()  # some samples at 0 itself, not counted
    warned = _lines(_export(tmp_path, "--set", HIGH), "warning")
    lost_motors = ((flight.thrusts > 1e-12) & (flight.thrusts < floor)).any(axis=0)
    motors = ", ".join(f"M{k + 1}" for k in np.flatnonzero(lost_motors))
    assert warned == [
        f"quadctl: warning: the configured flight asks {motors} for thrusts between 0 and the 0.01282 N under which "
        f"the firmware stops a motor ({100 * lost.mean():.3g} % of the run), where the vehicle loses thrust the design "
        "counts on; set motors.min_thrust: 0.01282 (the design's saturation, which the app flies, then asks no less), "
        "or fly gentler gains or offsets"]
    fixed = _export(tmp_path, "--set", HIGH, "--set", "motors.min_thrust=0.01282")
    assert _lines(fixed, "warning") == [] and "asks the firmware's motors for 0.01282 N (M4)" in fixed


def test_a_flight_above_the_firmwares_clip_is_warned_in_force_mode_only(tmp_path):
    """A 0.3 rad roll asks one rotor for 0.14 N: the firmware clips it at 0.12 N in force mode; in force-torque
    mode it has no clip there, and nothing is warned of the top."""
    sets = ("--set", "simulation.initial_offset.phi=0.3")
    warned = _lines(_export(tmp_path, *sets), "warning")
    assert len(warned) == 1 and "above the 0.12 N at which the firmware clips a motor in force mode" in warned[0]
    assert warned[0].endswith("set motors.max_thrust: 0.12 to saturate the design where the firmware does")
    torque = _export(tmp_path, *sets, "--mode", "force-torque")
    assert _lines(torque, "warning") == [] and "has no clip at 0.12 N in force-torque mode" in torque


def test_force_torque_mode_takes_the_rotor_thrusts_the_firmwares_own_mixer_gives():
    """Force-torque mode: the app hands over T and the torques in the firmware's body axes (torqueX = A,
    torqueY = -E, torqueZ = -R); the firmware's mixer, written out here, gives each motor a quarter of the
    thrust and a quarter of each torque over its lever (the arm times cos 45 deg) or over THRUST2TORQUE, and
    nothing when that is negative."""
    from quadctl.pipeline import simulation_of

    exp = _exp(HIGH)
    u = simulation_of(exp.setup, exp.loop).u
    tx, ty, tz = u[:, 1], -u[:, 2], -u[:, 3]
    lever = FW.arm_length * math.cos(math.pi / 4)
    signs = [(-1, -1, -1), (-1, 1, 1), (1, 1, -1), (1, -1, 1)]  # M1-M4: roll, pitch, yaw
    want = np.stack([u[:, 0] / 4 + sx * tx / (4 * lever) + sy * ty / (4 * lever) + sz * tz / (4 * FW.torque_coefficient)
                     for sx, sy, sz in signs], axis=1)
    got = crazyflie.flight_thrusts(exp, "force-torque").thrusts
    assert np.allclose(got, np.maximum(want, 0.0), rtol=1e-9, atol=1e-12), np.abs(got - np.maximum(want, 0.0)).max()
    assert (want < 0).any()  # the clamp is exercised


def _flight(lowest: float, highest: float, mode: str = "force") -> crazyflie.FlightThrusts:
    """A made-up flight: motor M3 at ``lowest`` and M2 at ``highest`` for one sample of four, hover otherwise."""
    thrusts = np.full((4, 4), 0.066)
    thrusts[1, 2], thrusts[2, 1] = lowest, highest
    return crazyflie.FlightThrusts(thrusts=thrusts, t=np.linspace(0.0, 3.0, 4), mode=mode, message="ok", ok=True)


@pytest.mark.parametrize("mode", ["force", "force-torque"])
@pytest.mark.parametrize("factor, warned", [(1 - 1e-9, True), (1.0, False), (1 + 1e-9, False)])
def test_the_least_thrust_is_compared_at_the_firmwares_value(mode, factor, warned):
    """A motor is stopped when asked for less than THRUST_MIN (the firmware compares ``thrust < THRUST_MIN``):
    just under it is warned, at it or just over is not, in both modes; one sample of four: 25 % of the run."""
    said = flight_sentences(_flight(0.012817578393224994 * factor, 0.1), FW)
    low = [text for level, text in said if level == "warning" and "stops a motor" in text]
    assert len(low) == warned and said[0][0] == "note"
    if warned:
        assert low[0].startswith("the configured flight asks M3 for thrusts between 0 and the 0.01282 N") and \
            "(25 % of the run)" in low[0]


@pytest.mark.parametrize("lowest, warned", [(0.0, False), (1e-13, False), (1e-6, True)])
def test_a_rotor_asked_for_no_thrust_is_given_it(lowest, warned):
    """The firmware gives a motor asked for 0 N (the design's saturation) what it asks: only a thrust between 0
    and THRUST_MIN is lost; the mixer's round-off about 0 is 0."""
    said = flight_sentences(_flight(lowest, 0.1), FW)
    assert any(level == "warning" and "stops a motor" in text for level, text in said) == warned


@pytest.mark.parametrize("factor, warned", [(1 + 1e-9, True), (1.0, False), (1 - 1e-9, False)])
def test_the_maximum_thrust_is_compared_at_the_firmwares_clip(factor, warned):
    """Force mode clips the share at 1, THRUST_MAX: just over it is warned, at it or under is not; in
    force-torque mode, never."""
    said = flight_sentences(_flight(0.05, 0.12 * factor), FW)
    high = [text for level, text in said if level == "warning"]
    assert len(high) == warned
    if warned:
        assert high[0].startswith("the configured flight asks M2 for 0.12 N, above the 0.12 N") and \
            "above it 25 % of the run" in high[0]
    assert [level for level, _ in flight_sentences(_flight(0.05, 0.12 * factor, "force-torque"), FW)] == ["note"]


def test_a_design_allowed_below_the_firmwares_least_thrust_is_told_without_blaming_the_vehicles_numbers():
    """The config's motors.min_thrust under the firmware's THRUST_MIN: one sentence with the firmware's number and
    the key to set, whatever the mode; it is no number of the vehicle, so alone it does not send the user to
    identify the vehicle. At or above the floor nothing is said of it but that it agrees."""
    def rows(least):
        return [("mass", "vehicle.mass", FW.mass, FW.mass, "kg"),
                ("least rotor thrust", "motors.min_thrust", least, FW.min_thrust, "N")]

    for mode in ("force", "force-torque"):
        text = "\n".join(platform_sentences(rows(0.0), FW, mode))
        assert ("the firmware stops a motor asked for less than 0.01282 N (THRUST_MIN of "
                "src/platform/interface/platform_defaults_cf2.h; src/drivers/src/motors.c "
                "motorsCompensateBatteryVoltage gives it no voltage), in either mode, where the design takes a rotor "
                "as able to give any thrust down to motors.min_thrust = 0 N") in text
        assert text.endswith("set motors.min_thrust: 0.01282 to keep the design's saturation above it\n"
                             "agrees with the firmware's defaults: mass (vehicle.mass = 0.029 kg)")
        assert "quadctl identify" not in text
    assert platform_sentences(rows(FW.min_thrust), FW) == [
        "agrees with the firmware's defaults: mass (vehicle.mass = 0.029 kg), least rotor thrust "
        "(motors.min_thrust = 0.01282 N)"]
    assert "stops a motor" not in "\n".join(platform_sentences(rows(0.02), FW))
    assert "down to motors.min_thrust = 0.005 N" in "\n".join(platform_sentences(rows(0.005), FW))


def test_the_json_gives_the_firmwares_limits_and_the_flights_thrusts(tmp_path):
    out = json.loads(CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "--set", HIGH,
                                              "-o", str(tmp_path / "app"), "--json"]).stdout)["crazyflie"]
    flight = crazyflie.flight_thrusts(_exp(HIGH))
    assert out["firmware"]["min_thrust"] == 0.012817578393224994 and out["firmware"]["max_thrust"] == 0.12
    assert out["flight"] == {"completed": True, "lowest": flight.lowest()[1], "highest": flight.highest()[1],
                             "stopped": flight.share_stopped(FW.min_thrust), "above_max": 0.0}
    assert {r["key"]: r["value"] for r in out["platform"]}["motors.min_thrust"] == 0.0
