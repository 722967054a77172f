"""``lqr.<name>.bryson``: Bryson's rule evaluated on the vehicle a config describes, as ``quadctl init`` writes it,
and the note on a config whose vehicle no longer matches the template it was started from."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from _paths import ROOT

from quadctl import config
from quadctl.config import template as starter
from quadctl.config.notices import notices
from quadctl.errors import ConfigError
from quadctl.physics.motors import Motors, actuators_of, headroom
from quadctl.setup import setup_of


def iris(**changes) -> dict:
    data = yaml.safe_load(starter.config_text("mine", "iris", "hold"))
    for path, value in changes.items():
        section, key = path.split("__")
        data[section][key] = value
    return data


def test_the_rule_is_bryson_on_the_vehicle_as_loaded():
    """Q = 1/e^2, R = 1/(share room)^2 with the room of the vehicle's own rotors at hover (T = m g, the others
    0): the hand-made numbers, for the template's vehicle and for a lighter one."""
    for mass in (1.5, 0.752):
        cfg = config.from_dict(iris(vehicle__mass=mass))
        setup = setup_of(cfg)
        act = actuators_of(Motors.from_config(cfg.motors))
        room = headroom(act, [mass * 9.81, 0.0, 0.0, 0.0])
        rules = {name: w.bryson for name, w in cfg.lqr.items()}
        for name, (Q, R) in setup.weights.items():
            inp = cfg.partition()[name].inputs[0]
            np.testing.assert_allclose(np.diag(Q), 1 / np.square(rules[name].errors), rtol=1e-15)
            np.testing.assert_allclose(R, [[1 / (rules[name].headroom * min(room[inp])) ** 2]], rtol=1e-12)
    lighter = setup_of(config.from_dict(iris(vehicle__mass=0.752))).weights["altitude"][1]
    heavier = setup_of(config.from_dict(iris())).weights["altitude"][1]
    assert lighter[0, 0] != heavier[0, 0]  # the rule follows the vehicle (the nearer side: down, m g)


def test_the_template_writes_the_rule_and_includes_a_rotor_lag_it_has():
    text = starter.config_text("mine", "iris", "hold")
    cfg = config.parse(text, "mine.yaml")
    assert all(w.bryson is not None and w.Q is None for w in cfg.lqr.values())
    assert cfg.motors.time_constant == 0.0125 and cfg.controller.rotor_lag == "include"
    crazyflie = config.parse(starter.config_text("mine", "crazyflie", "hold"), "mine.yaml")
    assert crazyflie.motors.time_constant == 0.065 and crazyflie.controller.rotor_lag == "include"
    mambo = config.parse(starter.config_text("mine", "mambo", "hold"), "mine.yaml")
    assert mambo.motors.time_constant is None and mambo.controller.rotor_lag == "ignore"
    assert cfg.description.startswith("Started from the 3DR Iris")


def test_a_vehicle_changed_under_its_template_is_noted():
    same = config.from_dict(iris())
    assert not [n for n in notices(same, "mine.yaml") if n.key == "description"]
    changed = config.from_dict(iris(vehicle__mass=0.752))
    found = [n for n in notices(changed, "mine.yaml") if n.key == "description"]
    assert len(found) == 1 and "iris template" in found[0].message
    assert changed.vehicle_digest() in found[0].message  # the value that silences it


@pytest.mark.parametrize(("change", "match"), [
    ({"Q": [1, 1]}, r"lqr.altitude.bryson.*remove Q and R"),
    ({"bryson": {"errors": [0.5], "headroom": 0.4}}, r"lqr.altitude.bryson.errors.*expected 2 values"),
])
def test_a_rule_that_cannot_be_evaluated_is_refused(change, match):
    data = iris()
    data["lqr"]["altitude"] = {**data["lqr"]["altitude"], **change}
    with pytest.raises(ConfigError, match=match):
        config.from_dict(data)


