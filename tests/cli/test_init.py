"""`quadctl init`: a commented config for a new vehicle that loads, flies its flight condition within
its rotors' limits, shows every key with its unit and the source of every physical number."""

from __future__ import annotations

import re

import numpy as np
import pytest
import yaml
from _paths import ROOT
from _solve import run
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app
from quadctl.config import Config, yamlio
from quadctl.config import template as starter
from quadctl.errors import ConfigError
from quadctl.layout import STATE_INDEX
from quadctl.linear import analysis
from quadctl.physics import motors

runner = CliRunner()
CASES = [(v, f) for v in starter.PRESETS for f in starter.FLIGHTS]


def _keys(model, prefix: str = "") -> list[str]:
    """Every key path of the schema below ``model`` (sections and their keys)."""
    out = []
    for key, field in model.model_fields.items():
        out.append(prefix + key)
        sub = config.first_model(field.annotation)
        if sub is not None and key not in ("subsystems", "lqr", "delay"):  # named entries; a number or {samples}
            out += _keys(sub, prefix + key + ".")
    return out


@pytest.mark.parametrize(("vehicle", "flight"), CASES)
def test_the_config_loads_and_flies_its_flight_within_the_rotor_limits(vehicle, flight):
    cfg = config.parse(starter.config_text("mine", vehicle, flight), "mine.yaml")
    data = cfg.model_dump(mode="json")
    data["simulation"]["duration"] = 4.0
    setup, design, loop, sim = run(data)
    assert sim.status == "ok", sim.message
    assert design.stable
    fractions = motors.saturation_fraction(loop.actuators, sim.u)
    assert max(fractions.values()) == 0.0, fractions  # the Bryson weights leave the offset room
    assert np.abs(sim.x[-1, STATE_INDEX["pD"]] - loop.x_trim[STATE_INDEX["pD"]]) < 0.05


@pytest.mark.parametrize("flight", starter.FLIGHTS)
def test_the_partition_fits_the_flight(flight):
    """Every subsystem, the unregulated one too, is controllable by its inputs at its trim (PBH); at
    hover the report's guidance (u, psi into pN, pE) is not, which is why hover gets u, v."""
    cfg = config.parse(starter.config_text("mine", "mambo", flight), "mine.yaml")
    names = set(cfg.partition())
    assert names == {"altitude", "roll", "pitch", "yaw"} | ({"guidance"} if flight == "forward" else
                                                            set() if flight == "hold" else {"position"})
    if flight == "hold":  # every state regulated: a waypoint is reached
        regulated = {s for sub in cfg.partition().values() if sub.regulate for s in sub.states}
        assert {"pN", "pE"} <= regulated and len(regulated) == 12
    from _solve import solve
    setup, trim, linear, dec, _ = solve(cfg.model_dump(mode="json"))
    for sub in dec.subsystems:
        assert analysis.check(sub.A, sub.B, names=sub.states).controllable, sub.name
    if flight == "hover":  # pN, pE from u and psi at hover: pE does not move (psi multiplies u = 0)
        rows = [STATE_INDEX["pN"], STATE_INDEX["pE"]]
        b = linear.A[np.ix_(rows, [STATE_INDEX["u"], STATE_INDEX["psi"]])]
        assert np.linalg.matrix_rank(b) == 1


def test_every_key_is_there_with_its_unit_and_every_number_with_its_source():
    text = starter.config_text("mine", "iris", "hover")
    for path in _keys(Config):
        key = path.split(".")[-1]
        assert re.search(rf"^[ #]*(- )?{key}:", text, re.M), f"{path} is missing"
    # each line with a value carries a comment; the schema's unit is in it
    for line in text.splitlines():
        if re.match(r"^ *[a-z_]+: \S", line) and not line.startswith(("name:", "description:")):
            assert "   # " in line or line.lstrip().startswith(("altitude", "roll", "pitch", "yaw", "position")), line
    assert "mass: 1.5   # kg [PX4]" in text
    assert "max_thrust: 7.0664   # N per rotor [PX4]" in text
    for key in ("inertia", "drag", "arm_length", "thrust_coefficient", "torque_coefficient", "numbering"):
        line = next(ln for ln in text.splitlines() if ln.lstrip().startswith(f"{key}:"))
        assert "[PX4]" in line, line
    assert "[PX4] PX4/PX4-SITL_gazebo-classic: models/iris/iris.sdf.jinja" in text
    assert not [ln for ln in text.splitlines() if ln.rstrip().endswith("null")]  # every null says what it means


