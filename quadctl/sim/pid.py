"""A flight stack's PID cascade as a control law of the one closed loop (:mod:`quadctl.sim.builder`).

Position P(I) -> velocity PID -> attitude stage -> rate PID, as the Crazyflie's ``controller_pid`` and
PX4's multicopter controllers run them, with the numbers of :mod:`quadctl.config.pid`. The attitude
stage is the Crazyflie's PID per Euler angle error (``euler``) or PX4's ``AttitudeControl`` (``px4``:
:func:`px4_attitude_error`, a P gain per axis, the yaw rate fed forward, the rate limits). Written for
quadctl from the stacks' documented behaviour; no stack code is copied. The loops, their rates and
outputs are described in the docs, docs/internals.md ("The PID cascade").

References
----------
.. [1] D. Brescianini, M. Hehn, R. D'Andrea, "Nonlinear quadrocopter attitude control", technical
   report, ETH Zurich, 2013 (the reduced and full attitude errors, the yaw weight).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.layout import N_STATES, STATE_INDEX
from quadctl.physics.model import euler_rates_matrix
from quadctl.sim.pid_mixing import PWM_FULL, legacy_pwm, px4_units

ca = lazy_import("casadi")

STATE_LAYOUT: tuple[tuple[str, int], ...] = (
    ("phase", 1),            # samples since the last position update (0 .. n_pos - 1)
    ("pos_integral", 3),     # m s: x, y (yaw-turned frame), z up
    ("vel_integral", 3),     # m
    ("vel_previous", 3),     # m/s: the last measured velocity (the D term's)
    ("att_setpoint", 3),     # roll, pitch, yaw (stack angle unit): held between position updates
    ("thrust_setpoint", 1),  # PWM (Crazyflie) or normalized (PX4)
    ("att_integral", 3),     # angle unit s (euler stage)
    ("att_previous", 3),     # angle unit (euler stage)
    ("rate_setpoint", 3),    # angle unit/s: held between attitude updates
    ("rate_integral", 3),    # angle unit (PWM torques: the Crazyflie's), torque (normalized torques: PX4's I term)
    ("rate_previous", 3),    # angle unit/s
    ("rate_derivative", 6),  # angle unit/s^2: the D-term low-pass's two delay elements per axis (rate_dfilter_hz > 0)
    ("gyro_filter", 6),      # angle unit/s: the gyro low-pass's two delay elements per axis (gyro_lpf_hz > 0)
)
"""The law's states, in order, in the loop state after the plant's."""
N_LAW_STATES = sum(n for _, n in STATE_LAYOUT)
_SLICES = {}
_offset = 0
for _name, _n in STATE_LAYOUT:
    _SLICES[_name] = slice(_offset, _offset + _n)
    _offset += _n


def state_slice(name: str) -> slice:
    """Where the law's state ``name`` (:data:`STATE_LAYOUT`) sits among the law's states."""
    return _SLICES[name]


def structure_of(gains) -> tuple:
    """The choices baked into the law's code (:attr:`quadctl.sim.loop_spec.LoopSpec.law`):
    ``("pid", n_att, n_pos, angle_unit, velocity_output, torque_output, dfilter, gyro_filter, attitude)``."""
    n_att, n_pos = gains.ratios
    return ("pid", n_att, n_pos, gains.angle_unit, gains.velocity_output, gains.torque_output,
            bool(gains["rate_dfilter_hz"] > 0), bool(gains["gyro_lpf_hz"] > 0), gains.attitude)


def n_constants(structure: tuple) -> int:
    """Constants the law reads from the loop's ``c`` (its values, :data:`quadctl.config.pid.PARAMETERS`)."""
    from quadctl.config.pid import NAMES

    return len(NAMES)


def integrate(integral, error, period, limit, lib=ca):
    """The stacks' integrator: ``clamp(integral + error period, +-limit)`` (backward Euler; ``limit`` 0: none)."""
    return _clamp(integral + error * period, limit, lib)


def derivative(measured, previous, period):
    """The stacks' D input: ``-(measured - previous) / period``, on the measurement (no setpoint kick)."""
    return -(measured - previous) / period


def pid_output(kp, ki, kd, error, integral, deriv):
    """``kp error + ki integral + kd deriv``: one PID's output from its (updated) integral and D input."""
    return kp * error + ki * integral + kd * deriv


def _clamp(value, limit, lib=ca):
    """``value`` within ``+-limit``; ``limit`` 0 (or less): no limit."""
    if lib is not ca:
        return np.clip(value, -limit, limit) if limit > 0 else value
    return ca.if_else(limit > 0, ca.fmin(ca.fmax(value, -limit), limit), value)


