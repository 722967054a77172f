"""LQG with the gyro filter (estimator: with controller.filters): the Kalman filter's model is the plant
followed by the filter on p, q, r, measuring the filtered rates. Its model against python-control's ZOH
plant in series with SciPy's filter designs, its gain against the DARE and CARE, the closed loop against
the separation principle, the simulated law against the linear loop, and the bundled LQG config flown
and its margins taken with a 30 Hz second-order gyro filter."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from _solve import without_compiler

from quadctl.config import loading
from quadctl.config.loading import from_dict
from quadctl.layout import N_STATES, STATE_INDEX
from quadctl.linear.filters import RATE_STATES
from quadctl.setup import setup_of

LQG_CONFIG = "docs/configs/mambo-lqg.yaml"
GYRO = {"gyro": {"cutoff": 30.0, "order": 2}}
GYRO_NOTCH = {"gyro": {"cutoff": 30.0, "order": 2}, "notch": {"center": 70.0, "bandwidth": 30.0}}
EPS = np.finfo(float).eps


def lqg_config(filters, duration: float = 0.5, **controller) -> dict:
    data = yaml.safe_load(loading.locate(LQG_CONFIG).text)
    data["controller"] = {**data["controller"], "filters": filters, **controller}
    data["simulation"]["duration"] = duration
    return data


@pytest.fixture(scope="module")
def filtered_lqg():
    """mambo-lqg (200 Hz, LQI on altitude, a Kalman filter on imu + mocap) with a 30 Hz Butterworth and a
    70 Hz notch on the gyro."""
    from quadctl.pipeline import Stages

    return Stages(setup_of(from_dict(lqg_config(GYRO_NOTCH))))


def as_sets_close(got, want, tol):
    """Every eigenvalue of ``want`` matched to its own eigenvalue of ``got`` within ``tol`` (each's)."""
    got, want, tol = list(got), np.asarray(want), np.broadcast_to(tol, np.shape(want))
    assert len(got) == len(want)
    worst = 0.0
    for w, t in sorted(zip(want, tol), key=lambda p: -abs(p[0])):
        k = int(np.argmin([abs(g - w) for g in got]))
        err = abs(got.pop(k) - w)
        assert err <= t, f"eigenvalue {w:.6g}: nearest {err:.3e} away, tolerance {t:.3e}"
        worst = max(worst, err)
    return worst


def eigen_tolerance(M, factor: float = 1e3):
    """Per eigenvalue of ``M``: ``factor eps ||M|| / s_i``, ``s_i = |y_i' x_i|`` of its unit left and right
    eigenvectors (Wilkinson's condition number: a backward error of ``eps ||M||`` moves it by that much)."""
    from scipy.linalg import eig

    lam, left, right = eig(M, left=True, right=True)
    s = np.abs(np.einsum("ij,ij->j", left.conj(), right)) / (np.linalg.norm(left, axis=0)
                                                              * np.linalg.norm(right, axis=0))
    return lam, factor * EPS * np.linalg.norm(M, 2) / np.maximum(s, 1e-300)


# ---------------------------------------------------------------------------------------
# The Kalman filter's model and gain


def test_the_filters_model_is_the_zoh_plant_in_series_with_scipys_filters(filtered_lqg):
    """kal.A, kal.B, kal.C from the commanded input to each measurement, frequency by frequency: python-control's
    ZOH plant, its rate rows through SciPy's Butterworth and iirnotch at 200 Hz; the other rows as they are."""
    import control as ct
    from scipy import signal

    st = filtered_lqg
    kal, lin = st.loop.estimator, st.linear
    Ts, fs = kal.sample_time, 1 / kal.sample_time
    assert kal.A.shape == (N_STATES + 12, N_STATES + 12) and kal.C.shape == (len(kal.measured), N_STATES + 12)
    plant = ct.c2d(ct.ss(lin.A, lin.B, np.eye(12), np.zeros((12, 4))), Ts, method="zoh")
    w = np.linspace(0.3, 0.97 * np.pi * fs, 200)
    P = np.moveaxis(plant.frequency_response(w).complex, -1, 0)  # (N, 12, 4)
    (b1, a1), (b2, a2) = signal.butter(2, 30.0, fs=fs), signal.iirnotch(70.0, 70.0 / 30.0, fs=fs)
    F = signal.freqz(b1, a1, worN=w, fs=2 * np.pi * fs)[1] * signal.freqz(b2, a2, worN=w, fs=2 * np.pi * fs)[1]
    z = np.exp(1j * w * Ts)
    got = np.stack([kal.C @ np.linalg.solve(zk * np.eye(len(kal.A)) - kal.A, kal.B) for zk in z])
    for row, name in enumerate(kal.measured):
        want = P[:, STATE_INDEX[name], :] * (F[:, None] if name in RATE_STATES else 1.0)
        np.testing.assert_allclose(got[:, row, :], want, rtol=1e-8, atol=1e-10 * np.abs(want).max(), err_msg=name)


def test_the_discrete_gain_solves_the_dare_of_the_filtered_model(filtered_lqg):
    """P = A P A' - A P C' (C P C' + Rn)^-1 C P A' + G Qn G' on the augmented model, M = P C' (C P C' + Rn)^-1;
    the estimator's eigenvalues are those of A - A M C, all inside the unit circle."""
    kal = filtered_lqg.loop.estimator
    A, C, G, P, M = kal.A, kal.C, kal.G, kal.P, kal.gain
    S = C @ P @ C.T + kal.Rn
    rhs = A @ P @ A.T - A @ P @ C.T @ np.linalg.solve(S, C @ P @ A.T) + G @ kal.Qn @ G.T
    assert np.abs(P - rhs).max() <= 1e-10 * np.abs(P).max(), np.abs(P - rhs).max() / np.abs(P).max()
    np.testing.assert_allclose(M, np.linalg.solve(S, C @ P).T, rtol=1e-10, atol=1e-14 * np.abs(M).max())
    assert np.abs(np.linalg.eigvals(A - A @ M @ C)).max() < 1


def test_the_gyros_noise_taken_before_the_filter_leaves_no_stabilizing_kalman_filter(filtered_lqg):
    """Why the model takes the gyro's noise at the filter's output: taken before it (as the simulation adds
    it), the noise drives the filter's states through b_f and the measurement through d_f (correlated, the
    cross covariance S), and the Butterworth's zeros at z = -1 leave the rates' spectrum zero on the unit
    circle (the notch's zeros too): SciPy's DARE with S refuses it, or returns a solution whose estimator is
    not stable (no stabilizing solution exists); the model's own problem is regular."""
    from scipy import linalg

    kal = filtered_lqg.loop.estimator
    form = filtered_lqg.setup.rate_filter.form(kal.sample_time)
    measured, ne, m = list(kal.measured), kal.n_estimate, form.order
    sigma2 = np.diag(kal.Rn)
    W, V = np.zeros((ne, 3)), np.zeros((len(measured), 3))  # the three gyro noises into g and into y
    for k, rate in enumerate(RATE_STATES):
        row = measured.index(rate)
        W[N_STATES + k * m:N_STATES + (k + 1) * m, k], V[row, k] = form.b, form.d
    gyro = np.diag([sigma2[measured.index(r)] for r in RATE_STATES])
    other = np.diag([0.0 if s in RATE_STATES else v for s, v in zip(measured, sigma2)])
    Q, R, S = kal.G @ kal.Qn @ kal.G.T + W @ gyro @ W.T, other + V @ gyro @ V.T, W @ gyro @ V.T
    try:
        P = linalg.solve_discrete_are(kal.A.T, kal.C.T, Q, R, s=S)
    except (ValueError, np.linalg.LinAlgError) as exc:
        assert "unit circle" in str(exc)
    else:
        L = (kal.A @ P @ kal.C.T + S) @ np.linalg.inv(kal.C @ P @ kal.C.T + R)
        assert np.abs(np.linalg.eigvals(kal.A - L @ kal.C)).max() >= 1.0
    P = linalg.solve_discrete_are(kal.A.T, kal.C.T, kal.G @ kal.Qn @ kal.G.T, kal.Rn)  # the model's: regular
    np.testing.assert_allclose(P, kal.P, rtol=1e-8, atol=1e-10 * np.abs(P).max())


def test_the_kalman_bucy_gain_solves_the_care_of_the_filtered_model():
    """A continuous LQG loop with the gyro filter: A P + P A' - P C' V^-1 C P + G W G' = 0, L = P C' V^-1, and
    the measured rates read the continuous filter's output (a low-pass has no direct term: c g alone)."""
    from quadctl.pipeline import Stages

    loop = Stages(setup_of(from_dict(lqg_config(GYRO, rate=None)))).loop
    kal = loop.estimator
    A, C, G, P, L = kal.A, kal.C, kal.G, kal.P, kal.gain
    res = A @ P + P @ A.T - P @ C.T @ np.linalg.solve(kal.Rn, C @ P) + G @ kal.Qn @ G.T
    scale = np.abs(A @ P).max() + np.abs(G @ kal.Qn @ G.T).max()
    assert np.abs(res).max() <= 1e-10 * scale, np.abs(res).max() / scale
    np.testing.assert_allclose(L, np.linalg.solve(kal.Rn, C @ P).T, rtol=1e-10, atol=1e-14 * np.abs(L).max())
    p = kal.measured.index("p")
    assert C[p, STATE_INDEX["p"]] == 0.0 and np.all(np.real(kal.eigenvalues) < 0)


# ---------------------------------------------------------------------------------------
# The closed loop: separation, the simulated law, the margins


def test_the_lqg_loop_with_the_filter_has_the_separation_principles_poles(filtered_lqg):
    """The closed LQG loop (:func:`quadctl.design.lqg_loop.lqg_matrix`, what the margins break) has, as a
    set, the LQI loop's poles on SciPy's ZOH plant, SciPy's filter poles on each rate, and the estimator's."""
    from scipy import signal

    from quadctl.design import lqg_loop

    st = filtered_lqg
    des, lin, kal = st.design, st.linear, st.loop.estimator
    Ts = kal.sample_time
    Ad, Bd, *_ = signal.cont2discrete((lin.A, lin.B, np.eye(12), np.zeros((12, 4))), Ts, method="zoh")
    nz = len(des.integral_states)
    S = np.zeros((nz, 12))
    for i, s in enumerate(des.integral_states):
        S[i, STATE_INDEX[s]] = 1.0
    lqi = np.block([[Ad - Bd @ des.K_block, -Bd @ des.Ki_block], [-Ts * S, np.eye(nz)]])
    (_, a1), (_, a2) = signal.butter(2, 30.0, fs=1 / Ts), signal.iirnotch(70.0, 70.0 / 30.0, fs=1 / Ts)
    filt = np.tile(np.concatenate([np.roots(a1), np.roots(a2)]), 3)
    want = np.concatenate([np.linalg.eigvals(lqi), filt, kal.eigenvalues])
    M = lqg_loop.lqg_matrix(des, lin.A, lin.B, kal)
    got, tol = eigen_tolerance(M)
    # the filter's poles are triple (one filter per rate): a semisimple eigenvalue is as well conditioned as
    # its cluster, so each takes the cluster's largest tolerance
    tol = np.array([max(tol[np.abs(got - g) < 1e-6].max(), 1e3 * EPS) for g in got])
    worst = as_sets_close(got, want, [tol[int(np.argmin(np.abs(got - w)))] for w in want])
    print(f"separation: {len(want)} poles, worst {worst:.2e}")


def test_the_simulated_law_is_the_linear_lqg_loops(filtered_lqg):
    """The builder's law at the trim, differentiated by CasADi (the command and the sampled loop state against
    the loop state [x; z; g; xh]), is :func:`quadctl.design.lqg_loop.lqg`'s: the same command gain and
    the same estimator update on the same filtered measurement. (The plant between samples is the ZOH
    model's, as for every loop.)"""
    import casadi as ca

    from quadctl.design import lqg_loop
    from quadctl.sim.builder import build

    st = filtered_lqg
    loop, des, lin, kal = st.loop, st.design, st.linear, st.loop.estimator
    spec = loop.spec()
    ne, nz, ng = kal.n_estimate, spec.nz, spec.n_filter
    assert spec.n_estimate == ne == N_STATES + ng and spec.nx == N_STATES + nz + ng + ne
    X = ca.SX.sym("X", spec.nx)
    u, Xs = build(spec).law(X, 0.0, loop.constants(kal.sample_time), ca.DM.zeros(spec.n_exo))
    jac = ca.Function("law_jacobian", [X], [ca.jacobian(u, X), ca.jacobian(Xs, X)])
    Ju, Jx = (np.asarray(J) for J in jac(loop.initial_loop_state(loop.x_trim)))
    base, Bp, Be, Kc = lqg_loop.lqg(des, lin.A, lin.B, kal)  # state [x; g; xh; z]
    order = [*range(N_STATES), *range(2 * ne, 2 * ne + nz), *range(N_STATES, 2 * ne)]  # -> [x; z; g; xh]
    np.testing.assert_allclose(Ju, -Kc[:, order], rtol=1e-12, atol=1e-12 * np.abs(Kc).max())
    # the estimate's prediction and the integrators: base less what the command adds, in the builder's order
    pred = (base - np.vstack([np.zeros_like(Bp), Be, np.zeros((nz, 4))]) @ Kc)[np.ix_(order, order)]
    rows = [*range(N_STATES, N_STATES + nz), *range(N_STATES + nz + ng, spec.nx)]
    np.testing.assert_allclose(Jx[rows], pred[rows], rtol=1e-12, atol=1e-12 * np.abs(pred[rows]).max())


def test_python_control_closes_the_lqg_loop_with_the_filter(filtered_lqg):
    """interop.controller of the filtered LQG loop runs the gyro filter and the estimator: python-control's
    feedback of the ZOH plant and it has the poles of the LQG loop (as sets)."""
    control = pytest.importorskip("control")
    from quadctl.design import lqg_loop
    from quadctl.export import interop

    st = filtered_lqg
    loop, lin, kal = st.loop, st.linear, st.loop.estimator
    ctl = interop.controller(loop)
    assert ctl.nstates == 12 + kal.n_estimate + len(st.design.integral_states)
    fb = control.feedback(interop.plant(lin, sample_time=kal.sample_time), ctl, sign=1)
    want, tol = eigen_tolerance(lqg_loop.lqg_matrix(st.design, lin.A, lin.B, kal), 1e5)
    as_sets_close(fb.poles(), want, np.maximum(tol, 1e-9))


@pytest.fixture(scope="module")
def unfiltered_lqg():
    """The same config without the gyro filter."""
    from quadctl.pipeline import Stages

    return Stages(setup_of(from_dict(lqg_config(None))))


def test_the_lqg_margins_have_the_filter_in_the_loop(filtered_lqg, unfiltered_lqg):
    """Every LQG loop (broken at a plant input, the estimator and the gyro filter in it) is stable with a
    finite phase margin, reported beside the full-state loops; the filter's lag costs the roll and pitch
    loops phase against the same LQG loop without it, and leaves the altitude loop (no rate in it) alone
    but for the estimator's own change (the filtered rates it measures)."""
    found = {(m.loop, m.model): m for m in filtered_lqg.margins}
    raw = {(m.loop, m.model): m for m in unfiltered_lqg.margins}
    for name in ("altitude", "roll", "pitch", "yaw"):
        m = found[(name, "lqg")]
        assert m.stable and np.isfinite(m.phase_margin_deg) and m.phase_margin_deg > 0, name
        print(f"{name}: LQG with the gyro filter PM {m.phase_margin_deg:.4g} deg, GM {m.gain_margin_db[0]:.4g} / "
              f"{m.gain_margin_db[1]:.4g} dB, disk alpha {m.disk_alpha:.4g}; without the filter PM "
              f"{raw[(name, 'lqg')].phase_margin_deg:.4g} deg")
    for name in ("roll", "pitch"):
        assert found[(name, "lqg")].phase_margin_deg < raw[(name, "lqg")].phase_margin_deg, name


def test_designing_with_the_filters_states_gives_them_no_gain(filtered_lqg):
    """Why there is no ``controller.filters.design: include`` (as ``rotor_lag: include``): the filter sits after
    the plant (:func:`quadctl.linear.filters.series`), so the discrete LQR of a rate's subsystem with the
    filter's states, unweighted, gives them zero gain (its Riccati solution has zero filter blocks) and the
    subsystem's states the gains the design has."""
    from quadctl.design import discrete
    from quadctl.linear.filters import series

    st = filtered_lqg
    Ts, form = st.design.sample_time, st.setup.rate_filter.form(st.design.sample_time)
    solved = []
    for sub in st.design.subsystems:
        rates = [i for i, s in enumerate(sub.states) if s in RATE_STATES]
        if not rates or sub.integral:
            continue
        dec = next(d for d in st.decoupled.regulated if d.name == sub.name)
        Ad, Bd, Qd, Rd, Nd = discrete.lqrd_weights(dec.A, dec.B, sub.Q, sub.R, Ts, name=sub.name)
        Aa, Ba = series(Ad, Bd, form, rates)
        ng = len(Aa) - len(Ad)
        Qa = np.block([[Qd, np.zeros((len(Ad), ng))], [np.zeros((ng, len(Ad))), np.zeros((ng, ng))]])
        res = discrete.dlqr(Aa, Ba, Qa, Rd, np.vstack([Nd, np.zeros((ng, Nd.shape[1]))]), name=sub.name)
        scale = np.abs(res.K).max()
        assert np.abs(res.K[:, len(Ad):]).max() <= 1e-12 * scale, sub.name
        np.testing.assert_allclose(res.K[:, :len(Ad)], sub.K, rtol=1e-9, atol=1e-12 * scale, err_msg=sub.name)
        solved.append(sub.name)
    assert solved == ["roll", "pitch", "yaw"]


def test_the_continuous_filtered_lqg_loops_linear_part_is_the_builders_jacobian():
    """A continuous LQG loop with the gyro filter (Kalman-Bucy on the filtered rates): the ETDRK4 remainder
    N = rhs - L X has no linear part at the trim, L (:func:`quadctl.design.lqg_loop.simulated`, the LQG
    loop reordered to the builder's [x; z; g; xh]) being the builder's own Jacobian there."""
    import casadi as ca

    from quadctl.pipeline import Stages
    from quadctl.sim.builder import build

    loop = Stages(setup_of(from_dict(lqg_config(GYRO, rate=None)))).loop
    L = loop.linear_part()
    spec = loop.spec(method="etdrk4")
    assert spec.n_estimate == N_STATES + spec.n_filter and L.shape == (spec.nx, spec.nx)
    X, nc = ca.SX.sym("X", spec.nx), spec.n_constants
    cs = ca.SX.sym("c", nc)
    N = build(spec).remainder(X, 0.0, cs, ca.DM.zeros(spec.n_exo))[0]
    jac = ca.Function("remainder_jacobian", [X, cs], [ca.jacobian(N, X)])
    base = loop.constants()
    lin = np.zeros(nc - len(base))
    lin[:L.size] = L.ravel(order="F")  # "lin", the first of the ETDRK4 block, is L itself
    residual = np.abs(np.asarray(jac(loop.initial_loop_state(loop.x_trim), np.concatenate([base, lin])))).max()
    assert residual <= 1e-9 * np.abs(L).max(), residual


# ---------------------------------------------------------------------------------------
# Every runner: the one-case compiled loop, CasADi's virtual machine, the SIMD lanes


@pytest.mark.compiler
def test_every_runner_flies_the_filtered_lqg_loop_alike(filtered_lqg, monkeypatch):
    """The compiled one-case loop and CasADi's virtual machine agree to round-off on the filtered LQG loop
    (noise before the filter); four lanes with other gains, Kalman gains and seeds each equal their own
    one-case run."""
    from dataclasses import replace

    from _solve import LANE_RTOL, lane_gap, lanes_and_one_case_runs

    from quadctl.sim.run import simulate

    setup, loop = filtered_lqg.setup, filtered_lqg.loop
    x0, duration = setup.initial_state(loop.x_trim), 0.2
    compiled = simulate(loop, x0, duration, setup.dt, noise=setup.noise)
    interpreted = without_compiler(monkeypatch, lambda: simulate(loop, x0, duration, setup.dt, noise=setup.noise))
    assert compiled.backend == "compiled" and interpreted.backend == "casadi"
    diff = max(np.abs(compiled.x - interpreted.x).max(), np.abs(compiled.u - interpreted.u).max(),
               np.abs(compiled.x_hat - interpreted.x_hat).max())
    assert diff < 1e-12, f"Max diff is {diff:.4E}"
    variants = []
    for k in range(4):
        kal = replace(loop.estimator, gain=loop.estimator.gain * (1.0 - 0.02 * k))
        vk = replace(loop, K=loop.K * (1.0 + 0.05 * k), Ki=loop.Ki * (1.0 + 0.05 * k), estimator=kal)
        variants.append((vk, replace(setup.noise, seed=setup.noise.seed + k), duration * (1.0 - 0.1 * k)))
    worst = 0.0
    start = loop.spec(True).nx - loop.estimator.n_estimate  # the estimate of x: the first 12 of xh
    for (_, _, xs, us), one in lanes_and_one_case_runs(setup, loop.spec(True), variants):
        x_hat = one.x_ref + xs[:, start:start + N_STATES]
        worst = max(worst, lane_gap(xs[:, :N_STATES], one.x), lane_gap(us, one.u), lane_gap(x_hat, one.x_hat))
    assert worst < LANE_RTOL, f"Max diff is {worst:.4E} of the quantity's size"


# ---------------------------------------------------------------------------------------
# The bundled config flown


def test_the_bundled_lqg_config_flies_with_a_30_hz_gyro_filter():
    """mambo-lqg with a 30 Hz second-order gyro filter, flown nonlinear (noise before the filter, rotors,
    LQI): the run completes, and over its second half the estimate is as good as without the filter but
    on the rates, which it now sees only through the filter's lag (their error grows, within half again)."""
    from quadctl.pipeline import Stages, simulation_of

    rms = []
    for filters in (None, GYRO):
        st = Stages(setup_of(from_dict(lqg_config(filters, duration=1.0))))
        sim = simulation_of(st.setup, st.loop)
        assert sim.status == "ok", sim.message
        err = (sim.x_hat - sim.x)[len(sim.t) // 2:]
        rms.append(np.sqrt((err ** 2).mean(axis=0)))
    ratio = rms[1] / rms[0]
    print("rms estimation error with / without the gyro filter, second half:", ratio.round(3))
    rates = [STATE_INDEX[s] for s in RATE_STATES]
    others = [i for i in range(N_STATES) if i not in rates]
    assert np.all(np.abs(ratio[others] - 1) < 0.02) and np.all((ratio[rates] > 1) & (ratio[rates] < 1.5)), ratio


def test_the_filter_and_the_estimator_are_no_longer_refused():
    cfg = from_dict(lqg_config(GYRO))
    assert cfg.estimator is not None and cfg.controller.filters.gyro.cutoff == 30.0
