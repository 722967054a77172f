"""Step-response metrics against closed forms: a first-order mode settles into the 2 % band at
``tau ln 50``, a second-order one overshoots by ``exp(-zeta pi / sqrt(1 - zeta^2))``; the one-run
functions and the batched ones a sweep uses alike."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadctl import metrics
from quadctl.layout import N_INPUTS, N_STATES, STATE_INDEX, STATE_NAMES


def _batched(t, e, state="pD", noisy=False):
    """:func:`metrics.summarize_errors` of one run whose only nonzero error is ``e`` on ``state``."""
    err = np.zeros((1, N_STATES, len(t)))
    err[0, STATE_INDEX[state]] = e
    return metrics.summarize_errors(t[None, :], err, np.zeros((1, N_INPUTS, len(t))), np.zeros((1, N_INPUTS)),
                                    np.zeros((1, N_STATES, N_STATES)), np.zeros((1, N_INPUTS, N_INPUTS)),
                                    STATE_NAMES, ["ok"], [noisy])[0]


@pytest.mark.parametrize("tau, e0, dt", [(0.3, 1.0, 1e-3), (2.0, -0.05, 4e-3), (0.05, 3.0, 1e-4)])
def test_a_first_order_mode_settles_at_tau_ln_50(tau, e0, dt):
    """``e = e0 exp(-t / tau)`` leaves ``|e| > 0.02 |e0|`` for good at ``tau ln 50``; the metric is the
    first sample past it, so it lies in ``[tau ln 50, tau ln 50 + dt)``."""
    t = np.arange(0.0, 8 * tau, dt)
    e = e0 * np.exp(-t / tau)
    want = tau * math.log(1 / metrics.SETTLING_BAND)
    assert metrics.SETTLING_BAND == 0.02 and want == pytest.approx(tau * math.log(50), rel=1e-15)
    for got in (metrics.settling_time(t, e), _batched(t, e)["settling_time"]["pD"]):
        assert want <= got < want + dt, (got, want)


@pytest.mark.parametrize("zeta", [0.2, 0.5, 0.8])
def test_a_second_order_mode_overshoots_as_its_damping_says(zeta):
    """``e = e0 (cos(wd t) + zeta / sqrt(1 - zeta^2) sin(wd t)) exp(-zeta wn t)`` (a released
    second-order mode from rest) peaks past zero at ``pi / wd`` by ``exp(-zeta pi / sqrt(1 - zeta^2))``
    of ``e0``: to the sampling's error (``dt^2`` at the flat peak)."""
    wn, e0, dt = 4.0, 0.5, 1e-4
    wd = wn * math.sqrt(1 - zeta ** 2)
    t = np.arange(0.0, 20 / (zeta * wn), dt)
    e = e0 * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta ** 2) * np.sin(wd * t)) * np.exp(-zeta * wn * t)
    want = 100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta ** 2))
    for got in (metrics.overshoot(e), _batched(t, e)["overshoot"]["pD"]):
        assert got == pytest.approx(want, rel=1e-6)


@pytest.mark.parametrize("sigma_in_bands, limited", [(0.02, False), (0.1, False), (1.5, True), (4.0, True)])
def test_a_decaying_mode_plus_white_noise_is_noise_limited_exactly_when_the_noise_exceeds_the_band(
        sigma_in_bands, limited):
    """``e = exp(-t / 0.3) + n``, ``n`` white of standard deviation ``sigma_in_bands`` times the 2 %
    band, over 10 s at 1 ms. Noise above the band crosses it to the end of the run: in a run with
    noise the state is noise-limited (no settling time) in the one-run and batched metrics alike;
    noise well inside it (at most 0.1 band: 10 sigma to the edge) leaves the mode's own settling time,
    ``0.3 ln 50`` moved by the noise at the edge (within 5 sigma of it). Read without noise, the same
    errors keep the number the band's last crossing gives."""
    tau, dt = 0.3, 1e-3
    t = np.arange(0.0, 10.0 + dt / 2, dt)
    band = metrics.SETTLING_BAND  # of the peak, 1 (the noise moves it by at most sigma)
    e = np.exp(-t / tau) + np.random.default_rng(7).normal(0.0, sigma_in_bands * band, t.size)
    single = metrics.settling_time(t, e, noisy=True)
    batched = metrics.summarize_errors(t[None], np.tile(e, (1, N_STATES, 1)), np.zeros((1, N_INPUTS, t.size)),
                                       np.zeros((1, N_INPUTS)), np.zeros((1, N_STATES, N_STATES)),
                                       np.zeros((1, N_INPUTS, N_INPUTS)), ("pD", "p"), ["ok"], [True])[0]
    run = _Run(t, e)
    summary = metrics.summarize(run, np.zeros(N_INPUTS), np.zeros((N_STATES, N_STATES)),
                                np.zeros((N_INPUTS, N_INPUTS)), ("pD", "p"), noisy=True)
    if limited:
        assert single is None
        assert batched["noise_limited"] == summary["noise_limited"] == ["pD", "p"]
        assert batched["settling_time"] == summary["settling_time"] == {"pD": None, "p": None}
        quiet = metrics.settling_time(t, e)  # the same errors read without noise: the last crossing
        assert quiet is None or quiet > 9.0
    else:
        edge = [tau * math.log(1 / (band * (1 + k * sigma_in_bands))) for k in (5, -5)]
        assert edge[0] < single < edge[1], (single, edge)
        assert batched["noise_limited"] == summary["noise_limited"] == []
        assert batched["settling_time"] == summary["settling_time"] == {"pD": single, "p": single}
        assert single == metrics.settling_time(t, e)


