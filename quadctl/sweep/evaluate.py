"""Evaluating cases: a chunk of sweep cases designed and simulated together (batched), or one by one."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from quadctl.errors import ConfigError, DesignError, QuadctlError, StepSizeError, TrimError
from quadctl.layout import INPUT_INDEX, N_INPUTS, N_STATES, STATE_INDEX, STATE_NAMES
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
        Use the batched path for configs it models (False: every case through the pipeline).
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

    The top-level function executors run (a local process or a Dask worker).
    """
    from quadctl import config as config_mod
    from quadctl import pipeline

    start = time.perf_counter()
    stats = {"cases": len(task.cases), "designs": 0, "design_time": 0.0, "design_cpu": 0.0, "simulate_time": 0.0,
             "steps": 0, "fallbacks": 0, "backend": set()}
    rows: dict[int, dict] = {}
    traces: dict[int, np.ndarray] = {}
    ready = []
    plant_cache: dict[str, Any] = {}
    for index, values in task.cases:
        data = task.base
        for keys, value in zip(task.keys, values):
            data = assign(data, keys, _plain(value))
        head = {"case": index, **dict(zip(task.names, values))}
        try:
            cfg = config_mod.from_dict(data, f"{task.label} case {index}")
        except ConfigError as exc:
            rows[index] = _failed(head, "invalid_config", str(exc))
            continue
        key = json.dumps(cfg.model_dump(mode="json", include={"vehicle", "trim", "subsystems"}),
                         sort_keys=True)
        if key not in plant_cache:
            try:
                trim = pipeline.trim_of(cfg)
                linear = pipeline.linear_of(cfg, trim)
                plant_cache[key] = (trim, linear, pipeline.decoupled_of(cfg, linear),
                                    pipeline.reference_rate(trim))
            except TrimError as exc:
                plant_cache[key] = exc
        plant = plant_cache[key]
        if isinstance(plant, TrimError):
            rows[index] = _failed(head, "no_trim", str(plant))
            continue
        ready.append(_Prepared(index, head, cfg, *plant))
    # the batched path for plain configs; a case is as plain as the base when the sweep only
    # touches keys the batched path models, so the full check runs once per chunk, not per case.
    # A Monte Carlo (noise: never plain) keeps trajectories, which only the pipeline path gives.
    batched = task.fast and not task.trace
    shortcut = ready and batched and all(_plain_key(keys) for keys in task.keys) and is_plain(ready[0].cfg)
    plain = [bool(shortcut) or (batched and is_plain(p.cfg)) for p in ready]
    fast = [p for p, ok in zip(ready, plain) if ok]
    slow = [p for p, ok in zip(ready, plain) if not ok]
    if fast:
        rows.update(_evaluate_batched(fast, stats))
    for prep in slow:
        try:
            rows[prep.index], trace = _evaluate_one(prep, stats, task.trace)
            if trace is not None:
                traces[prep.index] = trace
        except QuadctlError as exc:  # whatever else a feature of the config refuses: a row, not a crash
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


@dataclass
class _Prepared:
    index: int
    head: dict
    cfg: Any
    trim: Any
    linear: Any
    decoupled: Any
    rate: np.ndarray


_PLAIN = {
    "": {"name", "description", "vehicle", "trim", "subsystems", "lqr", "simulation"},
    "vehicle": {"mass", "gravity", "inertia", "drag"},
    "trim": {"velocity_ned", "position_ned", "yaw"},
    "simulation": {"duration", "dt", "initial_offset"},
    "lqr.*": {"Q", "R"},
    "subsystems.*": {"states", "inputs", "regulate", "outputs"},
}
"""The config keys the batched path models. A config that sets any other key away from its
default (a controller rate, motors, noise, integral action...) is evaluated case by case through
the pipeline."""