def test_weights_neither_given_nor_ruled_are_refused():
    data = iris()
    data["lqr"]["altitude"] = {"R": [1.0]}
    with pytest.raises(ConfigError, match=r"lqr.altitude.*has no Q"):
        config.from_dict(data)


def test_a_rule_needs_a_range_to_take_r_from():
    data = iris()
    data.pop("motors")
    data["controller"]["rotor_lag"] = "ignore"
    with pytest.raises(ConfigError, match=r"nothing limits"):
        config.from_dict(data)


AGILICIOUS_EDITS = {
    ("description",), ("vehicle", "mass"), ("vehicle", "inertia"), ("vehicle", "drag"), ("controller", "rate"),
    ("motors", "thrust_coefficient"), ("motors", "torque_coefficient"), ("motors", "max_thrust"),
    ("motors", "time_constant"), ("motors", "numbering"), ("motors", "spin"), ("motors", "positions"),
    ("started_from", "vehicle_digest"),
}
"""The edits docs/guide/vehicle.md makes to `quadctl init agilicious --from iris` (and the digest the note asks for)."""


def _leaves(data, prefix=()):
    if isinstance(data, dict):
        for key, value in data.items():
            yield from _leaves(value, (*prefix, key))
    else:
        yield prefix, data


def test_the_agilicious_is_the_iris_template_with_the_pages_few_edits():

    path = ROOT / "docs" / "configs" / "agilicious.yaml"
    ours = config.load(str(path))
    start = config.parse(starter.config_text("agilicious", "iris", "hold"), "agilicious.yaml")
    a, b = dict(_leaves(start.model_dump(mode="json"))), dict(_leaves(ours.model_dump(mode="json")))
    changed = {key for key in a.keys() | b.keys() if a.get(key) != b.get(key)}
    assert changed == AGILICIOUS_EDITS, changed ^ AGILICIOUS_EDITS
    assert ours.vehicle_digest() == ours.started_from.vehicle_digest  # no note left
    assert ours.motors.time_constant == 0.033 and ours.controller.rotor_lag == "include"
    assert ours.controller.rate == 500 and ours.vehicle.mass == 0.752


def test_the_agilicious_keeps_its_margins_with_its_geometry_and_motor_lag_in_the_loop():

    from quadctl.design.margins import THIN_GAIN_MARGIN_DB, THIN_PHASE_MARGIN_DEG
    from quadctl.pipeline import Stages

    setup = setup_of(config.load(str(ROOT / "docs" / "configs" / "agilicious.yaml")))
    st = Stages(setup)
    assert setup.rotor_time_constant == 0.033 and st.design.lag_time_constant == 0.033
    mix = setup.actuators.mix_inv  # roll arm 0.10 m, pitch arm 0.075 m
    np.testing.assert_allclose(np.abs(mix[1]), 0.10, rtol=1e-15)
    np.testing.assert_allclose(np.abs(mix[2]), 0.075, rtol=1e-15)
    from quadctl.design import margin_findings

    found = margin_findings.all_margins(st.design, st.decoupled, st.linear.A, st.linear.B,
                                        rotor_time_constant=setup.rotor_time_constant)
    assert all(not m.thin for m in found), [(m.loop, m.model, m.thin) for m in found if m.thin]
    assert min(m.phase_margin_deg for m in found) > THIN_PHASE_MARGIN_DEG
    assert min(min(abs(g) for g in m.gain_margin_db) for m in found) > THIN_GAIN_MARGIN_DB


def test_a_vehicle_the_rule_finds_no_room_on_trims_but_does_not_design():
    """A vehicle too heavy for its rotors: the stages without weights run, the design is refused in one line."""
    from quadctl import pipeline

    setup = setup_of(config.from_dict(iris(vehicle__mass=50.0)))
    assert setup.weight_error is not None and "lqr.altitude.bryson: T has no room" in setup.weight_error
    st = pipeline.Stages(setup)
    assert st.linear.A.shape == (12, 12)
    with pytest.raises(ConfigError, match="no room around the trim"):
        _ = st.design
