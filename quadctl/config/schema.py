"""The config's schema: each section a frozen pydantic model, with the limits and the units of its keys.

Unknown keys are refused (``extra="forbid"``), numbers are strict and finite
(:mod:`quadctl.config.schema_types`), and every bound is a named constant declared beside the field it
bounds. This module holds the whole :class:`Config`, its name, and the sections of the design (``trim:``,
``subsystems:``, ``lqr:``, ``schedule:``); the vehicle's sections (``vehicle:``, ``motors:``, ``limits:``)
are :mod:`quadctl.config.vehicle_schema`'s, ``simulation:`` is :mod:`quadctl.config.simulation_schema`'s,
and the sections of what runs on the flight computer (``controller:``, ``estimator:``) are
:mod:`quadctl.config.controller_schema`'s; :mod:`quadctl.config.schema_paths` walks the schema by a key
path (for messages, the shown YAML and ``key_field``). Rules across fields are
:mod:`quadctl.config.checks`'s.
"""

from __future__ import annotations

import hashlib
import json
from typing import Annotated, Any, Literal, Optional

from pydantic import Field

from quadctl.config import yamlio
from quadctl.config.controller_schema import ControllerConfig, EstimatorConfig
from quadctl.config.schema_types import Matrix, Number, Positive, Section, Vector3
from quadctl.config.simulation_schema import SimulationConfig
from quadctl.config.vehicle_schema import InputLimits, MotorsConfig, VehicleConfig
from quadctl.layout import REPORT_PARTITION

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
C identifiers and MATLAB struct fields (``.mat``: at most 63 characters). The names of quadctl's own
figures (:data:`quadctl.artifacts.places.OWN_FIGURES`) are refused beside it."""



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


MAX_SCHEDULE_POINTS = 1000
"""Most values a gain schedule may list (each is a trim and a design)."""


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


class StartedFrom(Section):
    """The ``quadctl init`` template a config was started from, and its vehicle's numbers as written."""

    template: str = Field(description="the vehicle template (quadctl init --from)")
    vehicle_digest: str = Field(description=(
        "the template's vehicle: and motors: numbers (Config.vehicle_digest); when yours differ, a note asks "
        "you to check the description still names your vehicle"))


class Config(Section):
    """A whole quadctl config (every key: the config reference, docs/reference/config.md).

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
        None, description="input name -> [low, high] (input units: N or N m); box limits, when the config has no "
                          "motors section")
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
        _drop_at_default(data, VEHICLE_LATER_KEYS)
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
        _drop_at_default(data, LATER_KEYS)
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
    (("motors", "thrust_curve"), None),
)
"""Keys added to the schema after configs were already hashed, with their defaults: left out of
:meth:`Config.digest` at that default."""
VEHICLE_LATER_KEYS: tuple[tuple[tuple[str, ...], Any], ...] = (
    (("motors", "thrust_curve"), None),
)
"""Keys of ``vehicle:`` and ``motors:`` added after :meth:`Config.vehicle_digest` was recorded in configs
(``started_from``), with their defaults: left out of it at that default."""


def _drop_at_default(data: dict, keys) -> None:
    """Remove from ``data`` (a config's JSON dump, in place) each of ``keys`` (path, default) at its default."""
    for path, default in keys:
        *parents, last = path
        node = data
        for part in parents:
            node = node.get(part) if isinstance(node, dict) else None
        if isinstance(node, dict) and node.get(last, default) == default:
            node.pop(last, None)
