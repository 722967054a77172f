"""The documentation site: it builds from docs/ with warnings as errors and broken references failing
(``sphinx-build -W -n``), it fetches nothing when read, and its reference documents what the pages use.

The reference pages are generated while the site builds (docs/_ext/quadctl_reference.py); their
generators are checked here on their own too, without Sphinx: every command and every config key.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest
from _paths import ROOT

DOCS = ROOT / "docs"
sys.path.insert(0, str(DOCS / "_ext"))
import quadctl_reference  # noqa: E402

ASSET = re.compile(r"""<(?:script|img|link|iframe|source|video|audio)\b[^>]*?\b(?:src|href)=["']?(?:https?:)?//""",
                   re.I)
"""An element that makes a browser fetch from the network: a script, image, stylesheet, frame or media
from an http(s) or protocol-relative address (a plain link ``<a href>`` is only followed when clicked)."""
CSS_URL = re.compile(r"""url\(\s*["']?(?:https?:)?//""", re.I)
IMPORT = re.compile(r"^\s*(?:from (quadctl[\w.]*) import ([\w, ()]+)|import (quadctl[\w.]*))", re.M)


def _sphinx_missing() -> str | None:
    missing = [m for m in ("sphinx", "myst_parser", "furo") if importlib.util.find_spec(m) is None]
    return f"the docs extra is not installed ({', '.join(missing)}): pip install '.[docs]'" if missing else None


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    why = _sphinx_missing()
    if why:
        pytest.skip(why)
    out = tmp_path_factory.mktemp("site")
    res = subprocess.run([sys.executable, "-m", "sphinx", "-W", "-n", "--keep-going", "-q", "-E", "-b", "html",
                          str(DOCS), str(out / "html"), "-d", str(out / "doctrees")],
                         capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert res.returncode == 0, f"sphinx-build -W -n failed:\n{res.stderr[-6000:]}"
    assert not res.stderr.strip(), f"sphinx-build warned:\n{res.stderr[-6000:]}"
    return out / "html"


def test_the_site_builds_without_a_warning_and_has_every_page(site):
    sources = sorted(p.relative_to(DOCS).with_suffix(".html") for p in DOCS.rglob("*.md") if "_build" not in p.parts)
    missing = [str(p) for p in sources if not (site / p).is_file()]
    assert not missing, f"pages the build did not write: {missing}"


def test_no_page_fetches_anything(site):
    """The site reads offline, like the run report: no script, style, font or image from the network."""
    fetching = {}
    for path in [*site.rglob("*.html"), *site.rglob("*.css")]:
        text = path.read_text(encoding="utf-8", errors="replace")
        found = ASSET.findall(text) + CSS_URL.findall(text)
        if found:
            fetching[str(path.relative_to(site))] = found[:3]
    assert not fetching, fetching


@pytest.mark.parametrize("html, fetches", [
    ('<script src="https://cdn.example.com/mathjax.js"></script>', True),
    ('<link rel="stylesheet" href="//fonts.example.com/css">', True),
    ("<img src='http://example.com/a.png'>", True),
    ('<a href="https://github.com/x">x</a>', False),
    ('<script src="_static/furo.js"></script>', False),
])
def test_a_fetching_page_is_found(html, fetches):
    assert bool(ASSET.search(html)) == fetches
    assert bool(CSS_URL.search("body { background: url('https://x.example/a.png') }"))


def _documented(site: Path) -> set[str]:
    """Every Python object the built reference documents (its objects.inv)."""
    from sphinx.util.inventory import InventoryFile

    with open(site / "objects.inv", "rb") as f:
        inventory = InventoryFile.load(f, "", lambda *parts: "/".join(parts))
    data = inventory.data if hasattr(inventory, "data") else inventory
    return {name for kind, items in data.items() if kind.startswith("py:") for name in items}


def _imported_names() -> set[str]:
    """``module.name`` for every name the pages' Python blocks import from quadctl."""
    sys.path.insert(0, str(ROOT / "tests"))
    from test_doc_pages import BLOCKS

    names = set()
    for block in BLOCKS:
        if block.lang != "python":
            continue
        for m in IMPORT.finditer(block.text):
            if m.group(1):
                for name in re.findall(r"\w+", m.group(2)):
                    names.add(f"{m.group(1)}.{name}")
    return names


def test_the_reference_documents_every_name_the_pages_import(site):
    """A public name the pages use is in the Python reference (as python-control's docs test it):
    a function or class the pages import, or, for a module the pages import, the module's ``__all__``
    where it has one (the package's public face included)."""
    import importlib

    import quadctl

    documented = _documented(site)
    wanted: dict[str, set[str]] = {}  # a name as the pages import it -> the names it is documented under
    for dotted in sorted(_imported_names()):
        module, _, name = dotted.rpartition(".")
        parent = importlib.import_module(module)
        value = getattr(parent, name) if hasattr(parent, name) else importlib.import_module(dotted)
        if isinstance(value, type(quadctl)):  # a module: its public names, where it declares them
            wanted |= {f"{value.__name__}.{n}": {f"{value.__name__}.{n}"}
                       for n in getattr(value, "__all__", []) if not n.startswith("__")}
        elif callable(value):
            wanted[dotted] = {dotted, f"{value.__module__}.{value.__qualname__}"}
    wanted |= {f"quadctl.{n}": {f"quadctl.{n}"} for n in getattr(quadctl, "__all__", []) if not n.startswith("__")}
    assert wanted, "the pages import nothing from quadctl"
    missing = sorted(n for n, names in wanted.items() if not names & documented)
    assert not missing, f"used by the pages but missing from docs/reference/python.md: {missing}"


def test_an_example_is_shown_by_its_docstring():
    """The gallery's entry of an example: its docstring's title line as a heading, the rest as prose."""
    entry = quadctl_reference.example_markdown("square_mission.py")
    title, blank, first, *_ = entry.splitlines()
    assert (title, blank) == ("## A waypoint mission: the bundled square", "")
    assert first.startswith("The bundled square config:") and "``python examples/square_mission.py [FOLDER]``" in entry


def test_the_cli_reference_has_every_command_and_option():
    import typer

    from quadctl.cli.app import app

    text = quadctl_reference.cli_markdown()
    root = typer.main.get_command(app)
    assert root.commands, "no commands"
    for name, command in root.commands.items():
        assert f"## `quadctl {name}`" in text, name
        for param in command.params:
            if param.param_type_name == "option" and not getattr(param, "hidden", False):
                section = text.split(f"## `quadctl {name}`")[1].split("\n## ")[0]
                assert any(re.search(rf"[`, ]{re.escape(o)}\b", section) for o in param.opts), (name, param.opts)


def test_the_config_reference_has_every_key_with_its_default_and_unit():
    from quadctl import config

    text = quadctl_reference.config_markdown()
    keys = re.findall(r"^\| `([^`]+)` \| [^|]*\| ([^|]*) \| ([^|]*) \|$", text, re.M)
    table = {key: (default.strip(), meaning.strip()) for key, default, meaning in keys}

    def walk(model, prefix):
        return [f"{prefix}{name}" for name in model.model_fields]

    from quadctl.config.controller_schema import ControllerConfig
    from quadctl.config.schema import Config
    from quadctl.config.simulation_schema import SimulationConfig
    from quadctl.config.vehicle_schema import VehicleConfig

    expected = [*walk(Config, ""), *walk(VehicleConfig, "vehicle."), *walk(SimulationConfig, "simulation."),
                *walk(ControllerConfig, "controller.")]
    sections = set(re.findall(r"^### `([^`]+)`$", text, re.M))  # a section: a heading, its keys in rows
    missing = [k for k in expected if k not in table and k not in sections]
    assert not missing, missing
    assert {"vehicle", "simulation", "controller", "motors", "estimator"} <= sections
    assert table["vehicle.mass"] == (f"`{config.load('forward').vehicle.mass}`", "kg")
    assert table["name"][0] == "required"
    assert table["controller.rate"][0] == "absent" and "absent: continuous" in table["controller.rate"][1]
    assert table["simulation.dt"][0] == '`"auto"`'


def test_a_page_marker_without_a_generator_fails_the_build():
    source = ["<!-- quadctl-reference: nothing -->\n"]
    with pytest.raises(ValueError, match="no generated reference named 'nothing'"):
        quadctl_reference._source_read(None, "reference/x", source)
    source = ["# CLI\n<!-- quadctl-reference: cli -->\n"]
    quadctl_reference._source_read(None, "reference/cli", source)
    assert "## `quadctl design`" in source[0] and "<!--" not in source[0]
