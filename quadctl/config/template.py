"""A commented config to start a vehicle from (``quadctl init``): every key with its unit, a named
vehicle's published values with their sources, and the partition that fits the flight condition.

The units and meanings in the comments are the schema's own field descriptions (:mod:`quadctl.config`),
so they cannot drift from what quadctl reads; the values are a :class:`Preset`'s; the LQR weights
are Bryson's rule (:func:`bryson_rules`), which ``design`` evaluates on the vehicle it loads. The text is returned,
not written: the command line writes it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel

from quadctl import config as config_mod
from quadctl.config import (
    Config,
    ControllerConfig,
    EstimatorConfig,
    FiltersConfig,
    MotorsConfig,
    NoiseConfig,
    PidConfig,
    PlantConfig,
    ReferenceConfig,
    ScheduleConfig,
    SimulationConfig,
    StartedFrom,
    TrimConfig,
    VehicleConfig,
    WindConfig,
    yamlio,
)
from quadctl.errors import ConfigError
from quadctl.layout import REPORT_PARTITION, STATE_UNITS
from quadctl.linear.trim import solve_trim
from quadctl.physics.model import Vehicle
from quadctl.physics.motors import Motors, actuators_of, headroom
from quadctl.text.messages import SHOWN_CHARS, unknown


@dataclass(frozen=True)
class Preset:
    """A vehicle with published parameters.

    Attributes
    ----------
    title : str
        One line naming the vehicle.
    sources : tuple of str
        The references, each starting with its tag (``[F] ...``).
    vehicle, motors : dict
        Key -> ``(value, source note)`` for the ``vehicle:`` and ``motors:`` sections (SI units).
    rate : float or None
        Hz, the controller rate (None: continuous feedback), and ``rate_note`` its source.
    """

    title: str
    sources: tuple[str, ...]
    vehicle: dict[str, tuple[Any, str]]
    motors: dict[str, tuple[Any, str]]
    rate: float | None
    rate_note: str


def _bundled(name: str, section: str, notes: dict[str, str]) -> dict[str, tuple[Any, str]]:
    """The values of ``section`` keys of bundled config ``name`` (one home for a vehicle's published
    numbers: the bundled config), each with its source note."""
    given = getattr(config_mod.load(name), section)
    return {key: (getattr(given, key), note) for key, note in notes.items()}


PRESETS: dict[str, Preset] = {
    "crazyflie": Preset(
        title="Bitcraze Crazyflie 2.x (27 g, brushed rotors)",
        sources=(
            "[F] J. Förster, \"System Identification of the Crazyflie 2.0 Nano Quadrocopter\", BA thesis, ETH "
            "Zurich, 2015",
            "[FW] bitcraze/crazyflie-firmware: src/platform/interface/platform_defaults_cf2.h (ARM_LENGTH), "
            "src/modules/src/power_distribution_quadrotor.c (thrustToTorque, pwmToThrustA/B: [F]'s fit), "
            "src/modules/interface/stabilizer_types.h (ATTITUDE_RATE)",
            "[R] spencerfolk/rotorpy: rotorpy/vehicles/crazyflie_params.py (rotor drag k_d, \"See [F]\")",
            "[L] the Crazyflie 2.x flight logs of quadctl's Identify page (docs/guide/identify.md)",
        ),
        vehicle=_bundled("crazyflie", "vehicle", {
            "mass": "[F]",
            "inertia": "[F]; [F]'s products of inertia (0.83e-6, 0.72e-6, 1.80e-6) can be given as the full 3x3 tensor",
            "drag": "[F]'s K_aero = diag(10.2506, 10.2506, 7.5533)e-7 kg/rad [R] times the hover rotor speeds' sum "
                    "6065 rad/s, over m g",
        }),
        motors={
            **_bundled("crazyflie", "motors", {
                "layout": "[FW]",
                "arm_length": "[FW] ARM_LENGTH",
                "thrust_coefficient": "[F]'s C_T = 3.1582e-10 N/rpm^2 times (30/pi)^2",
                "torque_coefficient": "[F], [FW] thrustToTorque",
                "min_thrust": "",
                "max_thrust": "[FW] pwmToThrustA + pwmToThrustB at full PWM",
            }),
            "time_constant": (0.065, "[L] quadctl identify on the bundled flight log10 (65 ms, 95 %: 62-69 ms)"),
            "numbering": ("crazyflie", "[FW] M1 front right ... M4 front left"),
        },
        rate=500.0, rate_note="[FW] ATTITUDE_RATE",
    ),
    "mambo": Preset(
        title="Parrot Mambo / Rolling Spider (68 g), the report's vehicle",
        sources=(
            "[Rep] the LQR design report this project started from: m, J, Kc",
            "[MW] MathWorks Aerospace Blockset asbQuadcopter model and Parrot's RollingSpiderEdu: rotor geometry, "
            "coefficients and the 5 ms controller sample time",
        ),
        vehicle=_bundled("mambo-200hz", "vehicle", {"mass": "[Rep]", "inertia": "[Rep]", "drag": "[Rep] Kc"}),
        motors={
            **_bundled("mambo-200hz", "motors", {
                "layout": "[MW]",
                "arm_length": "[MW] 0.0441 m per axis",
                "thrust_coefficient": "[MW]",
                "torque_coefficient": "[MW]",
                "min_thrust": "",
                "max_thrust": "[MW] about 0.33 N per rotor",
            }),
            "numbering": ("quadctl", ""),
        },
        rate=200.0, rate_note="[MW] 5 ms sample time",
    ),
    "iris": Preset(
        title="3DR Iris as PX4's simulator models it (1.5 kg, 450-550 mm class)",
        sources=(
            "[PX4] PX4/PX4-SITL_gazebo-classic: models/iris/iris.sdf.jinja (base_link inertial, rotor poses "
            "(+-0.13, +-0.22/0.20) m, motor model: motorConstant 5.84e-06, momentConstant 0.06, maxRotVelocity "
            "1100 rad/s, rotorDragCoefficient 0.000175, timeConstantUp 0.0125 s)",
        ),
        vehicle={
            "mass": (1.5, "[PX4]"),
            "inertia": ([0.029125, 0.029125, 0.055225], "[PX4]"),
            "drag": ([0.037763, 0.037763, 0.0], "[PX4] rotorDragCoefficient times the hover rotor speeds' sum "
                     "3175 rad/s, over m g (it acts across the rotor axes only)"),
        },
        motors={
            "layout": ("x", "[PX4]"),
            "arm_length": (0.2555, "[PX4] |(0.13, 0.22)| m; quadctl's x puts the rotors at 45 deg from the nose, "
                           "[PX4]'s sit at about 59 deg"),
            "thrust_coefficient": (5.84e-6, "[PX4] motorConstant"),
            "torque_coefficient": (0.06, "[PX4] momentConstant"),
            "min_thrust": (0.0, ""),
            "max_thrust": (7.0664, "[PX4] motorConstant * maxRotVelocity^2"),
            "time_constant": (0.0125, "[PX4] timeConstantUp (its timeConstantDown is 0.025 s)"),
            "numbering": ("px4", "[PX4] rotor_0 front right ccw, rotor_1 back left ccw, rotor_2 front left cw, "
                          "rotor_3 back right cw"),
        },
        rate=None, rate_note="set your flight controller's loop rate for a discrete design",
    ),
}
"""The vehicles ``quadctl init --from`` starts from."""

FLIGHTS = ("hold", "hover", "forward")
"""``hold``: still at 1 m, holding north and east position (the default: a waypoint is reached); ``hover``:
still at 1 m, the position left free; ``forward``: the report's 1 m/s north at 1 m."""
HOLD = {
    "roll": {"states": ["pE", "v", "phi", "p"], "inputs": ["A"], "regulate": True},
    "pitch": {"states": ["pN", "u", "theta", "q"], "inputs": ["E"], "regulate": True},
}
"""At ``hold`` roll regulates east and pitch north (with the velocity, attitude and rate under them)."""
HOLD_POSITION_ERROR = 1.0
"""m: the largest acceptable position error of ``hold``'s Bryson weights."""
HOVER_POSITION = {"states": ["pN", "pE"], "inputs": ["u", "v"], "regulate": False}
"""At hover pN and pE integrate u and v (psi = 0): the unregulated block that fits it. The report's
``guidance`` (u and psi) fits forward flight, and at hover ``check`` would find it not stabilizable."""
BRYSON = {
    "altitude": ((0.5, 0.5), "T", 0.4),
    "roll": ((1.0, 0.1, 2.0), "A", 0.2),
    "pitch": ((1.0, 0.1, 2.0), "E", 0.2),
    "yaw": ((0.2, 2.0), "R", 0.06),
}
"""Per subsystem: the largest acceptable state errors (state units), its input, and the share of the
input's headroom around the trim (``motors.headroom``) taken as its largest acceptable excursion:
enough room that the initial offset flies without reaching a rotor limit."""
INITIAL_OFFSET = {"pD": 0.5, "phi": 0.1, "theta": 0.1, "psi": 0.2}
REQUIRED = "..."
"""What a key without a default shows in a commented-out section: the place for a value, not one."""


