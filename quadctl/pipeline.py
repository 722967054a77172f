"""The stages chained from a :class:`~quadctl.setup.Setup`: pure functions, no I/O.

Each takes the setup (and upstream results) and returns the stage's result object; nothing here
reads the config (:func:`quadctl.setup.setup_of` did, once). :class:`Stages` is the one chain of
them, each computed once on first use: the run folder's :class:`~quadctl.workspace.Workspace` and
:func:`quadctl.export.prepare` take it. What a flown run reports (``sim.json``'s flight, wind,
tracking and mission verdict) is :mod:`quadctl.run_summary`'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from quadctl.config.pid import NEEDS_ROTORS
from quadctl.design import Design, design, discrete, kalman, linear_loop, lqg_loop, margin_findings
from quadctl.errors import ArgumentError, ArgumentTypeError, ConfigError, RateError
from quadctl.layout import INPUT_NAMES, STATE_NAMES
from quadctl.linear import stability
from quadctl.linear.analysis import Checks, check
from quadctl.linear.decouple import Decoupled, decouple
from quadctl.linear.linearize import LinearModel, linearize
from quadctl.linear.trim import Trim, solve_trim
from quadctl.metrics import Disturbance, settling_times
from quadctl.physics import motors
from quadctl.physics.motors import check_trim
from quadctl.setup import Setup, without_disturbances
from quadctl.sim.cascade_lift import lifted
from quadctl.sim.cascade_margins import cascade_margins
from quadctl.sim.loop import ClosedLoop, eigen_owners
from quadctl.sim.run import SimResult, simulate


def _require(who: str, *given) -> None:
    """An ArgumentTypeError naming the first ``(label, value, kind)`` of ``given`` whose value is not of its
    kind: stages swapped or from elsewhere failed with an AttributeError from inside."""
    for label, value, kind in given:
        if not isinstance(value, kind):
            raise ArgumentTypeError(f"{who}: {label} must be a {kind.__name__} (qc.Stages(setup) computes each stage), "
                                    f"got {type(value).__name__}")


def trim_of(setup: Setup) -> Trim:
    """The trim of the setup's flight condition: :func:`quadctl.linear.trim.solve_trim` of its velocity,
    heading and position, for its design vehicle, in its steady wind (``trim.wind``)."""
    _require("trim_of", ("setup", setup, Setup))
    return solve_trim(setup.velocity_ned, setup.yaw, setup.position_ned, setup.vehicle, wind_ned=setup.trim_wind)


def linear_of(setup: Setup, trim: Trim) -> LinearModel:
    """The setup's design vehicle linearized about ``trim`` (:func:`quadctl.linear.linearize.linearize`),
    in its steady wind."""
    _require("linear_of", ("setup", setup, Setup), ("trim", trim, Trim))
    return linearize(trim.x, trim.u, setup.vehicle, setup.trim_wind)


def decoupled_of(setup: Setup, linear: LinearModel) -> Decoupled:
    """The linear model split into the subsystems of the setup's partition
    (:func:`quadctl.linear.decouple.decouple`)."""
    _require("decoupled_of", ("setup", setup, Setup), ("linear", linear, LinearModel))
    return decouple(linear.A, linear.B, setup.partition)


def checks_of(decoupled: Decoupled, linear: LinearModel) -> dict[str, Checks]:
    """Checks of every subsystem, then ``"full"`` for the 12-state model with all 4 inputs."""
    out = {s.name: check(s.A, s.B, s.C, s.states) for s in decoupled.subsystems}
    out["full"] = check(linear.A, linear.B, None, STATE_NAMES)
    return out


def design_of(setup: Setup, decoupled: Decoupled, linear: LinearModel) -> Design:
    """The decoupled LQR design the setup asks for: discrete at its design rate, else continuous
    (the design says which: :attr:`~quadctl.design.Design.sample_time`)."""
    return design_at(setup, decoupled, linear, setup.timing.design_rate)


def design_at(setup: Setup, decoupled: Decoupled, linear: LinearModel, rate: float | None) -> Design:
    """The setup's decoupled LQR design computed at ``rate`` Hz (MATLAB ``lqrd``), or continuous for
    None, whatever the setup's own timing (``check`` compares a continuous design with a rate)."""
    _require("design_of", ("setup", setup, Setup), ("decoupled", decoupled, Decoupled), ("linear", linear, LinearModel))
    if setup.weight_error is not None:

        raise ConfigError(setup.weight_error)
    return design(decoupled, linear.A, linear.B, setup.weights, rate=rate, integral=setup.integral,
                  lag_time_constant=setup.design_lag_time_constant)


