"""The flight stacks' PID cascades as data: their published defaults, each value cited at its source.

The presets live in ``pid_presets.yaml`` beside this module (numbers only, each with the file and the
name it is read from; the law that flies them, :mod:`quadctl.sim.pid`, is quadctl's own code).
:func:`resolve` makes a preset and a config's overrides one :class:`PidGains`: the values in the
order of :data:`PARAMETERS` (the law's constants) and the choices baked into the law's code.

Units are the stack's own: ``angle_unit`` (``deg`` for the Crazyflie, ``rad`` for PX4) is the unit of
every angle the law's gains and limits read (rates per second of it).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from quadctl.errors import ArgumentError

PRESETS_FILE = Path(__file__).with_name("pid_presets.yaml")
"""The presets' data file (package data)."""

PARAMETERS: tuple[tuple[str, str], ...] = (
    ("rate_hz", "Hz: the rate loop's rate, the law's base rate (every loop runs at a whole divisor of it)"),
    ("attitude_hz", "Hz: the attitude loop's rate"),
    ("position_hz", "Hz: the position and velocity loops' rate"),
    ("rate_roll_kp", "rate PID roll P: output per angle unit/s of rate error"),
    ("rate_roll_ki", "rate PID roll I: output per angle unit of integrated rate error"),
    ("rate_roll_kd", "rate PID roll D (on the measured rate): output per angle unit/s^2"),
    ("rate_roll_ilimit", "rate PID roll integrator limit: angle unit (Crazyflie), output (PX4); 0: none"),
    ("rate_pitch_kp", "rate PID pitch P"),
    ("rate_pitch_ki", "rate PID pitch I"),
    ("rate_pitch_kd", "rate PID pitch D (on the measured rate)"),
    ("rate_pitch_ilimit", "rate PID pitch integrator limit; 0: none"),
    ("rate_yaw_kp", "rate PID yaw P"),
    ("rate_yaw_ki", "rate PID yaw I"),
    ("rate_yaw_kd", "rate PID yaw D (on the measured rate)"),
    ("rate_yaw_ilimit", "rate PID yaw integrator limit; 0: none"),
    ("rate_output_limit", "the rate PIDs' output limit: int16 command (Crazyflie) or normalized torque (PX4)"),
    ("rate_dfilter_hz", "Hz: second-order Butterworth low-pass on the rate PIDs' derivative; 0: none"),
    ("gyro_lpf_hz", "Hz: second-order Butterworth low-pass on the body rates the rate PIDs measure; 0: none"),
    ("att_roll_kp", "attitude roll P: 1/s (rate setpoint per angle error)"),
    ("att_roll_ki", "attitude roll I: 1/s^2 (the euler stage; px4 is P only)"),
    ("att_roll_kd", "attitude roll D (on the measured angle): dimensionless (the euler stage)"),
    ("att_roll_ilimit", "attitude roll integrator limit: angle unit s; 0: none"),
    ("att_pitch_kp", "attitude pitch P: 1/s"),
    ("att_pitch_ki", "attitude pitch I: 1/s^2"),
    ("att_pitch_kd", "attitude pitch D (on the measured angle)"),
    ("att_pitch_ilimit", "attitude pitch integrator limit: angle unit s; 0: none"),
    ("att_yaw_kp", "attitude yaw P: 1/s"),
    ("att_yaw_ki", "attitude yaw I: 1/s^2"),
    ("att_yaw_kd", "attitude yaw D (on the measured angle)"),
    ("att_yaw_ilimit", "attitude yaw integrator limit: angle unit s; 0: none"),
    ("att_rate_limit_rp", "roll and pitch rate setpoint limit: angle unit/s; 0: none"),
    ("att_rate_limit_yaw", "yaw rate setpoint limit: angle unit/s; 0: none"),
    ("att_yaw_weight", "the px4 attitude stage's yaw weight [0, 1]: the share of the yaw error kept after the "
                       "thrust axis's (its yaw P gain is divided by it, as PX4 does); unused by the euler stage"),
    ("vel_xy_kp", "horizontal velocity P: output per m/s (deg per m/s, Crazyflie; m/s^2 per m/s, PX4)"),
    ("vel_xy_ki", "horizontal velocity I: output per m"),
    ("vel_xy_kd", "horizontal velocity D (on the measured velocity): output per m/s^2"),
    ("vel_z_kp", "vertical velocity P: output per m/s (thrust_scale PWM per unit, Crazyflie; m/s^2, PX4)"),
    ("vel_z_ki", "vertical velocity I: output per m"),
    ("vel_z_kd", "vertical velocity D (on the measured velocity): output per m/s^2"),
    ("vel_ilimit", "velocity integrator limit: m; 0: none"),
    ("tilt_limit", "tilt limit: angle unit (each of roll and pitch, Crazyflie; of the thrust vector, PX4)"),
    ("pos_xy_kp", "horizontal position P: 1/s"),
    ("pos_xy_ki", "horizontal position I: 1/s^2"),
    ("pos_z_kp", "vertical position P: 1/s"),
    ("pos_z_ki", "vertical position I: 1/s^2"),
    ("pos_ilimit", "position integrator limit: m s; 0: none"),
    ("pos_vel_limit_xy", "horizontal velocity setpoint limit: m/s (each axis)"),
    ("pos_vel_limit_up", "climb velocity setpoint limit: m/s"),
    ("pos_vel_limit_down", "descent velocity setpoint limit: m/s"),
    ("thrust_base", "Crazyflie: PWM thrust at zero vertical velocity output (of 65535)"),
    ("thrust_min", "least collective thrust: PWM (Crazyflie) or normalized (PX4)"),
    ("thrust_max", "PX4: largest normalized collective thrust"),
    ("thrust_scale", "Crazyflie: PWM per unit of the vertical velocity PID's output"),
    ("pwm_thrust_a", "Crazyflie: the PWM-to-thrust curve's quadratic coefficient (f = a s^2 + b s, s = PWM/65535), "
                     "scaled so that full PWM gives motors.max_thrust; a vehicle's motors.thrust_curve replaces it"),
    ("pwm_thrust_b", "Crazyflie: the PWM-to-thrust curve's linear coefficient"),
)
"""Every value of a cascade, in the order of the law's constants, with its unit (a preset leaves out
the ones its stack has not: they are 0)."""
NAMES = tuple(name for name, _ in PARAMETERS)
PRESET_NAMES = ("crazyflie", "px4")
NEEDS_ROTORS = "a PID cascade commands the rotors: add motors: (the rotors' layout and thrust limits)"
"""Why a PID cascade cannot fly a config without ``motors:``, and the way out: every refusal says it."""
ANGLE_UNITS = ("deg", "rad")
VELOCITY_OUTPUTS = ("angles", "acceleration")
TORQUE_OUTPUTS = ("pwm", "normalized")
ATTITUDE_STAGES = ("euler", "px4")
"""The attitude stages: ``euler``, a PID per Euler angle error (the Crazyflie's ``attitude_pid_controller``);
``px4``, PX4's ``AttitudeControl``: the quaternion error, the thrust axis's first and the yaw's de-weighted,
P per axis, the yaw rate fed forward (:mod:`quadctl.sim.pid`)."""


