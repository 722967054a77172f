"""The problem a config poses, in numbers, once: a frozen :class:`Setup` that every stage takes.

A config says things the way a user writes them (lists for diagonal weights, optional sections,
a rate that means a discrete or an emulated design). :func:`setup_of` turns it into the numbers
and decisions the stages use, once: the design vehicle and the simulated plant, the partition,
the weights per subsystem and as blocks, the integrators, the regulated states, the timing,
the actuators, the noise, the initial state and the simulation settings. No stage reads the
config after that.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property, lru_cache
from typing import Literal

import numpy as np

from quadctl.bryson import bryson_weights, weight_error
from quadctl.config import Config, ScheduleConfig, SubsystemConfig, inertia_parts, weight_matrix
from quadctl.config.pid import PidGains, resolve
from quadctl.config.simulation_schema import ETDRK4_TOLERANCE
from quadctl.errors import ArgumentError, ArgumentTypeError, RateError
from quadctl.layout import INPUT_INDEX, N_INPUTS, N_STATES, STATE_INDEX
from quadctl.linear.filters import RateFilter, rate_filter_of
from quadctl.physics import trajectory
from quadctl.physics.model import Vehicle
from quadctl.physics.motors import Actuators, Motors, actuators_of
from quadctl.physics.noise import NoiseSpec, exogenous_period
from quadctl.physics.reference_rows import FlownReference
from quadctl.physics.trajectory import Reference
from quadctl.physics.wind import WindSpec, wind_of


@dataclass(frozen=True)
class Timing:
    """When the controller acts.

    Attributes
    ----------
    rate : float or None
        Hz of a sampled controller (zero-order hold); None: continuous feedback.
    design_rate : float or None
        Hz the design is computed at: the controller's ``rate`` for a discrete design (MATLAB
        ``lqrd``, ``controller.design: discrete``); None for a continuous design, which a ``rate``
        then runs sampled (emulation). The design it gives says which it is
        (:attr:`quadctl.design.Design.sample_time`), as python-control's systems carry their ``dt``.
    delay_samples : int
        Controller samples from measurement to actuation (``controller.delay``; 0: none).
    """

    rate: float | None = None
    design_rate: float | None = None
    delay_samples: int = 0

    def __post_init__(self):
        if self.design_rate is not None and self.design_rate != self.rate:
            raise ArgumentError(f"Timing: design_rate {self.design_rate:g} Hz: a discrete design is computed at the "
                                f"controller's rate ({self.rate} Hz); give design_rate = rate, or None for a "
                                "continuous design")

    @property
    def mode(self) -> Literal["continuous", "discrete", "emulated"]:
        if self.rate is None:
            return "continuous"
        return "discrete" if self.design_rate is not None else "emulated"

    @property
    def sample_time(self) -> float | None:
        """s between controller samples; None for continuous feedback."""
        return None if self.rate is None else 1.0 / self.rate

    @property
    def design_sample_time(self) -> float | None:
        return None if self.design_rate is None else 1.0 / self.design_rate

    def refuse_other_rate(self, rate: float | None) -> None:
        """Refuse a command-line rate (``--rate``, Hz) that differs from the config's own
        ``controller.rate``: ``check`` and ``export`` run a continuous design at another rate
        only when the config sets none.

        Raises
        ------
        RateError
            ``rate`` given, and the config sets another rate (exit 2).
        """
        if rate is not None and self.rate is not None and rate != self.rate:

            raise RateError(f"--rate {rate:g}: the config sets controller.rate = {self.rate:g} Hz; drop --rate, "
                            "or remove controller.rate to run the continuous design at another rate")


@dataclass(frozen=True)
class EstimatorSpec:
    """What the Kalman filter measures and the noise it assumes (``estimator:`` in numbers).

    Attributes
    ----------
    measured : tuple of str
        Measured states, in state order (sensor groups expanded).
    sensor_std : (p,) ndarray
        Standard deviation of each measurement (state units): ``estimator.sensor``, else
        ``simulation.noise.sensor``.
    process_std : (6,) ndarray
        Body force (N, 3) and torque (N m, 3) standard deviations: ``estimator.force/torque``, else
        ``simulation.noise.force/torque``.
    period : float
        s the noise is held for (``simulation.noise.period``, else the controller period, else 5 ms):
        a held sample of std ``sigma`` has the low-frequency intensity ``sigma^2 period``, which the
        continuous (Kalman-Bucy) filter takes.
    """

    measured: tuple[str, ...]
    sensor_std: np.ndarray
    process_std: np.ndarray
    period: float


@dataclass(frozen=True, eq=False)
class Setup:
    """A config in numbers: what every stage reads.

    Attributes
    ----------
    name : str
    vehicle : Vehicle
        The design model's parameters.
    plant : Vehicle
        The simulated vehicle (``simulation.plant`` overrides: model mismatch).
    velocity_ned, position_ned : (3,) tuple of float
        The flight condition (m/s, m).
    yaw : float
        rad.
    partition : dict of str -> SubsystemConfig
        The subsystems in force.
    weights : dict of str -> (Q, R)
        Per regulated subsystem, as matrices; an LQI subsystem's Q also weighs its integrators.
    integral : dict of str -> tuple of str
        Per subsystem with integral action, the states it integrates.
    Q_block : (12, 12) ndarray
        The subsystems' plant-state weights assembled (the cost the metrics report).
    R_block : (4, 4) ndarray
    regulated : tuple of str
        States of the regulated subsystems, in partition order.
    state_owner : dict of str -> str
        State name -> its subsystem.
    timing : Timing
    actuators : Actuators or None
        Rotors (``motors:``), box limits (``limits:``) or None (unlimited).
    noise : NoiseSpec or None
        Active noise only (None when absent or all zero).
    wind : WindSpec or None
        The simulated wind (None when absent or all zero).
    trim_wind : (3,) tuple of float
        m/s NED: the steady wind the trim and the linear model are computed in (``trim.wind``; else zero).
    initial_offset : (12,) ndarray
        Offset of the initial state from the trim (state units).
    duration : float
        s.
    dt : float or "auto"
    max_samples : int
    method : {"rk4", "etdrk4"}
        The integrator (``simulation.method``).
    tolerance : float
        ETDRK4's ``dt: auto`` aim (``simulation.tolerance``, else its default).
    plant_overrides : dict
        The ``simulation.plant`` values given (empty: the plant is the design model).
    rotor_lag : {"ignore", "include"}
        What the design does with the rotors' lag (``controller.rotor_lag``).
    estimator : EstimatorSpec or None
        The Kalman filter's measurements and noise (``estimator:``); None: full-state feedback.
    reference : quadctl.physics.trajectory.Reference or None
        The path to fly (``simulation.reference``); None: hold the trim.
    schedule : quadctl.config.ScheduleConfig or None
        The gain schedule (``schedule:``: variable, values, interpolation, check); None: one design.
    rate_filter : quadctl.linear.filters.RateFilter or None
        The filters on the gyro (``controller.filters``), in the loop the vehicle has; None: raw rates.
    weight_error : str or None
        Why a Bryson rule (``lqr.<name>.bryson``) has no weights on this vehicle
        (:func:`quadctl.bryson.weight_error`): the design refuses the setup with it; None: every weight is a number.

    Examples
    --------
    >>> import quadctl as qc
    >>> setup = qc.setup_of(qc.load_config("hover"))
    >>> setup.regulated[:2], setup.duration, float(setup.initial_state(np.zeros(12))[2])
    (('pD', 'w'), 10.0, 0.5)
    """

    name: str
    vehicle: Vehicle
    plant: Vehicle
    velocity_ned: tuple[float, float, float]
    position_ned: tuple[float, float, float]
    yaw: float
    partition: dict[str, SubsystemConfig]
    weights: dict[str, tuple[np.ndarray, np.ndarray]]
    integral: dict[str, tuple[str, ...]]
    Q_block: np.ndarray
    R_block: np.ndarray
    regulated: tuple[str, ...]
    state_owner: dict[str, str]
    timing: Timing
    actuators: Actuators | None
    noise: NoiseSpec | None
    wind: WindSpec | None
    trim_wind: tuple[float, float, float]
    initial_offset: np.ndarray
    duration: float
    dt: float | str
    max_samples: int
    plant_overrides: dict = field(default_factory=dict)
    rotor_lag: str = "ignore"
    estimator: EstimatorSpec | None = None
    reference: Reference | None = None
    method: str = "rk4"
    tolerance: float = ETDRK4_TOLERANCE
    schedule: ScheduleConfig | None = None
    law: str = "lqr"
    """The law that flies (``controller.flies``): ``lqr`` (the design) or ``pid`` (:attr:`pid`)."""
    pid: PidGains | None = None
    """:class:`quadctl.config.pid.PidGains`: the config's PID cascade (``controller.pid``, else the
    ``crazyflie`` preset): what ``controller.flies: pid`` and ``quadctl compare`` fly."""
    rate_filter: RateFilter | None = None
    weight_error: str | None = None

    @cached_property
    def flown_reference(self) -> FlownReference | None:
        """The path to fly with the design model's feedforward (:class:`quadctl.physics.reference_rows.FlownReference`),
        made once per setup; None without ``simulation.reference``."""
        return None if self.reference is None else FlownReference(self.reference, self.vehicle.vector())

    @property
    def rotor_time_constant(self) -> float | None:
        """s of the rotors' lag in the simulated plant (``motors.time_constant``); None: instantaneous."""
        motors = self.actuators.motors if self.actuators is not None else None
        return motors.time_constant if motors is not None else None

    @property
    def design_lag_time_constant(self) -> float | None:
        """s of the rotors' lag the design model includes (``controller.rotor_lag: include``); None:
        the design's rotors are instantaneous."""
        return self.rotor_time_constant if self.rotor_lag == "include" else None

    def input_owner(self, name: str) -> str:
        """The subsystem whose input ``name`` is (``unassigned``: none)."""
        for sub_name, sub in self.partition.items():
            if name in sub.inputs:
                return sub_name
        return "unassigned"

    def initial_state(self, x_trim) -> np.ndarray:
        """(12,) trim state plus the configured initial offset.

        Raises
        ------
        ArgumentError
            ``x_trim`` is not the 12 states (``trim.x`` or ``loop.x_trim``).
        ArgumentTypeError
            ``x_trim`` is not numbers (a :class:`~quadctl.linear.trim.Trim` itself: give its ``x``).
        """
        try:
            x = np.asarray(x_trim, dtype=float)
        except (TypeError, ValueError):  # a Trim itself (its x is the state), text
            raise ArgumentTypeError(f"initial_state takes the {N_STATES} states of a trim (a Trim's x, or a loop's "
                                f"x_trim), got {type(x_trim).__name__}") from None
        if x.shape != (N_STATES,):
            raise ArgumentError(f"initial_state takes the {N_STATES} states of a trim (a Trim's x, or a loop's "
                                f"x_trim), got shape {x.shape}")
        return x + self.initial_offset


