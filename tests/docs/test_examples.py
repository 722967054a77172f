"""Every example runs (under the Agg backend, in a temporary folder) and draws the figures it promises.

The figures the README and the pages show (``docs/figures/*.png``) are drawn by the examples, each
into the folder its first argument names (the checkout's ``docs/figures/`` without one): here into a
temporary folder, so a run never rewrites the checkout. The gallery (``docs/examples.md``) shows
every example. An example taking more than about 3 s is marked slow (CI's second step runs it):
:func:`test_every_figure_is_drawn_by_an_example` still checks, in the default run, that what it
promises is in ``docs/figures/``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from _paths import ROOT

EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
GALLERY = ROOT / "docs" / "examples.md"

FIGURES = {
    "library_quickstart.py": (),
    "trim_envelope.py": ("trim-envelope.png",),
    "design_that_flies.py": ("peak-demand.png", "mambo-response.png", "mambo-roll-margins.png",
                             "lqi-mass-error.png"),
    "lag_and_delay.py": ("lag-and-delay.png",),
    "uncertainty_bands.py": ("uncertainty-bands.png",),
    "wind_gust.py": ("crazyflie-gust.png",),
    "lqg_vs_lqr.py": ("lqg-vs-lqr.png",),
    "square_mission.py": ("square-mission.png",),
    "schedule_envelope.py": ("schedule-envelope.png",),
    "speed_schedule_transition.py": ("speed-schedule-transition.png",),
    "crazyflie_identified.py": ("crazyflie-identified.png",),
}
"""Each example and the PNGs it writes into the folder it is given."""

FAST = {"library_quickstart.py", "trim_envelope.py"}
"""The examples of the default run (about 1 and 2 s); the others take 4 s or more each (with a warm compile
cache), and run with ``-m slow``."""


def _param(script: Path):
    return pytest.param(script, id=script.name, marks=[] if script.name in FAST else [pytest.mark.slow])


@pytest.mark.parametrize("script", [_param(p) for p in EXAMPLES])
def test_example_runs_and_draws_its_figures(script, tmp_path):
    out = tmp_path / "figures"
    env = {**os.environ, "MPLBACKEND": "Agg"}
    res = subprocess.run([sys.executable, str(script), str(out)], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip()
    promised = FIGURES[script.name]
    empty = [name for name in promised if not (out / name).is_file() or (out / name).stat().st_size == 0]
    assert not empty, f"{script.name} did not write {empty} into the folder it was given:\n{res.stdout[-2000:]}"
    written = sorted(p.name for p in out.glob("*")) if out.is_dir() else []
    assert written == sorted(promised), f"{script.name} wrote {written}, tests/docs/test_examples.py lists {promised}"
    assert not [p.name for p in tmp_path.iterdir() if p != out], "an example wrote outside the folder it was given"


def test_every_example_lists_its_figures_and_every_figure_has_its_example():
    assert sorted(FIGURES) == [p.name for p in EXAMPLES], "list a new example's figures in FIGURES"
    drawn = sorted(name for names in FIGURES.values() for name in names)
    assert drawn == sorted(p.name for p in (ROOT / "docs" / "figures").glob("*.png"))


def test_every_example_has_a_title_and_a_description():
    """The gallery shows the docstring: a title line, a blank line, what the example shows."""
    import ast

    for script in EXAMPLES:
        doc = ast.get_docstring(ast.parse(script.read_text(encoding="utf-8")))
        assert doc, f"{script.name} has no docstring"
        title, blank, *description = doc.splitlines()
        assert title.strip() and not blank.strip() and any(line.strip() for line in description), script.name


def test_the_gallery_shows_every_example_and_its_figures():
    text = GALLERY.read_text(encoding="utf-8")
    included = re.findall(r"^```\{literalinclude\} \.\./examples/(\S+\.py)$", text, re.M)
    assert sorted(included) == [p.name for p in EXAMPLES], "docs/examples.md shows each example's source once"
    described = re.findall(r"^<!-- quadctl-example: (\S+\.py) -->$", text, re.M)
    assert described == included, "each example's entry starts with its title and description (the marker)"
    for script, names in FIGURES.items():
        for name in names:
            assert f"(figures/{name})" in text, f"docs/examples.md does not show {name} ({script})"
