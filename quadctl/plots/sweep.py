"""Figures of a sweep: the trade-off between two metrics, and a Monte Carlo's percentile bands."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from quadctl.layout import unit_of
from quadctl.plots.drawing import COLORS, axis_label, displayed


def sweep_tradeoff_figure(rows, x: str, y: str, gates=(), *, title: str = "") -> Figure:
    """A sweep's trade-off: metric ``y`` against metric ``x``, one point per case.

    Passing cases are dots, failing ones red crosses; gate thresholds on either axis are
    dashed lines. A case with ``x`` but no settling time ``y`` is drawn on a strip above the plot, at
    its ``x``, in a row for why it has none (:data:`UNSETTLED`); the legend counts each kind and, where some draw
    over others, the places they draw at (:func:`_places`). Cases without ``x``, or without a ``y``
    of another kind, are counted in the title.

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
        if family == "margin":
            return {"gain_db": "dB", "phase_deg": "deg"}.get(name, "")
        return "rad/s" if family == "eig" else ""

    fig = Figure(figsize=(7.5, 5.0), layout="constrained")
    plotted = {True: ([], []), False: ([], [])}
    unsettled: dict[tuple[bool, str], list] = {}  # (passed, why) -> x of the cases on the top strip
    missing = 0
    for row in rows:
        vx, vy = row.get(x), row.get(y)
        passed = bool(row.get("pass"))
        if _finite(vx) and _finite(vy):
            plotted[passed][0].append(vx)
            plotted[passed][1].append(vy)
        elif _finite(vx) and y.startswith("settling_time."):
            unsettled.setdefault((passed, _why_unsettled(row, y)), []).append(vx)
        else:
            missing += 1
    if unsettled:  # a strip above the plot, sharing its x axis: each reason a row
        top, ax = fig.subplots(2, 1, sharex=True, height_ratios=[1, 8])
        top.set_yticks([])
        top.set_ylim(len(UNSETTLED), -1)
        top.set_ylabel(f"no {y.partition('.')[0].replace('_', ' ')}", rotation=0, ha="right", va="center",
                       fontsize=8)
        top.grid(True, axis="x", alpha=0.3)
    else:
        top, ax = None, fig.subplots()
    drawn = {}
    for passed, style in ((True, {"s": 14, "color": COLORS[0], "alpha": 0.7}),
                          (False, {"s": 22, "color": COLORS[1], "marker": "x"})):
        if plotted[passed][0]:  # no empty "fail (0)" in the legend
            drawn[passed] = ax.scatter(*plotted[passed], **style)
    strip = []
    for (passed, why), xs in sorted(unsettled.items(), key=lambda item: (not item[0][0], item[0][1])):
        points = top.scatter(xs, np.full(len(xs), list(UNSETTLED).index(why)), marker=UNSETTLED[why], s=26,
                             facecolors="none", linewidths=1.0, edgecolors=COLORS[0] if passed else COLORS[1])
        strip.append((points, f"{'pass' if passed else 'fail'}, {why} ({len(xs)})"))
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
        # cases the parameters move off neither axis
        where = "" if places in (None, n) else f" at {places} place{'' if places == 1 else 's'}"
        points.set_label(f"{'pass' if passed else 'fail'} ({n}{where})")
    for points, label in strip:
        points.set_label(label)
    if top is not None and not values:
        ax.set_yticks([])
    ax.set_xlabel(f"{x} [{unit(x)}]" if unit(x) else x)
    ax.set_ylabel(f"{y} [{unit(y)}]" if unit(y) else y)
    ax.grid(True, alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    if top is not None:
        handles, labels = [*handles, *(p for p, _ in strip)], [*labels, *(label for _, label in strip)]
    if handles:  # nothing plotted and no gate: no empty legend
        ax.legend(handles, labels, loc="best", fontsize=8, frameon=False)
    note = f"; {missing} {'case' if missing == 1 else 'cases'} without both values" if missing else ""
    fig.suptitle(f"{title}: sweep trade-off ({len(rows)} cases{note})" if title else
                 f"sweep trade-off ({len(rows)} cases{note})")
    return fig


UNSETTLED = {"noise-limited": "^", "never settled": "v", "run stopped": "X"}
"""Why a case has no settling time, and its marker on the trade-off's strip (a row each, in this order):
noise-limited (:func:`quadctl.metrics.noise_limited`), outside its band at the end, or a run that did not
finish."""


def _finite(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and bool(np.isfinite(value))


def _why_unsettled(row: dict, metric: str) -> str:
    """The key of :data:`UNSETTLED` for a row with no ``metric`` (a ``settling_time.<state>``)."""
    if row.get("status", "ok") != "ok":
        return "run stopped"
    return "noise-limited" if metric.partition(".")[2] in row.get("noise_limited", ()) else "never settled"


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
            below.set_ylabel(f"about median\n[{unit}]", fontsize=8)
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
