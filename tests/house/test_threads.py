"""One BLAS thread while quadctl works on small matrices: in a context, or for good in a worker process."""

from __future__ import annotations

import os
import subprocess
import sys

_FOR_GOOD = """
import sys
import numpy  # a pool loaded before
from threadpoolctl import threadpool_info
from quadctl import threads
threads.one_thread_for_good()
assert "scipy.linalg" not in sys.modules
import scipy.linalg  # a pool loaded after
pools = threadpool_info()
assert len(pools) >= 1, pools
print(sorted({p["num_threads"] for p in pools}))
with threads.one_thread():
    print("scipy.linalg" in sys.modules)
"""


def test_a_worker_process_runs_every_pool_on_one_thread_those_loaded_later_too():
    out = subprocess.run([sys.executable, "-c", _FOR_GOOD], capture_output=True, text=True, check=True,
                         env={**os.environ, "OPENBLAS_NUM_THREADS": "2", "OMP_NUM_THREADS": "2"})
    assert out.stdout.split("\n")[:2] == ["[1]", "True"]


def test_one_thread_gives_the_pools_their_threads_back():
    from threadpoolctl import threadpool_info

    from quadctl.threads import one_thread

    before = {p["filepath"]: p["num_threads"] for p in threadpool_info()}
    with one_thread():
        assert {p["num_threads"] for p in threadpool_info()} == {1}
    after = {p["filepath"]: p["num_threads"] for p in threadpool_info()}
    assert {k: v for k, v in after.items() if k in before} == before


_FORKED = """
import os, sys
import numpy  # a pool loaded before
from threadpoolctl import threadpool_info
from quadctl.sweep.runner import _worker_init
from quadctl.threads import loaded_one_thread
r, w = os.pipe()
with loaded_one_thread():  # as the sweep forks its workers (which never leave the block)
    pid = os.fork()
    if pid == 0:
        _worker_init(forked=True)  # no search of the pools
        import scipy.linalg  # a pool loaded after
        os.write(w, str(sorted({p["num_threads"] for p in threadpool_info()})).encode())
        os._exit(0)
os.waitpid(pid, 0)
print(os.read(r, 100).decode())
print(sorted({p["num_threads"] for p in threadpool_info()}))  # the parent's back to its own
"""


def test_a_worker_forked_inside_loaded_one_thread_runs_one_thread_without_searching_its_pools():
    out = subprocess.run([sys.executable, "-c", _FORKED], capture_output=True, text=True, check=True,
                         env={**os.environ, "OPENBLAS_NUM_THREADS": "2", "OMP_NUM_THREADS": "2"})
    assert out.stdout.split("\n")[:2] == ["[1]", "[2]"]
