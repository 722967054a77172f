"""Rotor dynamics (``motors.time_constant``): each rotor's thrust lags its command.

The lag in the builder against its closed form, the limit of a vanishing lag, the config's
bounds. The engine's agreement with the lag (compiled, interpreted, lanes) is in
tests/sim/test_engine.py; the sweep's lanes in tests/sweep/test_sweep.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from _solve import cfg_dict, run

from quadctl import config
from quadctl.design import broken_loops, lag, margin_search
from quadctl.errors import ConfigError
from quadctl.layout import N_STATES
from quadctl.sim.builder import build
from quadctl.sim.run import simulate

EXACT = 1e-13
"""The builder's RK4 against RK4's own closed form ``R(z)^n`` on the linear lag: round-off only."""


def _lagged(tau: float | None, **changes):
    data = cfg_dict("mambo-200hz", **changes)
    data["motors"]["time_constant"] = tau
    data["simulation"]["initial_offset"] = {"phi": 0.2, "pD": 0.2}
    return data


@pytest.mark.parametrize("steps_per_tau", [5, 20])
def test_a_rotor_step_follows_one_minus_exp(steps_per_tau):
    """From zero thrust, a held command ``f_cmd``: ``f(t) = f_cmd (1 - exp(-t/tau))``.

    RK4 on ``df/dt = -f/tau`` multiplies the error ``f - f_cmd`` by ``R(z) = 1 + z + z^2/2 + z^3/6
    + z^4/24`` per step (``z = -dt/tau``): the builder must give ``f_cmd (1 - R(z)^n)`` to round-off,
    and that is within ``n |z|^5 / 120 e^{-(n-1)|z|}`` (RK4's local error ``|z|^5/120`` times
    ``n`` steps, each decayed at most to ``e^{-(n-1)|z|}``, to leading order) of the closed form.
    """
    _, _, loop, _ = run(_lagged(0.03))
    tau = loop.rotor_time_constant
    dt = tau / steps_per_tau
    plant = build(loop.spec()).plant
    c = loop.constants(0.005)
    u = loop.u_trim
    f_cmd = loop.actuators.commands(u)
    X = np.concatenate([loop.x_trim, np.zeros(4), np.zeros(len(loop.integral_states))])
    z = -dt / tau
    R = 1 + z + z ** 2 / 2 + z ** 3 / 6 + z ** 4 / 24
    worst_exact, worst_bound = 0.0, 0.0
    for n in range(1, 5 * steps_per_tau + 1):  # five time constants
        X = np.asarray(plant(X, u, dt, c, np.zeros(0))).ravel()
        f = X[N_STATES:N_STATES + 4]
        worst_exact = max(worst_exact, np.abs(f - f_cmd * (1 - R ** n)).max())
        closed = f_cmd * (1 - np.exp(-n * dt / tau))
        bound = f_cmd.max() * n * abs(z) ** 5 / 120 * np.exp(-(n - 1) * abs(z))
        worst_bound = max(worst_bound, (np.abs(f - closed) / bound).max())
    assert worst_exact < EXACT, f"Max diff is {worst_exact:.4E}"
    assert worst_bound < 1.0, f"error / RK4 bound is {worst_bound:.4E}"


def test_the_rotors_start_at_trim_and_the_lagged_loop_settles():
    setup, _, loop, _ = run(_lagged(0.03))
    sim = simulate(loop, setup.initial_state(loop.x_trim), setup.duration)  # without the config's noise
    assert sim.status == "ok"
    trim = loop.actuators.commands(loop.u_trim)
    np.testing.assert_allclose(sim.rotor_thrust[0], trim, rtol=1e-15)
    np.testing.assert_allclose(sim.rotor_thrust[-1], trim, rtol=1e-3)  # the altitude integrator still settles
    # the body feels the rotors, not the command: T = sum of rotor thrusts lags the commanded T
    assert np.abs(sim.rotor_thrust.sum(axis=1) - sim.u[:, 0]).max() > 1e-3


def test_a_vanishing_lag_approaches_the_instantaneous_loop():
    """The state's distance from the instantaneous loop's shrinks in proportion to ``tau``.

    Measured (largest state difference over 0.5 s, the roll rate's): 0.67, 0.129, 0.0130 at
    tau = 10, 1, 0.1 ms: the lag acts as a delay of about ``tau``, so the gap is first order in it.
    """
    duration = 0.5
    setup, _, base_loop, _ = run(_lagged(None))
    base = simulate(base_loop, setup.initial_state(base_loop.x_trim), duration)
    gaps = {}
    for tau in (1e-2, 1e-3, 1e-4):
        setup, _, loop, _ = run(_lagged(tau))
        sim = simulate(loop, setup.initial_state(loop.x_trim), duration)
        x = np.array([np.interp(base.t, sim.t, col) for col in sim.x.T]).T
        gaps[tau] = np.abs(x - base.x).max()
    assert gaps[1e-3] < gaps[1e-2] / 5, gaps
    assert gaps[1e-3] / gaps[1e-4] == pytest.approx(10.0, rel=0.1), gaps  # first order in tau (measured 9.9)


@pytest.mark.parametrize("k, tau", [(1.0, 0.5), (50.0, 0.03)])
def test_the_margins_see_the_lag_an_integrator_loop_loses_atan_wc_tau(k, tau):
    """``L = k / (s (tau s + 1))``: ``|L| = 1`` at ``w_c`` with ``k = w_c sqrt(1 + (w_c tau)^2)``,
    phase margin ``90 deg - atan(w_c tau)``."""
    A, B = lag.lagged(np.zeros((1, 1)), np.ones((1, 1)), tau)
    m = margin_search.loop_margins(broken_loops.BrokenLoop(A, B[:, 0], np.array([k, 0.0])))
    wc = np.sqrt((np.sqrt(1 + 4 * (k * tau) ** 2) - 1) / (2 * tau ** 2))
    assert m.gain_crossover_freq == pytest.approx(wc, rel=1e-9)
    assert m.phase_margin_deg == pytest.approx(90.0 - np.degrees(np.arctan(wc * tau)), rel=1e-9)


@pytest.mark.parametrize("value, why", [(0.0, "must be greater than 0.0 \\(s, "), (2.0, "must be at most 1 \\(s, ")])
def test_a_time_constant_out_of_range_is_refused(value, why):
    data = cfg_dict("mambo-200hz")
    data["motors"]["time_constant"] = value
    with pytest.raises(ConfigError, match=f"motors.time_constant = {value:g}: {why}"):
        config.from_dict(data)
