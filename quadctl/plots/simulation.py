"""Figures of a simulation, like the report's figures 2-4: a subsystem's states, the inputs, the wind,
the path flown and its tracking error."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from quadctl.layout import INPUT_NAMES, STATE_INDEX, unit_of
from quadctl.plots.drawing import COLORS, axis_label, displayed, input_limits, length_unit, limit_lines, trace


def subsystem_figure(sim, name: str, states, *, title: str = "", regulated: bool = True) -> Figure:
    """One panel per state of a subsystem: the state and its reference against time.

    Parameters
    ----------
    sim : SimResult
    name : str
        Subsystem name (figure title).
    states : sequence of str
    regulated : bool
        False: the partition leaves the subsystem unregulated (``regulate: false``), so no feedback
        holds its states to the reference: the title and the legends say so, and the reference is
        drawn as what the states would follow, not as a miss.
    """
    fig = Figure(figsize=(7.5, 1.9 * len(states) + 0.8), layout="constrained")
    axes = fig.subplots(len(states), 1, sharex=True, squeeze=False)[:, 0]
    free = "" if regulated else " (not regulated)"
    for ax, state, color in zip(axes, states, COLORS * 3):
        i = STATE_INDEX[state]
        y, unit = displayed(state, sim.x[:, i])
        ref, _ = displayed(state, sim.x_ref[:, i])
        trace(ax, sim.t, y, color=color, lw=1.6, label=axis_label(state) + free)
        trace(ax, sim.t, ref, color="0.35", lw=1.0, ls="--" if regulated else ":",
              label="reference" if regulated else "reference (no feedback holds it)")
        ax.set_ylabel(f"{axis_label(state)} [{unit}]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8, frameon=False)
    axes[-1].set_xlabel("time [s]")
    status = "" if sim.status == "ok" else f" ({sim.status})"
    what = f"{name} subsystem{free}{status}"
    fig.suptitle(f"{title}: {what}" if title else what)
    return fig


def inputs_figure(sim, u_trim=None, *, title: str = "", actuators=None) -> Figure:
    """The four inputs T, A, E, R against time, with their trim values dashed and, given
    ``actuators``, their limits (:func:`input_limits`) as red lines.

    Left: linear time. Right: the same samples on a time axis linear from 0 to the first step and
    logarithmic after it (``symlog``), where the fast transients of the rate loops (milliseconds or
    less) are visible beside the first sample. Each row's two panels share their y-limits, those of
    every sample. With rotors (``actuators.mode == "motors"``) a last row shows each rotor's thrust
    (what the applied inputs ask of it) between its ``min_thrust`` and ``max_thrust``, where a
    saturation shows; each rotor's line carries its own markers, staggered from the others', so that
    rotors with the same thrust all show (:func:`staggered_marks`).

    Parameters
    ----------
    sim : SimResult
    u_trim : (4,) array_like, optional
        N, N m.
    actuators : quadctl.physics.motors.Actuators, optional
        The simulated vehicle's limits (``setup.actuators``); None: no limit lines.
    """
    rotors = actuators is not None and actuators.mode == "motors"
    rows = len(INPUT_NAMES) + (1 if rotors else 0)
    fig = Figure(figsize=(10.0, 7.0 * rows / len(INPUT_NAMES)), layout="constrained")
    axes = fig.subplots(rows, 2, sharex="col", sharey="row")
    steps = sim.t[sim.t > 0]
    first_step = float(steps[0]) if len(steps) else 1.0  # s: the symlog axis's linear stretch, 0 to the first step
    lo, hi = input_limits(actuators) if actuators is not None else (np.full(4, -np.inf), np.full(4, np.inf))
    for j, (row, name, color) in enumerate(zip(axes, INPUT_NAMES, COLORS)):
        for ax, log in ((row[0], False), (row[1], True)):
            trace(ax, sim.t, sim.u[:, j], color=color, lw=1.6, label=name, log=log)
            if u_trim is not None:
                ax.axhline(u_trim[j], color="0.35", lw=1.0, ls="--", label="trim")
            limit_lines(ax, (lo[j], hi[j]), "rotor limits" if rotors else "limit")
            ax.grid(True, alpha=0.3)
            ax.set_ylabel(f"{name} [{unit_of(name)}]")
            ax.yaxis.set_tick_params(labelleft=True)
        row[0].legend(loc="best", fontsize=8, frameon=False)
    if rotors:
        thrust = actuators.commands(sim.u)
        for ax, log in ((axes[-1, 0], False), (axes[-1, 1], True)):
            ax.set_xscale("symlog", linthresh=first_step, linscale=0.3) if log else None
            for i, (rotor, color, marker) in enumerate(zip(actuators.names, COLORS, ROTOR_MARKERS)):
                line, = trace(ax, sim.t, thrust[:, i], color=color, lw=1.1, label=rotor, log=log, marker=marker,
                              ms=4.5, zorder=2)
                line.set_markevery(staggered_marks(ax, line.get_xdata(), i, len(actuators.names)))
            limit_lines(ax, (actuators.lo[0], actuators.hi[0]), "min / max thrust")
            ax.grid(True, alpha=0.3)
            ax.set_ylabel("rotor thrust [N]")
            ax.yaxis.set_tick_params(labelleft=True)
        axes[-1, 0].legend(loc="best", fontsize=7, frameon=False, ncols=3)
    for ax in axes[:, 1]:
        ax.set_xscale("symlog", linthresh=first_step, linscale=0.3)
        ax.set_xlim(left=0.0)
        end = float(sim.t[-1]) if len(sim.t) else 1.0
        decades = np.arange(np.ceil(np.log10(first_step)), np.floor(np.log10(max(end, first_step))) + 1)
        ax.set_xticks([0.0, *10.0 ** decades])  # 0, then the decades past the linear stretch (none inside it)
    axes[-1, 0].set_xlabel("time [s]")
    axes[-1, 1].set_xlabel(f"time [s], linear to the first sample ({first_step:.3g} s), log after")
    fig.suptitle(f"{title}: inputs" if title else "inputs")
    return fig


ROTOR_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
"""Each rotor's marker, in order."""