def bryson_rules(preset: Preset, velocity_ned=(0.0, 0.0, 0.0), hold: bool = False
                 ) -> dict[str, tuple[dict, str]]:
    """The LQR weights as Bryson's rule (``lqr.<name>.bryson``, :func:`quadctl.bryson.bryson_weights`
    evaluates it on the vehicle the config describes), with a comment giving what it comes to on the
    preset's vehicle (``hold``: roll and pitch weigh the east and north position too,
    :data:`HOLD_POSITION_ERROR`).

    Returns
    -------
    dict
        Subsystem -> ``(bryson rule, comment)``.
    """

    values = {k: v for k, (v, _) in preset.vehicle.items()}
    vehicle = Vehicle(mass=values["mass"], inertia=tuple(values["inertia"]), drag=tuple(values["drag"]))
    trim = solve_trim(velocity_ned, 0.0, (0.0, 0.0, -1.0), vehicle)
    rotors = {k: v for k, (v, _) in preset.motors.items() if k not in ("numbering",)}
    room = headroom(actuators_of(Motors(**rotors)), trim.u)
    out = {}
    for name, (errors, input_name, share) in BRYSON.items():
        unit = "N" if input_name == "T" else "N m"
        states = REPORT_PARTITION[name]["states"]
        if hold and name in HOLD:
            errors, states = (HOLD_POSITION_ERROR, *errors), HOLD[name]["states"]
        largest = ", ".join(f"{e:g} {STATE_UNITS[s]}" for e, s in zip(errors, states))
        around = min(room[input_name])
        why = (f"Bryson: Q = 1/[{largest}]^2, R = 1/du^2, du {share:.0%} of the room {input_name} has around the "
               f"trim (the template's vehicle: {around:.3g} {unit}, du = {_round(share * around):g} "
               f"{unit})")
        out[name] = ({"errors": list(errors), "headroom": share}, why)
    return out


