"""PID loops against closed forms, and the flight stacks' cascades flown on the full nonlinear model.

The axis loops (:func:`quadctl.design.pid.axis_loop`) must have the roots of their characteristic
polynomials written out by hand (continuous, and sampled through the zero-order hold's transfer
function ``T^2 (z + 1) / (2 m (z - 1)^2)``); the simulation law's PID arithmetic
(:mod:`quadctl.sim.pid`) must be the sampled loop's; the attitude PID inside the simulated cascade (its
D's sign and period) must give the roll axis the poles of that axis sampled by hand. The Crazyflie's
cascade with its firmware's defaults must hold the bundled ``crazyflie`` config's hover from its
initial offset within the rotor limits, and fail with one gain's sign flipped.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadctl.design.pid import axis_loop

POLE_TOL = 1e-9
"""Relative: the roots of a cubic or quartic with well-separated roots, and the eigenvalues of a 3x3 or
4x4 matrix of entries of order one, agree to ~1e-13; 1e-9 leaves room for any LAPACK."""

M, T = 0.027, 0.002  # kg (the Crazyflie's mass), s (its 500 Hz attitude loop)


def assert_same_poles(A, roots, extra=()):
    """The eigenvalues of ``A`` are ``roots`` (with ``extra``), as sets, each to POLE_TOL of its size."""
    want = np.sort_complex(np.concatenate([np.roots(roots), np.asarray(extra, dtype=complex)]))
    got = np.sort_complex(np.linalg.eigvals(A))
    assert len(got) == len(want)
    for g in got:  # each pole matched by the nearest root (sets, not sorted order)
        k = int(np.argmin(np.abs(want - g)))
        diff = abs(want[k] - g)
        assert diff <= POLE_TOL * max(1.0, abs(g)), f"pole {g} vs {want[k]}: max diff {diff:.4E}"
        want = np.delete(want, k)


@pytest.mark.parametrize("kp, ki, kd", [(2.0, 0.5, 0.3), (25.0, 15.0, 0.0), (0.8, 0.0, 0.2)])
def test_continuous_pid_on_a_double_integrator_has_the_poles_of_m_s3_kd_s2_kp_s_ki(kp, ki, kd):
    assert_same_poles(axis_loop(M, kp, ki, kd), [M, kd, kp, ki])


@pytest.mark.parametrize("kp, ki, kd", [(2.0, 0.5, 0.3), (25.0, 15.0, 0.001), (0.8, 0.0, 0.002)])
def test_sampled_pid_on_a_double_integrator_has_the_poles_of_its_z_domain_polynomial(kp, ki, kd):
    # 1 + P C = 0, P = T^2 (z + 1) / (2 m (z - 1)^2), C = kp + ki T z / (z - 1) + kd (z - 1) / (T z):
    # 2 m (z - 1)^3 z + T^2 (z + 1) (kp z (z - 1) + ki T z^2 + kd (z - 1)^2 / T) = 0
    z1, z = np.array([1.0, -1.0]), np.array([1.0, 0.0])
    controller = np.polyadd(np.polyadd(kp * np.polymul(z, z1), ki * T * np.polymul(z, z)),
                            kd / T * np.polymul(z1, z1))
    poly = np.polyadd(2 * M * np.polymul(np.polymul(np.polymul(z1, z1), z1), z),
                      T * T * np.polymul([1.0, 1.0], controller))
    assert_same_poles(axis_loop(M, kp, ki, kd, sample_time=T), poly)


@pytest.mark.parametrize("outer, kp, ki", [(2.0, 25.0, 15.0), (0.95, 4.0, 2.0)])
def test_continuous_p_over_pi_cascade_has_the_poles_of_its_cubic(outer, kp, ki):
    # m s^2 X = (kp + ki / s)(-outer X - s X)  =>  m s^3 + kp s^2 + (kp outer + ki) s + ki outer = 0
    assert_same_poles(axis_loop(M, kp, ki, outer=outer), [M, kp, kp * outer + ki, ki * outer])


@pytest.mark.parametrize("outer, kp, ki", [(2.0, 25.0, 15.0), (0.95, 4.0, 2.0)])
def test_sampled_p_over_pi_cascade_has_the_poles_of_its_z_domain_polynomial(outer, kp, ki):
    # E = -outer X - V, X = T^2 (z + 1) U / (2 m (z - 1)^2), V = T U / (m (z - 1)), U = (kp + ki T z / (z - 1)) E:
    # 2 m (z - 1)^3 + (kp (z - 1) + ki T z)(outer T^2 (z + 1) + 2 T (z - 1)) = 0; the unused previous
    # measurement (no D) adds a pole at 0
    z1 = np.array([1.0, -1.0])
    poly = np.polyadd(2 * M * np.polymul(np.polymul(z1, z1), z1),
                      np.polymul(np.polyadd(kp * z1, [ki * T, 0.0]),
                                 np.polyadd(outer * T * T * np.array([1.0, 1.0]), 2 * T * z1)))
    assert_same_poles(axis_loop(M, kp, ki, outer=outer, sample_time=T), poly, extra=[0.0])


def test_the_simulation_law_pid_is_the_sampled_axis_loop():
    """The law's PID arithmetic (integrate, derivative, pid_output of quadctl.sim.pid) on the axis state
    gives axis_loop's sampled matrix column by column (the map is linear: its columns are the images
    of the unit vectors)."""
    from quadctl.sim.pid import derivative, integrate, pid_output

    kp, ki, kd = 2.0, 0.5, 0.3

    def step(s):
        x, v, i, y_prev = s
        e = -x
        i_new = integrate(i, e, T, 0.0, lib=np)
        u = pid_output(kp, ki, kd, e, i_new, derivative(x, y_prev, T))
        return np.array([x + T * v + T * T / (2 * M) * u, v + T / M * u, i_new, x])

    A = np.column_stack([step(col) for col in np.eye(4)])
    np.testing.assert_allclose(A, axis_loop(M, kp, ki, kd, sample_time=T), rtol=1e-14, atol=1e-14)


@pytest.fixture(scope="module")
def crazyflie():
    import quadctl as qc

    return qc.Stages(qc.setup_of(qc.load_config("crazyflie")))


def fly(stages, gains, duration=8.0):
    import quadctl as qc
    from quadctl.pipeline import pid_loop_of

    loop = pid_loop_of(stages.setup, stages.linear, gains)
    return loop, qc.simulate(loop, stages.setup.initial_state(loop.x_trim), duration)


def roll_axis_frame_map(G, Ts, n_att, kp, ki, kd):
    """The roll axis sampled by hand: the map of one attitude period on ``[phi, p, i, phi_prev, r]``.

    ``phi'' = G (r - p)`` under a zero-order hold at ``Ts`` (the rate loop, a P; ``G`` in 1/s, its gain times the
    roll torque of a unit of its output over the inertia); ``r = kp e + ki i + kd d`` computed every ``n_att``
    samples and held (``e = -phi``, ``i`` by backward Euler, ``d = -(phi - phi_prev) / Ta`` on the measurement,
    ``Ta = n_att Ts``).
    """
    Ta = Ts * n_att
    update = np.eye(5)  # the attitude PID at phase 0, before the sample: i, phi_prev and r from the state
    update[2] = [-Ta, 0, 1, 0, 0]
    update[3] = [1, 0, 0, 0, 0]
    update[4] = [-kp - ki * Ta - kd / Ta, 0, ki, kd / Ta, 0]
    sample = np.eye(5)  # one sample of the plant under the held r
    sample[0] = [1, Ts - Ts ** 2 / 2 * G, 0, 0, Ts ** 2 / 2 * G]
    sample[1] = [0, 1 - Ts * G, 0, 0, Ts * G]
    return np.linalg.matrix_power(sample, n_att) @ update


def eigenvalue_conditions(A) -> tuple[np.ndarray, np.ndarray]:
    """The eigenvalues of ``A`` and their condition numbers ``|y| |x| / |y^H x|`` (first-order perturbation:
    an eigenvalue moves at most that times the size of a change of ``A``)."""
    lam, right = np.linalg.eig(A)
    left = np.linalg.inv(right).conj().T
    kappa = np.linalg.norm(left, axis=0) * np.linalg.norm(right, axis=0) / np.abs(np.sum(left.conj() * right, axis=0))
    return lam, kappa


MAP_TOL = 1e-10
"""Relative: the lifted loop's map (the plant's zero-order hold by a matrix exponential, the law's exact
Jacobian) against the hand map's arithmetic: both ~1e-14 of their size; 1e-10 leaves room for any LAPACK."""


