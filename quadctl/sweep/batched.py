"""The batched path of a sweep chunk: designs, verdicts and lane simulations of many cases at once.

:func:`design_all` poses each distinct case's subsystem problems once and hands them to the design's
one engine (:mod:`quadctl.design.stacked`, which a single design runs as a stack of one): a case
whose solve misses its check goes through the one-case design, which names the reason.

:func:`loops_of` makes each case's loop (:mod:`quadctl.pipeline`'s builders) and its job for the
lanes, by either integrator; what it adds to the one-case path is only what pays across cases: the
chunk's continuous closed-loop spectra and their RK4 limits computed at once, the per-plant caches
(Kalman filter, held step plan, lane spec and bounds per loop structure), the noise realizations
the cases of one seed share (:data:`REALIZATION_BYTES`), the reference rows of the cases that fly
one drawn together (:meth:`quadctl.sim.exogenous.ExoStream.samples_of`: their feedforward solved in
lockstep, each case's rows those it has alone), and the grouping. The step plan is the
loop's own (:meth:`quadctl.sim.loop.ClosedLoop.plan`; ETDRK4:
:func:`quadctl.sim.loop.exponential_plan`), and the runs are made by the simulation's one stack
builder: RK4's cases by :func:`quadctl.sim.stack.rk4_cases` (as :func:`quadctl.sim.stack.stack_of`
makes a stack of loops: each case's step, stride, bounds and rows, the constants once per loop
structure with each case's gains written in), ETDRK4's by :func:`quadctl.sim.stack.stack_of` itself.
:func:`simulate_all` and :func:`summarize_all` run them in the SIMD lanes.
"""
from __future__ import annotations

import pickle
from collections import OrderedDict
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from quadctl import pipeline
from quadctl.design import linear_loop, stacked
from quadctl.design.discrete import LqrdWeightMap
from quadctl.errors import DesignError, QuadctlError, StepSizeError
from quadctl.layout import INPUT_INDEX, N_INPUTS, N_STATES, STATE_INDEX, STATE_NAMES
from quadctl.physics.motors import check_trim
from quadctl.physics.noise import exogenous_period
from quadctl.pipeline import estimator_of
from quadctl.sim.engine import LANES, runner
from quadctl.sim.etdrk4_plan import rk4_limits
from quadctl.sim.exogenous import ExoStream
from quadctl.sim.lane_metrics import MetricSpec, case_values
from quadctl.sim.loop import ClosedLoop, exponential_plan
from quadctl.sim.plan import max_stable_steps
from quadctl.sim.stack import rk4_cases, simulate_stack

if TYPE_CHECKING:
    from quadctl.sim.builder import LoopSpec
    from quadctl.sim.plan import StepPlan

BATCHED = "batched"
"""``path`` of a row designed in the batched solve."""


@dataclass(frozen=True)
class CaseDesign:
    """What a row needs of a design: the gains, the coupled verdict, and which path made it."""

    K_block: np.ndarray
    Ki_block: np.ndarray
    integral_states: tuple[str, ...]
    stable: bool
    core: np.ndarray
    path: str
    Kv: np.ndarray | None = None
    """(4, 4) gain on the controller's rotor lag model (a design that includes the lag); else None."""
    extremes: tuple | None = None
    """(fastest, slowest): the least and the largest real part of ``core`` (None for an empty core),
    when computed with the stack's (else from ``core``: :meth:`eig_extremes`)."""

    def eig_extremes(self) -> tuple:
        """(fastest, slowest) of ``core`` (:func:`core_extremes`)."""
        return self.extremes if self.extremes is not None else core_extremes(self.core)


def core_extremes(core) -> tuple:
    """(fastest, slowest): the least and the largest real part of a loop's core eigenvalues, as
    floats (None, None for an empty core): a row's ``eig.fastest`` and ``eig.slowest``."""
    real = np.asarray(core).real
    return (float(real.min()), float(real.max())) if len(real) else (None, None)


