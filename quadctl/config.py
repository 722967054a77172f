"""The YAML config: schema, validation, loading and the bundled configs.

A config is validated whole on load: unknown keys are refused (with the nearest valid
key suggested), numbers must be finite, names must exist, and every error is one
:class:`~quadctl.errors.ConfigError` line naming the file, the key path, the value
and what is allowed.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import os
import re
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, NamedTuple, Optional, Union

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from quadctl import yamlio
from quadctl.errors import ConfigError
from quadctl.layout import INPUT_NAMES, REPORT_PARTITION, SENSOR_GROUPS, STATE_NAMES, STATE_UNITS
from quadctl.messages import hint as _hint
from quadctl.messages import key_path, show
from quadctl.messages import unknown as _unknown

DEFAULT_CONFIG = "forward"
"""Bundled config used when no ``--config`` is given: the report's forward-flight case."""

NAME_PATTERN = r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$"
"""A config's name: one folder name inside ``runs/`` (no separator, not ``.`` or ``..``)."""

SUBSYSTEM_NAME_PATTERN = r"^[A-Za-z][A-Za-z0-9_]{0,62}$"
"""A subsystem's name: a letter, then letters, digits or ``_``, at most 63 characters. One rule for
everything that uses the name: file names (``plots/<name>.png``, the report's figures), HTML ids,
C identifiers and MATLAB struct fields (``.mat``: at most 63 characters)."""

Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Positive = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0)]
NonNegative = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0)]
Vector3 = Annotated[list[Number], Field(min_length=3, max_length=3)]
Matrix = Union[list[Number], list[list[Number]]]


MASS_RANGE = (1e-4, 1e4)
"""kg: from a 0.1 g robot to ten tonnes (the heaviest multirotors weigh about one). Outside it
the input matrix (1/m) loses its digits and the design reports a false "not stabilizable"."""
MAX_GRAVITY = 100.0
"""m/s^2: ten g (Jupiter's is 24.8). 1e300 overflowed the controllability test."""
MAX_DRAG = 100.0
"""1/(m/s): 450 times the Mambo's 0.22. 1e300 overflowed the controllability test."""
MAX_RATE = 1e5
"""Hz: ten times the fastest flight controllers' loops (8 to 32 kHz)."""
MAX_NOISE = {"force": 1e4, "torque": 1e3}
"""Standard deviation of the process noise, N and N m: far past any gust; 1e300 overflowed the
run's error statistics."""
MAX_ROTOR_TIME_CONSTANT = 1.0
"""s: ten times the slowest small-rotor lags (brushless rotors reach their command in 10 to 100 ms);
a rotor slower than this cannot hold a vehicle's attitude, and LQR on the rigid body means nothing."""
RotorTimeConstant = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=MAX_ROTOR_TIME_CONSTANT)]
Mass = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=MASS_RANGE[0], le=MASS_RANGE[1])]
Gravity = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=MAX_GRAVITY)]
Drag = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0, le=MAX_DRAG)]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


INERTIA_DESCRIPTION = ("kg m^2: the diagonal [Jxx, Jyy, Jzz], or the full symmetric tensor J as 3 rows "
                       "[[Jxx, Jxy, Jxz], [Jxy, Jyy, Jyz], [Jxz, Jyz, Jzz]] (its entries: Jxy = -integral of x y dm)")


def inertia_parts(value: list) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """A validated ``inertia`` as its diagonal ``(Jxx, Jyy, Jzz)`` and off-diagonal ``(Jxy, Jxz, Jyz)``, kg m^2.

    Examples
    --------
    >>> inertia_parts([1.0, 2.0, 3.0])
    ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0))
    >>> inertia_parts([[1.0, 0.1, 0.2], [0.1, 2.0, 0.3], [0.2, 0.3, 3.0]])
    ((1.0, 2.0, 3.0), (0.1, 0.2, 0.3))
    """
    if value and isinstance(value[0], list):
        return ((float(value[0][0]), float(value[1][1]), float(value[2][2])),
                (float(value[0][1]), float(value[0][2]), float(value[1][2])))
    return tuple(float(v) for v in value), (0.0, 0.0, 0.0)


class VehicleConfig(_Section):
    """Vehicle parameters, SI units."""

    mass: Mass = Field(0.068, description="kg")
    gravity: Gravity = Field(9.81, description="m/s^2")
    inertia: Matrix = Field([0.69e-4, 0.775e-4, 1.5e-4], description=INERTIA_DESCRIPTION)
    drag: Annotated[list[Drag], Field(min_length=3, max_length=3)] = Field(
        [0.22, 0.22, 0.0], description="Kc diagonal; rotor drag force is -T Kc V_b (1/(m/s))")


class TrimConfig(_Section):
    """The flight condition to trim about."""

    velocity_ned: Vector3 = Field([0.0, 0.0, 0.0], description="m/s, earth frame (down positive)")
    position_ned: Vector3 = Field([0.0, 0.0, -1.0], description="m; altitude 1 m is pD = -1")
    yaw: Number = Field(0.0, description="rad, heading psi")
    wind: bool = Field(False, description=(
        "true: trim in the steady wind simulation.wind.steady (the vehicle holds velocity_ned over the "
        "ground, tilted into the wind), and linearize there; false: trim in still air"))


class SubsystemConfig(_Section):
    """One block of the partition: its states, its inputs, and whether it is regulated."""

    states: Annotated[list[str], Field(min_length=1)] = Field(
        description="state names (pN pE pD u v w phi theta psi p q r), each in one subsystem")
    inputs: Annotated[list[str], Field(min_length=1)] = Field(
        description="input names (T A E R), each driving one regulated subsystem; an unregulated "
        "subsystem may name states (their columns come from A)")
    regulate: bool = Field(True, description="false: analysed only, no LQR")
    outputs: list[str] | None = Field(None, description="measured states (C rows); default all")


class LqrWeights(_Section):
    """LQR weights of one subsystem: a list is a diagonal, a nested list a full matrix.

    With ``integral`` (LQI, as MATLAB ``lqi``), ``Q`` weighs ``[states; integrals]``: it has one
    entry more per integrated state, in the order of ``integral``.
    """

    Q: Matrix = Field(description=(
        "state weights, 1/(state unit)^2 (Bryson: 1 / largest acceptable error^2): a list is the diagonal "
        "(one per state, then one per integral), a list of rows the symmetric positive semidefinite matrix"))
    R: Matrix = Field(description=(
        "input weights, 1/(input unit)^2, i.e. 1/N^2 or 1/(N m)^2: a list is the diagonal, a list of rows "
        "the symmetric positive definite matrix"))
    integral: list[str] = Field(
        default_factory=list, description="states of this subsystem whose error is integrated (LQI)")


class NoiseConfig(_Section):
    """Process and sensor noise: zero-mean Gaussian, drawn every ``period`` and held in between."""

    seed: Annotated[int, Field(strict=True, ge=0)] = Field(0, description="random seed; same seed, same run")
    force: Annotated[list[Annotated[NonNegative, Field(le=MAX_NOISE["force"])]], Field(min_length=3, max_length=3)] \
        = Field([0.0, 0.0, 0.0], description="N, standard deviation of the body-frame force disturbance")
    torque: Annotated[list[Annotated[NonNegative, Field(le=MAX_NOISE["torque"])]], Field(min_length=3, max_length=3)] \
        = Field(
        [0.0, 0.0, 0.0], description="N m, standard deviation of the body torque disturbance")
    sensor: dict[str, NonNegative] = Field(
        default_factory=dict, description="state name -> standard deviation of its measurement (state units)")
    period: Optional[Positive] = Field(
        None, description="s between noise samples; default the controller period, or 5 ms if continuous")


MAX_WIND = 50.0
"""m/s per axis of a steady wind or a gust: past hurricane force (33 m/s) and twice the severe
turbulence's 45 kt at 20 ft; larger is a unit slip (km/h, knots)."""
MAX_GUSTS = 100
"""Gusts of one run: a gust every 0.1 s of a 10 s run; more belongs in turbulence."""
MAX_SCHEDULE_POINTS = 1000
"""Most values a gain schedule may list (each is a trim and a design)."""
MAX_TURBULENCE_SIGMA = 20.0
"""m/s: above the severe low-altitude intensity (4.5 m/s vertical, 9 m/s along the wind at 10 ft)."""
TURBULENCE_LENGTH = (1.0, 1e4)
"""m: turbulence scales from a metre (at the ground) to MIL-HDBK-1797's high-altitude 1750 ft and beyond;
shorter makes the turbulence white at the step, longer a steady wind."""
MAX_WIND_ALTITUDE = 304.8
"""m: the top of the low-altitude Dryden model (1000 ft, MIL-HDBK-1797 §B.4.4.1)."""

