"""Figures of an identification: each stage's fitted quantity, measured against predicted, and the residual."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from quadctl.plots.drawing import COLORS, png_bytes


def fit_figure(ident) -> bytes:
    """PNG: one row per fitted quantity (thrust, torques), measured and predicted over time, and the residual."""
    panels = [(stage, k, fit) for stage, fit in ident.fits.items() for k in range(fit.measured.shape[1])]
    fig = Figure(figsize=(10, 2.6 * len(panels)))
    axes = fig.subplots(len(panels), 2, squeeze=False, gridspec_kw={"width_ratios": [3, 2]})
    for row, (stage, k, fit) in enumerate(panels):
        left, right = axes[row]
        cut = max(1, fit.t.size // 4000)  # the figure's pixels, not every sample
        t, measured, predicted = _broken(fit.t[::cut], fit.measured[::cut, k], fit.predicted[::cut, k])
        left.plot(t, measured, color=COLORS[0], lw=0.6, label="measured")
        left.plot(t, predicted, color=COLORS[1], lw=0.6, label="model")
        left.set_ylabel(fit.rows[k])
        left.set_title(f"{stage}: {fit.rows[k]}, measured and predicted", fontsize=9)
        left.legend(loc="upper right", fontsize=8)
        left.grid(alpha=0.3)
        res = fit.residual[:, k]
        right.plot(t, measured - predicted, color=COLORS[2], lw=0.5)
        right.axhline(0.0, color="k", lw=0.5)
        right.set_title(f"residual, RMS {np.sqrt(np.mean(res ** 2)):.3g}", fontsize=9)
        right.grid(alpha=0.3)
        for ax in (left, right):
            ax.set_xlabel("t (s)")
    fig.tight_layout()
    return png_bytes(fig)


def _broken(t, *series):
    """``t`` and ``series`` with a NaN between windows, so no line joins one window to the next."""
    step = np.median(np.diff(t)) if t.size > 1 else 0.0
    gaps = np.nonzero(np.diff(t) > 10 * step)[0] + 1
    return (np.insert(t, gaps, np.nan),) + tuple(np.insert(s.astype(float), gaps, np.nan) for s in series)
