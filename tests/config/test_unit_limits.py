"""One range rule per unit: every key that holds a position, a velocity or a heading is held to its
unit's limit (``UNIT_LIMITS``), the newer keys (setpoints, waypoints, a mission's speed, a schedule's
values) as the trim's; a heading past a turn is named as the angle in degrees it most likely is."""

from __future__ import annotations

import copy
import re

import pytest
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app
from quadctl.config import schema, schema_paths, yamlio
from quadctl.config.key_units import key_unit
from quadctl.config.unit_limits import SCHEDULE_UNITS, UNIT_KEYS, UNIT_LIMITS
from quadctl.errors import ConfigError
from quadctl.text.messages import parse_key_path, show

runner = CliRunner()
HOVER = yamlio.load(config.bundled("hover").text, "hover.yaml", ConfigError)
SCAFFOLD = {
    "setpoints": {"simulation": {"reference": {"setpoints": [{"t": 1.0, "position": [0.0, 0.0, -1.0],
                                                              "velocity": [0.0, 0.0, 0.0], "yaw": 0.0}]}}},
    "waypoints": {"simulation": {"reference": {"waypoints": [{"position": [1.0, 0.0, -1.0], "yaw": 0.0}]}}},
    "schedule": {"schedule": {"variable": "speed", "values": [0.0, 1.0]}},
    "gusts": {"simulation": {"wind": {"gusts": [{"start": 1.0, "length": 1.0, "amplitude": [1.0, 0.0, 0.0]}]}}},
    "positions": {"motors": {"positions": [[0.03, 0.04], [-0.03, 0.04], [-0.03, -0.04], [0.03, -0.04]],
                             "spin": ["ccw", "cw", "ccw", "cw"]}},
}
"""The section each pattern of UNIT_KEYS needs, added to the hover config."""


def _config_with(path: str, value, variable: str = "speed") -> dict:
    """The hover config with ``value`` at the key path ``path`` (an index for each ``[*]``)."""
    data = copy.deepcopy(HOVER)
    for part, extra in SCAFFOLD.items():
        if part in path or part == "waypoints" and path.startswith("simulation.reference.") and "setpoints" not in path:
            data = {**data, **copy.deepcopy(extra)}
            if part == "waypoints":  # a mission whose reach (speed x duration, MAX_REACH) is past 1e6 m
                data["simulation"]["reference"]["speed"] = 1000.0
                data["simulation"]["duration"] = 86400.0
    if "schedule" in data:
        data["schedule"]["variable"] = variable
    node = data
    keys = parse_key_path(path)
    for key in keys[:-1]:
        if isinstance(node, dict):
            node = node.setdefault(key, {})
        else:
            node = node[key]
    if isinstance(keys[-1], int) and keys[-1] >= len(node):
        node.extend([0.0] * (keys[-1] + 1 - len(node)))
    node[keys[-1]] = value
    return data


def _cases():
    """(key path, unit, schedule variable) of each UNIT_KEYS pattern: the first item where ``[*]``, the
    last for a schedule's values (they increase), every variable of a schedule."""
    for pattern, unit in UNIT_KEYS:
        if unit == "schedule.variable":
            for variable, its in SCHEDULE_UNITS.items():
                yield pattern.replace("[*]", "[1]"), its, variable
        else:
            yield pattern.replace("[*]", "[0]"), unit, "speed"


CASES = list(_cases())


@pytest.mark.parametrize("path,unit,variable", CASES, ids=[f"{c[0]}-{c[2]}" if "schedule" in c[0] else c[0]
                                                         for c in CASES])
