"""One run of the full nonlinear closed loop (:class:`~quadctl.sim.loop.ClosedLoop`): RK4 at a fixed
step, or ETDRK4 (``simulation.method: etdrk4``) on a graded schedule of steps
(:mod:`quadctl.sim.etdrk4_plan`; its matrices :mod:`quadctl.sim.etdrk4_matrices`). :func:`simulate` runs
the stack of one (:func:`quadctl.sim.stack.stack_of`, :func:`quadctl.sim.stack_run.run_stack`) and reads its
records back as a :class:`SimResult`, with how the run ended (:func:`verdict`).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from quadctl.layout import N_STATES, STATE_NAMES
from quadctl.metrics import MAX_SAMPLES
from quadctl.physics.noise import NoiseSpec
from quadctl.physics.wind import WindSpec
from quadctl.sim.builder import heading_frame
from quadctl.sim.engine import runner
from quadctl.sim.exogenous import wind_felt
from quadctl.sim.loop import TURNED_OVER, VALID_PITCH, ClosedLoop
from quadctl.sim.loop_spec import LoopSpec
from quadctl.sim.plan import StepPlan
from quadctl.sim.stack import stack_of
from quadctl.sim.stack_run import run_stack


@dataclass(frozen=True, eq=False)
class SimResult:
    """A simulation run.

    Attributes
    ----------
    t : (N+1,) ndarray
        s.
    x : (N+1, 12) ndarray
        The plant's state, columns in :data:`quadctl.layout.STATE_NAMES` order, each in its
        :data:`quadctl.layout.STATE_UNITS` unit (m, m/s, rad, rad/s).
    u : (N+1, 4) ndarray
        Applied input (after any saturation), columns in :data:`quadctl.layout.INPUT_NAMES` order,
        in :data:`quadctl.layout.INPUT_UNITS` (N, N m).
    x_ref : (N+1, 12) ndarray
        The reference the controller regulates to (as ``x``).
    dt : float
        s: the integration step (RK4's; ETDRK4's last segment's, its whole schedule in ``plan``).
    status : str
        ``ok``, ``diverged`` or ``left_valid_range``.
    message : str
        One line on how the run ended.
    wall_time : float
        s spent integrating (excludes compilation).
    steps : int
        Steps taken (RK4's, or ETDRK4's over its schedule).
    stride : int
        Samples are every ``stride``-th step (and the last); see ``max_samples``. ETDRK4: of the
        largest step (:func:`quadctl.sim.etdrk4_plan.record_strides`), so samples are equally spaced.
    backend : str
        ``compiled`` or ``casadi`` (no C compiler).
    plan : StepPlan

    Examples
    --------
    >>> import quadctl as qc
    >>> stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    >>> run = qc.simulate(stages.loop, stages.loop.x_trim, 0.5)  # from the trim: it stays there
    >>> run.status, run.x.shape[1], run.u.shape[1], round(float(run.t[-1]), 9)
    ('ok', 12, 4, 0.5)
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    x_ref: np.ndarray
    dt: float
    status: str
    message: str
    wall_time: float
    backend: str
    plan: StepPlan
    steps: int
    stride: int
    z: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(N+1, nz) integrator states of an LQI controller."""
    rotor_thrust: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(N+1, 4) N: each rotor's thrust, when the rotors lag (``motors.time_constant``); else empty
    (an instantaneous rotor's thrust is the clipped command ``mix u``)."""
    noise_seed: int | None = None
    lag_model: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(N+1, 4) the controller's rotor lag model ``l`` (deviation of ``[T, A, E, R]`` from trim; N, N m)
    when the design includes the lag (``controller.rotor_lag: include``); else empty."""
    wind: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """(N+1, 3) m/s NED: the wind the plant felt over each recorded step (empty: still air)."""
    wind_seed: int | None = None
    """The turbulence's seed (None: no turbulence)."""
    x_hat: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(N+1, 12) the Kalman filter's estimate of ``x`` (``x_ref`` plus its deviation estimate) of an
    LQG loop; else empty. A held (sampled) loop records the a priori estimate ``x_hat[k|k-1]``:
    predicted at sample ``k - 1``, held over the steps up to and including sample ``k``'s time (the
    updated ``x_hat[k|k]`` the law acts on is not recorded), so ``x - x_hat`` at the samples has the
    a priori covariance ``P``. A continuous loop records the Kalman-Bucy estimate at each step."""
    u_ref: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    """(N+1, 4) the feedforward input the law used (a run that flies a reference); else empty (``u_trim``)."""

    @property
    def steps_per_second(self) -> float:
        return self.steps / self.wall_time if self.wall_time > 0 else math.inf


def simulate(loop: ClosedLoop, x0, duration: float, dt="auto", *,
             noise: NoiseSpec | None = None, wind: WindSpec | None = None,
             max_samples: int = MAX_SAMPLES, progress=None, reference=None, method: str = "rk4",
             tolerance: float | None = None, exo_rate: float | None = None) -> SimResult:
    """RK4 (or ETDRK4) of the nonlinear closed loop from ``x0`` for ``duration`` seconds.

    Parameters
    ----------
    loop : ClosedLoop
    x0 : (12,) array_like
        Initial state (integrators, if any, start at zero; lagging rotors at their trim thrust).
    duration : float
        s.
    dt : float or "auto"
        s; see :func:`quadctl.sim.plan.plan_step` (continuous control) or
        :func:`quadctl.sim.plan.plan_held_step` (``loop.rate``).
    noise : NoiseSpec, optional
        Process and sensor noise; the same spec gives the same run.
    wind : WindSpec, optional
        Steady wind, gusts and turbulence (:mod:`quadctl.physics.wind`); the same spec gives the same run.
    max_samples : int
        Samples kept, at most: every :func:`record_stride`-th step and the last.
    progress : callable, optional
        ``progress(done, total)``: called with the steps done and the steps in all after each
        chunk of the run (:func:`~quadctl.sim.stack_run.run_stack`), for a caller that shows how far a long run is.
    reference : FlownReference, optional
        A reference to fly (:class:`quadctl.physics.reference_rows.FlownReference`): ``x_ref(t)`` and the feedforward
        ``u_ref(t)`` in place of ``x_trim + x_rate t`` and ``u_trim``; ``SimResult.x_ref`` is then the
        reference the law used.
    method : {"rk4", "etdrk4"}
        ``etdrk4``: the exponential integrator on the loop's linear part (continuous feedback only;
        :mod:`quadctl.sim.etdrk4_plan`), ``dt: auto`` its graded schedule.
    tolerance : float, optional
        The error ETDRK4's ``dt: auto`` aims at; None: ``simulation.tolerance``'s default.
    exo_rate : float, optional
        Hz of the exogenous clock when there is no noise (:class:`~quadctl.sim.exogenous.ExoStream`; None: the
        controller's rate): loops of different rates flown with one ``exo_rate`` feel the same wind
        (ETDRK4's steps divide its period).

    Returns
    -------
    SimResult
        A diverging run stops at the first bad state and keeps everything before it.

    Raises
    ------
    ArgumentError
        ``duration`` or ``dt`` is not a positive number of seconds, ``method`` is unknown, ``max_samples``
        is not a whole number of at least 2, ``tolerance`` or ``exo_rate`` not a positive number, or ``x0`` is
        not the 12 finite real states (a ``ValueError``).
    ArgumentTypeError
        ``loop`` is not a :class:`ClosedLoop`, or ``noise``, ``wind`` or ``reference`` is not a
        :class:`~quadctl.physics.noise.NoiseSpec`, :class:`~quadctl.physics.wind.WindSpec` or
        :class:`~quadctl.physics.reference_rows.FlownReference` (a ``TypeError``).
    StepSizeError
        A fixed ``dt`` that RK4 cannot hold stable for the loop.

    Examples
    --------
    The hover design, flown 3 s from its configured offset (0.5 m low, tilted and turned), is back
    at its altitude (``pD``, index 2) to well within a millimetre:

    >>> import quadctl as qc
    >>> stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    >>> loop = stages.loop
    >>> run = qc.simulate(loop, stages.setup.initial_state(loop.x_trim), 3.0)
    >>> run.status, float(run.x[0, 2] - loop.x_trim[2]), bool(abs(run.x[-1, 2] - loop.x_trim[2]) < 1e-4)
    ('ok', 0.5, True)
    """
    stack = stack_of([loop], [x0], duration, dt, method=method, noise=noise, wind=wind, max_samples=max_samples,
                     reference=reference, tolerance=tolerance, exo_rate=exo_rate)
    run = runner(stack.spec, 1)
    start = time.perf_counter()
    (done, t, xs, us), = run_stack(stack, run, progress)
    wall = time.perf_counter() - start
    exo = stack.exo
    return _result(loop, stack.plans[0], run.backend, t, xs, us, done, stack.strides[0], wall, stack.cases.lo[0],
                   stack.cases.hi[0], noise if exo is not None and exo.noise is not None else None,
                   wind if exo is not None and exo.wind is not None else None, exo, t, 1.0, reference, stack.spec)


def _result(loop: ClosedLoop, plan: StepPlan, backend: str, t, xs, us, done: int, stride: int, wall: float,
            lo, hi, noise, wind, exo, ks, dt: float, reference=None, spec: LoopSpec | None = None) -> SimResult:
    """The :class:`SimResult` of a run's recorded rows (``t`` s; the wind felt and the reference flown at
    steps ``ks`` of ``dt``); ``spec``: the loop's (its state layout), when the caller has it."""
    spec = loop.spec() if spec is None else spec
    nz, n_plant, n_lag, ne = spec.nz, spec.n_plant, spec.n_lag, spec.n_estimate
    u_ref = np.zeros((0, len(loop.u_trim)))
    if reference is None:
        x_ref = loop.x_trim + np.outer(t, loop.x_rate)
    else:
        x_ref, u_ref = reference.flown(reference.rows(exo.index(ks, dt), exo.period), t)
    status, message = verdict(xs[:, :N_STATES], t, done, plan.n_steps, lo, hi)
    return SimResult(t=t, x=np.ascontiguousarray(xs[:, :N_STATES]), u=us, x_ref=x_ref, dt=plan.dt,
                     status=status, message=message, wall_time=wall, backend=backend, plan=plan,
                     steps=done, stride=stride, z=np.ascontiguousarray(xs[:, n_plant:n_plant + nz]),
                     rotor_thrust=np.ascontiguousarray(xs[:, N_STATES:n_plant]),
                     noise_seed=noise.seed if noise is not None else None,
                     lag_model=np.ascontiguousarray(xs[:, n_plant + nz:n_plant + nz + n_lag]),
                     wind=wind_felt(wind, exo.period, ks, dt) if wind is not None else np.zeros((0, 3)),
                     wind_seed=wind.seed if wind is not None else None,
                     x_hat=_estimate(loop, x_ref, xs[:, xs.shape[1] - ne:xs.shape[1] - ne + N_STATES],
                                     reference is not None) if ne
                     else np.zeros((0, 0)),
                     u_ref=u_ref)


def _estimate(loop: ClosedLoop, x_ref: np.ndarray, deviation: np.ndarray, reference: bool) -> np.ndarray:
    """(n, 12) the filter's estimate of ``x``: ``x_ref`` plus its deviation estimate, which the filter of a
    loop flying a ``reference`` keeps in its heading frame (:func:`quadctl.sim.builder.heading_frame`):
    turned back."""
    if not reference:
        return x_ref + deviation
    return x_ref + heading_frame(deviation, -loop.heading_offset(x_ref), lib=np)


STATUS_WORDS = {"ok": "completed", "diverged": "diverged", "left_valid_range": "left the valid range"}
"""Each :func:`verdict` status in words, for a figure's legend or a summary line."""


def verdict(xs, t, done, n, lo, hi) -> tuple[str, str]:
    """(status, message) of a run: ``ok``, ``diverged`` or ``left_valid_range`` (the message of a run that
    stopped: its cause, then ``; saved N steps``, :func:`stop_cause`)."""
    if done == n:
        return "ok", f"completed {n} steps to t = {t[-1]:.6g} s"
    last = xs[-1]
    bad = [i for i in range(N_STATES) if not (lo[i] <= last[i] <= hi[i])]
    name = STATE_NAMES[bad[0]] if bad else "?"
    if not np.all(np.isfinite(last)):
        status, cause = "diverged", f"diverged at t = {t[-1]:.4g} s: {name} is not finite"
    elif name == "theta":
        status, cause = "left_valid_range", (
            f"left the model's valid range at t = {t[-1]:.4g} s: pitch {math.degrees(last[bad[0]]):.1f} deg "
            f"is beyond +-{math.degrees(VALID_PITCH):.0f} deg (Euler kinematics singular at 90)")
    elif name == "phi":
        over = math.degrees(TURNED_OVER)
        status, cause = "diverged", (
            f"diverged at t = {t[-1]:.4g} s: roll {math.degrees(last[bad[0]]):.1f} deg is {over:.0f} deg or more "
            "from the trim's: the vehicle turned over, its thrust no longer holds it up")
    else:
        status, cause = "diverged", f"diverged at t = {t[-1]:.4g} s: {name} = {last[bad[0]]:.3g} ran away"
    return status, f"{cause}{_SAVED}{_steps(done)}"


_SAVED = "; saved "


def stop_cause(message: str) -> str:
    """A :func:`verdict` message without what the run saved: why it stopped (for a caller that keeps less
    than the run's steps, such as ``quadctl compare``)."""
    return message.rpartition(_SAVED)[0] or message


def _steps(n: int) -> str:
    return f"{n} step" if n == 1 else f"{n} steps"