def closed_loop_of(setup: Setup, linear: LinearModel, K: np.ndarray, *, Ki: np.ndarray | None = None,
                   integral_states=(), Kv: np.ndarray | None = None, estimator=None) -> ClosedLoop:
    """The loop to simulate: gains ``K`` (and an LQI design's ``Ki``, ``integral_states``; a design
    with the rotors' lag's ``Kv``, fed by the controller's lag model) on the setup's plant, timing
    and actuators; ``estimator``, the setup's Kalman filter when the caller has it already
    (:func:`estimator_of`, computed here when None).

    The eigenvalues (for the RK4 step) are those of the continuous closed loop including the
    integrators (and the lag states, with ``Kv``); a sampled controller steps on the open-loop
    plant's instead.
    """
    integral_states = tuple(integral_states)
    if setup.integral and not integral_states:
        raise ArgumentError("closed_loop_of: no integral_states, and the setup has integral action "
                            "(lqr.<subsystem>.integral): pass Ki and integral_states from the design, or call "
                            "pipeline.loop_of(setup, linear, design)")
    tau = setup.design_lag_time_constant if Kv is not None else None
    if Kv is not None and tau is None:
        raise ArgumentError("closed_loop_of: Kv feeds back the controller's rotor lag model, and the setup's design "
                            "has none: leave Kv out, or use a setup with controller.rotor_lag: include and "
                            "motors.time_constant")
    A_cl = linear_loop.matrix(linear.A, linear.B, K, Ki, integral_states, Kv=Kv, lag_time_constant=tau)
    lag_names = tuple(f"lag of {i}" for i in INPUT_NAMES) if tau is not None else ()
    owner = {**setup.state_owner, **{f"lag of {i}": setup.input_owner(i) for i in INPUT_NAMES}}
    eig, owners = eigen_owners(A_cl, owner, (*STATE_NAMES, *lag_names, *integral_states))
    check_trim(setup.actuators, linear.u_trim)
    return simulated_loop(setup, linear, K, Ki=Ki, integral_states=integral_states, Kv=Kv,
                          estimator=estimator if estimator is not None else estimator_of(setup, linear),
                          eigenvalues=eig, owners=owners)


def simulated_loop(setup: Setup, linear: LinearModel, K: np.ndarray, *, Ki: np.ndarray | None = None,
                   integral_states=(), Kv: np.ndarray | None = None, estimator=None, eigenvalues, owners,
                   params: np.ndarray | None = None, open_loop_eigenvalues: np.ndarray | None = None) -> ClosedLoop:
    """The one constructor of the :class:`~quadctl.sim.loop.ClosedLoop` a setup flies: gains on the
    setup's plant, trim, timing (rate, delay), actuators and the design's lag model (with ``Kv``).

    ``eigenvalues`` and ``owners`` (of the continuous closed loop, for the RK4 step) are the
    caller's; ``params`` (the plant's parameter vector) and ``open_loop_eigenvalues`` (of
    ``linear.A``) are computed unless the caller has them cached. ``estimator`` is taken as given
    (None: the law measures the state).
    """
    return ClosedLoop(params=setup.plant.vector() if params is None else params, x_trim=linear.x_trim,
                      u_trim=linear.u_trim, estimator=estimator, x_rate=linear.x_rate, K=K, eigenvalues=eigenvalues,
                      owners=owners, rate=setup.timing.rate,
                      Ki=Ki if integral_states else None, integral_states=tuple(integral_states),
                      actuators=setup.actuators,
                      open_loop_eigenvalues=(np.linalg.eigvals(linear.A) if open_loop_eigenvalues is None
                                             else open_loop_eigenvalues),
                      delay_samples=setup.timing.delay_samples, Kv=Kv,
                      lag_model_time_constant=setup.design_lag_time_constant if Kv is not None else None,
                      jacobians=(linear.A, linear.B), rate_filter=setup.rate_filter)


