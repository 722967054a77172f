"""One thread for BLAS and OpenMP while quadctl works on many small matrices at once.

The matrices of a sweep's chunk or a schedule's points are 12x12 to 30x30: too small for threads
to pay, and on a busy 2-core machine BLAS threads made a sweep 6 to 16 times slower and a
schedule's zero-order holds 500 times slower (1.7 s against 3 ms for 197 loops).
"""

from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext
from functools import lru_cache


@lru_cache(maxsize=1)
def _controller():
    """The process's BLAS and OpenMP thread pools, found once (a search costs ~1 ms), after loading
    every library quadctl computes with (a pool loaded later would not be limited)."""
    import scipy.linalg  # noqa: F401  (SciPy's own OpenBLAS)
    from threadpoolctl import ThreadpoolController

    import quadctl.lqr.riccati  # noqa: F401
    import quadctl.sim.engine  # noqa: F401

    return ThreadpoolController()


def one_thread() -> AbstractContextManager:
    """A context in which BLAS and OpenMP run one thread (``with one_thread(): ...``).

    Nothing to do when every pool runs one thread already: a sweep's worker forked inside this
    context (:func:`quadctl.sweep.runner.run`) then never sets a count. Setting one in a forked
    child makes OpenBLAS start its thread pool anew, whose threads spin ~0.1 s of CPU before they
    sleep: half the first chunk's time in each worker of a mambo-200hz sweep.
    """
    controller = _controller()
    if all(lib.num_threads == 1 for lib in controller.lib_controllers):
        return nullcontext()
    return controller.limit(limits=1)
