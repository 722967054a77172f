"""Figures of an identification: each stage's fitted quantity, measured against predicted, and the residual."""

from __future__ import annotations

import re

import numpy as np
from matplotlib.figure import Figure

from quadctl.plots.drawing import COLORS, png_bytes, wrap_titles


def identification_figure(ident) -> Figure:
    """One row per fitted quantity (thrust, torques): measured and predicted over time, and the residual.

    Each row's titles name the log its stage was fitted on and the quantity (the residual's too, without the
    stage, which the row's first title gives: the narrower panel keeps it on one line). The model is drawn
    first and wider, the measurement over it, thinner and partly transparent, so both show where they agree;
    the legend is the figure's, above the panels, never over data. A title wider than its panel (a long log name) is
    broken into lines.

    Parameters
    ----------
    ident : quadctl.identify.results.Identification
        Its ``fits`` (per stage: ``t``, ``measured``, ``predicted``, ``residual`` and ``rows``, each
        row's name with its unit in parentheses), ``logs`` (each with a ``name``) and ``stage_logs``.
    """
    panels = [(stage, k, fit) for stage, fit in ident.fits.items() for k in range(fit.measured.shape[1])]
    fig = Figure(figsize=(10, 2.6 * len(panels) + 0.4), layout="constrained")
    axes = fig.subplots(len(panels), 2, squeeze=False, gridspec_kw={"width_ratios": [3, 2]})
    for row, (stage, k, fit) in enumerate(panels):
        left, right = axes[row]
        log = ident.logs[ident.stage_logs[stage]].name
        unit = _unit(fit.rows[k])
        cut = max(1, fit.t.size // 4000)  # the figure's pixels, not every sample
        t, measured, predicted = _broken(fit.t[::cut], fit.measured[::cut, k], fit.predicted[::cut, k])
        left.plot(t, predicted, color=COLORS[1], lw=1.3, alpha=0.9, label="model", zorder=2)
        left.plot(t, measured, color=COLORS[0], lw=0.6, alpha=0.75, label="measured", zorder=3)
        left.set_ylabel(f"{_quantity(fit.rows[k])} [{unit}]" if unit else fit.rows[k])  # [N], as every axis
        left.set_title(f"{log}, {stage}: {fit.rows[k]}, measured and predicted", fontsize=9)
        left.grid(alpha=0.3)
        res = fit.residual[:, k]
        right.plot(t, measured - predicted, color=COLORS[2], lw=0.5)
        right.axhline(0.0, color="k", lw=0.5)
        right.set_ylabel(f"measured - model [{unit}]" if unit else "measured - model")
        right.set_title(f"{log}: {_quantity(fit.rows[k])} residual, RMS "
                        f"{np.sqrt(np.mean(res ** 2)):.3g} {unit}".rstrip(), fontsize=9)
        right.grid(alpha=0.3)
        for ax in (left, right):
            ax.set_xlabel("time [s]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles[::-1], labels[::-1], loc="outside upper center", ncols=2, fontsize=8, frameon=False)
    wrap_titles(fig)  # a long log name (a ULog's) would run a title off its panel
    return fig


def fit_figure(ident) -> bytes:
    """PNG of :func:`identification_figure`."""
    return png_bytes(identification_figure(ident))


def _unit(row: str) -> str:
    """The unit in a fitted row's name, ``"thrust (N)"`` -> ``"N"`` (empty without one)."""
    found = re.search(r"\(([^()]*)\)\s*$", row)
    return found.group(1) if found else ""


def _quantity(row: str) -> str:
    """A fitted row's name without its unit, ``"roll torque (N m)"`` -> ``"roll torque"``."""
    return re.sub(r"\s*\([^()]*\)\s*$", "", row)


def _broken(t, *series):
    """``t`` and ``series`` with a NaN between windows, so no line joins one window to the next."""
    step = np.median(np.diff(t)) if t.size > 1 else 0.0
    gaps = np.nonzero(np.diff(t) > 10 * step)[0] + 1
    return (np.insert(t, gaps, np.nan),) + tuple(np.insert(s.astype(float), gaps, np.nan) for s in series)