@dataclass(frozen=True)
class LaneJob:
    """A case ready for the lanes: what the sweep knows of it (its loop, initial state, step plan,
    bounds and exogenous rows), for :func:`quadctl.sim.stack.rk4_cases` to make its lane of."""

    spec: LoopSpec
    plan: StepPlan
    loop: ClosedLoop
    x0: np.ndarray
    """The initial (rigid-body) state."""
    lo: np.ndarray
    hi: np.ndarray
    max_samples: int
    exo: np.ndarray | None
    exo_first: int
    exo_period: float
    shared: tuple
    """The cases of one key are one loop but for its gains, from one ``x0`` (their constants made once)."""


@dataclass(frozen=True)
class ExponentialJob:
    """A case ready for the exponential lanes (what the evaluation reads of a job: ``plan``, ``lo``,
    ``hi``, ``exo_period``)."""

    loop: ClosedLoop
    x0: np.ndarray
    plan: StepPlan
    lo: np.ndarray
    hi: np.ndarray
    exo_period: float
    group: tuple
    """The cases that can share lanes: structure, rate and simulation inputs (by value)."""
    linear_part: np.ndarray
    """ETDRK4's linear part of the loop (:func:`quadctl.sim.loop.exponential_plan`)."""


def design_all(preps, stats, any_order: bool = False, compiled: bool = False) -> list:
    """A :class:`CaseDesign` per case, or the one-line reason its design failed.

    The cases are grouped by loop (plant, integrators, design rate, lag); in each group every
    subsystem's weights are stacked once and made distinct by rows (no key per case), so cases whose
    problems are identical (an uncertainty study varies only the simulated vehicle) share one design
    and a subsystem problem several cases pose (one whose weights no case varies) is solved once.
    The distinct problems go to the design's engine as stacks
    (:func:`quadctl.design.stacked.solve_problems`), the block gains and coupled verdicts of each
    group are stacked too. A design that includes the rotors' lag is made by the one-case design
    (:func:`quadctl.design.design`, the same engine with one case): the engine solves lagged
    subsystems, but its coupled verdict is on the lagged loop with the gain on the lag states,
    which :func:`quadctl.design.linear_loop.stack` does not build for a stack (few sweeps design
    with the lag). ``any_order``: each design's ``core`` eigenvalues in any order
    (:func:`quadctl.linear.stability.verdict_stack`), for a caller that reads only their extremes;
    ``compiled``: the discrete designs' doubling steps in C (:func:`quadctl.design.riccati.dare_batch`),
    the same gains to round-off.
    """
    loops: dict[tuple, list[int]] = {}  # (plant, integrators, design sample time, lag) -> its cases
    integrators: dict[tuple, tuple] = {}  # (plant, integral config) by identity -> per subsystem its integrators
    for k, prep in enumerate(preps):
        setup, plant = prep.setup, prep.plant
        key = (id(plant), id(setup.integral))
        if key not in integrators:
            integrators[key] = (setup.integral, tuple(tuple(setup.integral.get(sub.name, ()))
                                                       for sub in plant.regulated))
        loops.setdefault((id(plant), integrators[key][1], setup.timing.design_sample_time,
                          setup.design_lag_time_constant), []).append(k)
    out: list = [None] * len(preps)
    blocks: list[tuple] = []  # per (loop, subsystem): its distinct problems, one stack
    pending = []
    for (_, ints, Ts, lag), cases in loops.items():
        plant = preps[cases[0]].plant
        slots, problems = _distinct_problems([preps[k].setup.weights for k in cases], plant.regulated)
        owners, case_of = _distinct_rows(slots)  # cases posing the same problems share one design
        stats["designs"] += len(owners) * len(plant.regulated)  # (a shared design counts for each case)
        if lag is not None:
            designs = [_one_by_one(preps[cases[i]], "one-by-one: the design includes the rotors' lag") for i in owners]
        else:
            pending.append((cases, plant, ints, Ts, owners, slots[owners], range(len(blocks), len(blocks) + len(ints))))
            blocks.extend((sub, Q, R, sub_ints, Ts) for sub, sub_ints, (Q, R) in zip(plant.regulated, ints, problems))
            designs = None
        for k, i in zip(cases, case_of):  # pending: the number of its owner's design, until solved
            out[k] = designs[i] if designs is not None else i
    plants = {id(plant): plant for _, plant, *_ in pending}
    found = stacked.solve_problems(blocks, weight_map=_weight_maps(plants.values()), compiled=compiled)
    for cases, plant, ints, Ts, owners, owner_slots, numbers in pending:
        solved = np.all([found[b][1][owner_slots[:, s]] for s, b in enumerate(numbers)], axis=0)
        designs = [None] * len(owners)
        for i in np.flatnonzero(~solved).tolist():
            stats["fallbacks"] += 1
            designs[i] = _one_by_one(preps[cases[owners[i]]])
        good = np.flatnonzero(solved)
        if len(good):
            K, Ki, states = stacked.block_gains(plant.regulated, ints, [found[b][0][owner_slots[good, s]]
                                                                       for s, b in enumerate(numbers)])
            A, B = (plant.linear.A, plant.linear.B) if Ts is None else plant.sampled(Ts)
            verdicts = stacked.coupled_verdicts(A, B, K, Ki, states, Ts, any_order=any_order)
            extremes = _extremes([core for core, _, _ in verdicts])
            for j, (i, (core, _, stable)) in enumerate(zip(good.tolist(), verdicts)):
                designs[i] = CaseDesign(K[j], Ki[j], states, stable, core, BATCHED, extremes=extremes[j])
        for k in cases:
            out[k] = designs[out[k]]
    return out


