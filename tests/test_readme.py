"""The README, run: every command and config block it shows, and the output it prints.

Whatever fenced blocks the README holds are found and run, in README order, in one temporary
folder that sees the checkout's ``docs/``, ``examples/`` and ``benchmarks/``:

- ``bash`` blocks: each command (``a && b`` is two);
- ``console`` blocks: each ``$ command``, and the lines under it are its output: every piece of
  it (``...`` lines split the pieces, ``(...)`` and a trailing ``...`` elide within a line) must
  appear in what the command prints, at the width the README shows it, with only the numbers
  that change from run to run left free (:data:`VOLATILE`); a shown ``quadctl: error:`` means exit
  2, ``check failed`` exit 1, anything else exit 0; a block that shows the compiled backend's
  output is marked ``compiler``;
- ``python`` blocks: run as a script;
- ``yaml`` blocks: a config is validated (and one named like a bundled config is that file,
  verbatim), a sweep file is validated and run, a GitHub workflow's ``run:`` steps are run.

``pip install`` is never run (it would change this environment): it must install this checkout
(``.``, with extras ``pyproject.toml`` declares). Inline ``quadctl ...`` commands in the prose are
parsed against the command line (options and arguments exist), inline ``python script`` ones must
name a script of the checkout. The few commands not run are in :data:`NOT_RUN`, each with why.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
SHARED = ("docs", "examples", "benchmarks", "tests")
"""Folders of the checkout the README's commands name by relative path (``tests/data``: the flight logs)."""

NOT_RUN = {
    "pytest": "the test suite itself: running it from inside itself would recurse",
    "python benchmarks/bench.py": "the benchmark takes about a minute of timed runs; its options are parsed instead",
    "python docs/figures.py": "rewrites the checkout's docs/figures/*.png; tests/test_examples.py runs the library "
                              "calls it makes",
}
"""Command prefixes the test does not run, and why (kept short: everything else runs)."""

PROVIDED = {
    "my.yaml": ("forward", {"simulation": {"dt": 0.001}}),  # "quadctl simulate -c my.yaml  # with simulation.dt: 0.001"
    "slip.yaml": ("crazyflie", {"motors": {"arm_length": 46.0}}),  # "quadctl trim -c slip.yaml  # crazyflie, ... mm"
}
"""Files the README's prose describes and its commands use: made in the folder before they run."""

VOLATILE = [
    (r"(?<=steps in )[\d.]+ (?:ms|s)\b", r"[\d.]+ (?:ms|s)"),            # wall time of a simulation
    (r"[\d.]+ M (?:RK4 )?steps/s", r"[\d.]+ M (?:RK4 )?steps/s"),       # throughput
    (r"\d+ cases/s", r"\d+ cases/s"),
    (r"\d+:\d\d:\d\d", r"\d+:\d\d:\d\d"),                                # progress bar clock
    (r"(?<=computed\) in )[\d.]+ s\b", r"[\d.]+ s"),
    (r"[\d.,]+ designs/s", r"[\d.,]+ designs/s"),
    (r"[\d.]+ µs CPU", r"[\d.]+ µs CPU"),
    (r"(?<=local processes \()\d+(?=\))", r"\d+"),                        # the machine's cores
    (r"-?\d(?:\.\d+)?e-(?:1\d|[2-9]\d)", r"-?\d(?:\.\d+)?e-(?:1\d|[2-9]\d)"),  # round-off (below 1e-9)
    (r"[━─]+", r"[━─]+"),                                               # a rule's length follows its cells
]
"""(in the README, in the output): numbers that differ from run to run or machine to machine.
Round-off-level numbers (below 1e-9, in scientific notation: residuals, a regulated state's final
error) are decided by the BLAS, the compiler and the CPU."""


# ---------------------------------------------------------------------------------------
# Reading the README


@dataclass(frozen=True)
class Block:
    lang: str
    line: int
    text: str


@dataclass
class Command:
    line: int
    text: str
    shown: list[str] = field(default_factory=list)

    @property
    def argv(self) -> list[str]:
        return shlex.split(self.text, comments=True)


