"""Figures of a gain schedule: its envelope against the scheduling variable, and a transition flown
with it and with one fixed design."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from quadctl.design.gain_table import VARIABLES, scheduling_values
from quadctl.layout import INPUT_NAMES, STATE_INDEX, STATE_NAMES
from quadctl.plots.drawing import COLORS, input_limits, limit_lines, trace
from quadctl.sim.run import STATUS_WORDS

GAIN_COLORS = tuple(f"C{n}" for n in range(10)) + ("black", "0.55")
"""Colours of the gain entries in turn (a decoupled design has 10 to 12 nonzero entries)."""
INPUT_STYLES = ("-", (0, (5, 5)), (5, (5, 5)), (0, (1, 2)))
"""Line style of a gain entry by its input (T, A, E, R): A's and E's dashes alternate, so a roll gain
and a pitch gain on one curve show both colours."""
SAME_CURVE = 5e-3
"""Two normalized gain curves (each over its largest magnitude) closer than this everywhere draw as one
line (a pixel of the panel's -1 to 1 is about 0.006): the legend names the first."""
INPUT_MARKERS = ("o", "s", "^", "D")
"""Marker of a gain entry's design points by its input (T, A, E, R)."""


def transition_figure(transition, *, title: str = "") -> Figure:
    """A transition flown with a gain schedule and with one fixed design
    (:class:`quadctl.schedule.transition.Transition`).

    Top: the scheduling variable flown by each and the reference's, with the schedule's grid
    values dotted. Middle: the pitch angle. Bottom: the thrust of the most loaded rotor
    against its limits; with box limits, the largest share of an input's room from its reference to the
    limit it moves toward (:func:`limit_share`, 1 at a limit); with no limits, the thrust's change from its
    reference (N). A run that stopped early ends with a cross.
    """

    runs, loop = transition.runs(), transition.loops["scheduled"]
    table, heading = loop.schedule, loop.schedule_heading
    fig = Figure(figsize=(10.0, 7.5), layout="constrained")
    speed_ax, angle_ax, rotor_ax = fig.subplots(3, 1, sharex=True)

    def variable(x):
        return scheduling_values(table.variable, x, heading)

    first = runs["scheduled"]
    trace(speed_ax, first.t, variable(first.x_ref), color="0.35", lw=1.0, ls="--", label="reference")
    for value in table.values:
        speed_ax.axhline(value, color="0.7", lw=0.6, ls=":")
    act = loop.actuators
    for (label, sim), color in zip(runs.items(), COLORS):
        ended = sim.status != "ok"
        trace(speed_ax, sim.t, variable(sim.x), color=color, lw=1.6, label=f"{label} ({STATUS_WORDS[sim.status]})")
        trace(angle_ax, sim.t, np.rad2deg(sim.x[:, STATE_INDEX["theta"]]), color=color, lw=1.3, label=label)
        ref = sim.u_ref if len(sim.u_ref) else loop.u_trim
        if act is not None and act.mode == "motors":
            load = act.commands(sim.u).max(axis=1)
        elif act is not None:
            load = limit_share(sim.u, ref, act.lo, act.hi).max(axis=1)
        else:
            load = np.abs(sim.u[:, 0] - np.broadcast_to(ref, sim.u.shape)[:, 0])
        trace(rotor_ax, sim.t, load, color=color, lw=1.2, label=label)
        if ended:
            for ax, y in ((speed_ax, variable(sim.x[-1:])[0]), (angle_ax, np.rad2deg(sim.x[-1, STATE_INDEX["theta"]])),
                          (rotor_ax, load[-1])):
                ax.plot(sim.t[-1], y, "x", color=color, ms=9, mew=2)
    if act is not None and act.mode == "motors":
        limit_lines(rotor_ax, (act.lo[0], act.hi[0]), "min / max thrust")
        rotor_ax.set_ylabel("most loaded rotor [N]")
    elif act is not None:
        limit_lines(rotor_ax, (np.inf, 1.0), "at a limit")
        rotor_ax.set_ylabel("largest share of an\ninput's limit [1]")
    else:
        rotor_ax.set_ylabel("thrust change\n|T - T_ref| [N]")
    speed_ax.set_ylabel(f"{table.variable} [{VARIABLES[table.variable]}]")
    angle_ax.set_ylabel("pitch theta [deg]")
    rotor_ax.set_xlabel("time [s]")
    for ax in (speed_ax, angle_ax, rotor_ax):
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8, frameon=False, ncols=2)
    what = f"{table.variable} schedule ({table.interpolation}) against one fixed design"
    fig.suptitle(f"{title}: {what}" if title else what)
    return fig