class _Run:
    """A run's arrays as :func:`metrics.summarize` reads them: the error ``e`` on every state."""

    def __init__(self, t, e):
        self.t, self.x = t, np.tile(e[:, None], (1, N_STATES))
        self.x_ref, self.u = np.zeros_like(self.x), np.zeros((t.size, N_INPUTS))
        self.status = "ok"


def test_noise_limited_needs_a_late_crossing_a_trend_inside_the_band_and_noise_that_reaches_its_edge():
    """The rule at its edges, band 0.02 of a 10 s run: a crossing at 9 s is on time, past it late; a late
    crossing (or an error outside at the end) is noise-limited only when the band's edge lies within three
    standard deviations of the noise about where the error's trend ends, on either side."""
    band = 0.02
    assert not metrics.noise_limited(9.0, 10.0, 0.0, 0.01, band)
    assert not metrics.noise_limited(0.0, 10.0, 0.0, 0.01, band)
    assert metrics.noise_limited(9.001, 10.0, 0.0, 0.01, band)
    assert metrics.noise_limited(None, 10.0, -0.015, 0.002, band)
    assert not metrics.noise_limited(None, 10.0, 0.05, 0.0099, band)  # outside, beyond the noise: never settled
    assert metrics.noise_limited(None, 10.0, 0.05, 0.0101, band)
    assert metrics.noise_limited(None, 10.0, -0.05, 0.0101, band)
    assert not metrics.noise_limited(9.5, 10.0, 0.019, 0.0003, band)  # still coming in, too little noise to reach
    assert metrics.noise_limited(9.5, 10.0, 0.019, 0.00034, band)


@pytest.mark.parametrize("sigma", [0.0, 1e-4, 1e-3])
def test_an_error_still_coming_down_at_the_end_never_settled_with_or_without_noise(sigma):
    """``e = exp(-t / 3)`` cut at 10 s ends at ``exp(-10 / 3)`` = 3.6 % of its largest, outside its 2 % band,
    and is still coming down: with noise up to a twentieth of the band on it, it never settled (the rule that
    read any error down to half its largest at the end as noise-limited called this one noise-limited)."""
    t = np.arange(0.0, 10.0 + 5e-4, 1e-3)
    e = np.exp(-t / 3.0) + np.random.default_rng(1).normal(0.0, sigma, t.size)
    assert metrics.settling_time(t, e, noisy=True) is None
    assert not metrics.limited_by_noise(t, e, None)
    summary = metrics.summarize(_Run(t, e), np.zeros(N_INPUTS), np.zeros((N_STATES, N_STATES)),
                                np.zeros((N_INPUTS, N_INPUTS)), ("pD",), noisy=True)
    assert summary["noise_limited"] == [] and summary["settling_time"] == {"pD": None}
    assert _batched(t, e, noisy=True)["noise_limited"] == []


def test_a_mode_that_enters_its_band_in_the_last_tenth_keeps_its_settling_time():
    """``e = exp(-t / tau)`` with ``tau = 9.5 / ln 50`` enters its 2 % band at 9.5 s, in the last tenth of a
    10 s run, with no noise about its trend: in a run with noise it is on its way in, not noise-limited,
    and keeps ``tau ln 50`` to the sampling step."""
    tau, dt = 9.5 / math.log(50.0), 1e-3
    t = np.arange(0.0, 10.0 + dt / 2, dt)
    e = np.exp(-t / tau)
    assert metrics.settling_time(t, e, noisy=True) == pytest.approx(9.5, abs=dt)
    assert _batched(t, e, noisy=True)["settling_time"]["pD"] == pytest.approx(9.5, abs=dt)


