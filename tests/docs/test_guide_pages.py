"""The Guide's pages, run: every fenced block of docs/guide/*.md, each page in its own folder, by the
rules of tests/docs/test_doc_pages.py (which runs the other pages). A file of its own so the pages' blocks
run on two workers side by side (pytest-xdist gives each test file to one worker)."""

from __future__ import annotations

import pytest
from test_doc_pages import (
    RUNNABLE,
    _param,
    folders,  # noqa: F401  (the fixture: a folder per page)
    in_guide,
    run_block,
)

GUIDE = [b for b in RUNNABLE if in_guide(b)]


def test_the_guide_has_blocks_to_run():
    pages = {b.page for b in GUIDE}
    assert len(pages) >= 8 and {"docs/guide/flying.md", "docs/guide/export.md"} <= pages, sorted(pages)


@pytest.mark.parametrize("block", [_param(b) for b in GUIDE])
def test_guide_block(block, folders):  # noqa: F811
    run_block(block, folders(block.page))
