"""Evaluating cases: a chunk of sweep cases designed and simulated together (batched), or one by one.

:func:`evaluate_chunk` makes each case's setup and plant (:mod:`quadctl.sweep.prepare`), designs and flies
the chunk's cases together (:mod:`quadctl.sweep.lane_rows`) or each through the chain of stages as
``quadctl simulate`` runs it (the reference path), adds the verdicts of the law that flies and the margins
(:mod:`quadctl.sweep.rows`), and judges each row against the gates. Each row says which path it took
(``path``). Rows equal the one-by-one path's (``tests/sweep/test_sweep.py``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from quadctl import metrics, pipeline, run_summary
from quadctl.errors import ConfigError, DesignError, QuadctlError, StepSizeError, TrimError
from quadctl.sweep.gates import gated_margins, judge, noise_limited_reason, tracking_columns
from quadctl.sweep.lane_rows import SEED_KEYS, evaluate_batched
from quadctl.sweep.prepare import CaseSetups, Prepared, plant_of
from quadctl.sweep.rows import (
    add_margins,
    case_row,
    failed_row,
    judge_cascade,
    mission_reason,
    resample_deviation,
)
from quadctl.threads import one_thread


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
    case number -> (MC_POINTS, len(trace)) float32 array (see
    :func:`~quadctl.sweep.rows.resample_deviation`); a case that did not simulate to the end has none."""

    rows: list
    stats: dict
    traces: dict = field(default_factory=dict)


def evaluate_chunk(task: ChunkTask) -> ChunkResult:
    """Evaluate a chunk of cases: one row per case, never an exception for a bad case.

    The top-level function executors run (a local process or a Dask worker). BLAS and OpenMP run
    one thread meanwhile: the workers are the parallelism, and the matrices here are too small for
    threads to pay (on 2 cores, BLAS threads on top of two workers made a sweep 6 to 16x slower).
    """
    with one_thread():
        return _evaluate_chunk(task)


def _evaluate_chunk(task: ChunkTask) -> ChunkResult:
    start = time.perf_counter()
    stats = {"cases": len(task.cases), "designs": 0, "design_time": 0.0, "design_cpu": 0.0, "simulate_time": 0.0,
             "steps": 0, "fallbacks": 0, "backend": set()}
    rows: dict[int, dict] = {}
    traces: dict[int, np.ndarray] = {}
    ready = []
    setups = CaseSetups(task)
    base_plant = None  # the plant of the cases derived from the base's setup (they fly its condition)
    for (index, values), (setup, derived) in zip(task.cases, setups.all(task.cases)):
        head = {"case": index, **dict(zip(task.names, values))}
        if isinstance(setup, ConfigError):
            rows[index] = failed_row(head, "invalid_config", str(setup))
            continue
        if setup.weight_error is not None:  # a Bryson rule with no room on this case's vehicle
            rows[index] = failed_row(head, "invalid_config", setup.weight_error)
            continue
        if derived:
            base_plant = plant_of(setups.base) if base_plant is None else base_plant
            plant = base_plant
        else:
            plant = plant_of(setup)
        if isinstance(plant, TrimError):
            rows[index] = failed_row(head, "no_trim", str(plant))
            continue
        ready.append(Prepared(index, head, setup, plant))
    if task.fast:
        seeds = tuple(name for name, keys in zip(task.names, task.keys) if tuple(keys) in SEED_KEYS)
        batched_rows, batched_traces = evaluate_batched(ready, stats, task.trace, seeds)
        rows.update(batched_rows)
        traces.update(batched_traces)
    else:
        for prep in ready:
            try:
                rows[prep.index], trace = _evaluate_one(prep, stats, task.trace)
                if trace is not None:
                    traces[prep.index] = trace
            except QuadctlError as exc:  # whatever a feature of the config refuses: a row, not a crash
                rows[prep.index] = failed_row(prep.head, "failed", str(exc))
    margins = gated_margins(task.gates)
    stages = {prep.index: pipeline.Stages(prep.setup, linear=prep.plant.linear, decoupled=prep.plant.decoupled)
              for prep in ready if margins or prep.setup.law == "pid"}  # a cascade's lift serves both below
    for prep in ready:
        if prep.setup.law == "pid":
            judge_cascade(rows[prep.index], stages[prep.index])
    if margins:
        for prep in ready:
            add_margins(rows[prep.index], prep, stages[prep.index])
    out = []
    for index, _ in task.cases:
        row = rows[index]
        if row["noise_limited"]:  # its settling times are blank: say why (sweep.csv keeps its columns)
            note = noise_limited_reason(row["noise_limited"])
            row["reason"] = f"{row['reason']}; {note}" if row["reason"] else note
        passed, failed = judge(row, task.gates, task.require_ok)
        row["pass"] = passed
        row["failed_gates"] = "; ".join(failed)
        out.append(row)
    stats["backend"] = sorted(stats["backend"])
    stats["wall_time"] = time.perf_counter() - start
    return ChunkResult(rows=out, stats=stats, traces=traces)


def _evaluate_one(prep: Prepared, stats: dict, trace: tuple = ()) -> tuple[dict, np.ndarray | None]:
    """One case through the chain of stages (:class:`quadctl.pipeline.Stages`, from its plant's
    shared linear model and partition), as ``quadctl simulate`` runs it (the reference path).

    Returns the row and, when ``trace`` names states and the run reached its end, their
    deviations resampled by :func:`~quadctl.sweep.rows.resample_deviation` (else None).
    """

    setup, linear = prep.setup, prep.plant.linear
    stages = pipeline.Stages(setup, linear=linear, decoupled=prep.plant.decoupled)
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        des = stages.design
        stats["design_time"] += time.perf_counter() - t0
        stats["design_cpu"] += time.process_time() - c0
        stats["designs"] += len(prep.plant.decoupled.regulated)
    except DesignError as exc:
        return failed_row(prep.head, "design_failed", str(exc)), None
    loop = stages.loop
    try:
        t0 = time.perf_counter()
        sim = pipeline.simulation_of(setup, loop)
        stats["simulate_time"] += time.perf_counter() - t0
    except StepSizeError as exc:
        row = case_row(prep.head, des.stable, des.core_eigenvalues, None, None, 0, str(exc), "one-by-one")
        row["status"] = "step_refused"
        return row, None
    stats["backend"].add(sim.backend)
    stats["steps"] += sim.steps
    t0 = time.perf_counter()
    calm = pipeline.twin_simulation(setup, loop)  # turbulence: its late settling is read against the run without it
    if calm is not None:
        stats["simulate_time"] += time.perf_counter() - t0
        stats["steps"] += calm.steps
    twin = pipeline.twin_settling(setup, loop, calm)
    summary = metrics.summarize(sim, linear.u_trim, setup.Q_block, setup.R_block, setup.regulated,
                                noisy=pipeline.noisy(setup), twin=twin)
    row = case_row(prep.head, des.stable, des.core_eigenvalues, sim.plan, summary, sim.steps,
                   "" if sim.status == "ok" else sim.message, "one-by-one")
    tracking = run_summary.tracking_summary(setup, sim)
    row.update(tracking_columns(tracking))
    if tracking is not None and "waypoints" in tracking and sim.status == "ok":
        row["reason"] = mission_reason(setup, [w["reached"] for w in tracking["waypoints"]], sim.status)
    kept = None
    if trace and sim.status == "ok":
        kept = resample_deviation(sim.t, sim.x, sim.x_ref, trace, setup.duration)
    return row, kept
