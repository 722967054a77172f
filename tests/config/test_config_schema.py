"""The config's JSON Schema: printed by `configs --schema`, shipped in docs/, named by every bundled
config's modeline, in agreement with the loader on valid and invalid configs, units in its text."""

from __future__ import annotations

import json
import re
from pathlib import Path

import jsonschema
import pytest
from _paths import ROOT
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app
from quadctl.config import yamlio
from quadctl.errors import ConfigError

SCHEMA_FILE = ROOT / "docs" / "quadctl.schema.json"
MODELINE = re.compile(r"^# yaml-language-server: \$schema=(\S+)$")


def _is_config(path: Path) -> bool:
    """A config (not a sweep file): a mapping with LQR weights."""
    data = yamlio.load(path.read_text(), path.name, ConfigError)
    return isinstance(data, dict) and "lqr" in data


CONFIG_FILES = sorted([*(ROOT / "configs").glob("*.yaml"), *(ROOT / "docs" / "configs").glob("*.yaml"),
                       *(p for p in (ROOT / "examples").glob("*.yaml") if _is_config(p))])
IDS = [p.relative_to(ROOT).as_posix() for p in CONFIG_FILES]


@pytest.fixture(scope="module")
def validator():
    schema = json.loads(SCHEMA_FILE.read_text())
    jsonschema.Draft7Validator.check_schema(schema)  # a well-formed draft-07 schema
    return jsonschema.Draft7Validator(schema)


def test_the_schema_file_is_what_configs_schema_prints():
    res = CliRunner().invoke(app, ["configs", "--schema"])
    assert res.exit_code == 0, res.output
    assert res.stdout == SCHEMA_FILE.read_text(), (
        "docs/quadctl.schema.json is stale: regenerate it with `quadctl configs --schema > docs/quadctl.schema.json`")
    assert json.loads(res.stdout) == config.json_schema()


def test_schema_with_show_is_refused_not_half_done():
    """`configs --show hover --schema` printed the schema and dropped --show without a word."""
    res = CliRunner().invoke(app, ["configs", "--show", "hover", "--schema"])
    assert res.exit_code == 2 and res.stdout == ""
    assert "--schema with --show hover" in res.stderr and "give one of the two" in res.stderr


def test_every_bundled_config_is_found():
    names = {p.stem for p in CONFIG_FILES}
    assert set(config.bundled_names()) <= names and {"report-at-200hz", "report-on-mambo"} <= names


@pytest.mark.parametrize("path", CONFIG_FILES, ids=IDS)
def test_every_bundled_config_names_the_schema_and_passes_it(path, validator):
    first = path.read_text().splitlines()[0]
    match = MODELINE.match(first)
    assert match, f"{path.name}: first line should be the modeline, got {first!r}"
    assert (path.parent / match.group(1)).resolve() == SCHEMA_FILE  # relative to the config, as editors read it
    data = yamlio.load(path.read_text(), path.name, ConfigError)  # YAML 1.2 numbers, as editors read them
    errors = [f"{'.'.join(map(str, e.absolute_path))}: {e.message}" for e in validator.iter_errors(data)]
    assert errors == []
    config.parse(path.read_text(), path.name)  # and quadctl agrees


FORWARD = config.bundled("forward").text
BAD = {
    "unknown key": (FORWARD.replace("  mass: 0.068", "  mas: 0.068"), ["vehicle"], "Additional properties"),
    "unknown section": (FORWARD + "simulaton: {duration: 2}\n", [], "Additional properties"),
    "wrong type": (FORWARD.replace("  mass: 0.068", '  mass: "heavy"'), ["vehicle", "mass"], "not of type"),
    "a number for a list": (FORWARD.replace("inertia: [6.9e-5, 7.75e-5, 1.5e-4]", "inertia: 6.9e-5"),
                            ["vehicle", "inertia"], "is not valid under any"),
    "out of range": (FORWARD.replace("  mass: 0.068", "  mass: 0"), ["vehicle", "mass"], "less than the minimum"),
    "not auto": (FORWARD.replace("dt: auto", "dt: fast"), ["simulation", "dt"], "is not valid under any"),
    "missing name": (FORWARD.replace("name: forward\n", ""), [], "'name' is a required property"),
}