def pid_loop_of(setup: Setup, linear: LinearModel, gains=None) -> ClosedLoop:
    """The loop of a PID cascade (:mod:`quadctl.sim.pid`; ``gains`` a
    :class:`quadctl.config.pid.PidGains`, None: the setup's) on the setup's plant, trim, rotors and delay,
    sampled at the cascade's base rate (``rate_hz``). The delay, counted in the setup's controller
    samples, is kept in seconds: a whole number of the cascade's samples.

    Raises
    ------
    RateError
        The delay is not a whole number of the cascade's samples.
    ConfigError
        The setup has no rotors (``motors:``) to command.
    """

    gains = setup.pid if gains is None else gains
    if not motors.has_rotors(setup.actuators):
        raise ConfigError(f"controller.flies: pid: {NEEDS_ROTORS}, or fly lqr")
    rate = float(gains["rate_hz"])
    delay = 0
    if setup.timing.delay_samples:
        n = setup.timing.delay_samples / setup.timing.rate * rate
        delay = round(n)
        if abs(n - delay) > 1e-9 * max(1.0, n):
            raise RateError(f"controller.delay: {setup.timing.delay_samples / setup.timing.rate:g} s is {n:.6g} "
                            f"samples of the PID cascade's {rate:g} Hz: make it a whole number of both rates")
    return ClosedLoop(params=setup.plant.vector(), x_trim=linear.x_trim, u_trim=linear.u_trim, x_rate=linear.x_rate,
                      K=np.zeros((len(INPUT_NAMES), len(STATE_NAMES))), eigenvalues=np.zeros(0), owners=[],
                      rate=rate, actuators=setup.actuators, open_loop_eigenvalues=np.linalg.eigvals(linear.A),
                      delay_samples=delay, jacobians=(linear.A, linear.B), law=gains)


def estimator_of(setup: Setup, linear: LinearModel):
    """The setup's steady-state Kalman filter (:func:`quadctl.design.kalman.kalman`) at the controller's
    timing (discrete at the controller period when sampled, Kalman-Bucy when continuous), with the gyro
    filter (``controller.filters``) in its model; None without ``estimator:``."""
    est = setup.estimator
    if est is None:
        return None

    G = kalman.noise_input(linear.x_trim, linear.u_trim, setup.vehicle)
    return kalman.kalman(linear.A, linear.B, G, est.measured, est.sensor_std, est.process_std,
                         sample_time=setup.timing.sample_time, period=est.period, rate_filter=setup.rate_filter)


def loop_of(setup: Setup, linear: LinearModel, des: Design) -> ClosedLoop:
    """:func:`closed_loop_of` for a design: its state gain, its integrators (LQI) and its gain on
    the rotors' lag (a design that includes it)."""
    _require("loop_of", ("setup", setup, Setup), ("linear", linear, LinearModel), ("des", des, Design))
    return closed_loop_of(setup, linear, des.K_block, Ki=des.Ki_block, integral_states=des.integral_states,
                          Kv=des.Kv_block if des.lag_time_constant is not None else None)