def test_init_is_listed_and_writes_the_file_once(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert re.search(r"init\s+Start a config for your own vehicle", runner.invoke(app, ["--help"]).output)
    res = runner.invoke(app, ["init", "f450", "--from", "iris"])
    assert res.exit_code == 0, res.output
    assert res.output.startswith("wrote f450.yaml: 3DR Iris")
    assert config.load("f450.yaml").vehicle.mass == 1.5
    res = runner.invoke(app, ["init", "f450"])
    assert res.exit_code == 2
    assert res.stderr == ("quadctl: error: f450.yaml: already exists; pass --force to overwrite it, or choose another "
                          "NAME\n")
    assert runner.invoke(app, ["init", "f450", "--force", "--from", "mambo"]).exit_code == 0
    assert config.load("f450.yaml").vehicle.mass == 0.068
    res = runner.invoke(app, ["run", "-c", "f450.yaml", "-o", "out"])
    assert res.exit_code == 0, res.output


@pytest.mark.parametrize("name", ["1e3", "010", "0x1F", "1_000", "1.5", "yes", "on", "null", "true", "2024-01-01"])
def test_a_name_yaml_would_read_as_another_type_is_written_so_it_reads_back(tmp_path, monkeypatch, name):
    """`quadctl init 1e3` once wrote `name: 1e3`, which reads as the number 1000 (and `yes` as true)."""
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["init", name, "--from", "mambo"])
    assert res.exit_code == 0, res.output
    text = (tmp_path / f"{name}.yaml").read_text()
    assert yamlio.load(text, "c.yaml")["name"] == name
    if name != "2024-01-01":  # PyYAML's YAML 1.1 reads that as a date; quadctl's loader and YAML 1.2 as text
        assert yaml.safe_load(text)["name"] == name
    cfg = config.load(f"{name}.yaml")
    assert cfg.name == name
    assert cfg.description == ("Started from the Parrot Mambo / Rolling Spider (68 g), the report's vehicle template "
                               "(quadctl init): hold at 1 m")  # a colon and an apostrophe, read back as given
    assert cfg.vehicle_digest() == cfg.started_from.vehicle_digest


def test_the_page_the_template_points_to_for_every_key_exists_and_explains_the_editor_schema():
    """The template sent the reader to the README's "Config reference", a section the README does not have."""
    text = starter.config_text("mine", "crazyflie", "hold")
    pages = re.findall(r"docs/[\w/.-]+\.md", text)
    assert "docs/reference/config.md" in pages and all((ROOT / p).is_file() for p in pages), pages
    page = (ROOT / "docs/reference/config.md").read_text()
    assert "yaml-language-server" in page and "quadctl configs --schema" in page
    assert "README" not in text


def test_the_template_writes_numbers_short():
    text = starter.config_text("mine", "crazyflie", "hold")
    assert "  duration: 10.0   # s" in text
    assert "  yaw:      {bryson: {errors: [0.2, 2.0], headroom: 0.06}}  # Bryson" in text
    assert "  initial_offset: {pD: 0.5, phi: 0.1, theta: 0.1, psi: 0.2}   #" in text  # in the order given
    assert "  rate: 500.0   # " in text


@pytest.mark.parametrize(("args", "match"), [
    (("my/quad",), r"^NAME = 'my/quad': must start with a letter"),
    (("q", "iriss", "hover"), r"^--from iriss: unknown vehicle; did you mean `iris`\?"),
    (("q", "iris", "climb"), r"^--flight climb: unknown flight condition"),
    (("mine.yaml",), r"^NAME = 'mine\.yaml': give the config's name without \.yaml; quadctl init mine writes "
                     r"mine\.yaml$"),
    (("f450.YML",), r"^NAME = 'f450\.YML': give the config's name without \.YML; quadctl init f450 writes f450\.yaml$"),
])
def test_bad_init_arguments_are_named(args, match):
    with pytest.raises(ConfigError, match=match):
        starter.config_text(*args)


