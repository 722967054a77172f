"""Figures read as engineers expect: Bode phase about -180 deg (the closed-form phase of a known
loop, a real loop's phase margin read off the plot), altitude drawn as height (up positive), input
plots with the actuator limits (rotor limits in closed form: ``T`` in ``[4 min, 4 max]``, torques at
full differential thrust)."""

from __future__ import annotations

import math
import os
from types import SimpleNamespace

import numpy as np
import pytest
from _solve import cfg_dict, solve

from quadctl import config, plots
from quadctl.design import margin_findings
from quadctl.layout import INPUT_INDEX, N_INPUTS, N_STATES, STATE_INDEX
from quadctl.physics.motors import Motors, actuators_of


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
    """mambo-200hz's roll loop (sampled, the one docs/guide/flying.md shows): the plotted phase at the gain
    crossover is ``-180 + PM`` (PM from quadctl.design.margin_search, which never reads the plot), within the grid's
    spacing, and the whole curve lies in (-360, 0]."""
    setup, trim, linear, dec, des = solve(cfg_dict("mambo-200hz"))
    roll = next(m for m in margin_findings.all_margins(des, dec, linear.A, linear.B)
                if m.loop == "roll" and m.model == "design")
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



def test_the_nyquist_panel_names_every_curve_and_mark_it_draws():
    """The Nyquist panel's legend names each of its curves and marks: L for positive and negative frequencies,
    the unit circle (it was drawn unnamed, a grey circle a reader had to guess), the disk of the least return
    difference and the critical point -1."""
    setup, trim, linear, dec, des = solve(cfg_dict("mambo-200hz"))
    roll = next(m for m in margin_findings.all_margins(des, dec, linear.A, linear.B)
                if m.loop == "roll" and m.model == "design")
    ax_ny = _drawn(plots.margins_figure(roll)).axes[2]
    assert ax_ny.get_xlabel() == "Re L" and ax_ny.get_ylabel() == "Im L"
    named = [t.get_text() for t in ax_ny.get_legend().get_texts()]
    assert named[:2] == ["L(jw), w > 0", "w < 0"] and "|L| = 1" in named and "-1, the critical point" in named
    assert any(text.startswith("min |1+L| = ") for text in named)
    assert len(named) == len(_lines(ax_ny))  # every line and mark of the panel, none unnamed
    box = ax_ny.get_legend().get_window_extent()  # five entries, placed where no curve runs
    for line in _lines(ax_ny):
        points = line.get_transform().transform(line.get_xydata())
        assert not any(box.contains(x, y) for x, y in points), line.get_label()

def test_the_altitude_plot_shows_height_up():
    sim = _sim()
    fig = plots.subsystem_figure(sim, "altitude", ["pD", "w"])
    ax = fig.axes[0]
    assert ax.get_ylabel() == "height (-pD) [m]"
    state, ref = _lines(ax, "height (-pD)")[0], _lines(ax, "reference")[0]
    np.testing.assert_array_equal(state.get_ydata(), -sim.x[:, STATE_INDEX["pD"]])  # 0.5 m rising to 1 m
    np.testing.assert_array_equal(ref.get_ydata(), np.ones(len(sim.t)))
    assert state.get_ydata()[0] == pytest.approx(0.5) and state.get_ydata()[-1] > 0.99


def test_an_unregulated_subsystems_figure_says_no_feedback_holds_its_reference():
    """forward's guidance (pN, pE; regulate: false): pE drifts off its reference, which no loop holds."""
    sim = _sim()
    fig = plots.simulation_figure_makers(sim, config.load("forward").partition())["guidance"]()
    assert fig.get_suptitle() == "guidance subsystem (not regulated)"
    for ax, state in zip(fig.axes, ("pN", "pE")):
        assert [line.get_label() for line in ax.get_legend().get_lines()] == \
            [f"{state} (not regulated)", "reference (no feedback holds it)"]
    held = plots.subsystem_figure(sim, "altitude", ["pD", "w"])
    assert held.get_suptitle() == "altitude subsystem" and _lines(held.axes[0], "reference")


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