def setup_of(cfg: Config) -> Setup:
    """The :class:`Setup` every stage takes, from a validated config.

    Parameters
    ----------
    cfg : Config
        A validated config (:func:`quadctl.config.loading.load`).

    Returns
    -------
    Setup
        Every value the stages read, resolved once.

    Raises
    ------
    ArgumentTypeError
        ``cfg`` is not a :class:`~quadctl.config.schema.Config` (a name or a path: load it first).

    Examples
    --------
    >>> import quadctl as qc
    >>> setup = qc.setup_of(qc.load_config("hover"))
    >>> setup.timing.mode, setup.Q_block.shape, list(setup.weights)
    ('continuous', (12, 12), ['altitude', 'roll', 'pitch', 'yaw'])
    """
    if not isinstance(cfg, Config):
        raise ArgumentTypeError(f"setup_of takes a validated Config, qc.setup_of(qc.load_config('hover')); got "
                                f"{type(cfg).__name__}")
    v = cfg.vehicle
    diagonal, products = inertia_parts(v.inertia)
    vehicle = Vehicle(mass=v.mass, gravity=v.gravity, inertia=diagonal, drag=tuple(v.drag), products=products)
    over = cfg.simulation.plant
    overrides = over.model_dump(exclude_none=True) if over is not None else {}
    diagonal, products = inertia_parts(overrides["inertia"]) if "inertia" in overrides else (diagonal, products)
    plant = vehicle if not overrides else Vehicle(
        mass=overrides.get("mass", vehicle.mass), gravity=overrides.get("gravity", vehicle.gravity),
        inertia=diagonal, drag=tuple(overrides.get("drag", vehicle.drag)), products=products)
    partition = cfg.partition()
    trim_wind = tuple(float(w) for w in cfg.simulation.wind.steady) if cfg.trim.wind else (0.0, 0.0, 0.0)
    motors = Motors.from_config(cfg.motors) if cfg.motors is not None else None
    actuators = _rotors(motors) if motors is not None else actuators_of(None, cfg.limits)
    weights = {name: (weight_matrix(w.Q, 0), weight_matrix(w.R, 0)) for name, w in cfg.lqr.items()
               if w.bryson is None}
    weights.update(bryson_weights(cfg, vehicle, actuators, trim_wind))
    weights = {name: weights[name] for name in cfg.lqr}  # in the config's order
    unweighted = weight_error(cfg, weights)
    Q, R = _weight_blocks(partition, weights)
    offset = np.zeros(N_STATES)
    for state, value in cfg.simulation.initial_offset.items():
        offset[STATE_INDEX[state]] += value
    ctl = cfg.controller
    timing = Timing(rate=ctl.rate, design_rate=ctl.rate if ctl.design == "discrete" else None,
                    delay_samples=ctl.delay_samples())
    noise = None
    if cfg.simulation.noise is not None:
        spec = NoiseSpec.from_config(cfg.simulation.noise, timing.rate)
        noise = spec if spec.active else None
    wind = wind_of(cfg.simulation.wind, cfg.trim.velocity_ned, -cfg.trim.position_ned[2])
    return Setup(
        name=cfg.name, vehicle=vehicle, plant=plant, velocity_ned=tuple(cfg.trim.velocity_ned),
        position_ned=tuple(cfg.trim.position_ned), yaw=cfg.trim.yaw, partition=partition,
        weights=weights, integral={name: tuple(w.integral) for name, w in cfg.lqr.items() if w.integral},
        Q_block=Q, R_block=R,
        regulated=tuple(s for sub in partition.values() if sub.regulate for s in sub.states),
        state_owner={s: name for name, sub in partition.items() for s in sub.states},
        timing=timing, actuators=actuators, noise=noise, wind=wind, trim_wind=trim_wind, initial_offset=offset,
        duration=cfg.simulation.duration, dt=cfg.simulation.dt, max_samples=cfg.simulation.max_samples,
        plant_overrides=overrides, rotor_lag=ctl.rotor_lag, estimator=_estimator(cfg, timing),
        reference=_reference(cfg), method=cfg.simulation.method,
        tolerance=ETDRK4_TOLERANCE if cfg.simulation.tolerance is None else cfg.simulation.tolerance,
        schedule=cfg.schedule, law=ctl.flies, pid=_pid(cfg), rate_filter=rate_filter_of(ctl.filters),
        weight_error=unweighted)


