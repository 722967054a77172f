"""How a flight stack turns its PID cascade's outputs into rotor thrust: the Crazyflie's legacy power
distribution to PWM (:func:`legacy_pwm`) and its PWM-to-thrust curve (:func:`pwm_thrust_curve`), PX4's
control allocation of normalized thrust and torques (:func:`px4_units`). :func:`quadctl.sim.pid.law` applies them."""

from __future__ import annotations

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.physics.motors import scaled_thrust_curve

ca = lazy_import("casadi")

PWM_FULL = 65535.0
"""The full PWM command (uint16) of the Crazyflie's motors."""


def pwm_thrust_curve(gains, actuators) -> np.ndarray:
    """(4, 3) N: each rotor's ``(c0, c1, c2)``, its thrust ``c0 + c1 s + c2 s^2`` at the fraction ``s`` of full
    PWM, that the cascade of ``gains`` (:class:`quadctl.config.pid.PidGains`) flies on ``actuators``
    (:class:`quadctl.physics.motors.Actuators`): the vehicle's own curve (``motors.thrust_curve``), else the
    preset's ``f = a s^2 + b s`` (``pwm_thrust_a``, ``pwm_thrust_b``) scaled to each rotor's largest thrust
    ``hi`` at full PWM, ``(0, hi b / (a + b), hi a / (a + b))``. Zero for a cascade whose torques are
    normalized (PX4's, :func:`px4_units`), which reads no curve.

    Examples
    --------
    >>> from quadctl.config.pid import resolve
    >>> from quadctl.physics.motors import Motors, actuators_of
    >>> curve = pwm_thrust_curve(resolve("crazyflie"), actuators_of(Motors(max_thrust=0.2)))[0]
    >>> curve.round(5), round(float(curve.sum()), 12)  # Förster's shape, max_thrust at full PWM
    (array([0.     , 0.08504, 0.11496]), 0.2)
    >>> pwm_thrust_curve(resolve("crazyflie"), actuators_of(Motors(max_thrust=0.1382,
    ...                  thrust_curve=(0.0224, -0.0098, 0.1256))))[0]
    array([ 0.0224, -0.0098,  0.1256])
    """
    hi = np.asarray(actuators.hi, dtype=float)
    if gains.torque_output != "pwm":
        return np.zeros((len(hi), 3))
    own = actuators.motors.thrust_curve if actuators.motors is not None else None
    if own is not None:  # its shape, scaled to each rotor's largest thrust
        return np.stack([scaled_thrust_curve(own, h) for h in hi])
    a, b = gains["pwm_thrust_a"], gains["pwm_thrust_b"]
    return hi[:, None] * np.array([0.0, b, a]) / (a + b)


def legacy_pwm(thrust, out, mix):
    """The Crazyflie's legacy power distribution of its PID's outputs: each rotor's PWM (4,), the
    ``thrust`` PWM plus half the roll and pitch outputs and the whole yaw output (``out``, FRD
    torque senses), each with the sign of that torque's column in its rotor's row of ``mix`` (4, 4:
    rotors by rows, [T, A, E, R] by columns), as the firmware's ``powerDistributionLegacy``."""
    share = ca.if_else(mix > 0, 1, 0) - ca.if_else(mix < 0, 1, 0)
    return thrust + share[:, 1] * out[0] / 2 + share[:, 2] * out[1] / 2 + share[:, 3] * out[2]


PX4_COUNTED = 1e-3
"""Output per N m: PX4 counts a rotor in its mix's roll or pitch column when its entry is beyond this (a numerical
zero; in these units when ``CA_ROTOR_CT`` is the rotor's thrust at full output, in N)."""
FLT_EPSILON = float(np.finfo(np.float32).eps)
"""PX4 counts a rotor in its mix's thrust column when its entry is beyond single precision's epsilon."""


def px4_units(mix, hi):
    """``[T, A, E, R]`` (N, N m, N m, N m, (4,)) of one unit of PX4's normalized collective thrust and of each of
    its normalized torques (roll, pitch, yaw), as PX4's control allocation mixes them onto these rotors.

    PX4 mixes by the pseudo-inverse of its effectiveness (the thrust and torques of each rotor's output, 0 to 1,
    from the rotor positions, ``CA_ROTOR*_CT`` and ``_KM``), its columns divided by scales ``s``: roll and pitch
    both by the larger of ``sqrt(|c|^2 / (n / 2))`` of the two columns ``c`` (``n`` the rotors with a share),
    yaw by the column's largest entry, thrust by the mean size of the entries of the rotors with one. With
    outputs ``f_i / hi_i`` the pseudo-inverse of four rotors is the inverse, ``diag(1 / hi) mix``, and a unit of
    each normalized input commands ``1 / s`` of its own input and nothing of the others. So a symmetric X
    moves each rotor by ``1 / sqrt 2`` of its range for a full roll or pitch torque, by all of it for a full
    yaw torque. PX4 sets the normalized mix's entries below 1e-3 to zero: none are on four rotors.

    Parameters
    ----------
    mix : CasADi (4, 4)
        The mixer ``M^-1``: rotor thrusts (N) from ``[T, A, E, R]``.
    hi : CasADi column (4,)
        N: each rotor's largest thrust (PX4's full output).

    References
    ----------
    PX4/PX4-Autopilot, src/lib/control_allocation/control_allocation/ControlAllocationPseudoInverse.cpp
    (``updateControlAllocationMatrixScale``, commit 1316f1cea7199b56b51fab6835f59e7cf52aaa11);
    src/modules/control_allocator/VehicleActuatorEffectiveness/ActuatorEffectivenessRotors.cpp
    (``computeEffectivenessMatrix``, commit 1da805dc2d258aff311a0d5b9de8088b635f6c5e). Checked against those
    rules written out in tests/sim/test_px4_allocation.py.
    """
    n = mix.shape[0]
    col = [[mix[i, j] / hi[i] for i in range(n)] for j in range(4)]

    def spread(c):  # sqrt(|c|^2 / (n / 2)), n the entries beyond PX4_COUNTED
        counted = sum(ca.if_else(ca.fabs(e) > PX4_COUNTED, 1, 0) for e in c)
        return ca.sqrt(sum(e * e for e in c) / (ca.fmax(counted, 1) / 2))

    roll_pitch = ca.fmax(spread(col[1]), spread(col[2]))
    yaw = col[3][0]
    for e in col[3][1:]:
        yaw = ca.fmax(yaw, e)
    sizes = [ca.fabs(e) for e in col[0]]
    thrust = sum(sizes) / ca.fmax(sum(ca.if_else(s > FLT_EPSILON, 1, 0) for s in sizes), 1)
    return ca.vertcat(1 / thrust, 1 / roll_pitch, 1 / roll_pitch, 1 / yaw)