def is_plain(cfg) -> bool:
    """True when ``cfg`` is the plain continuous LQR loop the batched path simulates: every key
    outside :data:`_PLAIN` holds its schema default."""

    def at_default(section, key: str) -> bool:
        default = _default_of(type(section), key)
        return default is not _REQUIRED and _dumped(getattr(section, key)) == default

    def plain(section, allowed) -> bool:
        return all(key in allowed or at_default(section, key) for key in type(section).model_fields)

    if not plain(cfg, _PLAIN[""]):
        return False
    for name in ("vehicle", "trim", "simulation"):
        if not plain(getattr(cfg, name), _PLAIN[name]):
            return False
    blocks = [(w, _PLAIN["lqr.*"]) for w in cfg.lqr.values()]
    blocks += [(s, _PLAIN["subsystems.*"]) for s in (cfg.subsystems or {}).values()]
    return all(plain(section, allowed) for section, allowed in blocks)


def _plain_key(keys: tuple) -> bool:
    """Whether a key path stays inside what the batched path models (:data:`_PLAIN`)."""
    if not keys or keys[0] not in _PLAIN[""]:
        return False
    if keys[0] in ("lqr", "subsystems"):
        return len(keys) > 2 and keys[2] in _PLAIN[f"{keys[0]}.*"]
    if keys[0] in _PLAIN:
        return len(keys) > 1 and keys[1] in _PLAIN[keys[0]]
    return True


def _dumped(value):
    return value.model_dump(mode="json") if hasattr(value, "model_dump") else value


_REQUIRED = object()


@lru_cache(maxsize=256)
def _default_of(model: type, key: str):
    """A schema field's default, dumped (``_REQUIRED`` if it has none); pydantic's lookup is slow."""
    field_info = model.model_fields[key]
    if field_info.is_required():
        return _REQUIRED
    return _dumped(field_info.get_default(call_default_factory=True))


def _plain(value):
    """numpy scalars as Python numbers (the strict config schema takes float, not float64)."""
    if isinstance(value, np.generic):
        return value.item()
    return value


def _failed(head: dict, status: str, reason: str) -> dict:
    row = dict(head)
    row.update({"stable": None, "eig.fastest": None, "eig.slowest": None, "status": status,
                "dt": None, "steps": 0, "reason": reason})
    return row


def _row(head: dict, stable: bool, core_eigs, plan, summary: dict | None, steps: int, reason: str = "") -> dict:
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
    return row


def _weights_block(cfg) -> tuple[np.ndarray, np.ndarray, list[str], dict]:
    """(Q_block (12, 12), R_block (4, 4), regulated states, {subsystem: (Q, R)}) from the config."""
    from quadctl import pipeline

    regulated = [s for states in (v[2] for v in _block_index(cfg).values()) for s in states]
    Q, R = pipeline.weights_block(cfg)
    return Q, R, regulated, pipeline.weights_of(cfg)


def _block_index(cfg) -> dict:
    """Regulated subsystem -> (state indices, input indices, state names); cached per partition."""
    return _block_index_cached(_partition_key(cfg))


def _partition_key(cfg) -> tuple:
    return tuple((name, tuple(sub.states), tuple(sub.inputs))
                 for name, sub in cfg.partition().items() if sub.regulate)


@lru_cache(maxsize=64)
def _block_index_cached(key) -> dict:
    return {name: (np.array([STATE_INDEX[s] for s in states]), np.array([INPUT_INDEX[i] for i in inputs]),
                   list(states)) for name, states, inputs in key}


@lru_cache(maxsize=64)
def _pattern_cached(key) -> tuple[bool, ...]:
    mask = np.zeros((N_INPUTS, N_STATES), dtype=bool)
    for si, ii, _ in _block_index_cached(key).values():
        mask[np.ix_(ii, si)] = True
    return tuple(bool(v) for v in mask.ravel(order="F"))


def _core_eigenvalues(A_cl, K) -> tuple[np.ndarray, bool]:
    """Eigenvalues of the coupled closed loop without its marginal position modes, and stability.

    As :func:`quadctl.lqr.closed_loop_stability` decides it.
    """
    from quadctl.analysis import is_stable
    from quadctl.lqr import closed_loop_stability

    _, marginal, stable = closed_loop_stability(A_cl, K)
    keep = [i for i, s in enumerate(STATE_NAMES) if s not in marginal]
    core = np.linalg.eigvals(np.asarray(A_cl)[np.ix_(keep, keep)])
    return core, bool(stable and all(is_stable(e) for e in core))