WindComponent = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=-MAX_WIND, le=MAX_WIND)]
WindVector = Annotated[list[WindComponent], Field(min_length=3, max_length=3)]


class GustConfig(_Section):
    """A 1-cosine gust (MIL-F-8785C §3.7.3.4), in time: rises over ``length``, holds, falls back."""

    start: NonNegative = Field(description="s, when the gust begins")
    length: Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=3600)] = Field(
        description="s to rise from 0 to the amplitude (and to fall back)")
    amplitude: WindVector = Field(description="m/s, the gust's peak wind, NED")
    hold: Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0, le=86_400.0)] = Field(
        0.0, description="s at the amplitude between rise and fall; past the run's end: the specification's gust, "
        "which stays")


class TurbulenceConfig(_Section):
    """Dryden turbulence (MIL-HDBK-1797 low altitude): an intensity and altitude, or sigma and length_scale."""

    intensity: Optional[Literal["light", "moderate", "severe"]] = Field(
        None, description="wind at 20 ft of 15, 30 or 45 kt (sigma_w = 0.1 W20); or give sigma and length_scale")
    altitude: Optional[Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=MAX_WIND_ALTITUDE)]] = Field(
        None, description="m above ground for the intensity's scales (at least 10 ft); default the trim's altitude")
    sigma: Optional[Annotated[list[Annotated[NonNegative, Field(le=MAX_TURBULENCE_SIGMA)]],
                              Field(min_length=3, max_length=3)]] = Field(
        None, description="m/s, standard deviations [along the mean wind, across it, down]")
    length_scale: Optional[Annotated[list[Annotated[float, Field(
        strict=True, allow_inf_nan=False, ge=TURBULENCE_LENGTH[0], le=TURBULENCE_LENGTH[1])]],
        Field(min_length=3, max_length=3)]] = Field(
        None, description="m, [L_u, L_v, L_w] of MIL-HDBK-1797's \"2L\" Dryden form (L_v, L_w half of "
        "MIL-F-8785C's)")
    airspeed: Optional[Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=100)]] = Field(
        None, description="m/s turning the spatial spectra into time; default the trim's airspeed, at least 1 m/s")
    seed: Annotated[int, Field(strict=True, ge=0)] = Field(0, description="random seed; same seed, same wind")


class WindConfig(_Section):
    """Wind: steady, gusts and turbulence, summed; acts through the rotor drag on the air-relative velocity."""

    steady: WindVector = Field([0.0, 0.0, 0.0], description="m/s, the air's velocity over the ground, NED")
    gusts: Annotated[list[GustConfig], Field(max_length=MAX_GUSTS)] = Field(
        default_factory=list, description="1-cosine gusts (MIL-F-8785C)")
    turbulence: Optional[TurbulenceConfig] = Field(None, description="Dryden turbulence; absent: none")


class PlantConfig(_Section):
    """The simulated vehicle where it differs from the design model (model mismatch)."""

    mass: Optional[Mass] = Field(None, description="kg")
    gravity: Optional[Gravity] = Field(None, description="m/s^2")
    inertia: Optional[Matrix] = Field(None, description=INERTIA_DESCRIPTION)
    drag: Optional[Annotated[list[Drag], Field(min_length=3, max_length=3)]] = Field(
        None, description="Kc diagonal, 1/(m/s)")


class SetpointConfig(_Section):
    """A step of the reference at time ``t``: any of position, velocity and yaw (the others continue)."""

    t: NonNegative = Field(description="s, from the start of the run; increasing along the list")
    position: Optional[Vector3] = Field(None, description="m, NED")
    velocity: Optional[Vector3] = Field(None, description="m/s, NED")
    yaw: Optional[Number] = Field(None, description="rad")


class WaypointConfig(_Section):
    """A waypoint of a mission, flown to in order."""

    position: Vector3 = Field(description="m, NED")
    yaw: Optional[Number] = Field(None, description="rad; absent: the previous waypoint's (or the trim's)")
    hold: NonNegative = Field(0.0, description="s to stay at the waypoint before the next leg")


class ReferenceConfig(_Section):
    """A reference to fly: setpoint steps, or a waypoint mission with its feedforward."""

    setpoints: Optional[list[SetpointConfig]] = Field(
        None, description="steps of position, velocity and yaw at given times")
    waypoints: Optional[list[WaypointConfig]] = Field(None, description="a mission from the trim position, in order")
    speed: Positive = Field(1.0, description="m/s: the peak speed of each leg of a mission")
    tolerance: Positive = Field(0.1, description="m: a waypoint counts as reached within this distance")
    trajectory: Literal["minimum-jerk", "minimum-snap", "step"] = Field(
        "minimum-jerk", description="the shape of each leg (step: the reference jumps to the waypoint)")


class SimulationConfig(_Section):
    """Closed-loop simulation settings."""

    duration: Positive = Field(10.0, description="s")
    dt: Union[Literal["auto"], Positive] = Field("auto", description="s, or auto")
    initial_offset: dict[str, Number] = Field(
        default_factory=dict, description="state name -> offset from trim (state units)")
    noise: Optional[NoiseConfig] = Field(None, description="process and sensor noise; absent: none")
    wind: Optional[WindConfig] = Field(None, description="steady wind, gusts and turbulence; absent: still air")
    plant: Optional[PlantConfig] = Field(
        None, description="simulated vehicle parameters that differ from vehicle: (model mismatch)")
    max_samples: Annotated[int, Field(strict=True, ge=2)] = Field(
        20_000, description="samples kept (every k-th RK4 step and the last) for sim.npz, metrics and plots")
    reference: Optional[ReferenceConfig] = Field(
        None, description="setpoints or waypoints to fly; absent: hold the trim (moving with its velocity)")
    method: Literal["rk4", "etdrk4"] = Field(
        "rk4", description="rk4: classical Runge-Kutta, its step held stable by the fastest loop; etdrk4: "
        "exponential Runge-Kutta (Hochbruck-Ostermann, order 4) exact on the loop's linearization, dt: auto a "
        "graded step schedule (a sampled controller's plant between samples)")
    tolerance: Optional[Annotated[Positive, Field(ge=1e-14, le=1e-2)]] = Field(
        None, description="etdrk4 with dt: auto: the error the step schedule aims at (state units); absent: 1e-08")


MAX_DELAY_SAMPLES = 100
"""Controller samples of delay: half a second at 200 Hz, far past any loop that still flies (the
delay margin of a 200 Hz attitude loop is a few samples); each sample is four buffer states."""
DELAY_SAMPLES_TOL = 1e-9
"""A delay in seconds is a whole number of samples when ``delay * rate`` is within this (relative)
of an integer: float round-off of ``0.005 * 200``, never a real fraction of a sample."""


class DelaySamples(_Section):
    """A delay given in controller samples."""

    samples: Annotated[int, Field(strict=True, ge=0, le=MAX_DELAY_SAMPLES)] = Field(
        description="controller samples from measurement to actuation")


class ScheduleConfig(_Section):
    """A gain schedule (``quadctl schedule``): trim and design at each value of one variable."""

    variable: Literal["speed", "climb", "yaw"] = Field(description=(
        "speed: m/s along the trim's heading; climb: m/s, up positive; yaw: rad"))
    values: Annotated[list[Number], Field(min_length=2, max_length=MAX_SCHEDULE_POINTS)] = Field(
        description="the scheduling values to trim and design at, in increasing order, in the variable's unit")
    interpolation: Literal["nearest", "linear", "cubic"] = Field(
        "linear", description="nearest, linear or cubic (a not-a-knot spline): how gains are interpolated between "
        "values; outside them the end point's gain holds")
    check: Annotated[int, Field(strict=True, ge=1, le=64)] = Field(
        4, description="the frozen-point stability check splits each interval between values into this many")


class ControllerConfig(_Section):
    """How the controller runs on the flight computer."""

    rate: Optional[Annotated[Positive, Field(le=MAX_RATE)]] = Field(
        None, description="Hz; absent: continuous feedback, as in the report")
    design: Literal["discrete", "continuous"] = Field(
        "discrete", description="with a rate: discrete LQR at that rate (lqrd), or the continuous LQR "
        "run at that rate (emulation)")
    rotor_lag: Literal["ignore", "include"] = Field(
        "ignore", description="ignore: the design model's rotors are instantaneous (motors.time_constant lags "
        "the simulated plant only); include: the design model's inputs lag by motors.time_constant, and the "
        "controller feeds back its own model of the lag, propagated from its commands")
    delay: Optional[Union[NonNegative, DelaySamples]] = Field(
        None, description="s (a whole number of samples at the rate) or {samples: n}: from measurement to "
        "actuation; needs a rate; absent: none")

    def delay_samples(self) -> int:
        """Samples of delay (0 when none); :func:`_check_delay` has checked it is whole."""
        if self.delay is None:
            return 0
        if isinstance(self.delay, DelaySamples):
            return self.delay.samples
        return round(self.delay * self.rate) if self.rate is not None else 0


