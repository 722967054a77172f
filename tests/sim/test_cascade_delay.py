"""A PID cascade flown with a delay (``controller.flies: pid`` with ``controller.delay``) against closed forms.

A P rate loop on the roll inertia, ``J p' = A``, sampled at ``Ts`` with ``d`` samples from measurement to
actuation, ``A_k = -kp L p_(k-d)`` (``L`` PX4's roll torque per normalized unit, from the rotors' geometry and
thrust limit),
is ``p_(k+1) = p_k - a p_(k-d)``, ``a = kp L Ts / J``: characteristic polynomial ``z^(d+1) - z^d + a``. Every
other gain of the cascade zero (PX4's normalized torques: no PWM curve), nothing else moves ``p``, so the
nonlinear simulation follows the recurrence exactly (RK4 is exact on a constant rate) and the lifted loop
of the margins (:mod:`quadctl.sim.cascade_margins`) has its roots among its poles. The stock multi-rate
cascade with a delay is linearized at hover: one simulated frame from the lift's equilibrium returns to it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

RATE = 500.0   # Hz: the crazyflie config's controller rate, the cascade's base rate here
KP = 0.2       # normalized torque per rad/s: a = kp L Ts / J = 0.354 (stable for d <= 3: z^4 - z^3 + a needs a < 0.45)
P0 = 0.5       # rad/s: the initial roll rate (kp p0 = 0.1 of the torque range, the rotors far from their limits)
POLE_TOL = 1e-9
"""Relative: simple roots of a polynomial of degree <= 4 with coefficients of order one (their condition
numbers < 10) against the eigenvalues of the linearized law (~1e-15 each)."""
RECURRENCE_TOL = 1e-12
"""Relative to ``P0``: 50 samples of a stable recurrence in double precision, RK4 exact on ``p``."""


def crazyflie(delay_samples: int, **controller):
    import quadctl as qc

    cfg = qc.load_config("crazyflie")
    update = {"delay": delay_samples / RATE if delay_samples else None, **controller}
    return qc.Stages(qc.setup_of(cfg.model_copy(update={"controller": cfg.controller.model_copy(update=update)})))


def p_rate_gains(kp: float = KP):
    """PX4's cascade at one rate, every gain and filter zero but the roll rate loop's kp."""
    from quadctl.config.pid import NAMES, resolve

    px4 = resolve("px4")
    keep = {"rate_hz": RATE, "attitude_hz": RATE, "position_hz": RATE, "rate_roll_kp": kp}
    return px4.with_values(**{n: keep.get(n, 0.0) for n in NAMES if n in keep or not n.endswith(("limit", "_max",
                                                                                                    "_min"))})


def closed_form(d: int, kp: float = KP) -> tuple[float, np.ndarray]:
    """(a, roots of z^(d+1) - z^d + a) from the config's numbers alone: roll inertia, arm, rotor thrust limit."""
    import quadctl as qc

    cfg = qc.load_config("crazyflie")
    # X layout: each rotor 0.046 / sqrt(2) m off the roll axis; PX4's control allocation moves each by 1/sqrt 2 of
    # its thrust range per unit of normalized roll torque (tests/sim/test_px4_allocation.py)
    L = 4 * cfg.motors.arm_length / math.sqrt(2) * cfg.motors.max_thrust / math.sqrt(2)
    a = kp * L / RATE / cfg.vehicle.inertia[0]
    poly = np.zeros(d + 2)
    poly[:2] = 1.0, -1.0
    poly[-1] += a
    return a, np.roots(poly)


def recurrence(a: float, d: int, n: int) -> np.ndarray:
    """``p_0 .. p_n`` of ``p_(k+1) = p_k - a p_(k-d)``, ``p_0 = P0``, the buffer at the trim (no torque) before."""
    p = np.zeros(n + 1)
    p[0] = P0
    for k in range(n):
        p[k + 1] = p[k] - a * (p[k - d] if k >= d else 0.0)
    return p


@pytest.mark.parametrize("d", [0, 1, 2, 3])
def test_the_lifted_p_rate_loop_has_the_roots_of_z_to_the_d_plus_1_minus_z_to_the_d_plus_a(d):
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim.cascade_lift import lifted

    stages = crazyflie(d)
    loop = pid_loop_of(stages.setup, stages.linear, p_rate_gains())
    assert loop.delay_samples == d
    lift = lifted(loop)
    assert lift.frame == 1
    a, roots = closed_form(d)
    assert len(roots) == d + 1
    poles = np.linalg.eigvals(lift.frame_map)
    for r in roots:  # each root is a pole (the others: the plant's open-loop modes, the buffer's other inputs)
        diff = np.min(np.abs(poles - r))
        assert diff <= POLE_TOL * max(1.0, abs(r)), f"root {r} (a = {a:.6g}, d = {d}): nearest pole {diff:.4E} away"
    b0 = loop.spec().buffer_start  # the delay's buffer (four commands a sample) is in the lifted loop
    assert set(range(b0, b0 + 4 * d)) <= set(lift.states.tolist())


