"""The Crazyflie cascade's PWM becomes thrust by the vehicle's own curve (``motors.thrust_curve``), else by the
firmware's, scaled to ``motors.max_thrust``.

The law's rotor thrusts at chosen PWM commands must be ``c0 + c1 s + c2 s^2`` worked out here from the numbers
(through the loop the runners are generated from: its constants, its builder); without a curve, Förster's
``max_thrust (a s^2 + b s) / (a + b)``. The lifted cascade's margins on the identified curve must move from
those on the firmware's by the ratio of the two curves' slopes at hover, as a loop gain: every loop is broken at
a plant input, and the slope of thrust per PWM is a factor of each.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

IDENTIFIED = (0.02242, -0.009828, 0.1256)
"""N: c0, c1, c2 that ``quadctl identify`` fits to log10 (docs/guide/identify.md), its max_thrust their sum."""
TOP = 0.138192
FORSTER = (0.091492681, 0.067673604)
"""N: the firmware's pwmToThrustA and pwmToThrustB (pid_presets.yaml), Förster's bench curve."""
THRUST_RTOL = 1e-12
"""Relative: the law's arithmetic on four numbers of order 0.1 N, rounded once or twice."""
THRUST_ATOL = 1e-15
"""N: a rotor at no PWM on Förster's curve (0 N) comes back through the mixing and its inverse as ~1e-19 N."""


def crazyflie(*sets):
    import quadctl as qc
    from quadctl.config import overrides
    from quadctl.config.loading import locate

    return qc.Stages(qc.setup_of(overrides.load(locate("crazyflie"), sets)))


CURVE_SETS = (f"motors.max_thrust={TOP!r}", f"motors.thrust_curve={list(IDENTIFIED)}")


@pytest.fixture(scope="module")
def identified():
    return crazyflie(*CURVE_SETS)


@pytest.fixture(scope="module")
def forster():
    return crazyflie(f"motors.max_thrust={TOP!r}")


def rotor_thrusts(stages, base_pwm, torques):
    """N (4,): the rotor thrusts the cascade's law commands with its thrust setpoint at ``base_pwm`` and its rate
    PIDs' outputs ``torques`` (roll, pitch, yaw PWM), every other gain zero, evaluated by the loop's generated law
    (its constants as every runner packs them); and the PWM (4,) each rotor got."""
    import casadi as ca

    from quadctl.config.pid import NAMES, resolve
    from quadctl.layout import STATE_INDEX
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim import pid_mixing
    from quadctl.sim.builder import build

    zero = {n: 0.0 for n in NAMES if n.endswith(("_kp", "_ki", "_kd"))}
    gains = resolve("crazyflie").with_values(**{**zero, "rate_roll_kp": 1.0, "rate_pitch_kp": 1.0, "rate_yaw_kp": 1.0,
                                                "gyro_lpf_hz": 0.0, "thrust_base": base_pwm, "thrust_min": 0.0})
    loop = pid_loop_of(stages.setup, stages.linear, gains)
    x = np.array(loop.x_trim, dtype=float)
    x[STATE_INDEX["p"]:STATE_INDEX["p"] + 3] = -np.radians(torques)  # deg/s of rate error, kp 1: these outputs
    X = loop.initial_loop_state(x)
    spec = loop.spec()
    u, _ = build(spec).law(X, 0.0, loop.constants(1.0 / gains["rate_hz"]), np.zeros(spec.n_exo))
    act = loop.actuators
    pwm = np.asarray(pid_mixing.legacy_pwm(base_pwm, ca.DM(torques), ca.DM(act.mix))).ravel()
    return act.mix @ np.asarray(u, dtype=float).ravel(), pwm


COMMANDS = [(36000.0, (0.0, 0.0, 0.0)), (41300.0, (3000.0, -2000.0, 1500.0)), (20000.0, (-8000.0, 6000.0, -900.0)),
            (60000.0, (4000.0, 2000.0, 0.0)), (7000.0, (0.0, 0.0, 1000.0)), (62000.0, (9000.0, 0.0, 1000.0)),
            (3000.0, (-9000.0, 0.0, 0.0))]
