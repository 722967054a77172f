"""The config's schema: each section a frozen pydantic model, with the limits and the units of its keys.

Unknown keys are refused (``extra="forbid"``), numbers are strict and finite
(:mod:`quadctl.config.schema_types`), and every bound is a named constant declared beside the field it
bounds. The sections of what runs on the flight computer (``controller:``, ``estimator:``) are
:mod:`quadctl.config.controller_schema`'s; :mod:`quadctl.config.schema_paths` walks the schema by a key
path (for messages, the shown YAML and ``key_field``). Rules across fields are
:mod:`quadctl.config.checks`'s.
"""

from __future__ import annotations

import hashlib
import json
from typing import Annotated, Any, Literal, Optional, Union

from pydantic import Field

from quadctl.config import yamlio
from quadctl.config.controller_schema import ControllerConfig, EstimatorConfig
from quadctl.config.schema_types import MAX_NOISE, Matrix, NonNegative, Number, Positive, Section, Vector3
from quadctl.layout import REPORT_PARTITION
from quadctl.metrics import MAX_SAMPLES

NAME_PATTERN = r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$"
"""A config's name: one folder name inside ``runs/`` (no separator, not ``.`` or ``..``)."""
MAX_NAME_LENGTH = 128
"""Characters of a config's name: it names the folder ``runs/<name>`` and ``quadctl init``'s file
``<name>.yaml`` (with its temporary ``.<name>.yaml.<random>.tmp`` beside it); file systems stop a
file name at 255 bytes (the name is ASCII: a byte a character), so 128 leaves room."""
NAME_RULE = ("must start with a letter, digit or '_', use only letters, digits, '_', '.' and '-', and have at "
             f"most {MAX_NAME_LENGTH} characters")
"""What :data:`NAME_PATTERN` and :data:`MAX_NAME_LENGTH` ask, in words (the config's error and ``init``'s)."""

SUBSYSTEM_NAME_PATTERN = r"^[A-Za-z][A-Za-z0-9_]{0,62}$"
"""A subsystem's name: a letter, then letters, digits or ``_``, at most 63 characters. One rule for
everything that uses the name: file names (``plots/<name>.png``, the report's figures), HTML ids,
C identifiers and MATLAB struct fields (``.mat``: at most 63 characters)."""



MASS_RANGE = (1e-4, 1e4)
"""kg: from a 0.1 g robot to ten tonnes (the heaviest multirotors weigh about one). Outside it
the input matrix (1/m) loses its digits and the design reports a false "not stabilizable"."""
MAX_GRAVITY = 100.0
"""m/s^2: ten g (Jupiter's is 24.8). 1e300 overflowed the controllability test."""
MAX_DRAG = 100.0
"""1/(m/s): 450 times the Mambo's 0.22. 1e300 overflowed the controllability test."""
MAX_ROTOR_TIME_CONSTANT = 1.0
"""s: ten times the slowest small-rotor lags (brushless rotors reach their command in 10 to 100 ms);
a rotor slower than this cannot hold a vehicle's attitude, and LQR on the rigid body means nothing."""
RotorTimeConstant = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=MAX_ROTOR_TIME_CONSTANT)]
Mass = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=MASS_RANGE[0], le=MASS_RANGE[1])]
Gravity = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=MAX_GRAVITY)]
Drag = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0, le=MAX_DRAG)]


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


class VehicleConfig(Section):
    """Vehicle parameters, SI units."""

    mass: Mass = Field(0.068, description="kg")
    gravity: Gravity = Field(9.81, description="m/s^2")
    inertia: Matrix = Field([0.69e-4, 0.775e-4, 1.5e-4], description=INERTIA_DESCRIPTION)
    drag: Annotated[list[Drag], Field(min_length=3, max_length=3)] = Field(
        [0.22, 0.22, 0.0], description="1/(m/s): the Kc diagonal; rotor drag force is -T Kc V_b")


class TrimConfig(Section):
    """The flight condition to trim about."""

    velocity_ned: Vector3 = Field([0.0, 0.0, 0.0], description="m/s, earth frame (down positive)")
    position_ned: Vector3 = Field([0.0, 0.0, -1.0], description="m; altitude 1 m is pD = -1")
    yaw: Number = Field(0.0, description="rad, heading psi")
    wind: bool = Field(False, description=(
        "true: trim in the steady wind simulation.wind.steady (the vehicle holds velocity_ned over the "
        "ground, tilted into the wind), and linearize there; false: trim in still air"))


