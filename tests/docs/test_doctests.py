"""The library's docstring examples are tests: every module's, on the quadctl that is imported.

(``--doctest-modules`` over ``quadctl/`` would import the checkout's files, which in CI are not
the installed package the rest of the suite tests.)
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import quadctl

MODULES = sorted(m.name for m in pkgutil.walk_packages(quadctl.__path__, "quadctl.")
                 if not m.name.endswith("__main__"))  # __main__ runs the command line on import


def _examples(name: str) -> list[doctest.DocTest]:
    module = importlib.import_module(name)
    return [t for t in doctest.DocTestFinder().find(module, name) if t.examples]


@pytest.mark.parametrize("name", [m for m in MODULES if _examples(m)])
def test_docstring_examples(name):
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    report = []
    for test in _examples(name):
        runner.run(test, out=report.append)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, "".join(report)


def test_the_examples_are_found():
    """The modules whose docstrings show examples (a test that finds none would pass for nothing)."""
    with_examples = {m for m in MODULES if _examples(m)}
    assert {"quadctl.artifacts.json_values", "quadctl.design.decoupled", "quadctl.design.margins",
            "quadctl.design.margin_search",
            "quadctl.design.margin_findings", "quadctl.design.discrete", "quadctl.linear.trim"} <= with_examples
