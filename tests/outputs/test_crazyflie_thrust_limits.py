"""quadctl export --to crazyflie: the rotor thrusts the configured flight asks of the firmware, against the
thrusts the firmware gives (it stops a motor below ``THRUST_MIN``, clips one above ``THRUST_MAX`` in force mode,
caps one at full PWM in force-torque mode).

The firmware is not here: its limits are :data:`quadctl.export.crazyflie_platform.FIRMWARE`'s, and its
force-torque mixer is written out below from its documented convention (each motor a quarter of the thrust, plus
or minus a quarter of each torque over the arm's lever and over ``THRUST2TORQUE``), not taken from quadctl's mixer;
so is the way from a force-torque share to a motor's PWM (:func:`_firmware_pwm`: the battery compensation's fit
of thrust against motor voltage, the firmware's coefficients as
:attr:`~quadctl.export.crazyflie_platform.Platform.vmotor2thrust` holds them, solved here by bisection, and the
cap at full PWM), which gives the full-PWM limit a second time, not from quadctl's number.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app
from quadctl.config import overrides
from quadctl.export import crazyflie_platform, prepare
from quadctl.present.platform import flight_sentences, platform_sentences
from quadctl.setup import setup_of

FW = crazyflie_platform.FIRMWARE
HIGH = "simulation.initial_offset.pD=-1.0"
"""crazyflie started 1 m above its trim: sinking back, its rotors drop to 0 N for the first samples."""
MIX_RTOL = 1e-9
"""Mixing to rotor thrusts and back is a 4 x 4 solve: round-off only."""
HARD = ("--set", "motors.max_thrust=0.4", "--set", "simulation.initial_offset.pD=5.0")
"""crazyflie started 5 m below its trim, its rotors allowed 0.4 N: climbing back, one asks for 0.34 N."""

FULL_BATTERY = 4.2
"""V: a full LiPo cell, where the firmware's low-pass of the battery's voltage starts."""
FULL_PWM = 65535
"""The motors' PWM is 16 bits: 65535 is full."""
PWM_STEP = 1e-6
"""Relative: the firmware's integer PWM caps from about 1.3e-5 N (5e-5 of the full-PWM thrust) over the limit; a
thrust nearer the limit than this is compared with the limit alone, one farther also with the firmware's cap."""


def _thrust_at(volts):
    """N: what the fit gives a motor at ``volts`` (V)."""
    c0, c1, c2, c3 = FW.vmotor2thrust
    v = np.asarray(volts, dtype=float)
    return c0 + v * (c1 + v * (c2 + v * c3))


def _volts_for(thrust):
    """V: the motor voltage that gives ``thrust`` (N), by bisection (the fit rises everywhere: its slope's
    discriminant is negative)."""
    lo, hi = np.zeros_like(thrust, dtype=float), np.full_like(thrust, 10.0, dtype=float)
    for _ in range(80):
        mid = (lo + hi) / 2
        below = _thrust_at(mid) < thrust
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return (lo + hi) / 2


