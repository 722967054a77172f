"""Rotor lag and delay: mambo-200hz's weights on four plants.

Instantaneous rotors; a 30 ms rotor lag the design ignores; the same lag included in the design; one
sample (5 ms) of delay between measurement and command. Roll and pitch from the trim and rotor 1's
thrust over the first 1.5 s: the lag ignored rings at about 5 Hz, the design that includes it does
not, the delay hardly shows.

Run from a clone: ``python examples/lag_and_delay.py [FOLDER]`` writes lag-and-delay.png into FOLDER
(default: docs/figures/) and prints the peak roll of each run after 0.2 s.
"""

import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

import quadctl as qc
from quadctl import pipeline
from quadctl.layout import STATE_INDEX
from quadctl.physics import motors

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "figures"
CONFIGS = ROOT / "docs" / "configs"  # the guide's configs: mambo-200hz with a lag or a delay

runs = {}
for label, source in (("instantaneous rotors", "mambo-200hz"),
                      ("30 ms rotor lag, ignored by the design", CONFIGS / "mambo-rotor-lag.yaml"),
                      ("30 ms rotor lag, included in the design", CONFIGS / "mambo-rotor-lag-include.yaml"),
                      ("one sample (5 ms) of delay", CONFIGS / "mambo-delay.yaml")):
    stages = qc.Stages(qc.setup_of(qc.load_config(source)))
    sim = runs[label] = pipeline.simulation_of(stages.setup, stages.loop)
    err = np.rad2deg(np.abs(sim.x - sim.x_ref)[:, STATE_INDEX["phi"]])
    print(f"{label}: status {sim.status}; peak |phi - trim| after 0.2 s {err[sim.t > 0.2].max():.3g} deg")

fig = Figure(figsize=(8.0, 6.4), layout="constrained")
ax = fig.subplots(3, 1, sharex=True)
for label, sim in runs.items():
    err = sim.x - sim.x_ref
    ax[0].plot(sim.t, np.rad2deg(err[:, STATE_INDEX["phi"]]), lw=1.1, label=label)
    ax[1].plot(sim.t, np.rad2deg(err[:, STATE_INDEX["theta"]]), lw=1.1, label=label)
    # the lagging rotors' own thrust where the plant has a lag, else the commanded one
    thrust = (sim.rotor_thrust[:, 0] if sim.rotor_thrust.size
              else motors.actuators_of(motors.Motors()).commands(sim.u)[:, 0])
    ax[2].plot(sim.t, thrust, lw=1.1, label=label)
ax[0].set_ylabel("phi from trim [deg]")
ax[1].set_ylabel("theta from trim [deg]")
ax[2].set_ylabel("rotor 1 thrust [N]")
ax[2].set_xlabel("time [s]")
for a in ax:
    a.grid(True, alpha=0.3)
ax[0].legend(fontsize=8, frameon=False, loc="upper right")
ax[0].set_xlim(0.0, 1.5)
fig.suptitle("mambo-200hz weights: instantaneous rotors, a 30 ms lag ignored or included, 5 ms of delay")
OUT.mkdir(parents=True, exist_ok=True)
fig.savefig(OUT / "lag-and-delay.png", dpi=80)
print(f"wrote {OUT / 'lag-and-delay.png'}")