@pytest.mark.parametrize("n_att", [1, 2])
def test_the_attitude_pid_of_the_simulated_cascade_has_the_poles_of_the_roll_axis_sampled_by_hand(crazyflie, n_att):
    """The attitude stage's D (its sign, its period) as the simulation flies it: the cascade's loop linearized
    (:func:`quadctl.sim.cascade_lift.lifted`, from the law the runners are generated from), its roll axis
    closed on itself (no position or velocity loop around it; the rate loop a P on PX4's normalized torque, no
    filters), has the poles of :func:`roll_axis_frame_map`, as sets; with the D's sign flipped they are far off."""
    import quadctl as qc
    from quadctl.config.pid import resolve
    from quadctl.layout import STATE_INDEX
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim import pid
    from quadctl.sim.cascade_lift import lifted

    Ts, kp_rate = 1 / 500, 0.15  # s; normalized torque per rad/s
    kp, ki, kd = 5.0, 2.0, 0.2  # 1/s, 1/s^2, 1: rate setpoint per angle error, its integral, its rate
    axis = dict(rate_roll_kp=kp_rate, rate_roll_ki=0.0, rate_roll_kd=0.0,
                att_roll_kp=kp, att_roll_ki=ki, att_roll_kd=kd)
    outer_hz = 1 / (Ts * n_att)
    gains = resolve("px4", attitude="euler").with_values(
        rate_hz=1 / Ts, attitude_hz=outer_hz, position_hz=outer_hz, gyro_lpf_hz=0.0, rate_dfilter_hz=0.0,
        vel_xy_kp=0.0, vel_xy_ki=0.0, vel_xy_kd=0.0, pos_xy_kp=0.0,  # the roll setpoint held at 0
        # pitch alike: PX4's rate D (tuned for a 1.5 kg vehicle) would make the 27 g Crazyflie's pitch diverge
        **axis, **{name.replace("roll", "pitch"): value for name, value in axis.items()})
    assert gains.angle_unit == "rad" and gains.torque_output == "normalized"
    loop = pid_loop_of(crazyflie.setup, crazyflie.linear, gains)
    lift = lifted(loop)
    assert lift.frame == n_att

    base = loop.spec().nx - pid.N_LAW_STATES  # the law's states follow the plant's
    law = {name: base + pid.state_slice(name).start
           for name in ("att_integral", "att_previous", "rate_setpoint", "rate_integral")}
    keep = list(lift.states)
    block = [keep.index(k) for k in (STATE_INDEX["phi"], STATE_INDEX["p"], *law.values()) if k in keep]
    rest = [i for i in range(len(keep)) if i not in block]
    Phi = lift.frame_map
    assert not np.any(Phi[np.ix_(block, rest)])  # the roll axis reads nothing else: its poles are the loop's
    got = np.linalg.eigvals(Phi[np.ix_(block, block)])

    cfg = qc.load_config("crazyflie")
    # PX4's roll torque per normalized unit: each rotor, at 45 deg from the x axis, moved by 1/sqrt 2 of its range
    # (PX4's control allocation, tests/sim/test_px4_allocation.py): 4 (L / sqrt 2) f_max / sqrt 2
    torque = 2 * cfg.motors.arm_length * cfg.motors.max_thrust
    G = kp_rate * torque / cfg.vehicle.inertia[0]
    want, kappa = eigenvalue_conditions(roll_axis_frame_map(G, Ts, n_att, kp, ki, kd))
    # the hand map's r is overwritten at each update (a pole at 0), as is the loop's held rate setpoint, which
    # the loop leaves out when the attitude runs at every sample; the rate integrator (ki 0) stays: a pole at 1
    if law["rate_setpoint"] not in keep:
        k = int(np.argmin(np.abs(want)))
        want, kappa = np.delete(want, k), np.delete(kappa, k)
    want, kappa = np.append(want, 1.0), np.append(kappa, 1.0)
    size = np.linalg.norm(Phi[np.ix_(block, block)], 2)
    assert len(got) == len(want)
    for w, k in zip(want, kappa):
        i = int(np.argmin(np.abs(got - w)))
        diff, bound = abs(got[i] - w), k * MAP_TOL * size
        assert diff <= bound, f"pole {w} vs {got[i]}: diff {diff:.4E}, bound {bound:.4E}"
        got = np.delete(got, i)
    flipped = np.linalg.eigvals(roll_axis_frame_map(G, Ts, n_att, kp, ki, -kd))
    assert max(np.min(np.abs(flipped - w)) for w in want) > 1e-3  # the D moves the poles: the test can fail


