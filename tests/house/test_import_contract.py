"""The package's floors, as import-linter contracts (``[tool.importlinter]`` in pyproject.toml): each
floor imports only those below it, nothing imports the command line, every top-level module has a
floor; and the contracts fail when a lower floor imports a higher one."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from _paths import ROOT

import quadctl

CONFIG = ROOT / "pyproject.toml"
PACKAGE = Path(quadctl.__file__).parent


def lint_imports(path: Path = PACKAGE.parent) -> subprocess.CompletedProcess:
    """``lint-imports`` with the project's contracts, in a fresh process, on the quadctl in the folder
    ``path`` (by default the one imported here: in CI the installed package, not the checkout's)."""
    code = ("import sys\nfrom importlinter.cli import lint_imports\n"
            f"sys.exit(lint_imports(config_filename={str(CONFIG)!r}, no_cache=True, no_logo=True))\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(path), *filter(None, [os.environ.get("PYTHONPATH")])])}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=path,
                          timeout=120)  # cwd: `python -c` puts it first on the path


def test_the_package_keeps_its_floors():
    res = lint_imports()
    assert res.returncode == 0, res.stdout + res.stderr
    assert "Contracts: 2 kept, 0 broken." in res.stdout


@pytest.mark.parametrize("module, line, broken", [
    # the Riccati solver's compiled kernel reaching up into the simulation engine for its compiler
    ("design/riccati/doubling.py", "from quadctl.sim import engine",
     "quadctl.design.riccati.doubling -> quadctl.sim.engine"),
    # the one stability test reaching up for a sentence (sentences live in present/, above the core)
    ("linear/stability.py", "from quadctl.present import stages", "quadctl.linear.stability -> quadctl.present.stages"),
    # two modules of one "|" floor: the chained stages do not import what the artifacts hold
    ("pipeline.py", "import quadctl.payloads", "quadctl.pipeline -> quadctl.payloads"),
    # the design reaching up into the simulation (the Kalman filter is a design; a loop carries one)
    ("design/kalman.py", "from quadctl.sim import run", "quadctl.design.kalman -> quadctl.sim.run"),
    # the library importing the command line
    ("design/margins.py", "from quadctl.cli import app", "quadctl.design.margins -> quadctl.cli.app"),
])
def test_the_floors_break_when_a_lower_floor_imports_a_higher_one(tmp_path, module, line, broken):
    copy = tmp_path / "quadctl"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    target = copy / module
    target.write_text(target.read_text() + f"\n{line}  # an import that runs up\n")
    res = lint_imports(tmp_path)
    assert res.returncode == 1, res.stdout + res.stderr
    assert "BROKEN" in res.stdout and broken in res.stdout, res.stdout


def test_a_new_top_level_module_must_be_given_a_floor(tmp_path):
    copy = tmp_path / "quadctl"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    (copy / "autopilot.py").write_text('"""A new room."""\n')
    res = lint_imports(tmp_path)
    assert res.returncode == 1, res.stdout + res.stderr
    assert "quadctl.autopilot" in res.stdout, res.stdout