class MotorsConfig(_Section):
    """Four rotors; defaults: the Parrot Mambo (docs/model.md, "Motors")."""

    layout: Literal["x", "+"] = Field("x", description="x: rotors at +-45 deg from the nose; +: on the axes")
    arm_length: Positive = Field(0.0624, description="m, from the centre to each rotor axis")
    thrust_coefficient: Positive = Field(4.72e-8, description="N/(rad/s)^2, rotor thrust = k omega^2")
    torque_coefficient: Positive = Field(0.00241, description="N m of yaw reaction torque per N of thrust")
    min_thrust: NonNegative = Field(0.0, description="N per rotor")
    max_thrust: Positive = Field(0.33, description="N per rotor")
    time_constant: Optional[RotorTimeConstant] = Field(
        None, description="s, first-order lag of each rotor's thrust behind its command; absent: instantaneous")
    numbering: Union[Literal["quadctl", "crazyflie", "px4", "betaflight"], list[str]] = Field(
        "quadctl", description="the vehicle's motor order, rotor 1 first: a flight stack's quad-x order (crazyflie = "
        "quadctl: front_right, rear_right, rear_left, front_left; px4: front_right, rear_left, front_left, rear_right; "
        "betaflight: rear_right, front_right, rear_left, front_left) or 4 positions (x: front_right, rear_right, "
        "rear_left, front_left; +: front, right, rear, left)")
    spin: Optional[Annotated[list[Literal["cw", "ccw"]], Field(min_length=4, max_length=4)]] = Field(
        None, description="each rotor's turning direction seen from above, rotor 1 first (cw or ccw); absent: front "
        "right (front, in +) and its diagonal ccw, the others cw, as every preset's default")


class EstimatorConfig(_Section):
    """A steady-state Kalman filter: the loop closes through its estimate instead of the measured state."""

    measure: Annotated[list[str], Field(min_length=1)] = Field(description=(
        "measured quantities: state names or sensor groups (imu: phi theta psi p q r; baro: pD; "
        "mocap, gps: pN pE pD; flow: u v)"))
    sensor: dict[str, Positive] = Field(default_factory=dict, description=(
        "state name -> standard deviation of its measurement the filter assumes (state units); default "
        "simulation.noise.sensor's; every measured state needs one of the two, > 0"))
    force: Optional[Annotated[list[Annotated[NonNegative, Field(le=MAX_NOISE["force"])]],
                              Field(min_length=3, max_length=3)]] = Field(
        None, description="N, standard deviation of the body force process noise the filter assumes; "
        "default simulation.noise.force")
    torque: Optional[Annotated[list[Annotated[NonNegative, Field(le=MAX_NOISE["torque"])]],
                               Field(min_length=3, max_length=3)]] = Field(
        None, description="N m, standard deviation of the body torque process noise the filter assumes; "
        "default simulation.noise.torque")

    def measured(self) -> tuple[str, ...]:
        """The measured states, in state order (groups expanded)."""
        names = {s for item in self.measure for s in SENSOR_GROUPS.get(item, (item,))}
        return tuple(s for s in STATE_NAMES if s in names)


InputLimits = Annotated[list[Number], Field(min_length=2, max_length=2)]


