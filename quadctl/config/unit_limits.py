"""The bounds of a config's values by unit: the longest run (:func:`max_duration_s`), the largest initial
offset (:data:`MAX_OFFSET`, :data:`MAX_TILT_OFFSET`), one limit per unit for every key that carries a
position, a velocity, a heading or a time (:data:`UNIT_LIMITS` over :data:`UNIT_KEYS`), and the hint that
names an angle past its bound as the degrees it most likely is.

:func:`quadctl.config.checks.check_semantics` runs :func:`check_unit_limits` and
:func:`check_initial_offset` on every validated config.
"""

from __future__ import annotations

import math
import os
from typing import Any

from quadctl.config.schema import Config
from quadctl.errors import ConfigError
from quadctl.layout import STATE_NAMES, STATE_UNITS
from quadctl.text.messages import unknown

MAX_YAW_TURNS = 2
"""Turns a reference's yaw may wind (a waypoint's, a setpoint's, a yaw schedule's values, in rad): a
mission may circle past one turn, and beyond two the number is degrees (``yaw: 90``, 14 turns), as
a trim's yaw beyond one turn is."""
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
UNIT_LIMITS = {"m": 1e6, "m/s": 1e3, "rad": 2 * math.pi, "rad along a path": MAX_YAW_TURNS * 2 * math.pi,
               "s": MAX_DURATION}
"""Largest magnitude of a position (1000 km), a velocity or speed (1000 m/s, three times the speed of
sound), a heading (one turn; a reference's, which a mission may wind past one, :data:`MAX_YAW_TURNS`)
and a time (the longest run, :data:`MAX_DURATION`, or the environment's: :func:`max_duration_s`)
wherever the config gives one (:data:`UNIT_KEYS`): past them the trim and the reference lose their
digits (a reference 1e300 m away overflowed the run's error statistics), a heading past a turn is an
angle in degrees, and a time past a day is a slip no run reaches."""

UNIT_KEYS: tuple[tuple[str, str], ...] = (
    ("trim.position_ned[*]", "m"),
    ("trim.velocity_ned[*]", "m/s"),
    ("trim.yaw", "rad"),
    ("simulation.reference.setpoints[*].position[*]", "m"),
    ("simulation.reference.setpoints[*].velocity[*]", "m/s"),
    ("simulation.reference.setpoints[*].yaw", "rad along a path"),
    ("simulation.reference.waypoints[*].position[*]", "m"),
    ("simulation.reference.waypoints[*].yaw", "rad along a path"),
    ("simulation.reference.speed", "m/s"),
    ("simulation.reference.tolerance", "m"),
    ("schedule.values[*]", "schedule.variable"),
    ("motors.arm_length", "m"),
    ("motors.positions[*][*]", "m"),
    ("simulation.duration", "s"),
    ("simulation.dt", "s"),
    ("simulation.noise.period", "s"),
    ("simulation.wind.gusts[*].start", "s"),
    ("simulation.reference.setpoints[*].t", "s"),
    ("simulation.reference.waypoints[*].hold", "s"),
    ("controller.delay", "s"),
)
"""Every key whose value is a position, a velocity, a heading or a time, with its unit (``[*]``: each
item of a list) and no tighter bound in the schema; ``schedule.values`` take the unit of
``schedule.variable`` (:data:`SCHEDULE_UNITS`). Each is held to :data:`UNIT_LIMITS` by
:func:`check_unit_limits`: one rule per unit (``tests/config/test_unit_limits.py`` finds a key of the schema
with such a unit that is missing here)."""
SCHEDULE_UNITS = {"speed": "m/s", "climb": "m/s", "yaw": "rad along a path"}
"""The unit of each ``schedule.variable``'s values."""


def check_unit_limits(cfg: Config, fail) -> None:
    """Each value of :data:`UNIT_KEYS` within its unit's :data:`UNIT_LIMITS`; a heading past a turn is
    named as the angle in degrees it most likely is."""
    data = cfg.model_dump(mode="json")
    for pattern, unit in UNIT_KEYS:
        for path, value in _values_at(data, pattern.replace("[*]", ".*").split("."), ""):
            unit_here = SCHEDULE_UNITS[data["schedule"]["variable"]] if unit == "schedule.variable" else unit
            limit = max_duration_s() if unit_here == "s" else UNIT_LIMITS[unit_here]
            if not isinstance(value, (int, float)) or abs(value) <= limit:  # (``dt: auto``, ``{samples: n}``)
                continue
            if unit_here.startswith("rad"):
                fail(path, value, _degrees_hint(value, limit))
            if unit_here == "s":
                fail(path, value, f"must be at most {limit:g} s (one day; set {MAX_DURATION_ENV} to "
                     "allow longer)")
            fail(path, value, f"must be at most {limit:g} {unit_here} in magnitude")


def _values_at(node: Any, parts: list[str], path: str):
    """``(key path, value)`` of each value the pattern ``parts`` (``*``: every item of a list) reaches
    in ``node``; a section or list the config leaves out (null) reaches none."""
    if not parts:
        yield path, node
        return
    head, *rest = parts
    if head == "*":
        for i, item in enumerate(node if isinstance(node, list) else []):
            yield from _values_at(item, rest, f"{path}[{i}]")
    elif isinstance(node, dict) and node.get(head) is not None:
        yield from _values_at(node[head], rest, f"{path}.{head}" if path else head)


MAX_TILT_OFFSET = math.radians(85.0)
"""Roll or pitch offsets at or past 85 deg start outside the Euler model's valid range."""


def _degrees_hint(value: float, limit: float) -> str:
    """Angles are in rad: say what the value would be, and what the user likely meant."""
    deg = math.degrees(value)
    shown = f"{deg:.0f}" if abs(deg) < 1e6 else f"{deg:.3g}"  # 1e300 rad: not a number of 300 digits
    return (f"that is {shown} deg, beyond {math.degrees(limit):.0f} deg; angles are in rad: "
            f"for {value:g} deg write {math.radians(value):.4g}")


def check_initial_offset(cfg: Config, fail) -> None:
    """``simulation.initial_offset``: known states, roll and pitch under :data:`MAX_TILT_OFFSET`, yaw under a
    turn, the rest within :data:`MAX_OFFSET` of the trim."""
    for state, value in cfg.simulation.initial_offset.items():
        if state not in STATE_NAMES:
            fail(f"simulation.initial_offset.{state}", value, unknown(state, STATE_NAMES, "state"))
        limit = MAX_TILT_OFFSET if state in ("phi", "theta") else 2 * math.pi if state == "psi" else None
        if limit is not None:
            _check_angle(f"simulation.initial_offset.{state}", value, limit, fail, at_limit=True)
        unit = STATE_UNITS[state]
        if unit in MAX_OFFSET and abs(value) > MAX_OFFSET[unit]:
            fail(f"simulation.initial_offset.{state}", value,
                 f"must be at most {MAX_OFFSET[unit]:g} {unit} from the trim")


def _check_angle(path: str, value: float, limit: float, fail, *, at_limit: bool = False) -> None:
    """The range rule of an angle in rad: beyond ``limit`` (at it too, ``at_limit``) it reads as degrees."""
    if abs(value) > limit or (at_limit and abs(value) >= limit):
        fail(path, value, _degrees_hint(value, limit))