@pytest.mark.compiler
def test_the_delayed_p_rate_loop_flies_its_recurrence_in_the_lanes_and_the_interpreter():
    """Eight SIMD lanes of eight gains (the sweeps' compiled loop) and CasADi's virtual machine (the one-case
    fallback; the compiled one-case loop is held to the lanes in tests/sim/test_pid_cascade.py): each run's roll
    rate at the samples is its recurrence, to round-off."""
    from quadctl.layout import STATE_INDEX
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim.cases import Cases
    from quadctl.sim.engine import LANES, runner
    from quadctl.sim.interpreted import InterpretedRunner

    d, n, p = 2, 50, STATE_INDEX["p"]
    stages = crazyflie(d)
    x0 = stages.linear.x_trim.copy()
    x0[p] = P0
    kps = KP * (1 - 0.05 * np.arange(LANES))
    loops = [pid_loop_of(stages.setup, stages.linear, p_rate_gains(kp)) for kp in kps]
    plan = loops[0].plan(n / RATE)
    lo, hi = loops[0].bounds(n / RATE)
    cases = Cases.of(np.array([loop.initial_loop_state(x0) for loop in loops]),
                     np.array([loop.constants(plan.sample_time) for loop in loops]), plan.dt, plan.n_steps,
                     1, lo, hi, hold=plan.hold)
    spec = loops[0].spec()
    assert spec.delay == d
    first = Cases.of(cases.x0[:1], cases.c[0, :1], plan.dt, plan.n_steps, 1, lo, hi, hold=plan.hold)
    runs = [*runner(spec, LANES).run(cases), *InterpretedRunner(spec).run(first)]
    for kp, (done, _, xs, _) in zip([*kps, kps[0]], runs):
        assert done == plan.n_steps and len(xs) == n * plan.hold + 1  # every step recorded, the first the start
        want = recurrence(closed_form(d, kp)[0], d, n)
        miss = np.abs(xs[::plan.hold, p] - want).max()
        assert miss <= RECURRENCE_TOL * P0, (kp, miss)


def test_the_delayed_multirate_cascade_is_linearized_at_hover_and_lifted_to_the_simulated_frame():
    """The Crazyflie's cascade (rate loops softened to half, which one sample of delay leaves stable; the stock
    one it does not: 8 deg of phase margin at 556 rad/s is a quarter of a 2 ms sample): one frame of the law and
    RK4 plant from the lift's equilibrium returns to it (the command the law computes is the trim's, the buffer
    holds it), and the frame's Jacobian there is the lifted map, poles as sets."""
    import casadi as ca

    from quadctl.config.pid import resolve
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim.builder import build
    from quadctl.sim.cascade_lift import lifted

    stages = crazyflie(1)
    stock = resolve("crazyflie")
    soft = stock.with_values(**{k: stock[k] / 2 for k in ("rate_roll_kp", "rate_pitch_kp", "rate_roll_kd",
                                                          "rate_pitch_kd")})
    loop = pid_loop_of(stages.setup, stages.linear, soft)
    lift = lifted(loop)
    assert loop.delay_samples == 1 and lift.frame == 5
    spec = loop.spec()
    funcs = build(spec)
    c, e = loop.constants(lift.sample_time), np.zeros(spec.n_exo)

    def frame(X, substeps=8):
        for _ in range(lift.frame):
            u, X = funcs.law(X, 0.0, c, e)
            for _ in range(substeps):
                X = funcs.plant(X, u, lift.sample_time / substeps, c, e)
        return X

    X0 = lift.equilibrium
    moved = np.abs(np.asarray(frame(X0)).ravel() - X0)
    assert moved.max() <= 1e-9 * max(1.0, np.abs(X0).max()), f"the equilibrium moves {moved.max():.4E} in a frame"
    Xs = ca.MX.sym("X", spec.nx)
    keep = lift.states
    J_sim = np.asarray(ca.Function("frame", [Xs], [ca.jacobian(frame(Xs), Xs)])(X0))[np.ix_(keep, keep)]
    Phi = lift.frame_map
    gap = np.linalg.norm(J_sim - Phi, 2)
    assert gap < 1e-9 * np.linalg.norm(Phi, 2), gap
    got, right = np.linalg.eig(Phi)
    left = np.linalg.inv(right).conj().T
    kappa = np.linalg.norm(left, axis=0) * np.linalg.norm(right, axis=0) / np.abs(np.sum(left.conj() * right, axis=0))
    want = np.linalg.eigvals(J_sim)
    for g, k in zip(got, kappa):  # first-order perturbation: each pole within its condition number times the gap
        i = int(np.argmin(np.abs(want - g)))
        assert abs(want[i] - g) <= 2 * k * gap + 1e-12, f"pole {g} vs {want[i]}"
        want = np.delete(want, i)
    assert max(abs(got)) < 1
    stock_lift = lifted(pid_loop_of(stages.setup, stages.linear, stock))
    assert max(abs(np.linalg.eigvals(stock_lift.frame_map))) > 1  # the stock cascade: one sample too many


def test_the_margins_of_a_delayed_cascade_say_the_delay_is_in_them():
    from quadctl.payloads import cascade_margins as payload
    from quadctl.present.loops import cascade_sentence

    stages = crazyflie(2, flies="pid")  # the stock cascade, two samples late: unstable, its margins none
    data = payload(stages.setup, stages.pid_lift, stages.pid_margins)
    assert data["delay_samples"] == 2 and [m["delay_samples"] for m in data["loops"]] == [2] * 4
    assert not data["closed_loop"]["stable"]
    assert "with its 2 samples of delay (controller.delay) in every loop" in cascade_sentence(data)