@dataclass(frozen=True)
class PidGains:
    """A PID cascade's numbers and structure: a preset with its overrides.

    Attributes
    ----------
    preset : str
    values : tuple of float
        In the order of :data:`PARAMETERS`.
    angle_unit, velocity_output, torque_output, attitude : str
        The choices baked into the law's code (:data:`ANGLE_UNITS`, :data:`VELOCITY_OUTPUTS`,
        :data:`TORQUE_OUTPUTS`, :data:`ATTITUDE_STAGES`).
    citations : tuple of str
        Where each value comes from (``override`` for a config's own).
    source : str
        The stack's repository and version.
    """

    preset: str
    values: tuple[float, ...]
    angle_unit: str
    velocity_output: str
    torque_output: str
    attitude: str
    citations: tuple[str, ...]
    source: str
    title: str = ""

    def __getitem__(self, name: str) -> float:
        return self.values[NAMES.index(name)]

    @property
    def ratios(self) -> tuple[int, int]:
        """Base-rate samples per attitude update and per position update."""
        base = self["rate_hz"]
        return round(base / self["attitude_hz"]), round(base / self["position_hz"])

    def with_values(self, **values: float) -> PidGains:
        """This cascade with some values replaced (each cited ``override``)."""
        unknown = sorted(set(values) - set(NAMES))
        if unknown:
            raise ArgumentError(f"unknown PID values {unknown}: use {', '.join(NAMES)}")
        vals, cites = list(self.values), list(self.citations)
        for name, value in values.items():
            i = NAMES.index(name)
            vals[i], cites[i] = float(value), "override"
        return PidGains(self.preset, tuple(vals), self.angle_unit, self.velocity_output, self.torque_output,
                        self.attitude, tuple(cites), self.source, self.title)


