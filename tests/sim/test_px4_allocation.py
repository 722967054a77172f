"""The PX4 cascade's outputs as PX4's control allocation mixes them, against PX4's rules written out here.

PX4 turns the rate controller's normalized torque setpoint ``(roll, pitch, yaw)`` and the normalized
collective thrust ``t`` into motor outputs ``u`` (0: off, 1: full) for a multirotor as follows
(PX4/PX4-Autopilot; this module's reference is written from that documented behaviour, no code copied):

1. the effectiveness ``B`` (6 x n): rotor ``i`` at ``p_i`` (m, FRD) with thrust axis ``a = (0, 0, -1)``,
   thrust coefficient ``CT_i`` and moment ratio ``KM_i`` (positive: counter-clockwise seen from above) gives
   the moment ``CT_i (p_i x a) - CT_i KM_i a`` and the thrust ``CT_i a`` per unit output
   (src/modules/control_allocator/VehicleActuatorEffectiveness/ActuatorEffectivenessRotors.cpp,
   ``computeEffectivenessMatrix``, commit 1da805dc2d258aff311a0d5b9de8088b635f6c5e; the ``CA_ROTOR*``
   parameters in src/modules/control_allocator/module.yaml, commit 00f285ea, ``Thrust = CT u^2``: ``CT`` is
   the rotor's thrust at full output);
2. the mix is the pseudo-inverse of ``B``, its columns then divided by scales (roll, pitch and yaw only
   for effectiveness sources that ask for it, as the multirotor's does:
   VehicleActuatorEffectiveness/ActuatorEffectivenessMultirotor.hpp ``getNormalizeRPY``, commit 1d5efd10):
   roll and pitch both by the larger of ``sqrt(|col|^2 / (n_nonzero / 2))`` of the two columns (entries
   beyond 1e-3 counted), yaw by the column's largest entry, the thrust columns by the mean absolute entry
   of the rotors that have one
   (src/lib/control_allocation/control_allocation/ControlAllocationPseudoInverse.cpp,
   ``updateControlAllocationMatrixScale``, commit 1316f1cea7199b56b51fab6835f59e7cf52aaa11);
3. ``u = mix [roll, pitch, yaw, 0, 0, -t]`` (thrust along -z), inside the outputs' range unchanged.

So on a symmetric X a full roll or pitch torque moves each rotor by ``1/sqrt 2`` of its range and a full
yaw torque by all of it. The motors are numbered as the airframe's ``CA_ROTOR`` parameters: PX4's Generic
Quadcopter (docs.px4.io, "Adding a Frame Configuration": rotor 0 at (0.15, 0.15) m, 1 at (-0.15,
-0.15), 2 at (0.15, -0.15) with KM -0.05, 3 at (-0.15, 0.15) with KM -0.05; KM defaults to +0.05) and its
Iris SITL airframe (ROMFS/px4fmu_common/init.d-posix/airframes/10015_gazebo-classic_iris, commit 3eecef08).

The law (:func:`quadctl.sim.pid.law`) is evaluated on a state that makes its rate PIDs' outputs the chosen
torques (a unit P gain on the measured rates, every other gain zero) and its thrust the chosen one (the
reference's thrust at that share of the full); the rotor thrusts its command asks for, over each rotor's
largest, must be PX4's outputs rotor by rotor.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

OUTPUT_TOL = 1e-9
"""Absolute, in outputs (0 to 1): the law's CasADi arithmetic against NumPy's SVD pseudo-inverse of a 6 x 4
matrix whose nonzero rows have condition number below 100; both ~1e-14, 1e-9 leaves room for any LAPACK."""
GENERIC_QUAD = ((0.15, 0.15, 1.0), (-0.15, -0.15, 1.0), (0.15, -0.15, -1.0), (-0.15, 0.15, -1.0))
"""PX4's Generic Quadcopter: ``CA_ROTOR{i}_PX, _PY`` (m) and the sign of ``CA_ROTOR{i}_KM``, motor 1 first."""
IRIS_SITL = ((0.1515, 0.245, 1.0), (-0.1515, -0.1875, 1.0), (0.1515, -0.245, -1.0), (-0.1515, 0.1875, -1.0))
"""PX4's Iris SITL airframe, likewise: the wider front arms (a stretched, unequal X)."""
IRREGULAR = ((0.16, 0.12, 1.0), (-0.1, -0.2, 1.0), (0.12, -0.18, -1.0), (-0.18, 0.16, -1.0))
"""An irregular quadrilateral (m), whose pure yaw moves a clockwise rotor most: PX4 scales yaw by the column's
largest entry, signed (14.0 / N m here), not by its largest size (16.2), which the regular frames cannot tell
apart."""
PLUS = ((1.0, 0.0, 1.0), (0.0, 1.0, -1.0), (-1.0, 0.0, 1.0), (0.0, -1.0, -1.0))
"""quadctl's ``+`` layout (front, right, rear, left; front and rear counter-clockwise) as PX4 would be told it,
in that order, over the arm length: two rotors of four in each of the roll and pitch columns."""
CRAZYFLIE_ORDER = ((1.0, 1.0, 1.0), (-1.0, 1.0, -1.0), (-1.0, -1.0, 1.0), (1.0, -1.0, -1.0))
"""The Crazyflie's motors as PX4 would be told them (``CA_ROTOR`` in the vehicle's own order, M1 first): the
signs of x, y and KM of M1 front right (counter-clockwise) ... M4 front left (crazyflie-firmware,
power_distribution_quadrotor.c)."""
SETPOINTS = (
    (0.5, 0.0, 0.0, 0.0),
    (0.5, 0.3, 0.0, 0.0),
    (0.5, 0.0, -0.3, 0.0),
    (0.5, 0.0, 0.0, 0.25),
    (0.55, -0.15, 0.1, -0.15),
    (0.4, 0.1, 0.2, 0.1),
)
"""``(t, roll, pitch, yaw)``: normalized thrust and torques, each inside every geometry's outputs' range."""