def limit_share(u, ref, lo, hi) -> np.ndarray:
    """Each input's move from ``ref`` as a share of its room to the limit it moves toward (N, 4): 0 at the
    reference, 1 at ``lo`` or ``hi`` (box limits, (4,)); 0 where that side is unlimited.

    Examples
    --------
    >>> limit_share([[1.5, -0.1, 0.0, 0.0]], [1.0, 0.0, 0.0, 0.0], [0.0, -0.2, -1.0, -1.0], [2.0, 0.2, 1.0, 1.0])
    array([[0.5, 0.5, 0. , 0. ]])
    """
    u, ref = np.atleast_2d(np.asarray(u, dtype=float)), np.asarray(ref, dtype=float)
    move = u - ref
    room = np.where(move >= 0, np.asarray(hi, dtype=float) - ref, ref - np.asarray(lo, dtype=float))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.isfinite(room) & (room > 0), np.abs(move) / room, 0.0)


def schedule_figure(sched, actuators=None, *, title: str = "") -> Figure:
    """The envelope of a gain schedule (:class:`quadctl.schedule.envelope.Schedule`) against its variable.

    Four panels: the block gain's nonzero entries (each over its largest magnitude: markers at the
    points, the interpolated table between them; one line style and marker per input, the legend
    beside the panel, naming the curves that coincide); the slowest pole and the least damping of the
    frozen-point loops along the fine grid (failures in red); the trim attitude (deg); the trim
    thrust (each rotor's, between ``min_thrust`` and ``max_thrust``, with ``motors:``; else ``T``
    and any ``limits:``). Values with no trim are marked by red dotted lines.

    Parameters
    ----------
    sched : quadctl.schedule.envelope.Schedule
    actuators : quadctl.physics.motors.Actuators, optional
        The setup's limits: drawn as lines on the thrust panel.
    """

    fig = Figure(figsize=(12.5, 7.5), layout="constrained")
    (ax_k, ax_p), (ax_a, ax_t) = fig.subplots(2, 2, sharex=True)
    good = [p for p in sched.points if p.designed]
    v = np.array([p.value for p in good])
    c = sched.checks
    K = sched.table.gains[:, :, :len(STATE_NAMES)]
    fine_K = sched.table.at(c.values)[:, :, :len(STATE_NAMES)]
    entries = [(i, j) for i in range(K.shape[1]) for j in range(K.shape[2]) if np.abs(K[:, i, j]).max() > 0]
    drawn: list[tuple[str, np.ndarray]] = []
    for n, (i, j) in enumerate(entries):
        scale = np.abs(K[:, i, j]).max()
        name, curve = f"K[{INPUT_NAMES[i]},{STATE_NAMES[j]}]", fine_K[:, i, j] / scale
        # one line style and marker per input, so that the entries of different inputs stay apart where
        # their curves coincide (roll and pitch designed alike, constant gains at +-1); the legend says so
        same = next((other for other, seen in drawn if np.allclose(curve, seen, rtol=0.0, atol=SAME_CURVE)), None)
        drawn.append((name, curve))
        color, style, marker = GAIN_COLORS[n % len(GAIN_COLORS)], INPUT_STYLES[i], INPUT_MARKERS[i]
        ax_k.plot(c.values, curve, color=color, lw=1.2, ls=style,
                  label=f"{name} ({scale:.3g})" + (f",\non {same}'s curve" if same else ""))
        ax_k.plot(v, K[:, i, j] / scale, marker, color=color, ms=3.5, mfc="none")
    ax_k.set_ylabel("gain / max |gain|")
    ax_k.set_title(f"gains ({sched.interpolation} between the points)", fontsize=9)
    # beside the panel, not over its curves (the layout makes room for it)
    ax_k.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, frameon=False, handlelength=3.0,
                title="entry (max |gain|)", title_fontsize=7)
    ax_p.plot(c.values, c.slowest, color=COLORS[0], lw=1.4, label="slowest pole")
    bad = ~c.stable & np.isfinite(c.slowest)
    if bad.any():
        ax_p.plot(c.values[bad], c.slowest[bad], "x", color=COLORS[1], ms=7, label="frozen loop UNSTABLE")
    ax_p.axhline(0.0, color="0.35", lw=0.8)
    ax_p.set_ylabel("slowest pole Re(s) [rad/s]")
    twin = ax_p.twinx()
    twin.plot(c.values, c.least_damping, color=COLORS[2], lw=1.2, ls="--", label="least damping")
    twin.set_ylabel("least damping ratio")
    lines = ax_p.get_legend_handles_labels()
    more = twin.get_legend_handles_labels()
    # "best" avoids only the lines of the legend's own axes: an unseen copy of the damping curve, in the
    # twin's coordinates, keeps the legend off it too (add_artist leaves the pole axis' limits alone)
    ax_p.add_artist(Line2D(c.values, c.least_damping, transform=twin.transData, visible=False))
    ax_p.legend(lines[0] + more[0], lines[1] + more[1], loc="best", fontsize=7, frameon=False)
    ax_p.set_title(f"frozen-point loops, grid {c.refinement}x finer", fontsize=9)
    trimmed = [p for p in sched.points if p.trimmed]
    tv = np.array([p.value for p in trimmed])
    for name, color in (("theta", COLORS[0]), ("phi", COLORS[1]), ("psi", COLORS[2])):
        ax_a.plot(tv, np.rad2deg([p.trim.x[STATE_INDEX[name]] for p in trimmed]), "o-", color=color, ms=3,
                  lw=1.2, label=name)
    ax_a.set_ylabel("trim attitude [deg]")
    ax_a.legend(loc="best", fontsize=7, frameon=False)
    rotors = actuators is not None and actuators.mode == "motors"
    if rotors:
        thrust = np.array([p.actuator_commands for p in trimmed])
        for i, (rotor, color) in enumerate(zip(actuators.names, COLORS)):
            ax_t.plot(tv, thrust[:, i], "o-", color=color, ms=3, lw=1.2, label=rotor)
        limit_lines(ax_t, (actuators.lo[0], actuators.hi[0]), "min / max thrust")
        ax_t.set_ylabel("trim rotor thrust [N]")
    else:
        ax_t.plot(tv, [p.trim.u[0] for p in trimmed], "o-", color=COLORS[0], ms=3, lw=1.2, label="T")
        if actuators is not None:
            limit_lines(ax_t, input_limits(actuators)[0][:1].tolist() + input_limits(actuators)[1][:1].tolist(),
                         "limit")
        ax_t.set_ylabel("trim thrust T [N]")
    ax_t.legend(loc="best", fontsize=7, frameon=False)
    missing = [p.value for p in sched.points if not p.designed]
    for ax in (ax_k, ax_p, ax_a, ax_t):
        for k, value in enumerate(missing):
            ax.axvline(value, color=COLORS[1], lw=0.9, ls=":", label="no trim" if k == 0 and ax is ax_a else None)
        ax.grid(True, alpha=0.3)
    if missing:
        ax_a.legend(loc="best", fontsize=7, frameon=False)
    for ax in (ax_a, ax_t):
        ax.set_xlabel(f"{sched.variable} [{sched.unit}]")
    head = f"gain schedule over {sched.variable}"
    fig.suptitle(f"{title}: {head}" if title else head)
    return fig
