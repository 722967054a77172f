"""Many runs at once: the one entry that makes a stack of cases for either integrator, and RK4's cases.

:func:`stack_of` makes the :class:`~quadctl.sim.stack_run.Stack` of the runs (RK4: a segment each, its step
from :mod:`quadctl.sim.plan`, :func:`rk4_cases`, which makes a sweep's lanes too from what the sweep
knows per case; ETDRK4: a segment per step of its schedule, :mod:`quadctl.sim.etdrk4_stack`), and
:func:`quadctl.sim.stack_run.run_stack` runs them; :func:`simulate_stack` is both for many loops in the SIMD
lanes (:func:`quadctl.sim.run.simulate` is the stack of one).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from quadctl.errors import ArgumentError, ArgumentTypeError
from quadctl.layout import N_STATES, STATE_NAMES
from quadctl.metrics import MAX_SAMPLES
from quadctl.physics.noise import NoiseSpec
from quadctl.physics.reference_rows import FlownReference
from quadctl.physics.wind import WindSpec
from quadctl.sim.cases import Cases
from quadctl.sim.engine import LANES, runner
from quadctl.sim.etdrk4_stack import exponential_stack, kept_exponential_stack
from quadctl.sim.exogenous import ExoStream
from quadctl.sim.loop import ClosedLoop, gain_constants
from quadctl.sim.loop_layout import fill_constants_stack
from quadctl.sim.plan import StepPlan, record_stride
from quadctl.sim.stack_run import Stack, run_stack


def _positive_seconds(value) -> bool:
    """Whether ``value`` is a finite positive number (not a bool, not text numpy would convert)."""
    return not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating)) \
        and 0.0 < float(value) < float("inf")


def stack_of(loops, x0s, duration: float, dt="auto", *, method: str = "rk4", noise: NoiseSpec | None = None,
             wind: WindSpec | None = None, max_samples: int = MAX_SAMPLES, reference=None,
             tolerance: float | None = None, exo_rate: float | None = None, planned=None) -> Stack:
    """The :class:`~quadctl.sim.stack_run.Stack` of runs of ``loops`` from ``x0s`` (the arguments of
    :func:`~quadctl.sim.run.simulate`): one case is a stack of one (an ETDRK4 case from the setup its loop keeps,
    :func:`~quadctl.sim.etdrk4_stack.kept_exponential_stack`); more run in the SIMD lanes, each case stepping as its
    one-case run does (ETDRK4: the φ-functions of all the loops' linear parts computed on the stack of them).
    ``planned``: each loop's ``(L, StepPlan)`` of :func:`~quadctl.sim.etdrk4_stack.exponential_plan`, when the
    caller has them.

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

    ``exo``: per case ``(first, rows, period)``, its exogenous rows drawn (None: none given, the rows of
    ``exo_period`` drawn when the stack runs, :func:`~quadctl.sim.stack_run.run_stack`). ``shared``: per case a key;
    the cases of one key are one loop but for its gains (:meth:`~quadctl.sim.loop.ClosedLoop.gain_constants`) from
    one ``x0``: its constants and initial loop state are computed once, each case's gains written into a copy
    (:func:`quadctl.sim.loop_layout.fill_constants_stack`); None: each case's own.
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