def staggered_marks(ax, x, i: int, lines: int, marks: int = 12) -> list[int]:
    """Where line ``i`` of ``lines`` sharing ``ax`` puts its markers: the samples of ``x`` nearest
    ``marks`` points equally spaced across the axis (its scale's coordinates), each line's a
    ``1 / lines`` of the spacing after the one before. Lines on one another each show their markers."""
    x = np.asarray(x, dtype=float)
    if not len(x):
        return []
    scaled = ax.xaxis.get_transform().transform(x.reshape(-1, 1)).ravel()
    lo, hi = scaled[0], scaled[-1]
    targets = lo + (hi - lo) * (np.arange(marks) + (i + 0.5) / lines) / marks
    return sorted({int(k) for k in np.clip(np.searchsorted(scaled, targets), 0, len(x) - 1)})


def wind_figure(sim, *, title: str = "") -> Figure:
    """The wind the plant felt (N, E, D components, m/s) against time."""
    fig, ax = _over_time(3.5)
    for i, (name, color) in enumerate(zip(("wind N", "wind E", "wind D"), COLORS)):
        trace(ax, sim.t, sim.wind[:, i], color=color, lw=1.2, label=name)
    return _finished(fig, ax, "wind [m/s], NED", "wind", title)


def path_figure(sim, waypoints=(), *, reached=None, tolerance: float | None = None, title: str = "") -> Figure:
    """The flown path over the reference: the horizontal plane (east right, north up, equal scales)
    with the start, the end and the waypoints numbered in order, and the altitude ``-pD`` against
    time with each waypoint where it was reached.

    The reference is drawn wide and pale under the flown path, so that both show where they agree.

    Parameters
    ----------
    sim : SimResult
    waypoints : sequence of (3,) array_like, optional
        NED positions (m) to mark, numbered from 1 in order.
    reached : sequence of (float or None), optional
        Per waypoint, when it was reached (s; None: never): a reached waypoint is a filled square,
        marked at that time on the altitude panel too; a missed one a red cross. Absent: every
        waypoint a hollow square (not judged).
    tolerance : float, optional
        m: the radius within which a waypoint counts as reached, drawn around each.
    """
    fig = Figure(figsize=(10.0, 4.6), layout="constrained")
    plane, alt = fig.subplots(1, 2, width_ratios=(1.0, 1.3))
    n, e, d = (STATE_INDEX[s] for s in ("pN", "pE", "pD"))
    pale = {"color": "0.72", "lw": 4.0, "solid_capstyle": "round", "label": "reference"}
    plane.plot(sim.x_ref[:, e], sim.x_ref[:, n], zorder=1, **pale)
    plane.plot(sim.x[:, e], sim.x[:, n], color=COLORS[0], lw=1.4, label="flown", zorder=2)
    # the start a wide ring under the waypoints, the end a small dot over them: a mission that ends where
    # it began shows its last waypoint inside the ring and the end on that waypoint (MARKERS)
    plane.plot(sim.x[0, e], sim.x[0, n], "o", mfc="none", mec=COLORS[2], label="start", **MARKERS["start"])
    plane.plot(sim.x[-1, e], sim.x[-1, n], "o", mfc=COLORS[0], mec="white", label="end", **MARKERS["end"])
    judged = reached is not None
    reached = list(reached) if judged else [None] * len(waypoints)
    labelled: set[str] = set()
    for k, (wp, when) in enumerate(zip(waypoints, reached)):
        kind = "waypoint" if not judged else "reached" if when is not None else "missed"
        style = {"waypoint": {"marker": "s", "mfc": "white", "mec": COLORS[3]},
                 "reached": {"marker": "s", "mfc": COLORS[3], "mec": COLORS[3]},
                 "missed": {"marker": "X", "mfc": COLORS[1], "mec": COLORS[1]}}[kind]
        label = None if kind in labelled else f"reached within {tolerance:g} m" if kind == "reached" and \
            tolerance else kind
        labelled.add(kind)
        plane.plot(wp[1], wp[0], ls="none", label=label, **style, **MARKERS["waypoint"])
        if tolerance:
            plane.add_patch(Circle((wp[1], wp[0]), tolerance, fill=False, color=style["mec"], lw=0.8, ls=":",
                                   zorder=4))
        plane.annotate(str(k), (wp[1], wp[0]), textcoords="offset points", xytext=(7, 7), fontsize=9,
                       fontweight="bold", color=style["mec"], zorder=5)
        if when is not None:
            alt.plot(when, -wp[2], ls="none", ms=7, zorder=4, **style)
            alt.axvline(when, color=style["mec"], lw=0.6, ls=":", zorder=0)
            alt.annotate(str(k), (when, -wp[2]), textcoords="offset points", xytext=(5, 6), fontsize=9,
                         fontweight="bold", color=style["mec"])
    plane.set_aspect("equal", adjustable="datalim")
    plane.margins(0.08)
    plane.set_xlabel("east [m]")
    plane.set_ylabel("north [m]")
    plane.grid(True, alpha=0.3)
    plane.legend(loc="best", fontsize=8, framealpha=0.85)
    trace(alt, sim.t, -sim.x_ref[:, d], zorder=1, **pale)
    trace(alt, sim.t, -sim.x[:, d], color=COLORS[0], lw=1.4, label="flown", zorder=2)
    alt.ticklabel_format(axis="y", useOffset=False)
    low, high = alt.get_ylim()
    middle = (low + high) / 2
    low, high = min(low, middle - 0.25), max(high, middle + 0.25)  # a flat path shows flat, not its round-off
    alt.set_ylim(low, high + 0.06 * (high - low))  # room for the waypoints' numbers
    alt.set_xlabel("time [s]")
    alt.set_ylabel("altitude -pD [m]")
    alt.grid(True, alpha=0.3)
    alt.legend(loc="best", fontsize=8, framealpha=0.85)
    status = "" if sim.status == "ok" else f" ({sim.status})"
    count = "" if not judged or not len(waypoints) else \
        f", {sum(r is not None for r in reached)} of {len(reached)} waypoints reached"
    fig.suptitle(f"{title}: path{count}{status}" if title else f"path{count}{status}")
    return fig