def test_the_tail_trend_is_the_least_squares_line_of_the_last_tenth():
    """Against numpy's least-squares fit of the samples at ``t >= 0.9 t_end``: the line's value at the end and
    the RMS of the residuals about it; one sample in the tail, a flat line through it."""
    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 4.0, 4001)
    e = 0.3 - 0.05 * t + rng.normal(0.0, 0.01, t.size)
    tail = t >= 0.9 * t[-1]
    slope, intercept = np.polyfit(t[tail], e[tail], 1)
    residual = e[tail] - (intercept + slope * t[tail])
    end, spread = metrics.tail_trend(t, e)
    assert end == pytest.approx(intercept + slope * t[-1], rel=1e-10)
    assert spread == pytest.approx(math.sqrt(np.mean(residual ** 2)), rel=1e-8)
    assert metrics.tail_trend(np.array([0.0, 1.0]), np.array([5.0, 0.25])) == (0.25, math.inf)


def test_the_tail_trend_of_a_batch_works_on_its_tail_only_and_gives_the_same_lines():
    """A sweep's noisy batch reads the line of its errors' last tenth (16 runs, 12 states, 5001 samples, two
    steps): the sums start where the first run's tail does, so the work and the memory it takes are those of
    the tail, not of the whole run (it took over five times the errors' own size, an eleventh of it now); the
    lines are each run's own, to the last bit, whatever else is in the batch."""
    import tracemalloc

    rng = np.random.default_rng(2)
    t = np.stack([np.linspace(0.0, 5.0, 5001)] * 8 + [np.linspace(0.0, 4.0, 5001)] * 8)
    err = np.exp(-t[:, None, :] / rng.uniform(0.2, 3.0, (16, 12, 1))) + rng.normal(0.0, 1e-3, (16, 12, 5001))
    tracemalloc.start()
    try:
        end, spread = metrics.tail_trend(t[:, None, :], err)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < err.nbytes, f"{peak / err.nbytes:.2f} times the errors' size"
    for b, i in ((0, 0), (9, 7), (15, 11)):
        assert (end[b, i], spread[b, i]) == metrics.tail_trend(t[b], err[b, i])


@pytest.mark.parametrize("records", [12, 40, 150, 20_000])
def test_a_late_crossing_with_too_few_records_to_measure_the_noise_claims_no_settling_time(records):
    """A decay down into white noise of half a band, kept as ``records`` samples of a 10 s run (as a small
    ``simulation.max_samples`` keeps them): with fewer than NOISE_MIN_RECORDS in the last tenth a line
    fits them exactly and measures no noise, so a late crossing would have kept a settling time the records
    cannot support; it reads noise-limited, as it does with every record kept."""
    t = np.linspace(0.0, 10.0, records)
    band = metrics.SETTLING_BAND
    e = np.exp(-t / 0.3) + np.random.default_rng(11).normal(0.0, 0.5 * band, t.size)
    e[-1] = 1.5 * band  # the last record outside: never settled
    n_tail = int(np.sum(t >= (1.0 - metrics.NOISE_TAIL) * t[-1]))
    assert (n_tail < metrics.NOISE_MIN_RECORDS) == (records < 100)
    assert metrics.limited_by_noise(t, e, None)


def test_with_gusts_the_noise_about_the_trend_is_not_measured_so_a_late_crossing_is_noise_limited():
    """Dryden gusts last longer than a run's last tenth: a line through it follows a gust, so an error
    outside its band at the end reads noise-limited under turbulence (Disturbance.GUSTS) whatever its trend,
    where under noise a trend that ends far outside the band never settled."""
    t = np.linspace(0.0, 10.0, 10_001)
    e = np.exp(-t / 3.0)  # ends at 3.6 % of its largest, coming down: outside its 2 % band
    assert not metrics.limited_by_noise(t, e, None)
    assert metrics.limited_by_noise(t, e, None, metrics.Disturbance.GUSTS)
    assert metrics.settling_time(t, e, noisy=metrics.Disturbance.GUSTS) is None
    assert _batched(t, e, noisy=metrics.Disturbance.GUSTS)["noise_limited"] == ["pD"]
    assert _batched(t, e, noisy=True)["noise_limited"] == []


def test_a_turbulent_run_reads_the_same_noise_limited_states_whatever_its_seed():
    """crazyflie-wind (turbulence): which states read noise-limited does not depend on the turbulence's
    seed (a line through the last tenth, following a gust, read p noise-limited with seed 2 and never
    settled with seed 1)."""
    from quadctl import config, pipeline
    from quadctl.config import overrides
    from quadctl.setup import setup_of

    found = []
    for seed in (1, 2):
        cfg = overrides.load(config.locate("crazyflie-wind"), [f"simulation.wind.turbulence.seed={seed}"])
        stages = pipeline.Stages(setup_of(cfg))
        assert pipeline.noisy(stages.setup) == metrics.Disturbance.GUSTS
        sim = pipeline.simulation_of(stages.setup, stages.loop)
        found.append(metrics.summarize(sim, stages.linear.u_trim, stages.setup.Q_block, stages.setup.R_block,
                                       stages.setup.regulated, noisy=pipeline.noisy(stages.setup))["noise_limited"])
    assert found[0] == found[1] and "p" in found[0]
