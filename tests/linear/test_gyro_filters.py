"""The gyro filters (controller.filters): their forms against closed forms and SciPy's designs, their phase
lag in the margins against the closed form and an independent loop transfer, and the simulated loop."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from quadctl.config import loading
from quadctl.config.loading import from_dict
from quadctl.design import broken_loops, margin_findings, margin_search
from quadctl.errors import ConfigError
from quadctl.layout import INPUT_INDEX, STATE_INDEX
from quadctl.linear import filters
from quadctl.present.loops import loop_notes
from quadctl.setup import setup_of

TIGHT = 1e-9
"""The closed forms are evaluated in double: a few ulps of phases near 1 rad, and the crossover solved
to round-off by the margins' own refinement (:func:`quadctl.design.margin_search.loop_margins`)."""


def config(name: str, **controller) -> dict:
    data = yaml.safe_load(loading.locate(name).text)
    data["controller"] = {**(data.get("controller") or {}), **controller}
    data["simulation"]["duration"] = 1.0
    return data


# ---------------------------------------------------------------------------------------
# The forms


def test_the_butterworth_and_notch_biquads_are_scipys():
    """The sampled second-order low-pass is SciPy's Butterworth and the notch SciPy's iirnotch (both the
    bilinear transform prewarped at their frequency), response for response."""
    from scipy import signal

    fs, w = 500.0, np.linspace(1.0, 0.99 * np.pi * 500.0, 301)
    for form, (b, a) in ((filters.lowpass2(40.0, 1 / fs), signal.butter(2, 40.0, fs=fs)),
                         (filters.notch(120.0, 30.0, 1 / fs), signal.iirnotch(120.0, 120.0 / 30.0, fs=fs))):
        _, ref = signal.freqz(b, a, worN=w, fs=2 * np.pi * fs)
        np.testing.assert_allclose(form.response(w), ref, rtol=TIGHT, atol=TIGHT)
    # the prewarp keeps the -3 dB point at the cutoff and the notch's zero at its centre
    assert abs(abs(filters.lowpass2(40.0, 1 / fs).response(2 * np.pi * 40.0)[0]) - 1 / math.sqrt(2)) < TIGHT
    assert abs(filters.notch(120.0, 30.0, 1 / fs).response(2 * np.pi * 120.0)[0]) < TIGHT


def test_the_continuous_forms_are_their_transfer_functions():
    wc, w0, Q = 2 * np.pi * 30.0, 2 * np.pi * 90.0, 3.0
    w = np.logspace(0, 4, 50)
    s = 1j * w
    cases = ((filters.lowpass1(30.0, None), wc / (s + wc)),
             (filters.lowpass2(30.0, None), wc ** 2 / (s ** 2 + math.sqrt(2) * wc * s + wc ** 2)),
             (filters.notch(90.0, 30.0, None), (s ** 2 + w0 ** 2) / (s ** 2 + w0 / Q * s + w0 ** 2)))
    for form, ref in cases:
        np.testing.assert_allclose(form.response(w), ref, rtol=TIGHT)


def test_a_cascade_is_the_product_of_its_sections():
    Ts, w = 1 / 1000, np.linspace(1.0, 3000.0, 40)
    low, notch = filters.lowpass1(50.0, Ts), filters.notch(200.0, 60.0, Ts)
    both = filters.RateFilter((filters.Section("lowpass", 50.0, 1),
                               filters.Section("notch", 200.0, bandwidth=60.0))).form(Ts)
    np.testing.assert_allclose(both.response(w), low.response(w) * notch.response(w), rtol=TIGHT)


# ---------------------------------------------------------------------------------------
# The margins: a rate loop whose only feedback is the filtered rate


J, GAIN, CUTOFF = 7.75e-5, 0.01, 20.0
"""kg m^2, N m per rad/s, Hz: a pitch-rate loop q' = E / J closed by E = -GAIN q_filtered (unfiltered
crossover GAIN / J = 129 rad/s, beside the filter's 126 rad/s: the lag is large)."""


def rate_loop(sample_time=None):
    """The broken loop of ``E = -GAIN y``, ``y`` the first-order low-passed rate, ``q' = E / J`` (held)."""
    form = filters.lowpass1(CUTOFF, sample_time)
    A, B = np.zeros((1, 1)), np.array([[1 / J]])
    if sample_time is not None:
        B = B * sample_time  # the ZOH of an integrator: q <- q + Ts E / J
        A = np.eye(1)
    Aa, Ba, Ka = filters.with_rate_filter(A, B, [[GAIN]], form, [0])
    return broken_loops.broken_loop(Aa, Ba, Ka, 0, sample_time)