def _drawn(fig):
    """``fig`` laid out and drawn (its artists' window extents in pixels at :data:`plots.DPI`)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig.set_dpi(plots.DPI)
    FigureCanvasAgg(fig).draw()
    return fig


def test_the_input_plot_shows_the_first_sample_and_its_limits_in_both_columns():
    """A one-sample peak at t = 0 (the report's -0.74 N m roll torque): the right-hand column's time axis
    reaches 0 and draws it, each row's two panels share the limits of every sample, and every panel
    names its input with a unit."""
    sim = _sim()
    sim.u[0, INPUT_INDEX["A"]] = -0.74
    act = actuators_of(Motors(min_thrust=0.0, max_thrust=0.33))
    fig = _drawn(plots.inputs_figure(sim, [0.6, 0, 0, 0], actuators=act))
    axes = np.reshape(fig.axes, (-1, 2))
    for (left, right), name in zip(axes, [*INPUT_INDEX, "rotor thrust"]):
        for ax in (left, right):
            assert ax.get_ylabel().startswith(name) and ax.get_ylabel().endswith("]"), ax.get_ylabel()
        assert right.get_ylim() == left.get_ylim()
    left, right = axes[INPUT_INDEX["A"]]
    assert right.get_xscale() == "symlog" and right.get_xlim()[0] <= 0.0
    drawn = _lines(right, "A")[0]
    assert drawn.get_xdata()[0] == 0.0 and drawn.get_ydata().min() == -0.74
    assert left.get_ylim()[0] < -0.74


def _pixels(fig, ax):
    """The RGB pixels inside ``ax`` of ``fig`` drawn at :data:`plots.DPI`."""
    import io

    import matplotlib.image

    fig.set_dpi(plots.DPI)
    png = plots.png_bytes(fig)
    rgb = (matplotlib.image.imread(io.BytesIO(png))[..., :3] * 255).round()
    x0, y0, x1, y1 = np.asarray(ax.get_window_extent().extents).round().astype(int)
    height = rgb.shape[0]
    return rgb[height - y1 + 2:height - y0 - 2, x0 + 2:x1 - 2].reshape(-1, 3)


def test_every_rotor_in_the_legend_shows_when_their_thrusts_are_equal():
    """Hover with no torque: the four rotors' lines coincide, yet each one's colour is seen in the
    rotor panels."""
    from matplotlib.colors import to_rgb

    sim = _sim()
    sim.u[:, 1:] = 0.0
    act = actuators_of(Motors(min_thrust=0.0, max_thrust=0.33))
    fig = plots.inputs_figure(sim, actuators=act)
    for ax in fig.axes[-2:]:
        pixels = _pixels(fig, ax)
        for line in _lines(ax)[:4]:
            colour = np.asarray(to_rgb(line.get_color())) * 255
            assert (np.abs(pixels - colour).max(axis=1) <= 2).sum() > 20, line.get_label()


def test_the_start_ring_clears_a_waypoint_at_the_start_and_the_end_shows_on_top():
    """A square flown back to its start: the last waypoint, the start and the end at one point. The
    start's ring (inside radius) clears the waypoint's square (half diagonal, edge included), and the
    end is drawn over both."""
    n = 40
    sim = _sim(n)
    wps = [np.array([0.0, 1.0, -1.0]), np.array([0.0, 0.0, -1.0])]
    fig = plots.path_figure(sim, wps, reached=[0.5, 0.9], tolerance=0.05)
    plane = fig.axes[0]
    start, end = _lines(plane, "start")[0], _lines(plane, "end")[0]
    square = next(ln for ln in plane.get_lines() if ln.get_marker() == "s")
    inside = start.get_markersize() / 2 - start.get_markeredgewidth() / 2
    corner = square.get_markersize() / 2 * math.sqrt(2) + square.get_markeredgewidth() / 2
    assert inside > corner, (inside, corner)
    assert end.get_zorder() > max(square.get_zorder(), start.get_zorder())
    assert end.get_markerfacecolor() != square.get_markerfacecolor()


def _identification():
    t = np.linspace(0.0, 10.0, 500)
    fit = lambda rows, scale: SimpleNamespace(  # noqa: E731
        t=t, rows=rows, measured=scale * np.sin(np.outer(t, np.arange(1, len(rows) + 1))),
        predicted=scale * 0.9 * np.sin(np.outer(t, np.arange(1, len(rows) + 1))),
        residual=scale * 0.1 * np.sin(np.outer(t, np.arange(1, len(rows) + 1))))
    return SimpleNamespace(fits={"thrust": fit(("thrust (N)",), 0.3),
                                 "attitude": fit(("roll torque (N m)", "pitch torque (N m)"), 0.002)},
                           logs=[SimpleNamespace(name="log10"), SimpleNamespace(name="log15")],
                           stage_logs={"thrust": 0, "attitude": 1})


def test_the_identification_figure_names_its_logs_units_and_hides_no_data():
    """Each row's titles name the log its stage was fitted on and the quantity (the roll or pitch torque's
    residual apart); both axes carry the unit of their quantity, in brackets as every figure's axes do (the titles
    keep the row's "(N)"); the measurement is drawn over the model and thinner, so both show; the legend lies
    outside every panel."""
    from quadctl.plots.identify import identification_figure

    fig = _drawn(identification_figure(_identification()))
    rows = np.reshape(fig.axes, (-1, 2))
    named = ("thrust", "roll torque", "pitch torque")
    for (left, right), log, quantity, unit in zip(rows, ("log10", "log15", "log15"), named, ("[N]", "[N m]", "[N m]")):
        assert left.get_title().startswith(log) and right.get_title().startswith(log)
        assert f": {quantity} (" in left.get_title() and f": {quantity} residual, RMS" in " ".join(
            right.get_title().split())
        assert right.get_ylabel().endswith(unit) and left.get_ylabel().endswith(unit)
        measured, model = _lines(left, "measured")[0], _lines(left, "model")[0]
        assert measured.get_zorder() > model.get_zorder() and measured.get_linewidth() < model.get_linewidth()
    assert all(ax.get_legend() is None for ax in fig.axes) and len(fig.legends) == 1
    box = fig.legends[0].get_window_extent()
    assert not any(box.overlaps(ax.get_window_extent()) for ax in fig.axes)


@pytest.mark.parametrize("name", ["sample_px4_events.ulg", "log_49_2024-5-12-13-40-22_hover_and_roll_steps.ulg"])
def test_the_identification_figure_keeps_each_title_of_a_long_log_name_within_its_panel(name):
    """A ULog's name is long: each title still names it and stays within its panel (broken into lines
    at its commas), so none runs off the figure or into the next panel."""
    from quadctl.plots.identify import identification_figure

    ident = _identification()
    ident.logs[0].name = name
    fig = _drawn(identification_figure(ident))
    page = fig.bbox
    for ax in fig.axes:
        title, panel = ax.title.get_window_extent(), ax.get_window_extent()
        assert panel.x0 - 1 <= title.x0 and title.x1 <= panel.x1 + 1, (ax.get_title(), title, panel)
        assert page.x0 <= title.x0 and title.x1 <= page.x1 and title.y1 <= page.y1
    assert "".join(fig.axes[1].get_title().split()).startswith(name)  # named whole, whatever its lines


def test_the_position_error_figure_says_when_the_lqr_leaves_the_horizontal_position_free():
    """The note quadctl compare prints (present/compare.py) is written on the position-error figure."""
    from quadctl.plots.compare import comparison_figures
    from quadctl.present.compare import free_position_sentence

    note = free_position_sentence(("pD", "phi", "theta", "psi"), ["lqr", "pid:crazyflie"])
    assert note and free_position_sentence(("pN", "pE", "pD"), ["lqr", "pid:crazyflie"]) is None
    act = actuators_of(Motors(min_thrust=0.0, max_thrust=0.33))
    law = SimpleNamespace(name="lqr", run=_sim(), loop=SimpleNamespace(actuators=act), metrics={"rotor_peak": 0.5})
    figs = comparison_figures([law], notes={"position-error": note})
    assert " ".join(figs["position-error"].axes[0].get_title(loc="left").split()) == note
    assert all(fig.axes[0].get_title(loc="left") == "" for stem, fig in figs.items() if stem != "position-error")


@pytest.mark.parametrize("peak, unit, size, scale", [(3.4e-7, "nm", 1e-9, " = 10⁻⁹ m"),
                                                     (2.5e-5, "µm", 1e-6, " = 10⁻⁶ m"),
                                                     (0.4, "mm", 1e-3, " = 10⁻³ m"), (2.0, "m", 1.0, "")])
def test_the_tracking_error_reads_in_a_unit_of_its_size_with_no_multiplier_above_the_axis(peak, unit, size, scale):
    """A flatness-fed mission tracks to a fraction of a micrometre (`square`: 340 nm): the axis says nm and
    its ticks read the values, where matplotlib would write 1e-7 above the axis; a unit below the metre
    says its size (an "nm" beside the inputs' "N m" reads as a torque)."""
    sim = _sim()
    sim.x_ref = sim.x.copy()
    sim.x[:, STATE_INDEX["pN"]] += peak * np.sin(np.pi * sim.t)  # the error, peak at t = 0.5 s
    fig = _drawn(plots.tracking_error_figure(sim))
    ax = fig.axes[0]
    assert ax.get_ylabel() == f"position error [{unit}{scale}]"
    assert ax.yaxis.get_offset_text().get_text() == ""
    north = _lines(ax, "pN - reference")[0]
    assert north.get_ydata().max() == pytest.approx(peak / size, rel=1e-3)
    assert 1 <= north.get_ydata().max() < 1000


def test_a_law_whose_run_stopped_early_ends_with_a_cross_in_every_comparison_figure():
    """A law whose run left the valid range (a vehicle past 85 deg of pitch): its line ends there with a cross
    at its last value, and its legend entry says why and when; a completed run has none."""
    from quadctl.plots.compare import QUANTITIES, comparison_figures

    act = actuators_of(Motors(min_thrust=0.0, max_thrust=0.33))
    stopped = _sim(30)
    stopped.status = "left_valid_range"
    laws = [SimpleNamespace(name=name, run=run, loop=SimpleNamespace(actuators=act), metrics={"rotor_peak": 0.5})
            for name, run in (("lqr", _sim()), ("pid:px4", stopped))]
    figs = comparison_figures(laws)
    assert sorted(figs) == ["altitude", "attitude-error", "position-error", "rotor-use"]
    for stem, fig in figs.items():
        ax = fig.axes[0]
        crosses = [ln for ln in ax.get_lines() if ln.get_marker() == "x"]
        assert len(crosses) == 1, stem
        curve = _lines(ax, f"pid:px4, left the valid range at {stopped.t[-1]:.3g} s")[0]
        assert crosses[0].get_color() == curve.get_color()
        assert (crosses[0].get_xdata()[0], crosses[0].get_ydata()[0]) == (curve.get_xdata()[-1], curve.get_ydata()[-1])
        assert _lines(ax, "lqr") and ax.get_ylabel() == dict(QUANTITIES)[stem]


def _columns_of(x, columns, log=False):
    """Column of each sample, computed on its own: equal widths across x[0]..x[-1] (in log10 x with log)."""
    pos = np.log10(x) if log else np.asarray(x)
    edges = np.linspace(pos[0], pos[-1], columns + 1)
    return np.clip(np.searchsorted(edges, pos, side="right") - 1, 0, columns - 1)


@pytest.mark.parametrize("log", [False, True])
def test_the_pixel_envelope_keeps_every_columns_lowest_and_highest_sample(log):
    rng = np.random.default_rng(7)
    n, columns = 20_000, 300
    t = np.logspace(-5, 1, n) if log else np.linspace(0.0, 10.0, n)
    y = np.cumsum(rng.normal(size=n)) + np.where(rng.random(n) < 0.002, 50.0 * rng.normal(size=n), 0.0)  # spikes
    y[5000:5400] = 1.0  # a flat stretch: ties
    tk, yk = plots.pixel_envelope(t, y, columns, log=log)
    assert len(tk) <= 4 * columns and len(tk) < n
    kept = np.flatnonzero(np.isin(t, tk))
    assert len(kept) == len(tk)
    np.testing.assert_array_equal(t[kept], tk)  # samples of the series, in order
    np.testing.assert_array_equal(y[kept], yk)
    col, col_kept = _columns_of(t, columns, log), _columns_of(tk, columns, log)
    for c in np.unique(col):
        mine, theirs = y[col == c], yk[col_kept == c]
        assert theirs.min() == mine.min() and theirs.max() == mine.max(), c
        assert theirs[0] == mine[0] and theirs[-1] == mine[-1], c  # enters and leaves the column where the series does
    assert (tk[0], tk[-1], yk.min(), yk.max()) == (t[0], t[-1], y.min(), y.max())


def test_the_pixel_envelope_leaves_short_or_non_finite_series_whole():
    t = np.linspace(0.0, 1.0, 1000)
    y = np.sin(t)
    for series in (y[:400], np.where(t > 0.5, np.nan, y)):
        tk, yk = plots.pixel_envelope(t[: len(series)], series, 100)
        assert len(tk) == len(series)
        np.testing.assert_array_equal(yk, series)


def _content(fig):
    """What a reader sees of a figure, drawn: per axes its lines (label, style, color, data range), labels,
    scales, limits and legend (texts and place)."""
    plots.png_bytes(fig, plots.DPI)
    out = []
    for ax in fig.axes:
        legend = ax.get_legend()
        lines = [(ln.get_label(), ln.get_linestyle(), ln.get_color(), ln.get_linewidth(),
                  *np.round([np.nanmin(ln.get_xdata()), np.nanmax(ln.get_xdata()),
                             np.nanmin(ln.get_ydata()), np.nanmax(ln.get_ydata())], 12)) for ln in ax.get_lines()]
        out.append((lines, ax.get_xlabel(), ax.get_ylabel(), ax.get_xscale(), ax.get_xlim(), ax.get_ylim(),
                    [tick.get_text() for tick in ax.get_yticklabels()],
                    None if legend is None else ([t.get_text() for t in legend.get_texts()],
                                                 tuple(np.round(legend.get_window_extent().bounds, 6)))))
    return [fig.get_suptitle(), *out]


def _noisy_flight(n=20_000):
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 10.0, n)
    x = np.cumsum(rng.normal(scale=0.01, size=(n, N_STATES)), axis=0)
    x[n // 3, :] += 0.5  # a one-sample spike in every state
    return SimpleNamespace(t=t, x=x, x_ref=0.2 * x, u=0.6 + np.cumsum(rng.normal(scale=1e-3, size=(n, 4)), axis=0),
                           wind=np.cumsum(rng.normal(scale=0.02, size=(n, 3)), axis=0), u_ref=np.zeros((n, 4)),
                           status="ok")


@pytest.fixture(scope="module")
def forward_flight(tmp_path_factory):
    from quadctl import config
    from quadctl.workspace import Workspace

    with Workspace(config.load("forward"), tmp_path_factory.mktemp("forward")) as ws:
        return ws.simulation.sim, ws.setup, ws.linear.u_trim


@pytest.mark.parametrize("case", [pytest.param("forward", marks=pytest.mark.slow), "noisy"])
def test_the_figures_of_thinned_lines_show_what_those_of_every_sample_show(case, forward_flight, monkeypatch):
    """Every figure drawn from pixel envelopes has the lines, labels, limits, ticks and legends (texts and
    place) of the same figure drawn from every sample."""
    if case == "forward":
        sim, setup, u_trim = forward_flight
        partition, actuators = setup.partition, setup.actuators
        assert len(sim.t) > 4 * 1100  # long enough to be thinned
    else:
        sim, u_trim = _noisy_flight(8000), [0.6, 0.0, 0.0, 0.0]  # 7 samples a pixel column
        partition = {"altitude": SimpleNamespace(states=["pD", "w"])}
        actuators = actuators_of(Motors(min_thrust=0.0, max_thrust=0.33))
    thinned = plots.simulation_figures(sim, partition, u_trim, actuators=actuators)
    assert sum(len(ln.get_xdata()) for f in thinned.values() for ax in f.axes for ln in ax.get_lines()) < \
        0.5 * sum(len(sim.t) for f in thinned.values() for ax in f.axes for ln in ax.get_lines())
    monkeypatch.setattr(plots.drawing, "pixel_envelope",  # what the figures draw through
                        lambda x, y, columns, log=False: (np.asarray(x), np.asarray(y)))
    whole = plots.simulation_figures(sim, partition, u_trim, actuators=actuators)
    assert thinned.keys() == whole.keys()
    for name in whole:
        assert _content(thinned[name]) == _content(whole[name]), name
        for ax, ax_whole in zip(thinned[name].axes, whole[name].axes):
            width = ax.get_window_extent().width  # pixels at DPI: at least a column each
            for line, line_whole in zip(ax.get_lines(), ax_whole.get_lines()):
                assert len(line.get_xdata()) >= min(len(line_whole.get_xdata()), width), name


def _figure_files(folder):
    return {p.name: p.read_bytes() for p in sorted((folder / "plots").glob("*.png"))}


def test_the_cli_draws_the_same_figures_on_two_cores_and_redraws_what_a_failed_child_did_not(tmp_path, monkeypatch):
    """`run --plot` shares the figures out to a child process: the same files as drawn in one process,
    and all of them (drawn by the parent) when the child fails."""
    from quadctl.cli import figures

    if not hasattr(os, "fork"):
        pytest.skip("no os.fork here: figures are drawn in one process")
    sim = SimpleNamespace(**{**vars(_noisy_flight(3000)), "wind": (), "u_ref": ()})
    setup = SimpleNamespace(partition={"altitude": SimpleNamespace(states=["pD", "w"]),
                                       "roll": SimpleNamespace(states=["phi", "p"])},
                            actuators=None, name="noisy")

    def saved(name, can_fork):
        monkeypatch.setattr(figures, "_can_fork", lambda: can_fork)
        ws = SimpleNamespace(setup=setup, linear=SimpleNamespace(u_trim=[0.6, 0.0, 0.0, 0.0]), out=tmp_path / name,
                             remember=lambda *paths: None,  # (a workspace's record for its roll-back)
                             record_written=lambda *paths: None, stamp=lambda png: png)
        paths = figures.save_figures(ws, sim)
        assert [p.name for p in paths] == ["altitude.png", "roll.png", "inputs.png"]
        return _figure_files(tmp_path / name)

    one = saved("one", False)
    assert figures._share(plots.simulation_figure_makers(sim, setup.partition), SimpleNamespace(setup=setup))
    assert saved("two", True) == one
    parent, png = os.getpid(), plots.png_bytes

    def fails_in_the_child(fig, dpi=plots.DPI):
        if os.getpid() != parent:
            raise RuntimeError("the child fails")
        return png(fig, dpi)

    monkeypatch.setattr(plots, "png_bytes", fails_in_the_child)
    assert saved("failed", True) == one


def test_the_sweep_trade_off_draws_a_missions_errors_on_a_log_scale_and_no_empty_legend_entry():
    """Tracking errors of 2e-8 to 3e-6 m under a 1e-3 m gate: a log scale shows them apart (a linear one puts
    all three on its floor); a sweep where nothing fails has no 'fail (0)'; a settling time stays linear."""
    from quadctl.sweep.gates import Gate

    rows = [{"peak.T": t, "tracking.peak": e, "settling_time.pD": 1.0 + e, "pass": True}
            for t, e in ((0.68, 1.9e-8), (0.69, 3.4e-7), (0.80, 2.7e-6))]
    fig = plots.sweep_tradeoff_figure(rows, "peak.T", "tracking.peak", (Gate("tracking.peak", max=1e-3),))
    (ax,) = fig.axes
    assert ax.get_yscale() == "log" and ax.get_ylabel() == "tracking.peak [m]"
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["pass (3)", "gate"]
    (ax,) = plots.sweep_tradeoff_figure(rows, "peak.T", "settling_time.pD").axes
    assert ax.get_yscale() == "linear"
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "No artists with labels" from an empty legend
        (ax,) = plots.sweep_tradeoff_figure([{"pass": False}], "peak.T", "settling_time.pD").axes
    assert ax.get_legend() is None


def test_the_sweep_trade_off_labels_a_margin_axis_with_its_unit():
    """A sweep gated on its margins plots one: its axis reads dB or deg, as the sweep.json units do."""
    from quadctl.sweep.gates import Gate

    rows = [{"peak.T": 0.95, "margin.gain_db": 17.7, "margin.phase_deg": 42.5, "pass": True},
            {"peak.T": 0.96, "margin.gain_db": None, "margin.phase_deg": None, "pass": False}]
    (ax,) = plots.sweep_tradeoff_figure(rows, "peak.T", "margin.gain_db", (Gate("margin.gain_db", min=6),)).axes
    assert ax.get_ylabel() == "margin.gain_db [dB]"
    (ax,) = plots.sweep_tradeoff_figure(rows, "peak.T", "margin.phase_deg").axes
    assert ax.get_ylabel() == "margin.phase_deg [deg]"


def test_the_sweep_trade_off_counts_the_places_stacked_cases_draw_at():
    """A parameter that moves neither metric stacks its cases on one point (examples/ci-sweep.yaml's
    roll weight: 27 cases at 9 places): the legend says so; cases apart by more than a marker are counted
    each, as on a log scale."""
    rows = [{"peak.T": 3.0 + t, "settling_time.pD": 0.5 + 0.01 * t + 1e-6 * k, "pass": True}
            for t in range(3) for k in range(3)]
    (ax,) = plots.sweep_tradeoff_figure(rows, "peak.T", "settling_time.pD").axes
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["pass (9 at 3 places)"]
    rows[0]["pass"] = False
    (ax,) = plots.sweep_tradeoff_figure(rows, "peak.T", "settling_time.pD").axes
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["pass (8 at 3 places)", "fail (1)"]
    apart = [{"peak.T": 3.0 + 0.1 * k, "tracking.peak": 10.0 ** -k, "pass": True} for k in range(1, 8)]
    (ax,) = plots.sweep_tradeoff_figure(apart, "peak.T", "tracking.peak").axes
    assert ax.get_yscale() == "log" and [t.get_text() for t in ax.get_legend().get_texts()] == ["pass (7)"]


def test_the_sweep_trade_off_says_one_place_in_the_singular():
    """Cases stacked on one point (a mission's tolerance moves neither metric) read 'at 1 place', not
    'at 1 places'."""
    rows = [{"peak.T": 0.68, "tracking.rms": 8.9e-9, "pass": True}] * 2
    (ax,) = plots.sweep_tradeoff_figure(rows, "peak.T", "tracking.rms").axes
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["pass (2 at 1 place)"]


def test_the_sweep_trade_off_draws_cases_with_no_settling_time_on_a_strip_by_reason():
    """A noisy uncertainty study where most cases have no settling time (examples/uncertainty-sweep.yaml:
    62 of 64 noise-limited) still shows every case: those with a peak but no settling time sit on a strip
    above the plot at their peak, a row for each reason, and the legend counts them by pass and reason."""
    from quadctl.plots.sweep import UNSETTLED

    rows = [{"peak.T": 0.95, "settling_time.pD": 2.6, "pass": True, "status": "ok", "noise_limited": []},
            *({"peak.T": 0.94 + 0.001 * k, "settling_time.pD": None, "pass": True, "status": "ok",
               "noise_limited": ["pD", "u"]} for k in range(5)),
            {"peak.T": 0.96, "settling_time.pD": None, "pass": False, "status": "ok", "noise_limited": ["u"]},
            {"peak.T": 0.97, "settling_time.pD": None, "pass": False, "status": "diverged", "noise_limited": []},
            {"settling_time.pD": 1.0, "pass": True}]  # no peak: counted in the title only
    fig = plots.sweep_tradeoff_figure(rows, "peak.T", "settling_time.pD")
    top, ax = fig.axes
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [
        "pass (1)", "pass, noise-limited (5)", "fail, never settled (1)", "fail, run stopped (1)"]
    rows_drawn = {tuple(c.get_offsets()[:, 1]): sorted(c.get_offsets()[:, 0]) for c in top.collections}
    order = list(UNSETTLED)
    assert rows_drawn[(order.index("noise-limited"),) * 5] == pytest.approx([0.94, 0.941, 0.942, 0.943, 0.944])
    assert rows_drawn[(order.index("never settled"),)] == [0.96]
    assert rows_drawn[(order.index("run stopped"),)] == [0.97]
    assert ax.get_xlim() == top.get_xlim() and ax.get_xlim()[0] < 0.94 and ax.get_xlim()[1] > 0.97
    assert fig._suptitle.get_text() == "sweep trade-off (9 cases; 1 case without both values)"


@pytest.mark.parametrize("groups", [{"roll": ["v", "phi", "p"]},
                                    {"altitude": ["pD", "w"], "roll": ["v", "phi", "p"]}], ids=["one row", "two rows"])
def test_the_monte_carlo_figures_axis_labels_name_a_unit_and_stay_beside_their_own_panel(groups):
    """Each panel's y label names its unit and fits the panel's height: the short panels of the bands about
    the median (a third of a row) once carried a one-line label taller than themselves, which ran into the
    tick labels of the panel above (docs/figures/uncertainty-bands.png: 'about median [deg/s]' over '-60')."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from quadctl.sweep.outputs import MC_PERCENTILES, MonteCarloBands

    t = np.linspace(0.0, 3.0, 300)
    states = ("pD", "w", "v", "phi", "p")
    start = np.exp(-t)[:, None] * np.array([0.5, -0.6, 0.1, 0.1, -1.0])
    wobble = 0.01 * np.sin(5 * t)[:, None]
    levels = np.stack([start + q * wobble for q in (-2, -1, 0, 1, 2)])
    bands = MonteCarloBands(t=t, percentiles=MC_PERCENTILES, bands=levels, states=states, cases=np.arange(64),
                            traces=np.zeros((64, len(t), len(states)), np.float32))
    fig = plots.montecarlo_figure(bands, groups, title="mc", varied=("simulation.plant.mass",))
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)  # the constrained layout places the panels
    labelled = [ax for ax in fig.axes if ax.get_visible()]
    assert len(labelled) == 2 * sum(len(s) for s in groups.values())
    for ax in labelled:
        label, panel = ax.yaxis.label.get_window_extent(renderer), ax.get_window_extent(renderer)
        assert ax.get_ylabel().rstrip().endswith("]"), ax.get_ylabel()
        assert panel.y0 <= label.y0 and label.y1 <= panel.y1, (ax.get_ylabel(), label, panel)