class SubsystemConfig(Section):
    """One block of the partition: its states, its inputs, and whether it is regulated."""

    states: Annotated[list[str], Field(min_length=1)] = Field(
        description="state names (pN pE pD u v w phi theta psi p q r), each in one subsystem")
    inputs: Annotated[list[str], Field(min_length=1)] = Field(
        description="input names (T A E R), each driving one regulated subsystem; an unregulated "
        "subsystem may name states (their columns come from A)")
    regulate: bool = Field(True, description="false: analysed only, no LQR")
    outputs: list[str] | None = Field(None, description="measured states (C rows); default all")


Share = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=1)]


class BrysonRule(Section):
    """Bryson's rule, evaluated on the vehicle the config describes when it is loaded for a design."""

    errors: list[Positive] = Field(description=(
        "the largest acceptable error of each state (state units), then of each integral: Q = diag(1 / errors^2)"))
    headroom: Share = Field(description=(
        "the share of each input's headroom around the trim (how far the rotors or limits let it move, the "
        "nearer side) taken as its largest acceptable excursion du: R = diag(1 / du^2)"))


class LqrWeights(Section):
    """LQR weights of one subsystem: ``Q`` and ``R`` (a list is a diagonal, a nested list a full matrix), or
    the rule ``bryson`` that gives them from the vehicle.

    With ``integral`` (LQI, as MATLAB ``lqi``), ``Q`` weighs ``[states; integrals]``: it has one
    entry more per integrated state, in the order of ``integral``.
    """

    Q: Optional[Matrix] = Field(None, description=(
        "state weights, 1/(state unit)^2 (Bryson: 1 / largest acceptable error^2): a list is the diagonal "
        "(one per state, then one per integral), a list of rows the symmetric positive semidefinite matrix"))
    R: Optional[Matrix] = Field(None, description=(
        "input weights, 1/(input unit)^2, i.e. 1/N^2 or 1/(N m)^2: a list is the diagonal, a list of rows "
        "the symmetric positive definite matrix"))
    bryson: Optional[BrysonRule] = Field(None, description=(
        "in place of Q and R: Bryson's rule on the vehicle as loaded (its trim and its rotors' or limits' "
        "headroom), so the weights follow the vehicle's numbers when they change"))
    integral: list[str] = Field(
        default_factory=list, description="states of this subsystem whose error is integrated (LQI)")


class NoiseConfig(Section):
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


class GustConfig(Section):
    """A 1-cosine gust (MIL-F-8785C §3.7.3.4), in time: rises over ``length``, holds, falls back."""

    start: NonNegative = Field(description="s, when the gust begins")
    length: Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=3600)] = Field(
        description="s to rise from 0 to the amplitude (and to fall back)")
    amplitude: WindVector = Field(description="m/s, the gust's peak wind, NED")
    hold: Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0, le=86_400.0)] = Field(
        0.0, description="s at the amplitude between rise and fall; past the run's end: the specification's gust, "
        "which stays")


class TurbulenceConfig(Section):
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


class WindConfig(Section):
    """Wind: steady, gusts and turbulence, summed; acts through the rotor drag on the air-relative velocity."""

    steady: WindVector = Field([0.0, 0.0, 0.0], description="m/s, the air's velocity over the ground, NED")
    gusts: Annotated[list[GustConfig], Field(max_length=MAX_GUSTS)] = Field(
        default_factory=list, description="1-cosine gusts (MIL-F-8785C)")
    turbulence: Optional[TurbulenceConfig] = Field(None, description="Dryden turbulence; absent: none")


class PlantConfig(Section):
    """The simulated vehicle where it differs from the design model (model mismatch)."""

    mass: Optional[Mass] = Field(None, description="kg")
    gravity: Optional[Gravity] = Field(None, description="m/s^2")
    inertia: Optional[Matrix] = Field(None, description=INERTIA_DESCRIPTION)
    drag: Optional[Annotated[list[Drag], Field(min_length=3, max_length=3)]] = Field(
        None, description="1/(m/s), the Kc diagonal")


