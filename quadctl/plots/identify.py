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
        t = fit.t
        cut = max(1, t.size // 4000)  # the figure's pixels, not every sample
        left.plot(t[::cut], fit.measured[::cut, k], color=COLORS[0], lw=0.6, label="measured")
        left.plot(t[::cut], fit.predicted[::cut, k], color=COLORS[1], lw=0.6, label="model")
        left.set_ylabel(fit.rows[k])
        left.set_title(f"{stage}: {fit.rows[k]}, measured and predicted", fontsize=9)
        left.legend(loc="upper right", fontsize=8)
        left.grid(alpha=0.3)
        res = fit.residual[:, k]
        right.plot(t[::cut], res[::cut], color=COLORS[2], lw=0.5)
        right.axhline(0.0, color="k", lw=0.5)
        right.set_title(f"residual, RMS {np.sqrt(np.mean(res ** 2)):.3g}", fontsize=9)
        right.grid(alpha=0.3)
        for ax in (left, right):
            ax.set_xlabel("t (s)")
    fig.tight_layout()
    return png_bytes(fig)
