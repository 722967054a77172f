"""Running a sweep: chunks of cases on local worker processes or a Dask cluster, results in case order."""

from __future__ import annotations

import gc
import math
import multiprocessing
import os
import re
import signal
import sys
import time
import warnings
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field

import numpy as np

from quadctl.config.schema import Config
from quadctl.errors import ArgumentTypeError, SweepError
from quadctl.sim.engine import LANES, MarchNotice, say_march
from quadctl.sweep.config_tree import with_sections, with_set
from quadctl.sweep.evaluate import ChunkResult, ChunkTask, evaluate_chunk
from quadctl.sweep.gates import margin, regulated_states
from quadctl.sweep.spec import Case, SweepSpec
from quadctl.threads import die_with_parent, loaded_one_thread, one_thread_for_good


@dataclass
class SweepResult:
    """A finished (or resumed) sweep.

    Attributes
    ----------
    rows : list of dict
        One per case, by case number: ``case``, the parameters, the metrics, ``pass``,
        ``failed_gates``, ``reason``.
    columns : list of str
        The table's columns, in order.
    computed : int
        Cases computed in this call (the rest came from ``done``).
    wall_time : float
        s, for the cases computed here.
    stats : dict
        Totals over the chunks: ``designs`` (subsystem LQR solves), ``design_time`` and
        ``design_cpu`` (s of wall and of CPU time in the design stage, summed over workers: CPU
        time is what a design costs, wall time also counts what other processes took),
        ``steps`` (RK4 steps simulated), ``fallbacks`` (batched solves redone one by one),
        ``backend``, ``executor``, ``workers``.
    traces : dict
        A Monte Carlo: case number -> (MC_POINTS, regulated states) float32 deviations from the
        reference, for the cases computed here that simulated to the end (a resumed sweep's
        earlier cases are in its journal: :class:`SweepStore`).
    """

    rows: list
    columns: list
    computed: int
    wall_time: float
    stats: dict
    gates: tuple = ()
    require_ok: bool = True
    traces: dict = field(default_factory=dict)

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if not r["pass"]]

    def ranked(self) -> list[dict]:
        """Rows from the worst to the best (see :func:`margin`)."""
        return sorted(self.rows, key=lambda r: (margin(r, self.gates, self.require_ok), -r["case"]))

    @property
    def steps_per_second(self) -> float:
        return self.stats["steps"] / self.wall_time if self.wall_time > 0 else math.inf


