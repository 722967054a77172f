"""A designed case made ready for the lanes: its loop (:mod:`quadctl.pipeline`'s builders), step
plan, bounds and exogenous rows, as a :class:`LaneJob` (RK4) or an :class:`ExponentialJob` (ETDRK4).

:func:`loops_of` adds to the one-case path only what pays across cases: the chunk's continuous
closed-loop spectra and their RK4 limits computed at once, the per-plant caches (Kalman filter, held
step plan, lane spec and bounds per loop structure), the noise realizations the cases of one seed
share (:data:`REALIZATION_BYTES`), and the reference rows of the cases that fly one drawn together
(:meth:`quadctl.sim.exogenous.ExoStream.samples_of`: their feedforward solved in lockstep, each case's
rows those it has alone). The step plan is the loop's own (:meth:`quadctl.sim.loop.ClosedLoop.plan`;
ETDRK4: :func:`quadctl.sim.etdrk4_stack.exponential_plan`). :mod:`quadctl.sweep.batched` designs the cases
before and runs the jobs after.
"""
from __future__ import annotations

import pickle
from collections import OrderedDict
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from quadctl import pipeline
from quadctl.design import linear_loop
from quadctl.errors import QuadctlError, StepSizeError
from quadctl.layout import INPUT_INDEX, N_INPUTS, N_STATES, STATE_INDEX, STATE_NAMES
from quadctl.physics.motors import check_trim
from quadctl.physics.noise import exogenous_period
from quadctl.pipeline import estimator_of
from quadctl.sim.etdrk4_plan import rk4_limits
from quadctl.sim.etdrk4_stack import exponential_plan
from quadctl.sim.exogenous import ExoStream
from quadctl.sim.loop import ClosedLoop
from quadctl.sim.plan import max_stable_steps

if TYPE_CHECKING:
    from quadctl.sim.loop_spec import LoopSpec
    from quadctl.sim.plan import StepPlan


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
    """ETDRK4's linear part of the loop (:func:`quadctl.sim.etdrk4_stack.exponential_plan`)."""


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