class Config(_Section):
    """A whole quadctl config (see the README's config reference)."""

    name: Annotated[str, Field(min_length=1, pattern=NAME_PATTERN)] = Field(
        description="names the run directory runs/<name>")
    description: str = Field("", description="one line, shown by `quadctl configs`")
    vehicle: VehicleConfig = Field(VehicleConfig(), description="vehicle parameters, SI units")
    trim: TrimConfig = Field(TrimConfig(), description="the flight condition to trim about")
    subsystems: dict[str, SubsystemConfig] | None = Field(
        None, description="subsystem name -> states and inputs; absent: the report's five (replaced whole)")
    lqr: dict[str, LqrWeights] = Field(description="regulated subsystem name -> its LQR weights Q and R")
    simulation: SimulationConfig = Field(SimulationConfig(), description="closed-loop simulation settings")
    controller: ControllerConfig = Field(
        ControllerConfig(), description="how the controller runs on the flight computer")
    motors: Optional[MotorsConfig] = Field(None, description="rotor layout and thrust limits; saturates the inputs")
    limits: Optional[dict[str, InputLimits]] = Field(
        None, description="input name -> [low, high] (N or N m); box limits when there is no motors:")
    estimator: Optional[EstimatorConfig] = Field(
        None, description="state estimation (LQG): what is measured and the noise the Kalman filter assumes; "
        "absent: the controller measures the full state")
    schedule: Optional[ScheduleConfig] = Field(
        None, description="a gain schedule across the envelope (quadctl schedule); absent: one design")
    allow: list[Literal["implausible", "saturation"]] = Field(
        default_factory=list, description="failed checks this vehicle accepts (each otherwise exits 1): implausible "
        "(values that look like a unit slip: the warnings on load), saturation (a simulated design at an "
        "actuator limit more than half the run)")

    def partition(self) -> dict[str, SubsystemConfig]:
        """The subsystems in force: the config's, or the report's five."""
        if self.subsystems is not None:
            return dict(self.subsystems)
        return {k: SubsystemConfig(**v) for k, v in REPORT_PARTITION.items()}

    def digest(self) -> str:
        """sha256 of the validated config (canonical JSON): the provenance of every artifact.

        Keys added to the schema later are left out at their default (:data:`LATER_KEYS`), so a config
        that does not use them keeps the digest it always had.
        """
        data = self.model_dump(mode="json")
        for path, default in LATER_KEYS:
            *parents, last = path
            node = data
            for part in parents:
                node = node.get(part) if isinstance(node, dict) else None
            if isinstance(node, dict) and node.get(last, default) == default:
                node.pop(last, None)
        text = json.dumps(data, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    def to_yaml(self) -> str:
        """The validated config as YAML (all defaults filled in)."""
        return yaml.safe_dump(self.model_dump(mode="json"), sort_keys=False)


LATER_KEYS: tuple[tuple[tuple[str, ...], Any], ...] = (
    (("allow",), []),
    (("motors", "numbering"), "quadctl"),
    (("motors", "spin"), None),
    (("simulation", "reference"), None),
    (("simulation", "method"), "rk4"),
    (("simulation", "tolerance"), None),
    (("schedule",), None),
)
"""Keys added to the schema after configs were already hashed, with their defaults: left out of
:meth:`Config.digest` at that default."""


def shown_yaml(cfg: Config, label: str) -> str:
    """:meth:`Config.to_yaml` for a reader (``quadctl configs --show``): a header pointing to
    ``quadctl init`` for a vehicle of one's own, and each key left empty (``null``) followed by what
    its absence means (the schema's description: ``motors: null   # rotor layout and thrust limits; ...``).

    Examples
    --------
    >>> text = shown_yaml(load("hover"), "hover.yaml")
    >>> [line[:48] for line in text.splitlines() if line.startswith("motors:")]
    ['motors: null   # rotor layout and thrust limits;']
    """
    lines = [f"# {label}, validated, every default filled in. For a vehicle of your own start from",
             "# `quadctl init NAME --from crazyflie|mambo|iris`: every key with its unit, a named vehicle's values."]
    path: list[tuple[int, str]] = []
    for line in cfg.to_yaml().splitlines():
        match = re.match(r"^( *)([A-Za-z_][\w.-]*): ?(.*)$", line)
        if match is None:
            lines.append(line)
            continue
        indent, key, value = len(match.group(1)), match.group(2), match.group(3)
        path = [(i, k) for i, k in path if i < indent] + [(indent, key)]
        if value == "null":
            keys = [k for _, k in path]
            parent = _section_model(keys[:-1])
            field = parent.model_fields.get(key) if parent is not None else None
            if field is not None and field.description:
                line += f"   # {field.description}{TOP_LEVEL_ABSENT.get(key, '') if len(keys) == 1 else ''}"
        lines.append(line)
    return "\n".join(lines) + "\n"


TOP_LEVEL_ABSENT = {"motors": "; absent: the inputs are not limited (`quadctl init NAME` writes motors: with units)",
                    "limits": "; absent: none"}
"""What an absent top-level section means, for :func:`shown_yaml`."""


SCHEMA_DIALECT = "http://json-schema.org/draft-07/schema#"
"""The JSON Schema draft the schema declares: draft-07, the one editors validate YAML with
(yaml-language-server); pydantic's output uses nothing newer once its ``$defs`` are renamed."""


def json_schema() -> dict:
    """The config's JSON Schema, for editors (completion, hover, checks as you type) and validators.

    Built from the schema itself (:meth:`Config.model_json_schema`): types, bounds, enums, unknown
    keys refused (``additionalProperties: false``), and each field's description with its unit.
    For editors, which show a field's description on hover but not its default, the default is
    appended to the description (``"kg; default 0.068"``); ``$defs`` become draft-07's
    ``definitions``. Rules across fields (Q's size, state names, Jxx + Jyy >= Jzz) are checked only
    when quadctl loads the config.

    Returns
    -------
    dict
        A draft-07 JSON Schema (``quadctl configs --schema`` prints it).

    Examples
    --------
    >>> json_schema()["properties"]["vehicle"]["$ref"]
    '#/definitions/VehicleConfig'
    """
    schema = Config.model_json_schema()
    schema["definitions"] = schema.pop("$defs")

    def visit(node):
        if isinstance(node, dict):
            ref = node.get("$ref")
            if isinstance(ref, str) and ref.startswith("#/$defs/"):
                node["$ref"] = "#/definitions/" + ref[len("#/$defs/"):]
            default = node.get("default")
            if isinstance(node.get("description"), str) and default not in (None, "", [], {}) \
                    and not isinstance(default, dict):
                node["description"] += f"; default {json.dumps(default)}"
            for value in node.values():
                visit(value)
        elif isinstance(node, list):
            for value in node:
                visit(value)

    visit(schema)
    return {"$schema": SCHEMA_DIALECT, "title": "quadctl config", **{k: v for k, v in schema.items()
                                                                     if k != "title"}}


# ---------------------------------------------------------------------------------------
# Loading


class Source(NamedTuple):
    """Where a ``--config`` value led: the file to name in errors, its text, and a note when the
    name could have meant something else (a file here and a bundled config of that name)."""

    label: str
    text: str
    note: str | None = None


def bundled_names() -> list[str]:
    """Names of the configs that ship with quadctl (without ``.yaml``)."""
    folder = resources.files("quadctl") / "configs"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def bundled(name: str) -> Source:
    """A bundled config by name (``forward``), whatever files the working folder holds."""
    res = resources.files("quadctl") / "configs" / f"{name}.yaml"
    return Source(f"{name}.yaml", res.read_text(encoding="utf-8"))


def locate(spec: str | Path | None) -> Source:
    """Find a config: a file, else a bundled name (with or without ``.yaml``).

    A folder is never a config. A bundled name resolves unless a file of exactly that name
    exists; when both could be meant (a file ``forward`` or ``forward.yaml`` here and a bundled
    ``forward``), :attr:`Source.note` says which was taken and how to ask for the other.

    Returns
    -------
    Source : (label, text, note)
        The file name to cite in errors, its YAML text, and the note (or None).

    Raises
    ------
    ConfigError
        No such file and no bundled config of that name, a folder of that name and no bundled
        config, or a file that cannot be read (too large, not UTF-8, no permission).
    """
    spec = DEFAULT_CONFIG if spec is None else str(spec)
    path = Path(spec)
    name = re.sub(r"\.ya?ml$", "", spec)
    is_name = "/" not in name and os.sep not in name and name in bundled_names()
    if path.exists() and not path.is_dir():  # a file, a pipe or a device: read (with a size cap)
        note = (f"-c {spec}: using the file {path}, not the bundled config `{name}` "
                f"(`quadctl configs --show {name}` prints that one)") if is_name else None
        return Source(str(path), yamlio.read_text(path, spec, "config file"), note)
    if is_name:
        here = [p for p in (name, f"{name}.yaml", f"{name}.yml") if Path(p).is_file()]
        note = (f"-c {spec}: using the bundled config `{name}`, not the file {here[0]} in this folder "
                f"(give -c ./{here[0]} for the file)") if here else None
        return bundled(name)._replace(note=note)
    if path.is_dir():
        raise ConfigError(f"{spec}: is a folder, not a config file; give a .yaml file")
    here = "here" if str(path.parent) == "." else f"in {path.parent}"
    near = [f"{f}` (a file {here})" for f in near_files(path)] or [
        f"{b}`" for b in difflib.get_close_matches(name, bundled_names(), n=1) if "/" not in name]
    guess = f"did you mean `{near[0]}? " if near else ""
    raise ConfigError(
        f"{spec}: no such file and no bundled config of that name; {guess}"
        f"bundled: {', '.join(bundled_names())}")


resolve = locate
"""The former name of :func:`locate` (kept for code written against it)."""


FOLDER_SCAN = 1000
"""Entries of a folder looked at for a config file of a near name (a mistyped ``-c``): a bound for a
folder of many files."""


def near_files(path: Path) -> list[str]:
    """The YAML file in ``path``'s folder whose name is nearest ``path``'s (``f450.yml`` -> ``f450.yaml``),
    as a path to give ``-c``; empty when none is near.

    >>> near_files(Path("no-such-folder/f450.yml"))
    []
    """
    import itertools

    def stem(name: str) -> str:
        return re.sub(r"\.ya?ml$", "", name)

    try:
        entries = list(itertools.islice(os.scandir(path.parent), FOLDER_SCAN))
    except OSError:
        return []
    files = {stem(e.name): e.name for e in entries
             if re.search(r"\.ya?ml$", e.name) and e.name != path.name and e.is_file()}
    near = difflib.get_close_matches(stem(path.name), list(files), n=1)
    return [str(path.parent / files[near[0]])] if near else []


def load(spec: str | Path | None = None) -> Config:
    """Load and validate a config from a path or a bundled name (default: ``forward``).

    Raises
    ------
    ConfigError
        With one line naming the file, key path, value and the fix.
    """
    source = locate(spec)
    return parse(source.text, source.label)


def parse(text: str, label: str = "<config>") -> Config:
    """Validate YAML text as a config; ``label`` names it in errors (see :mod:`quadctl.yamlio`)."""
    return from_dict(yamlio.load(text, label, ConfigError), label)


def from_dict(data: Any, label: str = "<config>") -> Config:
    """Validate a mapping (as YAML gives it) as a config."""
    if not isinstance(data, dict):
        kind = "empty" if data is None else f"a {type(data).__name__}"
        raise ConfigError(f"{label}: the config is {kind}, not a mapping of keys; "
                          "start from `quadctl configs --show forward`")
    try:
        cfg = Config.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(_describe(exc, data, label)) from None
    _check_semantics(cfg, label)
    return cfg


OVERRIDES = {"--rate": "controller.rate"}
"""Command-line options that stand for a config key: each takes the key's own declaration (its type,
bounds, unit and messages) through :func:`check_override`."""


def key_field(key: str):
    """The schema's declaration (pydantic ``FieldInfo``) of a config key path (``controller.rate``)."""
    *parents, leaf = key.split(".")
    model = _section_model(parents)
    if model is None or leaf not in model.model_fields:
        raise KeyError(f"{key}: not a config key")
    return model.model_fields[leaf]


def check_override(option: str, value: Any, key: str | None = None) -> Any:
    """Validate ``value``, given on the command line as ``option``, against the config key it
    overrides (:data:`OVERRIDES`, or ``key``): the same bounds and words as that key in a file.

    Returns
    -------
    The value as the key holds it.

    Raises
    ------
    ConfigError
        ``--rate = inf: must be a finite number (not NaN or infinity); --rate is controller.rate``:
        one line naming the option, the value, what is allowed and the key.

    Examples
    --------
    >>> check_override("--rate", 200.0)
    200.0
    >>> try:
    ...     check_override("--rate", 1e12)
    ... except ConfigError as exc:
    ...     print(str(exc)[:48])
    --rate = 1000000000000: must be at most 100000 (
    """
    from pydantic import TypeAdapter

    key = key or OVERRIDES[option]
    field = key_field(key)
    try:
        kind = Annotated[(field.annotation, *field.metadata)] if field.metadata else field.annotation
        return TypeAdapter(kind).validate_python(value)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = key.split(".") + [p for p in err["loc"] if not _is_union_tag(p)]
        raise ConfigError(f"{option} = {show(value)}: {_expected(err, loc)}; {option} is {key}") from None


def _describe(exc: ValidationError, data: Any, label: str) -> str:
    """One line for the first pydantic error: file, key path, value, what is allowed."""
    # an unknown key usually explains the errors after it (a misspelt required key): say it first
    # and a mapping given where a number or a section is allowed (controller.delay) was meant as the section
    errors = sorted(exc.errors(), key=lambda e: (e["type"] != "extra_forbidden",
                                                 e["type"] == "float_type" and isinstance(e.get("input"), dict)))
    err = errors[0]
    loc = [part for part in err["loc"] if not _is_union_tag(part)]
    path = key_path(loc)
    distinct = {tuple(p for p in e["loc"] if not _is_union_tag(p)) for e in exc.errors()}
    n_more = len(distinct) - 1
    more = f" (and {n_more} more error{'s' if n_more > 1 else ''})" if n_more else ""
    kind = err["type"]
    if kind == "extra_forbidden":
        parent = _section_model(loc[:-1])
        allowed = sorted(parent.model_fields) if parent else []
        return f"{label}: {path}: unknown key; {_hint(str(loc[-1]), allowed)}{more}"
    if kind == "missing":
        return f"{label}: {path}: required key is missing; add it{_what_it_takes(loc)}{more}"
    value = _lookup(data, loc)
    if kind in ("int_type", "int_from_float") and isinstance(value, float) and value.is_integer():
        return f"{label}: {path} = {value!r}: must be a whole number; write {int(value)}{more}"
    return f"{label}: {path} = {show(value)}: {_expected(err, loc)}{more}"


def _what_it_takes(loc: list) -> str:
    """For a missing key: the values it takes (a choice) or its description in brackets, else ''."""
    field = _field_info(loc)
    if field is None:
        return ""
    choices = _literal_values(field.annotation)
    described = f" ({field.description})" if field.description else ""
    return f": {', '.join(choices[:-1])} or {choices[-1]}{described}" if choices else described


UNION_HINTS = {
    "dt": "must be a positive number of seconds, or auto",
    "Q": "must be a list of numbers (the diagonal) or a list of rows (a full matrix)",
    "R": "must be a list of numbers (the diagonal) or a list of rows (a full matrix)",
    "inertia": "must be [Jxx, Jyy, Jzz] or 3 rows [[Jxx, Jxy, Jxz], [Jxy, Jyy, Jyz], [Jxz, Jyz, Jzz]] (kg m^2)",
}
"""Fields whose type is a union: one plain sentence instead of pydantic's per-branch errors."""


def _expected(err: dict, loc: list) -> str:
    """What the value should be, in words, with the field's unit from the schema."""
    kind, ctx = err["type"], err.get("ctx") or {}
    names = [p for p in loc if isinstance(p, str)]
    if names and names[-1] in UNION_HINTS:
        return UNION_HINTS[names[-1]]
    field = _field_info(loc)
    unit = f" ({field.description})" if field is not None and field.description else ""
    if kind == "finite_number":
        return "must be a finite number (not NaN or infinity)"
    if kind == "greater_than":
        return f"must be greater than {ctx.get('gt')}{unit}"
    if kind == "greater_than_equal":
        return f"must be at least {ctx.get('ge')}{unit}"
    if kind == "less_than_equal":
        return f"must be at most {ctx.get('le'):g}{unit}"
    if kind in ("int_type", "int_parsing", "int_from_float"):
        return f"must be a whole number{unit}"
    if kind in ("float_type", "float_parsing"):
        return f"must be a number{unit}"
    if kind in ("too_short", "too_long"):
        lo, hi = ctx.get("min_length"), ctx.get("max_length")
        if field is not None:
            meta = {type(m).__name__: m for m in field.metadata}
            lo = getattr(meta.get("MinLen"), "min_length", lo)
            hi = getattr(meta.get("MaxLen"), "max_length", hi)
        count = f"exactly {lo}" if lo is not None and lo == hi else f"at least {lo}" if hi is None else \
            f"{lo} to {hi}"
        return f"must be a list of {count} items{unit}"
    if kind == "list_type":
        return f"must be a list{unit}"
    if kind in ("string_type",):
        return "must be text"
    if kind in ("bool_type", "bool_parsing"):
        return "must be true or false"
    if kind in ("dict_type", "model_type", "model_attributes_type"):
        return "must be a mapping of keys"
    if kind == "string_pattern_mismatch":
        return ("must start with a letter, digit or '_' and use only letters, digits, '_', '.' and '-' "
                "(it names the folder runs/<name>)")
    if kind == "string_too_short":
        return "must not be empty"
    if kind == "literal_error" and field is not None:
        choices = _literal_values(field.annotation)
        if choices:
            near = _hint(str(err.get("input")), choices)
            return f"must be one of {', '.join(choices)}" + (f"; {near}" if near.startswith("did you mean") else "")
    return err["msg"]


def _literal_values(annotation) -> list[str]:
    """The values a ``Literal[...]`` field takes (inside ``Optional`` or ``Union`` too)."""
    from typing import get_args, get_origin

    if get_origin(annotation) is Literal:
        return [str(v) for v in get_args(annotation)]
    return [v for arg in get_args(annotation) for v in _literal_values(arg)]


def _field_info(loc: list):
    """The pydantic FieldInfo a key path ends at (None inside dict values and lists)."""
    parent = _section_model([p for p in loc if not isinstance(p, int)][:-1])
    name = next((p for p in reversed(loc) if isinstance(p, str)), None)
    return parent.model_fields.get(name) if parent is not None and name else None


def _is_union_tag(part: Any) -> bool:
    return isinstance(part, str) and (part.startswith("list[") or part in ("literal['auto']",)
                                      or part.startswith("function-") or part == "float"
                                      or part.startswith("constrained-") or part == DelaySamples.__name__)


def _section_model(loc: list) -> type[BaseModel] | None:
    """The schema section that the key path ``loc`` points into (for unknown-key hints)."""
    model: Any = Config
    expect_key = False
    for part in loc:
        if isinstance(part, int):
            continue
        if expect_key:  # a name inside subsystems/lqr/initial_offset: the value model follows
            expect_key = False
            continue
        field = model.model_fields.get(part) if isinstance(model, type) else None
        if field is None:
            return None
        inner = _first_model(field.annotation)
        expect_key = "dict" in str(field.annotation)
        model = inner if inner is not None else None
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


def _first_model(annotation: Any) -> Any:
    """The BaseModel inside an annotation such as ``dict[str, X] | None``."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        found = _first_model(arg)
        if found is not None:
            return found
    return None


def _lookup(data: Any, loc: list) -> Any:
    for part in loc:
        try:
            data = data[part]
        except (KeyError, IndexError, TypeError):
            return None
    return data


# ---------------------------------------------------------------------------------------
# Checks across fields


def _safe_name(name: str) -> str:
    """A name close to ``name`` that :data:`SUBSYSTEM_NAME_PATTERN` allows (for the message's fix)."""
    safe = re.sub(r"[^A-Za-z0-9_]+", "_", name).strip("_") or "subsystem"
    return (safe if safe[0].isalpha() else f"s_{safe}")[:63]


def _check_semantics(cfg: Config, label: str) -> None:
    def fail(path: str, value: Any, why: str) -> None:
        raise ConfigError(f"{label}: {path} = {show(value)}: {why}")

    for name in cfg.subsystems or {}:
        if not re.fullmatch(SUBSYSTEM_NAME_PATTERN, name):
            raise ConfigError(f"{label}: subsystems: {name!r} is not a usable subsystem name: it must start with a "
                              "letter and use only letters, digits and '_' (at most 63 characters: it names "
                              f"files, C and MATLAB fields); rename it, e.g. `{_safe_name(name)}`")
    partition = cfg.partition()
    where = "subsystems" if cfg.subsystems is not None else "subsystems (the report's default)"
    seen_states: dict[str, str] = {}
    seen_inputs: dict[str, str] = {}
    for name, sub in partition.items():
        for i, state in enumerate(sub.states):
            if state not in STATE_NAMES:
                fail(f"subsystems.{name}.states[{i}]", state, _unknown(state, STATE_NAMES, "state"))
            if state in seen_states:
                fail(f"subsystems.{name}.states[{i}]", state,
                     f"state already in subsystem `{seen_states[state]}`; each state belongs to one subsystem")
            seen_states[state] = name
        allowed = INPUT_NAMES if sub.regulate else INPUT_NAMES + STATE_NAMES
        for i, inp in enumerate(sub.inputs):
            if inp not in allowed:
                kind = "input" if sub.regulate else "input or state"
                fail(f"subsystems.{name}.inputs[{i}]", inp, _unknown(inp, allowed, kind))
            if inp in INPUT_NAMES:
                if inp in seen_inputs:
                    fail(f"subsystems.{name}.inputs[{i}]", inp,
                         f"input already drives subsystem `{seen_inputs[inp]}`; give each input to one subsystem")
                seen_inputs[inp] = name
            elif inp in sub.states:
                fail(f"subsystems.{name}.inputs[{i}]", inp, "a subsystem's own state cannot be its input")
        for i, out in enumerate(sub.outputs or []):
            if out not in sub.states:
                fail(f"subsystems.{name}.outputs[{i}]", out,
                     f"outputs must be states of this subsystem: {', '.join(sub.states)}")
    regulated = {n: s for n, s in partition.items() if s.regulate}
    for inp in INPUT_NAMES:
        if inp not in seen_inputs:
            fail(where, sorted(regulated), f"input `{inp}` is not assigned to any regulated subsystem; "
                 "add it to one subsystem's inputs")
    for name in cfg.lqr:
        if name not in partition:  # a key, not a value: named as an unknown key is
            raise ConfigError(f"{label}: lqr.{name}: {_unknown(name, list(regulated), 'regulated subsystem')}")
        if not partition[name].regulate:
            raise ConfigError(f"{label}: lqr.{name}: this subsystem has regulate: false; remove its weights "
                              "or regulate it")
    for name, sub in regulated.items():
        if name not in cfg.lqr:
            fail("lqr", sorted(cfg.lqr), f"regulated subsystem `{name}` has no weights; "
                 f"add lqr.{name} with Q ({len(sub.states)} values) and R ({len(sub.inputs)})")
        weights = cfg.lqr[name]
        for i, state in enumerate(weights.integral):
            if state not in sub.states:
                fail(f"lqr.{name}.integral[{i}]", state,
                     f"not a state of subsystem `{name}`; integrate one of {', '.join(sub.states)}")
            if state in weights.integral[:i]:
                fail(f"lqr.{name}.integral[{i}]", state, "listed twice; integrate each state once")
        check_weight(weights.Q, len(sub.states) + len(weights.integral), f"lqr.{name}.Q", label,
                     definite=False, names=[*sub.states, *(f"integral of {s}" for s in weights.integral)])
        check_weight(weights.R, len(sub.inputs), f"lqr.{name}.R", label, definite=True,
                     names=sub.inputs)
    _check_reference(cfg.simulation.reference, fail)
    _check_schedule(cfg.schedule, fail)
    for state, value in cfg.simulation.initial_offset.items():
        if state not in STATE_NAMES:
            fail(f"simulation.initial_offset.{state}", value, _unknown(state, STATE_NAMES, "state"))
        limit = MAX_TILT_OFFSET if state in ("phi", "theta") else 2 * math.pi if state == "psi" else None
        if limit is not None and abs(value) >= limit:
            fail(f"simulation.initial_offset.{state}", value, _degrees_hint(value, limit))
        unit = STATE_UNITS[state]
        if unit in MAX_OFFSET and abs(value) > MAX_OFFSET[unit]:
            fail(f"simulation.initial_offset.{state}", value,
                 f"must be at most {MAX_OFFSET[unit]:g} {unit} from the trim (MAX_OFFSET)")
    if abs(cfg.trim.yaw) > 2 * math.pi:
        fail("trim.yaw", cfg.trim.yaw, _degrees_hint(cfg.trim.yaw, 2 * math.pi))
    for key in ("velocity_ned", "position_ned"):
        unit = "m/s" if key == "velocity_ned" else "m"
        for i, value in enumerate(getattr(cfg.trim, key)):
            if abs(value) > MAX_TRIM[unit]:
                fail(f"trim.{key}[{i}]", value, f"must be at most {MAX_TRIM[unit]:g} {unit} in magnitude (MAX_TRIM)")
    max_duration = max_duration_s()
    if cfg.simulation.duration > max_duration:
        fail("simulation.duration", cfg.simulation.duration,
             f"must be at most {max_duration:g} s (MAX_DURATION, one day; set {MAX_DURATION_ENV} to allow longer)")
    _check_inertia(cfg, fail)
    _check_controller_and_actuators(cfg, fail)
    _check_delay(cfg, fail)
    _check_method(cfg, fail)
    if cfg.controller.rotor_lag == "include" and (cfg.motors is None or cfg.motors.time_constant is None):
        fail("controller.rotor_lag", "include", "needs the rotors' lag to include: set motors.time_constant (s), "
             "or use rotor_lag: ignore")


def _check_schedule(schedule: ScheduleConfig | None, fail) -> None:
    """``schedule.values``: strictly increasing."""
    if schedule is None:
        return
    for i in range(1, len(schedule.values)):
        if schedule.values[i] <= schedule.values[i - 1]:
            fail(f"schedule.values[{i}]", schedule.values[i],
                 f"not above values[{i - 1}] = {show(schedule.values[i - 1])}; list the values increasing, each once")


def _check_reference(ref: ReferenceConfig | None, fail) -> None:
    """``simulation.reference``: setpoints or waypoints (not both, not neither), setpoints in time order."""
    if ref is None:
        return
    where = "simulation.reference"
    if (ref.setpoints is None) == (ref.waypoints is None):
        fail(where, "both" if ref.setpoints is not None else "neither",
             "give either setpoints (steps at times t) or waypoints (a mission), one of the two")
    if not (ref.setpoints or ref.waypoints):
        fail(f"{where}.{'setpoints' if ref.setpoints is not None else 'waypoints'}", [], "empty; list at least one")
    for i, sp in enumerate(ref.setpoints or []):
        if sp.position is None and sp.velocity is None and sp.yaw is None:
            fail(f"{where}.setpoints[{i}]", {"t": sp.t}, "sets nothing; give position, velocity or yaw")
        if i and sp.t <= ref.setpoints[i - 1].t:
            fail(f"{where}.setpoints[{i}].t", sp.t,
                 f"not after setpoints[{i - 1}].t = {show(ref.setpoints[i - 1].t)}; list setpoints in increasing t")


def _check_method(cfg: Config, fail) -> None:
    """``simulation.method: etdrk4``: its tolerance only with ``dt: auto``; a continuous loop with a Kalman
    filter and the rotors' lag has no linear part (a sampled one's is the plant's)."""
    sim = cfg.simulation
    if sim.method == "rk4":
        if sim.tolerance is not None:
            fail("simulation.tolerance", sim.tolerance, "sets the step schedule of method etdrk4: set "
                 "simulation.method: etdrk4, or remove the tolerance")
        return
    if sim.tolerance is not None and sim.dt != "auto":
        fail("simulation.tolerance", sim.tolerance, f"sets the step schedule of dt: auto, and simulation.dt is "
             f"{sim.dt:g} s: remove one of them")
    if cfg.schedule is not None:
        fail("simulation.method", sim.method, "does not fly a gain schedule (schedule:): use method: rk4")
    if (cfg.controller.rate is None and cfg.estimator is not None and cfg.motors is not None
            and cfg.motors.time_constant is not None):
        fail("simulation.method", sim.method, "has no linear part for a Kalman filter with the rotors' lag: "
             "use method: rk4, or remove motors.time_constant")


def _check_delay(cfg: Config, fail) -> None:
    """``controller.delay``: needs a rate, and is a whole number of samples at it."""
    delay, rate = cfg.controller.delay, cfg.controller.rate
    if delay is None:
        return
    shown = delay.model_dump() if isinstance(delay, DelaySamples) else delay
    if rate is None:
        fail("controller.delay", shown, "a delay is counted in controller samples: set controller.rate (Hz), "
             "or remove the delay")
    if isinstance(delay, DelaySamples):
        return
    n = delay * rate
    whole = round(n)
    if abs(n - whole) > DELAY_SAMPLES_TOL * max(1.0, n):
        lo, hi = math.floor(n), math.ceil(n)
        fail("controller.delay", delay,
             f"is {n:.6g} samples at {rate:g} Hz; the simulated delay is a whole number of samples: use "
             f"{lo / rate:.6g} s ({{samples: {lo}}}) or {hi / rate:.6g} s ({{samples: {hi}}})")
    if whole > MAX_DELAY_SAMPLES:
        fail("controller.delay", delay, f"is {whole} samples at {rate:g} Hz, more than MAX_DELAY_SAMPLES = "
             f"{MAX_DELAY_SAMPLES}; shorten it")


MAX_DURATION = 86_400.0
"""s: the longest simulation (one day). A controller settles in seconds and a long hold is
minutes; ``1e300`` is a typo that no step count can honour. Raise it with the environment
variable :data:`MAX_DURATION_ENV` (seconds); the engine bounds the number of RK4 steps on its own."""
MAX_DURATION_ENV = "QUADCTL_MAX_DURATION"


def max_duration_s() -> float:
    """The bound on ``simulation.duration`` in force: :data:`MAX_DURATION`, or the environment's."""
    text = os.environ.get(MAX_DURATION_ENV)
    if text is None:
        return MAX_DURATION
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{MAX_DURATION_ENV}={text}: must be a positive number of seconds; unset it for "
                          f"the default {MAX_DURATION:g} s")
    return value


MAX_OFFSET = {"m": 1e4, "m/s": 1e2, "rad/s": 1e2}
"""Largest initial offset from the trim, by state unit (angles have their own bounds): 10 km,
100 m/s and 100 rad/s (16 turns a second) are past any flight yet at least ten times inside
the simulation's run-away bounds, so a run never starts out diverged, and no arithmetic on the
state overflows (an offset of 1e308 did, with numpy warnings)."""
MAX_TRIM = {"m": 1e6, "m/s": 1e3}
"""Largest trim position (1000 km) and velocity (1000 m/s, three times the speed of sound): past
them the trim and the reference it drifts along lose their digits."""


INERTIA_TRIANGLE_RTOL = 0.10
"""Slack on the triangle inequality of the principal moments of inertia. Measured inertias
(pendulum tests, CAD) carry errors of a few percent: the report's Mambo itself has
Jxx + Jyy = 0.979 Jzz, 2 % under the bound. 10 % takes measurement error, not a swapped axis."""


def _check_inertia(cfg: Config, fail) -> None:
    """Refuse an impossible inertia: a shape other than 3 values or 3 x 3, a tensor that is not
    symmetric positive definite, or principal moments that break the triangle inequality.

    For any rigid body ``Jxx + Jyy >= Jzz`` (and the same for each axis: ``Jzz`` is the integral of
    ``x^2 + y^2`` dm, ``Jxx + Jyy`` that of ``x^2 + y^2 + 2 z^2``); for a full tensor the principal
    moments (its eigenvalues) obey it. A vehicle that breaks it by more than
    :data:`INERTIA_TRIANGLE_RTOL` does not exist: the values are a typo, a swapped or mis-scaled
    entry, and a design for them is a design for no vehicle, so it is refused (exit 2). Everything
    merely unusual (a heavy, long-armed, tall vehicle) is only warned about, by :func:`notices`.
    """
    for path, inertia in (("vehicle.inertia", cfg.vehicle.inertia),
                          ("simulation.plant.inertia", cfg.simulation.plant and cfg.simulation.plant.inertia)):
        if inertia:
            _check_one_inertia(path, inertia, fail)


def _check_one_inertia(path: str, inertia: list, fail) -> None:
    import numpy as np

    nested = isinstance(inertia[0], list)
    if nested and (len(inertia) != 3 or any(not isinstance(row, list) or len(row) != 3 for row in inertia)) \
            or not nested and (len(inertia) != 3 or any(isinstance(v, list) for v in inertia)):
        fail(path, inertia, UNION_HINTS["inertia"])
    if not nested:
        for k, value in enumerate(inertia):
            if not value > 0:
                fail(f"{path}[{k}]", value, f"must be greater than 0 ({INERTIA_DESCRIPTION})")
        principal, axes = list(inertia), ("Jxx", "Jyy", "Jzz")
        hint = "check the order [Jxx, Jyy, Jzz] and that all three are in kg m^2"
    else:
        tensor = np.array(inertia, dtype=float)
        scale = float(np.abs(tensor).max())
        for i, j in ((0, 1), (0, 2), (1, 2)):
            if abs(tensor[i, j] - tensor[j, i]) > SYMMETRY_RTOL * scale:
                fail(path, inertia, f"not symmetric: {path}[{i}][{j}] = {tensor[i, j]:g} but {path}[{j}][{i}] = "
                     f"{tensor[j, i]:g}; an inertia tensor equals its transpose: give both the same value")
        for k in range(3):
            if not tensor[k, k] > 0:
                fail(f"{path}[{k}][{k}]", inertia[k][k], "a moment of inertia must be greater than 0 (kg m^2)")
        principal = [float(v) for v in np.linalg.eigvalsh(tensor)]
        if principal[0] <= DEFINITENESS_RTOL * principal[-1]:
            fail(path, inertia, f"not positive definite (smallest principal moment {principal[0]:.4g} kg m^2): the "
                 "products of inertia are too large for the moments; check their units (kg m^2) and signs "
                 "(the tensor's entry is Jxy = -integral of x y dm)")
        axes = ("J1", "J2", "J3")
        hint = "check the products of inertia and that every entry is in kg m^2"
    for k, axis in enumerate(axes):
        others = sum(principal) - principal[k]
        if others < principal[k] * (1 - INERTIA_TRIANGLE_RTOL):
            names = " + ".join(a for a in axes if a != axis)
            what = "" if not nested else "the principal moments "
            fail(path, inertia, f"no rigid body has {what}{names} = {others:.4g} below {axis} = {principal[k]:.4g} "
                 f"kg m^2 (the moments of inertia obey {names} >= {axis}); {hint}")


def _check_controller_and_actuators(cfg: Config, fail) -> None:
    """Controller rate and delay, motors, limits and noise: the keys that only make sense together."""
    if cfg.motors is not None and cfg.limits is not None:
        fail("limits", cfg.limits, "give either motors: (limits from the rotors) or limits:, not both")
    if cfg.motors is not None:
        _check_rotor_numbering(cfg.motors, fail)
    if cfg.motors is not None and cfg.motors.min_thrust >= cfg.motors.max_thrust:
        fail("motors.min_thrust", cfg.motors.min_thrust,
             f"must be below motors.max_thrust = {cfg.motors.max_thrust:g} N")
    for name, (low, high) in (cfg.limits or {}).items():
        if name not in INPUT_NAMES:
            fail(f"limits.{name}", [low, high], _unknown(name, INPUT_NAMES, "input"))
        if not low < high:
            fail(f"limits.{name}", [low, high], "must be [low, high] with low < high")
    noise = cfg.simulation.noise
    for state, value in (noise.sensor if noise else {}).items():
        if state not in STATE_NAMES:
            fail(f"simulation.noise.sensor.{state}", value, _unknown(state, STATE_NAMES, "state"))
    if cfg.estimator is not None:
        _check_estimator(cfg.estimator, noise, fail)
    _check_wind(cfg, fail)


def _check_rotor_numbering(motors: MotorsConfig, fail) -> None:
    """``motors.numbering``: each of the layout's positions once (a preset names a quad-x order);
    ``motors.spin``: diagonal rotors alike, neighbours opposite (else yaw is not separable from roll
    and pitch: the mixer is singular)."""
    from quadctl.motors import NUMBERINGS, POSITIONS

    allowed = POSITIONS[motors.layout]
    numbering = motors.numbering
    if isinstance(numbering, str):
        if numbering != "quadctl" and motors.layout != "x":
            fail("motors.numbering", numbering, f"{numbering} is a quad-x order; for layout + give the 4 positions, "
                 f"rotor 1 first ({', '.join(allowed)})")
        order = allowed if numbering == "quadctl" else NUMBERINGS[numbering]
    else:
        for i, where in enumerate(numbering):
            if where not in allowed:
                fail(f"motors.numbering[{i}]", where,
                     _unknown(where, allowed, f"rotor position of layout {motors.layout}"))
        if len(numbering) != 4 or len(set(numbering)) != 4:
            fail("motors.numbering", numbering, f"must name each of the 4 positions once, rotor 1 first: "
                 f"{', '.join(allowed)} in the vehicle's order")
        order = tuple(numbering)
    if motors.spin is not None:
        spin = dict(zip(order, motors.spin))
        first, diagonal, *_ = ("front_right", "rear_left", "rear_right", "front_left") if motors.layout == "x" \
            else ("front", "rear", "right", "left")
        others = [p for p in allowed if p not in (first, diagonal)]
        if spin[first] != spin[diagonal] or any(spin[p] == spin[first] for p in others):
            fail("motors.spin", motors.spin, f"diagonal rotors must turn alike and neighbours opposite ({first} and "
                 f"{diagonal} one way, {' and '.join(others)} the other), else yaw cannot be told from roll and pitch; "
                 "check the order against motors.numbering")


def _check_estimator(est: EstimatorConfig, noise, fail) -> None:
    """Known names, a sensor noise for every measured state, some process noise."""
    known = tuple(SENSOR_GROUPS) + STATE_NAMES
    for i, item in enumerate(est.measure):
        if item not in known:
            fail(f"estimator.measure[{i}]", item, _unknown(item, known, "state or sensor group"))
    for state, value in est.sensor.items():
        if state not in STATE_NAMES:
            fail(f"estimator.sensor.{state}", value, _unknown(state, STATE_NAMES, "state"))
    given = noise.sensor if noise is not None else {}
    for state in est.measured():
        if est.sensor.get(state, given.get(state, 0.0)) <= 0:
            fail("estimator.measure", est.measure,
                 f"{state} is measured but has no sensor noise: give estimator.sensor.{state} or "
                 f"simulation.noise.sensor.{state} (> 0, {STATE_UNITS[state]})")
    force = est.force if est.force is not None else (noise.force if noise is not None else [0.0] * 3)
    torque = est.torque if est.torque is not None else (noise.torque if noise is not None else [0.0] * 3)
    if not any(v > 0 for v in (*force, *torque)):
        fail("estimator.force", force, "the filter needs process noise: give estimator.force and estimator.torque "
             "(N, N m) or simulation.noise.force/torque; with none it would trust its model and ignore every sensor")


def _check_wind(cfg: Config, fail) -> None:
    """``simulation.wind`` and ``trim.wind``: the keys that only make sense together."""
    wind = cfg.simulation.wind
    if cfg.trim.wind and (wind is None or not any(wind.steady)):
        fail("trim.wind", True, "needs a steady wind to trim in: set simulation.wind.steady, or trim.wind: false")
    turb = wind.turbulence if wind is not None else None
    if turb is None:
        return
    where = "simulation.wind.turbulence"
    explicit = turb.sigma is not None or turb.length_scale is not None
    if turb.intensity is not None and explicit:
        fail(f"{where}.intensity", turb.intensity, "give either intensity (with altitude) or sigma and "
             "length_scale, not both")
    if turb.intensity is None and not explicit:
        fail(where, turb.model_dump(exclude_none=True), "needs intensity: light|moderate|severe, or sigma and "
             "length_scale")
    if explicit and (turb.sigma is None or turb.length_scale is None):
        missing = "sigma" if turb.sigma is None else "length_scale"
        fail(f"{where}.{missing}", None, "sigma and length_scale go together: give both (or intensity)")
    if explicit and turb.altitude is not None:
        fail(f"{where}.altitude", turb.altitude, "sets the scales of an intensity only; remove it with sigma")
    if turb.intensity is not None and turb.altitude is None and -cfg.trim.position_ned[2] <= 0:
        fail(f"{where}.altitude", None, f"the trim's altitude {-cfg.trim.position_ned[2]:g} m is not above "
             "ground: give the turbulence's altitude (m)")
    if turb.intensity is not None and turb.altitude is None and -cfg.trim.position_ned[2] > MAX_WIND_ALTITUDE:
        fail(f"{where}.altitude", None, f"the trim's altitude {-cfg.trim.position_ned[2]:g} m is above the "
             f"low-altitude model's {MAX_WIND_ALTITUDE:g} m (1000 ft): give sigma and length_scale instead")


MAX_TILT_OFFSET = math.radians(85.0)
"""Roll or pitch offsets at or past 85 deg start outside the Euler model's valid range."""


def _degrees_hint(value: float, limit: float) -> str:
    """Angles are in rad: say what the value would be, and what the user likely meant."""
    return (f"that is {math.degrees(value):.0f} deg, beyond {math.degrees(limit):.0f} deg; angles are in rad: "
            f"for {value:g} deg write {math.radians(value):.4g}")


SYMMETRY_RTOL = 1e-10
"""Relative tolerance of the symmetry test, scaled by the matrix's largest entry."""
DEFINITENESS_RTOL = 1e-12
"""Eigenvalues above ``-rtol * max|eig|`` count as nonnegative (PSD test), as in SciPy's ``_are``."""


WEIGHT_RANGE = (1e-15, 1e15)
"""Magnitudes a nonzero entry of Q or R may have. The gains depend only on the ratios of the
weights, and Bryson's rule (1/largest error^2) gives 1e-6 to 1e12 for vehicles from nano to heavy
lift; past this range the Riccati solution, which holds products of weights, loses its digits
(lqr.yaw.Q = [1e300, 1] designed a 1e150 gain and crashed the simulation)."""


def weight_matrix(value: list, size: int):
    """A weight as a (size, size) numpy array: a list is a diagonal, a nested list a matrix."""
    import numpy as np

    arr = np.asarray(value, dtype=float)
    return np.diag(arr) if arr.ndim == 1 else arr


def _out_of_range(magnitudes):
    """Where a weight's magnitude is neither 0 nor within :data:`WEIGHT_RANGE` (any shape, elementwise)."""
    import numpy as np

    mag = np.asarray(magnitudes, dtype=float)
    return (mag != 0) & ~((mag >= WEIGHT_RANGE[0]) & (mag <= WEIGHT_RANGE[1]))


def _definite(low, top, definite: bool):
    """Whether a weight whose smallest eigenvalue is ``low`` and largest magnitude ``top`` (arrays of
    many weights, or floats) is positive definite (``definite``, for R) or semidefinite (Q), up to the
    floor :data:`DEFINITENESS_RTOL` of its scale."""
    import numpy as np

    floor = DEFINITENESS_RTOL * np.maximum(top, 1e-300)
    return low > floor if definite else low >= -floor


def check_weight(value: list, size: int, path: str, label: str, *, definite: bool,
                 names: list[str]) -> None:
    """Check Q (PSD) or R (PD): size, symmetry, definiteness; raise ConfigError naming ``path``.

    The range and definiteness rules are :func:`_out_of_range` and :func:`_definite`, which
    :func:`diagonal_weights_pass` applies to many diagonals at once.
    """
    import numpy as np

    nested = bool(value) and isinstance(value[0], list)
    if nested and any(not isinstance(row, list) for row in value):
        raise ConfigError(f"{label}: {path}: mixes numbers and rows; give a list (diagonal) or a list of rows")
    if (not nested and len(value) != size) or (nested and (len(value) != size or any(
            len(row) != size for row in value))):
        shape = (len(value), len(value[0])) if nested and value else (len(value),)
        expect = f"{size} value{'s' if size != 1 else ''} (one per {', '.join(names)}) or a {size}x{size} matrix"
        got = "x".join(map(str, shape)) if nested else f"{len(value)} values"
        raise ConfigError(f"{label}: {path} = {show(value)}: expected {expect}, got {got}")
    flat = np.abs(np.array(value, dtype=float)).ravel()
    bad = np.flatnonzero(_out_of_range(flat))
    if bad.size:
        k = int(bad[0])
        where = f"{path}[{k}]" if not nested else f"{path}[{k // size}][{k % size}]"
        entry = value[k] if not nested else value[k // size][k % size]
        raise ConfigError(f"{label}: {where} = {show(entry)}: a weight must be 0 or between {WEIGHT_RANGE[0]:g} "
                          f"and {WEIGHT_RANGE[1]:g} in magnitude (WEIGHT_RANGE); the gains depend only on the "
                          "ratios of the weights: scale Q and R together")
    if nested:
        mat = weight_matrix(value, size)
        scale = max(float(np.abs(mat).max()), 1.0)
        if not np.allclose(mat, mat.T, rtol=0, atol=SYMMETRY_RTOL * scale):
            raise ConfigError(f"{label}: {path} = {show(value)}: not symmetric; make it equal to its transpose")
        eig = np.linalg.eigvalsh((mat + mat.T) / 2)
        low, top = float(eig.min()), float(np.abs(eig).max())
    else:  # a diagonal is symmetric and its eigenvalues are its entries
        low, top = float(min(value)), float(flat.max())
    if not _definite(low, top, definite):
        kind, fix = ("positive definite", "positive") if definite else ("positive semidefinite", "nonnegative")
        raise ConfigError(f"{label}: {path} = {show(value)}: must be {kind} "
                          f"(smallest eigenvalue {low:.3g}); use {fix} weights")


def diagonal_weights_pass(values, *, definite: bool):
    """Which of many diagonal weights :func:`check_weight` passes, at once (a sweep checks thousands):
    the same rules (:func:`_out_of_range`, :func:`_definite`) on each row.

    Parameters
    ----------
    values : (N, size) array_like of float
        One diagonal a row, finite (the schema's check comes first).
    definite : bool

    Returns
    -------
    (N,) ndarray of bool
        True where :func:`check_weight` raises nothing; a False row goes through it for its message.
    """
    import numpy as np

    w = np.asarray(values, dtype=float)
    mag = np.abs(w)
    return ~_out_of_range(mag).any(axis=1) & _definite(w.min(axis=1), mag.max(axis=1), definite)
