"""Evaluating cases: a chunk of sweep cases designed and simulated together (batched), or one by one.

The batched path takes every config :func:`quadctl.pipeline.simulation_of` takes: the subsystem
designs of the whole chunk in batched Riccati solves (continuous, or discrete at the controller
rate with the ``lqrd`` weights), residual-checked, a case whose solve misses the check designed
again one by one (which names the reason); the coupled verdicts stacked; the simulations in the
SIMD lanes of :mod:`quadctl.sim`, :data:`~quadctl.sim.engine.LANES` cases per call, with the
rate and hold, motors and saturation, integrators and noise of each case. Each row says which
path it took (``path``). Rows equal the one-by-one path's (``tests/test_sweep.py``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from quadctl.errors import ConfigError, DesignError, QuadctlError, StepSizeError, TrimError
from quadctl.layout import STATE_INDEX
from quadctl.sweep.gates import judge
from quadctl.sweep.spec import assign

MC_POINTS = 201
"""A Monte Carlo case keeps its regulated states at this many evenly spaced times (float32): with
the ten regulated states of ``mambo-200hz``, 8 kB a case in memory and in the journal, whatever the
duration and step (10 000 seeds: 80 MB). At 10 s, a point every 50 ms."""
MC_PERCENTILES = (5, 25, 50, 75, 95)
"""The percentiles a Monte Carlo reports at every time (the bands 5-95 and 25-75, the median)."""

@dataclass(frozen=True)
class ChunkTask:
    """Everything a worker needs for a chunk of cases (plain data: it travels by pickle).

    Attributes
    ----------
    base : dict
        The base config as a mapping, with the sweep's ``set:`` values already in.
    label : str
        Names the config in the message of a case that fails validation.
    keys : tuple of tuple
        The parameters' parsed key paths.
    names : tuple of str
        The parameters' key paths as written (row keys).
    cases : tuple of (int, tuple)
        Case number and parameter values.
    gates : tuple of Gate
    require_ok : bool
    fast : bool
        Design and simulate the chunk's cases together (False: every case through the pipeline,
        one by one: the reference the batched path is tested against).
    trace : tuple of str
        A Monte Carlo: the states whose trajectories each case keeps (empty: none).
    """

    base: dict
    label: str
    keys: tuple
    names: tuple
    cases: tuple
    gates: tuple
    require_ok: bool
    fast: bool = True
    trace: tuple = ()


@dataclass
class ChunkResult:
    """Rows of a chunk, what computing them took and, in a Monte Carlo, each case's trajectory:
    case number -> (MC_POINTS, len(trace)) float32 array (see :func:`resample_deviation`); a case
    that did not simulate to the end has none."""

    rows: list
    stats: dict
    traces: dict = field(default_factory=dict)


def evaluate_chunk(task: ChunkTask) -> ChunkResult:
    """Evaluate a chunk of cases: one row per case, never an exception for a bad case.

    The top-level function executors run (a local process or a Dask worker). BLAS and OpenMP run
    one thread meanwhile: the workers are the parallelism, and the matrices here are too small for
    threads to pay (on 2 cores, BLAS threads on top of two workers made a sweep 6 to 16x slower).
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        return _evaluate_chunk(task)


def _evaluate_chunk(task: ChunkTask) -> ChunkResult:
    from quadctl import config as config_mod
    from quadctl import pipeline
    from quadctl.setup import resolve

    start = time.perf_counter()
    stats = {"cases": len(task.cases), "designs": 0, "design_time": 0.0, "design_cpu": 0.0, "simulate_time": 0.0,
             "steps": 0, "fallbacks": 0, "backend": set()}
    rows: dict[int, dict] = {}
    traces: dict[int, np.ndarray] = {}
    ready = []
    plant_cache: dict[tuple, Any] = {}
    for index, values in task.cases:
        data = task.base
        for keys, value in zip(task.keys, values):
            data = assign(data, keys, _plain(value))
        head = {"case": index, **dict(zip(task.names, values))}
        try:
            setup = resolve(config_mod.from_dict(data, f"{task.label} case {index}"))
        except ConfigError as exc:
            rows[index] = _failed(head, "invalid_config", str(exc))
            continue
        key = _plant_key(setup)
        if key not in plant_cache:
            try:
                trim = pipeline.trim_of(setup)
                linear = pipeline.linear_of(setup, trim)
                plant_cache[key] = Plant(linear, pipeline.decoupled_of(setup, linear))
            except TrimError as exc:
                plant_cache[key] = exc
        plant = plant_cache[key]
        if isinstance(plant, TrimError):
            rows[index] = _failed(head, "no_trim", str(plant))
            continue
        ready.append(Prepared(index, head, setup, plant))
    if task.fast:
        batched_rows, batched_traces = evaluate_batched(ready, stats, task.trace)
        rows.update(batched_rows)
        traces.update(batched_traces)
    else:
        for prep in ready:
            try:
                rows[prep.index], trace = _evaluate_one(prep, stats, task.trace)
                if trace is not None:
                    traces[prep.index] = trace
            except QuadctlError as exc:  # whatever a feature of the config refuses: a row, not a crash
                rows[prep.index] = _failed(prep.head, "failed", str(exc))
    out = []
    for index, _ in task.cases:
        row = rows[index]
        passed, failed = judge(row, task.gates, task.require_ok)
        row["pass"] = passed
        row["failed_gates"] = "; ".join(failed)
        out.append(row)
    stats["backend"] = sorted(stats["backend"])
    stats["wall_time"] = time.perf_counter() - start
    return ChunkResult(rows=out, stats=stats, traces=traces)