@pytest.mark.compiler
def test_the_crazyflie_cascade_with_firmware_defaults_recovers_hover_within_rotor_limits(crazyflie):
    from quadctl.config.pid import resolve

    loop, run = fly(crazyflie, resolve("crazyflie"))
    assert run.status == "ok", run.message
    offset = np.abs(crazyflie.setup.initial_offset)
    err = np.abs(run.x[-1] - run.x_ref[-1])
    # back to within 5 % of each offset (pD 0.5 m, phi and theta 0.1 rad, psi 0.2 rad) and 2 cm in position
    # (the altitude closes slowly: the firmware's position z integrator, KI 0.5)
    assert np.all(err[offset > 0] < 0.05 * offset[offset > 0]), err
    assert np.all(err[:3] < 0.02), err[:3]
    rotors = run.u @ loop.actuators.mix.T  # each rotor's thrust (N)
    act = loop.actuators
    assert rotors.min() >= act.lo.min() - 1e-12 and rotors.max() <= act.hi.max() + 1e-12


@pytest.mark.compiler
@pytest.mark.parametrize("flip", ["rate_roll_kp", "att_pitch_kp", "vel_z_kp"])
def test_the_crazyflie_cascade_with_one_gain_sign_flipped_does_not_recover(crazyflie, flip):
    from quadctl.config.pid import resolve

    gains = resolve("crazyflie")
    _, run = fly(crazyflie, gains.with_values(**{flip: -gains[flip]}), duration=4.0)
    err = np.abs(run.x[-1] - run.x_ref[-1])
    assert run.status != "ok" or err.max() > 0.5, (flip, run.status, err)


