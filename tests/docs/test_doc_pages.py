"""The pages, run: every command and config block of README.md and docs/**/*.md, and the output it prints.

Whatever fenced blocks a page holds are found and run, in page order, in a temporary folder of the
page's own (so no page depends on another having run first) that sees the checkout's ``configs/``,
``docs/``, ``examples/`` and ``benchmarks/``:

- ``bash`` blocks: each command (``a && b`` is two);
- ``console`` blocks: each ``$ command``, and the lines under it are its output: every piece of
  it (``...`` lines split the pieces, ``(...)`` and a trailing ``...`` elide within a line) must
  appear in what the command prints, at the width the page shows it, with only the numbers
  that change from run to run left free (:data:`VOLATILE`); a shown ``quadctl: error:`` means exit
  2, ``check failed`` exit 1, anything else exit 0; a block that shows the compiled backend's
  output is marked ``compiler``;
- ``python`` blocks: run as a script;
- ``yaml`` blocks: a config is validated (and one named like a bundled config is that file,
  verbatim), a sweep file is validated and run, a GitHub workflow's ``run:`` steps are run.

A page that needs a file its prose describes declares it in a comment, which neither GitHub nor
the site shows: ``<!-- page-test-file: my.yaml forward simulation.dt=0.001 -->`` is the bundled
``forward`` config with that value changed (each ``KEY=VALUE`` read as YAML), written as
``my.yaml`` in the page's folder before its blocks run. A block that repeats what an earlier block of
its page already ran (the README's walkthrough runs the command its install line ran) is marked
``<!-- page-test: slow -->`` on the line before it: it runs with the slow tests (``pytest -m slow``).

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
from _paths import ROOT
from test_examples import FIGURES

PAGES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts)]
"""Every page of the documentation: the README and the site's sources."""
WALKTHROUGH = ROOT / "docs" / "start" / "first-design.md"
SHARED = ("configs", "docs", "examples", "benchmarks", "tests")
"""Folders of the checkout the pages' commands name by relative path (``tests/data``: the flight logs)."""

NOT_RUN = {
    "pytest": "the test suite itself: running it from inside itself would recurse",
    "python benchmarks/bench.py": "the benchmark takes about a minute of timed runs; its options are parsed instead",
    "python benchmarks/instructions.py": "counts instructions under Valgrind, about five minutes",
    "python benchmarks/case_stages.py": "times three 1000-case sweeps' stages, its numbers this machine's; "
                                        "tests/sweep/test_stage_timer.py runs its timer on 16 cases",
    "sphinx-build": "builds the site: tests/docs/test_doc_site.py runs the same build (docs extra installed)",
    **{f"python examples/{script}": "without a folder it rewrites the checkout's docs/figures/; "
                                     "tests/docs/test_examples.py runs it into a temporary folder"
       for script, figures in FIGURES.items() if figures},
}
"""Command prefixes the test does not run, and why (kept short: everything else runs)."""

FILE_DECLARATION = re.compile(r"^<!-- page-test-file: (\S+) (\S+)((?: \S+=\S+)*) -->$", re.M)
"""A file a page's commands use and its prose describes: name, bundled config, ``KEY=VALUE`` changes."""

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
"""(in the page, in the output): numbers that differ from run to run or machine to machine.
Round-off-level numbers (below 1e-9, in scientific notation: residuals, a regulated state's final
error) are decided by the BLAS, the compiler and the CPU."""


# ---------------------------------------------------------------------------------------
# Reading the pages


def _name(page: Path) -> str:
    return page.relative_to(ROOT).as_posix()


@dataclass(frozen=True)
class Block:
    lang: str
    line: int
    text: str
    page: str = "README.md"
    slow: bool = False

    @property
    def where(self) -> str:
        return f"{self.page} line {self.line}"


@dataclass
class Command:
    line: int
    text: str
    shown: list[str] = field(default_factory=list)
    page: str = "README.md"

    @property
    def where(self) -> str:
        return f"{self.page} line {self.line}"

    @property
    def argv(self) -> list[str]:
        return shlex.split(self.text, comments=True)


