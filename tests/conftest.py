"""Shared fixtures (the report's configs solved once per session, a temporary compile cache for the
whole run) and the ``compiler`` marker: tests that need a C compiler skip, saying why, where there is
none. The suite runs in pytest-xdist workers (``addopts`` in pyproject.toml): each worker keeps to one
BLAS thread and sees the run's own ``COLUMNS``, and Ctrl-C has Python's own handler even where the run
was started with it ignored."""

from __future__ import annotations

import os
import signal

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

RUN_COLUMNS = "QUADCTL_TESTS_RUN_COLUMNS"
"""COLUMNS of the environment pytest was started in, for its pytest-xdist workers."""
if not os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ[RUN_COLUMNS] = os.environ.get("COLUMNS", "")
elif os.environ.get(RUN_COLUMNS) == "":
    # a worker starts with COLUMNS=80 and LINES=24 that the run did not have: without them a command's
    # stdout in a test is as wide as in a pipe (quadctl.cli.render.WIDE), as in one process
    os.environ.pop("COLUMNS", None)
    os.environ.pop("LINES", None)

if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    # started with Ctrl-C ignored (a script's `pytest &`, which a non-interactive shell starts so): the tests
    # of Ctrl-C raise SIGINT in this process and need Python's own handler, as a terminal's run has
    signal.signal(signal.SIGINT, signal.default_int_handler)

BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
if os.environ.get("PYTEST_XDIST_WORKER") and not any(v in os.environ for v in BLAS_THREADS):
    # one BLAS thread per pytest-xdist worker (there is one worker per core), in the commands it starts
    # too: more OpenBLAS threads than free cores spin against each other (a large CAREX case on a busy
    # 2-core machine: 14.4 s of CPU with two threads, 2.3 s with one)
    os.environ.update(dict.fromkeys(BLAS_THREADS, "1"))
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)  # a BLAS already loaded


@pytest.fixture(scope="session")
def forward():
    """(setup, trim, linear, decoupled, design) of the bundled forward config."""
    from quadctl import config, pipeline
    from quadctl.setup import setup_of

    setup = setup_of(config.load("forward"))
    trim = pipeline.trim_of(setup)
    linear = pipeline.linear_of(setup, trim)
    dec = pipeline.decoupled_of(setup, linear)
    des = pipeline.design_of(setup, dec, linear)
    return setup, trim, linear, dec, des


@pytest.fixture(scope="session")
def _compile_cache(tmp_path_factory) -> str:
    """The test run's compile cache: one folder for the whole run, shared by pytest-xdist's workers
    (each worker's temporary folder is one below the run's; the cache's writes are atomic)."""
    base = tmp_path_factory.getbasetemp()
    return str((base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "qc-cache")


@pytest.fixture(autouse=True)
def _cache_in_tmp(_compile_cache, monkeypatch):
    """Compiled steps go to one temporary cache per test run, never the user's."""
    monkeypatch.setenv("QUADCTL_CACHE", _compile_cache)


@pytest.hookimpl(tryfirst=True)  # before -m deselects
def pytest_collection_modifyitems(config, items):
    """The tests ``tests/slow_tests.txt`` lists are marked ``slow`` (``tests/_tiers.py``: those of 1.5 s
    or more run in CI's second step); tests marked ``compiler`` are skipped, with the reason, where no C
    compiler is found."""
    from _tiers import listed

    slow = listed()
    for item in items:
        if item.nodeid in slow:
            item.add_marker(pytest.mark.slow)
    marked = [item for item in items if item.get_closest_marker("compiler")]
    if not marked:
        return
    from quadctl.native.compile import find_compiler

    if find_compiler() is None:
        skip = pytest.mark.skip(reason="needs a C compiler: quadctl.native.compile.find_compiler() found none "
                                       "($CC, cc, gcc, clang; or QUADCTL_NO_COMPILE=1 is set)")
        for item in marked:
            item.add_marker(skip)
