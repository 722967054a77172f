"""The config's sections that describe the vehicle: ``vehicle:`` (mass, gravity, inertia, drag),
``motors:`` (the rotors' layout, coefficients, limits and lag) and ``limits:``'s input limits, with the
bounds and units of their keys. The simulated plant's differences from the vehicle
(``simulation.plant:``, :mod:`quadctl.config.simulation_schema`) take the same types.
"""

from __future__ import annotations

from typing import Annotated, Literal, Optional, Union

from pydantic import Field

from quadctl.config.schema_types import Matrix, NonNegative, Number, Positive, Section

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


RotorPosition = Annotated[list[Number], Field(min_length=2, max_length=2)]


class MotorsConfig(Section):
    """Four rotors; defaults: the Parrot Mambo (docs/model.md, "Motors")."""

    layout: Literal["x", "+"] = Field("x", description="x: rotors at +-45 deg from the nose; +: on the axes")
    arm_length: Positive = Field(0.0624, description="m, from the centre to each rotor axis")
    thrust_coefficient: Positive = Field(4.72e-8, description="N/(rad/s)^2, rotor thrust = k omega^2")
    torque_coefficient: Positive = Field(0.00241, description="N m/N: yaw reaction torque per N of thrust")
    min_thrust: NonNegative = Field(0.0, description="N per rotor")
    max_thrust: Positive = Field(0.33, description="N per rotor")
    thrust_curve: Optional[Annotated[list[Number], Field(min_length=3, max_length=3)]] = Field(
        None, description="N: [c0, c1, c2] of each rotor's thrust c0 + c1 s + c2 s^2 at the command s (a fraction of "
        "full command, 0 to 1; the Crazyflie's PWM / 65535), scaled so that its thrust at full command is max_thrust "
        "(quadctl identify writes both, max_thrust = c0 + c1 + c2); the curve the Crazyflie PID cascade's PWM "
        "becomes thrust by; absent: the flight stack's own curve scaled to max_thrust")
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
        "then the collective thrust, and gives up yaw first (as PX4 and Betaflight do in airmode); clip clips each "
        "rotor and mixes back (every input moves)")
    positions: Optional[Annotated[list[RotorPosition], Field(min_length=4, max_length=4)]] = Field(
        None, description="m, each rotor's [x, y] in the body frame (x forward, y right, from the centre of mass), "
        "rotor 1 first; needs spin; absent: from layout and arm_length (x: [+-L/sqrt 2, +-L/sqrt 2]; +: on the axes)")


InputLimits = Annotated[list[Number], Field(min_length=2, max_length=2)]