SLOW_MARK = "<!-- page-test: slow -->"
"""On the line before a block: the block repeats an earlier one of its page, and runs with ``pytest -m slow``."""


def fenced_blocks(text: str, page: str = "README.md") -> list[Block]:
    """The fenced blocks of a page, each with its language: the first word after the fence (a MyST
    directive's ``{name}``, whatever arguments follow it: ````{literalinclude} ../examples/x.py``),
    closed by a fence of at least its own length."""
    blocks, lang, fence, start, body = [], None, "", 0, []
    lines = text.splitlines()
    for i, line in enumerate(lines, 1):
        opening = re.match(r"^(`{3,})\s*([^`\s]*)[^`]*$", line)
        if opening and lang is None:
            fence, lang, start, body = opening.group(1), opening.group(2) or "text", i, []
        elif lang is not None and re.fullmatch(rf"{fence}`*\s*", line):
            blocks.append(Block(lang, start, "\n".join(body) + "\n", page,
                                slow=start >= 2 and lines[start - 2].strip() == SLOW_MARK))
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
                out.append(Command(where, line[2:], page=block.page))
            elif out:
                out[-1].shown.append(line)
        elif line.strip() and not line.lstrip().startswith("#"):
            out += [Command(where, part.strip(), page=block.page) for part in line.split("&&")]
    return out


BLOCKS = [b for page in PAGES for b in fenced_blocks(page.read_text(encoding="utf-8"), _name(page))]
RUNNABLE = [b for b in BLOCKS if b.lang in ("bash", "sh", "shell", "console", "python", "yaml", "yml")]


def _id(block: Block) -> str:
    first = (block.text.strip().splitlines() or [""])[0]
    return f"{block.page}:L{block.line}-{block.lang}-{first[:40]}"


def declared_files(text: str) -> dict[str, tuple[str, dict[str, object]]]:
    """The files a page declares: name -> (bundled config, {key path: value})."""
    out = {}
    for m in FILE_DECLARATION.finditer(text):
        changes = dict(item.split("=", 1) for item in m.group(3).split())
        out[m.group(1)] = (m.group(2), {k: yaml.safe_load(v) for k, v in changes.items()})
    return out


# ---------------------------------------------------------------------------------------
# Running


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """A folder per page, made when the page's first block runs: its runs/ build up in page order."""
    made: dict[str, Path] = {}

    def folder_of(page: str) -> Path:
        if page not in made:
            made[page] = make_folder(tmp_path_factory.mktemp(re.sub(r"\W", "-", page)), ROOT / page)
        return made[page]

    return folder_of


