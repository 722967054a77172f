"""Rotor positions as built (``motors.positions``): the mixer from the geometry, the presets as
shorthands for it (bit for bit), and geometries that cannot be mixed refused."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _solve import cfg_dict, run

from quadctl import config
from quadctl.errors import ConfigError
from quadctl.physics import motors

SPIN = ["ccw", "cw", "ccw", "cw"]


def _hand_mixer(a: float, b: float, k: float) -> np.ndarray:
    """Rotors at (a, b), (-a, b), (-a, -b), (a, -b) (x forward, y right), spins + - + -: each rotor
    carries a quarter of the thrust, of the roll torque over the arm b, pitch over a, yaw over k."""
    return 0.25 * np.array([[1.0, -1.0 / b, 1.0 / a, 1.0 / k],
                            [1.0, -1.0 / b, -1.0 / a, -1.0 / k],
                            [1.0, 1.0 / b, -1.0 / a, 1.0 / k],
                            [1.0, 1.0 / b, 1.0 / a, -1.0 / k]])


@pytest.mark.parametrize(("a", "b", "k"), [(0.075, 0.10, 0.0241), (0.13, 0.22, 0.06), (0.05, 0.05, 0.00241)])
def test_a_stretched_x_mixes_as_the_hand_derived_mixer(a, b, k):
    data = cfg_dict("mambo-200hz")
    data["motors"].update(positions=[[a, b], [-a, b], [-a, -b], [a, -b]], spin=SPIN, torque_coefficient=k)
    m = motors.Motors.from_config(config.from_dict(data, "c.yaml").motors)
    hand = _hand_mixer(a, b, k)
    np.testing.assert_allclose(m.mixer(), hand, rtol=1e-15, atol=0)
    act = motors.actuators_of(m)
    np.testing.assert_array_equal(act.mix, m.mixer())
    np.testing.assert_allclose(act.mix_inv @ hand, np.eye(4), rtol=0, atol=1e-15)


def test_the_x_preset_is_positions_at_45_degrees_bit_for_bit():
    preset = cfg_dict("mambo-200hz")
    d = preset["motors"]["arm_length"] / math.sqrt(2.0)
    given = cfg_dict("mambo-200hz")
    given["motors"].update(positions=[[d, d], [-d, d], [-d, -d], [d, -d]], spin=SPIN)
    _, _, loop_a, sim_a = run(preset)
    _, _, loop_b, sim_b = run(given)
    np.testing.assert_array_equal(loop_b.actuators.mix, loop_a.actuators.mix)
    np.testing.assert_array_equal(loop_b.actuators.mix_inv, loop_a.actuators.mix_inv)
    np.testing.assert_array_equal(sim_b.x, sim_a.x)
    np.testing.assert_array_equal(sim_b.u, sim_a.u)


def test_the_plus_preset_is_positions_on_the_axes():
    L = 0.0624
    plus = motors.Motors(layout="+", arm_length=L)
    given = motors.Motors(xy=((L, 0.0), (0.0, L), (-L, 0.0), (0.0, -L)), spins=(1.0, -1.0, 1.0, -1.0))
    np.testing.assert_array_equal(given.effectiveness(), plus.effectiveness())


def test_a_stretched_x_gives_roll_and_pitch_their_own_moment_arms():
    """The Agilicious (rotors at x = +-0.075 m, y = +-0.10 m): one rotor's thrust step gives a roll
    torque of 0.10 m and a pitch torque of 0.075 m per N, which no arm length of the x preset gives."""
    m = motors.Motors(xy=((0.075, 0.10), (-0.075, 0.10), (-0.075, -0.10), (0.075, -0.10)),
                      spins=(1.0, -1.0, 1.0, -1.0))
    np.testing.assert_array_equal(m.effectiveness()[1:3, 0], [-0.10, 0.075])
    assert "rotors at (0.075, 0.1)" in m.describe()


@pytest.mark.parametrize(("keys", "match"), [
    ({"positions": [[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]]},
     r"^c\.yaml: motors\.spin = null: motors\.positions needs each rotor's turning direction"),
    ({"positions": [[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]], "spin": SPIN, "numbering": "px4"},
     r"^c\.yaml: motors\.numbering = \"px4\": motors\.positions are already in the vehicle's order"),
    ({"positions": [[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]], "spin": ["ccw", "ccw", "cw", "cw"]},
     r"^c\.yaml: motors\.positions = .*: with motors\.spin = .* the rotors cannot command thrust, roll, pitch "
     r"and yaw independently \(the reciprocal condition number of the mixer is \S+, not above 1e-06\); put the "
     r"rotors around the centre of mass"),
    ({"positions": [[0.1, 0.0], [0.05, 0.0], [-0.1, 0.0], [-0.05, 0.0]], "spin": SPIN},  # one line: no roll
     r"^c\.yaml: motors\.positions = .*: .*cannot command"),
    ({"positions": [[0.0, 0.0], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]], "spin": SPIN},
     r"^c\.yaml: motors\.positions\[0\] = \[0, 0\]: a rotor at the centre of mass gives no torque"),
])
def test_a_geometry_that_cannot_be_mixed_is_refused(keys, match):
    data = cfg_dict("mambo-200hz")
    data["motors"].update(keys)
    with pytest.raises(ConfigError, match=match):
        config.from_dict(data, "c.yaml")


def test_positions_absent_leave_the_config_digest_as_it_was():
    data = cfg_dict("mambo-200hz")
    given = cfg_dict("mambo-200hz")
    given["motors"]["positions"] = None
    assert config.from_dict(given, "c.yaml").digest() == config.from_dict(data, "c.yaml").digest()