def scheduled_loop(loop: ClosedLoop, table, heading: float, eigenvalues=(),
                   jacobians: tuple | None = None) -> ClosedLoop:
    """``loop`` flying the gain table ``table`` (:class:`quadctl.design.gain_table.GainTable`), scheduled on
    the reference the law uses (:mod:`quadctl.sim.builder`, "Gain schedule"), ``speed`` measured along
    ``heading`` (rad; the schedule's, :attr:`quadctl.schedule.envelope.Schedule.heading`). The table's gains
    replace ``K`` (and ``Ki`` with the integrators' columns). ``eigenvalues`` (rad/s, any shape; NaN
    ignored): the frozen loops of the interpolated gains (:class:`quadctl.schedule.envelope.FrozenChecks`),
    which a continuous loop's RK4 step must hold stable as well as the loop's own. ``jacobians``:
    ``(A, B)`` of the model at each of the table's values (:attr:`quadctl.schedule.envelope.Schedule.jacobians`),
    the linear parts ETDRK4 flies a continuous loop on (:attr:`ClosedLoop.schedule_jacobians`).
    ``run`` and ``simulate`` fly ``schedule_of(setup)``'s table this way.
    """
    from dataclasses import replace

    if jacobians is not None and len(jacobians[0]) != len(table.values):
        raise ArgumentError(f"scheduled_loop: jacobians has {len(jacobians[0])} points for a table of "
                            f"{len(table.values)} values; give (A, B) at each of table.values")
    eig = np.asarray(eigenvalues, dtype=complex).ravel()
    return replace(loop, schedule=table, schedule_heading=float(heading), schedule_eigenvalues=eig[np.isfinite(eig)],
                   schedule_jacobians=jacobians)


def simulation_of(setup: Setup, loop: ClosedLoop, *, noise: bool = True, progress=None) -> SimResult:
    """The configured run of ``loop`` from the configured initial state (``noise=False``: without noise;
    the wind, a condition of the flight, stays); ``progress(done, total)`` as :func:`simulate` calls it."""
    _require("simulation_of", ("setup", setup, Setup), ("loop", loop, ClosedLoop))
    return simulate(loop, setup.initial_state(loop.x_trim), setup.duration, setup.dt,
                    noise=setup.noise if noise else None, wind=setup.wind, max_samples=setup.max_samples,
                    progress=progress, reference=setup.flown_reference, method=setup.method,
                    tolerance=setup.tolerance)


def noisy(setup: Setup, noise: bool = True) -> Disturbance:
    """What randomly disturbs the configured run (:class:`quadctl.metrics.Disturbance`, true when
    something does): turbulence (``GUSTS``, whatever the noise), noise (``NOISE``; ``noise=False``: a
    run without it, :func:`simulation_of`'s), or nothing. Its settling times may be noise-limited
    (:func:`quadctl.metrics.noise_limited`)."""
    if setup.wind is not None and setup.wind.turbulence is not None:
        return Disturbance.GUSTS
    return Disturbance.NOISE if noise and setup.noise is not None else Disturbance.QUIET


def twin_of(setup: Setup) -> Setup | None:
    """The setup of the configured run's twin: the same case without its random disturbances
    (:func:`quadctl.setup.without_disturbances`: no noise, no turbulence; the steady wind, the gusts,
    the reference, the delays and lags kept), against which a turbulent run's late settling is read
    (:func:`quadctl.metrics.noise_limited`); None when the run has no turbulence (it needs none)."""
    if noisy(setup) != Disturbance.GUSTS:
        return None
    return without_disturbances(setup)


def twin_simulation(setup: Setup, loop: ClosedLoop) -> SimResult | None:
    """The run of ``loop`` its twin makes (:func:`twin_of`, :func:`simulation_of`); None without turbulence."""
    twin = twin_of(setup)
    return None if twin is None else simulation_of(twin, loop)


def twin_settling(setup: Setup, loop: ClosedLoop, calm: SimResult | None = None) -> dict | None:
    """The settling times of the regulated states in the run of ``loop`` its twin makes (``calm``, that run
    flown already: :func:`twin_simulation`; :func:`quadctl.metrics.settling_times`): what
    :func:`quadctl.metrics.summarize`'s ``twin`` takes. None without turbulence."""
    calm = twin_simulation(setup, loop) if calm is None else calm
    return None if calm is None else settling_times(calm, setup.regulated)