@pytest.mark.parametrize("name", ["abc\n", "abc\r", "abc\n\n", "\nabc", "a b", "a" * (config.MAX_NAME_LENGTH + 1),
                                  "a" * 300, ""])
def test_a_name_no_config_takes_is_refused_by_init_in_one_line_and_writes_nothing(tmp_path, monkeypatch, name):
    """A name ending in a newline once wrote `abc\\n.yaml`; one of 300 characters ended in an internal error."""
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["init", name])
    assert res.exit_code == 2, res.output
    shown = repr(name) if len(name) <= 60 else rf"{name[:60]!r}\.\.\. \({len(name)} characters\)"
    assert re.fullmatch(rf"quadctl: error: NAME = {re.escape(shown) if len(name) <= 60 else shown}: must start "
                        r"with a letter, digit or '_', use only letters, digits, '_', '\.' and '-', and have at most "
                        r"128 characters \(it names the file NAME\.yaml and the folder runs/NAME\)\n", res.stderr), \
        res.stderr
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ConfigError):  # the config's own rule refuses it too
        config.from_dict({**config.load("hover").model_dump(mode="json"), "name": name}, "c.yaml")


def test_the_longest_name_init_takes_makes_a_config_that_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    name = "q" * config.MAX_NAME_LENGTH
    res = runner.invoke(app, ["init", name])
    assert res.exit_code == 0, res.output
    assert config.load(f"{name}.yaml").name == name
    res = runner.invoke(app, ["trim", "-c", f"{name}.yaml"])  # into runs/<name>
    assert res.exit_code == 0, res.output
    assert (tmp_path / "runs" / name / "trim.json").is_file()


def test_configs_show_says_what_each_empty_section_means():
    shown = runner.invoke(app, ["configs", "--show", "hover"]).output
    assert shown.startswith("# hover.yaml, validated, every default filled in. For a vehicle of your own start from\n"
                            "# `quadctl init NAME")
    assert re.search(r"^motors: null   # rotor layout and thrust limits; .*`quadctl init NAME` writes motors: with "
                     r"units\)$", shown, re.M)
    assert re.search(r"^  noise: null   # process and sensor noise; absent: none$", shown, re.M)


@pytest.mark.parametrize("vehicle", starter.PRESETS)
def test_hold_brings_the_vehicle_back_to_its_position(vehicle):
    """``--flight hold`` (the default) regulates north and east: from 0.5 m off it returns, where ``hover``
    would leave the position where the offset put it."""
    cfg = config.parse(starter.config_text("mine", vehicle), "mine.yaml")
    data = cfg.model_dump(mode="json")
    data["simulation"].update(duration=12.0, initial_offset={"pN": 0.5, "pE": -0.5})
    _, _, loop, sim = run(data)
    assert sim.status == "ok", sim.message
    for state in ("pN", "pE"):
        i = STATE_INDEX[state]
        assert abs(sim.x[-1, i] - loop.x_trim[i]) < 0.05, (state, sim.x[-1, i])


def test_the_digest_the_template_note_asks_for_reads_back_as_text_when_it_is_all_digits(tmp_path, monkeypatch):
    """The note gives the line to paste; a digest of digits only, pasted unquoted, would read as a number."""
    from quadctl.config import notices

    monkeypatch.chdir(tmp_path)
    assert runner.invoke(app, ["init", "f450", "--from", "mambo"]).exit_code == 0
    cfg = config.load("f450.yaml")
    monkeypatch.setattr(type(cfg), "vehicle_digest", lambda self: "123456789012")
    (note,) = [n for n in notices.notices(cfg, "f450.yaml") if n.key == "description"]
    line = note.message.split("then set ")[1].split(" (or remove")[0]
    assert yamlio.load(line, "c.yaml") == {"started_from.vehicle_digest": "123456789012"}
