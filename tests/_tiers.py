"""The suite's two tiers: the tests that take ``THRESHOLD`` seconds or more run with the slow ones
(``pytest -m slow``, CI's second step), so that ``pytest``, the README's test command, stays within
its 3 minutes on a 2-core machine; ``tests/slow_tests.txt`` lists them (conftest.py marks them).

Regenerate the list from a timed run of the whole suite (both tiers)::

    pytest -p no:cacheprovider -m "slow or not slow" --junitxml=/tmp/all.xml
    python tests/_tiers.py /tmp/all.xml   # (or the XML of several runs: a test slow in any is listed)

``KEEP`` are the tests that stay in the first tier whatever they cost: the README's own commands and
the golden master that holds on any CPU.
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

THRESHOLD = 1.5
"""s: a test this long (setup included, as pytest's junit XML times it) runs with the slow tests."""
LIST = Path(__file__).with_name("slow_tests.txt")
KEEP = ("tests/docs/test_doc_pages.py::test_page_block[README.md:",
        "tests/house/test_reference_runs.py::",
        "tests/outputs/test_report.py::test_the_markdown_twin_shows_the_figures_beside_it[forward]",  # one whole report
        "tests/docs/test_guide_pages.py::test_guide_block[docs/guide/export.md:L218",  # writes the file L276 reads
        # a sweep's Ctrl-C within a second, on a loaded machine too: a Ctrl-C that cut the figure's import short
        # had ended 2 to 4 runs in 30 by -2 or -6 at exit on a 2-core machine loaded to 6 (quadctl.cli.progress's
        # IMPORTS_CUT_SHORT: none in 30 since)
        "tests/cli/test_interrupts.py::test_ctrl_c_stops_a_sweep_within_a_second_and_its_workers_with_it")
HEADER = f"""# Tests of {THRESHOLD} s or more (tests/_tiers.py): marked slow by conftest.py, run by `pytest -m slow`.
# Generated from a timed run of the whole suite: python tests/_tiers.py JUNIT.xml
"""


def node_id(case) -> str:
    """pytest's node id of a junit ``testcase`` element (``tests.test_x`` + ``name``)."""
    return case.get("classname").replace(".", "/") + ".py::" + case.get("name")


def slow_ids(junit: str, threshold: float = THRESHOLD) -> list[str]:
    """The node ids of the tests of ``junit`` that took ``threshold`` s or more, but ``KEEP``'s."""
    cases = ET.parse(junit).iter("testcase")
    return sorted(n for c in cases if float(c.get("time")) >= threshold
                  and not (n := node_id(c)).startswith(KEEP) and c.find("skipped") is None)


def listed() -> frozenset[str]:
    """The node ids ``tests/slow_tests.txt`` lists."""
    if not LIST.is_file():
        return frozenset()
    return frozenset(line.strip() for line in LIST.read_text(encoding="utf-8").splitlines()
                     if line.strip() and not line.startswith("#"))


if __name__ == "__main__":
    ids = sorted(set().union(*(slow_ids(junit) for junit in sys.argv[1:])))  # one run's XML, or several
    LIST.write_text(HEADER + "".join(f"{i}\n" for i in ids), encoding="utf-8")
    print(f"{len(ids)} tests of {THRESHOLD} s or more -> {LIST}")