def test_a_value_past_its_unit_limit_is_refused_naming_its_key(path, unit, variable):
    limit = UNIT_LIMITS[unit]
    beyond = 90.0 if unit.startswith("rad") else limit * 1.5
    with pytest.raises(ConfigError) as err:
        config.from_dict(_config_with(path, beyond, variable), "c.yaml")
    shown = re.escape(f"c.yaml: {path} = {show(beyond)}: ")
    if unit.startswith("rad"):  # a heading in degrees, named so with the value in rad (a path's: two turns)
        turns = round(limit / 6.283185307179586)
        assert re.fullmatch(shown + rf"that is 5157 deg, beyond {360 * turns} deg; angles are in rad: for 90 deg "
                            r"write 1\.571", str(err.value)), str(err.value)
    elif unit == "s":  # the longest run, as simulation.duration's
        assert re.fullmatch(shown + re.escape("must be at most 86400 s (one day; set "
                                              "QUADCTL_MAX_DURATION to allow longer)"), str(err.value)), str(err.value)
    else:
        assert re.fullmatch(shown + re.escape(f"must be at most {limit:g} {unit} in magnitude"),
                            str(err.value)), str(err.value)
    assert err.value.key == path


@pytest.mark.parametrize("path,unit,variable", CASES, ids=[f"{c[0]}-{c[2]}" if "schedule" in c[0] else c[0]
                                                         for c in CASES])
def test_a_value_at_its_unit_limit_is_taken(path, unit, variable):
    if path == "controller.delay":
        pytest.skip("a delay has a tighter rule of its own (MAX_DELAY_SAMPLES, at a rate)")
    at = UNIT_LIMITS[unit] * (1 - 1e-12)
    cfg = config.from_dict(_config_with(path, at, variable), "c.yaml")
    assert cfg is not None


def _unit_of(field) -> str | None:
    """The unit a field's description starts with (``"m, NED"`` -> ``m``), if it is one of UNIT_LIMITS."""
    first = re.split(r"[,;: ]", field.description or "", maxsplit=1)[0]
    return first if first in UNIT_LIMITS else None


def _bounded(annotation, metadata=()) -> bool:
    """Whether the schema itself bounds the values above (an ``le`` in the annotation or an item's)."""
    if any(getattr(m, "le", None) is not None or getattr(m, "lt", None) is not None for m in metadata):
        return True
    meta = getattr(annotation, "__metadata__", ())
    if any(getattr(m, "le", None) is not None for m in meta):
        return True
    for m in meta:
        if _bounded(None, getattr(m, "metadata", ())):
            return True
    return any(_bounded(arg) for arg in getattr(annotation, "__args__", ()) or ())


def _unit_fields(model, prefix=""):
    """(key path pattern, unit) of every field of the schema whose description starts with a unit of
    UNIT_LIMITS and that the schema does not bound itself."""
    for name, field in model.model_fields.items():
        inner = schema_paths.first_model(field.annotation)
        depth = str(field.annotation).count("list[")  # a list of lists (rotor positions): each item's items
        path = f"{prefix}{name}" + "[*]" * depth
        if inner is not None:
            yield from _unit_fields(inner, path + ".")
            continue
        unit = _unit_of(field)
        if unit is not None and not _bounded(field.annotation, field.metadata):
            yield path, unit


def test_every_key_with_a_unit_is_held_to_its_limit():
    """A key added with a position, velocity or heading unit and no bound of its own joins UNIT_KEYS."""
    found = set(_unit_fields(schema.Config))
    held = {(p, u) for p, u in UNIT_KEYS}
    missing = {(p, u) for p, u in found if (p, u) not in held and p not in dict(UNIT_KEYS)}
    assert missing == set(), missing


def test_the_time_limit_follows_the_environment(monkeypatch):
    """QUADCTL_MAX_DURATION raises the limit of every time, a setpoint's as the duration's."""
    data = _config_with("simulation.reference.setpoints[0].t", 2e5)
    with pytest.raises(ConfigError, match=r"setpoints\[0\]\.t = 200000: must be at most 86400 s"):
        config.from_dict(data, "c.yaml")
    monkeypatch.setenv("QUADCTL_MAX_DURATION", "3e5")
    assert config.from_dict(data, "c.yaml").simulation.reference.setpoints[0].t == 2e5