@pytest.mark.parametrize("case", BAD, ids=list(BAD))
def test_the_schema_refuses_what_quadctl_refuses(case, validator):
    text, where, message = BAD[case]
    assert text != FORWARD
    data = yamlio.load(text, "c.yaml", ConfigError)
    errors = list(validator.iter_errors(data))
    assert errors, case
    assert any(list(e.absolute_path) == where and message in e.message for e in errors), \
        [(list(e.absolute_path), e.message) for e in errors]
    with pytest.raises(ConfigError):
        config.parse(text, "c.yaml")


UNITS = ("kg", "m", "s", "rad", "N", "Hz", "1/(m/s)", "state units", "state unit")
"""A numeric field's description names one of these (as a word: ``m`` in ``m/s``, not in ``mass``)."""


def _fields(schema: dict):
    """(path, property schema) of every field of every section."""
    sections = {"": schema, **{name: d for name, d in schema["definitions"].items()}}
    for section, body in sections.items():
        for name, prop in body.get("properties", {}).items():
            yield f"{section}.{name}".lstrip("."), prop


def _numeric(prop: dict) -> bool:
    text = json.dumps({k: v for k, v in prop.items() if k not in ("default", "description")})
    return '"number"' in text


def test_every_field_is_described_and_every_number_has_its_unit():
    schema = config.json_schema()
    fields = dict(_fields(schema))
    assert len(fields) > 40
    undescribed = [path for path, prop in fields.items() if not prop.get("description")]
    assert undescribed == []
    unitless = [path for path, prop in fields.items() if _numeric(prop)
                and not any(re.search(rf"(?<![A-Za-z]){re.escape(u)}(?![A-Za-z])", prop["description"])
                            for u in UNITS)]
    assert unitless == []


def test_descriptions_carry_the_defaults_read_from_the_schema():
    defs = config.json_schema()["definitions"]
    assert defs["VehicleConfig"]["properties"]["mass"]["description"] == (
        f"kg; default {config.VehicleConfig.model_fields['mass'].default}")
    assert defs["SimulationConfig"]["properties"]["dt"]["description"].endswith('; default "auto"')
    assert defs["VehicleConfig"]["properties"]["drag"]["description"].endswith("; default [0.22, 0.22, 0.0]")
    # the loader's messages keep the bare unit (pinned in test_errors): the schema adds defaults, not the model
    assert config.VehicleConfig.model_fields["mass"].description == "kg"


@pytest.mark.parametrize("key, value, message", [
    ("Q", [1, float("nan"), 1], r"lqr\.pitch\.Q\[1\] = nan: must be a finite number \(not NaN or infinity\)$"),
    ("R", [float("inf")], r"lqr\.pitch\.R\[0\] = inf: must be a finite number \(not NaN or infinity\)$"),
    ("Q", [[1, 0, 0], [0, float("nan"), 0], [0, 0, 1]],
     r"lqr\.pitch\.Q\[1\]\[1\] = nan: must be a finite number \(not NaN or infinity\)$"),
    ("Q", [1, "x", 1], r"lqr\.pitch\.Q\[1\] = \"x\": must be a list of numbers \(the diagonal\) or a list of rows "
                       r"\(a full matrix\)$"),
])
def test_a_bad_entry_of_a_weight_is_reported_in_the_form_it_was_written(key, value, message):
    """A NaN in a diagonal ``Q`` was reported as 'must be a list of numbers' with '2 more errors' at the entries
    that are fine (those of the full-matrix reading): the error is the entry, in the form the user wrote."""
    data = config.load("hover").model_dump()
    data["lqr"]["pitch"][key] = value
    with pytest.raises(ConfigError, match=rf"^<config>: {message}"):
        config.from_dict(data)