def _distinct_problems(weights: list[dict], regulated) -> tuple[np.ndarray, list[tuple]]:
    """The distinct weights each subsystem is designed with over cases of one loop: (slots (cases,
    subsystems): each case's problem in each subsystem's stack, per subsystem (Q, R) stacked once
    each). A subsystem whose weights no case varies is one problem."""
    N = len(weights)
    slots = np.zeros((N, len(regulated)), dtype=int)
    problems = []
    for s, sub in enumerate(regulated):
        pairs = [w[sub.name] for w in weights]
        Q0, R0 = pairs[0]
        if all(Q is Q0 and R is R0 for Q, R in pairs):  # the base's own arrays: one problem
            problems.append((Q0[None], R0[None]))
            continue
        Q, R = np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs])
        first, slots[:, s] = _distinct_rows(np.concatenate([Q.reshape(N, -1), R.reshape(N, -1)], axis=1))
        problems.append((Q[first], R[first]))
    return slots, problems


def _distinct_rows(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the first row of each distinct value of ``M``'s rows, in order of first appearance; each
    row's distinct value's number). Rows are told apart by their bytes, in a dict (``np.unique``
    with ``axis=0`` sorts them, at several times the cost); a ``-0.0`` beside a ``0.0`` makes two
    problems, solved alike. The solves are each problem's own, so their order changes no number."""
    if len(M) == 1:
        return np.zeros(1, dtype=int), np.zeros(1, dtype=int)
    rows = np.ascontiguousarray(M)
    if rows.shape[1] == 0:
        return np.zeros(1, dtype=int), np.zeros(len(rows), dtype=int)
    index: dict = {}
    inverse = np.array([index.setdefault(row, len(index)) for row in
                        rows.view(np.dtype((np.void, rows.shape[1] * rows.itemsize))).ravel().tolist()], dtype=int)
    first = np.full(len(index), len(inverse), dtype=int)
    np.minimum.at(first, inverse, np.arange(len(inverse)))
    return first, inverse


def _weight_maps(plants):
    """``weight_map(sub, Ts)`` for :func:`quadctl.design.stacked.solve_problems`: the
    :class:`~quadctl.design.discrete.LqrdWeightMap` of a subsystem's plant at ``Ts``, kept in its
    plant's cache (the plants of a sweep live across its chunks)."""

    cache_of = {id(sub): plant.cache for plant in plants for sub in plant.regulated}

    def weight_map(sub, Ts):
        cache = cache_of[id(sub)]
        key = ("lqrd map", sub.name, Ts)
        if key not in cache:
            cache[key] = LqrdWeightMap(sub.A, sub.B, Ts)
        return cache[key]
    return weight_map