@lru_cache(maxsize=1)
def presets() -> dict:
    """The presets' data (``pid_presets.yaml``), read once: by libyaml's reader where PyYAML has it
    (every setup resolves a cascade, so every command and sweep worker reads it, and Python's reader
    is many times slower), the same safe types either way."""
    import yaml

    with open(PRESETS_FILE, encoding="utf-8") as fh:
        return yaml.load(fh, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))


def rate_problem(gains: PidGains) -> str | None:
    """Why the cascade's rates cannot run in one base loop (each a whole divisor of ``rate_hz``), or None."""
    base = gains["rate_hz"]
    if not base > 0:
        return f"rate_hz must be > 0, got {base:g}"
    for name in ("attitude_hz", "position_hz"):
        value = gains[name]
        if not value > 0 or value > base or abs(base / value - round(base / value)) > 1e-9 * base / value:
            return f"{name} {value:g} Hz must divide rate_hz {base:g} Hz a whole number of times"
    if gains.ratios[1] % gains.ratios[0]:
        return (f"position_hz {gains['position_hz']:g} Hz must divide attitude_hz {gains['attitude_hz']:g} Hz "
                "a whole number of times")
    return None


def resolve(preset: str, overrides: dict | None = None, attitude: str | None = None) -> PidGains:
    """The cascade of ``preset`` with ``overrides`` (name -> value in the stack's units) and its attitude
    stage ``attitude`` (:data:`ATTITUDE_STAGES`; None: the preset's).

    Raises
    ------
    ArgumentError
        An unknown preset, value name or attitude stage, or rates that do not divide the base rate.

    Examples
    --------
    >>> g = resolve("crazyflie")
    >>> g["rate_roll_kp"], g["att_roll_kp"], g.ratios, g.angle_unit, g.attitude
    (250.0, 6.0, (1, 5), 'deg', 'euler')
    >>> resolve("px4", {"att_roll_kp": 6.5})["att_roll_kp"]
    6.5
    """
    data = presets()
    if preset not in data:
        raise ArgumentError(f"unknown PID preset {preset!r}: use one of {', '.join(PRESET_NAMES)}")
    entry = data[preset]
    attitude = entry["attitude"] if attitude is None else attitude
    if attitude not in ATTITUDE_STAGES:
        raise ArgumentError(f"unknown attitude stage {attitude!r}: use one of {', '.join(ATTITUDE_STAGES)}")
    table = entry["values"]
    values = tuple(float(table[n][0]) if n in table else 0.0 for n in NAMES)
    cites = tuple(str(table[n][1]) if n in table else "not in this stack (0)" for n in NAMES)
    gains = PidGains(preset, values, entry["angle_unit"], entry["velocity_output"], entry["torque_output"],
                     attitude, cites, entry["source"], entry.get("title", preset)).with_values(**(overrides or {}))
    problem = rate_problem(gains)
    if problem:
        raise ArgumentError(f"{problem}: change the rates in overrides")
    return gains