def make_folder(where: Path, page: Path) -> Path:
    """A reader's folder for ``page``: the checkout's shared folders, and the files the page declares."""
    from quadctl import config

    for name in SHARED:
        if (ROOT / name).is_dir():
            (where / name).symlink_to(ROOT / name, target_is_directory=True)
    for name, (bundled, changes) in declared_files(page.read_text(encoding="utf-8")).items():
        data = config.load(bundled).model_dump(mode="json")
        for key, value in changes.items():
            *parents, last = key.split(".")
            node = data
            for part in parents:
                if not isinstance(node.get(part), dict):  # a section the config leaves out (None)
                    node[part] = {}
                node = node[part]
            node[last] = value
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
    elif argv[0] == "cat" and all((where / a).is_file() for a in argv[1:]):  # a file the page shows
        argv = [shutil.which("cat") or "cat", *argv[1:]]
    else:
        pytest.fail(f"{command.where}: `{command.text}`: tests/docs/test_doc_pages.py does not know how to "
                    "run this; teach it (or list it in NOT_RUN with the reason)")
    columns = max([80, *(len(line) for line in command.shown)])
    res = subprocess.run(argv, cwd=where, env=_environment(columns), stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, timeout=600, stdin=subprocess.DEVNULL)
    printed = res.stdout  # stdout and stderr as a terminal shows them, in order (both unbuffered)
    expected = 2 if any("quadctl: error:" in s for s in command.shown) else (
        1 if any("check failed" in s for s in command.shown) else 0)
    assert res.returncode == expected, (f"{command.where}: `{command.text}` exited {res.returncode}, "
                                        f"the page implies {expected}:\n{printed[-3000:]}")
    for piece in pieces(command.shown):
        assert re.search(pattern(piece), normalized(printed)), (
            f"{command.where}: `{command.text}` did not print what the page shows:\n"
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
    """A page's ``pip install`` installs this checkout, with extras it declares."""
    extras = declared_extras()
    targets = [a for a in argv[2:] if not a.startswith("-")]
    assert targets, f"{command.where}: `{command.text}` installs nothing"
    for target in targets:
        m = re.fullmatch(r"\.(?:\[(?P<extras>[\w,-]+)\])?", target)
        assert m, (f"{command.where}: `{command.text}`: quadctl is installed from the checkout "
                   f"(`pip install .` or `pip install '.[extra]'`), not `{target}`")
        for extra in filter(None, (m["extras"] or "").split(",")):
            assert extra in extras, f"{command.where}: no extra `{extra}` in pyproject.toml"


# ---------------------------------------------------------------------------------------
# The tests


def test_the_pages_have_blocks_to_run():
    kinds = {b.lang for b in RUNNABLE}
    assert {"bash", "console", "python", "yaml"} <= kinds, kinds
    pages = {b.page for b in RUNNABLE}
    assert "README.md" in pages and len(pages) >= 15, sorted(pages)


def test_a_declared_file_is_made_in_the_page_folder(tmp_path):
    """A page's file declaration makes the bundled config with the changes, in that page's folder only."""
    from quadctl import config

    page = tmp_path / "page.md"
    page.write_text("<!-- page-test-file: my.yaml forward simulation.dt=0.001 simulation.plant.mass=0.07 -->\n")
    (tmp_path / "folder").mkdir()
    where = make_folder(tmp_path / "folder", page)
    made = config.load(str(where / "my.yaml"))
    assert made.simulation.dt == 0.001 and made.simulation.plant.mass == 0.07 and made.name == "forward"
    assert (where / "docs").is_symlink() and (where / "configs").exists()


def test_the_walkthrough_names_every_bundled_config():
    """`--config` takes a bundled name: the walkthrough's paragraph that lists them named all but
    `schedule`. Every bundled config is named there, in backticks."""
    from quadctl import config

    text = WALKTHROUGH.read_text(encoding="utf-8")
    start = text.index("`--config` takes a file, or the name of a bundled config:")
    paragraph = text[start:text.index("\n\n", start)]
    missing = [name for name in config.bundled_names() if f"`{name}`" not in paragraph]
    assert not missing, f"{_name(WALKTHROUGH)}'s list of bundled configs leaves out {missing}"


def _param(block: Block):
    """A block whose shown output comes from the compiled backend needs a compiler to print it; a
    block marked as a repeat runs with the slow tests."""
    marks = [pytest.mark.compiler] if "(compiled" in block.text else []
    return pytest.param(block, id=_id(block), marks=[*marks, *([pytest.mark.slow] if block.slow else [])])


def in_guide(block: Block) -> bool:
    """The Guide's pages run in tests/docs/test_guide_pages.py: the pages' blocks in two files, one per worker."""
    return block.page.startswith("docs/guide/")


@pytest.mark.parametrize("block", [_param(b) for b in RUNNABLE if not in_guide(b)])
def test_page_block(block, folders):
    run_block(block, folders(block.page))


def run_block(block: Block, folder: Path) -> None:
    """One fenced block, run in its page's folder."""
    if block.lang in ("bash", "sh", "shell", "console"):
        commands = commands_of(block)
        assert commands, f"{block.where}: a {block.lang} block without a command"
        for command in commands:
            run(command, folder)
    elif block.lang == "python":
        script = folder / f"page_line_{block.line}.py"
        script.write_text(block.text)
        run(Command(block.line, f"python {script.name}", page=block.page), folder)
    else:
        run_yaml(block, folder)


def run_yaml(block: Block, where: Path) -> None:
    from quadctl import config

    data = yaml.safe_load(block.text)
    assert isinstance(data, dict), f"{block.where}: a YAML block that is not a mapping"
    if "jobs" in data:  # a CI workflow: its steps are commands
        steps = [s["run"] for job in data["jobs"].values() for s in job.get("steps", []) if "run" in s]
        assert steps, f"{block.where}: a workflow without run steps"
        for step in steps:
            for part in step.split("&&"):
                run(Command(block.line, part.strip(), page=block.page), where)
    elif "parameters" in data:  # a sweep file: valid, and its cases pass the gates it sets
        path = where / f"page_line_{block.line}.yaml"
        path.write_text(block.text)
        run(Command(block.line, f"quadctl sweep -c forward -s {path.name} -o runs/page-sweep-{block.line}",
                    page=block.page), where)
    elif "vehicle" in data or "lqr" in data or "name" in data:  # a config
        cfg = config.from_dict(data, f"{block.where}")
        bundled = ROOT / "configs" / f"{cfg.name}.yaml"
        if bundled.exists():
            assert block.text == bundled.read_text(), (f"{block.where} shows `{bundled.name}`, but "
                                                       "not as the bundled file is: copy it verbatim")
    else:
        pytest.fail(f"{block.where}: a YAML block tests/docs/test_doc_pages.py does not know; teach it")


INLINE = re.compile(r"`((?:quadctl|python|pip install) [^`]*)`")


def inline_commands() -> list[Command]:
    out = []
    for page in PAGES:
        fenced = {i for b in BLOCKS if b.page == _name(page) for i in range(b.line, b.line + b.text.count("\n") + 2)}
        for i, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
            if i not in fenced:
                out += [Command(i, m.group(1), page=_name(page)) for m in INLINE.finditer(line)]
    return out


INLINE_COMMANDS = inline_commands()


@pytest.mark.parametrize("command", INLINE_COMMANDS,
                         ids=[f"{c.page}:L{c.line}-{c.text[:40]}" for c in INLINE_COMMANDS])
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

        assert importlib.util.find_spec(argv[2]), f"{command.where}: no module {argv[2]}"
    else:
        script = argv[1] if len(argv) > 1 else ""
        assert script.endswith(".py") and (ROOT / script).is_file(), \
            f"{command.where}: `{command.text}`: no script {script} in the checkout"
        for arg in argv[2:]:
            assert not arg.startswith("/"), \
                f"{command.where}: `{command.text}` names {arg}, a path of one machine, not the reader's"
        flags = [a.split("=")[0] for a in argv[2:] if a.startswith("-")]
        if flags:  # its options exist (argparse's --help lists them)
            usage = subprocess.run([sys.executable, script, "--help"], cwd=ROOT, capture_output=True, text=True,
                                   timeout=120, env=_environment(200)).stdout
            assert all(f in usage for f in flags), f"{command.where}: `{command.text}`: {usage}"


def check_quadctl(args: list[str], command: Command) -> None:
    import typer

    from quadctl.cli.app import app

    group = typer.main.get_command(app)
    where = f"{command.where}: `{command.text}`"
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


def test_a_directive_with_arguments_is_one_block_and_not_run():
    """A MyST directive's fence carries arguments (```` ```{literalinclude} ../examples/x.py ````): it
    opens one block of its own kind, which is not run, and the block after it is read as it is."""
    text = ("```{literalinclude} ../examples/x.py\n:language: python\n```\n\n"
            "````{note}\n```bash\nquadctl trim\n```\n````\n\n```console\n$ quadctl trim\n```\n")
    blocks = fenced_blocks(text, "page.md")
    assert [(b.lang, b.line) for b in blocks] == [("{literalinclude}", 1), ("{note}", 5), ("console", 11)]
    assert blocks[0].text == ":language: python\n" and blocks[2].text == "$ quadctl trim\n"


def test_a_block_marked_as_a_repeat_is_slow_and_others_are_not():
    text = "```bash\nquadctl trim\n```\n\n<!-- page-test: slow -->\n```console\n$ quadctl trim\n```\n"
    first, second = fenced_blocks(text, "page.md")
    assert (first.slow, second.slow) == (False, True)
    assert [m.name for m in _param(second).marks] == ["slow"] and not _param(first).marks