class SetpointConfig(Section):
    """A step of the reference at time ``t``: any of position, velocity and yaw (the others continue)."""

    t: NonNegative = Field(description="s, from the start of the run; increasing along the list")
    position: Optional[Vector3] = Field(None, description="m, NED")
    velocity: Optional[Vector3] = Field(None, description="m/s, NED")
    yaw: Optional[Number] = Field(None, description="rad")


class WaypointConfig(Section):
    """A waypoint of a mission, flown to in order."""

    position: Vector3 = Field(description="m, NED")
    yaw: Optional[Number] = Field(None, description="rad; absent: the previous waypoint's (or the trim's)")
    hold: NonNegative = Field(0.0, description="s to stay at the waypoint before the next leg")


class ReferenceConfig(Section):
    """A reference to fly: setpoint steps, or a waypoint mission with its feedforward."""

    setpoints: Optional[list[SetpointConfig]] = Field(
        None, description="steps of position, velocity and yaw at given times")
    waypoints: Optional[list[WaypointConfig]] = Field(None, description="a mission from the trim position, in order")
    speed: Positive = Field(1.0, description="m/s: the peak speed of each leg of a mission")
    tolerance: Positive = Field(0.1, description="m: a waypoint counts as reached within this distance")
    trajectory: Literal["minimum-jerk", "minimum-snap", "step"] = Field(
        "minimum-jerk", description="the shape of each leg (step: the reference jumps to the waypoint)")


ETDRK4_TOLERANCE = 1e-8
"""Default of ``simulation.tolerance``: the error ETDRK4's ``dt: auto`` aims at (state units, about the
final-state error of a 10 s run). Declared here only: the setup resolves an absent tolerance to it, and
the simulation's functions called without a config read it from here."""

class SimulationConfig(Section):
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
        MAX_SAMPLES, description="samples kept (every k-th RK4 step and the last) for sim.npz, metrics and plots")
    reference: Optional[ReferenceConfig] = Field(
        None, description="setpoints or waypoints to fly; absent: hold the trim (moving with its velocity)")
    method: Literal["rk4", "etdrk4"] = Field(
        "rk4", description="rk4: classical Runge-Kutta, its step held stable by the fastest loop; etdrk4: "
        "exponential Runge-Kutta (Hochbruck-Ostermann, order 4) exact on the loop's linearization, dt: auto a "
        "graded step schedule (a sampled controller's plant between samples)")
    tolerance: Optional[Annotated[Positive, Field(ge=1e-14, le=1e-2)]] = Field(
        None, description="etdrk4 with dt: auto: the error the step schedule aims at (state units); absent: "
        f"{ETDRK4_TOLERANCE:g}")


class ScheduleConfig(Section):
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


RotorPosition = Annotated[list[Number], Field(min_length=2, max_length=2)]


class MotorsConfig(Section):
    """Four rotors; defaults: the Parrot Mambo (docs/model.md, "Motors")."""

    layout: Literal["x", "+"] = Field("x", description="x: rotors at +-45 deg from the nose; +: on the axes")
    arm_length: Positive = Field(0.0624, description="m, from the centre to each rotor axis")
    thrust_coefficient: Positive = Field(4.72e-8, description="N/(rad/s)^2, rotor thrust = k omega^2")
    torque_coefficient: Positive = Field(0.00241, description="N m/N: yaw reaction torque per N of thrust")
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
    saturation: Literal["prioritize", "clip"] = Field(
        "prioritize", description="a command the rotors cannot produce: prioritize keeps the roll and pitch torques, "
        "then the collective thrust, and gives up yaw first (as PX4 and Betaflight do); clip clips each rotor and "
        "mixes back (every input moves)")
    positions: Optional[Annotated[list[RotorPosition], Field(min_length=4, max_length=4)]] = Field(
        None, description="m, each rotor's [x, y] in the body frame (x forward, y right, from the centre of mass), "
        "rotor 1 first; needs spin; absent: from layout and arm_length (x: [+-L/sqrt 2, +-L/sqrt 2]; +: on the axes)")


InputLimits = Annotated[list[Number], Field(min_length=2, max_length=2)]


