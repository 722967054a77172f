"""A gust in a steady wind: the Crazyflie in crazyflie-wind.

The bundled crazyflie-wind config: a Crazyflie trimmed in a 9.7 m/s east wind, hit at 5 s by a
1-cosine gust (MIL-F-8785C) of 2 m/s from the north rising over 0.5 s, flown with the gust alone and
with the config's moderate Dryden turbulence too: the north wind, the north drift (position is not
regulated) and the pitch from the trim.

Run from a clone: ``python examples/wind_gust.py [FOLDER]`` writes crazyflie-gust.png into FOLDER
(default: docs/figures/) and prints each run's peaks.
"""

import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

import quadctl as qc
from quadctl import config, pipeline, run_summary
from quadctl.config import overrides
from quadctl.layout import STATE_INDEX

OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "docs" / "figures"

runs = {}
for label, sets in (("gust", ["simulation.wind.turbulence=null"]), ("gust and turbulence", [])):
    stages = qc.Stages(qc.setup_of(overrides.load(config.locate("crazyflie-wind"), sets)))
    sim = runs[label] = pipeline.simulation_of(stages.setup, stages.loop)
    err = sim.x - sim.x_ref
    ground, air = run_summary.speeds(sim)
    print(f"crazyflie-wind, {label}: status {sim.status}; "
          f"peak |pN drift| {np.abs(err[:, STATE_INDEX['pN']]).max():.3g} m, "
          f"peak |theta - trim| {np.rad2deg(np.abs(err[:, STATE_INDEX['theta']]).max()):.3g} deg, "
          f"ground speed max {ground.max():.3g} m/s, airspeed max {air.max():.3g} m/s")

fig = Figure(figsize=(8.0, 6.0), layout="constrained")
ax = fig.subplots(3, 1, sharex=True)
for label, sim in runs.items():
    ls = "-" if "turbulence" not in label else ":"
    ax[0].plot(sim.t, sim.wind[:, 0], lw=1.2, ls=ls, label=f"wind N, {label}")
    err = sim.x - sim.x_ref
    ax[1].plot(sim.t, err[:, STATE_INDEX["pN"]], lw=1.2, ls=ls, label=f"pN, {label}")
    ax[2].plot(sim.t, np.rad2deg(err[:, STATE_INDEX["theta"]]), lw=1.2, ls=ls, label=f"theta, {label}")
ax[0].set_ylabel("wind N [m/s]")
ax[1].set_ylabel("pN drift [m]")
ax[2].set_ylabel("pitch from trim [deg]")
ax[2].set_xlabel("time [s]")
for a in ax:
    a.grid(True, alpha=0.3)
    a.legend(fontsize=7, frameon=False, loc="upper left")
fig.suptitle("crazyflie-wind: 1-cosine gust (MIL-F-8785C), 2 m/s north rising over 0.5 s, in a 9.7 m/s east wind")
OUT.mkdir(parents=True, exist_ok=True)
fig.savefig(OUT / "crazyflie-gust.png", dpi=80)
print(f"wrote {OUT / 'crazyflie-gust.png'}")
