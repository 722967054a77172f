"""Many runs at once: the one entry that runs a stack of cases by either integrator.

:func:`stack_of` makes the :class:`~quadctl.sim.cases.Cases` of the runs (RK4: a segment each, its step
from :mod:`quadctl.sim.plan`, :func:`rk4_cases`, which makes a sweep's lanes too from what the sweep
knows per case; ETDRK4: a segment per step of its schedule, :func:`exponential_stack`) and
:func:`run_stack` runs them; :func:`simulate_stack` is both for many loops in the SIMD lanes
(:func:`quadctl.sim.run.simulate` is the stack of one). A long run of one case goes in chunks so Ctrl-C
stops it at once, its exogenous rows drawn chunk by chunk (:class:`~quadctl.sim.exogenous.ExoStream`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from quadctl.design.gain_table import scheduling_value, scheduling_values
from quadctl.errors import ArgumentError, ArgumentTypeError
from quadctl.layout import N_STATES, STATE_NAMES
from quadctl.metrics import MAX_SAMPLES
from quadctl.physics.noise import NoiseSpec
from quadctl.physics.reference_rows import FlownReference
from quadctl.physics.wind import WindSpec
from quadctl.sim.cases import Cases
from quadctl.sim.engine import LANES, runner
from quadctl.sim.etdrk4_matrices import phi_constant_rows, phi_ladder, phi_pattern
from quadctl.sim.etdrk4_plan import Segment, record_strides
from quadctl.sim.exogenous import ExoStream
from quadctl.sim.loop import ClosedLoop, exponential_plan, gain_constants
from quadctl.sim.loop_layout import fill_constants_stack
from quadctl.sim.loop_spec import LoopSpec
from quadctl.sim.plan import StepPlan, record_stride


def _positive_seconds(value) -> bool:
    """Whether ``value`` is a finite positive number (not a bool, not text numpy would convert)."""
    return not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating)) \
        and 0.0 < float(value) < float("inf")


SETUPS_KEPT = 4
"""ETDRK4 stacks of one a loop keeps (:func:`kept_exponential_stack`): one per run settings, the latest."""


@dataclass(frozen=True)
class Stack:
    """``N`` runs of loops of one structure ready for a runner (:func:`stack_of`): each case's step plan
    and record stride (of its largest step), the loops' generated code (``spec``), the
    :class:`~quadctl.sim.cases.Cases` (RK4: a segment each; ETDRK4: a segment per step of its graded
    schedule), and the exogenous inputs they all take (drawn when the stack runs: :func:`run_stack`)."""

    plans: tuple
    strides: tuple
    spec: LoopSpec
    cases: Cases
    exo: ExoStream | None = None


def stack_of(loops, x0s, duration: float, dt="auto", *, method: str = "rk4", noise: NoiseSpec | None = None,
             wind: WindSpec | None = None, max_samples: int = MAX_SAMPLES, reference=None,
             tolerance: float | None = None, exo_rate: float | None = None, planned=None) -> Stack:
    """The :class:`Stack` of runs of ``loops`` from ``x0s`` (the arguments of :func:`~quadctl.sim.run.simulate`): one
    case is a stack of one (an ETDRK4 case from the setup its loop keeps,
    :func:`kept_exponential_stack`); more run in the SIMD lanes, each case stepping as its one-case
    run does (ETDRK4: the φ-functions of all the loops' linear parts computed on the stack of them).
    ``planned``: each loop's ``(L, StepPlan)`` of :func:`~quadctl.sim.loop.exponential_plan`, when the caller has them.

    Raises
    ------
    ArgumentTypeError
        A loop that is not a :class:`~quadctl.sim.loop.ClosedLoop`, or a ``noise``, ``wind`` or ``reference``
        not of its kind (a ``TypeError``).
    ArgumentError
        Loops of different structures or controller rates, an unknown method, a duration or a ``dt`` that
        is not a positive number of seconds, a ``max_samples`` below 2, a ``tolerance`` or ``exo_rate`` that is not
        a positive number, or an initial state that is not the loop's 12 finite real numbers.
    StepSizeError
        A step that a loop cannot take.
    """
    loops = list(loops)
    for loop in loops:
        if not isinstance(loop, ClosedLoop):
            raise ArgumentTypeError(f"simulate takes a ClosedLoop, stages.loop of qc.Stages(setup) "
                                    f"(or quadctl.pipeline.loop_of); got {type(loop).__name__}")
    if method not in ("rk4", "etdrk4"):
        raise ArgumentError(f"method must be 'rk4' or 'etdrk4', got {method!r}")
    if not _positive_seconds(duration):
        raise ArgumentError(f"duration must be a positive number of seconds, got {duration!r}")
    if not (isinstance(dt, str) and dt == "auto") and not _positive_seconds(dt):
        raise ArgumentError(f"dt must be a positive number of seconds or 'auto', got {dt!r}")
    for label, value, kind, configured in (("noise", noise, NoiseSpec, "noise"), ("wind", wind, WindSpec, "wind"),
                                           ("reference", reference, FlownReference, "flown_reference")):
        if value is not None and not isinstance(value, kind):  # an AttributeError from inside, otherwise
            raise ArgumentTypeError(f"simulate: {label} must be a {kind.__name__} (setup.{configured} is the "
                                    f"configured one) or None, got {type(value).__name__}")
    if tolerance is not None and not _positive_seconds(tolerance):  # a positive finite number, as seconds are
        raise ArgumentError(f"tolerance must be a positive number (the state error ETDRK4 aims at) or None, "
                            f"got {tolerance!r}")
    if exo_rate is not None and not _positive_seconds(exo_rate):
        raise ArgumentError(f"exo_rate must be a positive number of Hz or None, got {exo_rate!r}")
    if isinstance(max_samples, bool) or not isinstance(max_samples, (int, np.integer)) or max_samples < 2:
        raise ArgumentError(f"max_samples must be a whole number of at least 2 (the start and the end), "
                            f"got {max_samples!r}")
    for x0 in x0s:
        if np.shape(x0) != (N_STATES,):
            raise ArgumentError(f"x0 must be the {N_STATES} states {', '.join(STATE_NAMES)}, got shape "
                                f"{np.shape(x0)}")
        if np.asarray(x0).dtype.kind not in "biuf":
            raise ArgumentError(f"x0 must be {N_STATES} real numbers, got dtype {np.asarray(x0).dtype}")
        x = np.asarray(x0, dtype=float)
        if not np.isfinite(x).all():
            i = int(np.argmax(~np.isfinite(x)))
            raise ArgumentError(f"x0 must be finite: x0[{i}] ({STATE_NAMES[i]}) = {float(x[i])!r}; give every state "
                                "a number (setup.initial_state(loop.x_trim) is the configured start)")
    rate = loops[0].rate
    if len(loops) > 1:
        if len({loop.spec() for loop in loops}) > 1:
            raise ArgumentError("simulate_stack: the lanes run loops of one structure (LoopSpec): group the loops "
                                "by loop.spec()")
        if any(loop.rate != rate for loop in loops):
            raise ArgumentError("simulate_stack: the lanes run loops of one controller rate: group the loops by "
                                "loop.rate")
    noisy = noise is not None and noise.active
    windy = wind is not None and wind.active
    exo = (ExoStream(noise if noisy else None, wind if windy else None, exo_rate or rate, reference)
           if noisy or windy or reference is not None else None)
    exo_period = exo.period if exo is not None else None
    if method == "rk4":
        plans = [loop.plan(duration, dt) for loop in loops]
        cases = rk4_cases(loops, x0s, plans, [loop.bounds(duration, reference) for loop in loops],
                          max_samples=max_samples, exo_period=exo_period or 1.0)
        return Stack(tuple(plans), tuple(int(s) for s in cases.stride[0]),
                     loops[0].spec(noisy, windy, reference is not None), cases, exo)
    if len(loops) == 1 and planned is None:  # the loop's kept stack of one, from x0
        kept = kept_exponential_stack(loops[0], duration, dt, tolerance=tolerance, max_samples=max_samples,
                                      reference=reference, exo_period=exo_period, noise=noisy, wind=windy)
        return replace(kept, cases=kept.cases.starting(loops[0].initial_loop_state(x0s[0])), exo=exo)
    stack = exponential_stack(loops, x0s, duration, dt, tolerance=tolerance, max_samples=max_samples,
                              reference=reference, exo_period=exo_period, noise=noisy, wind=windy, planned=planned)
    return replace(stack, exo=exo)


def rk4_cases(loops, x0s, plans, bounds, *, max_samples=MAX_SAMPLES, exo=None, exo_period=1.0,
              shared=None) -> Cases:
    """The RK4 :class:`~quadctl.sim.cases.Cases` of ``loops`` (one lane spec) from ``x0s``, for
    :func:`stack_of` and a sweep's lanes alike: a segment each, of its ``plans`` step (its hold, its
    record stride for ``max_samples``, one value or one a case), between its ``bounds`` ``(lo, hi)``.

    ``exo``: per case ``(first, rows, period)``, its exogenous rows drawn (None: none given, the rows
    of ``exo_period`` drawn when the stack runs, :func:`run_stack`). ``shared``: per case a key; the
    cases of one key are one loop but for its gains (:meth:`~quadctl.sim.loop.ClosedLoop.gain_constants`) from one
    ``x0``: its constants and initial loop state are computed once, each case's gains written into a
    copy (:func:`quadctl.sim.loop_layout.fill_constants_stack`); None: each case's own.
    """
    N = len(loops)
    samples = np.broadcast_to(np.asarray(max_samples), (N,))
    strides = [record_stride(plan.n_steps, int(m)) for plan, m in zip(plans, samples)]
    keys = range(N) if shared is None else shared
    groups: dict = {}
    for i, (key, plan) in enumerate(zip(keys, plans)):
        groups.setdefault((key, plan.sample_time), []).append(i)
    C: list = [None] * N
    X0: list = [None] * N
    for members in groups.values():
        first = loops[members[0]]
        c = first.constants(plans[members[0]].sample_time)
        x = first.initial_loop_state(x0s[members[0]])
        if len(members) == 1:
            C[members[0]], X0[members[0]] = c, x
            continue
        rows = fill_constants_stack(np.repeat(c[None], len(members), axis=0), *first.constant_layout,
                                    **gain_constants([loops[i] for i in members]))
        for i, row in zip(members, rows):
            C[i], X0[i] = row, x
    rows = None if exo is None else [e[1] for e in exo]
    return Cases.of(np.stack(X0), np.stack(C), [plan.dt for plan in plans], [plan.n_steps for plan in plans],
                    strides, np.stack([b[0] for b in bounds]), np.stack([b[1] for b in bounds]),
                    hold=[max(plan.hold, 1) for plan in plans], exo=rows,
                    exo_first=0 if rows is None else [e[0] for e in exo],
                    exo_period=exo_period if rows is None else [e[2] for e in exo])


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
    """The :class:`Stack` of ETDRK4 runs of ``loops`` of one structure from ``x0s`` (``noise``, ``wind``:
    the runs have them; ``exo_period``: s of their exogenous rows, None: none; no rows drawn): each
    case its own linear part and graded schedule (:func:`~quadctl.sim.loop.exponential_plan`, or ``planned``), a segment
    a step, each segment's constants the loop's, then the φ-functions of its step and linear part. A
    sampled controller's segments start on its samples; a gain schedule's continuous loop flies each
    stretch on the loop closed at the schedule value nearest the commanded one (:func:`_linear_pieces`).
    The loops whose schedules start at one step share a φ ladder, computed on the stack of their linear
    parts (each matrix as its one-case run computes it, from that step up); the lanes step through their
    schedules together (segment ``i`` of every case per call)."""
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


CHUNK_STEPS = {"compiled": 250_000, "casadi": 20_000}
"""Steps per call into the runner, by backend (~5 M and ~0.2 M steps/s): 0.05 to 0.1 s each, so
Python sees Ctrl-C between calls at once."""


def run_stack(stack: Stack, run, progress=None) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """The runs of ``stack`` by ``run`` (a runner of its spec, :func:`quadctl.sim.engine.runner`): per case
    ``(done, t, xs, us)``, steps completed, recorded times (s), loop states (r, nx) and inputs (r, 4).

    The exogenous rows are drawn for the whole run at once; a case alone longer than the runner's
    chunk (:data:`CHUNK_STEPS`) runs in chunks instead (:func:`_in_chunks`: Ctrl-C between them, the
    rows drawn as it goes). ``progress(done, total)``, if given, is called with a case alone's steps
    done after each call.
    """
    cases, exo = stack.cases, stack.exo
    total = int(cases.n[:, 0].sum())
    if len(cases) == 1 and total > CHUNK_STEPS.get(run.backend, CHUNK_STEPS["compiled"]):
        return [_in_chunks(run, cases, exo, progress)]
    if exo is not None:
        taken = cases.n > 0  # the rows through the last step of any segment
        rows = exo.samples(0, int(exo.index((cases.k0 + cases.n - 1)[taken], cases.dt[taken]).max(initial=0)))
        cases = cases.starting(cases.x0, exo=[rows] * len(cases))
    out = run.run(cases)
    if progress is not None and len(cases) == 1:
        progress(out[0][0], total)
    return out


def _in_chunks(run, cases: Cases, exo: ExoStream | None, progress=None):
    """``(done, t, xs, us)`` of the one case of ``cases``: segment after segment, each in chunks of
    :data:`CHUNK_STEPS` (whole controller periods, each starting on a sample), a chunk's exogenous rows
    drawn before it; a chunk's final record is the next one's start (kept once)."""
    chunk = CHUNK_STEPS.get(run.backend, CHUNK_STEPS["compiled"])
    total, n_all, last = 0, int(cases.n[:, 0].sum()), int(cases.last[0])
    x = cases.x0[0]
    parts: tuple[list, list, list] = ([], [], [])
    for s in range(last + 1):
        dt, hold, stride = float(cases.dt[s, 0]), int(cases.hold[s, 0]), int(cases.stride[s, 0])
        k0, end = int(cases.k0[s, 0]), int(cases.k0[s, 0] + cases.n[s, 0])
        step = max(hold, chunk // hold * hold)
        while k0 < end:
            m = min(step, end - k0)
            rows, first = None, 0
            if exo is not None:
                first, row = exo.rows(k0, m, dt)
                rows = [row]
            piece = Cases.of(x, cases.c[s, 0], dt, m, stride, cases.lo, cases.hi, hold=hold, k0=k0, exo=rows,
                             exo_first=first, exo_period=cases.exo_period[0])
            (done, t, xs, us), = run.run(piece)
            total += done
            if progress is not None:
                progress(total, n_all)
            final = done < m or (k0 + m >= end and s == last)
            keep = len(t) if final else len(t) - 1
            for part, got in zip(parts, (t, xs, us)):
                part.append(got[:keep])
            if final:
                return total, *(np.concatenate(p) for p in parts)
            x = xs[-1]
            k0 += m
    return total, *(np.concatenate(p) for p in parts)


def simulate_stack(loops, x0s, duration: float, dt="auto", *, method: str = "rk4", noise: NoiseSpec | None = None,
                   wind: WindSpec | None = None, max_samples: int = MAX_SAMPLES, reference=None,
                   tolerance: float | None = None, exo_rate: float | None = None,
                   planned=None) -> tuple[list[StepPlan], str, list]:
    """Runs of several loops of one structure from ``x0s``, as :func:`~quadctl.sim.run.simulate` runs each
    (its arguments; the RK4 or ETDRK4 runs of :func:`stack_of`), in the SIMD lanes
    (:data:`quadctl.sim.engine.LANES` at a time; one case alone: the one-case loop). Every loop takes the
    same exogenous inputs: a ``reference`` (:class:`quadctl.physics.reference_rows.FlownReference`), noise and
    wind, tabulated once for the run.

    Returns
    -------
    (plans, backend, runs)
        Each loop's :class:`StepPlan`, the runner's backend, and per loop ``(done, t, xs, us)``: steps
        completed, recorded times (s), loop states (r, nx) and inputs (r, 4), as :func:`~quadctl.sim.run.simulate`
        records them.

    Raises
    ------
    ArgumentError
        Loops of different structures or controller rates.

    Examples
    --------
    Three designs of the hover loop (gains scaled) in the lanes: each as its own run.

    >>> import numpy as np, quadctl as qc
    >>> from dataclasses import replace
    >>> from quadctl.sim.stack import simulate_stack
    >>> loop = qc.Stages(qc.setup_of(qc.load_config("hover"))).loop
    >>> loops = [replace(loop, K=loop.K * k) for k in (0.8, 1.0, 1.2)]
    >>> plans, backend, runs = simulate_stack(loops, [loop.x_trim + 0.1] * 3, 0.5)
    >>> one = qc.simulate(loops[2], loop.x_trim + 0.1, 0.5)
    >>> bool(np.abs(runs[2][2][:, :12] - one.x).max() < 1e-12), len(runs)
    (True, 3)
    """

    stack = stack_of(loops, x0s, duration, dt, method=method, noise=noise, wind=wind, max_samples=max_samples,
                     reference=reference, tolerance=tolerance, exo_rate=exo_rate, planned=planned)
    run = runner(stack.spec, 1 if len(stack.cases) == 1 else LANES)
    return list(stack.plans), run.backend, run_stack(stack, run)