PX4_I_RATE_SCALE = 400.0
"""deg/s: the rate error at which PX4's rate integrator stops growing (``i_factor = 1 - (e / 400 deg/s)^2``,
src/lib/rate_control/rate_control.cpp, a constant there, no parameter)."""
YAW_WEIGHT_FLOOR = 1e-4
"""PX4's ``setProportionalGain`` divides the yaw P gain by the yaw weight only above this."""
HALF_TURN_AXIS = 1 - 1e-5
"""PX4's ``AttitudeControl::update`` takes the full setpoint for the reduced one when the rotation of the
thrust axis has an x or y component beyond this: a half turn about a horizontal axis."""


def quaternion_of_euler(phi, theta, psi, lib=ca):
    """``(w, x, y, z)`` (Hamilton, scalar first) of ``R_z(psi) R_y(theta) R_x(phi)``, the body-to-NED
    rotation of ZYX Euler angles (rad)."""
    cr, sr = lib.cos(phi / 2), lib.sin(phi / 2)
    cp, sp = lib.cos(theta / 2), lib.sin(theta / 2)
    cy, sy = lib.cos(psi / 2), lib.sin(psi / 2)
    return (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)


def _qmul(a, b):
    """The Hamilton product ``a b`` of quaternions as ``(w, x, y, z)`` tuples."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def _conj(q):
    return (q[0], -q[1], -q[2], -q[3])


def _body_z(q):
    """The body z axis in the world frame: the third column of the rotation of the unit quaternion ``q``."""
    w, x, y, z = q
    return (2 * (x * z + w * y), 2 * (y * z - w * x), w * w - x * x - y * y + z * z)


def _pick(cond, a, b):
    """``a`` where ``cond``, else ``b``: a select per component of two quaternions."""
    return tuple(ca.if_else(cond, ai, bi) for ai, bi in zip(a, b))


def px4_attitude_error(att, att_sp, yaw_weight):
    """PX4's attitude error (rad, body frame) of ZYX Euler angles ``att`` to ``att_sp`` (rad, (3,) each),
    as ``AttitudeControl::update`` computes it from Brescianini, Hehn and D'Andrea [1]_:

    1. the reduced setpoint ``q_red``: the shortest rotation taking the body z axis (the thrust axis) to
       the setpoint's, applied to the attitude ``q`` (``q`` itself turned, yaw untouched); when that
       rotation is a half turn about a horizontal axis, the full setpoint ``q_d`` instead (as PX4 does);
    2. the mix ``q_mix = q_red^-1 q_d``, a rotation about z by ``alpha`` (taken with ``w >= 0``),
       and the weighted setpoint ``q_red (cos(w alpha / 2), 0, 0, sin(w alpha / 2))``, ``w`` the yaw
       weight within [0, 1]: the yaw's share of the error;
    3. ``q_e = q^-1 q_w`` and the error ``2 sign(q_e.w) q_e.xyz`` (the shorter way round).

    The angle ``alpha / 2`` is ``atan2(z, w)`` of ``q_mix`` (PX4 takes ``acos(w)`` and ``asin(z)``, the
    same angle, less well conditioned near zero). ``sign`` is a select (``w >= 0``: +1). CasADi symbols
    or numbers (DM) alike.

    Returns
    -------
    CasADi column (3,)
    """
    q = quaternion_of_euler(att[0], att[1], att[2])
    qd = quaternion_of_euler(att_sp[0], att_sp[1], att_sp[2])
    ez, ezd = _body_z(q), _body_z(qd)
    dot = ez[0] * ezd[0] + ez[1] * ezd[1] + ez[2] * ezd[2]
    cross = (ez[1] * ezd[2] - ez[2] * ezd[1], ez[2] * ezd[0] - ez[0] * ezd[2], ez[0] * ezd[1] - ez[1] * ezd[0])
    raw = (1 + dot, *cross)  # the half-way quaternion from ez to ezd (unnormalized)
    norm = ca.sqrt(raw[0] ** 2 + raw[1] ** 2 + raw[2] ** 2 + raw[3] ** 2)
    turn = tuple(c / ca.fmax(norm, 1e-12) for c in raw)
    half_turn = ca.logic_or(norm < 1e-6, ca.logic_or(ca.fabs(turn[1]) > HALF_TURN_AXIS,
                                                     ca.fabs(turn[2]) > HALF_TURN_AXIS))
    q_red = _pick(half_turn, qd, _qmul(turn, q))
    mix = _qmul(_conj(q_red), qd)
    sign = ca.if_else(mix[0] >= 0, 1, -1)
    half = ca.atan2(sign * mix[3], sign * mix[0])
    w = ca.fmin(ca.fmax(yaw_weight, 0), 1)
    q_w = _qmul(q_red, (ca.cos(w * half), 0, 0, ca.sin(w * half)))
    q_e = _qmul(_conj(q), q_w)
    sign = ca.if_else(q_e[0] >= 0, 2, -2)
    return ca.vertcat(sign * q_e[1], sign * q_e[2], sign * q_e[3])


def _px4_rate_setpoint(att, att_sp, x_ref, v, scale):
    """PX4's attitude stage: the rate setpoint (angle unit/s, (3,)) of the measured attitude ``att`` and its
    setpoint ``att_sp`` (angle unit): :func:`px4_attitude_error` times the P gains (the yaw's divided by
    the yaw weight, as ``setProportionalGain`` does), plus the reference's yaw rate about the world z axis
    turned into the body frame, within the rate limits."""
    w = ca.fmin(ca.fmax(v["att_yaw_weight"], 0), 1)
    k_yaw = ca.if_else(w > YAW_WEIGHT_FLOOR, v["att_yaw_kp"] / ca.fmax(w, YAW_WEIGHT_FLOOR), v["att_yaw_kp"])
    err = px4_attitude_error(att / scale, att_sp / scale, v["att_yaw_weight"])
    rate_sp = err * ca.vertcat(v["att_roll_kp"], v["att_pitch_kp"], k_yaw)
    # the reference's yaw rate (omega = H euler_rates, the model's kinematics), fed forward about the world
    # z axis seen from the body (H's last column at the measured attitude)
    body = STATE_INDEX["p"]
    yaw_rate = ca.solve(euler_rates_matrix(x_ref[STATE_INDEX["phi"]], x_ref[STATE_INDEX["theta"]]),
                        x_ref[body:body + 3])[2]
    world_z = euler_rates_matrix(att[0] / scale, att[1] / scale)[:, 2]
    return (rate_sp + world_z * yaw_rate) * scale


def _wrap(angle, half_turn):
    return angle - 2 * half_turn * ca.floor((angle + half_turn) / (2 * half_turn))


def measurements(x, scale):
    """(velocity in the yaw-turned frame with z up (3,), attitude (3,), body rates (3,)) of the
    measured state ``x`` (12,), the angles and rates times ``scale`` (the stack's angle unit per rad)."""
    phi, theta = x[STATE_INDEX["phi"]], x[STATE_INDEX["theta"]]
    body = x[STATE_INDEX["u"]:STATE_INDEX["u"] + 3]
    cph, sph, cth, sth = ca.cos(phi), ca.sin(phi), ca.cos(theta), ca.sin(theta)
    # R_y(theta) R_x(phi) [u; v; w]: the velocity turned by the yaw only (NED heading frame)
    vx = cth * body[0] + sth * sph * body[1] + sth * cph * body[2]
    vy = cph * body[1] - sph * body[2]
    vz = -sth * body[0] + cth * sph * body[1] + cth * cph * body[2]
    att = ca.vertcat(phi, theta, x[STATE_INDEX["psi"]]) * scale
    rates = x[STATE_INDEX["p"]:STATE_INDEX["p"] + 3] * scale
    return ca.vertcat(vx, vy, -vz), att, rates


def _earth_velocity(x):
    """Velocity NED (3,) of the state ``x``: ``R_b^E [u; v; w]``."""
    phi, theta, psi = (x[STATE_INDEX[s]] for s in ("phi", "theta", "psi"))
    body = x[STATE_INDEX["u"]:STATE_INDEX["u"] + 3]
    cph, sph, cth, sth, cps, sps = ca.cos(phi), ca.sin(phi), ca.cos(theta), ca.sin(theta), ca.cos(psi), ca.sin(psi)
    R = ca.vertcat(ca.horzcat(cth * cps, sph * sth * cps - cph * sps, cph * sth * cps + sph * sps),
                   ca.horzcat(cth * sps, sph * sth * sps + cph * cps, cph * sth * sps - sph * cps),
                   ca.horzcat(-sth, sph * cth, cph * cth))
    return R @ body


def law(structure: tuple, s, x_m, x_ref, u_ref, values, mix, mix_inv, hi, curve, Ts, gravity):
    """One sample of the cascade: ``(command [T, A, E, R] (4,), the law's next states)``.

    Parameters
    ----------
    structure : tuple
        :func:`structure_of`.
    s : CasADi column (N_LAW_STATES,)
    x_m : CasADi column (12,)
        The measured state.
    x_ref : CasADi column (12,)
        The reference state (position, heading and body velocity the cascade tracks).
    u_ref : CasADi column (4,)
        The reference input (its thrust: PX4's hover thrust).
    values : CasADi column
        The cascade's values (:data:`quadctl.config.pid.PARAMETERS`).
    mix, mix_inv : CasADi (4, 4)
        The rotors' mixing and its inverse.
    hi : CasADi column (4,)
        The rotors' largest thrusts (N).
    curve : CasADi (4, 3)
        N: each rotor's ``(c0, c1, c2)``, its thrust ``c0 + c1 s + c2 s^2`` at the PWM fraction ``s``
        (:func:`pwm_thrust_curve`; PWM torques only).
    Ts : CasADi scalar
        s: the base period.
    gravity : CasADi scalar
        m/s^2.
    """
    from quadctl.config.pid import NAMES

    _, n_att, n_pos, unit, vel_out, torque_out, dfilter, gyro, stage = structure
    v = {name: values[i] for i, name in enumerate(NAMES)}
    scale = 180.0 / math.pi if unit == "deg" else 1.0
    half_turn = 180.0 if unit == "deg" else math.pi
    part = {name: s[sl] for name, sl in _SLICES.items()}
    T_pos, T_att = n_pos * Ts, n_att * Ts
    phase = part["phase"][0]
    run_pos = phase < 0.5
    run_att = run_pos
    for j in range(1, n_pos // n_att):  # the phases that are whole multiples of n_att
        run_att = ca.logic_or(run_att, ca.fabs(phase - j * n_att) < 0.5)

    vel, att, rates = measurements(x_m, scale)
    gyro_next = part["gyro_filter"]
    if gyro:  # the stack's gyro low-pass: second-order Butterworth (bilinear, prewarped) at the base rate
        b0, b1, b2, a1, a2 = butterworth2(v["gyro_lpf_hz"] * Ts)
        d1, d2 = part["gyro_filter"][0:3], part["gyro_filter"][3:6]
        d0 = rates - a1 * d1 - a2 * d2
        rates = b0 * d0 + b1 * d1 + b2 * d2
        gyro_next = ca.vertcat(d0, d1)
    psi = x_m[STATE_INDEX["psi"]]
    c, sn = ca.cos(psi), ca.sin(psi)

    def turn(vec):  # NED (x, y) into the yaw-turned frame
        return ca.vertcat(c * vec[0] + sn * vec[1], -sn * vec[0] + c * vec[1])

    # position: P(I) on the position error, plus the reference's velocity
    e_xy = turn(x_ref[0:2] - x_m[0:2])
    e_pos = ca.vertcat(e_xy, -(x_ref[2] - x_m[2]))
    v_ff_ned = _earth_velocity(x_ref)
    v_ff = ca.vertcat(turn(v_ff_ned[0:2]), -v_ff_ned[2])
    i_pos = integrate(part["pos_integral"], e_pos, T_pos, v["pos_ilimit"])
    kp_pos = ca.vertcat(v["pos_xy_kp"], v["pos_xy_kp"], v["pos_z_kp"])
    ki_pos = ca.vertcat(v["pos_xy_ki"], v["pos_xy_ki"], v["pos_z_ki"])
    v_sp = pid_output(kp_pos, ki_pos, 0, e_pos, i_pos, 0) + v_ff
    v_sp = ca.vertcat(_clamp(v_sp[0], v["pos_vel_limit_xy"]), _clamp(v_sp[1], v["pos_vel_limit_xy"]),
                      ca.fmin(ca.fmax(v_sp[2], -v["pos_vel_limit_down"]), v["pos_vel_limit_up"]))
    # velocity: PID, D on the measured velocity
    e_vel = v_sp - vel
    i_vel = integrate(part["vel_integral"], e_vel, T_pos, v["vel_ilimit"])
    d_vel = derivative(vel, part["vel_previous"], T_pos)
    kp_v = ca.vertcat(v["vel_xy_kp"], v["vel_xy_kp"], v["vel_z_kp"])
    ki_v = ca.vertcat(v["vel_xy_ki"], v["vel_xy_ki"], v["vel_z_ki"])
    kd_v = ca.vertcat(v["vel_xy_kd"], v["vel_xy_kd"], v["vel_z_kd"])
    o = pid_output(kp_v, ki_v, kd_v, e_vel, i_vel, d_vel)
    yaw_sp = x_ref[STATE_INDEX["psi"]] * scale
    if vel_out == "angles":
        tilt = v["tilt_limit"]
        att_sp = ca.vertcat(ca.fmin(ca.fmax(o[1], -tilt), tilt), ca.fmin(ca.fmax(-o[0], -tilt), tilt), yaw_sp)
        thrust_sp = ca.fmin(ca.fmax(v["thrust_base"] + v["thrust_scale"] * o[2], v["thrust_min"]), PWM_FULL)
    else:
        hover = u_ref[0] / px4_units(mix, hi)[0]
        t_vec = ca.vertcat(o[0], o[1], -o[2] - gravity) * (hover / gravity)
        up = -t_vec[2]
        horizontal = ca.sqrt(t_vec[0] ** 2 + t_vec[1] ** 2)
        allowed = ca.fmax(up, 0) * ca.tan(v["tilt_limit"] / scale)
        shrink = ca.if_else(horizontal > allowed, allowed / ca.fmax(horizontal, 1e-12), 1)
        t_vec = ca.vertcat(t_vec[0] * shrink, t_vec[1] * shrink, t_vec[2])
        norm = ca.sqrt(ca.sumsqr(t_vec))
        roll = ca.atan2(t_vec[1], ca.sqrt(t_vec[0] ** 2 + t_vec[2] ** 2))
        pitch = ca.atan2(-t_vec[0], -t_vec[2])
        att_sp = ca.vertcat(roll * scale, pitch * scale, yaw_sp)
        thrust_sp = ca.fmin(ca.fmax(norm, v["thrust_min"]), v["thrust_max"])
    att_sp = ca.if_else(run_pos, att_sp, part["att_setpoint"])
    thrust_sp = ca.if_else(run_pos, thrust_sp, part["thrust_setpoint"])
    i_pos = ca.if_else(run_pos, i_pos, part["pos_integral"])
    i_vel = ca.if_else(run_pos, i_vel, part["vel_integral"])
    vel_prev = ca.if_else(run_pos, vel, part["vel_previous"])

    if stage == "px4":  # PX4: the quaternion error, thrust axis first, P per axis, yaw rate fed forward
        rate_sp = _px4_rate_setpoint(att, att_sp, x_ref, v, scale)
        i_att = part["att_integral"]
    else:  # PID per Euler angle, the yaw error (and its D's difference) wrapped
        e_att = att_sp - att
        e_att = ca.vertcat(e_att[0:2], _wrap(e_att[2], half_turn))
        delta = att - part["att_previous"]
        delta = ca.vertcat(delta[0:2], _wrap(delta[2], half_turn))
        kp_a = ca.vertcat(v["att_roll_kp"], v["att_pitch_kp"], v["att_yaw_kp"])
        ki_a = ca.vertcat(v["att_roll_ki"], v["att_pitch_ki"], v["att_yaw_ki"])
        kd_a = ca.vertcat(v["att_roll_kd"], v["att_pitch_kd"], v["att_yaw_kd"])
        il_a = [v["att_roll_ilimit"], v["att_pitch_ilimit"], v["att_yaw_ilimit"]]
        i_att = ca.vertcat(*[integrate(part["att_integral"][k], e_att[k], T_att, il_a[k]) for k in range(3)])
        rate_sp = pid_output(kp_a, ki_a, kd_a, e_att, i_att, -delta / T_att)
    limits = [v["att_rate_limit_rp"], v["att_rate_limit_rp"], v["att_rate_limit_yaw"]]
    rate_sp = ca.vertcat(*[_clamp(rate_sp[k], limits[k]) for k in range(3)])
    rate_sp = ca.if_else(run_att, rate_sp, part["rate_setpoint"])
    i_att = ca.if_else(run_att, i_att, part["att_integral"])
    att_prev = ca.if_else(run_att, att, part["att_previous"])

    # rate: PID at every sample
    e_rate = rate_sp - rates
    kp_r = ca.vertcat(v["rate_roll_kp"], v["rate_pitch_kp"], v["rate_yaw_kp"])
    ki_r = ca.vertcat(v["rate_roll_ki"], v["rate_pitch_ki"], v["rate_yaw_ki"])
    kd_r = ca.vertcat(v["rate_roll_kd"], v["rate_pitch_kd"], v["rate_yaw_kd"])
    il_r = [v["rate_roll_ilimit"], v["rate_pitch_ilimit"], v["rate_yaw_ilimit"]]
    if torque_out == "normalized":
        # PX4: the I term in torque units, applied before it grows (forward Euler) by i_factor ki e dt,
        # i_factor = max(0, 1 - (e / 400 deg/s)^2), within the limits
        i_term = part["rate_integral"]
        i_factor = ca.fmax(0, 1 - (e_rate / (PX4_I_RATE_SCALE * scale * math.pi / 180)) ** 2)
        grown = i_term + i_factor * ki_r * e_rate * Ts
        i_rate = ca.vertcat(*[_clamp(grown[k], il_r[k]) for k in range(3)])
    else:
        i_rate = ca.vertcat(*[integrate(part["rate_integral"][k], e_rate[k], Ts, il_r[k]) for k in range(3)])
        i_term = ki_r * i_rate
    d_rate = derivative(rates, part["rate_previous"], Ts)
    d_next = part["rate_derivative"]
    if dfilter:  # the D-term low-pass: second-order Butterworth at the base rate
        b0, b1, b2, a1, a2 = butterworth2(v["rate_dfilter_hz"] * Ts)
        e1, e2 = part["rate_derivative"][0:3], part["rate_derivative"][3:6]
        e0 = d_rate - a1 * e1 - a2 * e2
        d_rate = b0 * e0 + b1 * e1 + b2 * e2
        d_next = ca.vertcat(e0, e1)
    out = pid_output(kp_r, 1, kd_r, e_rate, i_term, d_rate)
    out = ca.vertcat(*[_clamp(out[k], v["rate_output_limit"]) for k in range(3)])

    if torque_out == "pwm":
        pwm = legacy_pwm(thrust_sp, out, mix)
        sfrac = ca.fmin(ca.fmax(pwm, 0), PWM_FULL) / PWM_FULL
        rotors = curve[:, 0] + curve[:, 1] * sfrac + curve[:, 2] * sfrac ** 2
        command = mix_inv @ rotors
    else:  # PX4's control allocation, unsaturated: each normalized input is its own multiple of the input
        command = ca.vertcat(thrust_sp, out) * px4_units(mix, hi)
    phase = ca.if_else(phase + 1 > n_pos - 0.5, 0, phase + 1)
    s_next = ca.vertcat(phase, i_pos, i_vel, vel_prev, att_sp, thrust_sp, i_att, att_prev, rate_sp, i_rate,
                        rates, d_next, gyro_next)
    return command, s_next


def butterworth2(ratio, lib=ca):
    """``(b0, b1, b2, a1, a2)`` of the second-order Butterworth low-pass of cutoff ``ratio`` times the
    sample rate, by the bilinear transform prewarped at the cutoff: ``y = b0 d0 + b1 d1 + b2 d2`` with
    ``d0 = x - a1 d1 - a2 d2`` (direct form II), unit gain at zero frequency."""
    w = lib.tan(math.pi * ratio)
    c = 1 + math.sqrt(2) * w + w * w
    b0 = w * w / c
    return b0, 2 * b0, b0, 2 * (w * w - 1) / c, (1 - math.sqrt(2) * w + w * w) / c


@lru_cache(maxsize=4)
def _measure_function(unit: str):
    x = ca.SX.sym("x", N_STATES)
    vel, att, rates = measurements(x, 180.0 / math.pi if unit == "deg" else 1.0)
    return ca.Function("pid_measure", [x], [ca.vertcat(vel, att, rates)])


def initial_states(gains, x0, u_trim) -> np.ndarray:
    """The law's states at the start of a run from ``x0`` (12,): integrators at zero, each D term's
    previous measurement the initial one (as after flying steady: no kick on the first sample), the
    setpoints at level flight (the first sample computes them, every loop runs at phase 0)."""
    m = np.asarray(_measure_function(gains.angle_unit)(np.asarray(x0, dtype=float))).ravel()
    out = np.zeros(N_LAW_STATES)
    out[_SLICES["vel_previous"]] = m[0:3]
    out[_SLICES["att_previous"]] = m[3:6]
    out[_SLICES["rate_previous"]] = m[6:9]
    if gains["gyro_lpf_hz"] > 0:  # the filter at rest at the initial rates
        _, _, _, a1, a2 = butterworth2(gains["gyro_lpf_hz"] / gains["rate_hz"], lib=np)
        rest = m[6:9] / (1 + a1 + a2)
        out[_SLICES["gyro_filter"]] = np.concatenate([rest, rest])
    return out