MARKERS = {"start": {"ms": 18.0, "mew": 1.5, "zorder": 3},
           "waypoint": {"ms": 8.0, "mew": 1.5, "zorder": 4},
           "end": {"ms": 6.0, "mew": 1.5, "zorder": 7}}
"""The path's markers (points, and the order they are drawn in): the start's ring clears a waypoint's
square at its centre (its inside radius above the square's half diagonal), the end is drawn on top."""


def tracking_error_figure(sim, *, title: str = "") -> Figure:
    """The position tracking error against time: north, east and down, and its norm ``|p - p_ref|``, in the
    length unit its size reads in (:func:`~quadctl.plots.drawing.length_unit`: a flatness-fed mission's error
    of a fraction of a micrometre in nm)."""
    fig, ax = _over_time(3.8)
    err = sim.x[:, :3] - sim.x_ref[:, :3]
    norm = np.linalg.norm(err, axis=1)
    size, unit = length_unit(norm)
    for i, (name, color) in enumerate(zip(("pN", "pE", "pD"), COLORS)):
        trace(ax, sim.t, err[:, i] / size, color=color, lw=1.2, label=f"{name} - reference")
    trace(ax, sim.t, norm / size, color="k", lw=1.0, ls=":", label="|p - p_ref|")
    # a small unit with its size (an "nm" beside the inputs' "N m" is read as a torque)
    scale = "" if size == 1.0 else f" = 10{str(round(np.log10(size))).translate(SUPERSCRIPTS)} m"
    return _finished(fig, ax, f"position error [{unit}{scale}]", "tracking error", title)


