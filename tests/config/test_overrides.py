"""`--set KEY=VALUE`: the same run as the edited file, errors naming --set, recorded in the run folder."""

from __future__ import annotations

import copy
import json

import pytest
import yaml
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app
from quadctl.config import overrides
from quadctl.errors import ConfigError

runner = CliRunner()
HOVER = yaml.safe_load(config.bundled("hover").text)


def _edited(tmp_path, edit) -> str:
    """hover.yaml with ``edit`` applied to its data by hand, as a file."""
    data = copy.deepcopy(HOVER)
    edit(data)
    path = tmp_path / "edited.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return str(path)


def _design(config_arg, out, *sets) -> tuple[dict, str]:
    """design.json (without its time stamp) and config.resolved.yaml of `quadctl design`."""
    words = ["design", "-c", config_arg, "-o", str(out)] + [w for s in sets for w in ("--set", s)]
    res = runner.invoke(app, words, catch_exceptions=False)
    assert res.exit_code == 0, res.output
    payload = json.loads((out / "design.json").read_text())
    payload.pop("created")
    return payload, (out / "config.resolved.yaml").read_text()


def _set_rate(data):
    data["controller"] = {"rate": 250, "design": "continuous"}


@pytest.mark.parametrize("sets,edit", [
    pytest.param(["vehicle.mass=0.075"], lambda d: d["vehicle"].update(mass=0.075), id="number"),
    pytest.param(["vehicle.inertia=[7.2e-5, 8e-5, 1.6e-4]"],
                 lambda d: d["vehicle"].update(inertia=[7.2e-5, 8e-5, 1.6e-4]), id="list"),
    pytest.param(["controller.rate=250", "controller.design=continuous"], _set_rate,
                 id="text, in a section the file leaves out"),
    pytest.param(["lqr.roll.Q[1]=80"], lambda d: d["lqr"]["roll"]["Q"].__setitem__(1, 80), id="nested key, index"),
])
def test_set_gives_the_artifacts_of_the_edited_file(tmp_path, sets, edit):
    by_set = _design("hover", tmp_path / "set", *sets)
    by_file = _design(_edited(tmp_path, edit), tmp_path / "file")
    assert by_set == by_file
    assert by_set[0]["config_hash"] != config.load("hover").digest()  # it changed the design's config
    given = (tmp_path / "set" / "config.yaml").read_text()
    assert given.startswith(config.bundled("hover").text)  # the file as given, then what was put in
    assert given.endswith("".join(f"#   --set {s}\n" for s in sets))


def test_the_text_value_is_what_decides_the_design():
    """controller.design=continuous is read as the text it is: not the default (discrete)."""
    rate_only = overrides.load(config.bundled("hover"), ["controller.rate=250"])
    continuous = overrides.load(config.bundled("hover"), ["controller.rate=250", "controller.design=continuous"])
    assert (rate_only.controller.design, continuous.controller.design) == ("discrete", "continuous")


@pytest.mark.parametrize("sets,message", [
    (["simulation.durtion=30"], r"^--set: simulation\.durtion: unknown key; did you mean `duration`\?$"),
    (["simulation.duration=-1"], r"^--set: simulation\.duration = -1: must be greater than 0"),
    (["simulation.duration=thirty"], r"^--set: simulation\.duration = \"thirty\": must be a number"),
    (["vehicle.inertia=[1, 2]"], r"^--set: vehicle\.inertia = \[1, 2\]: must be \[Jxx, Jyy, Jzz\] or 3 rows"),
    (["controller.design=discret"], r"^--set: controller\.design = \"discret\": must be one of discrete, "
                                    r"continuous; did you mean `discrete`\?$"),
    (["simulation.duration"], r"^--set simulation\.duration: give KEY=VALUE, as `--set simulation\.duration=30`$"),
    (["vehicle..mass=1"], r"^--set vehicle\.\.mass=1: vehicle\.\.mass is not a key path; write it as"),
    (["vehicle.mass.kg=1"], r"^--set vehicle\.mass\.kg: vehicle\.mass = 0\.068 has no key `kg`; the path goes "
                            r"too deep$"),
    (["lqr.rol.Q=[1, 50, 1]"], r"^--set lqr\.rol\.Q: no such key in the config: `lqr\.rol`; did you mean `roll`\?$"),
    (["lqr.roll.Q[3]=1"], r"^--set lqr\.roll\.Q\[3\]: index 3 out of range: lqr\.roll\.Q has 3 values"),
    (["vehicle.mass[0]=1"], r"^--set vehicle\.mass\[0\]: vehicle\.mass is not a list; drop the \[0\]$"),
    (["vehicle.inertia[0][1]=1"], r"^--set vehicle\.inertia\[0\]\[1\]: vehicle\.inertia\[0\] is not a list; drop the"),
    (["vehicle.inertia=[1,"], r"^--set vehicle\.inertia: YAML syntax error"),
])
def test_a_bad_key_or_value_is_refused_naming_set(sets, message):
    with pytest.raises(ConfigError, match=message):
        overrides.load(config.bundled("hover"), sets)


