"""Shell completion: the options exist, the installed script completes quadctl's commands."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from quadctl.cli.app import app


def test_help_offers_completion():
    res = CliRunner().invoke(app, ["--help"])
    assert res.exit_code == 0
    assert "--install-completion" in res.output and "--show-completion" in res.output


def _complete(words: str) -> list[str]:
    """What bash's completion asks quadctl for ``words`` (the last one being typed)."""
    env = {**os.environ, "_QUADCTL_COMPLETE": "complete_bash", "COMP_WORDS": words,
           "COMP_CWORD": str(len(words.split()) - 1)}
    out = subprocess.run([sys.executable, "-m", "quadctl"], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return out.stdout.split()


def test_completion_names_commands_and_options():
    assert _complete("quadctl si") == ["simulate"]
    assert set(_complete("quadctl r")) >= {"run"}
    assert "--config" in _complete("quadctl simulate --c")
    assert "--schema" in _complete("quadctl configs --sc")


def test_install_completion_as_the_readme_says(tmp_path, monkeypatch):
    """`quadctl --install-completion` in bash: a script under ~/.bash_completions, sourced by ~/.bashrc."""
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setattr("shellingham.detect_shell", lambda *a, **k: ("bash", "/bin/bash"))
    res = CliRunner().invoke(app, ["--install-completion"], prog_name="quadctl")
    assert res.exit_code == 0, res.output
    script = tmp_path / ".bash_completions" / "quadctl.sh"
    assert "bash completion installed" in res.output and script.exists()
    assert str(script) in (tmp_path / ".bashrc").read_text()
    if shutil.which("bash") is None:
        pytest.skip("no bash to source the script in")
    registered = subprocess.run(["bash", "-c", f"source {script} && complete -p quadctl"],
                                capture_output=True, text=True, timeout=30)
    assert registered.returncode == 0 and "_quadctl_completion" in registered.stdout, registered.stderr


def test_show_completion_prints_the_script(monkeypatch):
    monkeypatch.setattr("shellingham.detect_shell", lambda *a, **k: ("zsh", "/bin/zsh"))
    res = CliRunner().invoke(app, ["--show-completion"], prog_name="quadctl")
    assert res.exit_code == 0 and "#compdef quadctl" in res.output and "_QUADCTL_COMPLETE" in res.output
