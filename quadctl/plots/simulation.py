"""Figures of a simulation, like the report's figures 2-4: a subsystem's states, the inputs, the wind,
the path flown and its tracking error."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from quadctl.layout import INPUT_NAMES, STATE_INDEX, unit_of
from quadctl.plots.drawing import COLORS, axis_label, displayed, input_limits, limit_lines, trace


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
    for ax, state, color in zip(axes, states, COLORS * 3):
        i = STATE_INDEX[state]
        y, unit = displayed(state, sim.x[:, i])
        ref, _ = displayed(state, sim.x_ref[:, i])
        trace(ax, sim.t, y, color=color, lw=1.6, label=axis_label(state))
        trace(ax, sim.t, ref, color="0.35", lw=1.0, ls="--", label="reference")
        ax.set_ylabel(f"{axis_label(state)} [{unit}]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8, frameon=False)
    axes[-1].set_xlabel("time [s]")
    status = "" if sim.status == "ok" else f" ({sim.status})"
    fig.suptitle(f"{title}: {name} subsystem{status}" if title else f"{name} subsystem{status}")
    return fig


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
    actuators : quadctl.physics.motors.Actuators, optional
        The simulated vehicle's limits (``setup.actuators``); None: no limit lines.
    """
    rotors = actuators is not None and actuators.mode == "motors"
    rows = len(INPUT_NAMES) + (1 if rotors else 0)
    fig = Figure(figsize=(10.0, 7.0 * rows / len(INPUT_NAMES)), layout="constrained")
    axes = fig.subplots(rows, 2, sharex="col")
    later = sim.t > 0
    lo, hi = input_limits(actuators) if actuators is not None else (np.full(4, -np.inf), np.full(4, np.inf))
    for j, (row, name, color) in enumerate(zip(axes, INPUT_NAMES, COLORS)):
        for ax, t, u, log in ((row[0], sim.t, sim.u[:, j], False), (row[1], sim.t[later], sim.u[later, j], True)):
            trace(ax, t, u, color=color, lw=1.6, label=name, log=log)
            if u_trim is not None:
                ax.axhline(u_trim[j], color="0.35", lw=1.0, ls="--", label="trim")
            limit_lines(ax, (lo[j], hi[j]), "rotor limits" if rotors else "limit")
            ax.grid(True, alpha=0.3)
        row[0].set_ylabel(f"{name} [{unit_of(name)}]")
        row[0].legend(loc="best", fontsize=8, frameon=False)
        row[1].set_xscale("log")
    if rotors:
        thrust = actuators.commands(sim.u)
        for ax, keep, log in ((axes[-1, 0], slice(None), False), (axes[-1, 1], later, True)):
            for i, (rotor, color) in enumerate(zip(actuators.names, COLORS)):
                trace(ax, sim.t[keep], thrust[keep, i], color=color, lw=1.2, label=rotor, log=log)
            limit_lines(ax, (actuators.lo[0], actuators.hi[0]), "min / max thrust")
            ax.grid(True, alpha=0.3)
        axes[-1, 0].set_ylabel("rotor thrust [N]")
        axes[-1, 0].legend(loc="best", fontsize=7, frameon=False, ncols=3)
        axes[-1, 1].set_xscale("log")
    axes[-1, 0].set_xlabel("time [s]")
    axes[-1, 1].set_xlabel("time [s], log scale")
    fig.suptitle(f"{title}: inputs" if title else "inputs")
    return fig


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
    plane.plot(sim.x[0, e], sim.x[0, n], "o", mfc="none", mec=COLORS[2], ms=13, mew=2.0, label="start",
               zorder=6)  # a ring: a mission that ends where it began shows its last waypoint inside
    plane.plot(sim.x[-1, e], sim.x[-1, n], "o", color=COLORS[0], ms=5, label="end", zorder=3)
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
        plane.plot(wp[1], wp[0], ls="none", ms=8, mew=1.5, zorder=4, label=label, **style)
        if tolerance:
            plane.add_patch(Circle((wp[1], wp[0]), tolerance, fill=False, color=style["mec"], lw=0.8, ls=":",
                                   zorder=4))
        plane.annotate(str(k + 1), (wp[1], wp[0]), textcoords="offset points", xytext=(7, 7), fontsize=9,
                       fontweight="bold", color=style["mec"], zorder=5)
        if when is not None:
            alt.plot(when, -wp[2], ls="none", ms=7, zorder=4, **style)
            alt.axvline(when, color=style["mec"], lw=0.6, ls=":", zorder=0)
            alt.annotate(str(k + 1), (when, -wp[2]), textcoords="offset points", xytext=(5, 6), fontsize=9,
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


def tracking_error_figure(sim, *, title: str = "") -> Figure:
    """The position tracking error against time: north, east and down, and its norm ``|p - p_ref|``."""
    fig, ax = _over_time(3.8)
    err = sim.x[:, :3] - sim.x_ref[:, :3]
    for i, (name, color) in enumerate(zip(("pN", "pE", "pD"), COLORS)):
        trace(ax, sim.t, err[:, i], color=color, lw=1.2, label=f"{name} - reference")
    trace(ax, sim.t, np.linalg.norm(err, axis=1), color="k", lw=1.0, ls=":", label="|p - p_ref|")
    return _finished(fig, ax, "position error [m]", "tracking error", title)


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
    waypoints from ``tracking``, :func:`quadctl.pipeline.tracking_of`) and the tracking error,
    keyed by file stem."""
    return {name: make() for name, make in simulation_figure_makers(sim, partition, u_trim, title=title,
                                                                     actuators=actuators, tracking=tracking).items()}


def simulation_figure_makers(sim, partition: dict, u_trim=None, *, title: str = "", actuators=None,
                             tracking: dict | None = None) -> dict[str, Callable[[], Figure]]:
    """The figures of :func:`simulation_figures`, each not yet made: file stem -> a function that
    makes it (so that a caller can make, draw and drop one at a time, or share them out)."""
    makers = {name: partial(subsystem_figure, sim, name, sub.states, title=title) for name, sub in partition.items()}
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
