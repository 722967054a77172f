"""One thread for BLAS and OpenMP while quadctl works on many small matrices at once.

The matrices of a sweep's chunk or a schedule's points are 12x12 to 30x30: too small for threads
to pay, and on a busy 2-core machine BLAS threads made a sweep 6 to 16 times slower and a
schedule's zero-order holds 500 times slower (1.7 s against 3 ms for 197 loops).
"""

from __future__ import annotations

from contextlib import AbstractContextManager
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
    """A context in which BLAS and OpenMP run one thread (``with one_thread(): ...``)."""
    return _controller().limit(limits=1)
