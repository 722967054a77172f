"""Figures of a simulation, like the report's figures 2-4, as matplotlib Figures.

The caller saves them. Angles and rates are shown in degrees (artifacts keep radians), and ``pD``
as the height ``-pD`` (up positive; artifacts keep NED). Bode phase is drawn in (-360, 0] deg at
the gain crossover, where the -180 deg line and the phase margin are read.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from functools import partial

import numpy as np
from matplotlib.figure import Figure

from quadctl.layout import INPUT_NAMES, STATE_INDEX, unit_of

_DEGREES = {"phi", "theta", "psi", "p", "q", "r"}
_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd")


_HEIGHT = "pD"
"""Drawn as the height ``-pD`` (m, up positive): NED's down-positive altitude reads upside down."""


DPI = 110
"""The resolution (dots per inch) figures are drawn for: their time series keep every pixel column's
extremes (:func:`pixel_envelope`) at this or any lower resolution. ``quadctl`` saves at it or below."""


def pixel_envelope(x, y, columns: int, *, log: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The samples of a time series a line drawn ``columns`` pixels wide shows: per column of equal
    width in ``x`` (in ``log10(x)`` with ``log``), its first, lowest, highest and last sample, in order.

    A line through them covers, in every column, the same vertical extent as the line through
    all samples and enters and leaves it at the same points: peaks and spikes one sample wide
    survive, and the data limits (first and last ``x``, lowest and highest ``y``) stay the same.
    A series of at most ``4 columns`` samples, with a non-finite value, or whose ``x`` is not
    increasing (or, with ``log``, not positive) is returned whole.

    Parameters
    ----------
    x : (n,) array_like
        Increasing, such as time (s).
    y : (n,) array_like
    columns : int
        Columns across ``x[0]..x[-1]``: at least the drawn width in pixels.
    log : bool
        Columns of equal width in ``log10(x)`` (a log-scaled axis).

    Returns
    -------
    x, y : (k,) ndarray
        The kept samples, ``k <= 4 columns``.

    Examples
    --------
    >>> t = np.arange(1000.0)
    >>> y = np.zeros(1000); y[123] = 5.0
    >>> tk, yk = pixel_envelope(t, y, 10)
    >>> len(tk), float(yk.max()), float(tk[yk.argmax()])  # a flat column keeps 2 samples, the spike's 3
    (21, 5.0, 123.0)
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    n = len(x)
    if n <= 4 * columns or not (np.isfinite(x).all() and np.isfinite(y).all()):
        return x, y
    if log and x[0] <= 0:
        return x, y
    pos = np.log10(x) if log else x
    span = pos[-1] - pos[0]
    if not span > 0 or (np.diff(pos) < 0).any():
        return x, y
    column = np.minimum(((pos - pos[0]) * (columns / span)).astype(np.intp), columns - 1)
    first = np.flatnonzero(np.r_[True, column[1:] != column[:-1]])
    last = np.r_[first[1:], n] - 1
    size = last - first + 1
    keep = np.zeros(n, dtype=bool)
    keep[first] = keep[last] = True
    for extreme in (np.minimum, np.maximum):
        hit = np.flatnonzero(y == np.repeat(extreme.reduceat(y, first), size))
        keep[hit[np.r_[True, column[hit][1:] != column[hit][:-1]]]] = True  # the first hit of each column
    return x[keep], y[keep]


def _trace(ax, x, y, *args, log: bool = False, **kwargs):
    """``ax.plot(x, y, ...)`` of a time series, thinned to the figure's pixel columns at :data:`DPI`
    (:func:`pixel_envelope`)."""
    columns = int(np.ceil(ax.get_figure(root=True).get_figwidth() * DPI))
    return ax.plot(*pixel_envelope(x, y, columns, log=log), *args, **kwargs)


def png_bytes(fig: Figure, dpi: float = DPI) -> bytes:
    """``fig`` as PNG bytes at ``dpi``: the pixels ``fig.savefig(buf, format="png", dpi=dpi)`` writes,
    drawn once.

    ``savefig`` draws a figure with a layout engine twice (once to lay it out, once to render);
    here one draw does both, then the RGBA buffer is encoded as ``savefig`` encodes it. As with
    ``savefig``, the figure keeps its own resolution and canvas afterwards.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.image import imsave

    canvas, resolution = fig.canvas, fig.dpi
    try:
        fig.set_dpi(dpi)
        drawn = FigureCanvasAgg(fig)
        drawn.draw()
        buf = io.BytesIO()
        imsave(buf, drawn.buffer_rgba(), format="png", origin="upper", dpi=dpi)
    finally:
        fig.set_dpi(resolution)
        fig.set_canvas(canvas)
    return buf.getvalue()


def _display(name: str, values: np.ndarray) -> tuple[np.ndarray, str]:
    """``values`` of state ``name`` as plotted, and their unit (degrees for angles, height for pD)."""
    if name in _DEGREES:
        unit = unit_of(name).replace("rad", "deg")
        return np.rad2deg(values), unit
    if name == _HEIGHT:
        return -np.asarray(values), unit_of(name)
    return values, unit_of(name)


def _label(name: str) -> str:
    """The axis label of state ``name`` as :func:`_display` shows it."""
    return "height (-pD)" if name == _HEIGHT else name


def phase_about_minus_180(response, anchor: int | None = None) -> np.ndarray:
    """The phase (deg) of a frequency response, unwrapped and shifted by whole turns so that it
    lies in (-360, 0] at sample ``anchor`` (the gain crossover), or, without one, so that the middle
    of its range does: the -180 deg line a phase margin is read from then runs through the plot.

    Parameters
    ----------
    response : (n,) complex array_like
    anchor : int, optional
        Index of the frequency whose phase is placed in (-360, 0].

    Examples
    --------
    >>> phase_about_minus_180(np.exp(1j * np.deg2rad([140.0, 200.0, 260.0]))).round(6).tolist()
    [-220.0, -160.0, -100.0]
    """
    phase = np.rad2deg(np.unwrap(np.angle(np.asarray(response, dtype=complex))))
    if not phase.size:
        return phase
    at = phase[anchor] if anchor is not None else (phase.min() + phase.max()) / 2
    return phase - 360.0 * np.ceil(at / 360.0)


def subsystem_figure(sim, name: str, states, *, title: str = "") -> Figure:
    """One panel per state of a subsystem: the state and its reference against time.

    Parameters
    ----------
    sim : SimResult
    name : str
        Subsystem name (figure title).
    states : sequence of str
    """
    fig = Figure(figsize=(7.5, 1.9 * len(states) + 0.8), layout="constrained")
    axes = fig.subplots(len(states), 1, sharex=True, squeeze=False)[:, 0]
    for ax, state, color in zip(axes, states, _COLORS * 3):
        i = STATE_INDEX[state]
        y, unit = _display(state, sim.x[:, i])
        ref, _ = _display(state, sim.x_ref[:, i])
        _trace(ax, sim.t, y, color=color, lw=1.6, label=_label(state))
        _trace(ax, sim.t, ref, color="0.35", lw=1.0, ls="--", label="reference")
        ax.set_ylabel(f"{_label(state)} [{unit}]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8, frameon=False)
    axes[-1].set_xlabel("time [s]")
    status = "" if sim.status == "ok" else f" ({sim.status})"
    fig.suptitle(f"{title}: {name} subsystem{status}" if title else f"{name} subsystem{status}")
    return fig


def input_limits(actuators) -> tuple[np.ndarray, np.ndarray]:
    """(4,) lowest and (4,) highest value each of ``T, A, E, R`` can take within the actuator limits
    (N, N m; infinite where unlimited). Box limits are themselves; rotor limits bound each input over
    every rotor thrust in ``[min_thrust, max_thrust]`` (the others free): ``T`` in ``[4 min, 4 max]``,
    a torque at the rotors' full differential thrust.

    Examples
    --------
    >>> from quadctl.motors import Motors, actuators_of
    >>> lo, hi = input_limits(actuators_of(Motors(min_thrust=0.0, max_thrust=0.33)))
    >>> lo[0].round(6).tolist(), hi[0].round(6).tolist()
    (0.0, 1.32)
    """
    lo, hi = np.asarray(actuators.lo, dtype=float), np.asarray(actuators.hi, dtype=float)
    if actuators.mode == "box":
        return lo.copy(), hi.copy()
    eff = np.asarray(actuators.mix_inv, dtype=float)  # actuator commands -> [T, A, E, R]
    with np.errstate(invalid="ignore"):  # 0 * inf of an unlimited rotor: that rotor adds nothing
        at_lo, at_hi = np.nan_to_num(eff * lo, nan=0.0), np.nan_to_num(eff * hi, nan=0.0)
    return np.minimum(at_lo, at_hi).sum(axis=1), np.maximum(at_lo, at_hi).sum(axis=1)


def inputs_figure(sim, u_trim=None, *, title: str = "", actuators=None) -> Figure:
    """The four inputs T, A, E, R against time, with their trim values dashed and, given
    ``actuators``, their limits (:func:`input_limits`) as red lines.

    Left: linear time. Right: the same on a log time axis, where the fast transients of the
    rate loops (milliseconds or less) are visible. With rotors (``actuators.mode == "motors"``) a
    last row shows each rotor's thrust (what the applied inputs ask of it) between its
    ``min_thrust`` and ``max_thrust``, where a saturation shows.

    Parameters
    ----------
    sim : SimResult
    u_trim : (4,) array_like, optional
        N, N m.
    actuators : quadctl.motors.Actuators, optional
        The simulated vehicle's limits (``setup.actuators``); None: no limit lines.
    """
    rotors = actuators is not None and actuators.mode == "motors"
    rows = len(INPUT_NAMES) + (1 if rotors else 0)
    fig = Figure(figsize=(10.0, 7.0 * rows / len(INPUT_NAMES)), layout="constrained")
    axes = fig.subplots(rows, 2, sharex="col")
    later = sim.t > 0
    lo, hi = input_limits(actuators) if actuators is not None else (np.full(4, -np.inf), np.full(4, np.inf))
    for j, (row, name, color) in enumerate(zip(axes, INPUT_NAMES, _COLORS)):
        for ax, t, u, log in ((row[0], sim.t, sim.u[:, j], False), (row[1], sim.t[later], sim.u[later, j], True)):
            _trace(ax, t, u, color=color, lw=1.6, label=name, log=log)
            if u_trim is not None:
                ax.axhline(u_trim[j], color="0.35", lw=1.0, ls="--", label="trim")
            _limit_lines(ax, (lo[j], hi[j]), "rotor limits" if rotors else "limit")
            ax.grid(True, alpha=0.3)
        row[0].set_ylabel(f"{name} [{unit_of(name)}]")
        row[0].legend(loc="best", fontsize=8, frameon=False)
        row[1].set_xscale("log")
    if rotors:
        thrust = actuators.commands(sim.u)
        for ax, keep, log in ((axes[-1, 0], slice(None), False), (axes[-1, 1], later, True)):
            for i, (rotor, color) in enumerate(zip(actuators.names, _COLORS)):
                _trace(ax, sim.t[keep], thrust[keep, i], color=color, lw=1.2, label=rotor, log=log)
            _limit_lines(ax, (actuators.lo[0], actuators.hi[0]), "min / max thrust")
            ax.grid(True, alpha=0.3)
        axes[-1, 0].set_ylabel("rotor thrust [N]")
        axes[-1, 0].legend(loc="best", fontsize=7, frameon=False, ncols=3)
        axes[-1, 1].set_xscale("log")
    axes[-1, 0].set_xlabel("time [s]")
    axes[-1, 1].set_xlabel("time [s], log scale")
    fig.suptitle(f"{title}: inputs" if title else "inputs")
    return fig


def _limit_lines(ax, bounds, label: str) -> None:
    """Red lines at the finite ``bounds`` (low, high), labelled once."""
    finite = [b for b in bounds if np.isfinite(b)]
    for k, bound in enumerate(finite):
        ax.axhline(bound, color=_COLORS[1], lw=1.0, ls="-.", alpha=0.8, label=label if k == 0 else None)


def wind_figure(sim, *, title: str = "") -> Figure:
    """The wind the plant felt (N, E, D components, m/s) against time."""
    fig = Figure(figsize=(10.0, 3.5), layout="constrained")
    ax = fig.subplots()
    for i, (name, color) in enumerate(zip(("wind N", "wind E", "wind D"), _COLORS)):
        _trace(ax, sim.t, sim.wind[:, i], color=color, lw=1.2, label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("wind [m/s], NED")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8, frameon=False)
    fig.suptitle(f"{title}: wind" if title else "wind")
    return fig


def path_figure(sim, waypoints=(), *, title: str = "") -> Figure:
    """The flown path against the reference: the horizontal plane (east right, north up, equal
    scales) with the waypoints, and the altitude ``-pD`` against time.

    Parameters
    ----------
    sim : SimResult
    waypoints : sequence of (3,) array_like, optional
        NED positions (m) to mark, numbered in order.
    """
    fig = Figure(figsize=(10.0, 4.6), layout="constrained")
    plane, alt = fig.subplots(1, 2, width_ratios=(1.0, 1.3))
    n, e, d = (STATE_INDEX[s] for s in ("pN", "pE", "pD"))
    plane.plot(sim.x_ref[:, e], sim.x_ref[:, n], color="0.35", lw=1.0, ls="--", label="reference")
    plane.plot(sim.x[:, e], sim.x[:, n], color=_COLORS[0], lw=1.6, label="flown")
    plane.plot(sim.x[0, e], sim.x[0, n], "o", color=_COLORS[2], ms=6, label="start")
    for k, wp in enumerate(waypoints):
        plane.plot(wp[1], wp[0], "s", color=_COLORS[1], ms=6, label="waypoint" if k == 0 else None)
        plane.annotate(str(k + 1), (wp[1], wp[0]), textcoords="offset points", xytext=(6, 6), fontsize=9)
    plane.set_aspect("equal", adjustable="datalim")
    plane.set_xlabel("east [m]")
    plane.set_ylabel("north [m]")
    plane.grid(True, alpha=0.3)
    plane.legend(loc="best", fontsize=8, frameon=False)
    _trace(alt, sim.t, -sim.x_ref[:, d], color="0.35", lw=1.0, ls="--", label="reference")
    _trace(alt, sim.t, -sim.x[:, d], color=_COLORS[0], lw=1.6, label="flown")
    alt.ticklabel_format(axis="y", useOffset=False)
    low, high = alt.get_ylim()
    middle = (low + high) / 2
    alt.set_ylim(min(low, middle - 0.25), max(high, middle + 0.25))  # a flat path shows flat, not its round-off
    alt.set_xlabel("time [s]")
    alt.set_ylabel("altitude -pD [m]")
    alt.grid(True, alpha=0.3)
    alt.legend(loc="best", fontsize=8, frameon=False)
    status = "" if sim.status == "ok" else f" ({sim.status})"
    fig.suptitle(f"{title}: path{status}" if title else f"path{status}")
    return fig


def tracking_error_figure(sim, *, title: str = "") -> Figure:
    """The position tracking error against time: north, east and down, and its norm ``|p - p_ref|``."""
    fig = Figure(figsize=(10.0, 3.8), layout="constrained")
    ax = fig.subplots()
    err = sim.x[:, :3] - sim.x_ref[:, :3]
    for i, (name, color) in enumerate(zip(("pN", "pE", "pD"), _COLORS)):
        _trace(ax, sim.t, err[:, i], color=color, lw=1.2, label=f"{name} - reference")
    _trace(ax, sim.t, np.linalg.norm(err, axis=1), color="k", lw=1.0, ls=":", label="|p - p_ref|")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position error [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8, frameon=False)
    fig.suptitle(f"{title}: tracking error" if title else "tracking error")
    return fig


def transition_figure(transition, *, title: str = "") -> Figure:
    """A transition flown with a gain schedule and with one fixed design (:class:`quadctl.transition.Transition`).

    Top: the scheduling variable flown by each and the reference's, with the schedule's grid
    values dotted. Middle: the pitch angle. Bottom: the thrust of the most loaded rotor
    (or the largest ``|u - u_ref|`` share of the limits without rotors) against its limits. A run
    that stopped early ends with a cross.
    """
    from quadctl.lqr.gain_table import VARIABLES, scheduling_values
    from quadctl.sim.run import STATUS_WORDS

    runs, loop = transition.runs(), transition.loops["scheduled"]
    table, heading = loop.schedule, loop.schedule_heading
    fig = Figure(figsize=(10.0, 7.5), layout="constrained")
    speed_ax, angle_ax, rotor_ax = fig.subplots(3, 1, sharex=True)

    def variable(x):
        return scheduling_values(table.variable, x, heading)

    first = runs["scheduled"]
    _trace(speed_ax, first.t, variable(first.x_ref), color="0.35", lw=1.0, ls="--", label="reference")
    for value in table.values:
        speed_ax.axhline(value, color="0.7", lw=0.6, ls=":")
    act = loop.actuators
    for (label, sim), color in zip(runs.items(), _COLORS):
        ended = sim.status != "ok"
        _trace(speed_ax, sim.t, variable(sim.x), color=color, lw=1.6, label=f"{label} ({STATUS_WORDS[sim.status]})")
        _trace(angle_ax, sim.t, np.rad2deg(sim.x[:, STATE_INDEX["theta"]]), color=color, lw=1.3, label=label)
        if act is not None and act.mode == "motors":
            load = act.commands(sim.u).max(axis=1)
        else:
            load = np.abs(sim.u - (sim.u_ref if len(sim.u_ref) else loop.u_trim)).max(axis=1)
        _trace(rotor_ax, sim.t, load, color=color, lw=1.2, label=label)
        if ended:
            for ax, y in ((speed_ax, variable(sim.x[-1:])[0]), (angle_ax, np.rad2deg(sim.x[-1, STATE_INDEX["theta"]])),
                          (rotor_ax, load[-1])):
                ax.plot(sim.t[-1], y, "x", color=color, ms=9, mew=2)
    if act is not None and act.mode == "motors":
        _limit_lines(rotor_ax, (act.lo[0], act.hi[0]), "min / max thrust")
        rotor_ax.set_ylabel("most loaded rotor [N]")
    else:
        rotor_ax.set_ylabel("largest |u - u_ref|")
    speed_ax.set_ylabel(f"{table.variable} [{VARIABLES[table.variable]}]")
    angle_ax.set_ylabel("pitch theta [deg]")
    rotor_ax.set_xlabel("time [s]")
    for ax in (speed_ax, angle_ax, rotor_ax):
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8, frameon=False, ncols=2)
    what = f"{table.variable} schedule ({table.interpolation}) against one fixed design"
    fig.suptitle(f"{title}: {what}" if title else what)
    return fig


def simulation_figures(sim, partition: dict, u_trim=None, *, title: str = "",
                       actuators=None) -> dict[str, Figure]:
    """A figure per subsystem (in partition order), one of the inputs (with ``actuators``' limits,
    :func:`inputs_figure`), in wind one of the wind and, flying a reference, the path and the
    tracking error, keyed by file stem."""
    return {name: make() for name, make in simulation_figure_makers(sim, partition, u_trim, title=title,
                                                                     actuators=actuators).items()}


def simulation_figure_makers(sim, partition: dict, u_trim=None, *, title: str = "",
                             actuators=None) -> dict[str, Callable[[], Figure]]:
    """The figures of :func:`simulation_figures`, each not yet made: file stem -> a function that
    makes it (so that a caller can make, draw and drop one at a time, or share them out)."""
    makers = {name: partial(subsystem_figure, sim, name, sub.states, title=title) for name, sub in partition.items()}
    makers["inputs"] = partial(inputs_figure, sim, u_trim, title=title, actuators=actuators)
    if len(getattr(sim, "wind", ())):
        makers["wind"] = partial(wind_figure, sim, title=title)
    if len(getattr(sim, "u_ref", ())):
        makers["path"] = partial(path_figure, sim, title=title)
        makers["tracking"] = partial(tracking_error_figure, sim, title=title)
    return makers


def margins_figure(m, *, title: str = "") -> Figure:
    """Bode (magnitude, phase) and Nyquist plot of one broken loop, with its margins marked.

    Parameters
    ----------
    m : quadctl.margins.LoopMargins
    """
    fig = Figure(figsize=(10.0, 5.2), layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=(1.25, 1.0))
    ax_mag = fig.add_subplot(grid[0, 0])
    ax_ph = fig.add_subplot(grid[1, 0], sharex=ax_mag)
    ax_ny = fig.add_subplot(grid[:, 1])
    w, L = m.freq, m.response
    crossover = None if m.gain_crossover_freq is None else int(np.argmin(np.abs(np.log(w / m.gain_crossover_freq))))
    phase = phase_about_minus_180(L, crossover)
    ax_mag.semilogx(w, 20 * np.log10(np.abs(L)), color=_COLORS[0], lw=1.5)
    ax_mag.axhline(0.0, color="0.35", lw=0.9, ls="--")
    ax_mag.set_ylabel("|L| [dB]")
    ax_ph.semilogx(w, phase, color=_COLORS[0], lw=1.5)
    for k in range(-3, 2):
        if phase.min() - 10 <= -180 + 360 * k <= phase.max() + 10:
            ax_ph.axhline(-180 + 360 * k, color="0.35", lw=0.9, ls="--")
    ax_ph.set_ylabel("phase of L [deg]")
    ax_ph.set_xlabel("frequency [rad/s]")
    if m.gain_crossover_freq is not None:
        for ax in (ax_mag, ax_ph):
            ax.axvline(m.gain_crossover_freq, color=_COLORS[2], lw=1.0, ls=":")
        ax_ph.annotate(f"PM {m.phase_margin_deg:.3g} deg", (m.gain_crossover_freq, phase.min()), xytext=(3, 4),
                       textcoords="offset points", fontsize=8, color=_COLORS[2], va="bottom")
    for wg, gm in zip(m.phase_crossover_freqs, m.gain_margin_db):
        if wg is not None:
            for ax in (ax_mag, ax_ph):
                ax.axvline(wg, color=_COLORS[1], lw=1.0, ls=":")
            ax_mag.annotate(f"GM {gm:+.3g} dB", (wg, 0.0), xytext=(-3, 3), textcoords="offset points",
                            fontsize=8, color=_COLORS[1], ha="right", va="bottom")
    if m.sample_time:  # labelled at the top: a gain margin often sits at the Nyquist frequency
        ax_mag.axvline(np.pi / m.sample_time, color="0.5", lw=0.9)
        ax_mag.annotate("Nyquist", (np.pi / m.sample_time, 1.0), xycoords=("data", "axes fraction"),
                        xytext=(-3, -3), textcoords="offset points", fontsize=8, color="0.4", ha="right", va="top")
    for ax in (ax_mag, ax_ph):
        ax.grid(True, which="both", alpha=0.3)
    ax_ny.plot(L.real, L.imag, color=_COLORS[0], lw=1.5, label="L(jw), w > 0")
    ax_ny.plot(L.real, -L.imag, color=_COLORS[0], lw=1.0, ls="--", alpha=0.6, label="w < 0")
    circle = np.exp(1j * np.linspace(0, 2 * np.pi, 361))
    ax_ny.plot(circle.real, circle.imag, color="0.6", lw=0.8)
    disk = -1 + m.min_return_difference * circle  # L never enters this disk around -1
    ax_ny.plot(disk.real, disk.imag, color=_COLORS[3], lw=1.0, label=f"min |1+L| = {m.min_return_difference:.3g}")
    ax_ny.plot(-1, 0, "x", color=_COLORS[1], ms=9, mew=2)
    ax_ny.set_xlim(-3, 2)
    ax_ny.set_ylim(-2.5, 2.5)
    ax_ny.set_aspect("equal", adjustable="box")
    ax_ny.set_xlabel("Re L")
    ax_ny.set_ylabel("Im L")
    ax_ny.grid(True, alpha=0.3)
    ax_ny.legend(loc="lower right", fontsize=7, frameon=False)
    kind = f"sampled, Ts = {m.sample_time * 1e3:.3g} ms" if m.sample_time else "continuous"
    head = f"{m.loop} loop broken at {m.input} ({m.model} model, {kind})"
    fig.suptitle(f"{title}: {head}" if title else head)
    return fig


def sweep_tradeoff_figure(rows, x: str, y: str, gates=(), *, title: str = "") -> Figure:
    """A sweep's trade-off: metric ``y`` against metric ``x``, one point per case.

    Passing cases are dots, failing ones red crosses; gate thresholds on either axis are
    dashed lines. Cases without both values (no design, never settled) are counted in the title.

    Parameters
    ----------
    rows : list of dict
        Sweep rows (:attr:`quadctl.sweep.SweepResult.rows`): metric name -> value, and ``pass``.
    x, y : str
        Metric names, such as ``peak.T`` and ``settling_time.pD``.
    gates : sequence of quadctl.sweep.Gate
    """
    def unit(metric: str) -> str:
        family, _, name = metric.partition(".")
        if family == "settling_time":
            return "s"
        if family == "overshoot":
            return "%"
        if family == "peak":
            return unit_of(name)
        return "rad/s" if family == "eig" else ""

    fig = Figure(figsize=(7.5, 5.0), layout="constrained")
    ax = fig.subplots()
    plotted = {True: ([], []), False: ([], [])}
    missing = 0
    for row in rows:
        vx, vy = row.get(x), row.get(y)
        if isinstance(vx, (int, float)) and isinstance(vy, (int, float)) and np.isfinite([vx, vy]).all():
            plotted[bool(row.get("pass"))][0].append(vx)
            plotted[bool(row.get("pass"))][1].append(vy)
        else:
            missing += 1
    ax.scatter(*plotted[True], s=14, color=_COLORS[0], alpha=0.7, label=f"pass ({len(plotted[True][0])})")
    ax.scatter(*plotted[False], s=22, color=_COLORS[1], marker="x", label=f"fail ({len(plotted[False][0])})")
    labelled = False
    for gate in gates:
        for bound in (gate.min, gate.max):
            if bound is None or gate.metric not in (x, y):
                continue
            line = ax.axvline if gate.metric == x else ax.axhline
            line(bound, color="0.3", ls="--", lw=1.0, label=None if labelled else "gate")
            labelled = True
    ax.set_xlabel(f"{x} [{unit(x)}]" if unit(x) else x)
    ax.set_ylabel(f"{y} [{unit(y)}]" if unit(y) else y)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8, frameon=False)
    note = f"; {missing} cases without both values" if missing else ""
    fig.suptitle(f"{title}: sweep trade-off ({len(rows)} cases{note})" if title else
                 f"sweep trade-off ({len(rows)} cases{note})")
    return fig



def montecarlo_figure(bands, groups: dict, *, title: str = "", varied: tuple = ()) -> Figure:
    """A Monte Carlo's percentile bands against time: a row per subsystem, a column per state.

    Each state gets two panels. Above: the median deviation from the reference, the 25-75 % band
    (dark) and the 5-95 % band (light) over the cases, at each time of the grid. Below: the same
    bands about the median, at a scale where the spread the noise causes is visible even while a
    deterministic transient (the initial offset) dwarfs it above.

    Parameters
    ----------
    bands : quadctl.sweep.MonteCarloBands
        ``t`` (P,) s; ``bands`` (5, P, S) at ``percentiles`` 5, 25, 50, 75, 95; ``states`` (S,).
    groups : dict
        Subsystem name -> its states (a row each, in order); states not in ``bands`` are skipped.
    varied : tuple of str
        The sweep's parameters (key paths), named in the title; none or only the noise seed: a
        Monte Carlo over noise seeds.
    """
    level = {p: k for k, p in enumerate(bands.percentiles)}
    rows = [(name, [s for s in states if s in bands.states]) for name, states in groups.items()]
    rows = [(name, states) for name, states in rows if states]
    ncols = max(len(states) for _, states in rows)
    fig = Figure(figsize=(3.7 * ncols + 0.4, 3.0 * len(rows) + 0.9), layout="constrained")
    axes = fig.subplots(2 * len(rows), ncols, sharex=True, squeeze=False,
                        gridspec_kw={"height_ratios": [2.0, 1.0] * len(rows)})
    for r, ((name, states), color) in enumerate(zip(rows, _COLORS * 3)):
        for c in range(ncols):
            top, below = axes[2 * r, c], axes[2 * r + 1, c]
            if c >= len(states):
                top.set_visible(False)
                below.set_visible(False)
                continue
            j = bands.states.index(states[c])
            p = {q: _display(states[c], bands.bands[k, :, j])[0] for q, k in level.items()}
            unit = _display(states[c], bands.bands[0, :1, j])[1]
            for ax, centre in ((top, 0.0), (below, p[50])):
                ax.fill_between(bands.t, p[5] - centre, p[95] - centre, color=color, alpha=0.2, lw=0,
                                label="5-95 %")
                ax.fill_between(bands.t, p[25] - centre, p[75] - centre, color=color, alpha=0.5, lw=0,
                                label="25-75 %")
                ax.axhline(0.0, color="0.35", lw=0.8, ls="--")
                ax.grid(True, alpha=0.3)
            top.plot(bands.t, p[50], color=color, lw=1.4, label="median")
            top.set_ylabel(f"Δ{_label(states[c])} [{unit}]")
            below.set_ylabel(f"about median [{unit}]", fontsize=8)
            below.tick_params(labelsize=7)
            if c == 0:
                top.set_title(name, loc="left", fontsize=10, fontweight="bold")
    for c in range(ncols):
        last = max(r for r, (_, states) in enumerate(rows) if c < len(states))
        axes[2 * last + 1, c].set_xlabel("time [s]")
        axes[2 * last + 1, c].xaxis.set_tick_params(labelbottom=True)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles[:3], labels[:3], loc="outside lower center", ncols=3, fontsize=8, frameon=False)
    n = len(bands.cases)
    left = f"; {len(bands.left_out)} left out (did not finish)" if len(bands.left_out) else ""
    if not varied or tuple(varied) == ("simulation.noise.seed",):
        head = f"Monte Carlo over {n} noise seeds{left}: deviation from the reference"
    else:
        import textwrap

        width = max(40, int(8 * fig.get_figwidth()))  # characters a title line holds (12 pt, ~8 an inch)
        text = f"{title}: " if title else ""
        fig.suptitle(textwrap.fill(f"{text}{n} cases of one design{left}, varying {', '.join(varied)}", width)
                     + "; deviation from the reference")
        return fig
    fig.suptitle(f"{title}: {head}" if title else head)
    return fig


def schedule_figure(sched, actuators=None, *, title: str = "") -> Figure:
    """The envelope of a gain schedule (:class:`quadctl.scheduling.Schedule`) against its variable.

    Four panels: the block gain's nonzero entries (each over its largest magnitude: markers at the
    points, the interpolated table between them); the slowest pole and the least damping of the
    frozen-point loops along the fine grid (failures in red); the trim attitude (deg); the trim
    thrust (each rotor's, between ``min_thrust`` and ``max_thrust``, with ``motors:``; else ``T``
    and any ``limits:``). Values with no trim are marked by red dotted lines.

    Parameters
    ----------
    sched : quadctl.scheduling.Schedule
    actuators : quadctl.motors.Actuators, optional
        The setup's limits: drawn as lines on the thrust panel.
    """
    from quadctl.layout import STATE_NAMES

    fig = Figure(figsize=(11.0, 7.5), layout="constrained")
    (ax_k, ax_p), (ax_a, ax_t) = fig.subplots(2, 2, sharex=True)
    good = [p for p in sched.points if p.designed]
    v = np.array([p.value for p in good])
    c = sched.checks
    K = sched.table.gains[:, :, :len(STATE_NAMES)]
    fine_K = sched.table.at(c.values)[:, :, :len(STATE_NAMES)]
    entries = [(i, j) for i in range(K.shape[1]) for j in range(K.shape[2]) if np.abs(K[:, i, j]).max() > 0]
    for n, (i, j) in enumerate(entries):
        scale = np.abs(K[:, i, j]).max()
        color = f"C{n % 10}"
        ax_k.plot(c.values, fine_K[:, i, j] / scale, color=color, lw=1.0,
                  label=f"K[{INPUT_NAMES[i]},{STATE_NAMES[j]}] ({scale:.3g})")
        ax_k.plot(v, K[:, i, j] / scale, "o", color=color, ms=3)
    ax_k.set_ylabel("gain / max |gain|")
    ax_k.set_title(f"gains ({sched.interpolation} between the points)", fontsize=9)
    ax_k.legend(loc="best", fontsize=6, frameon=False, ncols=2)
    ax_p.plot(c.values, c.slowest, color=_COLORS[0], lw=1.4, label="slowest pole")
    bad = ~c.stable & np.isfinite(c.slowest)
    if bad.any():
        ax_p.plot(c.values[bad], c.slowest[bad], "x", color=_COLORS[1], ms=7, label="frozen loop UNSTABLE")
    ax_p.axhline(0.0, color="0.35", lw=0.8)
    ax_p.set_ylabel("slowest pole Re(s) [rad/s]")
    twin = ax_p.twinx()
    twin.plot(c.values, c.least_damping, color=_COLORS[2], lw=1.2, ls="--", label="least damping")
    twin.set_ylabel("least damping ratio")
    lines = ax_p.get_legend_handles_labels()
    more = twin.get_legend_handles_labels()
    ax_p.legend(lines[0] + more[0], lines[1] + more[1], loc="best", fontsize=7, frameon=False)
    ax_p.set_title(f"frozen-point loops, grid {c.refinement}x finer", fontsize=9)
    trimmed = [p for p in sched.points if p.trimmed]
    tv = np.array([p.value for p in trimmed])
    for name, color in (("theta", _COLORS[0]), ("phi", _COLORS[1]), ("psi", _COLORS[2])):
        ax_a.plot(tv, np.rad2deg([p.trim.x[STATE_INDEX[name]] for p in trimmed]), "o-", color=color, ms=3,
                  lw=1.2, label=name)
    ax_a.set_ylabel("trim attitude [deg]")
    ax_a.legend(loc="best", fontsize=7, frameon=False)
    rotors = actuators is not None and actuators.mode == "motors"
    if rotors:
        thrust = np.array([p.actuator_commands for p in trimmed])
        for i, (rotor, color) in enumerate(zip(actuators.names, _COLORS)):
            ax_t.plot(tv, thrust[:, i], "o-", color=color, ms=3, lw=1.2, label=rotor)
        _limit_lines(ax_t, (actuators.lo[0], actuators.hi[0]), "min / max thrust")
        ax_t.set_ylabel("trim rotor thrust [N]")
    else:
        ax_t.plot(tv, [p.trim.u[0] for p in trimmed], "o-", color=_COLORS[0], ms=3, lw=1.2, label="T")
        if actuators is not None:
            _limit_lines(ax_t, input_limits(actuators)[0][:1].tolist() + input_limits(actuators)[1][:1].tolist(),
                         "limit")
        ax_t.set_ylabel("trim thrust T [N]")
    ax_t.legend(loc="best", fontsize=7, frameon=False)
    missing = [p.value for p in sched.points if not p.designed]
    for ax in (ax_k, ax_p, ax_a, ax_t):
        for k, value in enumerate(missing):
            ax.axvline(value, color=_COLORS[1], lw=0.9, ls=":", label="no trim" if k == 0 and ax is ax_a else None)
        ax.grid(True, alpha=0.3)
    if missing:
        ax_a.legend(loc="best", fontsize=7, frameon=False)
    for ax in (ax_a, ax_t):
        ax.set_xlabel(f"{sched.variable} [{sched.unit}]")
    head = f"gain schedule over {sched.variable}"
    fig.suptitle(f"{title}: {head}" if title else head)
    return fig