def _pid(cfg: Config):
    """The config's PID cascade (:func:`quadctl.config.pid.resolve`), checked on load."""

    pid = cfg.controller.pid
    return resolve(pid.preset, pid.values, pid.attitude) if pid is not None else resolve("crazyflie")


def _reference(cfg: Config):
    """The path of ``simulation.reference`` (:mod:`quadctl.physics.trajectory`), from the trim's position,
    velocity and yaw; None without one."""
    ref = cfg.simulation.reference
    if ref is None:
        return None

    if ref.setpoints is not None:
        return trajectory.setpoint_reference([sp.model_dump() for sp in ref.setpoints], cfg.trim.position_ned,
                                             cfg.trim.velocity_ned, cfg.trim.yaw)
    return trajectory.mission_reference([wp.model_dump() for wp in ref.waypoints], cfg.trim.position_ned,
                                        cfg.trim.yaw, ref.speed, ref.tolerance, ref.trajectory)


def _estimator(cfg: Config, timing: Timing) -> EstimatorSpec | None:
    """``estimator:`` with the noise it takes from ``simulation.noise`` filled in (checked by the config)."""
    est, noise = cfg.estimator, cfg.simulation.noise
    if est is None:
        return None
    measured = est.measured()
    given = noise.sensor if noise is not None else {}
    zeros = [0.0, 0.0, 0.0]
    force = est.force if est.force is not None else (noise.force if noise is not None else zeros)
    torque = est.torque if est.torque is not None else (noise.torque if noise is not None else zeros)
    period = exogenous_period(noise.period if noise is not None else None, timing.rate)
    return EstimatorSpec(measured=measured,
                         sensor_std=np.array([est.sensor.get(s, given.get(s, 0.0)) for s in measured], float),
                         process_std=np.array([*force, *torque], float), period=float(period))


