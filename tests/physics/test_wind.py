"""Wind: the drag on the air-relative velocity, trim in a steady wind, the MIL-F-8785C gust, the
MIL-HDBK-1797 Dryden spectra, realizations independent of the step and of chunking, wind in every
runner (compiled, interpreted, lanes) and in sweeps, its artifacts and its config errors."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from _solve import cfg_dict, solve, without_compiler

from quadctl import config, pipeline, sweep
from quadctl.errors import ConfigError
from quadctl.linear.trim import solve_trim
from quadctl.physics.model import Vehicle, build_model
from quadctl.physics.wind import (
    FT,
    KNOT,
    Gust,
    Turbulence,
    TurbulenceStream,
    WindSpec,
    WindStream,
    low_altitude,
)
from quadctl.setup import setup_of
from quadctl.sim import engine
from quadctl.sim.cases import Cases
from quadctl.sim.exogenous import ExoStream
from quadctl.sim.plan import record_stride
from quadctl.sim.run import simulate

# ---------------------------------------------------------------------------------------
# The model: drag on the velocity relative to the air


def test_still_air_is_the_model_without_wind():
    m, rng = build_model(), np.random.default_rng(0)
    for _ in range(5):
        x, u = rng.normal(size=12) * 0.3, np.array([0.7, 1e-3, -1e-3, 1e-4])
        p = Vehicle(drag=(0.3, 0.2, 0.1)).vector()
        np.testing.assert_array_equal(np.asarray(m.f_wind(x, u, p, np.zeros(3))), np.asarray(m.f(x, u, p)))
        A, B = m.jacobians(x, u, p)
        Aw, Bw = m.jacobians_wind(x, u, p, np.zeros(3))
        np.testing.assert_array_equal(np.asarray(A), np.asarray(Aw))
        np.testing.assert_array_equal(np.asarray(B), np.asarray(Bw))


def test_a_vehicle_moving_with_the_wind_feels_no_drag():
    """V_b = R_E^b w: the air-relative velocity is zero, so the model with drag equals the one without."""
    from quadctl.physics.model import rotation_earth_to_body

    m, rng = build_model(), np.random.default_rng(1)
    dragging, dragless = Vehicle(drag=(0.3, 0.2, 0.1)).vector(), Vehicle(drag=(0.0, 0.0, 0.0)).vector()
    for _ in range(5):
        x = rng.normal(size=12) * 0.3
        wind = rng.normal(size=3) * 5
        x[3:6] = np.asarray(rotation_earth_to_body(*x[6:9]), dtype=float) @ wind
        u = np.array([0.8, 0.0, 0.0, 0.0])
        with_wind = np.asarray(m.f_wind(x, u, dragging, wind), dtype=float).ravel()
        np.testing.assert_allclose(with_wind, np.asarray(m.f(x, u, dragless), dtype=float).ravel(), atol=1e-14)
        still = np.asarray(m.f(x, u, dragging), dtype=float).ravel()  # in still air the same motion drags
        assert np.abs(still - with_wind)[3:6].max() > 1e-3


# ---------------------------------------------------------------------------------------
# Trim in a steady wind


def test_hover_in_a_horizontal_wind_tilts_into_it_as_the_closed_form_says():
    """Kz = 0, nose north, wind w north: x balance T Kx cos(th) w = m g sin(th), z balance T = m g cos(th),
    so tan(th) = T Kx w / (m g); it is the forward-flight trim at -w (the same air-relative velocity)."""
    v = Vehicle()
    for w in (0.5, 1.0, 3.0):
        t = solve_trim([0, 0, 0], 0.0, [0, 0, -1], v, wind_ned=[w, 0, 0])
        theta, T = t.x[7], t.u[0]
        assert t.residual < 1e-12
        assert T == pytest.approx(v.mass * v.gravity * math.cos(theta), rel=1e-12)
        assert math.tan(theta) == pytest.approx(T * v.drag[0] * w / (v.mass * v.gravity), rel=1e-12)
        assert theta > 0  # nose up: the thrust leans south, against the wind
        flight = solve_trim([-w, 0, 0], 0.0, [0, 0, -1], v)
        assert theta == pytest.approx(flight.x[7], abs=1e-12)
    report = solve_trim([0, 0, 0], 0.0, [0, 0, -1], v, wind_ned=[1, 0, 0])
    assert report.x[7] == pytest.approx(0.2119, abs=1e-4)  # the report's -0.2119 rad at 1 m/s, mirrored


def test_trim_in_any_wind_is_an_equilibrium_and_holds_its_ground_velocity():
    m, rng = build_model(), np.random.default_rng(2)
    for _ in range(6):
        v = Vehicle(drag=tuple(rng.uniform(0, 0.3, 3)))
        wind, vel, yaw = rng.normal(size=3), rng.normal(size=3) * 0.5, rng.uniform(-3, 3)  # airspeed ~2 m/s
        t = solve_trim(vel, yaw, [0, 0, -1], v, wind_ned=wind)
        xdot = np.asarray(m.f_wind(t.x, t.u, v.vector(), wind), dtype=float).ravel()
        assert np.abs(xdot[3:]).max() < 1e-10 and t.residual < 1e-10
        np.testing.assert_allclose(xdot[:3], vel, atol=1e-12)


def test_the_linear_model_in_wind_is_the_jacobian_of_the_model_in_wind():
    from quadctl.linear.linearize import linearize

    v, wind = Vehicle(), np.array([2.0, -1.0, 0.0])
    t = solve_trim([0, 0, 0], 0.3, [0, 0, -1], v, wind_ned=wind)
    lin = linearize(t.x, t.u, v, wind)
    f = build_model().f_wind
    h, A = 1e-6, np.zeros((12, 12))
    for i in range(12):
        e = np.zeros(12)
        e[i] = h
        A[:, i] = (np.asarray(f(t.x + e, t.u, v.vector(), wind)) - np.asarray(f(t.x - e, t.u, v.vector(), wind))
                   ).ravel() / (2 * h)
    np.testing.assert_allclose(lin.A, A, atol=1e-7)
    still = linearize(t.x, t.u, v)
    assert np.abs(still.A - lin.A).max() > 1e-2  # the wind changes the drag's Jacobian


# ---------------------------------------------------------------------------------------
# The 1-cosine gust and Dryden turbulence


def test_the_gust_follows_its_formula():
    g = Gust(start=1.0, length=0.4, amplitude=(2.0, -1.0, 0.5))
    t = np.linspace(0, 3, 3001)
    s = (t - 1.0) / 0.4
    want = np.where((s >= 0) & (s <= 2), 0.5 * (1 - np.cos(np.pi * s)), 0.0)  # full 1-cosine over 2 lengths
    np.testing.assert_allclose(g.shape(t), want, atol=1e-15)
    held = Gust(start=1.0, length=0.4, amplitude=(1.0, 0, 0), hold=0.5)
    assert held.shape(np.array([1.4, 1.6, 1.9]))[1] == 1.0 and held.shape(np.array([2.1]))[0] == pytest.approx(
        0.5 * (1 + math.cos(math.pi * 0.2 / 0.4)))
    stays = Gust(start=0.0, length=1.0, amplitude=(1.0, 0, 0), hold=math.inf)  # MIL-F-8785C's own
    np.testing.assert_array_equal(stays.shape(np.array([1.0, 5.0, 1e6])), [1.0, 1.0, 1.0])


def test_low_altitude_scales_and_intensities_are_the_handbooks():
    for intensity, knots in (("light", 15), ("moderate", 30), ("severe", 45)):
        for h_ft in (10.0, 100.0, 999.0):
            sigma, L = low_altitude(intensity, h_ft * FT)
            sw = 0.1 * knots * KNOT
            assert sigma[2] == pytest.approx(sw, rel=1e-12)
            assert sigma[0] == sigma[1] == pytest.approx(sw / (0.177 + 0.000823 * h_ft) ** 0.4, rel=1e-12)
            assert L[2] == pytest.approx(h_ft / 2 * FT, rel=1e-12)  # 2 L_w = h
            assert L[0] == pytest.approx(2 * L[1]) == pytest.approx(h_ft / (0.177 + 0.000823 * h_ft) ** 1.2 * FT)
    assert low_altitude("light", 0.5) == low_altitude("light", 10 * FT)  # scales taken at 10 ft at least


TURB = Turbulence(sigma=(1.5, 1.2, 0.8), length=(20.0, 10.0, 6.0), speed=10.0, heading=0.0, seed=11)
"""Correlation times of 2 s at most: a 5000 s realization holds thousands of them."""


@pytest.fixture(scope="module")
def realization():
    return TurbulenceStream(TURB).samples(0, 2 ** 19 - 1).copy()  # 5243 s at 100 Hz


def test_dryden_realization_has_the_handbook_spectra(realization):
    """Welch (4096-sample Hann segments, 255 of them: about 7 % standard error per frequency bin)
    against MIL-HDBK-1797's spectra at the reference speed, averaged over octave bands from 0.05 to
    5 Hz (the corners V / L and V / 2L are 0.08 to 0.8 Hz): every band within 10 % (the 4-bin lowest
    band's standard error is 3.5 %, the others' less)."""
    from scipy.signal import welch

    f, P = welch(realization, fs=1 / TURB.period, nperseg=4096, axis=0)
    S = TURB.psd(f)
    edges = np.array([0.05, 0.15, 0.3, 0.6, 1.2, 2.5, 5.0])
    worst = 0.0
    for lo, hi in zip(edges[:-1], edges[1:]):
        band = (f >= lo) & (f < hi)
        ratio = P[band].mean(axis=0) / S[band].mean(axis=0)
        worst = max(worst, np.abs(ratio - 1).max())
    assert worst < 0.10, f"worst band ratio off by {worst:.3f}"


def _mil_f_8785c_psd(f, sigma, scales, speed):
    """(n, 3) one-sided PSD (m/s)^2/Hz at ``f`` (Hz) of MIL-F-8785C §3.7.2.1's Dryden spectra, written
    here from the specification (not from quadctl.physics.wind): ``Phi_u(W) = sigma_u^2 (2 L_u / pi) / (1 +
    (L_u W)^2)``, ``Phi_v(W) = sigma_v^2 (L_v / pi) (1 + 3 (L_v W)^2) / (1 + (L_v W)^2)^2`` (``w``
    alike), seen at ``speed``: ``S(f) = Phi(2 pi f / V) 2 pi / V``. ``scales`` are MIL-F-8785C's
    (``L_v = L_u``, ``L_w = h`` at low altitude)."""
    W = 2 * np.pi * np.asarray(f, dtype=float)[:, None] / speed
    (su, sv, sw), (Lu, Lv, Lw) = sigma, scales
    phi = np.column_stack([
        su ** 2 * (2 * Lu / np.pi) / (1 + (Lu * W[:, 0]) ** 2),
        sv ** 2 * (Lv / np.pi) * (1 + 3 * (Lv * W[:, 0]) ** 2) / (1 + (Lv * W[:, 0]) ** 2) ** 2,
        sw ** 2 * (Lw / np.pi) * (1 + 3 * (Lw * W[:, 0]) ** 2) / (1 + (Lw * W[:, 0]) ** 2) ** 2])
    return phi * 2 * np.pi / speed


def _low_altitude_8785c(intensity, h_ft):
    """MIL-F-8785C §3.7.2.3 near the ground (h in ft): sigma_w = 0.1 W20 (15, 30, 45 kt at 20 ft),
    sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4; L_u = L_v = h / (0.177 + 0.000823 h)^1.2,
    L_w = h. Returns (sigma m/s, L m)."""
    sw = 0.1 * {"light": 15, "moderate": 30, "severe": 45}[intensity] * 1852 / 3600
    su = sw / (0.177 + 0.000823 * h_ft) ** 0.4
    Lu = h_ft / (0.177 + 0.000823 * h_ft) ** 1.2 * 0.3048
    return (su, su, sw), (Lu, Lu, h_ft * 0.3048)


@pytest.mark.parametrize("turbulence, reference", [
    # explicit scales are MIL-HDBK-1797's: its L_v, L_w are half of MIL-F-8785C's
    ({"sigma": [1.5, 1.2, 0.8], "length_scale": [20.0, 10.0, 6.0], "airspeed": 10.0},
     ((1.5, 1.2, 0.8), (20.0, 20.0, 12.0), 10.0)),
    ({"intensity": "light", "altitude": 10 * 0.3048, "airspeed": 10.0},
     _low_altitude_8785c("light", 10.0) + (10.0,)),
    ({"intensity": "moderate", "altitude": 30 * 0.3048, "airspeed": 20.0},
     _low_altitude_8785c("moderate", 30.0) + (20.0,)),
    ({"intensity": "severe", "altitude": 100 * 0.3048, "airspeed": 50.0},
     _low_altitude_8785c("severe", 100.0) + (50.0,)),
], ids=["explicit", "light", "moderate", "severe"])
def test_the_recorded_wind_has_the_dryden_spectrum_of_mil_f_8785c(turbulence, reference):
    """The wind a run records (``wind_felt``, what ``sim.npz``'s ``wind`` holds) of a config's
    turbulence, 2^18 samples on a 100 Hz clock (2621 s), against the closed-form Dryden PSD of
    MIL-F-8785C with its own scales (the same spectra as MIL-HDBK-1797's "2L" form with 2 L_w = h).
    Welch, 4096-sample Hann segments (127 with half overlap: about 9 % standard error per bin),
    averaged over octave bands from 0.1 to 6.4 Hz (the corners V / L are 0.07 to 0.5 Hz), each band
    within 15 %: the lowest band's four bins hold about 6 % standard error, the others less; over
    eight seeds per case the worst band of the 18 was 10 % off. A scale off by two puts the vertical
    spectrum at 0.5-0.6 of it above its corner and twice it below."""
    from scipy.signal import welch

    from quadctl.sim.exogenous import wind_felt

    data = cfg_dict("hover")
    data["simulation"]["wind"] = {"turbulence": {**turbulence, "seed": 4}}
    wind = setup_of(config.from_dict(data, "dryden.yaml")).wind
    period, n = 0.01, 2 ** 18
    recorded = wind_felt(wind, period, np.arange(n), period, block=4096)
    f, P = welch(recorded, fs=1 / period, nperseg=4096, axis=0)
    sigma, scales, speed = reference
    S = _mil_f_8785c_psd(f, sigma, scales, speed)
    edges = 0.1 * 2.0 ** np.arange(7)  # 0.1 to 6.4 Hz
    ratios = np.array([P[(f >= lo) & (f < hi)].mean(axis=0) / S[(f >= lo) & (f < hi)].mean(axis=0)
                       for lo, hi in zip(edges[:-1], edges[1:])])
    worst = np.abs(ratios - 1).max()
    assert worst < 0.15, f"band PSD / Dryden (rows: octave bands; columns u, v, w):\n{np.round(ratios, 3)}"


def test_dryden_realization_has_the_configured_variance(realization):
    np.testing.assert_allclose(realization.var(axis=0), np.square(TURB.sigma), rtol=0.05)
    np.testing.assert_allclose(realization.mean(axis=0), 0.0, atol=0.05 * max(TURB.sigma))


def test_the_analytic_spectra_integrate_to_the_variances():
    from scipy.integrate import quad

    for axis in range(3):
        total = quad(lambda f, a=axis: TURB.psd(np.array([f]))[0, a], 0, np.inf, limit=500)[0]
        assert total == pytest.approx(TURB.sigma[axis] ** 2, rel=1e-6)


def test_turbulence_axes_follow_the_mean_wind():
    east = replace(TURB, heading=math.pi / 2)
    a = TurbulenceStream(TURB).samples(0, 999)
    b = TurbulenceStream(east).samples(0, 999)
    np.testing.assert_allclose(b[:, 1], a[:, 0], atol=1e-15)   # along the wind: east
    np.testing.assert_allclose(b[:, 0], -a[:, 1], atol=1e-15)  # its right: south
    np.testing.assert_array_equal(b[:, 2], a[:, 2])


def test_the_realization_does_not_depend_on_how_it_is_asked_for():
    spec = WindSpec(steady=(1.0, 0.0, 0.0), gusts=(Gust(0.3, 0.2, (0.0, 1.0, 0.0)),), turbulence=TURB)
    whole = WindStream(spec, 0.005).samples(0, 4000)
    stream, parts, first = WindStream(spec, 0.005), [], 0
    for size in (1, 2, 333, 1000, 7, 2658):
        parts.append(stream.samples(first, first + size - 1).copy())
        first += size
    np.testing.assert_array_equal(np.concatenate(parts), whole)
    again = WindStream(spec, 0.005).samples(0, 4000)
    np.testing.assert_array_equal(again, whole)
    other = WindStream(replace(spec, turbulence=replace(TURB, seed=12)), 0.005).samples(0, 4000)
    assert np.abs(other - whole).max() > 0.1



def test_the_turbulence_between_its_samples_is_the_line_through_them():
    """The turbulence at any time is linear between its samples (every ``period`` s): at a sample it is that
    sample, at a fraction ``a`` of the way to the next it is ``(1 - a)`` of one and ``a`` of the other, so it
    is continuous. A run reads it on its own exogenous clock, which need not be the turbulence's: a 200 Hz
    controller's 5 ms falls halfway between two samples 10 ms apart."""
    rows = TurbulenceStream(TURB).samples(0, 200)
    period = TURB.period
    for a in (0.0, 0.25, 0.5, 0.9):
        t = (np.arange(200) + a) * period
        want = (1.0 - a) * rows[:-1] + a * rows[1:]
        np.testing.assert_allclose(TurbulenceStream(TURB).at(t), want, rtol=0, atol=1e-12 * np.abs(rows).max())


# ---------------------------------------------------------------------------------------
# Wind in the closed loop


def _windy(name="hover", seed=3, **wind):
    data = cfg_dict(name)
    data["simulation"]["wind"] = {"steady": [1.0, 0.5, 0.0],
                                  "gusts": [{"start": 0.05, "length": 0.02, "amplitude": [0.0, 2.0, -0.5]}],
                                  "turbulence": {"intensity": "moderate", "seed": seed}, **wind}
    data["trim"]["wind"] = True
    return data


def _loop(data):
    setup, trim, linear, _, des = solve(data)
    return setup, pipeline.loop_of(setup, linear, des)


def test_the_plant_feels_the_gust_sample_for_sample():
    data = _windy(turbulence=None, steady=[0.0, 0.0, 0.0])
    data["trim"]["wind"] = False
    setup, loop = _loop(data)
    sim = simulate(loop, setup.initial_state(loop.x_trim), 0.2, setup.dt, wind=setup.wind)
    period = 0.005  # continuous control, no noise: the exogenous clock's default
    ks = np.rint(sim.t / sim.dt)
    t_sample = np.floor(ks * sim.dt / period + 1e-9) * period  # the sample each recorded step holds
    gust = setup.wind.gusts[0]
    s = (t_sample - gust.start) / gust.length
    want = np.where((s >= 0) & (s <= 2), 0.5 * (1 - np.cos(np.pi * s)), 0.0)[:, None] * np.array(gust.amplitude)
    np.testing.assert_allclose(sim.wind, want, atol=1e-15)
    assert np.abs(sim.wind).max() == pytest.approx(2.0, abs=1e-3)
    assert np.abs(sim.x[-1, 4] - loop.x_trim[4]) > 1e-4  # the east gust pushed the vehicle


def test_a_run_in_wind_is_the_same_at_any_step_and_any_chunking(monkeypatch):
    from quadctl.sim import stack_run as stack_module

    setup, loop = _loop(_windy())
    x0 = setup.initial_state(loop.x_trim)
    a = simulate(loop, x0, 0.1, setup.dt, wind=setup.wind)
    b = simulate(loop, x0, 0.1, setup.dt, wind=setup.wind)
    np.testing.assert_array_equal(a.x, b.x)  # bit-identical reruns
    np.testing.assert_array_equal(a.wind, b.wind)
    monkeypatch.setattr(stack_module, "CHUNK_STEPS", {"compiled": 97, "casadi": 97})
    c = simulate(loop, x0, 0.1, setup.dt, wind=setup.wind)
    np.testing.assert_array_equal(a.x, c.x)  # chunked differently: the same run
    np.testing.assert_array_equal(a.wind, c.wind)
    monkeypatch.undo()
    fine = simulate(loop, x0, 0.1, a.dt / 2, wind=setup.wind, max_samples=10 ** 6)
    coarse = simulate(loop, x0, 0.1, a.dt, wind=setup.wind, max_samples=10 ** 6)
    common = np.isin(np.round(fine.t / coarse.dt, 6), np.round(coarse.t / coarse.dt))
    np.testing.assert_array_equal(fine.wind[common], coarse.wind)  # the same wind at half the step
    # the states agree to the step's error: a held sample takes over at the first step past its time
    assert np.abs(fine.x[common] - coarse.x).max() < 1e-3


@pytest.mark.compiler
def test_compiled_and_interpreted_loops_agree_in_wind(monkeypatch):
    data = _windy("mambo-200hz")
    data["simulation"]["noise"] = {"seed": 2, "force": [0.01, 0.01, 0.01], "sensor": {"phi": 0.01}}
    setup, loop = _loop(data)
    x0 = setup.initial_state(loop.x_trim)
    compiled = simulate(loop, x0, 0.3, setup.dt, noise=setup.noise, wind=setup.wind)
    interpreted = without_compiler(monkeypatch,
                                   lambda: simulate(loop, x0, 0.3, setup.dt, noise=setup.noise, wind=setup.wind))
    assert compiled.backend == "compiled" and interpreted.backend == "casadi"
    assert np.abs(compiled.x - interpreted.x).max() < 1e-12 and np.abs(compiled.u - interpreted.u).max() < 1e-12
    np.testing.assert_array_equal(compiled.wind, interpreted.wind)
    still = simulate(loop, x0, 0.3, setup.dt, noise=setup.noise)
    assert still.backend == "compiled"
    assert np.abs(still.x - compiled.x).max() > 1e-3  # the wind moved it


@pytest.mark.compiler
@pytest.mark.parametrize("name, noise", [("hover", False), ("mambo-200hz", True)])
def test_lanes_equal_the_one_case_loop_in_wind(name, noise):
    """Eleven lanes (the last group padded), each with its own gains and turbulence seed, against
    its own one-case run: to 1e-12."""
    data = _windy(name)
    if noise:
        data["simulation"]["noise"] = {"seed": 5, "force": [0.01, 0.0, 0.01], "sensor": {"theta": 0.01}}
    setup, loop = _loop(data)
    duration = 0.3
    variants = []
    for k in range(11):
        wind = replace(setup.wind, turbulence=replace(setup.wind.turbulence, seed=k))
        variants.append((replace(loop, K=loop.K * (1 + 0.05 * k)), wind))
    spec = loop.spec(noise, True)
    jobs = []
    for vk, wind in variants:
        plan = vk.plan(duration, setup.dt)
        lo, hi = vk.bounds(duration)
        stream = ExoStream(setup.noise, wind, vk.rate)
        first, exo = stream.rows(0, plan.n_steps, plan.dt)
        jobs.append((plan, vk.constants(plan.sample_time), vk.initial_loop_state(setup.initial_state(vk.x_trim)),
                     lo, hi, exo, first, stream.period))
    cases = Cases.of(np.stack([j[2] for j in jobs]), np.stack([j[1] for j in jobs]), [j[0].dt for j in jobs],
                     [j[0].n_steps for j in jobs], [record_stride(j[0].n_steps, setup.max_samples) for j in jobs],
                     np.stack([j[3] for j in jobs]), np.stack([j[4] for j in jobs]),
                     hold=[max(j[0].hold, 1) for j in jobs], exo=[j[5] for j in jobs],
                     exo_first=[j[6] for j in jobs], exo_period=[j[7] for j in jobs])
    run = engine.runner(spec, engine.LANES)
    assert run.backend == "compiled-simd"
    worst = 0.0
    for (vk, wind), (done, t, xs, us) in zip(variants, run.run(cases)):
        one = simulate(vk, setup.initial_state(vk.x_trim), duration, setup.dt, noise=setup.noise, wind=wind,
                       max_samples=setup.max_samples)
        assert done == one.steps and one.status == "ok"
        np.testing.assert_array_equal(t, one.t)
        worst = max(worst, np.abs(xs[:, :12] - one.x).max(), np.abs(us - one.u).max())
    assert worst < 1e-12, f"Max diff is {worst:.4E}"


def test_a_sweep_in_wind_gives_the_same_rows_on_one_or_two_processes():
    cfg = config.from_dict(_windy("mambo-200hz"), "wind.yaml")
    spec = sweep.from_dict({"parameters": {"simulation.wind.turbulence.seed": [0, 1, 2],
                                           "simulation.wind.gusts[0].start": [0.05, 0.1]},
                            "set": {"simulation.duration": 0.3}, "chunk_size": 2}, cfg, "wind-sweep.yaml")
    one = sweep.run(cfg, spec, jobs=1)
    two = sweep.run(cfg, spec, jobs=2)
    assert one.rows == two.rows and len(one.rows) == 6
    assert all(r["status"] == "ok" for r in one.rows)
    eig = {r["eig.fastest"] for r in one.rows}
    assert len(eig) == 1  # seeds and gust timing do not change the design
    costs = {r["cost"] for r in one.rows} if "cost" in one.rows[0] else {r["rms.pE"] for r in one.rows}
    assert len(costs) == 6  # but every case flew its own wind
    slow = sweep.run(cfg, spec, jobs=1, fast=False)  # the lanes against the one-case pipeline
    for a, b in zip(one.rows, slow.rows):
        for key, value in a.items():
            if isinstance(value, float) and key not in ("path",):
                assert value == pytest.approx(b[key], rel=1e-6, abs=1e-9), key


# ---------------------------------------------------------------------------------------
# Artifacts, the bundled config, config errors


def test_simulate_records_the_wind_and_reports_ground_and_air_speed(tmp_path):
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    res = CliRunner().invoke(app, ["simulate", "-c", "crazyflie-wind", "-o", str(tmp_path)], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    assert "airspeed" in res.output and "ground speed" in res.output
    npz = np.load(tmp_path / "sim.npz")
    assert npz["wind"].shape == (len(npz["t"]), 3) and str(npz["wind_unit"]) == "m/s"
    assert list(npz["wind_names"]) == ["wind N", "wind E", "wind D"]
    assert json.loads((tmp_path / "trim.json").read_text())["wind_ned"] == [0.0, 9.7, 0.0]
    wind = json.loads((tmp_path / "sim.json").read_text())["wind"]
    assert wind["steady"] == [0.0, 9.7, 0.0] and wind["trim_in_wind"] and wind["turbulence"]["seed"] == 1
    # hovering in a 9.7 m/s wind: the airspeed is about the wind, the ground speed small
    assert 8.0 < wind["airspeed"]["rms"] < 11.5 and wind["ground_speed"]["rms"] < 2.0
    air = np.linalg.norm(npz["wind"], axis=1)
    assert wind["peak_wind"] == pytest.approx(air.max())


@pytest.mark.parametrize("wind, trim, fragment", [
    ({"steady": [100.0, 0.0, 0.0]}, {}, "simulation.wind.steady[0]"),
    ({"gust": []}, {}, "simulation.wind.gust"),
    ({"gusts": [{"start": 1.0, "length": 0.0, "amplitude": [1, 0, 0]}]}, {}, "simulation.wind.gusts[0].length"),
    ({"turbulence": {"intensity": "moderate", "sigma": [1, 1, 1], "length_scale": [10, 10, 10]}}, {},
     "simulation.wind.turbulence.intensity"),
    ({"turbulence": {"sigma": [1, 1, 1]}}, {}, "simulation.wind.turbulence.length_scale"),
    ({"turbulence": {"intensity": "stormy"}}, {}, "simulation.wind.turbulence.intensity"),
    ({"turbulence": {}}, {}, "simulation.wind.turbulence"),
    ({"turbulence": {"intensity": "light", "altitude": 2000.0}}, {}, "simulation.wind.turbulence.altitude"),
    ({}, {"wind": True}, "trim.wind"),
])
def test_bad_wind_keys_give_one_line_naming_the_key(wind, trim, fragment):
    data = cfg_dict("hover")
    data["simulation"]["wind"] = wind
    data["trim"].update(trim)
    with pytest.raises(ConfigError) as err:
        setup_of(config.from_dict(data, "w.yaml"))
    text = str(err.value)
    assert "\n" not in text and fragment in text, text


def test_the_bundled_wind_config_trims_tilted_into_its_wind():
    setup, trim, linear, _, des = solve(cfg_dict("crazyflie-wind"))
    assert setup.trim_wind == (0.0, 9.7, 0.0) and trim.residual < 1e-10
    phi = trim.x[6]
    v = setup.vehicle  # wind blowing east: roll left (negative phi) to lean the thrust west
    assert phi < 0 and math.tan(-phi) == pytest.approx(trim.u[0] * v.drag[1] * 9.7 / (v.mass * v.gravity), rel=1e-9)
    assert setup.wind.turbulence.speed == pytest.approx(9.7)  # the trim's airspeed


def test_the_readme_gust_numbers():
    """docs/guide/wind.md: the gust alone moves crazyflie-wind 0.24 m and 0.72 deg, the turbulence 2.5 m and 5.2 deg;
    the trim rolls it -0.2266 rad."""
    for turbulence, drift, pitch in ((False, 0.24, 0.72), (True, 2.5, 5.2)):
        data = cfg_dict("crazyflie-wind")
        if not turbulence:
            data["simulation"]["wind"]["turbulence"] = None
        setup, trim, linear, _, des = solve(data)
        sim = pipeline.simulation_of(setup, pipeline.loop_of(setup, linear, des))
        err = sim.x - sim.x_ref
        assert sim.status == "ok"
        assert np.abs(err[:, 0]).max() == pytest.approx(drift, abs=0.005 if drift < 1 else 0.05)
        assert math.degrees(np.abs(err[:, 7]).max()) == pytest.approx(pitch, abs=0.005 if pitch < 1 else 0.05)
        assert trim.x[6] == pytest.approx(-0.2266, abs=5e-5)


def test_the_forming_filters_closed_forms_are_expm_and_lyapunov():
    from scipy.linalg import expm, solve_continuous_lyapunov

    from quadctl.physics.wind import _stationary, _transition

    for axis, (A, B, C) in enumerate(TURB.filters()):
        P = solve_continuous_lyapunov(A, -B @ B.T)
        np.testing.assert_allclose(_stationary(A, B), P, rtol=1e-12, atol=1e-12 * np.abs(P).max())
        np.testing.assert_allclose(_transition(A, TURB.period), expm(A * TURB.period), rtol=1e-12, atol=1e-15)
        variance = float((C @ _stationary(A, B) @ C.T)[0, 0])
        assert variance == pytest.approx(TURB.sigma[axis] ** 2, rel=1e-12)


def test_a_steady_wind_without_trim_wind_gets_a_note():
    from quadctl.config import notices

    data = _windy()
    data["trim"]["wind"] = False
    found = notices.notices(config.from_dict(data, "w.yaml"), "w.yaml")
    assert [(n.level, n.key) for n in found] == [("note", "trim.wind")]
    assert "trim.wind: true" in found[0].message and "\n" not in found[0].message
    assert notices.notices(config.from_dict(_windy(), "w.yaml"), "w.yaml") == []


def test_wind_keys_are_plant_side_but_the_steady_wind_a_trim_is_made_in():
    cfg = config.from_dict(_windy("mambo-200hz"), "wind.yaml")  # trim.wind: true
    study = {"simulation.wind.turbulence.seed": [0, 1], "simulation.wind.gusts[0].start": [0.05, 0.1]}
    assert sweep.from_dict({"parameters": study}, cfg, "s.yaml").monte_carlo
    steady = {"simulation.wind.steady[0]": [1.0, 2.0]}
    assert not sweep.from_dict({"parameters": steady}, cfg, "s.yaml").monte_carlo  # a design per wind
    assert sweep.from_dict({"parameters": steady, "set": {"trim.wind": False}}, cfg, "s.yaml").monte_carlo
