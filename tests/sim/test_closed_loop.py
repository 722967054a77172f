"""The linear closed loop (quadctl.design.linear_loop) against independent references.

- The nonlinear loop the simulation runs (quadctl.sim.builder) linearized by CasADi at the
  reference equals the linear loop, for every bundled config and for loops with the rotors' lag,
  the controller's lag model and a delay; through a Kalman filter, it has the eigenvalues of the loop
  the closed-loop verdict judges (quadctl.design.lqg_loop.lqg_vehicle), the rotors' lag, the delay and
  the gyro filter included.
- The free-position rule (quadctl.linear.stability.free_positions): a position no gain reads but another
  state depends on is not free, so its mode stays in the verdict.
- The sampled cost of a discrete design (quadctl.design.coupled.linear_cost) equals the cost a linear
  simulation accumulates, and the design's own DARE cost.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg
import yaml
from _solve import cfg_dict, solve

from quadctl import config, pipeline
from quadctl.config import loading
from quadctl.design import coupled, linear_loop, lqg_loop
from quadctl.layout import INPUT_NAMES, N_STATES, STATE_INDEX, STATE_NAMES
from quadctl.linear import stability
from quadctl.sim.builder import build

AGREE = 1e-9
"""Relative agreement of the builder's Jacobian and the linear loop: both differentiate the one
CasADi model exactly (and the hold is an exact matrix exponential on both sides), so they agree to
round-off; 1e-9 of the loop's norm leaves room for expm's conditioning."""


def _variant(name: str) -> dict:
    """Bundled configs, and loops with what the bundled ones lack: the rotors' lag, the design's lag
    model (``rotor_lag: include``), and a delay."""
    if name == "hover+lag model":
        data = cfg_dict("hover", motors={"time_constant": 0.02})
        data["controller"]["rotor_lag"] = "include"
        return data
    if name == "mambo+lag model+delay":
        data = cfg_dict("mambo-200hz")
        data["motors"]["time_constant"] = 0.02
        data["controller"]["rotor_lag"] = "include"
        data["controller"]["delay"] = {"samples": 2}
        return data
    if name.startswith("hover+LQG"):
        data = cfg_dict("hover")
        if name.endswith("200 Hz"):
            data["controller"] = {"rate": 200.0}
        data["simulation"]["noise"] = {"seed": 3, "force": [0.005] * 3, "torque": [2e-5] * 3,
                                       "sensor": dict.fromkeys(("pN", "pE", "pD", "phi", "theta", "psi", "p", "q", "r"),
                                                               0.01)}
        data["estimator"] = {"measure": ["imu", "mocap"]}
        return data
    if name == "mambo+rotor lag ignored":
        data = cfg_dict("mambo-200hz")
        data["motors"]["time_constant"] = 0.02
        return data
    return cfg_dict(name)


LOOPS = [*config.bundled_names(), "hover+lag model", "mambo+lag model+delay", "mambo+rotor lag ignored",
         "hover+LQG", "hover+LQG 200 Hz"]


def _jacobians(loop, setup):
    """(d X+/dX of the held sample, or d X'/dX of continuous feedback) of the builder's loop at the
    reference at ``t = 0``: the loop's own generated functions, differentiated by CasADi.

    Continuous feedback: ``step(X, h)`` is one RK4 step, ``X + h/6 (k1 + 2 k2 + 2 k3 + k4)``; the
    derivative in ``h`` at ``h = 0`` of its Jacobian is exactly the Jacobian of the closed-loop
    right-hand side (each ``k_i`` equals it at ``h = 0``).

    Held: the law at the sample gives ``u(X)`` and the controller states ``X_s(X)``; between samples
    RK4 integrates the plant under the held ``u``. The linear loop holds the plant exactly (ZOH), so
    the plant's right-hand side is taken the same way (``d/dh`` of the plant step's Jacobians at
    ``h = 0``: ``A_p``, ``B_p``) and held exactly over ``Ts``: ``X+ = Phi X_s + Gamma u``, with
    ``[Phi, Gamma] = expm([[A_p, B_p], [0, 0]] Ts)``. The comparison is then exact, not RK4's
    O(dt^4) approximation of the hold.
    """
    import casadi as ca

    spec = loop.spec(noise=False, wind=True)
    fns = build(spec)
    Ts = 1.0 / loop.rate if loop.rate else None
    c = loop.constants(Ts)
    e = ca.DM(np.asarray(setup.trim_wind, dtype=float))  # the wind the trim is in (still air: zero)
    X0 = loop.initial_loop_state(loop.x_trim)
    X, h = ca.SX.sym("X", spec.nx), ca.SX.sym("h")
    nx = spec.nx

    def rate_of(step_out, wrt):
        J = ca.jacobian(step_out, wrt)
        return ca.reshape(ca.jacobian(ca.vec(J), h), J.shape[0], J.shape[1])

    if not spec.held:
        X_next, _ = fns.step(X, 0.0, h, c, e)
        return np.asarray(ca.Function("J", [X, h], [rate_of(X_next, X)])(X0, 0.0)), None
    u = ca.SX.sym("u", len(INPUT_NAMES))
    X_next = fns.plant(X, u, h, c, e)
    Ap, Bp = (np.asarray(M) for M in ca.Function("AB", [X, u, h], [rate_of(X_next, X), rate_of(X_next, u)])(
        X0, loop.u_trim, 0.0))
    u_now, X_s = fns.law(X, 0.0, c, e)
    Ju, Js = (np.asarray(M) for M in ca.Function("L", [X], [ca.jacobian(u_now, X), ca.jacobian(X_s, X)])(X0))
    m = Bp.shape[1]
    held = scipy.linalg.expm(np.block([[Ap, Bp], [np.zeros((m, nx + m))]]) * Ts)
    Phi, Gamma = held[:nx, :nx], held[:nx, nx:]
    return Phi @ Js + Gamma @ Ju, Ts


@pytest.fixture(scope="module", params=LOOPS)
def builder_and_linear(request):
    """(builder's Jacobian, linear loop, sample time) of one loop, built once."""
    setup, _, linear, _, des = solve(_variant(request.param))
    loop = pipeline.loop_of(setup, linear, des)
    loop = replace(loop, params=setup.vehicle.vector())  # the design model (a config may fly another plant)
    J, Ts = _jacobians(loop, setup)
    timing = setup.timing
    if loop.estimator is not None:  # [x; x_hat; z] here, [x; z; x_hat] in the builder
        nz = len(des.integral_states)
        order = [*range(N_STATES), *range(2 * N_STATES, 2 * N_STATES + nz), *range(N_STATES, 2 * N_STATES)]
        A_lin = lqg_loop.lqg_matrix(des, linear.A, linear.B, loop.estimator)[np.ix_(order, order)]
        return request.param, J, A_lin, Ts
    A_lin = linear_loop.vehicle_matrix(des, linear.A, linear.B, Ts, timing.delay_samples,
                                       setup.rotor_time_constant, keep_free=True)
    act = setup.actuators
    if setup.rotor_time_constant is not None:  # the builder's rotor thrusts f = mix v (deviations from trim)
        T = np.eye(len(A_lin))
        T[N_STATES:N_STATES + 4, N_STATES:N_STATES + 4] = act.mix
        A_lin = T @ A_lin @ np.linalg.inv(T)
    return request.param, J, A_lin, Ts


def test_the_simulated_loop_linearized_is_the_linear_loop(builder_and_linear):
    """Same state order ``[x; f; z; l; b]``, same entries: the builder's Jacobian at the reference equals
    :func:`quadctl.design.linear_loop.vehicle_matrix` (every state kept) to round-off."""
    name, J, A_lin, Ts = builder_and_linear
    assert J.shape == A_lin.shape, name
    err = np.abs(J - A_lin).max() / max(1.0, np.abs(A_lin).max())
    assert err < AGREE, f"{name}: max diff {err:.3e}"


# ---------------------------------------------------------------------------------------------
# The free-position rule


def _loop_reading_pN():
    """A 12-state loop in which no gain reads ``pN`` but ``u`` depends on it: ``u' = pN - u``,
    ``pN' = u`` (a saddle: eigenvalues ``(-1 +- sqrt 5) / 2``); ``pE`` and ``pD`` are free (zero
    columns), every other state decays at -1."""
    A = -np.eye(N_STATES)
    pN, u = STATE_INDEX["pN"], STATE_INDEX["u"]
    for s in ("pN", "pE", "pD"):
        A[STATE_INDEX[s], STATE_INDEX[s]] = 0.0
    A[pN, u] = 1.0
    A[u, pN] = 1.0
    return A, np.zeros((4, N_STATES))


def test_a_position_another_state_reads_is_not_free():
    """Independent reference: a free position's column of the loop is zero, so the unit vector ``e_s``
    is an eigenvector at ``s = 0``. Here ``A e_pN != 0``: pN is not free, and the loop (a saddle) is
    unstable, which the verdict must say."""
    A, K = _loop_reading_pN()
    e = np.zeros(N_STATES)
    e[STATE_INDEX["pN"]] = 1.0
    assert np.any(A @ e != 0)                                  # the reference: something depends on pN
    assert np.any(np.linalg.eigvals(A).real > 0.5)             # (-1 + sqrt 5) / 2 = 0.618
    assert stability.free_positions(A, reads=(K,)) == ("pE", "pD")
    verdict = stability.assess(A, K)
    assert verdict.marginal == ("pE", "pD") and not verdict.stable
    # the same through the stacked verdict the sweep uses, and as a discrete loop (I + A Ts)
    assert stability.verdict_stack(A[None], K[None])[0][2] is False
    Ad = np.eye(N_STATES) + 0.01 * A
    assert stability.free_positions(Ad, reads=(K,), discrete=True) == ("pE", "pD")
    assert not stability.assess(Ad, K, sample_time=0.01).stable


def test_positions_read_by_a_gain_a_weight_or_an_integrator_are_not_free():
    A = np.zeros((N_STATES, N_STATES))
    K = np.zeros((4, N_STATES))
    K[0, STATE_INDEX["pD"]] = 1.0
    Q = np.zeros((N_STATES, N_STATES))
    Q[STATE_INDEX["pE"], STATE_INDEX["pE"]] = 1.0
    assert stability.free_positions(A) == ("pN", "pE", "pD")
    assert stability.free_positions(A, reads=(K,)) == ("pN", "pE")
    assert stability.free_positions(A, reads=(K, Q)) == ("pN",)
    assert stability.free_positions(A, reads=(K, Q), integral_states=("pN",)) == ()


def test_the_vehicle_loop_keeps_a_position_the_plant_reads():
    """margins' and check's loop (linear_loop.vehicle) leaves out only the free positions: with a plant
    in which ``u`` depends on ``pN``, ``pN`` stays in the loop."""
    setup, _, linear, _, des = solve(cfg_dict("hover"))
    Aa, _, _ = linear_loop.vehicle(des, linear.A, linear.B)
    A = linear.A.copy()
    A[STATE_INDEX["u"], STATE_INDEX["pN"]] = 0.1
    Ab, _, _ = linear_loop.vehicle(des, A, linear.B)
    assert len(Ab) == len(Aa) + 1


# ---------------------------------------------------------------------------------------------
# The sampled cost of a discrete design


def _sampled_cost(step, Q, R, N, K, x0, max_steps: int = 40000) -> float:
    """``sum_k x_k' Q x_k + u_k' R u_k + 2 x_k' N u_k`` along ``u_k = -K x_k``, ``x_(k+1) = step(x_k, u_k)``,
    summed until the state has decayed to 1e-15 of its start (the rest adds less than 1e-30 of it)."""
    x, J = np.asarray(x0, dtype=float), 0.0
    stop = 1e-15 * np.abs(x).max()
    if stop == 0:
        return 0.0
    for _ in range(max_steps):
        u = -K @ x
        J += x @ Q @ x + u @ R @ u + 2 * x @ N @ u
        x = step(x, u)
        if np.abs(x).max() < stop:
            return J
    raise AssertionError(f"the loop has not decayed in {max_steps} samples")


def test_a_discrete_designs_sampled_cost_is_what_a_linear_simulation_accumulates():
    """The cost of a sampled loop is ``sum_k x_k' Qd x_k + u_k' Rd u_k + 2 x_k' Nd u_k`` with lqrd's
    weights (the continuous cost integrated over each sample under the hold). Simulated sample by
    sample, it equals ``x0' P x0`` of the design's own DARE, and :func:`quadctl.design.coupled.linear_cost`.
    mambo-200hz: a discrete design with an integrator (pD); the offset moves every regulated state."""
    from quadctl.design import discrete, integral

    setup, _, linear, _, des = solve(cfg_dict("mambo-200hz"))
    Ts = des.sample_time
    Q_all, R, _ = coupled.assembled_weights(des)
    ints = des.integral_states
    free = [STATE_INDEX[s] for s in stability.free_positions(linear.A, reads=(Q_all, des.K_block),
                                                                 integral_states=ints)]
    keep = [i for i in range(N_STATES) if i not in free]
    Ad, Bd, Qd, Rd, Nd = discrete.lqrd_weights(linear.A[np.ix_(keep, keep)], linear.B[keep],
                                               Q_all[np.ix_(keep, keep)], R, Ts, name="test")
    nz = len(ints)
    qidx = keep + list(range(N_STATES, N_STATES + nz))
    Qa, Na = integral.discrete_weights(Qd, Nd, Q_all[np.ix_(qidx, qidx)], Ts)
    Ka = np.hstack([des.K_block[:, keep], des.Ki_block.reshape(4, nz)])
    C = integral.selector([STATE_NAMES[i] for i in keep], ints)
    dx0 = setup.initial_offset
    n = len(keep)
    J = _sampled_cost(lambda x, u: np.concatenate([Ad @ x[:n] + Bd @ u, x[n:] - Ts * C @ x[:n]]),
                      Qa, Rd, Na, Ka, np.concatenate([dx0[keep], np.zeros(nz)]))
    got = coupled.linear_cost(linear.A, linear.B, des.K_block, des.Ki_block, des, dx0)
    assert got == pytest.approx(J, rel=1e-9)
    # the same loop and weights as the design's own Riccati equation (per subsystem, the same blocks)
    P = np.zeros((N_STATES + nz,) * 2)
    z_at = {s: N_STATES + i for i, s in enumerate(ints)}
    for sub in des.subsystems:
        idx = [STATE_INDEX[s] for s in sub.states] + [z_at[s] for s in sub.integral]
        P[np.ix_(idx, idx)] = sub.P
    x0 = np.concatenate([dx0, np.zeros(nz)])
    decoupled_cost = float(x0 @ P @ x0)  # each subsystem's x0' P x0: its own DARE's cost
    sub_J = 0.0
    for sub in des.subsystems:  # simulated on each subsystem's own model
        dsub = solve(cfg_dict("mambo-200hz"))[3][sub.name]
        Ads, Bds, Qds, Rds, Nds = discrete.lqrd_weights(dsub.A, dsub.B, sub.Q[:len(sub.states), :len(sub.states)],
                                                        sub.R, Ts, name=sub.name)
        Qas, Nas = integral.discrete_weights(Qds, Nds, sub.Q, Ts)
        Aas, Bas = integral.augment_discrete(Ads, Bds, integral.selector(sub.states, sub.integral), Ts)
        Kas = np.hstack([sub.K, sub.Ki]) if sub.Ki is not None else sub.K
        xs = np.concatenate([dx0[[STATE_INDEX[s] for s in sub.states]], np.zeros(len(sub.integral))])
        sub_J += _sampled_cost(lambda x, u, Aas=Aas, Bas=Bas: Aas @ x + Bas @ u, Qas, Rds, Nas, Kas, xs)
    assert decoupled_cost == pytest.approx(sub_J, rel=1e-9)


# ---------------------------------------------------------------------------------------------
# A gain schedule at a frozen reference

@pytest.mark.parametrize("name, grid, speed", [("hover", [0.0, 4.0, 8.0], 3.0),
                                               ("crazyflie-speed-schedule", [0.0, 10.0, 20.0], 6.0)])
def test_a_scheduled_loop_at_a_frozen_reference_is_the_linear_loop_of_its_gain(name, grid, speed):
    """A speed schedule (designs at the ``grid`` speeds, linear between) flown at the trim of ``speed`` m/s,
    between two of its points: the reference's speed is constant, so the builder's loop linearized
    there is the linear loop of the interpolated gain ``G(speed)``, not of the design at that trim
    (hover: continuous feedback; the Crazyflie: 500 Hz, rotor limits)."""
    from _solve import designed_table

    table = designed_table(name, grid)
    data = cfg_dict(name)
    data["trim"]["velocity_ned"] = [speed, 0.0, 0.0]
    setup, _, linear, _, des = solve(data)
    loop = replace(pipeline.loop_of(setup, linear, des), schedule=table, params=setup.vehicle.vector())
    J, Ts = _jacobians(loop, setup)
    G = table.at(speed)
    A_lin = linear_loop.matrix(linear.A, linear.B, G, sample_time=Ts)
    assert np.abs(G - des.K_block).max() > 1e-3 * np.abs(G).max()  # the schedule's gain, not the trim's design
    err = np.abs(J - A_lin).max() / max(1.0, np.abs(A_lin).max())
    assert err < AGREE, f"{name}: max diff {err:.3e}"


# ---------------------------------------------------------------------------------------------
# The loop through a Kalman filter that the verdict judges (lqg_loop.lqg_vehicle)


def _lqg_variant(name: str) -> dict:
    """mambo-lqg (a discrete filter) with the rotors' lag, the lag model, a delay and the gyro filter, or
    hover through a continuous filter on rotors that lag."""
    if name.startswith("hover"):
        data = _variant("hover+lag model")
        lqg = _variant("hover+LQG")
        data["simulation"]["noise"], data["estimator"] = lqg["simulation"]["noise"], lqg["estimator"]
        data["simulation"]["method"] = "rk4"
        return data
    data = yaml.safe_load(loading.locate("docs/configs/mambo-lqg.yaml").text)
    data["motors"]["time_constant"] = 0.02
    if name.endswith("lag model+delay+gyro"):
        data["controller"].update(rotor_lag="include", delay={"samples": 2},
                                  filters={"gyro": {"cutoff": 30.0, "order": 2}})
    else:
        data["controller"]["delay"] = {"samples": 1}
    return data


@pytest.mark.parametrize("name", ["mambo-lqg+lag model+delay+gyro", "mambo-lqg+rotor lag ignored+delay",
                                  "hover+LQG continuous+lag model"])
def test_the_simulated_lqg_loop_has_the_verdicts_eigenvalues(name):
    """The builder's loop through the Kalman filter, linearized at the reference, has as a set the eigenvalues
    of :func:`quadctl.design.lqg_loop.lqg_vehicle` (every state kept): the verdict judges the loop that
    flies, with the rotors' lag the filter does not model, the controller's lag model, the delay (the filter
    predicting under the input the plant gets) and the gyro filter. Eigenvalues of two similar matrices:
    each within its conditioning (Wilkinson) of the linear loop."""
    from scipy.linalg import eig

    setup, _, linear, _, des = solve(_lqg_variant(name))
    loop = pipeline.loop_of(setup, linear, des)
    loop = replace(loop, params=setup.vehicle.vector())
    J, Ts = _jacobians(loop, setup)
    M = lqg_loop.lqg_vehicle(des, linear.A, linear.B, loop.estimator, setup.timing.delay_samples,
                             setup.rotor_time_constant, keep_free=True)
    assert J.shape == M.shape, name
    lam, left, right = eig(M, left=True, right=True)
    s = np.abs(np.einsum("ij,ij->j", left.conj(), right)) / (np.linalg.norm(left, axis=0)
                                                              * np.linalg.norm(right, axis=0))
    tol = AGREE * max(1.0, np.abs(M).max()) / np.maximum(s, 1e-300)
    got = list(np.linalg.eigvals(J))
    worst = 0.0
    for w, t in sorted(zip(lam, tol), key=lambda p: -abs(p[0])):
        k = int(np.argmin([abs(g - w) for g in got]))
        err = abs(got.pop(k) - w)
        assert err <= t, f"{name}: eigenvalue {w:.6g}: nearest {err:.3e} away, tolerance {t:.3e}"
        worst = max(worst, err)
    print(f"{name}: {len(lam)} eigenvalues, worst {worst:.2e}")