def _evaluate_one(prep: _Prepared, stats: dict, trace: tuple = ()) -> tuple[dict, np.ndarray | None]:
    """One case through the pipeline, as ``quadctl simulate`` runs it (the reference path).

    Returns the row and, when ``trace`` names states and the run reached its end, their
    deviations resampled by :func:`resample_deviation` (else None).
    """
    from quadctl import metrics, pipeline

    cfg, linear = prep.cfg, prep.linear
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        des = pipeline.design_of(cfg, prep.decoupled, linear)
        stats["design_time"] += time.perf_counter() - t0
        stats["design_cpu"] += time.process_time() - c0
        stats["designs"] += len(prep.decoupled.regulated)
    except DesignError as exc:
        return _failed(prep.head, "design_failed", str(exc)), None
    A_cl = linear.A - linear.B @ des.K_block
    core, stable = _core_eigenvalues(A_cl, des.K_block)
    loop = pipeline.loop_of(cfg, linear, des, prep.rate)  # the integrators of an LQI design too
    try:
        t0 = time.perf_counter()
        sim = pipeline.simulation_of(cfg, loop)
        stats["simulate_time"] += time.perf_counter() - t0
    except StepSizeError as exc:
        row = _row(prep.head, stable, core, None, None, 0, str(exc))
        row["status"] = "step_refused"
        return row, None
    stats["backend"].add(sim.backend)
    stats["steps"] += sim.steps
    Q, R, regulated, _ = _weights_block(cfg)
    summary = metrics.summarize(sim, linear.u_trim, Q, R, regulated)
    row = _row(prep.head, stable, core, sim.plan, summary, sim.steps,
               "" if sim.status == "ok" else sim.message)
    kept = None
    if trace and sim.status == "ok":
        kept = resample_deviation(sim.t, sim.x, sim.x_ref, trace, cfg.simulation.duration)
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


