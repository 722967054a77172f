"""Step-response metrics against closed forms: a first-order mode settles into the 2 % band at
``tau ln 50``, a second-order one overshoots by ``exp(-zeta pi / sqrt(1 - zeta^2))``; the one-run
functions and the batched ones a sweep uses alike."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadctl import metrics
from quadctl.layout import N_INPUTS, N_STATES, STATE_INDEX, STATE_NAMES


def _batched(t, e, state="pD"):
    """:func:`metrics.summarize_errors` of one run whose only nonzero error is ``e`` on ``state``."""
    err = np.zeros((1, N_STATES, len(t)))
    err[0, STATE_INDEX[state]] = e
    return metrics.summarize_errors(t[None, :], err, np.zeros((1, N_INPUTS, len(t))), np.zeros((1, N_INPUTS)),
                                    np.zeros((1, N_STATES, N_STATES)), np.zeros((1, N_INPUTS, N_INPUTS)),
                                    STATE_NAMES, ["ok"])[0]


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


def test_noise_limited_is_a_settling_time_in_the_last_tenth_of_the_run_or_an_error_that_came_down():
    """The rule at its edges: at 9 s of a 10 s run a number, past it noise-limited; never settled, an
    error that ends at half its largest or less is noise-limited, one that ends above it (a drift, an
    error still growing at the end) never settled."""
    assert not metrics.noise_limited(9.0, 10.0) and not metrics.noise_limited(0.0, 10.0)
    assert metrics.noise_limited(9.001, 10.0)
    assert metrics.noise_limited(None, 10.0, final=-0.5, peak=1.0) and metrics.noise_limited(None, 10.0, 0.03, 1.0)
    assert not metrics.noise_limited(None, 10.0, final=0.51, peak=1.0)
    assert not metrics.noise_limited(None, 10.0, final=1.0, peak=1.0)  # at its largest at the end: growing
    assert not metrics.noise_limited(None, 10.0)