def vary(setup: Setup, n: int, weights: dict[str, tuple[np.ndarray | None, np.ndarray | None]] | None = None,
         noise_seeds=None) -> list[Setup]:
    """``n`` copies of ``setup``, each with some subsystems' weights or the noise seed replaced: what
    :func:`setup_of` gives for the config with those values, without validating and resolving all
    of it again (a sweep builds thousands of cases from one base this way, a chunk at once).

    Parameters
    ----------
    setup : Setup
    n : int
        Setups to make.
    weights : dict of str -> (Q, R), optional
        Per subsystem, its weight matrices, one a case: ``(n, size, size)`` arrays (None: as in
        ``setup``), already checked (:func:`quadctl.config.check_weight`): the caller validates.
        Each setup holds its case's slice of them.
    noise_seeds : sequence of int, optional
        Per case, ``simulation.noise.seed`` (a whole number >= 0).
    """
    cases: list[dict] = [{} for _ in range(n)]
    if weights:
        Q_block, R_block = _weight_blocks(setup.partition, weights, setup, n)
        names = list(weights)
        for k, changes in enumerate(cases):
            merged = dict(setup.weights)
            for name in names:
                Q, R = weights[name]
                old_Q, old_R = merged[name]
                merged[name] = (old_Q if Q is None else Q[k], old_R if R is None else R[k])
            changes.update(weights=merged, Q_block=Q_block[k], R_block=R_block[k])
    if noise_seeds is not None and setup.noise is not None:
        noises: dict[int, NoiseSpec] = {}  # frozen: cases drawing one seed share it
        for seed, changes in zip(noise_seeds, cases):
            if seed not in noises:
                noises[seed] = replace(setup.noise, seed=int(seed))
            changes["noise"] = noises[seed]
    return [_replaced(setup, changes) if changes else setup for changes in cases]


