"""Laws overlaid (:mod:`quadctl.compare`): one figure per quantity, each law a line."""

from __future__ import annotations

import textwrap

import numpy as np
from matplotlib.figure import Figure

from quadctl.layout import STATE_INDEX
from quadctl.plots.drawing import COLORS, trace
from quadctl.sim.run import STATUS_WORDS

QUANTITIES: tuple[tuple[str, str], ...] = (
    ("position-error", "|p - p_ref| [m]"),
    ("altitude", "pD - reference [m]"),
    ("attitude-error", "|attitude - reference| [rad]"),
    ("rotor-use", "largest rotor thrust / max [1]"),
)
"""Each figure: file stem and axis label."""


def _values(name: str, run, loop) -> np.ndarray:
    err = run.x - run.x_ref
    if name == "position-error":
        return np.linalg.norm(err[:, :3], axis=1)
    if name == "altitude":
        return err[:, STATE_INDEX["pD"]]
    if name == "attitude-error":
        return np.linalg.norm(err[:, STATE_INDEX["phi"]:STATE_INDEX["psi"] + 1], axis=1)
    act = loop.actuators
    return (run.u @ act.mix.T).max(axis=1) / float(np.max(act.hi))


def comparison_figures(laws, *, title: str = "", notes: dict[str, str] | None = None) -> dict[str, Figure]:
    """``{stem: figure}``: each of :data:`QUANTITIES` against time, the laws overlaid (the rotor use only
    when the plant has rotors). A run that stopped early (it diverged or left the model's valid range) ends
    with a cross, its legend entry saying why and when.

    Parameters
    ----------
    laws : sequence
        Each with ``name``, ``run`` (a SimResult), ``loop`` (its ClosedLoop) and ``metrics``
        (:func:`quadctl.compare.metrics_of`: ``rotor_peak`` None without rotors).
    notes : dict, optional
        ``{stem: sentence}``: said above that figure's axes, wrapped to its width (such as
        :func:`quadctl.present.compare.free_position_sentence` on the position error).
    """
    notes = notes or {}
    out = {}
    for stem, label in QUANTITIES:
        if stem == "rotor-use" and any(law.metrics.get("rotor_peak") is None for law in laws):
            continue  # no rotors (no motors:): the plant takes the inputs themselves
        fig = Figure(figsize=(10.0, 3.6), layout="constrained")
        ax = fig.subplots()
        for k, law in enumerate(laws):
            run, color = law.run, COLORS[k % len(COLORS)]
            values = _values(stem, run, law.loop)
            ended = run.status != "ok" and len(run.t)
            entry = f"{law.name}, {STATUS_WORDS[run.status]} at {run.t[-1]:.3g} s" if ended else law.name
            trace(ax, run.t, values, color=color, lw=1.2, label=entry)
            if ended:  # where the run stopped: its line ends there, not the quantity
                ax.plot(run.t[-1], values[-1], "x", color=color, ms=9, mew=2, zorder=4)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8, frameon=False)
        if notes.get(stem):
            ax.set_title(textwrap.fill(notes[stem], 130), fontsize=8, loc="left")
        what = stem.replace("-", " ")
        fig.suptitle(f"{title}: {what}" if title else what)
        out[stem] = fig
    return out
