"""PX4's attitude stage (``attitude: px4`` of :mod:`quadctl.sim.pid`) against an independent reference.

The law's attitude error must be Brescianini, Hehn and D'Andrea's (2013) reduced-then-full quaternion
error, written here again from the paper's equations with SciPy's rotations (no select, no shared code):
to round-off on random attitudes and setpoints, the plain quaternion error with yaw weight 1, the Euler
angle errors to first order about level flight. Flown on PX4's Iris with PX4's defaults, a 60 deg roll
and 90 deg yaw error must close the thrust axis first. PX4's rate integrator grows in torque units by
``i_factor ki e dt`` within its limit (src/lib/rate_control/rate_control.cpp).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

ROUND_OFF = 1e-12
"""Absolute, rad: both sides compute a unit-size vector from a dozen well-conditioned products and one
atan2 (the reference's rotation vectors); they agree to ~1e-15."""


def brescianini(att, att_sp, weight):
    """The attitude error (body frame, rad) from the paper's equations: ``alpha``, ``k`` the angle and
    axis taking the body z axis to the setpoint's (world frame), ``q_red = R(alpha k) q``; ``q_mix =
    q_red^-1 q_d`` a rotation by ``alpha_mix`` about z; ``q_cmd = q_red R_z(weight alpha_mix)``; the error
    ``2 sin(|theta| / 2) theta / |theta|`` of ``q^-1 q_cmd``'s rotation vector ``theta`` (the shorter way)."""
    q = Rotation.from_euler("ZYX", att[::-1])
    qd = Rotation.from_euler("ZYX", att_sp[::-1])
    ez, ezd = q.as_matrix()[:, 2], qd.as_matrix()[:, 2]
    cross = np.cross(ez, ezd)
    alpha = math.atan2(np.linalg.norm(cross), ez @ ezd)
    q_red = Rotation.from_rotvec(alpha * cross / np.linalg.norm(cross)) * q
    mix = (q_red.inv() * qd).as_rotvec()
    assert np.hypot(mix[0], mix[1]) < 1e-12  # the mix is about z alone
    theta = (q.inv() * q_red * Rotation.from_rotvec([0.0, 0.0, weight * mix[2]])).as_rotvec()
    angle = np.linalg.norm(theta)
    return 2 * math.sin(angle / 2) * theta / angle if angle > 0 else theta


@pytest.fixture(scope="module")
def law_error():
    """The law's :func:`quadctl.sim.pid.px4_attitude_error` as a numeric function of (att, att_sp, weight)."""
    import casadi as ca

    from quadctl.sim.pid import px4_attitude_error

    a, b, w = ca.SX.sym("a", 3), ca.SX.sym("b", 3), ca.SX.sym("w")
    f = ca.Function("px4_error", [a, b, w], [px4_attitude_error(a, b, w)])
    return lambda att, sp, weight: np.asarray(f(att, sp, weight)).ravel()


def random_attitudes(n, seed):
    """``n`` pairs (attitude, setpoint) of Euler angles over the whole sphere short of the poles."""
    rng = np.random.default_rng(seed)
    lim = np.array([math.pi, 0.45 * math.pi, math.pi])
    return rng.uniform(-lim, lim, (n, 3)), rng.uniform(-lim, lim, (n, 3))


@pytest.mark.parametrize("weight", [0.4, 0.0, 0.75, 1.0])
def test_the_px4_attitude_error_is_brescianinis_reduced_then_full_error(law_error, weight):
    atts, sps = random_attitudes(300, seed=11)
    worst, shorter_way = 0.0, 0
    for att, sp in zip(atts, sps):
        want = brescianini(att, sp, weight)
        worst = max(worst, np.abs(law_error(att, sp, weight) - want).max())
        shorter_way += np.linalg.norm(want) > math.sqrt(2)  # beyond a half turn's half: q_e.w < 0 was flipped
    assert worst < ROUND_OFF, f"max diff {worst:.4E}"
    assert weight == 0.0 or shorter_way > 10  # the sign(w) select was exercised


def test_with_yaw_weight_one_it_is_the_plain_quaternion_error(law_error):
    """Weight 1: the error of ``q_e = q^-1 q_d`` itself, ``2 sign(w) (x, y, z)``."""
    atts, sps = random_attitudes(200, seed=5)
    worst = 0.0
    for att, sp in zip(atts, sps):
        x, y, z, w = (Rotation.from_euler("ZYX", att[::-1]).inv() * Rotation.from_euler("ZYX", sp[::-1])).as_quat()
        worst = max(worst, np.abs(law_error(att, sp, 1.0) - 2 * math.copysign(1.0, w) * np.array([x, y, z])).max())
    assert worst < ROUND_OFF, f"max diff {worst:.4E}"


@pytest.mark.parametrize("setpoint", [(math.pi, 0.0, 0.3), (math.pi, 0.0, -2.0), (0.0, math.pi, 1.0)])
def test_a_half_turn_of_the_thrust_axis_takes_the_full_setpoint_unweighted(law_error, setpoint):
    """From level to a setpoint upside down (its thrust axis a half turn about a horizontal axis away),
    the reduced attitude is undefined; PX4 takes the full setpoint: the plain quaternion error, the yaw
    weight unused."""
    att, sp = np.zeros(3), np.array(setpoint)
    x, y, z, w = Rotation.from_euler("ZYX", sp[::-1]).as_quat()
    want = 2 * math.copysign(1.0, w) * np.array([x, y, z])
    np.testing.assert_allclose(law_error(att, sp, 0.4), want, atol=ROUND_OFF)


@pytest.mark.parametrize("eps", [1e-1, 1e-2, 1e-3])
def test_small_errors_about_level_are_the_euler_angle_errors_to_first_order(law_error, eps):
    """Attitude and error each within ``eps`` of level, every angle: the error is ``(d phi, d theta, w d psi)``
    (times the P gains, the yaw's divided by ``w``: the Euler law's P) but for products of two small
    angles, at most ``2 eps^2`` (measured 1.5 eps^2)."""
    rng = np.random.default_rng(3)
    for _ in range(100):
        att, d = rng.uniform(-eps, eps, 3), rng.uniform(-eps, eps, 3)
        for weight in (0.4, 1.0):
            err = law_error(att, att + d, weight) - d * np.array([1.0, 1.0, weight])
            assert np.abs(err).max() <= 2 * eps ** 2, (att, d, weight, err)


@pytest.fixture(scope="module")
def iris_tumbled():
    """PX4's Iris (``quadctl init``'s iris preset, hover) from a 60 deg roll and 90 deg yaw error."""
    import yaml

    import quadctl as qc
    from quadctl.config import Config
    from quadctl.config import template as starter

    data = yaml.safe_load(starter.config_text("iris-px4", "iris", "hover"))
    data["simulation"]["initial_offset"] = {"phi": math.radians(60), "psi": math.radians(90)}
    return qc.Stages(qc.setup_of(Config(**data)))


def errors_after(stages, gains, times):
    """(roll, yaw) errors (deg) of the cascade ``gains`` flown from the stages' offset, at ``times`` (s)."""
    import quadctl as qc
    from quadctl.layout import STATE_INDEX
    from quadctl.pipeline import pid_loop_of

    loop = pid_loop_of(stages.setup, stages.linear, gains)
    run = qc.simulate(loop, stages.setup.initial_state(loop.x_trim), max(times))
    assert run.status == "ok", run.message
    k = np.searchsorted(run.t, np.asarray(times) - 1e-9)
    e = np.degrees(run.x[k] - run.x_ref[k])
    return np.abs(e[:, STATE_INDEX["phi"]]), np.abs(e[:, STATE_INDEX["psi"]])


@pytest.mark.compiler
def test_a_large_tilt_and_yaw_error_closes_the_thrust_axis_first(iris_tumbled):
    """60 deg roll and 90 deg yaw off: in the first 0.2 s the roll error closes (as a share of itself)
    more than three times faster than the yaw's; with the yaw weight 1 (no priority) the yaw closes
    more and the roll less than with PX4's 0.4 (measured: roll 60 -> 31 deg, yaw 90 -> 84 deg at 0.4;
    roll -> 34, yaw -> 75 at 1)."""
    from quadctl.config.pid import resolve

    px4 = resolve("px4")
    assert px4.attitude == "px4" and px4["att_yaw_weight"] == 0.4
    roll, yaw = errors_after(iris_tumbled, px4, [0.0, 0.2])
    assert roll[0] == pytest.approx(60) and yaw[0] == pytest.approx(90)
    roll_closed, yaw_closed = 1 - roll[1] / roll[0], 1 - yaw[1] / yaw[0]
    assert roll_closed > 3 * yaw_closed > 0, (roll, yaw)
    roll1, yaw1 = errors_after(iris_tumbled, px4.with_values(att_yaw_weight=1.0), [0.0, 0.2])
    assert yaw1[1] < yaw[1] - 3 and roll1[1] > roll[1] + 1, (roll, yaw, roll1, yaw1)


def test_the_attitude_stage_is_the_presets_unless_the_config_names_one():
    import quadctl as qc
    from quadctl.config import Config
    from quadctl.config.pid import resolve

    assert resolve("crazyflie").attitude == "euler"  # attitude_pid_controller.c: Euler angle errors
    assert resolve("px4").attitude == "px4"
    assert resolve("px4", attitude="euler").attitude == "euler"
    with pytest.raises(ValueError, match="unknown attitude stage 'quat'"):
        resolve("px4", attitude="quat")
    data = qc.load_config("crazyflie").model_dump(mode="json")
    data["controller"]["pid"] = {"preset": "crazyflie", "attitude": "px4"}
    assert qc.setup_of(Config(**data)).pid.attitude == "px4"


@pytest.mark.parametrize("error_dps, factor", [(0.0, 1.0), (200.0, 0.75), (400.0, 0.0), (600.0, 0.0)])
def test_px4s_rate_integrator_grows_in_torque_units_by_i_factor_ki_e_dt(error_dps, factor):
    """One sample of the law at level with a roll rate error ``e``: the roll I term (torque) grows by
    ``max(0, 1 - (e / 400 deg/s)^2) ki e dt`` and stops at MC_RR_INT_LIM."""
    import casadi as ca

    from quadctl.config.pid import resolve
    from quadctl.layout import N_STATES, STATE_INDEX
    from quadctl.sim import pid

    gains = resolve("px4", {"gyro_lpf_hz": 0.0, "rate_dfilter_hz": 0.0})
    Ts, e = 1 / gains["rate_hz"], math.radians(error_dps)
    ki, lim = gains["rate_roll_ki"], gains["rate_roll_ilimit"]

    def next_integral(start):
        s = np.zeros(pid.N_LAW_STATES)
        s[pid.state_slice("rate_integral")] = [start, 0.0, 0.0]
        x = np.zeros(N_STATES)
        x[STATE_INDEX["p"]] = -e  # rate setpoint 0 at level: the error is e
        _, s_next = pid.law(pid.structure_of(gains), ca.DM(s), ca.DM(x), ca.DM(np.zeros(N_STATES)),
                            ca.DM([10.0, 0, 0, 0]), ca.DM(gains.values), ca.DM(np.eye(4)), ca.DM(np.eye(4)),
                            ca.DM(np.full(4, 10.0)), ca.DM.zeros(4, 3), Ts, 9.81)
        return float(np.asarray(s_next).ravel()[pid.state_slice("rate_integral")][0])

    assert next_integral(0.0) == pytest.approx(factor * ki * e * Ts, rel=1e-12, abs=1e-15)
    assert next_integral(lim) == pytest.approx(lim, rel=1e-12)
    assert next_integral(-lim) == pytest.approx(-lim + factor * ki * e * Ts, rel=1e-12)