def _round(value: float) -> float:
    """Three significant digits."""
    return float(f"{value:.3g}")


def config_text(name: str, vehicle: str = "crazyflie", flight: str = "hold") -> str:
    """The commented YAML of a new vehicle's config.

    Parameters
    ----------
    name : str
        The config's name (its run folder ``runs/<name>``).
    vehicle : {"crazyflie", "mambo", "iris"}
        The :data:`PRESETS` entry whose values fill ``vehicle:``, ``motors:`` and the controller rate.
    flight : {"hold", "hover", "forward"}
        The trim and the partition that fits it (:data:`FLIGHTS`).

    Returns
    -------
    str
        YAML that :func:`quadctl.config.parse` accepts, every key present (optional sections commented
        out) with its unit in a comment.

    Raises
    ------
    ConfigError
        ``name`` is not a valid config name, or ``vehicle``/``flight`` is unknown.
    """
    import re


    if not re.fullmatch(config_mod.NAME_PATTERN, name) or len(name) > config_mod.MAX_NAME_LENGTH:  # the schema's
        # rule (fullmatch: a `$` alone would take a name ending in a newline)
        shown = repr(name) if len(name) <= SHOWN_CHARS else f"{name[:SHOWN_CHARS]!r}... ({len(name)} characters)"
        raise ConfigError(f"NAME = {shown}: {config_mod.NAME_RULE} (it names the file NAME.yaml and the folder "
                          "runs/NAME)")
    stem, dot, suffix = name.rpartition(".")
    if dot and stem and suffix.lower() in ("yaml", "yml"):  # the file, not the name: it would write NAME.yaml.yaml
        raise ConfigError(f"NAME = {name!r}: give the config's name without .{suffix}; quadctl init {stem} "
                          f"writes {stem}.yaml")
    if vehicle not in PRESETS:
        raise ConfigError(f"--from {vehicle}: {unknown(vehicle, tuple(PRESETS), 'vehicle')}")
    if flight not in FLIGHTS:
        raise ConfigError(f"--flight {flight}: {unknown(flight, FLIGHTS, 'flight condition')}")
    preset = PRESETS[vehicle]
    velocity = [1.0, 0.0, 0.0] if flight == "forward" else [0.0, 0.0, 0.0]
    out = [f"# {name}: a quadctl config started from the {preset.title}, {flight} (quadctl init).",
           "# Replace the vehicle's numbers with your own; each line says its unit. Sources of the numbers given:"]
    out += [f"#   {s}" for s in preset.sources]
    out += ["# Optional sections are commented out: uncomment one to use it. The config reference,",
            "# docs/reference/config.md, explains every key, and how an editor checks them as you type.",
            f"name: {yamlio.flow(name)}",
            f"description: {yamlio.flow(f'Started from the {preset.title} template (quadctl init): {flight} at 1 m')}"]
    out += ["vehicle:   # " + _doc(Config, "vehicle")]
    out += _section(VehicleConfig, {"gravity": (9.81, ""), **preset.vehicle}, 2)
    out += ["trim:   # " + _doc(Config, "trim")]
    out += _section(TrimConfig, {"velocity_ned": (velocity, flight), "position_ned": ([0.0, 0.0, -1.0], "1 m up"),
                                 "yaw": (0.0, ""), "wind": (False, "")}, 2)
    out += ["subsystems:   # " + _doc(Config, "subsystems")]
    partition = {k: v for k, v in REPORT_PARTITION.items() if k != "guidance"}
    if flight == "hold":
        partition.update(HOLD)
    else:
        partition["guidance" if flight == "forward" else "position"] = (
            REPORT_PARTITION["guidance"] if flight == "forward" else HOVER_POSITION)
    width = max(len(k) for k in partition)
    for key, sub in partition.items():
        flow = f"{{states: [{', '.join(sub['states'])}], inputs: [{', '.join(sub['inputs'])}]"
        flow += ", regulate: false}" if not sub["regulate"] else "}"
        note = "  # analysed only: " + ("pN, pE integrate u, v at hover" if key == "position" else
                                        "the report's guidance: pN, pE follow u and psi in forward flight") \
            if not sub["regulate"] else ""
        out.append(f"  {key + ':':<{width + 1}} {flow}{note}")
    out += ["lqr:   # " + _doc(Config, "lqr") + "; Q in 1/(state unit)^2, R in 1/(input unit)^2"]
    for key, (rule, why) in bryson_rules(preset, velocity, hold=flight == "hold").items():
        out.append(f"  {key + ':':<9} {{bryson: {yamlio.flow(rule)}}}  # {why}")
    out += ["simulation:   # " + _doc(Config, "simulation")]
    out += _section(SimulationConfig, {"duration": (10.0, ""), "dt": ("auto", ""),
                                       "initial_offset": (INITIAL_OFFSET, ""), "max_samples": (20_000, "")}, 2)
    for key, model in (("noise", NoiseConfig), ("wind", WindConfig), ("plant", PlantConfig),
                       ("reference", ReferenceConfig)):
        out += [f"  # {key}:   # {_doc(SimulationConfig, key)}"] + _section(model, {}, 4, commented=True)
    out += ["controller:   # " + _doc(Config, "controller")]
    rate = (preset.rate, preset.rate_note)
    lagged = preset.motors.get("time_constant", (None, ""))[0] is not None
    out += _section(ControllerConfig, {"rate": rate, "design": ("discrete", ""), "rotor_lag": (
        "include" if lagged else "ignore", "the template's rotors lag (motors.time_constant)" if lagged else ""),
        "delay": (None, "")}, 2)
    out += [f"  # filters:   # {_doc(ControllerConfig, 'filters')}"] + _section(FiltersConfig, {}, 4, commented=True)
    out += [f"  # pid:   # {_doc(ControllerConfig, 'pid')}"] + _section(PidConfig, {}, 4, commented=True)
    out += ["motors:   # " + _doc(Config, "motors")]
    out += _section(MotorsConfig, {"time_constant": (None, ""), **preset.motors, "spin": (None, "")}, 2)
    out += [f"# limits: {{T: [0, 1], A: [-0.01, 0.01]}}   # {_doc(Config, 'limits')}",
            f"# estimator:   # {_doc(Config, 'estimator')}"] + _section(EstimatorConfig, {}, 2, commented=True)
    out += [f"# schedule:   # {_doc(Config, 'schedule')}"] + _section(ScheduleConfig, {}, 2, commented=True)
    out += [f"allow: []   # {_doc(Config, 'allow')}"]
    text = "\n".join(out) + "\n"
    digest = config_mod.parse(text, f"{name}.yaml").vehicle_digest()
    recorded = {"template": (vehicle, ""), "vehicle_digest": (digest, "")}
    return "\n".join([text + f"started_from:   # {_doc(Config, 'started_from')}",
                      *_section(StartedFrom, recorded, 2)]) + "\n"


