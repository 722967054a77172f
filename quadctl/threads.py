"""One thread for BLAS and OpenMP while quadctl works on many small matrices at once.

The matrices of a sweep's chunk or a schedule's points are 12x12 to 30x30: too small for threads
to pay: on a busy machine BLAS threads spend far longer waiting for each other than computing,
and a sweep or a schedule's zero-order holds slow down by orders of magnitude.

:func:`one_thread` is the context for work done in the caller's process (its pools get their
thread counts back after). A sweep's worker processes fork inside :func:`loaded_one_thread` (the
pools loaded so far, SciPy's not loaded for it) and then run :func:`one_thread_for_good`: every
pool runs one thread for the life of the worker, those loaded later too, and :func:`one_thread`
has nothing left to do (and never loads SciPy only to find its pool).

:func:`die_with_parent`: a process quadctl forks (a sweep's worker, a figure drawer) ends with it.
"""

from __future__ import annotations

import os
from contextlib import AbstractContextManager, nullcontext
from functools import lru_cache

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS")
"""The environment variables BLAS and OpenMP libraries read, when they load, for their thread count."""

_for_good = False
"""True once :func:`one_thread_for_good` ran in this process."""


@lru_cache(maxsize=1)
def _controller():
    """The process's BLAS and OpenMP thread pools, found once (a search walks every loaded library), after loading
    every library quadctl computes with (a pool loaded later would not be limited)."""
    import scipy.linalg  # noqa: F401  (SciPy's own OpenBLAS)
    from threadpoolctl import ThreadpoolController

    import quadctl.design.riccati  # noqa: F401
    import quadctl.sim.engine  # noqa: F401

    return ThreadpoolController()


def die_with_parent() -> None:
    """This process (a child quadctl forked) is killed when its parent dies, on Linux: a parent killed
    hard (``kill -9``) leaves no child computing, or writing into a folder whose lock died with the
    parent, for nobody. Elsewhere nothing."""
    import signal
    import sys

    if not sys.platform.startswith("linux"):
        return
    import ctypes

    PR_SET_PDEATHSIG = 1
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        pass


def one_thread() -> AbstractContextManager:
    """A context in which BLAS and OpenMP run one thread (``with one_thread(): ...``).

    Nothing to do when every pool runs one thread already: a sweep's worker forked inside
    :func:`loaded_one_thread` then never sets a count. Setting one in a forked child makes OpenBLAS
    start its thread pool anew, whose threads spin before they sleep: CPU time a worker's first chunk
    would pay for nothing.
    """
    if _for_good:
        return nullcontext()
    return _limited(_controller())


def loaded_one_thread() -> AbstractContextManager:
    """:func:`one_thread` for the pools loaded so far only (SciPy's is not loaded for it, ~0.2 s):
    held while a sweep's workers fork, so that they start with one thread in each."""
    from threadpoolctl import ThreadpoolController

    return _limited(ThreadpoolController())


def _limited(controller) -> AbstractContextManager:
    if all(lib.num_threads == 1 for lib in controller.lib_controllers):
        return nullcontext()
    return controller.limit(limits=1)


def one_thread_for_good(forked_limited: bool = False) -> None:
    """Every BLAS and OpenMP pool of this process runs one thread from now on: one that loads later
    (SciPy's, when a chunk first needs ``scipy.linalg``) reads :data:`THREAD_VARIABLES`, set here,
    as it loads; those loaded now are limited, unless they run one already (a worker forked inside
    :func:`loaded_one_thread` sets no count: see :func:`one_thread`).

    ``forked_limited``: this process was forked inside :func:`loaded_one_thread`, so every pool it
    has runs one thread: they are not searched for again.

    For a process that only works on small matrices (a sweep's worker process). Its environment then
    also asks one thread of the processes it starts.
    """
    global _for_good
    os.environ.update(dict.fromkeys(THREAD_VARIABLES, "1"))
    if not forked_limited:
        loaded_one_thread().__enter__()  # not left: for good
    _for_good = True