SUPERSCRIPTS = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")
"""Digits and the minus sign as superscripts (an exponent in an axis label)."""


def _over_time(height: float) -> tuple[Figure, object]:
    """A full-width figure ``height`` inches tall with one axes, for quantities against time."""
    fig = Figure(figsize=(10.0, height), layout="constrained")
    return fig, fig.subplots()


def _finished(fig: Figure, ax, ylabel: str, what: str, title: str) -> Figure:
    """``fig`` with its time axis, ``ylabel``, grid, legend and title (``title: what``)."""
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8, frameon=False)
    fig.suptitle(f"{title}: {what}" if title else what)
    return fig


def simulation_figures(sim, partition: dict, u_trim=None, *, title: str = "", actuators=None,
                       tracking: dict | None = None) -> dict[str, Figure]:
    """A figure per subsystem (in partition order), one of the inputs (with ``actuators``' limits,
    :func:`inputs_figure`), in wind one of the wind and, flying a reference, the path (a mission's
    waypoints from ``tracking``, :func:`quadctl.run_summary.tracking_of`) and the tracking error,
    keyed by file stem."""
    return {name: make() for name, make in simulation_figure_makers(sim, partition, u_trim, title=title,
                                                                     actuators=actuators, tracking=tracking).items()}


def simulation_figure_makers(sim, partition: dict, u_trim=None, *, title: str = "", actuators=None,
                             tracking: dict | None = None) -> dict[str, Callable[[], Figure]]:
    """The figures of :func:`simulation_figures`, each not yet made: file stem -> a function that
    makes it (so that a caller can make, draw and drop one at a time, or share them out)."""
    makers = {name: partial(subsystem_figure, sim, name, sub.states, title=title,
                            regulated=getattr(sub, "regulate", True))  # a partition's Subsystem
              for name, sub in partition.items()}
    makers["inputs"] = partial(inputs_figure, sim, u_trim, title=title, actuators=actuators)
    if len(getattr(sim, "wind", ())):
        makers["wind"] = partial(wind_figure, sim, title=title)
    if len(getattr(sim, "u_ref", ())):
        wps = (tracking or {}).get("waypoints")
        mission = {} if not wps else {"waypoints": [w["position"] for w in wps],
                                      "reached": [w["reached"] for w in wps], "tolerance": tracking["tolerance"]}
        makers["path"] = partial(path_figure, sim, title=title, **mission)
        makers["tracking"] = partial(tracking_error_figure, sim, title=title)
    return makers