def _doc(model: type[BaseModel], key: str) -> str:
    return model.model_fields[key].description or ""


def _section(model: type[BaseModel], given: dict[str, tuple[Any, str]], indent: int, *,
             commented: bool = False) -> list[str]:
    """One line per field of ``model``: the given value (or the schema's default), then the field's
    description (its unit) and the value's source. ``commented``: every line behind ``#``, nested
    sections spelled out the same way."""
    lines = []
    pad = " " * indent
    for key, field in model.model_fields.items():
        sub = config_mod.first_model(field.annotation)
        if key in given:
            value, note = given[key]
        elif sub is not None and not commented:
            continue  # an optional section: the caller spells it out, commented
        elif sub is not None:
            lines.append(f"{pad}# {key}:   # {field.description}")
            inner = _section(sub, {}, indent + 2, commented=True)
            if "list[" in str(field.annotation):  # a list of them (optional or not): one item
                inner = [line.replace("# ", "# - ", 1) if i == 0 else line.replace("# ", "#   ", 1)
                         for i, line in enumerate(inner)]
            lines += inner
            continue
        else:
            value = field.get_default(call_default_factory=True) if not field.is_required() else REQUIRED
            note = ""
        text = f"{key}: {value if value is REQUIRED else yamlio.flow(value)}"
        comment = field.description + (f" {note}" if note.startswith("[") else f"; {note}" if note else "")
        lines.append(f"{pad}{'# ' if commented else ''}{text}   # {comment}")
    return lines