def default_jobs() -> int:
    """All the cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


MAX_CHUNK = 256
"""The most cases a task takes by default (the batched solves pay off with more; a stop leaves less
half-done work with fewer)."""


def default_chunks(n_cases: int, workers: int) -> list[int]:
    """Cases per task, in order: about two tasks per worker (the load still balances: a task goes to
    the next free worker), each whole groups of the SIMD lanes, at most :data:`MAX_CHUNK` cases, as
    even as whole groups allow, the larger first. So the workers end together: 48 cases on two
    workers are tasks of 16, 16, 8 and 8 (each worker 24), where tasks of one size, 16, would be three
    (one worker 32, the other 16).

    A task has a fixed cost whatever its size (setups, the batched solves' and the lanes' fixed
    costs), so more, smaller tasks per worker make a sweep of short cases slower.
    """
    if n_cases <= 0:
        return []
    groups = math.ceil(n_cases / LANES)
    tasks = min(groups, max(2 * max(1, workers), math.ceil(groups * LANES / MAX_CHUNK)))
    per, extra = divmod(groups, tasks)
    sizes = [LANES * (per + (k < extra)) for k in range(tasks)]
    sizes[-1] -= sum(sizes) - n_cases  # the last group holds what is left
    return sizes


def tasks_for(cfg, spec: SweepSpec, cases: Iterable[Case], label: str, sizes: int | list[int],
              fast: bool = True) -> list[ChunkTask]:
    """The chunks of ``cases`` (in case order; ``sizes``: the cases of each, or one size for all),
    ready for any executor.

    A case's row does not depend on the chunk it is in, so the chunk size is free to follow the
    executor (the resume test checks this: a resumed sweep, chunked anew, writes the same table).
    """
    cases = list(cases)
    if isinstance(sizes, int):
        sizes = [sizes] * math.ceil(len(cases) / sizes)
    starts = np.cumsum([0, *sizes])
    base = base_of(cfg, spec)
    keys = tuple(p.keys for p in spec.parameters)
    trace = tuple(regulated_states(cfg)) if spec.monte_carlo else ()
    return [ChunkTask(base=base, label=label, keys=keys, names=tuple(spec.names),
                      cases=tuple((c.index, c.values) for c in cases[i:j]), gates=spec.gates,
                      require_ok=spec.require_ok, fast=fast, trace=trace)
            for i, j in zip(starts[:-1].tolist(), starts[1:].tolist()) if j > i]


def base_of(cfg, spec: SweepSpec) -> dict:
    """The config every case starts from, as a mapping: ``cfg`` with the ``set:`` values in."""
    base = with_sections(cfg.model_dump(mode="json"), [*spec.names, *(path for path, _, _ in spec.fixed)])
    return with_set(base, spec.fixed)


def run(cfg, spec: SweepSpec, *, label: str | None = None, jobs: int | None = None,
        scheduler: str | None = None, done: dict[int, dict] | None = None,
        on_chunk: Callable[[list, dict], None] | None = None,
        progress: Callable[[int, int], None] | None = None, fast: bool = True) -> SweepResult:
    """Run a sweep: every case of ``spec`` not already in ``done``.

    Parameters
    ----------
    cfg : Config
        The base config.
    spec : SweepSpec
    label : str, optional
        Names the config in case messages (default its name).
    jobs : int, optional
        Local worker processes (default all cores; 1 runs in this process).
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:8786``): run the chunks there.
    done : dict, optional
        Rows already computed, by case number (a resumed sweep): not recomputed.
    on_chunk : callable, optional
        ``on_chunk(rows, traces)`` for each finished chunk, in completion order (to save them);
        ``traces`` as :attr:`ChunkResult.traces` (empty unless a Monte Carlo).
    progress : callable, optional
        ``progress(cases_done, cases_total)`` after each chunk.
    fast : bool
        Use the batched path where it applies (False: every case through the pipeline).

    Returns
    -------
    SweepResult

    Raises
    ------
    SweepError
        ``jobs`` not a whole number of at least 1, or the scheduler cannot be reached.
    ArgumentTypeError
        ``cfg`` is not a :class:`~quadctl.config.schema.Config` or ``spec`` not a :class:`SweepSpec` (a
        ``TypeError``).
    """
    if not isinstance(cfg, Config):
        raise ArgumentTypeError(f"sweep.run takes a validated Config, qc.load_config('forward'); got "
                                f"{type(cfg).__name__}")
    if not isinstance(spec, SweepSpec):
        raise ArgumentTypeError(f"sweep.run takes a SweepSpec, sweep.from_dict(data, cfg) or sweep.load(path, cfg); "
                                f"got {type(spec).__name__}")
    label = label or cfg.name
    done = dict(done or {})
    cases = spec.cases()
    todo = [c for c in cases if c.index not in done]
    stats = {"designs": 0, "design_time": 0.0, "design_cpu": 0.0, "simulate_time": 0.0, "steps": 0, "fallbacks": 0,
             "backend": set()}
    if jobs is not None and (isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or jobs < 1):
        raise SweepError(f"--jobs {jobs!r}: must be a whole number of at least 1")
    client = _dask_client(scheduler) if scheduler else None
    try:
        if client is not None:
            workers = max(1, sum(client.nthreads().values()))
            stats["executor"] = f"dask {scheduler} ({workers} threads)"
        else:
            workers = max(1, min(jobs or default_jobs(), len(todo)))
        tasks = tasks_for(cfg, spec, todo, label, spec.chunk_size or default_chunks(len(todo), workers), fast)
        if client is None:  # no more processes than tasks: one task (a sweep of a lane group) runs here, no pool
            workers = max(1, min(workers, len(tasks)))
            stats["executor"] = "local" if workers == 1 else f"local processes ({workers})"
        stats["workers"] = workers
        rows = dict(done)
        traces: dict[int, np.ndarray] = {}
        total = len(cases)
        start = time.perf_counter()
        # the workers start first: what this process does next (the progress bar) overlaps their work
        with (nullcontext(_dask_results(client, tasks)) if client is not None
              else _local_results(tasks, workers)) as results:
            if progress:
                progress(len(rows), total)
            for result in results:
                for row in result.rows:
                    rows[row["case"]] = row
                traces.update(result.traces)
                for key in ("designs", "design_time", "design_cpu", "simulate_time", "steps", "fallbacks"):
                    stats[key] += result.stats[key]
                stats["backend"].update(result.stats["backend"])
                if on_chunk:
                    on_chunk(result.rows, result.traces)
                if progress:
                    progress(len(rows), total)
        wall = time.perf_counter() - start
    finally:
        if client is not None:
            client.close()
    stats["backend"] = sorted(stats["backend"])
    ordered = [rows[c.index] for c in cases]
    return SweepResult(rows=ordered, columns=columns_of(spec), computed=len(todo), wall_time=wall,
                       stats=stats, gates=spec.gates, require_ok=spec.require_ok,
                       traces={c.index: traces[c.index] for c in cases if c.index in traces})


def columns_of(spec: SweepSpec) -> list[str]:
    """Table columns: ``case``, the parameters, the metrics, ``pass``, ``failed_gates``, ``reason``,
    and ``path`` (batched, or one-by-one and why)."""
    return ["case", *spec.names, *spec.metrics, "pass", "failed_gates", "reason", "path"]


def _worker_init(forked: bool = False) -> None:
    """A worker ignores Ctrl-C (the parent handles it and stops the pool), ends on SIGTERM and, on Linux, dies with
    its parent: a killed sweep leaves no worker computing for nobody. It works on small matrices
    only: one BLAS thread for good (:func:`quadctl.threads.one_thread_for_good`; ``forked``: inside
    :func:`quadctl.threads.loaded_one_thread`, its pools run one thread already). It keeps quiet about
    QUADCTL_MARCH: the parent said it once (:func:`quadctl.sim.engine.say_march`)."""

    warnings.filterwarnings("ignore", category=MarchNotice)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # the pool stops a worker by SIGTERM: not the CLI handler
    one_thread_for_good(forked_limited=forked)
    die_with_parent()
    _keep_freed_memory()


WORKER_MALLOC = {-3: 32 << 20, -1: 256 << 20, -2: 64 << 20}
"""glibc ``mallopt`` settings of a worker process: M_MMAP_THRESHOLD (-3), M_TRIM_THRESHOLD (-1),
M_TOP_PAD (-2), bytes."""


def _keep_freed_memory() -> None:
    """glibc only: a worker keeps the memory a chunk frees for the next one, rather than give it
    back to the system and take it again, zero-filled a page at a time."""
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc
        return
    for param, value in WORKER_MALLOC.items():
        mallopt(param, value)


@contextmanager
def _local_results(tasks: list[ChunkTask], jobs: int) -> Iterator[Iterator[ChunkResult]]:
    """The chunks' results as they finish, from ``jobs`` worker processes (``jobs == 1``: computed
    here, one by one as the iterator is read).

    The workers start on entering (they compute while the caller does its own work) and stop on
    leaving: at once, if the caller leaves before the last result (Ctrl-C, an error).
    """
    if jobs == 1:
        yield (evaluate_chunk(task) for task in tasks)
        return
    say_march()  # here, not once by each worker
    # fork on Linux: workers start at once with everything imported so far (the progress bar runs no
    # thread, so nothing is forked mid-lock); spawn elsewhere (macOS's system libraries are not fork-safe)
    ctx = multiprocessing.get_context("fork" if sys.platform.startswith("linux") else "spawn")
    # held while the workers fork and run: they start with one BLAS thread and set no count (threads.py)
    with loaded_one_thread():
        pool = ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_worker_init,
                                   initargs=(ctx.get_start_method() == "fork",))
        queue, pending = list(tasks), set()

        def fill() -> None:
            # two tasks per worker in flight: a stop (Ctrl-C) leaves little half-done work
            while queue and len(pending) < 2 * jobs:
                pending.add(pool.submit(evaluate_chunk, queue.pop(0)))

        def results() -> Iterator[ChunkResult]:
            while pending:
                finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                pending.difference_update(finished)
                fill()  # before the caller handles these: no worker waits for it
                for fut in finished:
                    try:
                        result = fut.result()
                    except BrokenProcessPool:
                        raise RuntimeError("a sweep worker process died (killed, or out of memory); the chunks "
                                           "finished before are kept: rerun with --resume (--jobs 1 shows "
                                           "any error in this process)") from None
                    yield result

        try:
            _forking(fill, ctx.get_start_method() == "fork")
            yield results()
        finally:
            for fut in pending:
                fut.cancel()
            stopped = bool(pending or queue)
            if stopped:  # Ctrl-C or an error: stop the running chunks now, not when they end
                for process in list(getattr(pool, "_processes", {}).values()):
                    process.terminate()
            # every result in: the workers exit on their own while the caller goes on (writing the
            # rows, the figure); stopped: gone before this returns
            pool.shutdown(wait=stopped, cancel_futures=True)


def _forking(start: Callable[[], None], fork: bool) -> None:
    """``start()`` the workers; by ``fork``, with every object so far out of the garbage collector's
    sight (``gc.freeze``) meanwhile: a worker's collections then do not write to, and so copy, each
    page of objects it shares with this process (forward sweep: 8 000 -> 5 700 page faults a worker,
    0.02 s of CPU). This process gets its objects back to collect after."""
    if not fork:
        start()
        return
    gc.freeze()
    try:
        start()
    finally:
        gc.unfreeze()


SCHEDULER_TIMEOUT = "10s"
"""How long to try to reach a Dask scheduler before saying it cannot be reached."""
SCHEDULER_PROTOCOLS = ("tcp", "tls", "ws", "wss", "ucx")
"""The protocols a Dask scheduler address may name (``tcp://`` when none is given)."""
_ADDRESS_RE = re.compile(r"(?:(?P<scheme>[^:/]*)://)?(?P<host>\[[^\]]*\]|[^:/\[\]]*)(?::(?P<port>[^/]*))?/?")
_HOST_RE = re.compile(r"\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_]([A-Za-z0-9_.-]*[A-Za-z0-9_])?")


def check_scheduler_address(address: str) -> str:
    """Check the form of a Dask scheduler address, ``[protocol://]host:port``, before connecting.

    A malformed address would otherwise fail only after Dask's connection retries (more than
    15 s for ``tcp://127.0.0.1:notaport``).

    Returns
    -------
    str
        The address, with ``tcp://`` when it names no protocol.

    Raises
    ------
    SweepError
        Naming ``--scheduler``, the address and what is wrong: an unknown protocol, no host, no
        port, or a port that is not a whole number from 1 to 65535.

    Examples
    --------
    >>> check_scheduler_address("10.0.0.5:8786")
    'tcp://10.0.0.5:8786'
    """
    def bad(why: str) -> SweepError:
        return SweepError(f"--scheduler {address}: {why}; give the address as tcp://host:port "
                          "(a Dask scheduler listens on 8786 unless told otherwise)")

    if not address.strip():  # --scheduler "$UNSET": not this machine's cores without a word
        raise SweepError(f"--scheduler {address!r}: an empty address; give the address as tcp://host:port, or "
                         "leave --scheduler out to run on this machine's cores")
    match = _ADDRESS_RE.fullmatch(address.strip())
    if match is None:
        raise bad("not a scheduler address")
    scheme, host, port = match.group("scheme"), match.group("host"), match.group("port")
    if scheme is not None and scheme.lower() not in SCHEDULER_PROTOCOLS:
        raise bad(f"`{scheme}` is not a Dask protocol ({', '.join(SCHEDULER_PROTOCOLS)})")
    if not host:
        raise bad("no host")
    if not _HOST_RE.fullmatch(host):
        raise bad(f"`{host}` is not a host name or IP address")
    if port is None or port == "":
        raise bad("no port")
    if not re.fullmatch(r"[0-9]{1,5}", port) or not 1 <= int(port) <= 65535:
        raise bad(f"the port `{port}` is not a whole number from 1 to 65535")
    return f"{(scheme or 'tcp').lower()}://{host}:{int(port)}"


def _dask_client(address: str):
    address = check_scheduler_address(address)
    try:
        from distributed import Client
    except ImportError:
        raise SweepError("--scheduler needs the `distributed` package; "
                         "install it from the quadctl checkout with pip install '.[cluster]'") from None
    try:
        return Client(address, timeout=SCHEDULER_TIMEOUT, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SweepError(f"--scheduler {address}: cannot reach the Dask scheduler ({reason}); "
                         "check the address, or start one with `dask scheduler`") from None


def _dask_results(client, tasks: list[ChunkTask]) -> Iterator[ChunkResult]:
    from distributed import as_completed

    futures = client.map(evaluate_chunk, tasks, pure=False)
    try:
        for fut in as_completed(futures, loop=client.loop):
            yield fut.result()
    finally:
        client.cancel(futures)