class StartedFrom(Section):
    """The ``quadctl init`` template a config was started from, and its vehicle's numbers as written."""

    template: str = Field(description="the vehicle template (quadctl init --from)")
    vehicle_digest: str = Field(description=(
        "the template's vehicle: and motors: numbers (Config.vehicle_digest); when yours differ, a note asks "
        "you to check the description still names your vehicle"))


class Config(Section):
    """A whole quadctl config (see the README's config reference).

    Examples
    --------
    >>> import quadctl as qc
    >>> cfg = qc.load_config("hover")
    >>> cfg.controller.rate is None, cfg.simulation.duration
    (True, 10.0)
    """

    name: Annotated[str, Field(min_length=1, max_length=MAX_NAME_LENGTH, pattern=NAME_PATTERN)] = Field(
        description="names the run directory runs/<name>")
    description: str = Field("", description="one line, shown by `quadctl configs`")
    vehicle: VehicleConfig = Field(VehicleConfig(), description="vehicle parameters, SI units")
    trim: TrimConfig = Field(TrimConfig(), description="the flight condition to trim about")
    subsystems: dict[str, SubsystemConfig] | None = Field(
        None, description="subsystem name -> states and inputs; absent: the report's five (replaced whole)")
    lqr: dict[str, LqrWeights] = Field(description="regulated subsystem name -> its LQR weights Q and R (or the "
                                       "Bryson rule that gives them)")
    simulation: SimulationConfig = Field(SimulationConfig(), description="closed-loop simulation settings")
    controller: ControllerConfig = Field(
        ControllerConfig(), description="how the controller runs on the flight computer")
    motors: Optional[MotorsConfig] = Field(None, description="rotor layout and thrust limits; saturates the inputs")
    limits: Optional[dict[str, InputLimits]] = Field(
        None, description="input name -> [low, high] (input units: N or N m); box limits when there is no motors:")
    estimator: Optional[EstimatorConfig] = Field(
        None, description="state estimation (LQG): what is measured and the noise the Kalman filter assumes; "
        "absent: the controller measures the full state")
    schedule: Optional[ScheduleConfig] = Field(
        None, description="a gain schedule across the envelope (quadctl schedule); absent: one design")
    started_from: Optional[StartedFrom] = Field(
        None, description="the quadctl init template this config was started from (written by init); absent: none")
    allow: list[Literal["implausible", "saturation", "thin-margins"]] = Field(
        default_factory=list, description="failed checks this vehicle accepts (each otherwise exits 1): implausible "
        "(values that look like a unit slip: the warnings on load), saturation (a simulated design at an "
        "actuator limit more than half the run), thin-margins (a loop below 6 dB of gain margin or 30 deg of "
        "phase margin, MIL-F-9490D)")

    def vehicle_digest(self) -> str:
        """sha256 (first 12 hex digits) of the vehicle's numbers (``vehicle:`` and ``motors:``, canonical JSON):
        what ``started_from`` records of the template's vehicle."""
        data = {"vehicle": self.vehicle.model_dump(mode="json"),
                "motors": self.motors.model_dump(mode="json") if self.motors is not None else None}
        return hashlib.sha256(json.dumps(data, sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:12]

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
        for weights in (data.get("lqr") or {}).values():  # lqr.<name>.bryson, added later: named entries
            if isinstance(weights, dict) and weights.get("bryson") is None:
                weights.pop("bryson", None)
        text = json.dumps(data, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    def to_yaml(self) -> str:
        """The validated config as YAML (all defaults filled in)."""
        return yamlio.dump(self.model_dump(mode="json"))


LATER_KEYS: tuple[tuple[tuple[str, ...], Any], ...] = (
    (("allow",), []),
    (("motors", "numbering"), "quadctl"),
    (("motors", "spin"), None),
    (("motors", "positions"), None),
    (("motors", "saturation"), "prioritize"),
    (("simulation", "reference"), None),
    (("simulation", "method"), "rk4"),
    (("simulation", "tolerance"), None),
    (("schedule",), None),
    (("controller", "flies"), "lqr"),
    (("controller", "pid"), None),
    (("controller", "filters"), None),
    (("started_from",), None),
)
"""Keys added to the schema after configs were already hashed, with their defaults: left out of
:meth:`Config.digest` at that default."""


