"""A file given to the wrong option is named for what it is, with the way to pass it: a sweep file
to -c, a config to -s, an artifact (design.json) to either, instead of a list of unknown keys."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from _paths import ROOT
from typer.testing import CliRunner

from quadctl import artifacts, config, sweep
from quadctl.cli.app import app
from quadctl.errors import ConfigError, SweepError

runner = CliRunner()


def _artifact(tmp_path, cfg) -> Path:
    """A design.json as the run folder holds it: the provenance every artifact carries, and results."""
    path = tmp_path / "design.json"
    path.write_text(json.dumps({**artifacts.metadata(cfg, "design"),
                                "subsystems": {"altitude": {"K": [[1.0, 2.0]]}}, "rate": None}))
    return path


def test_a_sweep_file_given_as_the_config_says_to_run_it_with_sweep(tmp_path):
    """It said `mode: unknown key; did you mean 'name'? (and 6 more errors)`."""
    path = shutil.copy(ROOT / "examples" / "ci-sweep.yaml", tmp_path / "ci-sweep.yaml")
    with pytest.raises(ConfigError, match=rf"^{path}: is a sweep file, not a config: run it with "
                                          rf"quadctl sweep -s {path} \(-c names the config it varies\)$"):
        config.load(path)


def test_an_artifact_given_as_the_config_says_to_pass_the_config_it_came_from(tmp_path):
    """It said `subsystems.altitude.K: unknown key ... (and 48 more errors)`."""
    path = _artifact(tmp_path, config.load("hover"))
    with pytest.raises(ConfigError, match=rf"^{path}: is a quadctl design artifact, not a config: pass the "
                                          r"config it came from \(its config\.yaml beside it\)$"):
        config.load(path)


def test_a_config_given_as_the_sweep_file_says_to_give_it_to_c(tmp_path):
    """It said `f450.yaml: name: unknown key; did you mean 'samples'?`."""
    cfg = config.load("hover")
    path = tmp_path / "f450.yaml"
    path.write_text(config.bundled("hover").text)
    with pytest.raises(SweepError, match=rf"^{path}: is a config, not a sweep file: give it to -c "
                                         rf"\(quadctl sweep -c {path} -s SWEEP_FILE\)$"):
        sweep.load(path, cfg)
    with pytest.raises(SweepError, match=rf"^{tmp_path}/design\.json: is a quadctl design artifact, not a sweep "
                                         r"file: give a sweep file"):
        sweep.load(_artifact(tmp_path, cfg), cfg)


@pytest.mark.parametrize("text,message", [
    ("name: x\nlqr: {}\nmode: grid\n", r"mode: unknown key"),  # a config with a stray key: its own error
    ("parameters: {vehicle.mass: [1]}\nname: x\nlqr: {}\n", r"parameters: unknown key"),  # both: no guess
])
def test_a_file_of_no_one_kind_keeps_its_own_error(tmp_path, text, message):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        config.load(path)


def test_the_command_line_exits_2_with_the_one_line(tmp_path):
    res = runner.invoke(app, ["trim", "-c", str(ROOT / "examples" / "ci-sweep.yaml"), "-o", str(tmp_path)])
    assert res.exit_code == 2
    assert res.output.startswith("quadctl: error: ") and res.output.count("\n") == 1
    assert "is a sweep file, not a config: run it with quadctl sweep -s" in res.output
