"""A subsystem's name is checked once, at load, against everything that uses it (a file name, an
HTML id, a C identifier, a MATLAB field): one rule, one line naming the key, the value and the fix."""

from __future__ import annotations

import re

import pytest
import yaml

from quadctl import artifacts, config
from quadctl.errors import ConfigError
from quadctl.text import escape

BAD = ["yaw axis", "<b>yaw</b>", "..", "../escaped", "1st", "yaw-axis", "yaw.x", "_yaw", "yåw", "x" * 64]
GOOD = ["heading", "Yaw_2", "r", "x" * 63]


def _renamed(new: str) -> dict:
    data = config.load("hover").model_dump(mode="json")
    data["subsystems"][new] = data["subsystems"].pop("yaw")
    data["lqr"][new] = data["lqr"].pop("yaw")
    return data


@pytest.mark.parametrize("name", BAD)
def test_a_name_no_stage_can_use_is_refused_at_load(name):
    with pytest.raises(ConfigError, match=rf"^c\.yaml: subsystems: {re.escape(repr(name))} is not a usable "
                                          r"subsystem name: .*; rename it, e\.g\. `[A-Za-z][A-Za-z0-9_]*`$"):
        config.from_dict(_renamed(name), "c.yaml")


@pytest.mark.parametrize("name", GOOD)
def test_a_name_the_rule_allows_is_usable_everywhere(name):
    """What the load accepts, every stage can use: a figure's file name, a C identifier, a .mat field."""
    cfg = config.from_dict(_renamed(name), "c.yaml")
    assert name in cfg.partition()
    assert artifacts.plot_path("run", name).name == f"{name}.png"
    assert escape.c_identifier(name) == escape.matlab_field(name) == name


@pytest.mark.parametrize("name", artifacts.places.OWN_FIGURES)
def test_a_name_of_one_of_quadctls_own_figures_is_refused(name):
    """A subsystem named `inputs` drew plots/inputs.png, then the inputs' figure took its place (the report
    lost sim-inputs.png the same way): `run --plot` listed five figures for five subsystems and the inputs."""
    with pytest.raises(ConfigError, match=rf"^c\.yaml: subsystems: '{name}' is the name of a figure quadctl draws "
                                          rf"of its own \(plots/{name}\.png\), .*; rename it, e\.g\. `{name}_loop`$"):
        config.from_dict(_renamed(name), "c.yaml")
    config.from_dict(_renamed(f"{name}_loop"), "c.yaml")


@pytest.mark.parametrize("name", ["Inputs", "WIND", "Schedule"])
def test_a_name_of_an_own_figure_in_other_case_is_refused(name):
    """macOS's and Windows's file systems ignore case by default: plots/Inputs.png is plots/inputs.png there."""
    own = name.casefold()
    with pytest.raises(ConfigError, match=rf"^c\.yaml: subsystems: '{name}' is the name of a figure quadctl draws "
                                          rf"of its own \(plots/{own}\.png, one file with plots/{name}\.png where "
                                          rf"file names ignore case \(macOS, Windows\)\), .*; rename it, e\.g\. "
                                          rf"`{name}_loop`$"):
        config.from_dict(_renamed(name), "c.yaml")


def test_two_names_that_differ_only_in_case_are_refused():
    """hover's roll beside a Roll (yaw renamed): their figures would be one file where file names ignore case."""
    with pytest.raises(ConfigError, match=r"^c\.yaml: subsystems: 'roll' and 'Roll' differ only in case: their "
                                          r"figures \(plots/roll\.png, plots/Roll\.png\) are one file where file "
                                          r"names ignore case \(macOS, Windows\); rename one, e\.g\. `Roll_2`$"):
        config.from_dict(_renamed("Roll"), "c.yaml")
    config.from_dict(_renamed("Roll_2"), "c.yaml")


def test_the_own_figures_are_every_figure_drawn_beside_the_subsystems():
    from types import SimpleNamespace

    from quadctl.plots.simulation import simulation_figure_makers

    drawn = simulation_figure_makers(SimpleNamespace(wind=[0.0], u_ref=[0.0]), {})  # wind and a reference: all
    assert set(drawn) <= set(artifacts.places.OWN_FIGURES), set(drawn)


def test_the_suggested_name_is_itself_allowed():
    for name in BAD:
        message = str(pytest.raises(ConfigError, config.from_dict, _renamed(name), "c.yaml").value)
        suggestion = re.search(r"e\.g\. `([^`]*)`", message)[1]
        config.from_dict(_renamed(suggestion), "c.yaml")


def test_report_refuses_a_spaced_name_at_once_with_exit_2(tmp_path):
    """The issue's case: a name with a space used to pass design, run, margins and export, then crash report."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(_renamed("yaw axis")))
    for command in (["report"], ["design"], ["export", "--to", "json"]):
        res = CliRunner().invoke(app, [*command, "-c", str(path), "-o", str(tmp_path / "out")])
        assert res.exit_code == 2, res.output
        assert res.stderr.count("\n") == 1 and "subsystems: 'yaw axis' is not a usable subsystem name" in res.stderr
    assert not (tmp_path / "out" / "report").exists()
