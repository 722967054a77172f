"""Which identified values are physically possible: a rule per identified parameter, judged on its 95 % interval.

A value that fails its rule is not written into the identified config (the config's own value stays
there, with a comment saying why), is flagged in ``identified.json`` and makes ``quadctl identify``
exit 1 (:class:`~quadctl.errors.CheckFailed`, after writing).

Examples
--------
A motor time constant whose interval reaches below zero is not resolved by the log:

>>> judge("T_m", 0.008, (-0.0041, 0.0201))
False
>>> judge("T_m", 0.0725, (0.069, 0.076)), judge("bias_A", -1e-4, (-3e-4, 1e-4))
(True, True)

Nor is a thrust at full command of rotors that may not lift the 27 g Crazyflie (its rotors hover at 0.0662 N each):

>>> judge("max_thrust", 0.07, (0.065, 0.075), hover=0.027 * 9.81 / 4)
False
"""

from __future__ import annotations

from enum import Enum


class Rule(str, Enum):
    """What a parameter's 95 % interval must show for its value to be written."""

    POSITIVE = "positive"
    """The whole interval above zero: a quantity that is positive in any real vehicle (a time constant,
    an inertia, a torque coefficient), which an interval reaching zero does not resolve."""
    NON_NEGATIVE = "non-negative"
    """The value at or above zero; its interval may reach below (a pure delay, which may be none)."""
    LIFTS = "lifts"
    """The whole interval above the rotor's share of the weight, ``m g / 4`` with the config's mass and
    gravity (:meth:`quadctl.identify.measurement.Airframe.hover_thrust`): the rotors at full command lift the
    vehicle (``max_thrust``, the thrust curve at full command; a vehicle that flew the log did), which an
    interval reaching the hover thrust does not resolve. Above a positive hover thrust it is positive too."""
    FREE = "free"
    """Any value: a constant disturbance torque, or a coefficient of the thrust curve (which trade
    against each other; the curve is judged by its thrust at full command, ``max_thrust``)."""


RULES = {
    "c0": Rule.FREE, "c1": Rule.FREE, "c2": Rule.FREE, "max_thrust": Rule.LIFTS,
    "T_m": Rule.POSITIVE, "delay": Rule.NON_NEGATIVE,
    "Jxx": Rule.POSITIVE, "Jyy": Rule.POSITIVE, "Jzz": Rule.POSITIVE, "k_m": Rule.POSITIVE,
    "bias_A": Rule.FREE, "bias_E": Rule.FREE, "bias_R": Rule.FREE,
}
"""The rule of every identified parameter (:data:`quadctl.identify.measurement.PARAMETERS`, ``T_m``, ``delay``) and
of ``max_thrust``, the thrust curve at full command (``c0 + c1 + c2``), which the identified config writes."""

WRITTEN = {
    ("motors", "time_constant"): ("T_m",),
    ("controller", "rotor_lag"): ("T_m",),
    ("controller", "delay"): ("delay", "T_m"),
    ("motors", "max_thrust"): ("max_thrust",),
    ("motors", "thrust_curve"): ("max_thrust",),
    ("vehicle", "inertia"): ("Jxx", "Jyy", "T_m"),
    ("motors", "torque_coefficient"): ("k_m", "T_m"),
}
"""Each key the identified config writes, and the parameters it needs plausible: the rotors' lag is
designed with (``controller.rotor_lag: include``) only when T_m is written; a delay fitted with T_m
(the two trade against each other) is written only with it; the inertia and the torque coefficient are
fitted to the torques of rotors lagged by T_m (:func:`quadctl.identify.estimate.fit_attitude`), so an
unresolved T_m leaves them unresolved too, whatever their own intervals say. The thrust curve goes with its thrust
at full command (``motors.thrust_curve`` and ``motors.max_thrust``: both or neither)."""


def judge(name: str, value: float, interval: tuple[float, float], hover: float | None = None) -> bool:
    """Whether ``value`` of parameter ``name`` (:data:`RULES`) with its 95 % ``interval`` is plausible;
    ``hover`` (N, a rotor's share of the weight) is the bound of a :attr:`Rule.LIFTS` rule, which needs it."""
    rule = RULES[name]  # a Python bool each (identified.json holds it): NumPy's comparisons give numpy.bool
    if rule is Rule.POSITIVE:
        return bool(interval[0] > 0.0)
    if rule is Rule.LIFTS:
        if hover is None:
            raise TypeError(f"judge({name!r}): its rule, {rule.value}, needs hover=")
        return bool(interval[0] > hover)
    if rule is Rule.NON_NEGATIVE:
        return bool(value >= 0.0)
    return True


def withheld(implausible) -> dict[tuple[str, str], tuple[str, ...]]:
    """``{(section, key): the implausible parameters it needs}`` for each key (:data:`WRITTEN`) not written."""
    bad = set(implausible)
    return {key: tuple(n for n in needs if n in bad) for key, needs in WRITTEN.items() if bad & set(needs)}
