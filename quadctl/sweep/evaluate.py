"""Evaluating cases: a chunk of sweep cases designed and simulated together (batched), or one by one.

The batched path takes every config :func:`quadctl.pipeline.simulation_of` takes: the subsystem
designs of the whole chunk in batched Riccati solves (continuous, or discrete at the controller
rate with the ``lqrd`` weights), residual-checked, a case whose solve misses the check designed
again one by one (which names the reason); the coupled verdicts stacked; the simulations in the
SIMD lanes of :mod:`quadctl.sim`, :data:`~quadctl.sim.engine.LANES` cases per call, with the
rate and hold, motors and saturation, integrators and noise of each case; a case with turbulence
reads its late settling against its twin (:func:`quadctl.pipeline.twin_of`), flown in the lanes too.
Each row says which path it took (``path``). Rows equal the one-by-one path's
(``tests/sweep/test_sweep.py``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from quadctl import metrics, pipeline, run_summary
from quadctl.errors import ConfigError, DesignError, QuadctlError, StepSizeError, TrimError
from quadctl.layout import N_STATES, STATE_INDEX
from quadctl.metrics import error_into, summarize_errors
from quadctl.present.mission import mission_text
from quadctl.present.stages import unstable_cascade_gate
from quadctl.sim.lane_metrics import row_values, tracking
from quadctl.sim.run import verdict
from quadctl.sweep import batched, lane_jobs
from quadctl.sweep.batched import CaseDesign, core_extremes
from quadctl.sweep.gates import (
    MARGIN_COLUMNS,
    gated_margins,
    judge,
    margin_columns,
    noise_limited_reason,
    tracking_columns,
)
from quadctl.sweep.prepare import CaseSetups, Prepared, plant_of
from quadctl.threads import one_thread

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
            rows[index] = _failed(head, "invalid_config", str(setup))
            continue
        if setup.weight_error is not None:  # a Bryson rule with no room on this case's vehicle
            rows[index] = _failed(head, "invalid_config", setup.weight_error)
            continue
        if derived:
            base_plant = plant_of(setups.base) if base_plant is None else base_plant
            plant = base_plant
        else:
            plant = plant_of(setup)
        if isinstance(plant, TrimError):
            rows[index] = _failed(head, "no_trim", str(plant))
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
                rows[prep.index] = _failed(prep.head, "failed", str(exc))
    margins = gated_margins(task.gates)
    stages = {prep.index: pipeline.Stages(prep.setup, linear=prep.plant.linear, decoupled=prep.plant.decoupled)
              for prep in ready if margins or prep.setup.law == "pid"}  # a cascade's lift serves both below
    for prep in ready:
        if prep.setup.law == "pid":
            _judge_cascade(rows[prep.index], stages[prep.index])
    if margins:
        for prep in ready:
            _add_margins(rows[prep.index], prep, stages[prep.index])
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


def _judge_cascade(row: dict, stages: pipeline.Stages) -> None:
    """With ``controller.flies: pid``, a case's ``stable`` is the cascade's that flies, as ``simulate`` checks it
    (:attr:`quadctl.sim.cascade_lift.Lifted.stable`: its closed loop about hover, lifted to its frame), not the
    LQR design's; ``eig.slowest`` is the rate of its slowest mode, ln(spectral radius) / frame (rad/s), and
    ``eig.fastest`` is empty (the frame map's poles at 0, the held samples', have no rate)."""
    if row.get("stable") is None:  # no design: the case did not fly
        return
    lift = stages.pid_lift
    radius = float(np.abs(lift.poles).max())
    row["stable"] = lift.stable
    row["eig.fastest"], row["eig.slowest"] = None, float(np.log(radius)) / lift.frame_time
    if not lift.stable:
        row["instability"] = unstable_cascade_gate(radius, lift.frame_time)


def _add_margins(row: dict, prep: Prepared, stages: pipeline.Stages) -> None:
    """A designed case's :data:`~quadctl.sweep.gates.MARGIN_COLUMNS` (None where it has no design): of the law
    that flies, as ``quadctl margins`` reports them (``controller.flies: pid``: the cascade's loops)."""

    row.update(dict.fromkeys(MARGIN_COLUMNS))
    if row.get("stable") is None:  # no design
        return
    try:
        found = stages.pid_margins if prep.setup.law == "pid" else \
            pipeline.margins_of(prep.setup, prep.plant.linear, prep.plant.decoupled, stages.design)
    except QuadctlError as exc:
        row["margins_missing"] = f"no margins: {exc}"
        return
    row.update(margin_columns(found))
    if row[MARGIN_COLUMNS[0]] is None:
        row["margins_missing"] = "a loop is unstable"


@lru_cache(maxsize=32)
def _columns(kind: str, names: tuple[str, ...]) -> tuple[str, ...]:
    """Row keys of a metric's values: ``settling_time.phi``, ... (the same few for every row)."""
    return tuple(f"{kind}.{name}" for name in names)


def _failed(head: dict, status: str, reason: str) -> dict:
    row = dict(head)
    row.update({"stable": None, "eig.fastest": None, "eig.slowest": None, "status": status,
                "dt": None, "steps": 0, "reason": reason, "path": "", "noise_limited": []})
    return row


def _row(head: dict, stable: bool, core_eigs, plan, summary: dict | None, steps: int, reason: str = "",
         path: str = "", flat: tuple | None = None) -> dict:
    """A case's row: its head, design verdict, metrics and run. ``core_eigs``: the core eigenvalues,
    or a :class:`~quadctl.sweep.batched.CaseDesign` (its :meth:`eig_extremes`). The metrics from
    ``summary`` (the dict of :func:`quadctl.metrics.summarize`) or ``flat``, (column names, values)
    as :func:`quadctl.sim.lane_metrics.row_values` gives them (the same columns)."""
    row = dict(head)
    row["stable"] = bool(stable)

    row["eig.fastest"], row["eig.slowest"] = (core_eigs.eig_extremes() if isinstance(core_eigs, CaseDesign)
                                              else core_extremes(core_eigs))
    if flat is not None:
        row.update(zip(*flat))
    elif summary is not None:
        for kind in ("settling_time", "overshoot", "peak"):
            values = summary[kind]
            row.update(zip(_columns(kind, tuple(values)), values.values()))
        row["cost"] = summary["cost"]
        row["status"] = summary["status"]
        row["noise_limited"] = summary["noise_limited"]
    row.setdefault("noise_limited", [])
    row["dt"] = plan.dt if plan is not None else None
    row["steps"] = int(steps)
    row["reason"] = reason
    row["path"] = path
    return row


def mission_reason(setup, reached, status: str) -> str:
    """A row's ``reason`` for a mission (``setup.reference`` with waypoints) whose waypoints were
    ``reached`` (s each, or None) in a run that ended ``status``: the sentence ``simulate`` fails with
    (:func:`quadctl.present.mission.mission_text`), or empty (reached; a run that did not finish says
    so itself). A sweep's lanes keep no final error: only the missed waypoints count here."""

    ref = setup.reference
    if ref is None or not ref.legs or status != "ok":
        return ""
    tracking = {"waypoints": [{"position": list(leg.position), "reached": r} for leg, r in zip(ref.legs, reached)],
                "tolerance": ref.tolerance, "mission_end": ref.end}
    tracking.update(run_summary.mission_check(tracking, status=status,
                                              unregulated=run_summary.unregulated_positions(setup),
                                              duration=setup.duration))
    return mission_text(tracking) or ""


def _evaluate_one(prep: Prepared, stats: dict, trace: tuple = ()) -> tuple[dict, np.ndarray | None]:
    """One case through the chain of stages (:class:`quadctl.pipeline.Stages`, from its plant's
    shared linear model and partition), as ``quadctl simulate`` runs it (the reference path).

    Returns the row and, when ``trace`` names states and the run reached its end, their
    deviations resampled by :func:`resample_deviation` (else None).
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
        return _failed(prep.head, "design_failed", str(exc)), None
    loop = stages.loop
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
    t0 = time.perf_counter()
    calm = pipeline.twin_simulation(setup, loop)  # turbulence: its late settling is read against the run without it
    if calm is not None:
        stats["simulate_time"] += time.perf_counter() - t0
        stats["steps"] += calm.steps
    twin = pipeline.twin_settling(setup, loop, calm)
    summary = metrics.summarize(sim, linear.u_trim, setup.Q_block, setup.R_block, setup.regulated,
                                noisy=pipeline.noisy(setup), twin=twin)
    row = _row(prep.head, des.stable, des.core_eigenvalues, sim.plan, summary, sim.steps,
               "" if sim.status == "ok" else sim.message, "one-by-one")
    tracking = run_summary.tracking_summary(setup, sim)
    row.update(tracking_columns(tracking))
    if tracking is not None and "waypoints" in tracking and sim.status == "ok":
        row["reason"] = mission_reason(setup, [w["reached"] for w in tracking["waypoints"]], sim.status)
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


SEED_KEYS = (("simulation", "noise", "seed"), ("simulation", "wind", "turbulence", "seed"))
"""Key paths whose value a case's twin (:func:`quadctl.pipeline.twin_of`) does not read: the cases of a
chunk whose other values are the same share one twin (a Monte Carlo over turbulence seeds runs one)."""


def evaluate_batched(preps: list[Prepared], stats: dict, trace: tuple = (), seeds: tuple = ()) -> tuple[dict, dict]:
    """Design, assess and simulate cases together; (rows, Monte Carlo traces) by case number.

    A case with turbulence reads its late settling against its twin (:func:`quadctl.pipeline.twin_of`),
    simulated as one more case in the lanes, before the cases (its settling times are read with
    theirs); the cases whose parameters differ only in the columns ``seeds`` (their names,
    :data:`SEED_KEYS`) share one."""

    rows: dict[int, dict] = {}
    t0, c0 = time.perf_counter(), time.process_time()
    # rows read the extremes of each core, and take its gains to round-off
    designs = batched.design_all(preps, stats, any_order=True, compiled=True)
    stats["design_time"] += time.perf_counter() - t0
    stats["design_cpu"] += time.process_time() - c0
    live = []
    for prep, des in zip(preps, designs):
        if isinstance(des, str):
            rows[prep.index] = _failed(prep.head, "design_failed", des)
        else:
            live.append((prep, des))
    twin_live, twin_of_case = _twins(live, seeds)
    exponential = bool(live) and live[0][0].setup.method == "etdrk4"  # a sweep runs one method
    jobs, twin_jobs = [], []
    made = lane_jobs.loops_of(live + twin_live, "etdrk4" if exponential else "rk4")
    for (prep, des), job in zip(live, made):
        if isinstance(job, str):
            row = _row(prep.head, des.stable, des.core, None, None, 0, job, des.path)
            row["status"] = "step_refused"
            rows[prep.index] = row
        elif isinstance(job, QuadctlError):
            rows[prep.index] = _failed(prep.head, "failed", str(job))
        else:
            jobs.append((prep, des, job))
    # a twin whose job is refused did not run: no state of it settled
    twin_jobs = [(prep, des, job) for (prep, des), job in zip(twin_live, made[len(live):])
                 if not isinstance(job, (str, QuadctlError))]
    t0 = time.perf_counter()
    twin_rows = _simulated(twin_jobs, stats, (), exponential, {})[0]
    twins = {case: {name: twin_rows.get(k, {}).get(f"settling_time.{name}") for name in twin_live[k][0].setup.regulated}
             for case, k in twin_of_case.items()}
    simulated, traces, tracked, reasons = _simulated(jobs, stats, trace, exponential, twins)
    rows.update(simulated)
    stats["simulate_time"] += time.perf_counter() - t0
    for index, columns in tracked.items():
        rows[index].update(columns)
    for index, reason in reasons.items():
        if reason:
            rows[index]["reason"] = reason
    return rows, traces


def _twins(live: list, seeds: tuple) -> tuple[list, dict]:
    """The twins (:func:`quadctl.pipeline.twin_of`) the cases with turbulence among ``live`` (``(prep,
    design)`` each) read their settling against: ``(prep, design)`` per twin (its ``index`` its place
    in the list) and the twin's place per case number; cases whose parameters but ``seeds`` are the
    same share one."""

    twins: list = []
    place: dict = {}  # the case's parameters but its seeds -> its twin's place
    of_case: dict[int, int] = {}
    for prep, des in live:
        twin = pipeline.twin_of(prep.setup)
        if twin is None:
            continue
        key = repr([(name, value) for name, value in prep.head.items() if name != "case" and name not in seeds])
        if key not in place:
            place[key] = len(twins)
            twins.append((Prepared(len(twins), {}, twin, prep.plant), des))
        of_case[prep.index] = place[key]
    return twins, of_case


def _simulated(jobs: list, stats: dict, trace: tuple, exponential: bool, twins: dict) -> tuple:
    """Run ``jobs`` (``(prep, design, job)`` each) in the lanes and read their rows: (rows, Monte Carlo
    traces, tracking columns, a mission's reason), each by ``prep.index``. ``twins``: per case with
    turbulence, its twin's settling times (:func:`quadctl.metrics.summarize`'s ``twin``)."""

    rows: dict[int, dict] = {}
    traces: dict[int, np.ndarray] = {}
    tracked: dict[int, dict] = {}  # case -> its tracking columns (cases that fly a reference)
    reasons: dict[int, str] = {}  # case -> why its mission failed (cases that fly waypoints and finish)
    batch = MetricsBatch()
    summed: list = []  # (prep, design, job, done, status, message, sums) of the runs summed in the lanes

    def recorded(prep, des, job, done, t, xs, us, backend):
        setup, linear = prep.setup, prep.plant.linear
        plan = job.plan
        x = xs[:, :len(linear.x_trim)]
        status, message = verdict(x, t, done, plan.n_steps, job.lo, job.hi)
        stats["steps"] += done
        stats["backend"].add(backend)
        x_ref = None
        if setup.reference is not None:  # the reference the lanes flew: their exogenous rows

            flown = setup.flown_reference
            rows_at = np.floor(t / job.exo_period + 1e-9).astype(np.int64)
            x_ref = flown.flown(flown.rows(rows_at, job.exo_period), t)[0]
            tracking = run_summary.tracking_of(setup.reference, t, x, x_ref)
            tracked[prep.index] = tracking_columns(tracking)
            if "waypoints" in tracking:
                reasons[prep.index] = mission_reason(setup, [w["reached"] for w in tracking["waypoints"]], status)
        for (p, d, j, steps, msg), summary in batch.add(t, x, us, setup, linear, status,
                                                         (prep, des, job, done, message), x_ref,
                                                         twins.get(prep.index)):
            rows[p.index] = _row(p.head, d.stable, d.core, j.plan, summary, steps, "" if summary["status"] == "ok"
                                 else msg, d.path)
        if trace and status == "ok":
            x_ref = linear.x_trim + np.outer(t, linear.x_rate) if x_ref is None else x_ref
            traces[prep.index] = resample_deviation(t, x, x_ref, trace, setup.duration)

    if trace or exponential:  # a Monte Carlo keeps each trajectory; ETDRK4's lanes keep records
        for (prep, des, job), (done, t, xs, us), backend in batched.simulate_all(jobs):
            recorded(prep, des, job, done, t, xs, us, backend)
    else:
        for (prep, des, job), result, backend in batched.summarize_all(jobs):
            done = result[0]
            if result[-1] is None:  # a runner that keeps records (CasADi's VM)
                recorded(prep, des, job, *result[:4], backend)
                continue
            _, t_end, x_end, _, sums = result
            status, message = verdict(x_end[None, :N_STATES], np.array([t_end]), done, job.plan.n_steps, job.lo,
                                      job.hi)
            stats["steps"] += done
            stats["backend"].add(backend)
            summed.append((prep, des, job, done, status, message, sums.copy()))
    for (p, d, j, steps, msg), summary in batch.flush():
        rows[p.index] = _row(p.head, d.stable, d.core, j.plan, summary, steps,
                             "" if summary["status"] == "ok" else msg, d.path)
    _summed_rows(summed, rows, tracked, reasons, twins)
    return rows, traces, tracked, reasons


def _summed_rows(summed: list, rows: dict, tracked: dict, reasons: dict, twins: dict) -> None:
    """Rows (and tracking columns, and a mission's reason) of the runs summed in the lanes: ``(prep,
    design, job, done, status, message, sums)`` each, read back together per set of regulated states;
    ``twins`` as :func:`_simulated`'s."""

    groups: dict[tuple, list] = {}
    for item in summed:
        groups.setdefault(item[0].setup.regulated, []).append(item)
    for regulated, items in groups.items():
        names, out = row_values(np.stack([it[6] for it in items]), [it[2].plan.dt for it in items], regulated,
                                [it[4] for it in items], [pipeline.noisy(it[0].setup) for it in items],
                                [twins.get(it[0].index) for it in items])
        for (prep, des, job, done, status, message, sums), values in zip(items, out):
            rows[prep.index] = _row(prep.head, des.stable, des, job.plan, None, done,
                                    "" if status == "ok" else message, des.path, flat=(names, values))
            ref = prep.setup.reference
            if ref is not None:
                got = tracking(sums, len(ref.legs))
                columns = {"position_error": {"rms": got["rms"], "peak": got["peak"]}}
                if ref.legs:
                    columns["waypoints"] = [{"reached": r} for r in got["reached"]]
                    reasons[prep.index] = mission_reason(prep.setup, got["reached"], status)
                tracked[prep.index] = tracking_columns(columns)


class MetricsBatch:
    """Runs gathered for :func:`quadctl.metrics.summarize_errors`: their errors are computed as the
    runner yields them (its arrays are overwritten by the next lanes) into one (B, 12, r) array,
    and summarized together when the batch is full (:meth:`size`) or the next run differs in
    samples, regulated states or weight sparsity (each run's numbers are those it gets alone)."""

    SIZE = 8
    """Runs a batch holds at most."""
    SAMPLES = 16_384
    """Samples a batch holds at most (runs times samples): past that the per-call cost saved is
    small and the batch's arrays outgrow the caches (measured: 2 000-sample runs gain 8 at a time,
    10 000-sample runs lose ~5 % even 2 at a time)."""

    def size(self, r: int) -> int:
        """Runs of ``r`` samples a batch holds."""
        return max(1, min(self.SIZE, self.SAMPLES // max(r, 1)))

    def __init__(self):
        self.key = None
        self.items: list = []

    def add(self, t, x, u, setup, linear, status, item, x_ref=None, twin: dict | None = None) -> list:
        """Gather one run (``x`` (r, 12), ``u`` (r, 4); ``x_ref`` (r, 12) the reference it flew, None:
        the trim moving at its velocity; ``twin``: with turbulence, its twin's settling times,
        :func:`quadctl.metrics.summarize`'s); returns the ``(item, summary)`` pairs of the
        batch this completes or closes (else none)."""
        key = (len(t), setup.regulated, (setup.Q_block != 0).tobytes(), (setup.R_block != 0).tobytes())
        done = self.flush() if key != self.key else []
        if not self.items:
            self.key = key
            r = len(t)
            self.capacity = self.size(r)
            self.t, self.err, self.u = np.empty((self.capacity, r)), np.empty((self.capacity, N_STATES, r)), \
                np.empty((self.capacity, u.shape[1], r))
            self.u_trim, self.Q, self.R, self.status, self.noisy, self.twin = [], [], [], [], [], []

        b = len(self.items)
        self.t[b] = t
        if x_ref is None:
            error_into(self.err[b], t, x.T, linear.x_trim, linear.x_rate)
        else:
            np.subtract(x.T, x_ref.T, out=self.err[b])
        self.u[b] = u.T
        self.u_trim.append(linear.u_trim)
        self.Q.append(setup.Q_block)
        self.R.append(setup.R_block)
        self.status.append(status)
        self.noisy.append(pipeline.noisy(setup))
        self.twin.append(twin)
        self.items.append(item)
        return done + (self.flush() if len(self.items) == self.capacity else [])

    def flush(self) -> list:
        """Summarize what is gathered: ``(item, summary)`` pairs."""

        if not self.items:
            return []
        B = len(self.items)
        summaries = summarize_errors(self.t[:B], self.err[:B], self.u[:B], np.array(self.u_trim), np.array(self.Q),
                                     np.array(self.R), self.key[1], self.status, self.noisy, self.twin)
        out = list(zip(self.items, summaries))
        self.items = []
        return out