class Plant:
    """The linear model of a flight condition and its partition, shared by the cases that fly it;
    the matrices the batched path needs of it are computed once (``cache``)."""

    def __init__(self, linear, decoupled):
        self.linear = linear
        self.decoupled = decoupled
        self.cache: dict = {}

    def sampled(self, Ts: float):
        """ZOH ``(Ad, Bd)`` of the coupled model at ``Ts``."""
        from quadctl import discrete

        if ("zoh", Ts) not in self.cache:
            self.cache[("zoh", Ts)] = discrete.c2d(self.linear.A, self.linear.B, Ts)
        return self.cache[("zoh", Ts)]

    def open_loop_eigenvalues(self):
        if "eig" not in self.cache:
            self.cache["eig"] = np.linalg.eigvals(self.linear.A)
        return self.cache["eig"]


@dataclass
class Prepared:
    """A case ready to design: its row head, its resolved setup and its plant."""

    index: int
    head: dict
    setup: Any
    plant: Plant


def _plant_key(setup) -> tuple:
    """What the trim, the linear model and the decoupling depend on."""
    parts = tuple((name, tuple(sub.states), tuple(sub.inputs), sub.regulate, tuple(sub.outputs or ()))
                  for name, sub in setup.partition.items())
    return (setup.vehicle, setup.velocity_ned, setup.position_ned, setup.yaw, setup.trim_wind, parts)


def _plain(value):
    """numpy scalars as Python numbers (the strict config schema takes float, not float64)."""
    if isinstance(value, np.generic):
        return value.item()
    return value


def _failed(head: dict, status: str, reason: str) -> dict:
    row = dict(head)
    row.update({"stable": None, "eig.fastest": None, "eig.slowest": None, "status": status,
                "dt": None, "steps": 0, "reason": reason, "path": ""})
    return row


def _row(head: dict, stable: bool, core_eigs, plan, summary: dict | None, steps: int, reason: str = "",
         path: str = "") -> dict:
    row = dict(head)
    row["stable"] = bool(stable)
    row["eig.fastest"] = float(np.min(core_eigs.real)) if len(core_eigs) else None
    row["eig.slowest"] = float(np.max(core_eigs.real)) if len(core_eigs) else None
    if summary is not None:
        for state, value in summary["settling_time"].items():
            row[f"settling_time.{state}"] = value
        for state, value in summary["overshoot"].items():
            row[f"overshoot.{state}"] = value
        for name, value in summary["peak"].items():
            row[f"peak.{name}"] = value
        row["cost"] = summary["cost"]
        row["status"] = summary["status"]
    row["dt"] = plan.dt if plan is not None else None
    row["steps"] = int(steps)
    row["reason"] = reason
    row["path"] = path
    return row


