"""Figures of a simulation, like the report's figures 2-4, as matplotlib Figures.

The caller saves them. Angles and rates are shown in degrees (artifacts keep radians).
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from quadctl.layout import INPUT_NAMES, STATE_INDEX, unit_of

_DEGREES = {"phi", "theta", "psi", "p", "q", "r"}
_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd")


def _display(name: str, values: np.ndarray) -> tuple[np.ndarray, str]:
    if name in _DEGREES:
        unit = unit_of(name).replace("rad", "deg")
        return np.rad2deg(values), unit
    return values, unit_of(name)


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
        ax.plot(sim.t, y, color=color, lw=1.6, label=state)
        ax.plot(sim.t, ref, color="0.35", lw=1.0, ls="--", label="reference")
        ax.set_ylabel(f"{state} [{unit}]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=8, frameon=False)
    axes[-1].set_xlabel("time [s]")
    status = "" if sim.status == "ok" else f" ({sim.status})"
    fig.suptitle(f"{title}: {name} subsystem{status}" if title else f"{name} subsystem{status}")
    return fig


def inputs_figure(sim, u_trim=None, *, title: str = "") -> Figure:
    """The four inputs T, A, E, R against time, with their trim values dashed."""
    fig = Figure(figsize=(7.5, 7.0), layout="constrained")
    axes = fig.subplots(len(INPUT_NAMES), 1, sharex=True)
    for j, (ax, name, color) in enumerate(zip(axes, INPUT_NAMES, _COLORS)):
        ax.plot(sim.t, sim.u[:, j], color=color, lw=1.6, label=name)
        if u_trim is not None:
            ax.axhline(u_trim[j], color="0.35", lw=1.0, ls="--", label="trim")
        ax.set_ylabel(f"{name} [{unit_of(name)}]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=8, frameon=False)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{title}: inputs" if title else "inputs")
    return fig


def simulation_figures(sim, partition: dict, u_trim=None, *, title: str = "") -> dict[str, Figure]:
    """A figure per subsystem (in partition order) and one of the inputs, keyed by file stem."""
    figs = {name: subsystem_figure(sim, name, sub.states, title=title)
            for name, sub in partition.items()}
    figs["inputs"] = inputs_figure(sim, u_trim, title=title)
    return figs