def _one_by_one(prep, why: str = "one-by-one: the batched Riccati solve missed its residual or stability check"):
    """The one-case design of a case the batched solve does not make: its verdict, or why it failed."""

    try:
        des = pipeline.design_of(prep.setup, prep.plant.decoupled, prep.plant.linear)
    except DesignError as exc:
        return str(exc)
    return CaseDesign(des.K_block, des.Ki_block, des.integral_states, des.stable, des.core_eigenvalues, why,
                      Kv=des.Kv_block if des.lag_time_constant is not None else None)


def _extremes(cores: list) -> list:
    """:func:`core_extremes` of each core, the stack at once (cores of one length; else each alone)."""
    if not cores or len({len(core) for core in cores}) != 1:
        return [core_extremes(core) for core in cores]
    if len(cores[0]) == 0:
        return [(None, None)] * len(cores)
    real = np.array(cores).real
    return list(zip(real.min(axis=1).tolist(), real.max(axis=1).tolist()))


def loops_of(live, method: str = "rk4") -> list:
    """Per (prep, design): its job for the lanes (RK4: a :class:`LaneJob`; ETDRK4 (``method``
    ``etdrk4``): an :class:`ExponentialJob`), a refused step's message, or a QuadctlError."""

    if method == "etdrk4":
        return _exponential_jobs(live)
    out: list = [None] * len(live)
    seen = _Seen()
    continuous = [j for j, (prep, des) in enumerate(live) if prep.setup.timing.rate is None and des.Kv is None]
    eig_of: dict[int, tuple] = {}
    by_plant: dict[tuple, list] = {}
    for j in continuous:
        prep, des = live[j]
        by_plant.setdefault((id(prep.plant), des.integral_states), []).append(j)
    for (_, states), members in by_plant.items():
        plant = live[members[0]][0].plant
        A_cl = linear_loop.stack(plant.linear.A, plant.linear.B, np.stack([live[j][1].K_block for j in members]),
                                 np.stack([live[j][1].Ki_block for j in members]), states)
        eigs, vecs = np.linalg.eig(A_cl)
        limits = max_stable_steps(eigs)
        largest = np.argmax(np.abs(vecs), axis=1)
        names = (*STATE_NAMES, *states)
        for i, j in enumerate(members):
            owner_of = live[j][0].setup.state_owner
            eig_of[j] = (eigs[i], [owner_of.get(names[r], "unassigned") for r in largest[i]], limits[i])
    trims: dict[tuple, QuadctlError | None] = {}  # (actuators, u_trim) by identity -> check_trim's verdict
    flying: list[tuple] = []  # (case, its ExoStream, its rows' span) of the cases that fly a reference
    starts: dict[tuple, tuple] = {}  # (initial offset, x_trim) by identity -> the initial state, its bytes
    for j, (prep, des) in enumerate(live):
        setup, linear = prep.setup, prep.plant.linear
        trim_key = (id(setup.actuators), id(linear.u_trim))  # the objects live as long as live does
        if trim_key not in trims:
            try:
                check_trim(setup.actuators, linear.u_trim)
                trims[trim_key] = None
            except QuadctlError as exc:
                trims[trim_key] = exc
        if trims[trim_key] is not None:
            out[j] = trims[trim_key]
            continue
        try:
            kalman = _estimator(prep)
        except QuadctlError as exc:
            out[j] = exc
            continue
        eig, owners, limits = eig_of.get(j, (np.zeros(0, complex), [], None))  # held: the plan needs none
        if setup.law == "pid":  # controller.flies: pid: the case's cascade flies (its values), not the design
            try:
                loop = pipeline.pid_loop_of(setup, linear)
            except QuadctlError as exc:
                out[j] = exc
                continue
        elif des.Kv is not None:  # a design with the rotors' lag: the loop (and its lag model) as simulate builds it
            loop = pipeline.closed_loop_of(setup, linear, des.K_block, Ki=des.Ki_block,
                                           integral_states=des.integral_states, Kv=des.Kv, estimator=kalman)
        else:
            loop = pipeline.simulated_loop(setup, linear, des.K_block, Ki=des.Ki_block,
                                           integral_states=des.integral_states, estimator=kalman,
                                           eigenvalues=eig, owners=owners, params=seen.params(setup.plant),
                                           open_loop_eigenvalues=prep.plant.open_loop_eigenvalues())
        try:
            if loop.rate is not None:  # the open-loop plant's (and rotors'): the same for every case of a plant
                key = ("held plan", loop.rate, setup.duration, setup.dt, loop.rotor_time_constant)
                if key not in prep.plant.cache:
                    prep.plant.cache[key] = loop.plan(setup.duration, setup.dt)
                plan = prep.plant.cache[key]
            else:  # the chunk's limits of the design's eigenvalues, when the loop flies them
                plan = loop.plan(setup.duration, setup.dt, limits=limits if loop.eigenvalues is eig else None)
        except StepSizeError as exc:
            out[j] = str(exc)
            continue
        noisy, windy = setup.noise is not None, setup.wind is not None
        # a reference: one more exogenous input, as simulate takes it (none: not asked of the setup, whose
        # cached property costs a lock per case)
        flown = setup.flown_reference if setup.reference is not None else None
        shape, held = _structure(loop, (noisy, windy, setup.duration, id(setup.reference)), seen)
        if shape not in prep.plant.cache:  # the loop's structure and bounds: once per shape of loop
            lane_spec = loop.spec(noisy, windy, flown is not None)
            if not lane_spec.law:  # an LQR gain's structural zeros (a cascade has no gain)
                lane_spec = replace(lane_spec, pattern=_structural_gain(prep))
            prep.plant.cache[shape] = (lane_spec, *loop.bounds(setup.duration, flown), [*held, setup.reference])
        spec, lo, hi, _ = prep.plant.cache[shape]
        exo, first, period = None, 0, 1.0
        exo_rate = loop.rate if loop.law is not None else setup.timing.rate  # simulate's clock: the loop's
        if setup.noise is not None or setup.wind is not None or flown is not None:  # simulate's rows, at once
            key = None
            if setup.wind is None and flown is None:
                noise = setup.noise
                key = (noise.seed, noise.process_std.tobytes(), noise.sensor_std.tobytes(), noise.period,
                       exo_rate, plan.n_steps, plan.dt)
            if key is not None and key in _realized:
                _realized.move_to_end(key)
                first, exo, period = _realized[key]
            else:
                stream = ExoStream(setup.noise, setup.wind, exo_rate, flown)
                period = stream.period
                if flown is not None:  # drawn below with the chunk's other references (one feedforward solve)
                    # through the final step's row (the lanes measure the final record against the
                    # reference there, as simulate's x_ref does)
                    flying.append((j, stream, stream.span(0, plan.n_steps + 1, plan.dt)))
                else:
                    first, exo = stream.rows(0, plan.n_steps, plan.dt)
                    if key is not None:
                        _keep_realization(key, (first, exo, period))
        start_key = (id(setup.initial_offset), id(linear.x_trim))
        if start_key not in starts:
            start = setup.initial_state(linear.x_trim)
            starts[start_key] = (start, start.tobytes())
        start, start_bytes = starts[start_key]
        out[j] = LaneJob(spec, plan, loop, start, lo, hi, setup.max_samples, exo, first, period,
                         shared=(shape, start_bytes))
    drawn = ExoStream.samples_of([stream for _, stream, _ in flying], [span for *_, span in flying])
    for (j, _, (first, _)), got in zip(flying, drawn):  # a refused reference: that case's error alone
        out[j] = got if isinstance(got, QuadctlError) else replace(out[j], exo=got, exo_first=first)
    return out