def test_a_first_order_gyro_lowpass_costs_atan_of_the_crossover_over_its_cutoff():
    """Continuous: L = (GAIN / J s) wc / (s + wc): the integrator's 90 deg less atan(w / wc) at the crossover."""
    m = margin_search.loop_margins(rate_loop(), name="pitch", input_name="E")
    wc = m.gain_crossover_freq
    assert abs(abs(GAIN / (J * wc)) / math.hypot(1, wc / (2 * np.pi * CUTOFF)) - 1) < TIGHT
    expected = 90.0 - math.degrees(math.atan(wc / (2 * np.pi * CUTOFF)))
    assert abs(m.phase_margin_deg - expected) < TIGHT, (m.phase_margin_deg, expected)
    assert m.phase_margin_deg < 60.0  # the filter costs real margin: 90 deg without it


def test_the_sampled_lowpass_costs_its_own_phase_at_the_crossover():
    """At 200 Hz: L(z) = (GAIN Ts / J) / (z - 1) (1 - a) z / (z - a): the ZOH integrator's
    90 deg - th / 2 less the PT1's atan2(a sin th, 1 - a cos th), th = w Ts."""
    Ts = 1 / 200
    m = margin_search.loop_margins(rate_loop(Ts), name="pitch", input_name="E")
    th = m.gain_crossover_freq * Ts
    a = math.exp(-2 * np.pi * CUTOFF * Ts)
    z = np.exp(1j * th)
    assert abs(abs(GAIN * Ts / J / (z - 1) * (1 - a) * z / (z - a)) - 1) < TIGHT
    lag = math.atan2(a * math.sin(th), 1 - a * math.cos(th))
    expected = 90.0 - math.degrees(th / 2) - math.degrees(lag)
    assert abs(m.phase_margin_deg - expected) < TIGHT, (m.phase_margin_deg, expected)


# ---------------------------------------------------------------------------------------
# The margins of a full LQR loop, against an independent loop transfer


def gains(des, w, Ts, F) -> np.ndarray:
    """(N, 4, 12): the law's transfer from the state to the command at ``z = e^(j w Ts)``: ``K`` with the
    rates through the filter ``F`` (N,), and the integrators ``z <- z - Ts x_s`` fed back through ``Ki``."""
    from quadctl.design import integral
    from quadctl.layout import STATE_NAMES

    z = np.exp(1j * np.asarray(w) * Ts)
    K = np.broadcast_to(des.K_block, (len(z), 4, 12)).astype(complex).copy()
    for s in ("p", "q", "r"):
        K[:, :, STATE_INDEX[s]] *= F[:, None]
    if des.integral_states:
        C = integral.selector(STATE_NAMES, des.integral_states)
        K = K + (-Ts / (z - 1))[:, None, None] * (np.asarray(des.Ki_block) @ C)[None]
    return K


@pytest.fixture(scope="module")
def filtered_mambo():
    from quadctl.pipeline import Stages

    cfg = from_dict(config("mambo-200hz", filters={"gyro": {"cutoff": 30.0, "order": 2},
                                                   "notch": {"center": 80.0, "bandwidth": 30.0}}))
    return Stages(setup_of(cfg))


