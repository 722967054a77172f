"""Figures of a sweep: the trade-off between two metrics, and a Monte Carlo's percentile bands."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from quadctl.layout import unit_of
from quadctl.plots.drawing import COLORS, axis_label, displayed


def sweep_tradeoff_figure(rows, x: str, y: str, gates=(), *, title: str = "") -> Figure:
    """A sweep's trade-off: metric ``y`` against metric ``x``, one point per case.

    Passing cases are dots, failing ones red crosses; gate thresholds on either axis are
    dashed lines. Cases without both values (no design, never settled) are counted in the title; the
    legend counts each kind and, where some draw over others, the places they draw at (:func:`_places`).

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
        if family == "tracking":
            return "m"
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
    drawn = {}
    for passed, style in ((True, {"s": 14, "color": COLORS[0], "alpha": 0.7}),
                          (False, {"s": 22, "color": COLORS[1], "marker": "x"})):
        if plotted[passed][0]:  # no empty "fail (0)" in the legend
            drawn[passed] = ax.scatter(*plotted[passed], **style)
    labelled = False
    for gate in gates:
        for bound in (gate.min, gate.max):
            if bound is None or gate.metric not in (x, y):
                continue
            line = ax.axvline if gate.metric == x else ax.axhline
            line(bound, color="0.3", ls="--", lw=1.0, label=None if labelled else "gate")
            labelled = True
    values = plotted[True][1] + plotted[False][1]
    if y.startswith("tracking.") and values and min(values) > 0:  # errors of many decades, a gate far above them
        ax.set_yscale("log")
    for passed, points in drawn.items():  # labelled once the axes' limits are final (the gates widen them)
        n, places = len(plotted[passed][0]), _places(ax, *plotted[passed])
        where = "" if places in (None, n) else f" at {places} places"  # cases the parameters move off neither axis
        points.set_label(f"{'pass' if passed else 'fail'} ({n}{where})")
    ax.set_xlabel(f"{x} [{unit(x)}]" if unit(x) else x)
    ax.set_ylabel(f"{y} [{unit(y)}]" if unit(y) else y)
    ax.grid(True, alpha=0.3)
    if ax.get_legend_handles_labels()[0]:  # nothing plotted and no gate: no empty legend
        ax.legend(loc="best", fontsize=8, frameon=False)
    note = f"; {missing} cases without both values" if missing else ""
    fig.suptitle(f"{title}: sweep trade-off ({len(rows)} cases{note})" if title else
                 f"sweep trade-off ({len(rows)} cases{note})")
    return fig


OVERLAP = 0.01
"""Points closer than this share of each axis's span draw as one (a marker is about that wide)."""


def _places(ax, xs, ys) -> int | None:
    """How many places the points ``(xs, ys)`` draw at on ``ax``: a point within :data:`OVERLAP` of each
    axis's span (its limits, on its scale) of one counted before it is drawn over by it (a parameter that
    moves neither metric stacks its cases on one point). None past :data:`PLACES_MAX` points."""
    if len(xs) > PLACES_MAX:
        return None
    scaled = []
    for values, (lo, hi), scale in ((xs, ax.get_xlim(), ax.get_xscale()), (ys, ax.get_ylim(), ax.get_yscale())):
        v, lo, hi = (np.log10(values), np.log10(lo), np.log10(hi)) if scale == "log" else (np.asarray(values), lo, hi)
        scaled.append((v - lo) / (hi - lo) if hi > lo else np.zeros(len(v)))
    points = np.column_stack(scaled)
    kept = points[:1]
    for point in points[1:]:
        if not np.any(np.all(np.abs(kept - point) <= OVERLAP, axis=1)):
            kept = np.vstack([kept, point])
    return len(kept)


PLACES_MAX = 5000
"""Points past which the trade-off's legend does not count the places they draw at (a quadratic count)."""


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
    for r, ((name, states), color) in enumerate(zip(rows, COLORS * 3)):
        for c in range(ncols):
            top, below = axes[2 * r, c], axes[2 * r + 1, c]
            if c >= len(states):
                top.set_visible(False)
                below.set_visible(False)
                continue
            j = bands.states.index(states[c])
            p = {q: displayed(states[c], bands.bands[k, :, j])[0] for q, k in level.items()}
            unit = displayed(states[c], bands.bands[0, :1, j])[1]
            for ax, centre in ((top, 0.0), (below, p[50])):
                ax.fill_between(bands.t, p[5] - centre, p[95] - centre, color=color, alpha=0.2, lw=0,
                                label="5-95 %")
                ax.fill_between(bands.t, p[25] - centre, p[75] - centre, color=color, alpha=0.5, lw=0,
                                label="25-75 %")
                ax.axhline(0.0, color="0.35", lw=0.8, ls="--")
                ax.grid(True, alpha=0.3)
            top.plot(bands.t, p[50], color=color, lw=1.4, label="median")
            top.set_ylabel(f"Δ{axis_label(states[c])} [{unit}]")
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