def _evaluate_one(prep: Prepared, stats: dict, trace: tuple = ()) -> tuple[dict, np.ndarray | None]:
    """One case through the pipeline, as ``quadctl simulate`` runs it (the reference path).

    Returns the row and, when ``trace`` names states and the run reached its end, their
    deviations resampled by :func:`resample_deviation` (else None).
    """
    from quadctl import metrics, pipeline

    setup, linear = prep.setup, prep.plant.linear
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        des = pipeline.design_of(setup, prep.plant.decoupled, linear)
        stats["design_time"] += time.perf_counter() - t0
        stats["design_cpu"] += time.process_time() - c0
        stats["designs"] += len(prep.plant.decoupled.regulated)
    except DesignError as exc:
        return _failed(prep.head, "design_failed", str(exc)), None
    loop = pipeline.loop_of(setup, linear, des)
    try:
        t0 = time.perf_counter()
        sim = pipeline.simulation_of(setup, loop)
        stats["simulate_time"] += time.perf_counter() - t0
    except StepSizeError as exc:
        row = _row(prep.head, des.stable, des.core_eigenvalues, None, None, 0, str(exc), "one-by-one")
        row["status"] = "step_refused"
        return row, None
    stats["backend"].add(sim.backend)
    stats["steps"] += sim.steps
    summary = metrics.summarize(sim, linear.u_trim, setup.Q_block, setup.R_block, setup.regulated)
    row = _row(prep.head, des.stable, des.core_eigenvalues, sim.plan, summary, sim.steps,
               "" if sim.status == "ok" else sim.message, "one-by-one")
    kept = None
    if trace and sim.status == "ok":
        kept = resample_deviation(sim.t, sim.x, sim.x_ref, trace, setup.duration)
    return row, kept


def mc_grid(duration: float) -> np.ndarray:
    """The Monte Carlo time grid: (MC_POINTS,) evenly spaced times from 0 to ``duration`` s."""
    return np.linspace(0.0, float(duration), MC_POINTS)


def resample_deviation(t, x, x_ref, states, duration: float) -> np.ndarray:
    """Deviation of ``states`` from the reference, linearly interpolated onto :func:`mc_grid`.

    Parameters
    ----------
    t : (N,) array_like
        s, increasing (a simulation's records).
    x, x_ref : (N, 12) array_like
        State and reference (state units: m, m/s, rad, rad/s).
    states : sequence of str
    duration : float
        s, the end of the grid.

    Returns
    -------
    (MC_POINTS, len(states)) float32 ndarray
        ``x - x_ref`` at the grid's times. float32 keeps seven digits, far below the noise a Monte
        Carlo measures, at half the memory.
    """
    grid = mc_grid(duration)
    index = [STATE_INDEX[s] for s in states]
    dev = np.asarray(x)[:, index] - np.asarray(x_ref)[:, index]
    return np.stack([np.interp(grid, t, dev[:, j]) for j in range(len(index))], axis=1).astype(np.float32)


def evaluate_batched(preps: list[Prepared], stats: dict, trace: tuple = ()) -> tuple[dict, dict]:
    """Design, assess and simulate cases together; (rows, Monte Carlo traces) by case number."""
    from quadctl.sweep import batched

    rows: dict[int, dict] = {}
    traces: dict[int, np.ndarray] = {}
    t0, c0 = time.perf_counter(), time.process_time()
    designs = batched.design_all(preps, stats)
    stats["design_time"] += time.perf_counter() - t0
    stats["design_cpu"] += time.process_time() - c0
    live = []
    for prep, des in zip(preps, designs):
        if isinstance(des, str):
            rows[prep.index] = _failed(prep.head, "design_failed", des)
        else:
            live.append((prep, des))
    jobs = []
    for (prep, des), job in zip(live, batched.loops_of(live)):
        if isinstance(job, str):
            row = _row(prep.head, des.stable, des.core, None, None, 0, job, des.path)
            row["status"] = "step_refused"
            rows[prep.index] = row
        elif isinstance(job, QuadctlError):
            rows[prep.index] = _failed(prep.head, "failed", str(job))
        else:
            jobs.append((prep, des, job))
    t0 = time.perf_counter()
    for (prep, des, job), (done, ks, xs, us), backend in batched.simulate_all(jobs):
        from quadctl import metrics
        from quadctl.simulate import verdict

        setup, linear = prep.setup, prep.plant.linear
        plan = job.plan
        t = plan.dt * ks
        x = xs[:, :len(linear.x_trim)]
        status, message = verdict(x, t, done, plan.n_steps, job.lo, job.hi)
        summary = metrics.summarize_run(t, x, us, (linear.x_trim, linear.x_rate), linear.u_trim,
                                        setup.Q_block, setup.R_block, setup.regulated, status)
        stats["steps"] += done
        stats["backend"].add(backend)
        rows[prep.index] = _row(prep.head, des.stable, des.core, plan, summary, done,
                                "" if status == "ok" else message, des.path)
        if trace and status == "ok":
            x_ref = linear.x_trim + np.outer(t, linear.x_rate)
            traces[prep.index] = resample_deviation(t, x, x_ref, trace, setup.duration)
    stats["simulate_time"] += time.perf_counter() - t0
    return rows, traces
