"""Every page's Markdown (the README, docs/**/*.md) renders as written, here as on GitHub: a code span that
quotes a backtick is delimited by two (a message such as ``did you mean `dt`?`` split a one-backtick span
and showed its rest as text with stray backticks), and a table row has as many cells as its header (an
unescaped ``|`` in a code span, as in ``x_hat[k|k-1]``, opens a cell the table then drops)."""

from __future__ import annotations

import re

import pytest
from _paths import ROOT
from markdown_it import MarkdownIt

PAGES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts)]
PARSER = MarkdownIt("commonmark").enable("table")  # the parser MyST builds on, with GitHub's tables
CELL_BAR = re.compile(r"(?<!\\)\|")


def _name(page) -> str:
    return str(page.relative_to(ROOT))


@pytest.mark.parametrize("page", PAGES, ids=_name)
def test_no_backtick_shows_outside_code(page):
    stray = []
    for token in PARSER.parse(page.read_text(encoding="utf-8")):
        for child in token.children or ():
            if child.type == "text" and "`" in child.content:
                stray.append((token.map[0] + 1 if token.map else None, child.content.strip()[:80]))
    assert not stray, f"{_name(page)}: a backtick shows as text (a code span quoting one needs two): {stray}"


@pytest.mark.parametrize("page", PAGES, ids=_name)
def test_every_table_row_has_its_headers_cells(page):
    lines = page.read_text(encoding="utf-8").splitlines()
    fenced, header, short = False, None, []
    for number, line in enumerate(lines, 1):
        if line.lstrip().startswith(("```", "~~~")):
            fenced = not fenced
        if fenced or not line.startswith("|"):
            header = None
            continue
        cells = len(CELL_BAR.split(line.strip())) - 2
        if header is None:
            header = cells
        elif cells != header:
            short.append((number, cells, header))
    assert not short, f"{_name(page)}: rows (line, cells, header's) whose cells differ from the header's: {short}"


@pytest.mark.parametrize("page", PAGES, ids=_name)
def test_every_fenced_block_names_its_language(page):
    """Sphinx highlights a fence without a language as Python: the model's equations (``phi' = p + ...``)
    showed as green string literals. Plain text says ``text``."""
    unnamed = [token.map[0] + 1 for token in PARSER.parse(page.read_text(encoding="utf-8"))
               if token.type == "fence" and not token.info.strip()]
    assert not unnamed, f"{_name(page)}: fenced blocks at lines {unnamed} name no language (plain text: ```text)"