def px4_effectiveness(rotors, ct, km) -> np.ndarray:
    """``B`` (6, n): moments and thrust per unit output of rotors at ``(x, y)`` (m) with thrust coefficients
    ``ct`` (N at full output) and signed moment ratios ``km`` (m), thrust axis up."""
    axis = np.array([0.0, 0.0, -1.0])
    B = np.zeros((6, len(rotors)))
    for i, (x, y) in enumerate(rotors):
        B[:3, i] = ct[i] * np.cross([x, y, 0.0], axis) - ct[i] * km[i] * axis
        B[3:, i] = ct[i] * axis
    return B


def px4_mix(B) -> np.ndarray:
    """PX4's normalized mix (n, 6) of the effectiveness ``B``: its pseudo-inverse, columns scaled."""
    P = np.linalg.pinv(B)
    rp = max(math.sqrt(P[:, k] @ P[:, k] / (np.count_nonzero(np.abs(P[:, k]) > 1e-3) / 2)) for k in (0, 1))
    thrust = np.abs(P[:, 5])
    scale = np.array([rp, rp, P[:, 2].max(), 1.0, 1.0, thrust.sum() / np.count_nonzero(thrust > 1e-7)])
    return P / scale


def cascade_setup(geometry: str):
    """The setup of PX4's Iris (``quadctl init``'s iris, numbering px4), of the same with PX4's Iris SITL rotor
    positions, with :data:`IRREGULAR`'s or as a ``+``, or the bundled crazyflie; with the rotors PX4 would be
    given for it (``CA_ROTOR`` x, y and the sign of KM)."""
    import yaml

    import quadctl as qc
    from quadctl.config import Config
    from quadctl.config import template as starter

    if geometry == "crazyflie":
        setup = qc.setup_of(qc.load_config("crazyflie"))
        d = setup.actuators.motors.arm_length / math.sqrt(2)
        return setup, [(sx * d, sy * d, sk) for sx, sy, sk in CRAZYFLIE_ORDER]
    data = yaml.safe_load(starter.config_text("iris-px4", "iris", "hover"))
    if geometry == "iris":
        d = data["motors"]["arm_length"] / math.sqrt(2)
        return qc.setup_of(Config(**data)), [(x / 0.15 * d, y / 0.15 * d, k) for x, y, k in GENERIC_QUAD]
    if geometry == "plus":
        data["motors"].update(layout="+", numbering="quadctl")
        arm = data["motors"]["arm_length"]
        return qc.setup_of(Config(**data)), [(x * arm, y * arm, k) for x, y, k in PLUS]
    rotors = IRIS_SITL if geometry == "iris-sitl" else IRREGULAR
    data["motors"].update(positions=[[x, y] for x, y, _ in rotors],
                          spin=["ccw" if k > 0 else "cw" for *_, k in rotors], numbering="quadctl")
    return qc.setup_of(Config(**data)), list(rotors)