def _evaluate_batched(preps: list[_Prepared], stats: dict) -> dict[int, dict]:
    """Cases of plain configs, designed and simulated together."""
    from quadctl import batch, batch_codegen, pipeline
    from quadctl.lqr import lqr
    from quadctl.simulate import RUNAWAY, VALID_PITCH, _verdict, max_stable_steps, plan_step, record_stride

    rows: dict[int, dict] = {}
    # 1. LQR of every regulated subsystem of every case, batched by shape
    weights = [_weights_block(prep.cfg) for prep in preps]
    # the design stage: stacking, batched solves, one-by-one fallbacks (wall and CPU time)
    t0, c0 = time.perf_counter(), time.process_time()
    problems = []  # (case position, subsystem, Q, R)
    for k, prep in enumerate(preps):
        for sub in prep.decoupled.regulated:
            problems.append((k, sub, *weights[k][3][sub.name]))
    gains: dict[tuple[int, str], np.ndarray] = {}
    failed: dict[int, str] = {}
    by_shape: dict[tuple[int, int], list] = {}
    for item in problems:
        by_shape.setdefault(item[1].B.shape, []).append(item)
    for group in by_shape.values():
        res = batch.care(np.stack([g[1].A for g in group]), np.stack([g[1].B for g in group]),
                         np.stack([g[2] for g in group]), np.stack([g[3] for g in group]))
        for j, (k, sub, Q, R) in enumerate(group):
            if res.ok[j]:
                gains[(k, sub.name)] = res.K[j]
                continue
            stats["fallbacks"] += 1  # the one-case solver decides, and says why
            try:
                gains[(k, sub.name)] = lqr(sub.A, sub.B, Q, R, name=f"subsystem {sub.name}",
                                           state_names=sub.states).K
            except DesignError as exc:
                failed.setdefault(k, str(exc))
    stats["designs"] += len(problems)
    stats["design_time"] += time.perf_counter() - t0
    stats["design_cpu"] += time.process_time() - c0
    # 2. block gains, coupled eigenvalues, step plans
    live = []
    for k, prep in enumerate(preps):
        if k in failed:
            rows[prep.index] = _failed(prep.head, "design_failed", failed[k])
            continue
        K = np.zeros((N_INPUTS, N_STATES))
        index = _block_index(prep.cfg)
        for sub in prep.decoupled.regulated:
            si, ii, _ = index[sub.name]
            K.flat[(ii[:, None] * N_STATES + si).ravel()] = gains[(k, sub.name)].ravel()
        live.append((k, prep, K))
    if not live:
        return rows
    A_cl = np.stack([prep.linear.A - prep.linear.B @ K for _, prep, K in live])
    eigs, vecs = np.linalg.eig(A_cl)
    limits = max_stable_steps(eigs)
    cores, stables = batch.coupled_stability(A_cl, np.stack([K for _, _, K in live]))
    largest = np.argmax(np.abs(vecs), axis=1).tolist()  # each mode's largest state (eigen_owners)
    jobs = []
    for j, (k, prep, K) in enumerate(live):
        cfg = prep.cfg
        owner_of = pipeline.state_owner(cfg)
        owners = [owner_of.get(STATE_NAMES[i], "unassigned") for i in largest[j]]
        core, stable = cores[j], bool(stables[j])
        sim_cfg = cfg.simulation
        try:
            plan = plan_step(eigs[j], owners, sim_cfg.duration, sim_cfg.dt, limits=limits[j])
        except StepSizeError as exc:
            row = _row(prep.head, stable, core, None, None, 0, str(exc))
            row["status"] = "step_refused"
            rows[prep.index] = row
            continue
        x_trim, rate = prep.linear.x_trim, prep.rate
        bound = np.array([RUNAWAY[s] for s in STATE_NAMES])
        lo, hi = x_trim - bound, x_trim + bound
        theta = STATE_INDEX["theta"]
        lo[theta], hi[theta] = -VALID_PITCH, VALID_PITCH
        drift = np.abs(rate) * sim_cfg.duration
        lo, hi = lo - drift, hi + drift
        c = batch_codegen.pack_lane_constants(x_trim, rate, prep.linear.u_trim, K,
                                              pipeline.vehicle_of(cfg).vector())
        pattern = _pattern_of(cfg)
        jobs.append((pattern, prep, k, core, stable, plan, pipeline.initial_state(cfg, x_trim), c, lo, hi,
                     record_stride(plan.n_steps, sim_cfg.max_samples)))
    # 3. simulations, LANES at a time per gain pattern, metrics as each group lands
    by_pattern: dict[tuple, list] = {}
    for job in jobs:
        by_pattern.setdefault(job[0], []).append(job)
    for pattern, group in by_pattern.items():
        runner = batch_codegen.get_lanes(pattern)
        stats["backend"].add(runner.backend)
        t0 = time.perf_counter()
        results = runner.iter_run(np.stack([g[6] for g in group]), np.array([g[5].dt for g in group]),
                                  np.array([g[5].n_steps for g in group]), np.stack([g[7] for g in group]),
                                  np.array([g[10] for g in group]), np.stack([g[8] for g in group]),
                                  np.stack([g[9] for g in group]))
        for j, done, ks, xs, us in results:
            _, prep, k, core, stable, plan, _, _, lo, hi, _ = group[j]
            t = plan.dt * ks
            status, message = _verdict(xs, t, done, plan.n_steps, lo, hi)
            Qb, Rb, regulated, _ = weights[k]
            summary = batch.summarize_run(t, xs, us, (prep.linear.x_trim, prep.rate), prep.linear.u_trim,
                                          Qb, Rb, regulated, status)
            stats["steps"] += done
            rows[prep.index] = _row(prep.head, stable, core, plan, summary, done,
                                    "" if status == "ok" else message)
        stats["simulate_time"] += time.perf_counter() - t0
    return rows


def _pattern_of(cfg) -> tuple[bool, ...]:
    """:func:`structural_pattern` of a config's partition (cached per partition)."""
    return _pattern_cached(_partition_key(cfg))


def structural_pattern(decoupled) -> tuple[bool, ...]:
    """The block gain's sparsity (48 bools, column-major): regulated inputs x their subsystem's states."""
    mask = np.zeros((N_INPUTS, N_STATES), dtype=bool)
    for sub in decoupled.regulated:
        mask[np.ix_([INPUT_INDEX[i] for i in sub.inputs], sub.state_index)] = True
    return tuple(bool(v) for v in mask.ravel(order="F"))