def _exponential_jobs(live) -> list:
    """:func:`loops_of` for ETDRK4: per (prep, design) an :class:`ExponentialJob`, a refused step's
    message, or a QuadctlError."""

    out: list = []
    loops: list = []
    for prep, des in live:
        setup, linear = prep.setup, prep.plant.linear
        try:
            check_trim(setup.actuators, linear.u_trim)
            loops.append(pipeline.closed_loop_of(setup, linear, des.K_block, Ki=des.Ki_block,
                                                 integral_states=des.integral_states, Kv=des.Kv,
                                                 estimator=_estimator(prep)))
        except QuadctlError as exc:
            loops.append(exc)
    # the linear parts, and RK4's limit each plan reports, of all the continuous loops at once
    parts, limits = {}, {}
    shapes: dict = {}
    for k, loop in enumerate(loops):
        if not isinstance(loop, QuadctlError) and loop.rate is None:
            parts[k] = loop.linear_part()
            shapes.setdefault(parts[k].shape, []).append(k)
    for members in shapes.values():
        eig = np.linalg.eigvals(np.stack([parts[k] for k in members]))
        limits.update(zip(members, rk4_limits(eig)))
    for k, ((prep, _), loop) in enumerate(zip(live, loops)):
        setup, linear = prep.setup, prep.plant.linear
        if isinstance(loop, QuadctlError):
            out.append(loop)
            continue
        noise = setup.noise if setup.noise is not None and setup.noise.active else None
        wind = setup.wind if setup.wind is not None and setup.wind.active else None
        flown = setup.flown_reference
        exogenous = noise is not None or wind is not None or flown is not None
        period = exogenous_period(noise.period if noise is not None else None, loop.rate)
        try:
            L, plan = exponential_plan(loop, setup.duration, setup.dt, reference=flown,
                                       exo_period=period if exogenous else None, linear_part=parts.get(k),
                                       max_stable_dt=limits.get(k), tolerance=setup.tolerance)
        except StepSizeError as exc:
            out.append(str(exc))
            continue
        lo, hi = loop.bounds(setup.duration, flown)
        inputs = pickle.dumps((noise, wind, setup.reference, flown.params.tobytes() if flown else None))
        group = (loop.spec(), loop.rate, setup.duration, setup.dt, setup.tolerance, setup.max_samples, inputs)
        out.append(ExponentialJob(loop, setup.initial_state(linear.x_trim), plan, lo, hi, period, group, L))
    return out