def law_outputs(setup, thrust_newtons, torques) -> np.ndarray:
    """The rotor outputs (4,), thrust over each rotor's largest, that the PX4 cascade's law commands with its
    rate PIDs' outputs ``torques`` (normalized roll, pitch, yaw) and the reference thrust ``thrust_newtons``
    (N, the hover thrust its velocity loop holds with every outer gain zero)."""
    import casadi as ca

    from quadctl.config.pid import NAMES, resolve
    from quadctl.layout import STATE_INDEX
    from quadctl.sim import pid

    zero = {n: 0.0 for n in NAMES if n.endswith(("_kp", "_ki", "_kd"))}
    gains = resolve("px4").with_values(**{**zero, "gyro_lpf_hz": 0.0, "rate_dfilter_hz": 0.0,
                                          "rate_roll_kp": 1.0, "rate_pitch_kp": 1.0, "rate_yaw_kp": 1.0})
    act = setup.actuators
    x = np.zeros(12)
    x[STATE_INDEX["pD"]] = -1.0
    measured = x.copy()
    measured[STATE_INDEX["p"]:STATE_INDEX["p"] + 3] = -np.asarray(torques)  # rate error = the torque wanted
    state = np.zeros(pid.N_LAW_STATES)
    state[pid.state_slice("rate_previous")] = measured[STATE_INDEX["p"]:STATE_INDEX["p"] + 3]
    command, _ = pid.law(pid.structure_of(gains), ca.DM(state), ca.DM(measured), ca.DM(x),
                         ca.DM([thrust_newtons, 0.0, 0.0, 0.0]), ca.DM(gains.values), ca.DM(act.mix),
                         ca.DM(act.mix_inv), ca.DM(act.hi), ca.DM.zeros(4, 3), 1 / gains["rate_hz"], 9.81)
    return act.mix @ np.asarray(command, dtype=float).ravel() / act.hi


@pytest.mark.parametrize("geometry", ["iris", "iris-sitl", "irregular", "plus", "crazyflie"])
def test_the_px4_cascade_mixes_its_torques_and_thrust_as_px4s_control_allocation(geometry):
    setup, rotors = cascade_setup(geometry)
    motors = setup.actuators.motors
    hi = setup.actuators.hi
    B = px4_effectiveness([(x, y) for x, y, _ in rotors], ct=hi, km=[k * motors.torque_coefficient
                                                                    for *_, k in rotors])
    mix = px4_mix(B)
    full = -(B @ (mix @ [0.0, 0.0, 0.0, 0.0, 0.0, -1.0]))[5]  # N: the collective thrust of normalized thrust 1
    for t, roll, pitch, yaw in SETPOINTS:
        want = mix @ np.array([roll, pitch, yaw, 0.0, 0.0, -t])
        assert np.all((want > 0) & (want < 1)), want  # inside the outputs' range: no desaturation
        got = law_outputs(setup, t * full, (roll, pitch, yaw))
        diff = np.max(np.abs(got - want))
        assert diff <= OUTPUT_TOL, f"{geometry} {(t, roll, pitch, yaw)}: {got} vs PX4 {want}: max diff {diff:.4E}"


def test_the_px4_numbering_is_the_generic_quadcopters_ca_rotor_order():
    """quadctl's ``px4`` numbering puts rotor ``i`` where PX4's Generic Quadcopter puts ``CA_ROTOR{i-1}``, with
    its turning direction (the sign of ``KM``)."""
    from quadctl.physics.motors import NUMBERINGS, Motors

    motors = Motors(layout="x", arm_length=0.15 * math.sqrt(2), order=NUMBERINGS["px4"])
    np.testing.assert_allclose(motors.positions(), [(x, y) for x, y, _ in GENERIC_QUAD], rtol=1e-15, atol=1e-15)
    assert motors.rotor_spins() == tuple(k for *_, k in GENERIC_QUAD)


def test_px4s_symmetric_x_moves_each_rotor_by_a_root_half_for_a_full_roll_and_all_the_way_for_a_full_yaw():
    """The reference itself against numbers worked by hand: on the Generic Quadcopter the pseudo-inverse's roll
    column is ``-+1 / (4 CT 0.15)``, scaled by ``sqrt(4 / (4 CT 0.15)^2 / 2)``: ``-+1/sqrt 2``; the yaw column's
    ``+-1 / (4 CT KM)`` by its largest: ``+-1``; the thrust column's ``-1 / (4 CT)`` by its mean size: ``-1``."""
    B = px4_effectiveness([(x, y) for x, y, _ in GENERIC_QUAD], ct=[6.5] * 4, km=[0.05 * k for *_, k in GENERIC_QUAD])
    r = 1 / math.sqrt(2)
    want = np.array([[-r, r, 1.0, -1.0], [r, -r, 1.0, -1.0], [r, r, -1.0, -1.0], [-r, -r, -1.0, -1.0]])
    np.testing.assert_allclose(px4_mix(B)[:, [0, 1, 2, 5]], want, rtol=1e-12, atol=1e-12)
