"""``motors.thrust_curve``: three finite numbers (N), their sum the thrust at full command, ``motors.max_thrust``,
and a curve that rises from 10 % of full command to full (:func:`quadctl.physics.motors.thrust_curve_problem`);
each refusal one line naming the key, its value and the fix."""

from __future__ import annotations

import pytest

from quadctl.config import overrides
from quadctl.config.loading import locate
from quadctl.errors import ConfigError

IDENTIFIED = "[0.02242, -0.009828, 0.1256]"
"""N: log10's curve (docs/guide/identify.md): least thrust at s = 0.039, below the 0.1 the rule starts at."""


def load(*sets):
    return overrides.load(locate("crazyflie"), sets)


@pytest.mark.parametrize("top", ["0.138192", "0.1381920001"])
def test_a_curve_whose_full_command_thrust_is_max_thrust_loads(top):
    cfg = load(f"motors.max_thrust={top}", f"motors.thrust_curve={IDENTIFIED}")
    assert cfg.motors.thrust_curve == [0.02242, -0.009828, 0.1256]


@pytest.mark.parametrize("top, curve, pattern", [
    # max_thrust left at the config's (Förster's 0.159166 N), or rounded by hand: the message gives the number
    (None, IDENTIFIED, r"^--set: motors\.thrust_curve = \[0\.02242, -0\.009828, 0\.1256\]: gives c0 \+ c1 \+ c2 = "
     r"0\.138192 N at full command, but motors\.max_thrust = 0\.159166 N: they are the same thrust; set "
     r"motors\.max_thrust: 0\.138192, correct the curve, or remove it \(motors\.thrust_curve: null\) to fly the "
     r"flight stack's own curve scaled to max_thrust$"),
    ("0.1382", IDENTIFIED, r"c0 \+ c1 \+ c2 = 0\.138192 N at full command, but motors\.max_thrust = 0\.1382 N"),
    # c0 and c2 swapped: falls from 0.1 (log15's curve, fitted on a narrow command range, falls below 0.31)
    ("0.138192", "[0.1256, -0.009828, 0.02242]",
     r"^--set: motors\.thrust_curve = \[0\.1256, -0\.009828, 0\.02242\]: its slope c1 \+ 2 c2 s is -0\.005344 N at "
     r"s = 0\.1: the thrust must rise with the command from s = 0\.1 to 1, else the feedback turns over; check the "
     r"order \[c0, c1, c2\], each in N$"),
    ("0.13647", "[0.06247, -0.1159, 0.1899]", r"its slope c1 \+ 2 c2 s is -0\.07792 N at s = 0\.1: "),
    ("0.14", "[0.0, 0.3, -0.16]", r"its slope c1 \+ 2 c2 s is -0\.02 N at s = 1: "),  # saturating past full
    (None, "[0.1, .nan, 0.1]", r"^--set: motors\.thrust_curve\[1\] = nan: must be a finite number"),
    (None, "[0.1, 0.1]", r"^--set: motors\.thrust_curve = \[0\.1, 0\.1\]: must be a list of exactly 3 items \(N: "
     r"\[c0, c1, c2\] of each rotor's thrust c0 \+ c1 s \+ c2 s\^2"),
])
def test_a_curve_that_is_no_rotors_is_refused_naming_the_key(top, curve, pattern):
    sets = ([f"motors.max_thrust={top}"] if top else []) + [f"motors.thrust_curve={curve}"]
    with pytest.raises(ConfigError, match=pattern):
        load(*sets)


def test_a_max_thrust_changed_under_a_curve_is_refused_naming_the_way_to_fly_it():
    """An identified config carries the curve; a --set (or a sweep) of max_thrust alone leaves the two apart.
    The message names the key to drop, and dropping it flies the new max_thrust (the preset's curve scaled)."""
    with pytest.raises(ConfigError, match=r"or remove it \(motors\.thrust_curve: null\)"):
        load(f"motors.thrust_curve={IDENTIFIED}", "motors.max_thrust=0.15")
    cfg = load(f"motors.thrust_curve={IDENTIFIED}", "motors.max_thrust=0.15", "motors.thrust_curve=null")
    assert cfg.motors.max_thrust == 0.15 and cfg.motors.thrust_curve is None


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