def test_the_lqr_loops_margins_are_those_of_the_loop_with_the_filter_in_its_rate_path(filtered_mambo):
    """The coupled loops broken at each input equal python-control's ZOH plant closed by the gains with
    SciPy's Butterworth and notch on the rate columns (every other loop closed), frequency by frequency;
    the phase margin is that transfer's phase at its own unit-gain crossover."""
    import control as ct
    from scipy import signal

    st = filtered_mambo
    setup, des, lin = st.setup, st.design, st.linear
    Ts = 1 / setup.timing.rate
    fs = setup.timing.rate
    b1, a1 = signal.butter(2, 30.0, fs=fs)
    b2, a2 = signal.iirnotch(80.0, 80.0 / 30.0, fs=fs)
    plant = ct.c2d(ct.ss(lin.A, lin.B, np.eye(12), np.zeros((12, 4))), Ts, method="zoh")
    loops = {(name, inp): loop for name, inp, model, loop in
             broken_loops.design_loops(des, st.decoupled, lin.A, lin.B, Ts, rate_filter=setup.rate_filter)
             if model == "coupled"}
    w = np.linspace(0.5, 0.98 * np.pi / Ts, 400)
    P = np.moveaxis(plant.frequency_response(w).complex, -1, 0)  # (N, 12, 4)
    F = signal.freqz(b1, a1, worN=w, fs=2 * np.pi * fs)[1] * signal.freqz(b2, a2, worN=w, fs=2 * np.pi * fs)[1]
    G = gains(des, w, Ts, F) @ P  # (N, 4, 4): the controller's output per plant input
    for (name, inp), loop in loops.items():
        j = INPUT_INDEX[inp]
        o = [i for i in range(4) if i != j]
        Goo = G[:, o][:, :, o]
        ref = G[:, j, j] - np.einsum("ni,nij,nj->n", G[:, j, o], np.linalg.inv(np.eye(3) + Goo), G[:, o, j])
        np.testing.assert_allclose(loop(w), ref, rtol=1e-8, atol=1e-12, err_msg=f"{name} ({inp})")
        m = margin_search.loop_margins(loop, name=name, input_name=inp, model="coupled")
        if m.gain_crossover_freq is not None:
            wc = np.array([m.gain_crossover_freq])
            Pc = np.moveaxis(plant.frequency_response(wc).complex, -1, 0)
            Fc = (signal.freqz(b1, a1, worN=wc, fs=2 * np.pi * fs)[1]
                  * signal.freqz(b2, a2, worN=wc, fs=2 * np.pi * fs)[1])
            Gc = gains(des, wc, Ts, Fc)[0] @ Pc[0]
            Lc = Gc[j, j] - Gc[j, o] @ np.linalg.inv(np.eye(3) + Gc[np.ix_(o, o)]) @ Gc[o, j]
            assert abs(abs(Lc) - 1) < 1e-8, (name, abs(Lc))
            assert abs(m.phase_margin_deg - (180 + math.degrees(np.angle(Lc)))) < 1e-6, name


def test_the_filter_lowers_the_attitude_loops_margins(filtered_mambo):
    """Roll and pitch lose phase margin to the filter's lag; altitude (no rate in its loop) keeps its own."""
    st = filtered_mambo
    lin = st.linear
    Ts = 1 / st.setup.timing.rate
    with_filter = {(m.loop, m.model): m for m in margin_findings.all_margins(
        st.design, st.decoupled, lin.A, lin.B, rate_filter=st.setup.rate_filter)}
    raw = {(m.loop, m.model): m for m in margin_findings.all_margins(st.design, st.decoupled, lin.A, lin.B)}
    assert Ts == st.design.sample_time
    for key in (("roll", "design"), ("pitch", "coupled")):
        assert with_filter[key].phase_margin_deg < raw[key].phase_margin_deg - 5, key
    assert with_filter[("altitude", "design")].phase_margin_deg == raw[("altitude", "design")].phase_margin_deg


# ---------------------------------------------------------------------------------------
# The simulated loop


def test_a_config_without_gyro_filters_flies_bit_for_bit_as_before():
    """``filters: {}`` (nothing on the gyro) is no filter: the same loop structure, constants and run."""
    from quadctl.pipeline import Stages, simulation_of

    runs = []
    for extra in ({}, {"filters": {}}):
        setup = setup_of(from_dict(config("mambo-200hz", **extra)))
        assert setup.rate_filter is None
        loop = Stages(setup).loop
        runs.append((loop.spec().key(), loop.constants(0.005), simulation_of(setup, loop, noise=False).x))
    assert runs[0][0] == runs[1][0] and "filter" not in runs[0][0]
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    np.testing.assert_array_equal(runs[0][2], runs[1][2])


def test_the_continuous_loops_linear_part_is_the_builders_jacobian():
    """A continuous loop with the filter: the ETDRK4 remainder N = rhs - L X has no linear part at the trim
    (L, :func:`quadctl.design.lqg_loop.simulated` with the filter, is the builder's own Jacobian there)."""
    import casadi as ca

    from quadctl.pipeline import Stages
    from quadctl.sim.builder import build

    setup = setup_of(from_dict(config("hover", filters={"gyro": {"cutoff": 25.0, "order": 2},
                                                        "notch": {"center": 60.0, "bandwidth": 20.0}})))
    loop = Stages(setup).loop
    L = loop.linear_part()
    spec = loop.spec(method="etdrk4")
    assert spec.n_filter == 12 and L.shape == (spec.nx, spec.nx)
    fns = build(spec)
    X = ca.SX.sym("X", spec.nx)
    nc = spec.n_constants
    cs = ca.SX.sym("c", nc)
    N = fns.remainder(X, 0.0, cs, ca.DM.zeros(spec.n_exo))[0]
    jac = ca.Function("remainder_jacobian", [X, cs], [ca.jacobian(N, X)])
    base = loop.constants()
    lin = np.zeros(nc - len(base))
    lin[:L.size] = L.ravel(order="F")  # "lin", the first of the ETDRK4 block, is L itself
    x0 = loop.initial_loop_state(loop.x_trim)
    residual = np.abs(np.asarray(jac(x0, np.concatenate([base, lin])))).max()
    assert residual <= 1e-9 * np.abs(L).max(), residual


