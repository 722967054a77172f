"""The step schedule of the exponential integrator (ETDRK4, :mod:`quadctl.sim.builder`).

ETDRK4 integrates the loop's linearization at the reference ``L`` exactly (its matrix exponential),
so its step is not held to the fast loops' stability limit as RK4's is: what limits it is the
nonlinear remainder ``N = f - L X``, which varies on the time scale of the modes still excited.
A mode ``lambda`` that decays at ``sigma = -Re lambda`` from ``t = 0`` drives ``N`` with
derivatives of size ``|lambda|^k e^(-sigma t)``, so a fourth-order step ``h`` leaves an error
about ``(h |lambda|)^4 e^(-sigma t)`` of it. ``dt: auto`` keeps that below ``tolerance`` for
every mode:

    h(t) = SAFETY tolerance^(1/4) min_lambda e^(sigma t / 4) / |lambda|

(:data:`FREE_SAFETY` in place of :data:`SAFETY` for a free run: continuous feedback, no exogenous inputs)

small steps over the first time constants of the fast modes, growing geometrically as they decay,
up to the step the slow modes allow (and never past :data:`MAX_STEP`, the exogenous inputs' period,
or the run; with a reference, which keeps the loop moving and under which the method's error falls
only as ``h^3``, never past :func:`forced_step`; a step
of the reference kicks the fast modes as the initial state does, and the grading starts again
there: ``kicks`` of :func:`plan_schedule`). The
schedule is deterministic, a few segments of uniform steps ``h_top / 2^j`` (a short one merged into
the finer one before it, :data:`MERGE_STEPS`): every
step starts at a whole multiple of its own size, so a step never straddles an exogenous sample
(``h_top`` divides its period) and the runners' clock ``t = dt (k0 + k)`` is exact per segment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl.linear.stability import is_stable
from quadctl.sim.plan import RK4_RAY_BRACKET, StepPlan, max_stable_steps, record_stride, step_count, steps_per_sample

SAFETY = 1.0
"""The constant of ``h(t)`` for runs with exogenous inputs or a sampled controller (a free run takes
:data:`FREE_SAFETY`; a reference's largest step :func:`forced_step`). With noise, whose every sample
re-excites the fast modes (the schedule grades for ``t = 0`` only), 2.0 multiplied the error by 10 to
15 (hover with sensor noise, 0.2 s)."""
FREE_SAFETY = 2.0
"""The constant of ``h(t)`` for a free run (continuous feedback, no noise, wind or reference: only the
initial state excites the fast modes, the case the rule's ``t = 0`` grading describes). Measured
against RK4 at a 2.5e-5 s step over 3 s of the bundled ``forward``, ``hover``, ``drake-hover`` and
``forward-script-q`` at tolerance 1e-8 and 1e-10, and on the report's 10 s ``forward`` loop against
LSODA at rtol 1e-12 (docs/internals.md gives the numbers): the error starts to rise at 6, and
2 keeps a factor of 3 in step below that."""
MERGE_STEPS = 1
"""A graded segment that would save at most this many steps over the finer step before it is not
taken: the finer segment runs on. All the segments of a run go in one call into the runner
(``qc_run_segments``), where a segment costs its step's setup and one record, about a step
(measured: 0.46 us a segment against 0.55 us a step of the compiled ``forward`` loop); so only a
segment that saves no step whole is merged."""
MAX_STEP = 0.01
"""s: the largest step ``dt: auto`` takes (100 samples a second for plots and metrics)."""


@dataclass(frozen=True)
class Segment:
    """``n`` steps of ``dt`` s starting at ``k0 dt`` s (``k0`` whole)."""

    dt: float
    n: int
    k0: int

    @property
    def start(self) -> float:
        return self.dt * self.k0

    @property
    def end(self) -> float:
        return self.dt * (self.k0 + self.n)


def auto_step(t: float, eigenvalues, tolerance: float, safety: float = SAFETY) -> float:
    """``h(t)`` of the module's rule (s): the step every mode allows at ``t`` (``safety``: its constant)."""
    lam = np.asarray(eigenvalues, dtype=complex)
    lam = lam[np.abs(lam) > 0]
    if lam.size == 0:
        return math.inf
    sigma = np.maximum(-lam.real, 0.0)
    return float(safety * tolerance ** 0.25 * np.min(np.exp(np.minimum(sigma * t / 4, 700)) / np.abs(lam)))


def allows(h, eigenvalues, tolerance: float, safety: float = SAFETY):
    """The first time (s) at which :func:`auto_step` reaches ``h`` (inf: never), in closed form:
    the latest over the modes of ``(4 / sigma) ln(h |lambda| / (safety tolerance^(1/4)))``. ``h``
    a float (returns a float) or an array of steps (returns the array of their times)."""
    lam = np.asarray(eigenvalues, dtype=complex)
    lam = lam[np.abs(lam) > 0]
    if lam.size == 0:
        return 0.0 if np.ndim(h) == 0 else np.zeros(np.shape(h))
    ratio = np.multiply.outer(h, np.abs(lam)) / (safety * tolerance ** 0.25)
    sigma = -lam.real
    with np.errstate(divide="ignore"):
        times = np.where(ratio > 1, 4.0 / np.where(sigma > 0, sigma, 1.0) * np.log(np.maximum(ratio, 1.0)), 0.0)
    times = np.where(np.any((ratio > 1) & (sigma <= 0), axis=-1), math.inf, times.max(axis=-1))
    return float(times) if np.ndim(h) == 0 else times


FORCED_SAFETY = 1.0
"""The constant of :func:`forced_step`, measured on the bundled ``square`` mission (its whole 15 s,
largest error over the run against RK4 at 1/2000 of the rows' period, a step whose grid holds its
knots): at 0.7, 1.0, 1.4 and 2.0 the error is 1.0e-9, 4.3e-9, 8.5e-9 and 2.0e-8 at tolerance 1e-8, and
3.7e-11, 3.7e-11, 9.2e-11 and 2.9e-10 at 1e-10 (about ``h^3``, down to what the knots' grading leaves);
1.0 leaves a factor of 2 to 3 in error."""


def forced_step(eigenvalues, tolerance: float) -> float:
    """The largest step (s) of a run that flies a reference:
    ``FORCED_SAFETY tolerance^(1/3) / |lambda_slow|``, ``lambda_slow`` the slowest nonzero eigenvalue
    (inf: none).

    The reference keeps the loop moving for the whole run, so the slowest mode's term of ``h(t)`` does
    not grow (its excitation does not decay); and the method's error there falls as ``h^3``, not
    ``h^4`` (stiff order reduction): the nonlinear remainder ``N = f - L X`` carries the loop's
    distance from the trim the linear part ``L`` is taken at (a tilted thrust, a heading away from the
    trim's), through which it reaches the fast modes, and the reference's rows (quadratic in ``t``
    over each row, its slope and input's slope kinked at each row's boundary) kick those modes at
    every boundary. Graded on ``tolerance^(1/4)`` the largest error over the bundled ``square``
    mission was 12 times ``tolerance`` at 1e-8; on ``tolerance^(1/3)`` (:data:`FORCED_SAFETY`) it
    stays within it.
    """
    mag = np.abs(np.asarray(eigenvalues, dtype=complex))
    mag = mag[mag > 0]
    return float(FORCED_SAFETY * tolerance ** (1 / 3) / mag.min()) if mag.size else math.inf


def default_tolerance() -> float:
    """The error ``dt: auto`` aims at when none is given: ``simulation.tolerance``'s default
    (:data:`quadctl.config.simulation_schema.ETDRK4_TOLERANCE`, declared there only; read when first needed, so
    that the simulation does not load the config's schema)."""
    from quadctl.config.simulation_schema import ETDRK4_TOLERANCE

    return ETDRK4_TOLERANCE


def plan_schedule(eigenvalues, owners, duration: float, dt="auto", *, tolerance: float | None = None,
                  period: float | None = None, forced: bool = False, held: bool = False,
                  max_stable_dt: float | None = None, kicks=()) -> StepPlan:
    """The ETDRK4 steps of a run: uniform ``dt``, or the graded schedule of ``dt: auto``.

    Parameters
    ----------
    eigenvalues : (n,) array_like
        Of the loop's linear part (rad/s).
    owners : sequence of str
        The subsystem of each eigenvalue (for the plan's report).
    duration : float
        s.
    dt : float or "auto"
    tolerance : float, optional
        The error ``dt: auto`` aims at; None: the config's default (:func:`default_tolerance`).
    period : float, optional
        s of the exogenous inputs (noise, wind, a reference): steps divide it. None (no exogenous
        inputs) and neither ``forced`` nor ``held``: a free run, graded with :data:`FREE_SAFETY`.
    forced : bool
        The run flies a reference: the largest step is at most :func:`forced_step`.
    held : bool
        A sampled controller whose period is ``period``: every segment starts on a sample (the law
        runs there), and the plan's ``hold``/``sample_time`` are its last segment's.
    max_stable_dt : float, optional
        RK4's largest stable step (s) the plan reports, when the caller has it (computed from
        ``eigenvalues`` when None).
    kicks : sequence of float
        s: when the inputs step (a reference's knots: its setpoints, its legs' ends, where the
        feedforward's torques step), each exciting the fast modes again as the initial state does at
        ``t = 0``: ``dt: auto`` grades again from each, from the last multiple of the finest step
        before it (a held loop: the start of the ``period`` it falls in), the steps before it halving
        down to there (so every step still starts on a multiple of itself).

    Raises
    ------
    StepSizeError
        ``held`` and a given step that does not divide the controller period.

    Returns
    -------
    StepPlan
        ``method = "etdrk4"``, ``schedule`` its segments; ``dt`` the last segment's step.
    """
    tolerance = default_tolerance() if tolerance is None else tolerance
    eig = np.asarray(eigenvalues, dtype=complex)
    k_fast = int(np.argmax(np.abs(eig))) if eig.size else 0
    fastest = complex(eig[k_fast]) if eig.size else 0j
    owner = owners[k_fast] if eig.size else ""
    limit = _rk4_limit(eig) if max_stable_dt is None else max_stable_dt
    if dt != "auto":
        if held:
            hold = steps_per_sample(float(dt), period)
            h = period / hold
            n = step_count(duration, h, fastest, owner, given=float(dt))
            return StepPlan(h, n, limit, fastest, owner, False, hold=hold, sample_time=period,
                            method="etdrk4", schedule=(Segment(h, n, 0),))
        n = step_count(duration, float(dt), fastest, owner, given=float(dt))
        h = duration / n
        return StepPlan(h, n, limit, fastest, owner, False, method="etdrk4",
                        schedule=(Segment(h, n, 0),))
    safety = FREE_SAFETY if period is None and not forced and not held else SAFETY
    cap = min(MAX_STEP, duration, auto_step(math.inf, eig, tolerance, safety))
    if forced:
        cap = min(cap, forced_step(eig, tolerance))
    if period is not None:
        top = period / math.ceil(period / cap - 1e-9)
    else:
        top = duration / math.ceil(duration / cap - 1e-9)
    level = 0
    first = auto_step(0.0, eig, tolerance, safety)
    while top / 2 ** level > first and level < 60:
        level += 1
    kick_level = level if held else level + KICK_LEVELS
    allowed_at = allows(2 * top / 2.0 ** np.arange(kick_level + 1), eig, tolerance, safety)  # of 2h, each level
    grid = period if held else top / 2 ** kick_level  # a kick's grading starts on a sample, or its finest step
    at = {}  # each grading's start: the kick it is for (the first, if several share it)
    for k in sorted(kicks, reverse=True):
        if 0 < k < duration:
            at[_before(k, grid, held)] = k
    starts = sorted({0.0, *at})
    segments = []
    for start, end in zip(starts, [*starts[1:], duration]):
        allowed = allowed_at
        if start > 0 and not held:  # the kick's finest steps until it is behind them, then graded up
            allowed = allowed_at.copy()
            allowed[level + 1:] = np.maximum(allowed[level + 1:], at[start] - start)
        segments += _graded(start, end - start, top, kick_level if start > 0 else level, allowed,
                            period if held else None, exact=end < duration)
    total = sum(s.n for s in segments)
    step_count(total * top, top, fastest, owner)  # refuses (or announces) a runaway plan
    held_at = dict(hold=round(period / segments[-1].dt), sample_time=period) if held else {}
    return StepPlan(segments[-1].dt, total, limit, fastest, owner, True, method="etdrk4",
                    schedule=tuple(segments), **held_at)


KICK_LEVELS = 4
"""A kick's grading (continuous feedback) starts ``2^KICK_LEVELS`` times finer than the run's, on that
grid's last point before the kick, and steps on it until the kick is behind: a knot off the step grid
falls inside a step, which integrates the side its midpoint is on over the whole step (measured on the
bundled ``square`` at tolerance 1e-10: 1.9e-10 with the run's finest step there, within the tolerance
16 times finer), for a few steps more per kick."""


def _before(kick: float, grid: float, held: bool) -> float:
    """s: where the grading from ``kick`` starts: the sample it falls in (a held loop: its law reads the
    reference at samples only), or the last multiple of the finest step ``grid`` before it (a kick on
    that grid: the one before), so that only finest steps touch it: the one that starts on it reads the
    reference after it at every stage, the one that ends on it, at its end."""
    if held:
        return math.floor(kick / grid + 1e-9) * grid
    return (math.ceil(kick / grid - 1e-6) - 1) * grid


def _graded(origin: float, span: float, top: float, level: int, allowed_at, held_period: float | None,
            exact: bool = False) -> list[Segment]:
    """The segments of ``[origin, origin + span)`` s graded from its start: steps ``top / 2^level``
    first, each level up from where :func:`allows` lets ``h(t)`` take twice the step (``allowed_at``:
    those times after the start, of ``2h``, for each level from ``top``); ``held_period``: a sampled
    controller's period, on which segments start. Every step starts on a multiple of itself (``origin``
    a multiple of the first). ``exact``: the span ends exactly at ``origin + span`` (a multiple of the
    finest step: where the next kick's grading starts), its last steps halved down to it; else the
    last segment may run past it by less than a step."""
    segments, t = [], 0.0
    end = span
    if exact:  # graded up to the last multiple of ``top``, then steps halving down to the span's end
        end = math.floor((origin + span) / top + 1e-9) * top - origin
        if end <= 1e-12 * top:
            fine = top / 2 ** level
            return [Segment(fine, round(span / fine), round(origin / fine))]

    def switch_at(h: float, t: float) -> float:
        """The first time at or after ``t`` on the grid of ``2h`` (a held loop's samples) at which
        ``h(t)`` allows ``2h``; inf: not within the span."""
        allowed = allowed_at[round(math.log2(top / h))]
        if allowed >= end:
            return math.inf
        unit = held_period if held_period is not None else 2 * h  # a held loop's segments start on a sample
        return math.ceil((origin + max(allowed, t)) / unit - 1e-9) * unit - origin

    while True:
        h = top / 2 ** level
        remaining = math.ceil((end - t) / h - 1e-9)
        switch, after_level, coarse = (switch_at(h, t) if level else math.inf), level - 1, 2 * h
        # a coarser segment that would save at most MERGE_STEPS steps is taken at h (one segment less)
        while switch < end and after_level > 0:
            after = switch_at(coarse, switch)
            span_after = min(after, end) - switch
            if span_after / h - span_after / coarse > MERGE_STEPS:
                break
            switch, after_level, coarse = after, after_level - 1, 2 * coarse
        if switch >= end:
            segments.append(Segment(h, remaining, round((origin + t) / h)))
            break
        n = min(round((switch - t) / h), remaining)
        if n > 0:
            segments.append(Segment(h, n, round((origin + t) / h)))
        t = switch
        level = after_level
        if t >= end - 1e-12 * max(end, top):
            break
    if exact:
        t, h = end, segments[-1].dt
        while t < span - 1e-12 * top:
            while t + h > span + 1e-12 * top:
                h /= 2
            segments.append(Segment(h, 1, round((origin + t) / h)))
            t += h
    return segments


def record_strides(plan: StepPlan, max_samples: int) -> list[int]:
    """Per segment of ``plan``, the stride that records at the same times in every segment: the
    multiples of ``m h_top`` (``h_top`` the largest step; ``m`` the smallest that keeps at most
    ``max_samples`` records), so records are equally spaced, as metrics and plots take them. Every
    step is ``h_top / 2^j`` and starts on a multiple of itself, so these times are steps' starts."""
    top = max(s.dt for s in plan.schedule)
    m = record_stride(max(1, round(max(s.end for s in plan.schedule) / top)), max_samples)
    return [m * round(top / s.dt) for s in plan.schedule]


def _rk4_limit(eig) -> float:
    """RK4's largest stable step for these eigenvalues (s; reported beside the schedule): of the
    stable ones fast enough to set it (each limit is ``|z| / |lambda|`` with ``|z|`` within the
    bisection's bracket, so a mode slower than ``bracket[0] / bracket[1]`` of the fastest cannot)."""
    eig = np.asarray(eig, dtype=complex)
    mag = np.where(is_stable(eig), np.abs(eig), 0.0)
    lo, hi = RK4_RAY_BRACKET
    return float(rk4_limits(eig[(mag > 0) & (mag >= mag.max(initial=0.0) * lo / hi)][None])[0])


def rk4_limits(eigenvalues) -> np.ndarray:
    """(N,) RK4's largest stable step (s) for each row of eigenvalues (N, n), in one vectorized pass."""
    limits = max_stable_steps(eigenvalues)
    return np.where(np.isfinite(limits) & (limits > 0), limits, np.inf).min(axis=-1)


def summary(plan: StepPlan) -> list[dict]:
    """The steps as sim.json reports them: per segment of uniform steps its step (s), steps, start
    and end (s); RK4's plan is one segment."""
    segments = plan.schedule or (Segment(plan.dt, plan.n_steps, 0),)
    return [{"dt": s.dt, "steps": s.n, "start": s.start, "end": s.end} for s in segments]
