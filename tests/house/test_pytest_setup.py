"""The suite runs what it claims: the library's doctests, and the compiler tests skip, saying why."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from _paths import ROOT


def _pytest(*args: str, **env: str) -> str:
    res = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", *args], cwd=ROOT,
                         capture_output=True, text=True, timeout=300, env={**os.environ, **env})
    return res.stdout + res.stderr


@pytest.mark.slow
def test_a_bare_pytest_collects_the_docstring_examples_and_the_readme():
    out = _pytest("--collect-only", "-q")
    for item in ("tests/docs/test_doctests.py::test_docstring_examples[quadctl.design.margins]",
                 "tests/docs/test_doctests.py::test_docstring_examples[quadctl.design.decoupled]",
                 "tests/docs/test_doc_pages.py::test_page_block"):
        assert item in out, out[-2000:]


def test_compiler_tests_skip_with_the_reason_where_there_is_no_compiler():
    out = _pytest("-q", "-rs", "-n0", "tests/sim/test_engine.py", "-k", "cached_library or compile_cache_key",
                  QUADCTL_NO_COMPILE="1")
    assert "2 skipped" in out and "needs a C compiler: quadctl.native.compile.find_compiler() found none" in out, out


def test_every_test_that_names_the_compiled_backend_is_marked():
    """A test asserting a compiled backend (itself or through a helper of its module) fails without a
    compiler unless it is marked `compiler` (or its whole module is, by `pytestmark`)."""
    import ast

    def asserts_compiled(source: str) -> bool:
        return "== 'compiled" in source or "else 'compiled" in source

    unmarked = []
    for path in sorted((ROOT / "tests").glob("test_*.py")):
        text = path.read_text()
        if "pytestmark = pytest.mark.compiler" in text:  # the whole module is marked
            continue
        tree = ast.parse(text)
        functions = {n.name: ast.unparse(n) for n in tree.body if isinstance(n, ast.FunctionDef)}
        helpers = {n for n, source in functions.items() if not n.startswith("test_") and asserts_compiled(source)}
        for name, source in functions.items():
            needs = asserts_compiled(source) or any(f"{h}(" in source for h in helpers)
            if name.startswith("test_") and needs and "pytest.mark.compiler" not in source:
                unmarked.append(f"{path.name}::{name}")
    assert not unmarked, unmarked


def test_every_test_the_slow_tier_lists_is_a_test_of_the_suite():
    """tests/slow_tests.txt names tests by node id: a renamed or removed test leaves a stale line (and the
    renamed test back in the first tier), so each line names a test function of its file."""
    import re

    from _tiers import listed
    sys.path.insert(0, str(ROOT / "tests" / "docs"))  # (the docs tests' folder, as pytest puts it when it runs them)
    try:
        from test_doc_pages import RUNNABLE, _id
    finally:
        sys.path.remove(str(ROOT / "tests" / "docs"))

    root = ROOT
    blocks = {_id(block) for block in RUNNABLE}  # a docs block's id names its line: an edit above it moves it
    stale = []
    for node in sorted(listed()):
        path, _, name = node.partition("::")
        function, _, param = name.partition("[")
        if not (root / path).is_file() or not re.search(rf"^def {function}\(", (root / path).read_text(), re.M):
            stale.append(node)
        elif function in ("test_guide_block", "test_page_block") and param[:-1] not in blocks:
            stale.append(node)
    assert listed() and not stale, f"stale lines of tests/slow_tests.txt (regenerate it: tests/_tiers.py): {stale}"
