"""A broken loop's frequency response: Bode (magnitude, phase) and Nyquist, with its margins marked."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from quadctl.plots.drawing import COLORS, place_labels

MAGNITUDE_SPAN_DB = 60.0
"""dB: the magnitude axis shows ``|L|`` within this of 0 dB (the crossover), or of the farthest finite gain margin
and 10 dB more: a lifted cascade's integrators reach +400 dB at the lowest frequency drawn and its zeros -300 dB
at Nyquist, which would squeeze the crossover into a few pixels."""


def magnitude_limits(mag_db, gain_margins_db=()) -> tuple[float, float]:
    """``(low, high)`` dB of the magnitude axis: the finite ``mag_db`` within :data:`MAGNITUDE_SPAN_DB` of 0 dB
    (wider to show every finite gain margin with 10 dB to spare, and the curve's point nearest 0 dB with
    10 dB more when it lies beyond that), 0 dB always inside, 5 % of the range padded.

    Examples
    --------
    >>> magnitude_limits([470.0, 25.0, 0.0, -140.0], (-25.0, 0.75))
    (-66.0, 66.0)
    >>> magnitude_limits([20.0, 0.0, -10.0])
    (-11.5, 21.5)
    >>> magnitude_limits([100.0, 80.0, 70.0])  # |L| never within 60 dB of 0 dB: its nearest point still shown
    (-4.0, 84.0)
    """
    mag = np.asarray(mag_db, dtype=float)
    mag = mag[np.isfinite(mag)]
    span = max([MAGNITUDE_SPAN_DB] + [abs(g) + 10.0 for g in gain_margins_db if g is not None and np.isfinite(g)])
    low = max(min(float(mag.min()), 0.0), -span) if mag.size else -span
    high = min(max(float(mag.max()), 0.0), span) if mag.size else span
    near = float(mag[np.argmin(np.abs(mag))]) if mag.size else 0.0
    if not low <= near <= high:  # no point of the curve in view
        low, high = min(low, near - 10.0), max(high, near + 10.0)
    pad = 0.05 * (high - low)
    return low - pad, high + pad


PHASE_SPAN_DEG = 180.0
"""deg: the phase axis shows the phase within this of -180 deg (the line the margins are read from; the
gain crossover's phase lies within it, :func:`phase_about_minus_180`), or of the phase at every phase
crossover and 20 deg more: a lifted cascade's integrators take the phase to -540 deg at the lowest frequency
drawn, which would squeeze the crossover into a third of the axis."""


def phase_limits(phase, crossings=()) -> tuple[float, float]:
    """``(low, high)`` deg of the phase axis: the finite ``phase`` within :data:`PHASE_SPAN_DEG` of -180 deg
    (wider to show the phase at each of the ``crossings`` with 20 deg to spare), -180 deg and the crossings
    always inside, 5 % of the range padded.

    Examples
    --------
    >>> phase_limits([-540.0, -170.0, -80.0])
    (-374.0, -66.0)
    >>> phase_limits([-600.0, -170.0, -80.0], (-540.0,))
    (-584.0, -56.0)
    """
    ph = np.asarray(phase, dtype=float)
    ph = ph[np.isfinite(ph)]
    marks = [-180.0] + [float(c) for c in crossings if np.isfinite(c)]
    floor = min([-180.0 - PHASE_SPAN_DEG] + [c - 20.0 for c in marks])
    ceiling = max([-180.0 + PHASE_SPAN_DEG] + [c + 20.0 for c in marks])
    low = max(min([float(ph.min())] + marks) if ph.size else floor, floor)
    high = min(max([float(ph.max())] + marks) if ph.size else ceiling, ceiling)
    pad = 0.05 * (high - low)
    return low - pad, high + pad


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


def margins_figure_name(m) -> str:
    """The file stem of a broken loop's figure, in ``plots/`` (``quadctl margins --plot``) and in the report
    alike: ``margins-<loop>-<model>`` for an LQR design's loop (a subsystem, on the model it is broken on),
    ``margins-<cascade>-<input>`` for a PID cascade's (one cascade, broken at each input in turn).

    Parameters
    ----------
    m : quadctl.design.margins.LoopMargins

    Examples
    --------
    >>> from types import SimpleNamespace as L
    >>> margins_figure_name(L(loop="roll", input="A", model="coupled"))
    'margins-roll-coupled'
    >>> margins_figure_name(L(loop="crazyflie", input="A", model="cascade"))
    'margins-crazyflie-A'
    """
    return f"margins-{m.loop}-{m.input if m.model == 'cascade' else m.model}"


def margins_figure(m, *, title: str = "") -> Figure:
    """Bode (magnitude, phase) and Nyquist plot of one broken loop, with its margins marked (an unstable loop's
    title says it has none); the magnitude
    axis about the crossover (:func:`magnitude_limits`), the phase axis about -180 deg (:func:`phase_limits`),
    each margin's label where it crosses no curve (:func:`quadctl.plots.drawing.place_labels`).

    Parameters
    ----------
    m : quadctl.design.margins.LoopMargins
    """
    fig = Figure(figsize=(10.0, 5.2), layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=(1.25, 1.0))
    ax_mag = fig.add_subplot(grid[0, 0])
    ax_ph = fig.add_subplot(grid[1, 0], sharex=ax_mag)
    ax_ny = fig.add_subplot(grid[:, 1])
    w, L = m.freq, m.response
    crossover = None if m.gain_crossover_freq is None else int(np.argmin(np.abs(np.log(w / m.gain_crossover_freq))))
    phase = phase_about_minus_180(L, crossover)
    with np.errstate(divide="ignore"):  # a zero of L on the grid: -inf dB, off the axis
        mag = 20 * np.log10(np.abs(L))
    ax_mag.semilogx(w, mag, color=COLORS[0], lw=1.5)
    ax_mag.set_ylim(*magnitude_limits(mag, m.gain_margin_db))
    ax_mag.axhline(0.0, color="0.35", lw=0.9, ls="--")
    ax_mag.set_ylabel("|L| [dB]")
    ax_ph.semilogx(w, phase, color=COLORS[0], lw=1.5)
    crossings = [wg for wg in m.phase_crossover_freqs if wg is not None]
    low, high = phase_limits(phase, [phase[int(np.argmin(np.abs(np.log(w / wg))))] for wg in crossings])
    ax_ph.set_ylim(low, high)
    for k in range(-3, 2):
        if low <= -180 + 360 * k <= high:
            ax_ph.axhline(-180 + 360 * k, color="0.35", lw=0.9, ls="--")
    ax_ph.set_ylabel("phase of L [deg]")
    ax_ph.set_xlabel("frequency [rad/s]")
    labels = []
    if m.gain_crossover_freq is not None:  # read from -180 deg: the curve is PM above it there
        for ax in (ax_mag, ax_ph):
            ax.axvline(m.gain_crossover_freq, color=COLORS[2], lw=1.0, ls=":")
        labels.append(ax_ph.annotate(f"PM {m.phase_margin_deg:.3g} deg", (m.gain_crossover_freq, -180.0),
                                     xytext=(0, 0), textcoords="offset points", fontsize=8, color=COLORS[2]))
    for wg, gm in zip(m.phase_crossover_freqs, m.gain_margin_db):
        if wg is not None:
            for ax in (ax_mag, ax_ph):
                ax.axvline(wg, color=COLORS[1], lw=1.0, ls=":")
            labels.append(ax_mag.annotate(f"GM {gm:+.3g} dB", (wg, 0.0), xytext=(0, 0), textcoords="offset points",
                                          fontsize=8, color=COLORS[1]))
    if m.sample_time:  # labelled at the top: a gain margin often sits at the Nyquist frequency
        ax_mag.axvline(np.pi / m.sample_time, color="0.5", lw=0.9)
        ax_mag.annotate("Nyquist", (np.pi / m.sample_time, 1.0), xycoords=("data", "axes fraction"),
                        xytext=(-3, -3), textcoords="offset points", fontsize=8, color="0.4", ha="right", va="top")
    for ax in (ax_mag, ax_ph):
        ax.grid(True, which="both", alpha=0.3)
    ax_ny.plot(L.real, L.imag, color=COLORS[0], lw=1.5, label="L(jw), w > 0")
    ax_ny.plot(L.real, -L.imag, color=COLORS[0], lw=1.0, ls="--", alpha=0.6, label="w < 0")
    circle = np.exp(1j * np.linspace(0, 2 * np.pi, 361))
    ax_ny.plot(circle.real, circle.imag, color="0.6", lw=0.8, label="|L| = 1")
    disk = -1 + m.min_return_difference * circle  # L never enters this disk around -1
    ax_ny.plot(disk.real, disk.imag, color=COLORS[3], lw=1.0, label=f"min |1+L| = {m.min_return_difference:.3g}")
    ax_ny.plot(-1, 0, "x", color=COLORS[1], ms=9, mew=2, label="-1, the critical point")
    ax_ny.set_xlim(-3, 2)
    ax_ny.set_ylim(-2.5, 2.5)
    ax_ny.set_aspect("equal", adjustable="box")
    ax_ny.set_xlabel("Re L")
    ax_ny.set_ylabel("Im L")
    ax_ny.grid(True, alpha=0.3)
    ax_ny.legend(loc="best", fontsize=7, frameon=False)  # five entries: where the curves leave room
    kind = f"sampled, Ts = {m.sample_time * 1e3:.3g} ms" if m.sample_time else "continuous"
    head = (f"{m.loop} PID cascade broken at {m.input} (the rest of it closed; lifted, frequencies at its "
            f"{m.sample_time * 1e3:.3g} ms sample)"
            if m.model == "cascade" else f"{m.loop} loop broken at {m.input} ({m.model} model, {kind})")
    if not m.stable:  # no margin marked: it has none
        head += ": closed loop unstable, no margins"
    fig.suptitle(f"{title}: {head}" if title else head)
    place_labels(fig, labels)  # last: measured on the figure as laid out
    return fig