def without_disturbances(setup: Setup) -> Setup:
    """``setup`` without its random disturbances: no noise (``simulation.noise``) and the wind without
    its turbulence (the steady wind and the gusts kept; None when nothing is left). Everything else
    is the same, the flown reference (:attr:`Setup.flown_reference`) shared: the run a turbulent one is
    read against (:func:`quadctl.pipeline.twin_of`).

    >>> import quadctl as qc
    >>> setup = qc.setup_of(qc.load_config("crazyflie-wind"))
    >>> calm = without_disturbances(setup)
    >>> calm.wind.turbulence is None, calm.wind.steady == setup.wind.steady, calm.noise
    (True, True, None)
    """
    wind = setup.wind
    if wind is not None:
        wind = replace(wind, turbulence=None)
        wind = wind if wind.active else None
    return _replaced(setup, {"noise": None, "wind": wind})


def _replaced(setup: Setup, changes: dict) -> Setup:
    """``dataclasses.replace(setup, **changes)`` without running ``Setup.__init__`` again (six times
    faster: a sweep builds thousands of cases; Setup derives nothing from its fields)."""
    unknown = changes.keys() - setup.__dataclass_fields__.keys()
    if unknown:
        raise TypeError(f"Setup has no fields {sorted(unknown)}")
    new = object.__new__(Setup)
    new.__dict__.update(setup.__dict__, **changes)
    return new


def _weight_blocks(partition, weights, base: Setup | None = None, n: int | None = None):
    """(Q (12, 12), R (4, 4)): the regulated subsystems' plant-state weights assembled; with a
    ``base`` setup, ``n`` cases' (Q (n, 12, 12), R (n, 4, 4)): its blocks with only the subsystems
    in ``weights`` rewritten (their (n, size, size) matrices, or None: unchanged; the subsystems'
    blocks do not overlap: a state belongs to one subsystem, an input drives one)."""
    if base is None:
        Q, R = np.zeros((N_STATES, N_STATES)), np.zeros((N_INPUTS, N_INPUTS))
        lead: tuple = ()
    else:
        Q, R = np.repeat(base.Q_block[None], n, axis=0), np.repeat(base.R_block[None], n, axis=0)
        lead = (slice(None),)
    for name, sub in partition.items():
        if name in weights:
            (qi, qj, size), (ri, rj) = _block_index(tuple(sub.states), tuple(sub.inputs))
            Qw, Rw = weights[name]
            if Qw is not None:
                Q[(*lead, qi, qj)] = Qw[..., :size, :size]
            if Rw is not None:
                R[(*lead, ri, rj)] = Rw
    return Q, R


@lru_cache(maxsize=64)
def _block_index(states: tuple[str, ...], inputs: tuple[str, ...]):
    """``np.ix_`` index pairs of a subsystem's block in Q (with its size) and in R (a sweep resolves
    thousands of cases of one partition)."""
    si = [STATE_INDEX[s] for s in states]
    ii = [INPUT_INDEX[i] for i in inputs]
    return (*np.ix_(si, si), len(si)), np.ix_(ii, ii)


@lru_cache(maxsize=64)
def _rotors(motors: Motors) -> Actuators:
    """The actuators of a rotor set (its mixer inverted once; the arrays are only read)."""
    return actuators_of(motors, None)
