"""Figures read as engineers expect: Bode phase about -180 deg (the closed-form phase of a known
loop, a real loop's phase margin read off the plot), altitude drawn as height (up positive), input
plots with the actuator limits (rotor limits in closed form: ``T`` in ``[4 min, 4 max]``, torques at
full differential thrust)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from _solve import cfg_dict, solve

from quadctl import margins, plots
from quadctl.layout import INPUT_INDEX, N_INPUTS, N_STATES, STATE_INDEX
from quadctl.motors import Motors, actuators_of


def _lines(ax, label=None):
    return [ln for ln in ax.get_lines() if label is None or ln.get_label() == label]


def test_the_phase_of_a_known_loop_is_its_closed_form_in_minus_360_to_0():
    """``L(s) = k / (s (s + 1))``: phase ``-90 - atan(w)`` deg at every frequency, whatever whole turns
    ``numpy.angle`` and ``unwrap`` start from; and a curve that unwraps to 140..260 deg (a loop whose
    phase starts just past -180) is drawn at -220..-100."""
    w = np.logspace(-2, 2, 400)
    L = 2.0 / (1j * w * (1j * w + 1))
    want = -90 - np.rad2deg(np.arctan(w))
    for turns in (-2, 0, 1, 3):  # the same response, started on another branch
        shifted = np.rad2deg(np.unwrap(np.angle(L))) + 360 * turns
        got = plots.phase_about_minus_180(np.exp(1j * np.deg2rad(shifted)))
        np.testing.assert_allclose(got, want, atol=1e-9)
    wc = math.sqrt((math.sqrt(17) - 1) / 2)  # |L| = 1: w^2 (1 + w^2) = 4
    i = int(np.argmin(np.abs(w - wc)))
    np.testing.assert_allclose(plots.phase_about_minus_180(L, i), want, atol=1e-9)
    past = np.exp(1j * np.deg2rad(np.linspace(140.0, 260.0, 50)))
    np.testing.assert_allclose(plots.phase_about_minus_180(past), np.linspace(-220.0, -100.0, 50), atol=1e-9)


def test_a_loops_bode_phase_shows_its_phase_margin_above_minus_180():
    """mambo-200hz's roll loop (sampled, the one the README shows): the plotted phase at the gain
    crossover is ``-180 + PM`` (PM from quadctl.margins, which never reads the plot), within the grid's
    spacing, and the whole curve lies in (-360, 0]."""
    setup, trim, linear, dec, des = solve(cfg_dict("mambo-200hz"))
    roll = next(m for m in margins.all_margins(des, dec, linear.A, linear.B) if m.loop == "roll"
                and m.model == "design")
    fig = plots.margins_figure(roll)
    ax_ph = fig.axes[1]
    assert ax_ph.get_ylabel() == "phase of L [deg]"
    curve = _lines(ax_ph)[0]
    w, phase = curve.get_xdata(), curve.get_ydata()
    assert phase.max() <= 0.0 and phase.min() > -360.0, (phase.min(), phase.max())
    at = phase[int(np.argmin(np.abs(np.log(w / roll.gain_crossover_freq))))]
    step = np.abs(np.diff(phase)).max()  # the phase moves at most this much between grid points
    assert at == pytest.approx(-180.0 + roll.phase_margin_deg, abs=step), (at, roll.phase_margin_deg)
    assert any(np.allclose(ln.get_ydata(), -180.0) for ln in _lines(ax_ph)[1:])  # the -180 line is drawn


def _sim(n=50):
    t = np.linspace(0.0, 1.0, n)
    x, x_ref = np.zeros((n, N_STATES)), np.zeros((n, N_STATES))
    x[:, STATE_INDEX["pD"]] = -1.0 + 0.5 * np.exp(-5 * t)  # 0.5 m up, rising to 1 m
    x_ref[:, STATE_INDEX["pD"]] = -1.0
    u = np.tile([0.6, 0.001, -0.002, 0.0], (n, 1))
    return SimpleNamespace(t=t, x=x, x_ref=x_ref, u=u, status="ok")


def test_the_altitude_plot_shows_height_up():
    sim = _sim()
    fig = plots.subsystem_figure(sim, "altitude", ["pD", "w"])
    ax = fig.axes[0]
    assert ax.get_ylabel() == "height (-pD) [m]"
    state, ref = _lines(ax, "height (-pD)")[0], _lines(ax, "reference")[0]
    np.testing.assert_array_equal(state.get_ydata(), -sim.x[:, STATE_INDEX["pD"]])  # 0.5 m rising to 1 m
    np.testing.assert_array_equal(ref.get_ydata(), np.ones(len(sim.t)))
    assert state.get_ydata()[0] == pytest.approx(0.5) and state.get_ydata()[-1] > 0.99


def _limit_values(ax):
    return sorted({float(ln.get_ydata()[0]) for ln in ax.get_lines() if ln.get_linestyle() == "-."})


def test_the_input_plot_draws_rotor_limits_in_closed_form():
    """X layout, arm ``l`` (``d = l / sqrt2`` per axis), rotor thrust in ``[a, b]``, yaw ``c`` N m per N:
    ``T`` in ``[4 a, 4 b]``, roll and pitch torques within ``+-2 d (b - a)``, yaw within ``+-2 c (b - a)``;
    and a last row of rotor thrusts between ``a`` and ``b``."""
    a, b, arm, c = 0.01, 0.33, 0.0624, 0.00241
    act = actuators_of(Motors(arm_length=arm, min_thrust=a, max_thrust=b, torque_coefficient=c))
    fig = plots.inputs_figure(_sim(), [0.6, 0, 0, 0], actuators=act)
    left = fig.axes[0::2]
    d = arm / math.sqrt(2)
    want = {"T": [4 * a, 4 * b], "A": [-2 * d * (b - a), 2 * d * (b - a)], "E": [-2 * d * (b - a), 2 * d * (b - a)],
            "R": [-2 * c * (b - a), 2 * c * (b - a)]}
    for name, bounds in want.items():
        np.testing.assert_allclose(_limit_values(left[INPUT_INDEX[name]]), bounds, rtol=1e-12)
    assert len(left) == N_INPUTS + 1 and left[-1].get_ylabel() == "rotor thrust [N]"
    np.testing.assert_allclose(_limit_values(left[-1]), [a, b], rtol=1e-12)
    np.testing.assert_allclose(sum(ln.get_ydata()[0] for ln in _lines(left[-1])[:4]), 0.6, rtol=1e-12)  # sum = T


def test_the_input_plot_draws_box_limits_and_none_without_limits():
    act = actuators_of(None, {"T": [0.2, 1.0], "A": [-0.01, 0.01]})
    left = plots.inputs_figure(_sim(), actuators=act).axes[0::2]
    assert _limit_values(left[INPUT_INDEX["T"]]) == [0.2, 1.0]
    assert _limit_values(left[INPUT_INDEX["A"]]) == [-0.01, 0.01]
    assert _limit_values(left[INPUT_INDEX["E"]]) == []  # unlimited: no line
    assert len(left) == N_INPUTS
    assert all(_limit_values(ax) == [] for ax in plots.inputs_figure(_sim()).axes)
