"""The options the commands share (:mod:`quadctl.cli.options`) are on every command they belong to, with
one meaning: ``--set`` wherever a config is loaded, ``--allow-saturation`` wherever the simulation's
check is made."""

from __future__ import annotations

import pytest
import typer.main

from quadctl.cli.app import app
from quadctl.cli.options import SET_HELP, AllowSaturationOpt

COMMANDS = typer.main.get_command(app).commands
FLY_THE_SIMULATION = ("simulate", "run", "report")
"""The commands whose check includes the simulation's (the stage ``simulate``, its saturation verdict)."""


def options(name: str) -> dict:
    return {opt: param for param in COMMANDS[name].params for opt in param.opts}


def test_every_command_that_loads_a_config_takes_set_with_one_meaning():
    loading = [name for name in COMMANDS if "--config" in options(name)]
    assert {"identify", "report", "run", "export"} <= set(loading)
    missing = [name for name in loading if "--set" not in options(name)]
    assert not missing, f"--config without --set: {missing}"
    for name in loading:
        assert options(name)["--set"].help.startswith(SET_HELP), name


@pytest.mark.parametrize("name", FLY_THE_SIMULATION)
def test_every_command_that_checks_the_flight_takes_allow_saturation(name):
    param = options(name).get("--allow-saturation")
    assert param is not None, f"{name} has no --allow-saturation"
    assert param.help == AllowSaturationOpt.__metadata__[0].help and param.default is False


def test_the_report_records_allow_saturation_in_its_command_line():
    from quadctl.cli.commands.report import _command_line

    assert _command_line("crazyflie", None, False, ["simulation.duration=1"], True) == (
        "quadctl report --config crazyflie --set simulation.duration=1 --allow-saturation")