REALIZATION_BYTES = 32 * 2**20
"""Bytes of noise realizations a process keeps (:func:`loops_of`), the last used: the cases of a sweep
that draw one seed, in every chunk, share its exogenous rows (a 2 s run at 200 Hz: 58 kB, ~0.1 ms
to draw)."""
_realized: OrderedDict[tuple, tuple] = OrderedDict()
"""Every value the rows depend on (the noise spec's, the rate, the steps) -> (first, rows, period)."""


def _keep_realization(key: tuple, rows: tuple) -> None:
    """Keep a realization (not one larger than the whole budget), dropping the least recently used."""
    if rows[1].nbytes > REALIZATION_BYTES:
        return
    _realized[key] = rows
    total = sum(kept[1].nbytes for kept in _realized.values())
    while total > REALIZATION_BYTES:
        total -= _realized.popitem(last=False)[1][1].nbytes


PER_CASE = ("K", "Ki", "Kv", "eigenvalues", "owners", "jacobians")
"""Fields of a :class:`~quadctl.sim.loop.ClosedLoop` whose values its lane spec and bounds do not read
(only whether they are there; the gain's sparsity is the partition's: :func:`_structural_gain`;
``jacobians``, ETDRK4's linear part, only through each lane's own φ matrices: :func:`loops_of`'s ETDRK4 jobs)."""


