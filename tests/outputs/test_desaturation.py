"""Saturation by priority (``motors.saturation: prioritize``): roll and pitch torques kept while some
thrust fits them, then the collective thrust, the yaw torque given up first; the same rule in the
simulated loop (CasADi), on arrays, in the anti-windup's flag and in the exported C."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from _solve import cfg_dict
from test_export import DOUBLE_TOL, FLOAT_INPUT_RTOL, Controller

from quadctl import config, export
from quadctl.layout import N_STATES, STATE_INDEX
from quadctl.physics import motors
from quadctl.setup import setup_of
from quadctl.sim.builder import build

MAMBO = motors.Motors()
AGILICIOUS = motors.Motors(xy=((0.075, 0.10), (-0.075, 0.10), (-0.075, -0.10), (0.075, -0.10)),
                           spins=(1.0, -1.0, 1.0, -1.0), torque_coefficient=0.0136, max_thrust=8.5)
ROTORS = {"mambo": MAMBO, "stretched": AGILICIOUS}
FLOAT_MIX_ULPS = 16
"""Float build: the rule's bounds are the rotors' limits carried through the mixer (a sum of 4 products) and
back (another 4): 8 roundings of each term, twice that for the thrust's and the yaw's two stages."""
FIT_TOL = 1e-12
"""Relative to the rotor limit: how far round-off may put a desaturated rotor outside its limits."""


def _casadi_rule():
    """The rule as the simulated loop builds it (CasADi expressions), as a function of its data."""
    cmd, mix, lo, hi = ca.SX.sym("cmd", 4), ca.SX.sym("mix", 4, 4), ca.SX.sym("lo", 4), ca.SX.sym("hi", 4)
    return ca.Function("desaturate", [cmd, mix, lo, hi], [motors.desaturate(cmd, mix, lo, hi, lib=ca)])


RULE = _casadi_rule()


def _both(m: motors.Motors, cmd):
    """(loop's CasADi rule, rule on arrays) of ``cmd``; they must agree bit for bit."""
    act = motors.actuators_of(m)
    symbolic = np.asarray(RULE(cmd, act.mix, act.lo, act.hi)).ravel()
    arrays = motors.desaturate(np.asarray(cmd, dtype=float), act.mix, act.lo, act.hi)
    np.testing.assert_array_equal(symbolic, arrays)
    return act, arrays


def _hover(m: motors.Motors) -> float:
    return 4 * 0.6 * m.max_thrust  # every rotor at 60 % of its limit


def _fits(act, u) -> bool:
    f = act.mix @ u
    tol = FIT_TOL * act.hi.max()
    return bool(np.all(f >= act.lo - tol) and np.all(f <= act.hi + tol))


def _at_limit(act, u) -> bool:
    f = act.mix @ u
    tol = FIT_TOL * act.hi.max()
    return bool(np.any(np.abs(f - act.lo) <= tol) or np.any(np.abs(f - act.hi) <= tol))


@pytest.mark.parametrize("name", ROTORS)
def test_a_command_the_rotors_can_produce_is_left_bit_for_bit(name):
    m = ROTORS[name]
    rng = np.random.default_rng(1)
    act = motors.actuators_of(m)
    for f in rng.uniform(act.lo, act.hi, size=(200, 4)):
        cmd = act.mix_inv @ f
        _, u = _both(m, cmd)
        np.testing.assert_array_equal(u, cmd)


@pytest.mark.parametrize("name", ROTORS)
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_yaw_is_given_up_first(name, sign):
    """Thrust, roll and pitch the rotors can give, a yaw torque they cannot: only the yaw moves, to
    the largest the rotors give (a rotor at a limit), keeping its sign."""
    m = ROTORS[name]
    act = motors.actuators_of(m)
    T = _hover(m)
    A, E = 0.1 * T * 0.05, -0.05 * T * 0.05
    R = sign * 10.0 * m.torque_coefficient * T
    _, u = _both(m, [T, A, E, R])
    assert (u[0], u[1], u[2]) == (T, A, E)
    assert 0 < sign * u[3] < abs(R)
    assert _fits(act, u) and _at_limit(act, u)


@pytest.mark.parametrize("name", ROTORS)
@pytest.mark.parametrize("up", [True, False])
def test_thrust_gives_way_before_roll_and_pitch(name, up):
    """Roll and pitch that fit only at another thrust: they are kept exactly, the thrust moves the least
    that fits them (a rotor at a limit), and a zero yaw command stays zero."""
    m = ROTORS[name]
    act = motors.actuators_of(m)
    T = 3.9 * m.max_thrust if up else 0.1 * m.max_thrust
    arm = np.abs(m.positions()).min()
    A, E = 0.3 * m.max_thrust * arm, 0.2 * m.max_thrust * arm
    _, u = _both(m, [T, A, E, 0.0])
    assert (u[1], u[2], u[3]) == (A, E, 0.0)
    assert (u[0] < T) if up else (u[0] > T)
    assert _fits(act, u) and _at_limit(act, u)


@pytest.mark.parametrize("name", ROTORS)
def test_roll_and_pitch_beyond_the_rotors_are_scaled_together(name):
    """A torque no thrust fits: roll and pitch scaled by one factor (the direction kept) to the largest
    that fits, the rotors then spanning their whole range, and yaw given up to zero."""
    m = ROTORS[name]
    act = motors.actuators_of(m)
    arm = np.abs(m.positions()).max()
    A, E, R = 3.0 * m.max_thrust * arm, -2.0 * m.max_thrust * arm, 0.5 * m.torque_coefficient * m.max_thrust
    _, u = _both(m, [_hover(m), A, E, R])
    s = u[1] / A
    assert 0 < s < 1 and u[2] / E == pytest.approx(s, rel=1e-14)
    f = act.mix @ u
    assert f.max() - f.min() == pytest.approx(act.hi[0] - act.lo[0], rel=1e-12)
    assert _fits(act, u)
    assert abs(u[3]) <= 1e-12 * m.torque_coefficient * m.max_thrust


def test_clipping_makes_a_yaw_torque_from_no_yaw_command_and_priority_does_not():
    """Pitch up and roll left with the rear rotors pushed below their minimum: clipping each rotor and
    mixing back gives a yaw torque no one asked for (5.5e-5 N m, a third of the Mambo's yaw authority
    about the trim) and less roll and pitch; priority raises the thrust instead and keeps A, E and R = 0."""
    m = MAMBO
    act = motors.actuators_of(m)
    cmd = np.array([0.2, -0.002, 0.012, 0.0])  # 0.05 N per rotor: the rear rotors asked for -0.007, -0.029 N
    assert (act.mix @ cmd)[1:3].max() < 0
    clipped = act.mix_inv @ np.clip(act.mix @ cmd, act.lo, act.hi)
    assert clipped[3] > 5e-5 and clipped[1] > cmd[1] and clipped[2] < cmd[2]
    _, u = _both(m, cmd)
    assert (u[1], u[2], u[3]) == (cmd[1], cmd[2], 0.0) and u[0] > cmd[0]
    assert _fits(act, u) and _at_limit(act, u)


# --- in the loop: the law, the anti-windup flag, the exported C -----------------------------------------------

def _prepared(rule: str):
    data = cfg_dict("mambo-200hz")
    data["motors"]["saturation"] = rule
    cfg = config.from_dict(data, f"mambo-{rule}.yaml")
    return export.prepare(setup_of(cfg), None, config_hash=cfg.digest())


STATES = {  # deviations from the trim that drive the command beyond the rotors
    "yaw only": {"psi": 2.8},
    "yaw and thrust": {"psi": -2.8, "pD": 3.0},
    "roll beyond": {"phi": 0.9, "psi": 1.0},
    "roll and pitch beyond": {"phi": -0.8, "theta": 0.7, "pD": -2.0},
}


def _state(loop, offsets) -> np.ndarray:
    x = np.array(loop.x_trim, dtype=float)
    for name, value in offsets.items():
        x[STATE_INDEX[name]] += value
    return x


def _law(loop, x, z=0.0):
    """(command before saturation, applied input, the integrator after one sample) of the simulated law."""
    Ts = 1.0 / loop.rate
    spec = loop.spec()
    X = loop.initial_loop_state(x)
    X[N_STATES:N_STATES + len(loop.integral_states)] = z
    u, X1 = build(spec).law(X, 0.0, loop.constants(Ts), ca.DM.zeros(0, 1))
    err = x - loop.x_trim
    cmd = loop.u_trim - loop.K @ err - (loop.Ki @ np.full(len(loop.integral_states), z) if loop.integral_states
                                         else 0.0)
    return cmd, np.asarray(u).ravel(), np.asarray(X1).ravel()[N_STATES:N_STATES + len(loop.integral_states)]


@pytest.mark.parametrize("case", STATES)
def test_the_simulated_law_applies_the_rule(case):
    exp = _prepared("prioritize")
    loop = exp.loop
    cmd, u, _ = _law(loop, _state(loop, STATES[case]))
    act = loop.actuators
    assert not _fits(act, cmd), "the hand-made state must saturate the rotors"
    np.testing.assert_array_equal(u, motors.desaturate(cmd, act.mix, act.lo, act.hi))


def test_the_integrator_freezes_on_the_rule_not_on_the_rotors():
    """Yaw alone given up: the thrust is the command's, so the altitude integrator keeps integrating;
    clipping the same command moves the thrust too and freezes it."""
    x = None
    frozen = {}
    for rule in ("prioritize", "clip"):
        loop = _prepared(rule).loop
        x = _state(loop, {"psi": 2.8, "pD": 0.2})
        cmd, u, z1 = _law(loop, x, z=0.01)
        frozen[rule] = bool(np.all(z1 == 0.01))
        if rule == "prioritize":
            assert u[0] == cmd[0] and u[3] != cmd[3]
    assert frozen == {"prioritize": False, "clip": True}


@pytest.mark.compiler
@pytest.mark.parametrize("single", [False, True], ids=["double", "float"])
@pytest.mark.parametrize("rule", ["prioritize", "clip"])
def test_the_exported_c_desaturates_as_the_simulation(rule, single, tmp_path):
    exp = _prepared(rule)
    loop = exp.loop
    act = loop.actuators
    for case, offsets in STATES.items():
        x = _state(loop, offsets)
        _, u, _ = _law(loop, x)
        got = Controller(exp, tmp_path / case.replace(" ", "-"), single).step(x)
        scale = np.abs(loop.u_trim) + np.abs(loop.K) @ (np.abs(x) + np.abs(loop.x_trim))
        if single:  # and a few ulps of what the rotors give on each input: the rule's bounds come through the mixer
            rotors = FLOAT_MIX_ULPS * np.finfo(np.float32).eps * (np.abs(act.mix_inv) @ act.hi)
            assert np.all(np.abs(got - u) <= FLOAT_INPUT_RTOL * scale + rotors), (case, got, u)
        else:
            assert np.abs(got - u).max() <= DOUBLE_TOL, (case, got, u)