@pytest.mark.compiler
def test_the_cascade_flies_alike_in_the_one_case_loop_the_simd_lanes_and_the_interpreter(crazyflie):
    """Every runner is generated from the one builder: eight lanes of eight gain sets (the firmware's,
    scaled) give, lane by lane, the one-case compiled run of that gain set, and CasADi's virtual machine
    the first, to round-off (the SIMD build and the virtual machine may order or fuse operations
    differently: ~1e-14 relative over 250 samples of a loop whose PWM states are ~3e4)."""
    from quadctl.config.pid import resolve
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim.cases import Cases
    from quadctl.sim.engine import LANES, runner
    from quadctl.sim.interpreted import InterpretedRunner

    base = resolve("crazyflie")
    loops = [pid_loop_of(crazyflie.setup, crazyflie.linear,
                         base.with_values(rate_roll_kp=base["rate_roll_kp"] * (1 + 0.05 * k),
                                          att_pitch_kp=base["att_pitch_kp"] * (1 - 0.04 * k)))
             for k in range(LANES)]
    plan = loops[0].plan(0.5)
    x0 = crazyflie.setup.initial_state(loops[0].x_trim)
    lo, hi = loops[0].bounds(0.5)
    spec = loops[0].spec()
    assert len({loop.spec() for loop in loops}) == 1  # gains are constants: one compiled loop for all

    def cases(chosen):
        return Cases.of(np.array([loop.initial_loop_state(x0) for loop in chosen]),
                        np.array([loop.constants(plan.sample_time) for loop in chosen]), plan.dt, plan.n_steps, 50,
                        lo, hi, hold=plan.hold)

    lanes = runner(spec, LANES).run(cases(loops))
    for loop, (done, _, xs, _) in zip(loops, lanes):
        (done1, _, xs1, _), = runner(spec, 1).run(cases([loop]))
        assert done == done1 == plan.n_steps
        np.testing.assert_allclose(xs, xs1, rtol=1e-9, atol=1e-9)
    (_, _, xs_vm, _), = InterpretedRunner(spec).run(cases(loops[:1]))
    np.testing.assert_allclose(xs_vm, lanes[0][2], rtol=1e-9, atol=1e-9)