"""PWM thrust setpoints and roll, pitch and yaw outputs: the firmware's hover base, the identified hover (s 0.63)
with torques, the least thrust with large torques, near full, low (below the curve's minimum at s 0.04 for
one rotor: the curve, not a clip), and two that ask one rotor for more than full PWM (67500) and two for less
than none (-1500): the firmware clamps each motor's PWM to 0..65535, so those fly the curve's ends."""


def clamped(pwm):
    """The command fraction ``s`` of each rotor's ``pwm``, clamped as the firmware clamps a motor's PWM to
    its 16 bits (power_distribution_quadrotor.c, limitUint16)."""
    return np.clip(pwm, 0.0, 65535.0) / 65535.0


@pytest.mark.parametrize("base, torques", COMMANDS)
def test_the_cascade_flies_the_vehicles_curve_c0_plus_c1_s_plus_c2_s_squared(identified, base, torques):
    got, pwm = rotor_thrusts(identified, base, torques)
    c0, c1, c2 = IDENTIFIED
    s = clamped(pwm)
    want = c0 + c1 * s + c2 * s * s
    assert len(set(np.round(pwm))) > 1 or not any(torques)  # the rotors' commands differ: each its own thrust
    np.testing.assert_allclose(got, want, rtol=THRUST_RTOL, atol=THRUST_ATOL)


@pytest.mark.parametrize("base, torques", COMMANDS)
def test_without_a_curve_the_cascade_flies_forsters_scaled_to_max_thrust(forster, base, torques):
    got, pwm = rotor_thrusts(forster, base, torques)
    a, b = FORSTER
    s = clamped(pwm)
    np.testing.assert_allclose(got, TOP * (a * s * s + b * s) / (a + b), rtol=THRUST_RTOL, atol=THRUST_ATOL)


def hover_slope(curve, hover):
    """N per unit command: the slope ``c1 + 2 c2 s`` of ``curve`` (c0, c1, c2) where it gives ``hover`` N."""
    c0, c1, c2 = curve
    s = (-c1 + math.sqrt(c1 * c1 - 4 * c2 * (c0 - hover))) / (2 * c2)
    return c1 + 2 * c2 * s


MARGIN_TOL_DB = 1e-6
"""dB: the exact gain margins are the lifted loops' poles on the unit circle, found to ~1e-10 relative."""


def test_the_identified_curves_lower_slope_at_hover_raises_every_gain_margin_by_its_ratio(identified, forster):
    """At hover (m g / 4 a rotor: the integrators bring the PWM there) the identified curve rises 5 % less steeply
    than Förster's scaled to the same max_thrust; every loop's gain is that much lower, so each of its gain
    margins moves by -20 log10 of the ratio, +0.45 dB (upper up, lower toward zero)."""
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim.cascade_margins import cascade_margins

    setup = identified.setup
    hover = setup.vehicle.mass * setup.vehicle.gravity / 4
    a, b = FORSTER
    ratio = hover_slope(IDENTIFIED, hover) / hover_slope((0.0, TOP * b / (a + b), TOP * a / (a + b)), hover)
    shift = -20 * math.log10(ratio)
    assert 0.4 < shift < 0.5  # the curve is less steep at hover: less loop gain
    after = cascade_margins(pid_loop_of(setup, identified.linear))
    before = cascade_margins(pid_loop_of(forster.setup, forster.linear))
    for old, new in zip(before, after):
        assert new.stable and old.stable
        for was, now in zip(old.gain_margin_db, new.gain_margin_db):
            if was is None or not math.isfinite(was):
                continue
            assert now - was == pytest.approx(shift, abs=MARGIN_TOL_DB), (new.input, was, now)