def test_filters_a_sampled_controller_cannot_run_are_refused():
    with pytest.raises(ConfigError, match=r"controller.filters.gyro.cutoff.*Nyquist"):
        from_dict(config("mambo-200hz", filters={"gyro": {"cutoff": 100.0}}))
    with pytest.raises(ConfigError, match=r"controller.filters.notch.bandwidth"):
        from_dict(config("mambo-200hz", filters={"notch": {"center": 30.0, "bandwidth": 70.0}}))


def test_a_d_term_filter_on_the_lqr_law_is_a_notice_and_changes_nothing():
    from quadctl.config.notices import notices

    cfg = from_dict(config("mambo-200hz", filters={"d_term": {"cutoff": 30.0}}))
    found = [n for n in notices(cfg, "c.yaml") if n.key == "controller.filters.d_term"]
    assert len(found) == 1 and "no D term" in found[0].message
    assert setup_of(cfg).rate_filter is None


def test_the_margins_notes_give_the_filters_lag_at_each_rate_loops_crossover(filtered_mambo):
    st = filtered_mambo
    found = margin_findings.all_margins(st.design, st.decoupled, st.linear.A, st.linear.B,
                                        rate_filter=st.setup.rate_filter)
    form = st.setup.rate_filter.form(st.design.sample_time)
    for m in found:
        notes = [n for n in loop_notes(m) if n.startswith("gyro filter")]
        if m.loop == "altitude":  # no rate in its loop
            assert not notes
            continue
        lag = -math.degrees(np.angle(form.response(m.gain_crossover_freq)[0]))
        assert len(notes) == 1 and f"{lag:.3g} deg of phase lag" in notes[0], (m.loop, notes)
        (fact,) = [f for f in m.findings if isinstance(f, margin_findings.GyroFilterLag)]
        assert fact.phase_lag_deg == pytest.approx(lag, rel=1e-12) and fact.crossover_rad_s == m.gain_crossover_freq


def test_python_control_closes_the_same_loop_with_the_filter(filtered_mambo):
    """interop.controller of a filtered loop carries the filter: python-control's feedback of the ZOH plant
    and it has the eigenvalues of the vehicle's loop with the filter (as sets)."""
    control = pytest.importorskip("control")
    from quadctl.design import linear_loop
    from quadctl.export import interop

    st = filtered_mambo
    loop, des, lin = st.loop, st.design, st.linear
    Ts = des.sample_time
    ctl = interop.controller(loop, sample_time=Ts)
    assert ctl.nstates == len(des.integral_states) + 3 * st.setup.rate_filter.order
    fb = control.feedback(interop.plant(lin, sample_time=Ts), ctl, sign=1)
    want = np.linalg.eigvals(linear_loop.vehicle_matrix(des, lin.A, lin.B, Ts, keep_free=True,
                                                        rate_filter=st.setup.rate_filter.form(Ts)))
    got = list(fb.poles())
    assert len(got) == len(want)
    for w in want:
        k = int(np.argmin([abs(g - w) for g in got]))
        assert abs(got.pop(k) - w) < 1e-9 * max(1.0, abs(w)), w
    with pytest.raises(ValueError, match="gyro filter"):
        interop.closed_loop(lin, loop)


def test_the_mat_and_json_export_carry_the_filter_the_law_runs(filtered_mambo):
    from quadctl import export
    from quadctl.export import data

    exp = export.prepare(filtered_mambo.setup)
    found = {f.name: f for f in data.fields(exp)}
    value = found["gyro_filter"].value
    form = filtered_mambo.loop.filter_form
    for key in ("A", "b", "c"):
        np.testing.assert_array_equal(value[key], getattr(form, key))
    assert value["d"] == form.d and "through its filter (second-order low-pass at 30 Hz" in exp.law()


def test_an_integrator_on_a_filtered_rate_is_refused():
    data = config("mambo-200hz", filters={"gyro": {"cutoff": 30.0}})
    data["lqr"]["yaw"] = {**data["lqr"]["yaw"], "Q": [25, 0.25, 1.0], "integral": ["r"]}
    with pytest.raises(ConfigError, match=r"lqr.yaw.integral\[0\].*integrates a body rate"):
        from_dict(data)