def test_an_error_of_the_file_itself_names_the_file(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(config.bundled("hover").text.replace("mass: 0.068", "mass: -1"))
    with pytest.raises(ConfigError, match=r"^.*bad\.yaml: vehicle\.mass = -1: must be at least"):
        overrides.load(config.locate(str(path)), ["simulation.duration=3"])
    fixed = overrides.load(config.locate(str(path)), ["vehicle.mass=0.07"])  # a --set that fixes it is fine
    assert fixed.vehicle.mass == 0.07


def test_a_bad_set_exits_2_with_one_line(tmp_path):
    res = runner.invoke(app, ["trim", "-c", "hover", "-o", str(tmp_path), "--set", "simulation.durtion=3"])
    assert res.exit_code == 2
    assert res.output == "quadctl: error: --set: simulation.durtion: unknown key; did you mean `duration`?\n"
    assert not (tmp_path / "trim.json").exists()


def _plant_inertia(data):
    data["simulation"]["plant"] = {"inertia": [7e-5] + HOVER["vehicle"]["inertia"][1:]}


@pytest.mark.parametrize("given,edit", [
    pytest.param("simulation.plant.inertia[0]=7e-5", _plant_inertia, id="plant: the design vehicle's list"),
    pytest.param("simulation.plant.drag[1]=0.3",
                 lambda d: d["simulation"].update(plant={"drag": [HOVER["vehicle"]["drag"][0], 0.3,
                                                                  HOVER["vehicle"]["drag"][2]]}), id="plant drag"),
    pytest.param("simulation.noise.force[0]=0.01",
                 lambda d: d["simulation"].update(noise={"force": [0.01, 0, 0]}), id="noise: the schema's [0, 0, 0]"),
    pytest.param("simulation.wind.steady[0]=3",
                 lambda d: d["simulation"].update(wind={"steady": [3, 0, 0]}), id="wind: the schema's [0, 0, 0]"),
])
def test_an_index_into_a_list_of_a_section_the_file_leaves_out_starts_from_its_default(given, edit):
    """hover has no plant, noise or wind: `--set simulation.plant.inertia[0]=7e-5` said "index 0 out of
    range: simulation.plant.inertia has 0 values (indices 0 to -1)", though a sweep varies that path."""
    for section in ("plant", "noise", "wind"):
        assert HOVER["simulation"].get(section) is None
    data = copy.deepcopy(HOVER)
    edit(data)
    assert overrides.load(config.bundled("hover"), [given]) == config.from_dict(data, "edited.yaml")


def test_a_left_out_plant_starts_from_the_vehicle_every_set_leaves_whatever_their_order():
    """The plant's list is filled from the vehicle after the vehicle's own --set values: given before or
    after them, the same config (before: the plant took the file's vehicle, a mismatch nobody asked for)."""
    sets = ["simulation.plant.inertia[0]=1e-4", "vehicle.inertia[1]=2e-4"]
    data = copy.deepcopy(HOVER)
    data["vehicle"]["inertia"][1] = 2e-4
    data["simulation"]["plant"] = {"inertia": [1e-4, 2e-4, HOVER["vehicle"]["inertia"][2]]}
    expected = config.from_dict(data, "edited.yaml")
    assert overrides.load(config.bundled("hover"), sets) == expected
    assert overrides.load(config.bundled("hover"), sets[::-1]) == expected


@pytest.mark.parametrize("given,message", [
    ("simulation.wind.gusts[0]=1", r"^--set simulation\.wind\.gusts\[0\] = 1: the config leaves "
     r"`simulation\.wind\.gusts` out and its default \[\] has no \[0\]; set the whole list: "
     r"--set simulation\.wind\.gusts=\[\.\.\.\]$"),
    ("simulation.noise.force[3]=0.01", r"^--set simulation\.noise\.force\[3\] = 0\.01: the config leaves "
     r"`simulation\.noise\.force` out and its default \[0, 0, 0\] has no \[3\]; set the whole list"),
    ("simulation.wind.turbulence.sigma[0]=1", r"^--set simulation\.wind\.turbulence\.sigma\[0\] = 1: the config "
     r"leaves `simulation\.wind\.turbulence\.sigma` out and it has no default list; set the whole list: "
     r"--set simulation\.wind\.turbulence\.sigma=\[\.\.\.\]$"),
    ("simulation.initial_offset.foo=1", r"^--set: simulation\.initial_offset\.foo = 1: unknown state; allowed: "
     r"pN, pE, pD, u, v, w, phi, theta, psi, p, q, r$"),
])
def test_an_index_with_no_list_to_go_into_and_a_new_state_name_the_fix(given, message):
    """No list by default: the key and the fix, not "indices 0 to -1"; a new initial_offset key is checked
    as in a file (every state named), not against the keys hover happens to hold (pD, phi, theta, psi)."""
    with pytest.raises(ConfigError, match=message):
        overrides.load(config.bundled("hover"), [given])


@pytest.mark.parametrize("text,value", [
    ("description=a=b", "a=b"),
    ("description=speed = 2 m/s, tolerance = 5 cm", "speed = 2 m/s, tolerance = 5 cm"),
    ("description=x==y", "x==y"),
    ("description='k=v=w'", "k=v=w"),
])
def test_a_value_may_contain_equals_signs_the_key_ends_at_the_first(text, value):
    """The key path ends at the first ``=``: a parser splitting at the last would make ``description=a``
    the key and refuse it as no key path."""
    assert overrides.parse(text) == overrides.Assignment("description", ("description",), value)
    assert overrides.load(config.bundled("hover"), [text]).description == value


@pytest.mark.parametrize("bad,message", [
    ("simulation.initial_offset.zz=1", r"^--set: simulation\.initial_offset\.zz = 1: unknown state; allowed: "
     r"pN, pE, pD, u, v, w, phi, theta, psi, p, q, r$"),
    ("lqr.rol.Q=[1, 50, 1]", r"^--set lqr\.rol\.Q: no such key in the config: `lqr\.rol`; did you mean `roll`\?$"),
])
@pytest.mark.parametrize("good", ["simulation.initial_offset.u=0.1", "simulation.initial_offset.r=0.2"])
@pytest.mark.parametrize("first", ["good", "bad"])
def test_of_several_new_keys_the_refused_one_is_named(bad, message, good, first):
    """Two --set values each adding a key, one of them accepted (a state hover's initial_offset lacks): the
    error names the other, never "allowed: pD, phi, theta, psi" against the accepted one."""
    assert overrides.load(config.bundled("hover"), [good]) is not None
    sets = [good, bad] if first == "good" else [bad, good]
    with pytest.raises(ConfigError, match=message):
        overrides.load(config.bundled("hover"), sets)


@pytest.mark.parametrize("brk", ["\n", "\r\n", "\r", "\x85", "\u2028", "\u2029"],
                         ids=["LF", "CRLF", "CR", "NEL", "LS", "PS"])
@pytest.mark.parametrize("value", ["simulation.initial_offset={pD: 0.3,{brk} phi: 0.05}",
                                   "description=\"two{brk} lines\"", "vehicle.inertia=[7.2e-5,{brk}8e-5,{brk}1.6e-4]"])
def test_a_value_on_several_lines_is_recorded_as_comments_and_the_folder_reruns(tmp_path, brk, value):
    """Each line of a --set value that spans lines is a comment in config.yaml: its rest never becomes live
    YAML; the file loads as the config given, and rerun with the same --set makes the same config."""
    given = value.replace("{brk}", brk)
    out = tmp_path / "out"
    res = runner.invoke(app, ["trim", "-c", "hover", "-o", str(out), "--set", given])
    assert res.exit_code == 0, res.output
    text = (out / "config.yaml").read_bytes().decode("utf-8")
    assert text.startswith(config.bundled("hover").text)
    assert config.load(str(out / "config.yaml")) == config.load("hover")  # the comments change nothing
    with_set = overrides.load(config.locate(str(out / "config.yaml")), [given])
    assert with_set.digest() == overrides.load(config.bundled("hover"), [given]).digest()
    tail = text[len(config.bundled("hover").text):]
    assert all(line.startswith("#") for line in tail.splitlines()), tail


@pytest.mark.parametrize("key, said", [
    ("rate_roll_kpp", "unknown PID value 'rate_roll_kpp'; did you mean `rate_roll_kp`?"),
    ("zzz", "unknown PID value 'zzz'; use one of rate_hz, attitude_hz,"),
])
def test_a_misspelt_pid_value_is_one_plain_sentence(tmp_path, key, said):
    """`--set controller.pid.values.rate_roll_kpp=100` said "Value error, unknown PID value ...: use one of" and
    the 56 names: pydantic's prefix, and no nearest name."""
    res = runner.invoke(app, ["design", "-c", "crazyflie", "-o", str(tmp_path / "o"), "--set",
                              f"controller.pid.values.{key}=100"])
    assert res.exit_code == 2
    assert said in res.output and "Value error" not in res.output
