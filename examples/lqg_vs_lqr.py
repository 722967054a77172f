"""LQG against LQR: the same gains, through a Kalman filter.

mambo-200hz's gains flown with full-state feedback (on the noisy measured state) and through the
steady-state Kalman filter of docs/configs/mambo-lqg.yaml (imu and mocap), with the same noise: the
altitude, roll and pitch errors, and the filter's error on the climb rate w, a state it does not
measure. The filter learns the initial offset, then averages the noise away.

Run from a clone: ``python examples/lqg_vs_lqr.py [FOLDER]`` writes lqg-vs-lqr.png into FOLDER
(default: docs/figures/) and prints the RMS errors over the second half of each run.
"""

import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

import quadctl as qc
from quadctl import pipeline
from quadctl.layout import STATE_INDEX
from quadctl.physics.noise import rms_deviation

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "figures"

runs = {}
for label, source in (("full state", "mambo-200hz"), ("LQG", ROOT / "docs" / "configs" / "mambo-lqg.yaml")):
    stages = qc.Stages(qc.setup_of(qc.load_config(source)))
    sim = runs[label] = pipeline.simulation_of(stages.setup, stages.loop)
    rms = rms_deviation(sim.t, sim.x, sim.x_ref, sim.t[-1] / 2)
    print(f"{label}: {sim.status}; RMS second half: pD {rms['pD'] * 100:.3g} cm, phi "
          f"{np.degrees(rms['phi']):.3g} deg, theta {np.degrees(rms['theta']):.3g} deg")
full, lqg = runs["full state"], runs["LQG"]
err = rms_deviation(lqg.t, lqg.x, lqg.x_hat, lqg.t[-1] / 2)
print("LQG estimation error RMS (second half): " + ", ".join(f"{k} {v:.3g}" for k, v in err.items()))

fig = Figure(figsize=(9.0, 5.6), layout="constrained")
axes = fig.subplots(2, 2, sharex=True).ravel()
for ax, name, scale, unit in zip(axes[:3], ("pD", "phi", "theta"), (100.0, 180 / np.pi, 180 / np.pi),
                                 ("cm", "deg", "deg")):
    i = STATE_INDEX[name]
    for label, sim, style in (("full-state LQR (measured x)", full, "-"),
                              ("LQG (Kalman filter on imu + mocap)", lqg, "--")):
        ax.plot(sim.t, (sim.x[:, i] - sim.x_ref[:, i]) * scale, style, lw=1.0, label=label)
    ax.set_ylabel(f"{name} error [{unit}]")
    ax.grid(True, alpha=0.3)
axes[0].legend(fontsize=8, frameon=False)
w = STATE_INDEX["w"]
axes[3].plot(lqg.t, (lqg.x[:, w] - lqg.x_hat[:, w]) * 100, lw=0.8, color="C2")
axes[3].set_ylabel("w - w_hat [cm/s] (not measured)")
axes[3].grid(True, alpha=0.3)
for ax in axes[2:]:
    ax.set_xlabel("time [s]")
fig.suptitle("mambo-200hz: the same gains, full state against LQG (same noise seed)")
OUT.mkdir(parents=True, exist_ok=True)
fig.savefig(OUT / "lqg-vs-lqr.png", dpi=80)
print(f"wrote {OUT / 'lqg-vs-lqr.png'}")
