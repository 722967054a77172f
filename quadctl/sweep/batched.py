"""The batched path of a sweep chunk: designs, verdicts and lane simulations of many cases at once.

:func:`design_all` poses each distinct case's subsystem problems once and hands them to the design's
one engine (:mod:`quadctl.design.stacked`, which a single design runs as a stack of one): a case
whose solve misses its check goes through the one-case design, which names the reason.

:func:`quadctl.sweep.lane_jobs.loops_of` makes each designed case's job for the lanes;
:func:`simulate_all` and :func:`summarize_all` run the jobs in the SIMD lanes, grouped, by the
simulation's one stack builder: RK4's cases by :func:`quadctl.sim.stack.rk4_cases` (as
:func:`quadctl.sim.stack.stack_of` makes a stack of loops: each case's step, stride, bounds and rows,
the constants once per loop structure with each case's gains written in), ETDRK4's by
:func:`quadctl.sim.stack.stack_of` itself.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from quadctl import pipeline
from quadctl.design import stacked
from quadctl.design.discrete import LqrdWeightMap
from quadctl.errors import DesignError
from quadctl.metrics import Disturbance
from quadctl.sim.engine import LANES, runner
from quadctl.sim.lane_metrics import MetricSpec, case_values
from quadctl.sim.stack import rk4_cases, simulate_stack
from quadctl.sweep.lane_jobs import LaneJob

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


def _cases_of(group):
    """The one-segment :class:`~quadctl.sim.cases.Cases` of a group of ``(prep, design, job)`` of one
    lane spec (:func:`quadctl.sim.stack.rk4_cases`, as a stack of loops makes its own)."""

    js = [g[2] for g in group]
    exo = [(j.exo_first, j.exo, j.exo_period) for j in js] if js[0].spec.n_exo else None
    return rk4_cases([j.loop for j in js], [j.x0 for j in js], [j.plan for j in js], [(j.lo, j.hi) for j in js],
                     max_samples=[j.max_samples for j in js], exo=exo,
                     exo_period=[j.exo_period for j in js], shared=[j.shared for j in js])


def simulate_all(jobs):
    """Yield ``((prep, design, job), (done, t, xs, us), backend)``: the runs of
    :func:`~quadctl.sweep.lane_jobs.loops_of`'s jobs: RK4's (:class:`~quadctl.sweep.lane_jobs.LaneJob`)
    grouped by loop spec into the lanes' cases (:func:`quadctl.sim.stack.rk4_cases`), ETDRK4's
    (:class:`~quadctl.sweep.lane_jobs.ExponentialJob`) grouped by structure and simulation inputs and
    run by :func:`quadctl.sim.stack.simulate_stack`; ``t`` (s) the recorded times; a yielded ``job``
    carries the plan its run took. The arrays of a lane job's run are overwritten by the next (use
    them first)."""

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
    :func:`~quadctl.sweep.lane_jobs.loops_of`'s jobs summed in the lanes as it steps
    (:mod:`quadctl.sim.lane_metrics`), lanes grouped by loop spec and by what the sums need (the
    weights' sparsity, a reference and its legs);
    ``sums`` is None where the runner keeps records instead (CasADi's VM): then ``(done, t, xs, us)``."""

    by_spec: dict = {}
    specs: dict[tuple, MetricSpec] = {}  # what a metric spec depends on -> the spec, once a chunk
    for item in jobs:
        setup = item[0].setup
        ref = setup.reference
        legs = len(ref.legs) if ref is not None else 0
        tail = pipeline.noisy(setup) == Disturbance.NOISE  # the line through its errors' tails measures the noise
        key = (setup.regulated, (setup.Q_block != 0).tobytes(), (setup.R_block != 0).tobytes(), ref is not None, legs,
               tail)
        if key not in specs:
            specs[key] = MetricSpec.of(setup.regulated, setup.Q_block, setup.R_block, ref is not None, legs, tail)
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