class _Seen:
    """What :func:`loops_of` derives once per object in a chunk (the cases of a chunk share their
    trim, vehicle and actuators): each array's value key, each vehicle's parameter vector. Holds the
    objects, so an identity stays theirs while it is a key."""

    def __init__(self):
        self.arrays: dict[int, tuple] = {}
        self.vehicles: dict[int, tuple] = {}
        self.structures: dict[tuple, tuple] = {}
        """The field objects' identities -> (the objects, the key's parts, the unhashable objects)."""

    def array_key(self, value: np.ndarray) -> tuple:
        if id(value) not in self.arrays:
            self.arrays[id(value)] = (value, (value.dtype.str, value.shape, value.tobytes()))
        return self.arrays[id(value)][1]

    def params(self, vehicle) -> np.ndarray:
        """``vehicle.vector()``, one array per vehicle (so its key is derived once)."""
        if id(vehicle) not in self.vehicles:
            self.vehicles[id(vehicle)] = (vehicle, vehicle.vector())
        return self.vehicles[id(vehicle)][1]


def _structure(loop, extra: tuple, seen: _Seen) -> tuple[tuple, list]:
    """What a loop's lane spec and bounds depend on: ``extra`` and every field of the loop but the
    values of the gains and the spectrum (a field added to ``ClosedLoop`` is part of the key without
    a change here); arrays by value, other unhashable objects (the actuators) by identity, returned
    to be kept alive with the cached entry (an identity is unique only while its object lives).
    Derived once per set of field objects (:attr:`_Seen.structures`: the cases of a chunk share them)."""
    shared, per_case = _loop_getters()
    values = shared(loop)
    ids = (*map(id, values), *(v is None for v in per_case(loop)))
    if ids not in seen.structures:
        parts, held = [], []
        for value in values:
            if isinstance(value, np.ndarray):
                parts.append(seen.array_key(value))
                continue
            try:
                hash(value)
                parts.append(value)
            except TypeError:
                parts.append(("id", id(value)))
                held.append(value)
        seen.structures[ids] = (values, (*parts, *ids[len(values):]), held)  # values: the ids stay theirs
    _, parts, held = seen.structures[ids]
    return ("structure", *extra, *parts), held


@lru_cache(maxsize=1)
def _loop_getters():
    """(the fields of a loop its lane spec reads the values of, those of :data:`PER_CASE`), as getters
    of a tuple."""
    from operator import attrgetter

    names = _loop_fields()
    return (attrgetter(*(n for n in names if n not in PER_CASE)), attrgetter(*(n for n in names if n in PER_CASE)))


@lru_cache(maxsize=1)
def _loop_fields() -> tuple[str, ...]:
    from dataclasses import fields


    return tuple(f.name for f in fields(ClosedLoop))


def _estimator(prep):
    """The case's Kalman filter (:func:`quadctl.pipeline.estimator_of`), once per plant and filter config."""
    est, timing = prep.setup.estimator, prep.setup.timing
    if est is None:
        return None
    key = ("estimator", est.measured, tuple(est.sensor_std), tuple(est.process_std), est.period, timing.sample_time,
           prep.setup.rate_filter)
    if key not in prep.plant.cache:

        prep.plant.cache[key] = estimator_of(prep.setup, prep.plant.linear)
    return prep.plant.cache[key]


def _structural_gain(prep) -> tuple[bool, ...]:
    """The block gain's sparsity from the partition (48 bools, column-major): cases with a gain that
    happens to be zero share the lanes of their structure (a zero gain computes the same numbers)."""
    if "pattern" not in prep.plant.cache:
        mask = np.zeros((N_INPUTS, N_STATES), dtype=bool)
        for sub in prep.plant.regulated:
            mask[np.ix_([INPUT_INDEX[i] for i in sub.inputs], [STATE_INDEX[s] for s in sub.states])] = True
        prep.plant.cache["pattern"] = tuple(bool(v) for v in mask.ravel(order="F"))
    return prep.plant.cache["pattern"]


def _cases_of(group):
    """The one-segment :class:`~quadctl.sim.cases.Cases` of a group of ``(prep, design, job)`` of one
    lane spec (:func:`quadctl.sim.stack.rk4_cases`, as a stack of loops makes its own)."""

    js = [g[2] for g in group]
    exo = [(j.exo_first, j.exo, j.exo_period) for j in js] if js[0].spec.n_exo else None
    return rk4_cases([j.loop for j in js], [j.x0 for j in js], [j.plan for j in js], [(j.lo, j.hi) for j in js],
                     max_samples=[j.max_samples for j in js], exo=exo,
                     exo_period=[j.exo_period for j in js], shared=[j.shared for j in js])


