"""``motors.thrust_curve``: three finite numbers (N), a curve that rises from 10 % of full command to full and has
a thrust there, its shape scaled to ``motors.max_thrust`` (:func:`quadctl.physics.motors.thrust_curve_problem`,
:func:`~quadctl.physics.motors.scaled_thrust_curve`); each refusal one line naming the key, its value and the fix."""

from __future__ import annotations

import pytest

from quadctl.config import overrides
from quadctl.config.loading import locate
from quadctl.errors import ConfigError

IDENTIFIED = "[0.02242, -0.009828, 0.1256]"
"""N: log10's curve (docs/guide/identify.md): least thrust at s = 0.039, below the 0.1 the rule starts at."""


def load(*sets):
    return overrides.load(locate("crazyflie"), sets)


@pytest.mark.parametrize("top", ["0.138192", "0.15", None])
def test_a_curve_loads_beside_any_max_thrust_and_is_flown_scaled_to_it(top):
    """The curve is the shape, max_thrust the one thrust at full command: a --set or a sweep of max_thrust on an
    identified config scales the curve (the cascade's PWM-to-thrust per rotor, sim.pid_mixing.pwm_thrust_curve)."""
    import numpy as np

    from quadctl.config.pid import resolve
    from quadctl.setup import setup_of
    from quadctl.sim.pid_mixing import pwm_thrust_curve

    cfg = load(*([f"motors.max_thrust={top}"] if top else []), f"motors.thrust_curve={IDENTIFIED}")
    assert cfg.motors.thrust_curve == [0.02242, -0.009828, 0.1256]
    hi = cfg.motors.max_thrust
    flown = pwm_thrust_curve(resolve("crazyflie"), setup_of(cfg).actuators)
    shape = np.array([0.02242, -0.009828, 0.1256])
    np.testing.assert_allclose(flown, np.tile(shape * hi / shape.sum(), (4, 1)), rtol=1e-15)
    np.testing.assert_allclose(flown.sum(axis=1), hi, rtol=1e-15)  # full PWM gives max_thrust


@pytest.mark.parametrize("top, curve, pattern", [
    # c0 and c2 swapped: falls from 0.1 (log15's curve, fitted on a narrow command range, falls below 0.31)
    ("0.138192", "[0.1256, -0.009828, 0.02242]",
     r"^--set: motors\.thrust_curve = \[0\.1256, -0\.009828, 0\.02242\]: its slope c1 \+ 2 c2 s is -0\.005344 N at "
     r"s = 0\.1: the thrust must rise with the command from s = 0\.1 to 1, else the feedback turns over; check the "
     r"order \[c0, c1, c2\], each in N$"),
    ("0.13647", "[0.06247, -0.1159, 0.1899]", r"its slope c1 \+ 2 c2 s is -0\.07792 N at s = 0\.1: "),
    ("0.14", "[0.0, 0.3, -0.16]", r"its slope c1 \+ 2 c2 s is -0\.02 N at s = 1: "),  # saturating past full
    (None, "[-0.2, 0.05, 0.05]", r"^--set: motors\.thrust_curve = \[-0\.2, 0\.05, 0\.05\]: its thrust at full command, "
     r"c0 \+ c1 \+ c2 = -0\.1 N, is not positive: there is no curve to scale to motors\.max_thrust"),
    (None, "[0.1, .nan, 0.1]", r"^--set: motors\.thrust_curve\[1\] = nan: must be a finite number"),
    (None, "[0.1, 0.1]", r"^--set: motors\.thrust_curve = \[0\.1, 0\.1\]: must be a list of exactly 3 items \(N: "
     r"\[c0, c1, c2\] of each rotor's thrust c0 \+ c1 s \+ c2 s\^2"),
])
def test_a_curve_that_is_no_rotors_is_refused_naming_the_key(top, curve, pattern):
    sets = ([f"motors.max_thrust={top}"] if top else []) + [f"motors.thrust_curve={curve}"]
    with pytest.raises(ConfigError, match=pattern):
        load(*sets)


def test_the_curve_has_its_unit_and_counts_in_the_digests_when_given():
    """Its unit is its description's (a sweep's column says N). Given, it is part of the vehicle's digests;
    absent, it is left out of them (schema.LATER_KEYS, VEHICLE_LATER_KEYS), so configs hashed before the key
    existed keep their digests: tests/config/test_bryson_rule.py holds the agilicious page's recorded
    started_from.vehicle_digest to it."""
    from quadctl.config.key_units import key_unit

    assert key_unit(load(), "motors.thrust_curve[2]") == "N"
    curved = load("motors.max_thrust=0.138192", f"motors.thrust_curve={IDENTIFIED}")
    same_top = load("motors.max_thrust=0.138192")
    assert curved.digest() != same_top.digest() and curved.vehicle_digest() != same_top.vehicle_digest()