def fenced_blocks(text: str) -> list[Block]:
    blocks, lang, start, body = [], None, 0, []
    for i, line in enumerate(text.splitlines(), 1):
        fence = re.match(r"^```\s*(\S*)\s*$", line)
        if fence and lang is None:
            lang, start, body = fence.group(1) or "text", i, []
        elif line.startswith("```") and lang is not None:
            blocks.append(Block(lang, start, "\n".join(body) + "\n"))
            lang = None
        elif lang is not None:
            body.append(line)
    return blocks


def commands_of(block: Block) -> list[Command]:
    """The commands of a shell or console block (a console block's output lines under each)."""
    out: list[Command] = []
    for offset, line in enumerate(block.text.splitlines(), 1):
        where = block.line + offset
        if block.lang == "console":
            if line.startswith("$ "):
                out.append(Command(where, line[2:]))
            elif out:
                out[-1].shown.append(line)
        elif line.strip() and not line.lstrip().startswith("#"):
            out += [Command(where, part.strip()) for part in line.split("&&")]
    return out


BLOCKS = fenced_blocks(README.read_text(encoding="utf-8"))
RUNNABLE = [b for b in BLOCKS if b.lang in ("bash", "sh", "shell", "console", "python", "yaml", "yml")]


def _id(block: Block) -> str:
    first = (block.text.strip().splitlines() or [""])[0]
    return f"L{block.line}-{block.lang}-{first[:40]}"


# ---------------------------------------------------------------------------------------
# Running


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """One folder for every block, as a reader's would be: their runs/ build up in README order."""
    from quadctl import config

    where = tmp_path_factory.mktemp("readme")
    for name in SHARED:
        (where / name).symlink_to(ROOT / name, target_is_directory=True)
    for name, (bundled, changes) in PROVIDED.items():
        data = config.load(bundled).model_dump(mode="json")
        for key, value in changes.items():
            data[key] = {**data[key], **value}
        (where / name).write_text(yaml.safe_dump(data, sort_keys=False))
    return where


def _environment(columns: int) -> dict:
    return {**os.environ, "MPLBACKEND": "Agg", "COLUMNS": str(columns), "PYTHONUNBUFFERED": "1",
            "TERM": "dumb", "NO_COLOR": "1"}


def _not_run(argv: list[str]) -> str | None:
    text = " ".join(argv)
    return next((why for prefix, why in NOT_RUN.items() if text == prefix or text.startswith(prefix + " ")), None)


def run(command: Command, where: Path) -> None:
    argv = command.argv
    if not argv:
        return
    if argv[:2] == ["pip", "install"]:
        check_pip(argv, command)
        return
    if _not_run(argv):
        return
    if argv[0] == "ruff":
        if shutil.which("ruff") is None:
            pytest.skip("ruff is not installed here (pip install -e '.[dev]' installs it)")
        argv, where = [shutil.which("ruff"), *argv[1:]], ROOT  # lints the checkout, not the folder
    elif argv[0] == "quadctl":
        argv = [sys.executable, "-m", "quadctl", *argv[1:]]
    elif argv[0] == "python":
        argv = [sys.executable, *argv[1:]]
    elif argv[0] == "cat" and all((where / a).is_file() for a in argv[1:]):  # a file the README shows
        argv = [shutil.which("cat") or "cat", *argv[1:]]
    else:
        pytest.fail(f"README line {command.line}: `{command.text}`: tests/test_readme.py does not know how to "
                    "run this; teach it (or list it in NOT_RUN with the reason)")
    columns = max([80, *(len(line) for line in command.shown)])
    res = subprocess.run(argv, cwd=where, env=_environment(columns), stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, timeout=600, stdin=subprocess.DEVNULL)
    printed = res.stdout  # stdout and stderr as a terminal shows them, in order (both unbuffered)
    expected = 2 if any("quadctl: error:" in s for s in command.shown) else (
        1 if any("check failed" in s for s in command.shown) else 0)
    assert res.returncode == expected, (f"README line {command.line}: `{command.text}` exited {res.returncode}, "
                                        f"the README implies {expected}:\n{printed[-3000:]}")
    for piece in pieces(command.shown):
        assert re.search(pattern(piece), normalized(printed)), (
            f"README line {command.line}: `{command.text}` did not print what the README shows:\n"
            f"  shown:   {normalized(piece)}\n  printed:\n{printed[-5000:]}")


def pieces(shown: list[str]) -> list[str]:
    """The shown output split at ``...`` lines (what is left out there is not checked)."""
    out, current = [], []
    for line in shown:
        if line.strip() == "...":
            out.append(current)
            current = []
        else:
            current.append(line)
    out.append(current)
    return [" ".join(p) for p in out if any(s.strip() for s in p)]


