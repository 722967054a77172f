"""A command-line option that stands for a config key obeys that key's declaration: the same bounds
and the same words, exit 2, for every command that has it (``quadctl.config.OVERRIDES``)."""

from __future__ import annotations

import math

import pytest
import typer
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app
from quadctl.errors import ConfigError
from quadctl.text.messages import show

VALUES = [math.inf, -math.inf, math.nan, 0.0, -1.0, 1e12, config.MAX_RATE * (1 + 1e-12)]


def _options() -> dict[str, list[str]]:
    """Every option of every command: ``{"--rate": ["check", "export"], ...}``."""
    group = typer.main.get_command(app)
    found: dict[str, list[str]] = {}
    for name, command in group.commands.items():
        for param in command.params:
            for opt in getattr(param, "opts", []):
                if opt.startswith("--"):
                    found.setdefault(opt, []).append(name)
    return found


def _leaf_keys(model=config.Config, prefix: str = "") -> dict[str, str]:
    """``{leaf name: key path}`` of every key of the schema (the last part, dashed as an option)."""
    from pydantic import BaseModel

    keys = {}
    for name, field in model.model_fields.items():
        inner = config.first_model(field.annotation)
        if inner is not None and isinstance(inner, type) and issubclass(inner, BaseModel) and "dict" not in str(
                field.annotation):
            keys.update(_leaf_keys(inner, f"{prefix}{name}."))
        else:
            keys[name.replace("_", "-")] = prefix + name
    return keys


NOT_TWINS = {"--force": "init's overwrite switch; estimator.force is a noise level (N)"}
"""Options that share a name with a config key but do not stand for it, each with why."""


def test_every_option_named_like_a_config_key_is_declared_as_its_override():
    """An option named like a config key's last part (``--rate``: controller.rate) must take that key's
    bounds: it is listed in OVERRIDES with that key (or in NOT_TWINS, saying why not)."""
    leaves = _leaf_keys()
    twins = {opt: leaves[opt[2:]] for opt in _options() if opt[2:] in leaves and opt not in NOT_TWINS}
    assert twins, "no option has a config twin: the test lost its subject"
    assert {opt: config.OVERRIDES.get(opt) for opt in twins} == twins


def _config_message(key: str, value: float) -> str:
    section, leaf = key.split(".")
    data = config.load("crazyflie").model_dump(mode="json")
    data[section][leaf] = value
    with pytest.raises(ConfigError) as info:
        config.from_dict(data, "c.yaml")
    return str(info.value).split(": ", 2)[2]  # after "c.yaml: controller.rate = <value>"


@pytest.mark.parametrize("option, command", [(opt, cmd) for opt in config.OVERRIDES for cmd in _options()[opt]])
@pytest.mark.parametrize("value", VALUES)
def test_an_option_outside_its_keys_bounds_is_refused_as_the_key_would_be(option, command, value):
    key = config.OVERRIDES[option]
    args = [command, *(["--to", "c"] if command == "export" else []), "-c", "hover", option, repr(value)]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2, res.output
    why = _config_message(key, value)
    assert res.stderr == f"quadctl: error: {option} = {show(value)}: {why}; {option} is {key}\n"


def test_check_override_keeps_a_value_inside_the_bounds():
    assert config.check_override("--rate", 500.0) == 500.0
    assert config.check_override("--rate", config.MAX_RATE) == config.MAX_RATE


def test_the_export_api_takes_the_rate_with_its_keys_bounds(forward):
    from quadctl import export

    setup = forward[0]
    with pytest.raises(ConfigError, match=r"^rate = inf: must be a finite number .*; rate is controller\.rate$"):
        export.prepare(setup, math.inf)
    with pytest.raises(ConfigError, match=r"^rate = 1000000000000: must be at most 100000 .*controller\.rate$"):
        export.prepare(setup, 1e12)