@pytest.mark.parametrize("key,value", [
    ("simulation.reference.setpoints[0].yaw", "90"),
    ("schedule.values", "[0, 90]"),
    ("simulation.reference.speed", "1e9"),
])
def test_a_slip_on_the_command_line_is_refused_before_anything_is_written(tmp_path, key, value):
    """The catalogue's examples: a setpoint's and a yaw schedule's 90 flown as rad, a mission at 1e9 m/s."""
    sets = {"simulation.reference.setpoints[0].yaw":
            ["--set", "simulation.reference={setpoints: [{t: 1, yaw: 0}]}"],
            "schedule.values": ["--set", "schedule={variable: yaw, values: [0, 1]}"],
            "simulation.reference.speed": ["--set", "simulation.reference={waypoints: [{position: [1, 0, -1]}]}"]}
    out = tmp_path / "out"
    res = runner.invoke(app, ["simulate", "-c", "hover", "-o", str(out), *sets[key], "--set", f"{key}={value}"])
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("quadctl: error: --set: "), res.stderr
    assert ("that is 5157 deg" in lines[0]) == (key != "simulation.reference.speed"), lines[0]
    assert not out.exists() or not any(out.iterdir())


# ---------------------------------------------------------------------------------------
# The unit of a key (quadctl.config.key_units.key_unit): a sweep's parameter columns


@pytest.mark.parametrize("name,path,unit", [
    ("forward", "vehicle.mass", "kg"),
    ("forward", "vehicle.inertia[2]", "kg m^2"),
    ("forward", "vehicle.drag[0]", "1/(m/s)"),           # F = -T Kc V: N = N Kc m/s
    ("forward", "trim.velocity_ned[0]", "m/s"),
    ("forward", "trim.yaw", "rad"),
    ("forward", "simulation.initial_offset.phi", "rad"),
    ("forward", "lqr.roll.Q[0]", "1/(m/s)^2"),           # roll's states: v, phi, p
    ("forward", "lqr.roll.Q[1]", "1/rad^2"),
    ("forward", "lqr.roll.Q[2]", "1/(rad/s)^2"),
    ("forward", "lqr.altitude.R[0]", "1/N^2"),           # thrust
    ("forward", "lqr.yaw.R[0]", "1/(N m)^2"),            # yaw torque
    ("mambo-200hz", "lqr.altitude.Q[0]", "1/m^2"),       # altitude: pD, w, then the integral of pD (m s)
    ("mambo-200hz", "lqr.altitude.Q[2]", "1/(m s)^2"),
    ("mambo-200hz", "lqr.roll.R[0]", "1/(N m)^2"),
    ("mambo-200hz", "motors.thrust_coefficient", "N/(rad/s)^2"),
    ("mambo-200hz", "motors.torque_coefficient", "N m/N"),
    ("mambo-200hz", "motors.max_thrust", "N"),
    ("mambo-200hz", "motors.time_constant", "s"),
    ("mambo-200hz", "controller.rate", "Hz"),
    ("mambo-200hz", "simulation.noise.force[2]", "N"),
    ("mambo-200hz", "simulation.noise.torque[0]", "N m"),
    ("mambo-200hz", "simulation.noise.sensor.p", "rad/s"),
    ("mambo-200hz", "simulation.plant.mass", "kg"),
])
def test_a_bundled_configs_keys_have_their_units(name, path, unit):
    assert key_unit(config.load(name), path) == unit