def test_a_cascade_told_to_fly_with_etdrk4_is_refused_naming_the_key():
    """ETDRK4's linear part is the LQR loop's: a PID cascade with it is one config error, not a traceback."""
    from _solve import cfg_dict

    from quadctl import config
    from quadctl.errors import ConfigError

    data = cfg_dict("crazyflie")
    data["controller"]["flies"] = "pid"
    data["simulation"]["method"] = "etdrk4"
    with pytest.raises(ConfigError, match=r"simulation\.method.*a PID cascade flies with RK4"):
        config.from_dict(data, "pid-etd.yaml")


def test_a_cascade_with_controller_filters_is_refused_naming_the_key():
    """The cascade filters the gyro as its stack does (the preset's cutoffs): a second filter is refused."""
    from _solve import cfg_dict

    from quadctl import config
    from quadctl.errors import ConfigError

    data = cfg_dict("crazyflie")
    data["controller"].update(flies="pid", filters={"gyro": {"cutoff": 80.0}})
    with pytest.raises(ConfigError, match=r"controller\.filters.*its flight stack's own gyro"):
        config.from_dict(data, "pid-filtered.yaml")


BUTTERWORTH_RTOL = 1e-12
"""Relative: two evaluations of the same rational coefficients in double precision."""


@pytest.mark.parametrize("cutoff, rate", [(80.0, 1000.0), (30.0, 500.0), (200.0, 500.0)])
def test_the_stacks_low_pass_is_scipys_prewarped_butterworth_and_minus_3_db_at_its_cutoff(cutoff, rate):
    """The gyro and D-term low-pass (:func:`quadctl.sim.pid.butterworth2`, direct form II) against
    ``scipy.signal.butter(2, cutoff, fs=rate)`` (the bilinear transform prewarped at the cutoff, as the
    Crazyflie's lpf2p and PX4's LowPassFilter2p are): the same coefficients, unit gain at zero frequency
    and ``1/sqrt(2)`` of it at the cutoff itself (without the prewarp, 200 Hz sampled at 500 Hz sits at -16 dB)."""
    import scipy.signal

    from quadctl.sim.pid import butterworth2

    b0, b1, b2, a1, a2 = butterworth2(cutoff / rate, lib=np)
    b, a = scipy.signal.butter(2, cutoff, fs=rate)
    np.testing.assert_allclose([b0, b1, b2], b, rtol=BUTTERWORTH_RTOL)
    np.testing.assert_allclose([1.0, a1, a2], a, rtol=BUTTERWORTH_RTOL, atol=BUTTERWORTH_RTOL)
    _, h = scipy.signal.freqz([b0, b1, b2], [1.0, a1, a2], worN=[0.0, cutoff], fs=rate)
    assert abs(h[0]) == pytest.approx(1.0, rel=BUTTERWORTH_RTOL)
    assert abs(h[1]) == pytest.approx(1 / math.sqrt(2), rel=1e-9)


def test_the_crazyflie_legacy_pwm_is_the_firmwares_power_distribution():
    """The firmware's legacy power distribution, written from its documented form
    (crazyflie-firmware, power_distribution_quadrotor.c): half the roll and pitch outputs, the whole
    yaw output, M1 front right, M2 rear right, M3 rear left, M4 front left, M1 and M3 counter-clockwise:
    m1 = T - r/2 + p/2 + y, m2 = T - r/2 - p/2 - y, m3 = T + r/2 - p/2 + y, m4 = T + r/2 + p/2 - y,
    in FRD torque senses (a roll to the right lifts the left rotors, nose up the front ones, a yaw to
    the right the counter-clockwise ones). quadctl's takes the signs from the crazyflie config's mixer."""
    import casadi as ca

    from quadctl import config
    from quadctl.setup import setup_of
    from quadctl.sim.pid_mixing import legacy_pwm

    mix = setup_of(config.load("crazyflie")).actuators.mix
    rng = np.random.default_rng(3)
    for thrust, r, p, y in rng.uniform(-20000.0, 40000.0, size=(20, 4)):
        want = [thrust - r / 2 + p / 2 + y, thrust - r / 2 - p / 2 - y, thrust + r / 2 - p / 2 + y,
                thrust + r / 2 + p / 2 - y]
        got = np.asarray(legacy_pwm(thrust, ca.DM([r, p, y]), ca.DM(mix))).ravel()
        np.testing.assert_allclose(got, want, rtol=1e-15, atol=1e-9)
