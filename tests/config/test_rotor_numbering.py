"""The vehicle's own rotor numbering and spins: the same vehicle in two numberings flies the same,
its per-rotor outputs permuted; the flight stacks' presets; bad numberings refused."""

from __future__ import annotations

import numpy as np
import pytest
from _solve import cfg_dict, run

from quadctl import config
from quadctl.errors import ConfigError
from quadctl.physics import motors

QUADCTL = ("front_right", "rear_right", "rear_left", "front_left")


def _vehicle(numbering, spin=None) -> dict:
    """mambo-200hz with rotor lag (rotor thrust states in sim.npz) and an offset that saturates a rotor."""
    data = cfg_dict("mambo-200hz")
    data["motors"].update(time_constant=0.02, numbering=numbering, spin=spin)
    data["simulation"].update(duration=2.0, initial_offset={"phi": 0.5, "pD": 0.3, "psi": 0.6})
    return data


def _permutation(order) -> list[int]:
    """Index, in quadctl's numbering, of each rotor of ``order`` (rotor 1 first)."""
    return [QUADCTL.index(p) for p in order]


@pytest.mark.parametrize("preset", ["px4", "betaflight"])
def test_the_same_vehicle_in_another_numbering_flies_the_same_with_its_rotors_permuted(preset):
    _, _, loop_a, sim_a = run(_vehicle("quadctl"))
    _, _, loop_b, sim_b = run(_vehicle(preset))
    perm = _permutation(motors.NUMBERINGS[preset])
    # the mixer is the same matrix with its rotors (columns of M, rows of M^-1) in the vehicle's order
    np.testing.assert_array_equal(loop_b.actuators.mix_inv, loop_a.actuators.mix_inv[:, perm])
    np.testing.assert_allclose(loop_b.actuators.mix, loop_a.actuators.mix[perm], rtol=1e-12, atol=1e-12)
    assert sim_a.status == sim_b.status == "ok"
    scale = np.abs(sim_a.x).max(axis=0) + 1e-12
    np.testing.assert_allclose(sim_b.x / scale, sim_a.x / scale, rtol=0, atol=1e-9)  # the same flight
    np.testing.assert_allclose(sim_b.rotor_thrust, sim_a.rotor_thrust[:, perm], rtol=0, atol=1e-9)
    frac_a = motors.saturation_fraction(loop_a.actuators, sim_a.u)
    frac_b = motors.saturation_fraction(loop_b.actuators, sim_b.u)
    assert max(frac_a.values()) > 0.01, "the offset must drive a rotor to its limit"
    assert list(frac_b.values()) == [frac_a[f"rotor {i + 1}"] for i in perm]


def test_the_presets_are_the_flight_stacks_published_orders():
    """Each preset's rotor 1..4 positions and spins (seen from above), as the stacks document them."""
    def of(name):
        m = motors.Motors(order=motors.NUMBERINGS[name])
        return list(zip(m.rotor_positions(), ["ccw" if s > 0 else "cw" for s in m.rotor_spins()]))

    assert of("px4") == [("front_right", "ccw"), ("rear_left", "ccw"), ("front_left", "cw"), ("rear_right", "cw")]
    assert of("betaflight") == [("rear_right", "cw"), ("front_right", "ccw"), ("rear_left", "ccw"),
                                ("front_left", "cw")]
    assert of("crazyflie") == [("front_right", "ccw"), ("rear_right", "cw"), ("rear_left", "ccw"),
                               ("front_left", "cw")]


def test_spins_set_the_sign_of_the_yaw_row():
    """Props out (every rotor turned the other way): the same mixer with the yaw row negated."""
    base = motors.Motors.from_config(config.from_dict(_vehicle("betaflight"), "c.yaml").motors)
    out = motors.Motors.from_config(config.from_dict(_vehicle("betaflight", ["ccw", "cw", "cw", "ccw"]),
                                                     "c.yaml").motors)
    np.testing.assert_array_equal(out.effectiveness()[:3], base.effectiveness()[:3])
    np.testing.assert_array_equal(out.effectiveness()[3], -base.effectiveness()[3])


def test_the_default_numbering_leaves_the_config_digest_as_it_was():
    data = cfg_dict("mambo-200hz")
    given = cfg_dict("mambo-200hz")
    given["motors"].update(numbering="quadctl", spin=None)
    assert config.from_dict(given, "c.yaml").digest() == config.from_dict(data, "c.yaml").digest()
    given["motors"]["numbering"] = "px4"
    assert config.from_dict(given, "c.yaml").digest() != config.from_dict(data, "c.yaml").digest()


@pytest.mark.parametrize(("motors_keys", "match"), [
    ({"numbering": ["front_right", "front_right", "rear_left", "front_left"]},
     r"^c\.yaml: motors\.numbering = .*: must name each of the 4 positions once, rotor 1 first"),
    ({"numbering": ["front_right", "rear_left", "front_lef", "rear_right"]},
     r"^c\.yaml: motors\.numbering\[2\] = \"front_lef\": unknown rotor position of layout x; did you mean "
     r"`front_left`\?"),
    ({"numbering": "px4", "spin": ["ccw", "cw", "ccw", "cw"]},
     r"^c\.yaml: motors\.spin = .*: diagonal rotors must turn alike and neighbours opposite \(front_right and "
     r"rear_left one way"),
    ({"layout": "+", "numbering": "px4"}, r"^c\.yaml: motors\.numbering = \"px4\": px4 is a quad-x order; for "
                                           r"layout \+ give the 4 positions"),
    ({"numbering": "ardupilot"}, r"^c\.yaml: motors\.numbering = \"ardupilot\": must be one of quadctl, crazyflie, "
                                 r"px4, betaflight, or a list of the 4 rotor positions, rotor 1 first$"),
    ({"numbering": "px5"}, r"^c\.yaml: motors\.numbering = \"px5\": must be one of quadctl, crazyflie, px4, "
                           r"betaflight, or a list of the 4 rotor positions, rotor 1 first; did you mean `px4`\?$"),
    ({"numbering": 4},
     r"^c\.yaml: motors\.numbering = 4: must be one of quadctl, .*, rotor 1 first; did you mean `px4`\?$"),
    ({"numbering": {"x": 1}},
     r"^c\.yaml: motors\.numbering = \{\"x\": 1\}: must be one of quadctl, .*, rotor 1 first$"),
    ({"numbering": [1, 2, 3, 4]}, r"^c\.yaml: motors\.numbering\[0\] = 1: must be text "
                                  r"\(and 3 more errors, at motors\.numbering\[1\], motors\.numbering\[2\] and "
                                  r"motors\.numbering\[3\]\)$"),
    ({"spin": ["cw", "ccw", "cw", "clockwise"]},
     r"^c\.yaml: motors\.spin\[3\] = \"clockwise\": must be one of cw, ccw; did you mean `ccw`\?$"),
])
def test_a_bad_numbering_is_refused_naming_the_key_and_fix(motors_keys, match):
    data = cfg_dict("mambo-200hz")
    data["motors"].update(motors_keys)
    with pytest.raises(ConfigError, match=match):
        config.from_dict(data, "c.yaml")
