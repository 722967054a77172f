"""ETDRK4 for loops and stacks of them: each loop's linear part and graded schedule, the φ-functions of
every step computed on the stack of the loops' linear parts, and the stack of one a loop keeps.

:func:`exponential_plan` gives a loop's linear part and steps (from the loop alone; a sweep plans its
cases with it); :func:`exponential_stack` makes the :class:`~quadctl.sim.stack_run.Stack` of ETDRK4 runs (a
segment per step of each case's schedule; a gain schedule's continuous loop flown piece by piece on the loop
closed at the nearest schedule value, :func:`_linear_pieces`); :func:`kept_exponential_stack` is the stack of one
a loop keeps for its next run with the same settings. :func:`quadctl.sim.stack.stack_of` takes them for
``method="etdrk4"``.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from quadctl.design.gain_table import scheduling_value, scheduling_values
from quadctl.metrics import MAX_SAMPLES
from quadctl.sim.cases import Cases
from quadctl.sim.etdrk4_matrices import phi_constant_rows, phi_ladder, phi_pattern
from quadctl.sim.etdrk4_plan import Segment, plan_schedule, record_strides
from quadctl.sim.loop import ClosedLoop
from quadctl.sim.plan import StepPlan
from quadctl.sim.stack_run import Stack

SETUPS_KEPT = 4
"""ETDRK4 stacks of one a loop keeps (:func:`kept_exponential_stack`): one per run settings, the latest."""


def exponential_plan(loop: ClosedLoop, duration: float, dt="auto", *, tolerance: float | None = None,
                     reference=None, exo_period: float | None = None, linear_part=None,
                     max_stable_dt: float | None = None) -> tuple[np.ndarray, StepPlan]:
    """ETDRK4's linear part and steps for ``loop``: the closed loop's
    (:meth:`~quadctl.sim.loop.ClosedLoop.linear_part`) graded by its modes, steps dividing the exogenous period
    ``exo_period`` (s; None: no exogenous inputs); a sampled controller's plant
    (:meth:`~quadctl.sim.loop.ClosedLoop.plant_linear_part`) graded by the
    closed loop's modes, which move it, in segments that start on samples
    (:func:`quadctl.sim.etdrk4_plan.plan_schedule`). ``linear_part`` and RK4's ``max_stable_dt`` (which
    the plan reports), when the caller has them (a sweep computes them for many loops at once).

    Raises
    ------
    StepSizeError
        A given step a sampled controller's period does not hold whole, or a runaway plan.
    """

    kicks = tuple(reference.path.knots) if reference is not None else ()
    if loop.rate is not None:
        L, eig = loop.plant_linear_part(), np.asarray(loop.eigenvalues)
        owners = list(loop.owners) or ["loop"] * len(eig)
        plan = plan_schedule(eig, owners, duration, dt, tolerance=tolerance, period=1.0 / loop.rate,
                             forced=reference is not None, held=True, kicks=kicks)
        rk4 = loop.plan(duration, "auto")  # reported: RK4's limit on the plant between samples
        return L, replace(plan, max_stable_dt=rk4.max_stable_dt, fastest_eigenvalue=rk4.fastest_eigenvalue,
                          fastest_owner=rk4.fastest_owner)
    L = loop.linear_part() if linear_part is None else linear_part
    eig = np.linalg.eigvals(L)
    if loop.schedule is not None and loop.schedule_jacobians is not None:  # graded by every point's modes
        eig = np.concatenate([eig, np.linalg.eigvals(loop.point_linear_parts).ravel()])
    return L, plan_schedule(eig, ["loop"] * len(eig), duration, dt, tolerance=tolerance, period=exo_period,
                            forced=reference is not None, max_stable_dt=max_stable_dt, kicks=kicks)


def _linear_pieces(loop: ClosedLoop, plan: StepPlan, strides, reference) -> list[tuple]:
    """``(segment, stride, point)``: the plan's segments with their record strides, a continuous gain
    schedule's cut where the schedule value nearest the commanded one changes (``point``: its index; at
    records only, so records stay equally spaced), each flown on the loop closed there; ``point`` None:
    on the loop's own linear part (fixed gains, a sampled controller's plant, or no schedule_jacobians).

    A step's linear part may be any matrix (the nonlinear remainder carries the difference) without
    costing the method its order; the nearest point's keeps the remainder free of the fast modes that
    the gains move (the rate loops), so the steps the plan grades by stay stable along the schedule.
    """

    table = loop.schedule
    if table is None or loop.rate is not None or loop.schedule_jacobians is None:
        return [(seg, stride, None) for seg, stride in zip(plan.schedule, strides)]
    values = np.asarray(table.values, dtype=float)
    if reference is None:  # the law's reference is the trim (drifting in position): one value
        v = scheduling_value(table.variable, np.asarray(loop.x_trim, dtype=float), loop.schedule_heading)
        point = int(np.argmin(np.abs(values - v)))
        return [(seg, stride, point) for seg, stride in zip(plan.schedule, strides)]
    starts = [np.arange(seg.k0, seg.k0 + seg.n, stride) for seg, stride in zip(plan.schedule, strides)]
    t = np.concatenate([ks * seg.dt for ks, seg in zip(starts, plan.schedule)])  # where a piece may start
    v = scheduling_values(table.variable, reference.exact(t)[0], loop.schedule_heading)  # one mapped call
    nearest_all = np.argmin(np.abs(v[:, None] - values[None, :]), axis=1)
    bounds = np.cumsum([0, *map(len, starts)])
    pieces = []
    for i, (seg, stride, ks) in enumerate(zip(plan.schedule, strides, starts)):
        nearest = nearest_all[bounds[i]:bounds[i + 1]]
        cuts = [0, *np.flatnonzero(np.diff(nearest)) + 1]
        for a, b in zip(cuts, [*cuts[1:], len(ks)]):
            k_end = seg.k0 + seg.n if b == len(ks) else int(ks[b])
            pieces.append((Segment(seg.dt, k_end - int(ks[a]), int(ks[a])), stride, int(nearest[a])))
    return pieces


def exponential_stack(loops, x0s, duration: float, dt="auto", *, tolerance: float | None = None,
                      max_samples: int = MAX_SAMPLES, reference=None, exo_period: float | None = None,
                      noise: bool = False, wind: bool = False, planned=None) -> Stack:
    """The :class:`~quadctl.sim.stack_run.Stack` of ETDRK4 runs of ``loops`` of one structure from ``x0s``
    (``noise``, ``wind``: the runs have them; ``exo_period``: s of their exogenous rows, None: none; no rows drawn):
    each case its own linear part and graded schedule (:func:`exponential_plan`, or ``planned``),
    a segment a step, each segment's constants the loop's, then the φ-functions of its step and linear part. A
    sampled controller's segments start on its samples; a gain schedule's continuous loop flies each stretch on the
    loop closed at the schedule value nearest the commanded one (:func:`_linear_pieces`). The loops whose schedules
    start at one step share a φ ladder, computed on the stack of their linear parts (each matrix as its one-case run
    computes it, from that step up); the lanes step through their schedules together (segment ``i`` of every case
    per call)."""
    rate = loops[0].rate
    held = rate is not None
    period = 1.0 / rate if held else exo_period
    Ls, plans = zip(*(planned or [exponential_plan(loop, duration, dt, tolerance=tolerance, reference=reference,
                                                   exo_period=exo_period) for loop in loops]))
    strides = [record_strides(plan, max_samples) for plan in plans]
    pieces = [_linear_pieces(loop, plan, st, reference) for loop, plan, st in zip(loops, plans, strides)]
    points = [sorted({p for _, _, p in case if p is not None}) for case in pieces]
    parts = [loop.point_linear_parts[pts] if pts else np.asarray(L, dtype=float)[None]  # each case's linear parts
             for loop, L, pts in zip(loops, Ls, points)]
    rung: dict[float, list[int]] = {}
    for i, plan in enumerate(plans):
        rung.setdefault(min(seg.dt for seg in plan.schedule), []).append(i)
    blocks: list = [None] * len(loops)  # per case: {step: its parts' φ blocks}, and its first row in them
    patterns = []
    for members in rung.values():
        ladder = phi_ladder(np.concatenate([parts[i] for i in members]),
                            [seg.dt for i in members for seg in plans[i].schedule])
        rows = {h: phi_constant_rows(mats) for h, mats in ladder.items()}
        patterns.append(phi_pattern(ladder))
        for i, first in zip(members, np.cumsum([0, *(len(parts[i]) for i in members)])):
            blocks[i] = (rows, int(first))
    spec = loops[0].spec(noise, wind, reference is not None, method="etdrk4",
                         phi_pattern=tuple(bool(b) for b in np.array(patterns).any(axis=0)))
    S = max(map(len, pieces))
    bounds = [loop.bounds(duration, reference) for loop in loops]
    base = [loop.constants(period if held else None) for loop in loops]

    def block(i, seg, point):
        rows, first = blocks[i]
        return np.concatenate([base[i], rows[seg.dt][first + (0 if point is None else points[i].index(point))]])

    def per_piece(value, empty):  # a piece a case does not have: no steps, its last piece's constants
        return [[value(i, *pieces[i][k]) if k < len(pieces[i]) else empty(i, *pieces[i][-1])
                 for i in range(len(loops))] for k in range(S)]

    cases = Cases.graded([loop.initial_loop_state(x0) for loop, x0 in zip(loops, x0s)],
                         np.array(per_piece(lambda i, seg, _, point: block(i, seg, point),
                                            lambda i, seg, _, point: block(i, seg, point))),
                         per_piece(lambda i, seg, *_: seg.dt, lambda i, seg, *_: seg.dt),
                         per_piece(lambda i, seg, *_: seg.n, lambda *_: 0),
                         per_piece(lambda i, seg, stride, _: stride, lambda *_: 1),
                         per_piece(lambda i, seg, *_: seg.k0, lambda *_: 0),
                         np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds]),
                         hold=per_piece(lambda i, seg, *_: round(period / seg.dt) if held else 1, lambda *_: 1),
                         exo_period=exo_period if exo_period is not None else 1.0)
    return Stack(tuple(plans), tuple(st[-1] for st in strides), spec, cases)


def kept_exponential_stack(loop: ClosedLoop, duration: float, dt="auto", *, tolerance: float | None = None,
                           max_samples: int = MAX_SAMPLES, reference=None, exo_period: float | None = None,
                           noise: bool = False, wind: bool = False) -> Stack:
    """:func:`exponential_stack` of ``loop`` alone (from its trim: :meth:`~quadctl.sim.cases.Cases.starting`
    runs it from a state), kept with it (:attr:`~quadctl.sim.loop.ClosedLoop.kept`, the :data:`SETUPS_KEPT`
    latest settings): a second run with the same settings computes no plan, φ-functions or constants
    again (nor marshals them for the runner).

    A :class:`~quadctl.physics.reference_rows.FlownReference` counts as the same when it flies the same
    path object, with the same knots (``knots``) and parameters (its position range and, for a gain
    schedule, the pieces the plan is cut into are read from it).
    """
    key = (float(duration), dt if dt == "auto" else float(dt), tolerance, int(max_samples),
           exo_period, bool(noise), bool(wind),
           None if reference is None else (id(reference.path), tuple(reference.path.knots),
                                             np.asarray(reference.params).tobytes()))
    kept = loop.kept.setdefault("exponential_stacks", {})
    if key in kept:
        path, found = kept.pop(key)
        kept[key] = (path, found)  # the latest used last
        return found
    found = exponential_stack([loop], [loop.x_trim], duration, dt, tolerance=tolerance, max_samples=max_samples,
                              reference=reference, exo_period=exo_period, noise=noise, wind=wind)
    kept[key] = (None if reference is None else reference.path, found)  # the path held: its id stays its own
    while len(kept) > SETUPS_KEPT:
        kept.pop(next(iter(kept)))
    return found
