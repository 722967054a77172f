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