def simulate_all(jobs):
    """Yield ``((prep, design, job), (done, t, xs, us), backend)``: the runs of :func:`loops_of`'s
    jobs: RK4's (:class:`LaneJob`) grouped by loop spec into the lanes' cases
    (:func:`quadctl.sim.stack.rk4_cases`), ETDRK4's (:class:`ExponentialJob`) grouped by structure and
    simulation inputs and run by :func:`quadctl.sim.stack.simulate_stack`; ``t`` (s) the recorded
    times; a yielded ``job`` carries the plan its run took. The arrays of a lane job's run are
    overwritten by the next (use them first)."""

    groups: dict = {}
    for item in jobs:
        job = item[2]
        groups.setdefault(job.spec if isinstance(job, LaneJob) else job.group, []).append(item)
    for group in groups.values():
        if isinstance(group[0][2], LaneJob):
            run = runner(group[0][2].spec, LANES)
            for i, done, t, xs, us in run.iter_run(_cases_of(group)):
                yield group[i], (done, t, xs, us), run.backend
            continue
        setup = group[0][0].setup
        plans, backend, runs = simulate_stack(
            [job.loop for _, _, job in group], [job.x0 for _, _, job in group], setup.duration, setup.dt,
            method="etdrk4", max_samples=setup.max_samples, reference=setup.flown_reference, noise=setup.noise,
            wind=setup.wind, planned=[(job.linear_part, job.plan) for _, _, job in group], tolerance=setup.tolerance)
        for (prep, des, job), plan, result in zip(group, plans, runs):
            yield (prep, des, replace(job, plan=plan)), result, backend


def summarize_all(jobs):
    """Yield ``((prep, design, job), (done, t_end, x_end, u_end, sums), backend)``: each run of
    :func:`loops_of`'s jobs summed in the lanes as it steps (:mod:`quadctl.sim.lane_metrics`), lanes
    grouped by loop spec and by what the sums need (the weights' sparsity, a reference and its legs);
    ``sums`` is None where the runner keeps records instead (CasADi's VM): then ``(done, t, xs, us)``."""

    by_spec: dict = {}
    specs: dict[tuple, MetricSpec] = {}  # what a metric spec depends on -> the spec, once a chunk
    for item in jobs:
        setup = item[0].setup
        ref = setup.reference
        legs = len(ref.legs) if ref is not None else 0
        key = (setup.regulated, (setup.Q_block != 0).tobytes(), (setup.R_block != 0).tobytes(), ref is not None, legs)
        if key not in specs:
            specs[key] = MetricSpec.of(setup.regulated, setup.Q_block, setup.R_block, ref is not None, legs)
        by_spec.setdefault((item[2].spec, specs[key]), []).append(item)
    for (spec, metrics), group in by_spec.items():
        run = runner(spec, LANES)
        cases = _cases_of(group)
        if not hasattr(run, "iter_summaries"):
            for i, done, t, xs, us in run.iter_run(cases):
                yield group[i], (done, t, xs, us, None), run.backend
            continue
        if metrics.legs:  # each case's tolerance and legs
            values = np.stack([case_values(metrics, prep.plant.linear.u_trim, prep.setup.Q_block, prep.setup.R_block,
                                           prep.setup.reference.tolerance, prep.setup.reference.legs)
                               for prep, _, _ in group])
        else:
            values = case_values(metrics, np.stack([prep.plant.linear.u_trim for prep, _, _ in group]),
                                 np.stack([prep.setup.Q_block for prep, _, _ in group]),
                                 np.stack([prep.setup.R_block for prep, _, _ in group]))
        for i, done, t_end, x_end, u_end, sums in run.iter_summaries(cases, metrics, values):
            yield group[i], (done, t_end, x_end, u_end, sums), run.backend