class Stages:
    """The chain of stages of one setup, each computed on first use and once (no I/O).

    trim -> linear -> decoupled -> design -> loop, and, for a continuous design run sampled at the
    controller rate, :attr:`rate_warnings`. :func:`quadctl.export.prepare` builds this chain from a setup
    (``prepare(stages.setup)``); :class:`quadctl.workspace.Workspace` (the command line, the report) is
    this chain with a run folder: it reuses and writes each stage's artifact.

    Parameters
    ----------
    setup : Setup
        :func:`quadctl.setup.setup_of` a config.
    trim, linear, decoupled : optional
        Upstream stages already computed for this setup's flight condition: the chain starts there.

    Raises
    ------
    ArgumentTypeError
        ``setup`` is not a :class:`~quadctl.setup.Setup`, or a given stage is not of its kind (a ``TypeError``).

    Examples
    --------
    >>> import quadctl as qc
    >>> stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    >>> stages.design.K_block.shape, stages.design.sample_time, stages.rate_warnings
    ((4, 12), None, ())

    A sweep's cases that fly one flight condition share its upstream stages: pass them
    (``Stages(setup, linear=..., decoupled=...)``) and the chain starts from there.
    """

    def __init__(self, setup: Setup, *, trim: Trim | None = None, linear: LinearModel | None = None,
                 decoupled: Decoupled | None = None):
        if not isinstance(setup, Setup):
            raise ArgumentTypeError(f"Stages takes a Setup, qc.Stages(qc.setup_of(qc.load_config('hover'))); got "
                                    f"{type(setup).__name__}")
        self.setup = setup
        given = {"trim": trim, "linear": linear, "decoupled": decoupled}
        kinds = {"trim": Trim, "linear": LinearModel, "decoupled": Decoupled}
        for stage, result in given.items():
            if result is not None and not isinstance(result, kinds[stage]):
                raise ArgumentTypeError(f"Stages: {stage} must be a {kinds[stage].__name__} (another Stages' "
                                        f"stages.{stage}), got {type(result).__name__}")
        self.__dict__.update({stage: result for stage, result in given.items() if result is not None})

    @cached_property
    def trim(self) -> Trim:
        return trim_of(self.setup)

    @cached_property
    def linear(self) -> LinearModel:
        return linear_of(self.setup, self.trim)

    @cached_property
    def decoupled(self) -> Decoupled:
        return decoupled_of(self.setup, self.linear)

    @cached_property
    def design(self) -> Design:
        return design_of(self.setup, self.decoupled, self.linear)

    @cached_property
    def rate_warnings(self) -> tuple:
        """:func:`rate_warnings_of` the controller rate when it runs a continuous design (emulation);
        ``()`` for a continuous or a discrete controller. Needs every regulated subsystem stabilizable."""
        timing = self.setup.timing
        if timing.mode != "emulated":
            return ()
        return tuple(rate_warnings_of(self.setup, self.decoupled, self.linear, timing.rate))

    @cached_property
    def loop(self) -> ClosedLoop:
        """The loop that flies: the LQR design's (:attr:`lqr_loop`), or the cascade's (``controller.flies: pid``)."""
        if self.setup.law == "pid":
            return pid_loop_of(self.setup, self.linear)
        return self.lqr_loop

    @cached_property
    def lqr_loop(self) -> ClosedLoop:
        """The LQR design's loop, whatever law flies."""
        return loop_of(self.setup, self.linear, self.design)

    @property
    def margins(self) -> list:
        """Margins of the loops of the law that flies: :attr:`lqr_margins`, or :attr:`pid_margins`
        (``controller.flies: pid``)."""
        return self.pid_margins if self.setup.law == "pid" else self.lqr_margins

    @cached_property
    def lqr_margins(self) -> list:
        """Margins of every regulated loop of the LQR design (design model, coupled, with the Kalman filter:
        :func:`quadctl.design.margin_findings.all_margins`), whatever law flies."""
        return margins_of(self.setup, self.linear, self.decoupled, self.design)

    @cached_property
    def pid_lift(self):
        """The setup's PID cascade linearized about hover, lifted to its frame
        (:func:`quadctl.sim.cascade_lift.lifted`)."""

        return lifted(self.pid_loop)

    @cached_property
    def pid_loop(self) -> ClosedLoop:
        """The setup's PID cascade's loop (:func:`pid_loop_of`), whatever law flies."""
        return self.loop if self.setup.law == "pid" else pid_loop_of(self.setup, self.linear)

    @cached_property
    def pid_margins(self) -> list:
        """Margins of the setup's PID cascade, each input's loop broken at the plant
        (:func:`quadctl.sim.cascade_margins.cascade_margins`)."""

        return cascade_margins(self.pid_loop, title=self.setup.pid.preset, lift=self.pid_lift)