def _firmware_pwm(thrusts, battery=FULL_BATTERY):
    """The PWM each motor gets in force-torque mode, and whether the sample was capped, from the motors' mixed
    thrusts (N, negative shares already 0): the share is handed on as an integer count of ``THRUST_MAX``/65535
    and read back as N; under ``THRUST_MIN`` a motor gets 0, else the voltage the fit needs over the battery's,
    in integer 1/65535 of full PWM, uncapped; the highest over full lowers all four by its excess, none below 0.

    Returns
    -------
    pwm : (..., 4) ndarray
    capped : (...) bool ndarray
    """
    counts = np.trunc(np.asarray(thrusts, dtype=float) / FW.max_thrust * FULL_PWM)
    asked = counts / FULL_PWM * FW.max_thrust
    uncapped = np.where(asked < FW.min_thrust, 0.0, np.trunc(FULL_PWM * _volts_for(asked) / battery))
    excess = np.maximum(uncapped.max(axis=-1) - FULL_PWM, 0.0)
    return np.maximum(uncapped - excess[..., None], 0.0), excess > 0


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
    flight = crazyflie_platform.flight_thrusts(exp)
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
    flight = crazyflie_platform.flight_thrusts(_exp(HIGH))
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
    mode it has no clip there, and full PWM gives 0.14 N: nothing is warned of the top."""
    sets = ("--set", "simulation.initial_offset.phi=0.3")
    warned = _lines(_export(tmp_path, *sets), "warning")
    assert len(warned) == 1 and "above the 0.12 N at which the firmware clips a motor in force mode" in warned[0]
    assert warned[0].endswith("set motors.max_thrust: 0.12 to saturate the design where the firmware does")
    torque = _export(tmp_path, *sets, "--mode", "force-torque")
    assert _lines(torque, "warning") == [] and "(no clip at 0.12 N in force-torque mode)" in torque
    fixed = _export(tmp_path, *sets, "--set", "motors.max_thrust=0.12")  # the fix the warning names
    assert _lines(fixed, "warning") == [] and "asks the firmware's motors for" in fixed and "to 0.12 N (M2)" in fixed


def test_the_bundled_crazyflie_flight_stays_under_full_pwm_in_force_torque_mode(tmp_path):
    """Force-torque mode: the firmware's own mix of the run asks 0.064 to 0.117 N, under the 0.2787 N full PWM
    gives on a full battery (and under the 0.12 N full PWM gives down to 3.08 V): a note, no warning."""
    flight = crazyflie_platform.flight_thrusts(_exp(), "force-torque")
    assert flight.ok and round(flight.lowest()[1], 3) == 0.064 and round(flight.highest()[1], 3) == 0.117
    assert not _firmware_pwm(flight.thrusts)[1].any() and not _firmware_pwm(flight.thrusts, 3.08)[1].any()
    out = _export(tmp_path, "--mode", "force-torque")
    assert _lines(out, "note") == [
        "quadctl: note: the configured flight (quadctl simulate's run, 10 s) asks the firmware's motors for "
        f"{flight.lowest()[1]:.4g} N (M4) to {flight.highest()[1]:.4g} N (M2) in force-torque mode: the firmware "
        "stops a motor below 0.01282 N and caps one at full PWM, lowering all four alike: 0.2787 N on a full battery "
        "(4.2 V), less as it drains (no clip at 0.12 N in force-torque mode)"]
    assert _lines(out, "warning") == []


def test_a_flight_above_full_pwm_is_warned_in_force_torque_mode(tmp_path):
    """5 m low, the rotors allowed 0.4 N: climbing back, the firmware's mix of the run asks M2 for 0.34 N, more
    than full PWM gives on a full battery. Warned, with the rotor, the thrust, the limit and the share of the run;
    the samples counted are those in which the firmware's way to the PWM (written out here) caps the motors, and
    none lies within the integer PWM's step of the limit. In force mode the same run is warned of the 0.12 N
    clip instead."""
    exp = _exp(*HARD[1::2])
    flight = crazyflie_platform.flight_thrusts(exp, "force-torque")
    above = np.any(flight.thrusts > FW.full_pwm_thrust, axis=1)
    capped = _firmware_pwm(flight.thrusts)[1]
    assert flight.ok and flight.highest()[0] == 1 and round(flight.highest()[1], 2) == 0.34
    assert 0 < above.sum() < len(above) and np.array_equal(above, capped)
    assert np.abs(flight.thrusts / FW.full_pwm_thrust - 1).min() > 1e-4
    warned = _lines(_export(tmp_path, *HARD, "--mode", "force-torque"), "warning")
    assert warned == [
        f"quadctl: warning: the configured flight asks M2 for {flight.highest()[1]:.4g} N, above the 0.2787 N full "
        "PWM gives a motor on a full battery (4.2 V), at which the firmware caps a motor in force-torque mode and "
        f"lowers the other three by as much PWM: some motor is above it {100 * above.mean():.3g} % of the run, where "
        "the vehicle lacks thrust and torque the design counts on; export with --mode force and motors.max_thrust: "
        "0.12 (the app's saturation then asks no more), or fly gentler gains or offsets"]
    force = _lines(_export(tmp_path, *HARD), "warning")
    assert len(force) == 1 and "at which the firmware clips a motor in force mode" in force[0]


def test_full_pwm_gives_the_fit_at_a_full_battery_and_less_as_it_drains():
    """The limit is the firmware's fit at 4.2 V: the firmware's way to the PWM caps no motor at it, nor 1e-4 under,
    and caps 1e-4 over, the other three lowered by the same PWM; its integer PWM caps from about 1.3e-5 N over
    (the firmware's docs: 0.193 N at 3.7 V, 0.132 N at 3.2 V, THRUST_MAX at 3.08 V)."""
    assert FW.full_pwm_voltage == FULL_BATTERY
    assert FW.full_pwm_thrust == pytest.approx(_thrust_at(FULL_BATTERY), rel=1e-15)
    assert _volts_for(np.array(FW.full_pwm_thrust)) == pytest.approx(FULL_BATTERY, rel=1e-12)
    hover = [0.07, 0.06, 0.05]
    for factor, caps in [(1 - 1e-4, False), (1.0, False), (1 + 1e-4, True)]:
        thrusts = np.array([hover[0], FW.full_pwm_thrust * factor, *hover[1:]])
        pwm, capped = _firmware_pwm(thrusts)
        assert bool(capped) == caps, factor
        alone = _firmware_pwm(np.array(hover))[0]
        if caps:
            assert pwm[1] == FULL_PWM and np.all(pwm[[0, 2, 3]] < alone) and np.ptp(alone - pwm[[0, 2, 3]]) == 0
        else:
            assert np.array_equal(pwm[[0, 2, 3]], alone) and pwm[1] <= FULL_PWM
    step = [bool(_firmware_pwm(np.array([FW.full_pwm_thrust + d, *hover]))[1]) for d in (1.2e-5, 1.5e-5)]
    assert step == [False, True]
    assert [round(float(_thrust_at(v)), 3) for v in (3.7, 3.2)] == [0.193, 0.132]
    assert round(float(_volts_for(np.array(FW.max_thrust))), 2) == 3.08


def test_the_full_pwm_thrust_is_the_fit_at_the_platforms_voltage():
    """A platform at another voltage has its own full-PWM thrust, the fit there (solved back to the voltage by
    bisection), none kept from 4.2 V."""
    for volts in (3.7, 3.2):
        other = dataclasses.replace(FW, full_pwm_voltage=volts)
        assert other.full_pwm_thrust == pytest.approx(float(_thrust_at(volts)), rel=1e-14)
        assert _volts_for(np.array(other.full_pwm_thrust)) == pytest.approx(volts, rel=1e-12)
        assert other.full_pwm_thrust < FW.full_pwm_thrust


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
    got = crazyflie_platform.flight_thrusts(exp, "force-torque").thrusts
    assert np.allclose(got, np.maximum(want, 0.0), rtol=1e-9, atol=1e-12), np.abs(got - np.maximum(want, 0.0)).max()
    assert (want < 0).any()  # the clamp is exercised


def _flight(lowest: float, highest: float, mode: str = "force",
            rotors: bool = True) -> crazyflie_platform.FlightThrusts:
    """A made-up flight: motor M3 at ``lowest`` and M2 at ``highest`` for one sample of four, hover otherwise;
    ``rotors``: the config has ``motors:``."""
    thrusts = np.full((4, 4), 0.066)
    thrusts[1, 2], thrusts[2, 1] = lowest, highest
    return crazyflie_platform.FlightThrusts(thrusts=thrusts, t=np.linspace(0.0, 3.0, 4), mode=mode, message="ok",
                                            ok=True, rotors=rotors)


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


@pytest.mark.parametrize("highest, warned", [(0.12 * (1 + 1e-9), True), (0.12, False), (0.12 * (1 - 1e-9), False),
                                             (0.12000000000000002, False)])
def test_the_maximum_thrust_is_compared_at_the_firmwares_clip(highest, warned):
    """Force mode clips the share at 1, THRUST_MAX: just over it is warned, with as many digits as tell the two
    apart, at it or under is not, nor the mixer's round-off over it (a rotor the design's saturation holds at
    ``motors.max_thrust: 0.12`` mixes to 0.12000000000000002 N); in force-torque mode, never."""
    said = flight_sentences(_flight(0.05, highest), FW)
    high = [text for level, text in said if level == "warning"]
    assert len(high) == warned
    if warned:
        assert high[0].startswith("the configured flight asks M2 for 0.1200000001 N, above the 0.12 N") and \
            "above it 25 % of the run" in high[0]
    assert [level for level, _ in flight_sentences(_flight(0.05, highest, "force-torque"), FW)] == ["note"]


@pytest.mark.parametrize("factor", [1 - 1e-4, 1 - 1e-9, 1.0, 1 + 1e-9, 1 + 1e-4])
def test_the_full_pwm_thrust_is_compared_at_the_firmwares_cap(factor):
    """Force-torque mode: a motor asked for more than full PWM gives on a full battery is warned, with as many
    digits as tell the thrust from the limit, at it or under is not; 1e-4 from it the warning and the samples
    counted are the firmware's way to the PWM's cap (within 1.3e-5 N over it, the integer PWM's step, the firmware
    does not cap yet); one sample of four: 25 % of the run. In force mode the same flight is warned of the 0.12 N
    clip alone."""
    flight = _flight(0.05, FW.full_pwm_thrust * factor, "force-torque")
    said = flight_sentences(flight, FW)
    high = [text for level, text in said if level == "warning"]
    assert len(high) == (factor > 1)
    if abs(factor - 1) > PWM_STEP:  # at 1 +- 1e-4, abs(factor - 1) is 9.999999999998899e-05: not >= 1e-4
        capped = _firmware_pwm(flight.thrusts)[1]
        assert bool(high) == capped.any() and np.array_equal(np.any(flight.thrusts > FW.full_pwm_thrust, axis=1),
                                                             capped), factor
    if high:
        asked, limit = re.match(r"the configured flight asks M2 for (\S+) N, above the (\S+) N full PWM gives a motor "
                                r"on a full battery \(4\.2 V\)", high[0]).groups()
        assert float(asked) > float(limit)  # the two written apart, the limit with as many digits as that takes
        assert limit == {1 + 1e-9: "0.278692927", 1 + 1e-4: "0.27869"}[factor] and "above it 25 % of the run" in high[0]
    force = [text for level, text in flight_sentences(_flight(0.05, FW.full_pwm_thrust * factor), FW)
             if level == "warning"]
    assert len(force) == 1 and "clips a motor in force mode" in force[0] and "full PWM" not in force[0]


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
    flight = crazyflie_platform.flight_thrusts(_exp(HIGH))
    assert out["firmware"]["min_thrust"] == 0.012817578393224994 and out["firmware"]["max_thrust"] == 0.12
    assert out["firmware"]["full_pwm_thrust"] == FW.full_pwm_thrust and out["firmware"]["full_pwm_voltage"] == 4.2
    assert out["flight"] == {"completed": True, "lowest": flight.lowest()[1], "highest": flight.highest()[1],
                             "stopped": flight.share_stopped(FW.min_thrust), "above_max": 0.0,
                             "above_full_pwm": None}
    assert {r["key"]: r["value"] for r in out["platform"]}["motors.min_thrust"] == 0.0


def _json_flight(tmp_path, *args) -> dict:
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", *args, "-o",
                                   str(tmp_path / "app"), "--json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)["crazyflie"]["flight"]


def test_the_json_gives_the_share_of_a_force_torque_flight_above_full_pwm_and_none_above_the_clip(tmp_path):
    """Force-torque mode caps at full PWM and has no clip at THRUST_MAX: its share above 0.12 N is null, though the
    flight asks for far more."""
    got = _json_flight(tmp_path, *HARD, "--mode", "force-torque")
    flight = crazyflie_platform.flight_thrusts(_exp(*HARD[1::2]), "force-torque")
    assert got["highest"] == flight.highest()[1] > FW.full_pwm_thrust
    assert got["above_full_pwm"] == float(np.mean(_firmware_pwm(flight.thrusts)[1])) > 0
    assert got["above_max"] is None


def test_the_json_gives_the_share_of_a_force_flight_above_the_clip_and_none_above_full_pwm(tmp_path):
    """Force mode clips at THRUST_MAX, under full PWM: its share above full PWM is null, though the design's
    rotors (allowed 0.4 N) ask for more than full PWM gives."""
    got = _json_flight(tmp_path, *HARD)
    flight = crazyflie_platform.flight_thrusts(_exp(*HARD[1::2]))
    assert got["highest"] == flight.highest()[1] > FW.full_pwm_thrust
    assert got["above_max"] == float(np.mean(np.any(flight.thrusts > FW.max_thrust, axis=1))) > 0
    assert got["above_full_pwm"] is None


@pytest.mark.parametrize("lowest, highest, kind", [(0.005, 0.1, "stops a motor"), (0.05, 0.3, "full PWM")])
def test_a_force_torque_flight_without_rotors_is_told_to_add_them_for_force_mode(lowest, highest, kind):
    """Without ``motors:`` force mode is refused (its refusal names the section to add): the warnings of a
    force-torque flight send it there with that section, the firmware's own rotors, not with one key to set."""
    for rotors in (True, False):
        said = [text for level, text in flight_sentences(_flight(lowest, highest, "force-torque", rotors), FW)
                if level == "warning"]
        assert len(said) == 1 and kind in said[0]
        add = (f"add the rotors force mode needs, {FW.motors_section()} (the firmware's; your vehicle's own where "
               "they differ), and export with --mode force (the app's saturation then asks no ")
        key = "min_thrust: 0.01282" if kind == "stops a motor" else "max_thrust: 0.12"
        assert (add in said[0]) == (not rotors)
        assert (f"export with --mode force and motors.{key} (the app's saturation then asks no " in said[0]) == rotors
        assert said[0].endswith("or fly gentler gains or offsets")


def test_the_rotors_a_force_torque_flight_without_them_is_told_to_add_take_it_to_force_mode(tmp_path):
    """crazyflie without ``motors:``, 5 m low, in force-torque mode: above full PWM, told to add the firmware's
    rotors and export in force mode, which refuses it as it is, with the same section; given the section, force
    mode exports and the firmware neither clips nor stops a motor the design does not."""
    warned = _lines(_export(tmp_path, "--set", "motors=null", *HARD[2:], "--mode", "force-torque"), "warning")
    assert len(warned) == 1 and f"add the rotors force mode needs, {FW.motors_section()}" in warned[0]
    res = CliRunner().invoke(app, ["export", "--to", "crazyflie", "-c", "crazyflie", "--set", "motors=null",
                                   "-o", str(tmp_path / "refused")])
    assert res.exit_code == 2 and f"add them, {FW.motors_section()} (the firmware's" in res.output
    section = FW.motors_section().replace("motors: ", "motors=", 1)
    fixed = _export(tmp_path, "--set", "motors=null", "--set", section, *HARD[2:])
    assert _lines(fixed, "warning") == [] and "in force mode" in fixed