def normalized(text: str) -> str:
    return " ".join(text.split())


_TOKENS = re.compile("|".join([r"(?P<elided>\(\.\.\.\)|\.\.\.)"]
                              + [f"(?P<v{i}>{readme})" for i, (readme, _) in enumerate(VOLATILE)]))


def pattern(piece: str) -> str:
    """A regex for a shown piece: literal text, with elisions and volatile numbers left free."""
    text, parts, pos = normalized(piece), [], 0
    for m in _TOKENS.finditer(text):
        if m.lastgroup == "elided":  # "x ..." also stands for "x; ..." and "x, ..."
            parts += [re.escape(text[pos:m.start()].rstrip()), ".*?"]
        else:
            parts.append(re.escape(text[pos:m.start()]))
            parts.append(VOLATILE[int(m.lastgroup[1:])][1])
        pos = m.end()
    parts.append(re.escape(text[pos:]))
    return "".join(parts)


def declared_extras() -> set[str]:
    try:
        import tomllib
    except ImportError:  # Python 3.10: what the installed metadata says pyproject.toml declared
        from importlib.metadata import metadata

        return set(metadata("quadctl").get_all("Provides-Extra") or [])
    return set(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"])


def check_pip(argv: list[str], command: Command) -> None:
    """A README ``pip install`` installs this checkout, with extras it declares."""
    extras = declared_extras()
    targets = [a for a in argv[2:] if not a.startswith("-")]
    assert targets, f"README line {command.line}: `{command.text}` installs nothing"
    for target in targets:
        m = re.fullmatch(r"\.(?:\[(?P<extras>[\w,-]+)\])?", target)
        assert m, (f"README line {command.line}: `{command.text}`: quadctl is installed from the checkout "
                   f"(`pip install .` or `pip install '.[extra]'`), not `{target}`")
        for extra in filter(None, (m["extras"] or "").split(",")):
            assert extra in extras, f"README line {command.line}: no extra `{extra}` in pyproject.toml"


# ---------------------------------------------------------------------------------------
# The tests


def test_the_readme_has_blocks_to_run():
    kinds = {b.lang for b in RUNNABLE}
    assert {"bash", "console", "python", "yaml"} <= kinds, kinds


def test_the_walkthrough_names_every_bundled_config():
    """`--config` takes a bundled name: the walkthrough's paragraph that lists them named all but
    `schedule`. Every bundled config is named there, in backticks."""
    from quadctl import config

    text = README.read_text(encoding="utf-8")
    start = text.index("`--config` takes a file, or the name of a bundled config:")
    paragraph = text[start:text.index("\n\n", start)]
    missing = [name for name in config.bundled_names() if f"`{name}`" not in paragraph]
    assert not missing, f"README's list of bundled configs leaves out {missing}"


def _param(block: Block):
    """A block whose shown output comes from the compiled backend needs a compiler to print it."""
    compiled = "(compiled" in block.text
    return pytest.param(block, id=_id(block), marks=[pytest.mark.compiler] if compiled else [])


@pytest.mark.parametrize("block", [_param(b) for b in RUNNABLE])
def test_readme_block(block, folder):
    if block.lang in ("bash", "sh", "shell", "console"):
        commands = commands_of(block)
        assert commands, f"README line {block.line}: a {block.lang} block without a command"
        for command in commands:
            run(command, folder)
    elif block.lang == "python":
        script = folder / f"readme_line_{block.line}.py"
        script.write_text(block.text)
        run(Command(block.line, f"python {script.name}"), folder)
    else:
        run_yaml(block, folder)


def run_yaml(block: Block, where: Path) -> None:
    from quadctl import config

    data = yaml.safe_load(block.text)
    assert isinstance(data, dict), f"README line {block.line}: a YAML block that is not a mapping"
    if "jobs" in data:  # a CI workflow: its steps are commands
        steps = [s["run"] for job in data["jobs"].values() for s in job.get("steps", []) if "run" in s]
        assert steps, f"README line {block.line}: a workflow without run steps"
        for step in steps:
            for part in step.split("&&"):
                run(Command(block.line, part.strip()), where)
    elif "parameters" in data:  # a sweep file: valid, and its cases pass the gates it sets
        path = where / f"readme_line_{block.line}.yaml"
        path.write_text(block.text)
        run(Command(block.line, f"quadctl sweep -c forward -s {path.name} -o runs/readme-sweep-{block.line}"), where)
    elif "vehicle" in data or "lqr" in data or "name" in data:  # a config
        cfg = config.from_dict(data, f"README line {block.line}")
        bundled = ROOT / "quadctl" / "configs" / f"{cfg.name}.yaml"
        if bundled.exists():
            assert block.text == bundled.read_text(), (f"README line {block.line} shows `{bundled.name}`, but "
                                                       "not as the bundled file is: copy it verbatim")
    else:
        pytest.fail(f"README line {block.line}: a YAML block tests/test_readme.py does not know; teach it")


INLINE = re.compile(r"`((?:quadctl|python|pip install) [^`]*)`")


def inline_commands() -> list[Command]:
    text = README.read_text(encoding="utf-8")
    fenced = {i for b in BLOCKS for i in range(b.line, b.line + b.text.count("\n") + 2)}
    out = []
    for i, line in enumerate(text.splitlines(), 1):
        if i not in fenced:
            out += [Command(i, m.group(1)) for m in INLINE.finditer(line)]
    return out


INLINE_COMMANDS = inline_commands()


@pytest.mark.parametrize("command", INLINE_COMMANDS, ids=[f"L{c.line}-{c.text[:40]}" for c in INLINE_COMMANDS])
def test_inline_command(command):
    """A command in the prose exists as written: its command, options and arguments parse
    (``[--plot]`` is an optional flag, ``...`` elided arguments, ``NAME`` a placeholder)."""
    argv = shlex.split(re.sub(r"\[(--?[\w-]+[^\]]*)\]", r"\1", command.text))
    if argv[:2] == ["pip", "install"]:
        check_pip(argv, command)
    elif argv[0] == "quadctl":
        check_quadctl(argv[1:], command)
    elif argv[1:2] == ["-m"]:
        import importlib.util

        assert importlib.util.find_spec(argv[2]), f"README line {command.line}: no module {argv[2]}"
    else:
        script = argv[1] if len(argv) > 1 else ""
        assert script.endswith(".py") and (ROOT / script).is_file(), \
            f"README line {command.line}: `{command.text}`: no script {script} in the checkout"
        for arg in argv[2:]:
            assert not arg.startswith("/"), \
                f"README line {command.line}: `{command.text}` names {arg}, a path of one machine, not the reader's"
        flags = [a.split("=")[0] for a in argv[2:] if a.startswith("-")]
        if flags:  # its options exist (argparse's --help lists them)
            usage = subprocess.run([sys.executable, script, "--help"], cwd=ROOT, capture_output=True, text=True,
                                   timeout=120, env=_environment(200)).stdout
            assert all(f in usage for f in flags), f"README line {command.line}: `{command.text}`: {usage}"


def check_quadctl(args: list[str], command: Command) -> None:
    import typer

    from quadctl.cli.app import app

    group = typer.main.get_command(app)
    where = f"README line {command.line}: `{command.text}`"
    options = {o for p in group.params for o in getattr(p, "opts", [])}
    while args and args[0].startswith("-"):
        assert args[0] in options, f"{where}: quadctl has no option {args[0]}"
        valued = any(args[0] in getattr(p, "opts", []) and not getattr(p, "is_flag", True) for p in group.params)
        args = args[2:] if valued else args[1:]  # `quadctl --width 100 design`: 100 is --width's
    if not args or args[0] == "...":
        return
    sub = group.commands.get(args[0])
    assert sub is not None, f"{where}: quadctl has no command {args[0]}"
    rest = args[1:]
    known = {o for p in sub.params for o in [*getattr(p, "opts", []), *getattr(p, "secondary_opts", [])]}
    for token in rest:
        if token.startswith("-"):
            assert token.split("=")[0] in known, f"{where}: `quadctl {args[0]}` has no option {token}"
    if rest and "..." not in rest and not any(t.isupper() for t in rest):  # a whole command line: it parses
        try:
            sub.make_context(args[0], list(rest))
        except Exception as exc:  # typer's own click: its exception classes are not click's
            if "does not exist" not in str(exc):  # a file the prose describes (mc.yaml) need not be here
                raise AssertionError(f"{where}: {exc}") from None