def test_lqr_weights_take_the_units_of_the_partition_states_then_integrals():
    """Q's diagonal runs over the subsystem's states in the partition's order, then the integrals in the
    order of ``integral``: the integral of an angle in rad s, of a rate in rad/s in rad; Bryson's errors
    are in the same units, not squared."""
    data = copy.deepcopy(HOVER)
    data["subsystems"] = {"altitude": {"states": ["pD", "w"], "inputs": ["T"]},
                          "roll": {"states": ["phi", "p", "v"], "inputs": ["A"]},
                          "pitch": {"states": ["u", "theta", "q"], "inputs": ["E"]},
                          "yaw": {"states": ["psi", "r"], "inputs": ["R"]},
                          "guidance": {"states": ["pN", "pE"], "inputs": ["u", "psi"], "regulate": False}}
    data["lqr"]["roll"] = {"Q": [100, 0.25, 1, 10, 1], "R": [40000], "integral": ["p", "phi"]}
    data["lqr"]["pitch"] = {"bryson": {"errors": [1.0, 0.1, 2.0, 0.5], "headroom": 0.2}, "integral": ["theta"]}
    data["motors"] = {}  # the Mambo's rotors: the headroom Bryson's R takes
    cfg = config.from_dict(data, "c.yaml")
    assert [key_unit(cfg, f"lqr.roll.Q[{i}]") for i in range(5)] == [
        "1/rad^2", "1/(rad/s)^2", "1/(m/s)^2", "1/rad^2", "1/(rad s)^2"]
    assert key_unit(cfg, ("lqr", "roll", "Q", 1)) == "1/(rad/s)^2"  # the path as the sweep parses it
    assert [key_unit(cfg, f"lqr.pitch.bryson.errors[{i}]") for i in range(4)] == ["m/s", "rad", "rad/s", "rad s"]
    assert key_unit(cfg, "lqr.roll.R[0]") == "1/(N m)^2"
    data["lqr"]["roll"]["Q"] = [[100, 0, 0, 0, 0], [0, 0.25, 0, 0, 0], [0, 0, 1, 0, 0], [0, 0, 0, 10, 0],
                                [0, 0, 0, 0, 1]]
    full = config.from_dict(data, "c.yaml")
    assert key_unit(full, "lqr.roll.Q[0][2]") == "1/(rad (m/s))"  # an off-diagonal entry: 1/(unit i unit j)
    assert key_unit(full, "lqr.roll.Q[4][4]") == "1/(rad s)^2"
    assert key_unit(full, "lqr.roll.Q[1]") is None  # a row of a full Q is not one value


@pytest.mark.parametrize("path", ["simulation.noise.seed", "simulation.wind.turbulence.seed", "simulation.max_samples",
                                  "controller.delay.samples", "controller.filters.gyro.order", "schedule.check",
                                  "lqr.roll.bryson.headroom", "controller.pid.values.rate_roll_kp", "lqr.roll.Q[3]",
                                  "lqr.roll.integral[0]", "lqr.nosuch.Q[0]", "name", "motors.layout", "vehicle.nosuch"])
def test_a_key_with_no_unit_has_none(path):
    """A seed, a count, an order, a share, a name, a PID value (its flight stack's units), a weight past Q's
    size or of no subsystem, a key the schema does not have."""
    assert key_unit(config.load("mambo-200hz"), path) is None


def test_a_schedules_values_take_the_unit_of_its_variable():
    data = {**copy.deepcopy(HOVER), "schedule": {"variable": "yaw", "values": [0.0, 1.0]}}
    assert key_unit(config.from_dict(data, "c.yaml"), "schedule.values[1]") == "rad"
    data["schedule"]["variable"] = "climb"
    assert key_unit(config.from_dict(data, "c.yaml"), "schedule.values[1]") == "m/s"


def test_every_key_whose_description_gives_a_limited_unit_has_that_unit():
    """The schema's fields whose description begins with a position, velocity, heading or time unit, read
    by this file's own parser (``_unit_of``), against key_unit's."""
    cfg = config.load("mambo-200hz")
    found = list(_unit_fields(schema.Config))
    assert len(found) > 10
    for pattern, unit in found:
        assert key_unit(cfg, pattern.replace("[*]", "[0]")) == unit.split(" ")[0], pattern