@dataclass(frozen=True)
class VehicleLoop:
    """The linear closed loop the vehicle flies: the design's gains on the coupled model with the
    rotors' lag, the controller's lag model (a design that includes it), the integrators and the
    delay (:func:`quadctl.design.linear_loop.vehicle_matrix`), and the Kalman filter the law acts
    through when there is one (:func:`quadctl.design.lqg_loop.lqg_vehicle`), next to the loop the
    design saw.

    Attributes
    ----------
    eigenvalues : (n,) ndarray of complex
        ``s`` (rad/s), or ``z`` of a loop sampled every ``sample_time`` s.
    design_eigenvalues : (n,) ndarray of complex
        The loop as designed: without the delay, and without the rotors' lag unless the design includes it
        (what a design that ignores them sees); the full-state loop, or with a Kalman filter in the loop the
        regulator's and the filter's eigenvalues together (the separation principle).
    sample_time : float or None
    stable : bool
    least_damping, design_least_damping : float
        :func:`quadctl.linear.stability.least_damping` of each.

    Its sentences: :func:`quadctl.present.stages.vehicle_loop_summary` and, unstable,
    :func:`quadctl.present.stages.vehicle_loop_verdict`.
    """

    eigenvalues: np.ndarray
    design_eigenvalues: np.ndarray
    sample_time: float | None
    stable: bool
    least_damping: float
    design_least_damping: float
    rotor_time_constant: float | None = None
    rotor_lag: str = "ignore"
    delay_samples: int = 0
    gyro_filter: str = ""
    """What the gyro filter in the loop is (:meth:`quadctl.linear.filters.RateFilter.describe`); empty: none."""
    estimated: tuple[str, ...] = ()
    """The states a Kalman filter in the loop measures (the law acts on its estimate and ``eigenvalues``
    are the plant's and the filter's: :func:`quadctl.design.lqg_loop.lqg_vehicle`); empty: full state."""


