"""Advice that exists: every option and config key a message names is one quadctl has.

A hint such as "delete it or rerun with --fresh" is only help if the command that printed it has
``--fresh`` (``sweep`` has not: it used to say so of a corrupted chunk). The options are read from
the CLI itself (typer's click command tree), the keys from the config schema.
"""

from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

import quadctl
from quadctl import config
from quadctl.cli.app import app

PACKAGE = Path(quadctl.__file__).parent
OPTION_RE = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
KEY_RE = re.compile(r"(?<![\w.`-])(?:" + "|".join(config.Config.model_fields) + r")(?:\.[A-Za-z_]\w*)+")
NOT_KEYS = re.compile(r"\.(json|npz|png|csv|yaml|yml|py|md|html|parts|c|h)$")
"""File names (trim.json, simulate.py, the firmware's motors.c) look like key paths."""


def _options(command) -> set[str]:
    return {opt for param in command.params for opt in (*param.opts, *param.secondary_opts)}


ROOT = typer.main.get_command(app)
ROOT_OPTIONS = _options(ROOT) | set(ROOT.context_settings["help_option_names"])
COMMAND_OPTIONS = {name: _options(cmd) for name, cmd in ROOT.commands.items()}


def _module_file(name: str) -> Path | None:
    path = PACKAGE.parent / (name.replace(".", "/") + ".py")
    if path.exists():
        return path
    package = PACKAGE.parent / name.replace(".", "/") / "__init__.py"
    return package if package.exists() else None


@cache
def _direct_imports(path: Path) -> tuple[Path, ...]:
    """The quadctl files ``path`` itself imports, at any depth of the file (lazy imports too)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("quadctl"):
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        found += [f for f in map(_module_file, (n for n in names if n.startswith("quadctl"))) if f]
    return tuple(found)


def _imports(path: Path) -> set[Path]:
    """The quadctl files ``path`` imports, at any depth of the file (lazy imports too), and on."""
    seen, todo = set(), [path]
    while todo:
        here = todo.pop()
        if here in seen:
            continue
        seen.add(here)
        todo += _direct_imports(here)
    return seen


REACH = {name: _imports(PACKAGE / "cli" / "commands" / f"{name}.py") for name in COMMAND_OPTIONS}
"""Command -> the files whose messages it can print."""
FOR_OTHER_COMMANDS = {("quadctl/cli/commands/configs.py", "--config")}
"""Hints about another command's option, on purpose: `configs` lists what to give the others."""


def _strings(path: Path):
    """Every string constant of a file (f-strings: their literal parts), with its line."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            yield node.lineno, node.value


def _named_options():
    for path in sorted(PACKAGE.rglob("*.py")):
        for line, text in _strings(path):
            for option in OPTION_RE.findall(text):
                yield path, line, option


def test_the_scan_finds_the_hints():
    """The scan is not vacuous: it sees the options quadctl's messages are known to name."""
    found = {option for _, _, option in _named_options()}
    assert {"--fresh", "--resume", "--debug", "--scheduler", "--jobs", "--out", "--config"} <= found


def test_every_option_a_message_names_exists_in_a_command_that_prints_it():
    """An option named in a module's strings must belong to a command that imports that module
    (or to the root: --debug, --version); a module no command imports may name any command's."""
    wrong = []
    for path, line, option in _named_options():
        commands = [name for name, files in REACH.items() if path in files] or list(COMMAND_OPTIONS)
        allowed = ROOT_OPTIONS.union(*(COMMAND_OPTIONS[c] for c in commands))
        if option not in allowed and (str(path.relative_to(PACKAGE.parent)), option) not in FOR_OTHER_COMMANDS:
            wrong.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {option} (commands: {', '.join(commands)})")
    assert wrong == []


def _named_keys():
    for path in sorted(PACKAGE.rglob("*.py")):
        for line, text in _strings(path):
            for key in KEY_RE.findall(text):
                if not NOT_KEYS.search(key):
                    yield path, line, key


def test_the_scan_finds_the_keys():
    found = {key for _, _, key in _named_keys()}
    assert {"simulation.dt", "controller.rate", "vehicle.drag", "motors.max_thrust", "vehicle.mass"} <= found


def test_every_config_key_a_message_names_exists():
    """``controller.rate``, ``vehicle.drag[2]``, ``simulation.noise.seed``: paths in the schema
    (names under lqr, subsystems, initial_offset, sensor, limits are free)."""
    wrong = [f"{path.relative_to(PACKAGE.parent)}:{line}: {key}" for path, line, key in _named_keys()
             if not _in_schema(key.split("."))]
    assert wrong == []


def _in_schema(parts: list[str]) -> bool:
    model, free = config.Config, False
    for part in parts:
        if free:  # a free name (lqr.<name>, initial_offset.<state>): its value's model follows
            free = False
            continue
        if model is None or part not in model.model_fields:
            return False
        annotation = model.model_fields[part].annotation
        model, free = config.first_model(annotation), "dict" in str(annotation)
    return True


@pytest.mark.parametrize("key,exists", [("controller.rate", True), ("simulation.noise.seed", True),
                                        ("lqr.roll.Q", True), ("simulation.initial_offset.pD", True),
                                        ("vehicle.drag", True), ("vehicle.mas", False), ("motors.thrust", False),
                                        ("lqr.roll.S", False), ("simulation.fresh", False)])
def test_the_schema_walk(key, exists):
    assert _in_schema(key.split(".")) == exists


def test_a_corrupted_sweep_chunk_names_an_option_sweep_has(tmp_path):
    """The hint a user meets: the chunk journal of an interrupted sweep, damaged, then --resume."""
    runner = CliRunner()
    sweep = tmp_path / "s.yaml"
    sweep.write_text("parameters:\n  lqr.roll.Q[1]: [10, 50]\nset: {simulation.duration: 0.05}\nchunk_size: 1\n")
    args = ["sweep", "-s", str(sweep), "-o", str(tmp_path / "out"), "-j", "1", "--json"]
    assert runner.invoke(app, args).exit_code == 0
    chunk = sorted((tmp_path / "out" / "sweep.parts").glob("chunk-*.json"))[0]
    chunk.write_text('{"rows": [')
    res = runner.invoke(app, [*args, "--resume"])
    assert res.exit_code == 2
    assert res.stderr == (f"quadctl: error: {chunk}: corrupted artifact (Expecting value: line 1 column 11 (char 10)); "
                          "delete it, or run without --resume to start over\n")
    assert set(OPTION_RE.findall(res.stderr)) <= COMMAND_OPTIONS["sweep"] | ROOT_OPTIONS