def vehicle_loop_of(setup: Setup, linear: LinearModel, des: Design, *, estimator=None,
                    with_filter: bool = True) -> VehicleLoop:
    """:class:`VehicleLoop` of a design flown with the setup's rotors and delay, through the setup's Kalman
    filter when it has one (``estimator``: that filter, :func:`estimator_of` when None; ``with_filter``
    False: the full-state loop, for a measured set that cannot estimate the state, which has no filter)."""

    timing = setup.timing
    Ts = des.sample_time or (timing.sample_time if timing.mode == "emulated" else None)
    form = setup.rate_filter.form(Ts) if setup.rate_filter is not None else None
    kal = None if setup.estimator is None or not with_filter else \
        estimator if estimator is not None else estimator_of(setup, linear)
    if kal is not None:  # the loop that flies has the filter's dynamics too
        eig = np.linalg.eigvals(lqg_loop.lqg_vehicle(des, linear.A, linear.B, kal, timing.delay_samples,
                                                     setup.rotor_time_constant))
    else:
        eig = np.linalg.eigvals(linear_loop.vehicle_matrix(des, linear.A, linear.B, Ts, timing.delay_samples,
                                                           setup.rotor_time_constant, rate_filter=form))
    seen = setup.rotor_time_constant if des.lag_time_constant is not None else None
    if kal is not None:  # as designed: the regulator and the filter (the separation principle), as flown
        ideal = np.linalg.eigvals(lqg_loop.lqg_vehicle(des, linear.A, linear.B, kal, 0, seen))
    else:
        ideal = np.linalg.eigvals(linear_loop.vehicle_matrix(des, linear.A, linear.B, Ts, 0, seen))
    return VehicleLoop(eigenvalues=eig, design_eigenvalues=ideal, sample_time=Ts,
                       stable=bool(np.all(stability.is_stable(eig, discrete=Ts is not None))),
                       least_damping=stability.least_damping(eig, Ts),
                       design_least_damping=stability.least_damping(ideal, Ts),
                       rotor_time_constant=setup.rotor_time_constant, rotor_lag=setup.rotor_lag,
                       delay_samples=timing.delay_samples,
                       gyro_filter=setup.rate_filter.describe() if setup.rate_filter is not None else "",
                       estimated=tuple(kal.measured) if kal is not None else ())


def rate_warnings_of(setup: Setup, decoupled: Decoupled, linear: LinearModel, rate: float):
    """Loops of the *continuous* design that ``rate`` Hz cannot realize (``check``'s warning).

    Each subsystem (with its integrators) and the coupled loop are checked: the fastest
    continuous closed-loop pole against :func:`quadctl.design.discrete.realizable_frequency`, and the
    continuous gains run through a zero-order hold at ``rate`` (stable or not).

    Returns
    -------
    list of quadctl.design.discrete.RateWarning
    """

    des = design_at(setup, decoupled, linear, None)
    Ts = 1.0 / rate
    loops = []
    for sub in des.subsystems:
        sampled = linear_loop.close(*linear_loop.subsystem(sub, decoupled[sub.name], Ts))
        loops.append((sub.name, sub.eigenvalues, sampled))
    sampled = linear_loop.matrix(linear.A, linear.B, des.K_block, des.Ki_block, des.integral_states, Ts)
    keep = [i for i in range(sampled.shape[0])
            if i >= len(STATE_NAMES) or STATE_NAMES[i] not in des.marginal_states]
    loops.append(("coupled", des.core_eigenvalues, sampled[np.ix_(keep, keep)]))
    return discrete.rate_warnings(loops, rate)


def margins_of(setup: Setup, linear: LinearModel, decoupled: Decoupled, des: Design) -> list:
    """The margins of every regulated loop of a design as the setup flies it
    (:func:`quadctl.design.margin_findings.all_margins`): sampled at the controller's rate (a continuous
    design's gains emulated there), with the rotors' lag, the delay, the gyro filter and the setup's
    Kalman filter; what ``quadctl margins`` reports and a sweep's ``margin.*`` columns
    (:data:`quadctl.sweep.gates.MARGIN_COLUMNS`) take."""

    timing = setup.timing
    emulated = timing.rate if des.sample_time is None else None  # a continuous design, sampled (or None)
    return margin_findings.all_margins(
        des, decoupled, linear.A, linear.B, emulated_rate=emulated, actuators=setup.actuators, u_trim=linear.u_trim,
        initial_demand=initial_demand(setup, des), delay_samples=timing.delay_samples,
        rotor_time_constant=setup.rotor_time_constant, estimator=estimator_of(setup, linear),
        rate_filter=setup.rate_filter)


def initial_demand(setup: Setup, des: Design) -> dict[str, float]:
    """``|K (x0 - x_trim)|`` per input: what the configured initial offset asks for at t = 0."""
    du = des.K_block @ setup.initial_offset
    return {name: float(abs(du[j])) for j, name in enumerate(INPUT_NAMES)}
