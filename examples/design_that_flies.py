"""A design that flies: from the report's LQR to mambo-200hz.

What the report's design asks of a Parrot Mambo's rotors, and what a 200 Hz discrete LQR sized by
Bryson's rule asks instead (peak demand over rotor headroom); mambo-200hz flying the report's initial
offset with rotor limits and noise; the Bode and Nyquist plots of its roll loop; and its altitude
integrator removing the error a 10 % heavier vehicle leaves (plain LQR against LQI).

Run from a clone: ``python examples/design_that_flies.py [FOLDER]`` writes peak-demand.png,
mambo-response.png, mambo-roll-margins.png and lqi-mass-error.png into FOLDER (default: docs/figures/)
and prints the numbers of the guide's "A design that flies".
"""

import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Patch

import quadctl as qc
from quadctl import config, pipeline, plots
from quadctl.config import overrides
from quadctl.layout import INPUT_NAMES, STATE_INDEX
from quadctl.physics import motors

OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "docs" / "figures"
MAMBO = motors.Motors()  # the default rotors: the Parrot Mambo's


def fly(name, *sets):
    """The stages of a bundled config with ``--set`` values, and its configured run."""
    stages = qc.Stages(qc.setup_of(overrides.load(config.locate(name), sets)))
    return stages, pipeline.simulation_of(stages.setup, stages.loop)


def save(fig, name):
    OUT.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT / name, dpi=80)
    print(f"wrote {OUT / name}")


# 1. What each design asks of the Mambo's rotors: peak |u - u_trim| over the headroom from the trim
cases, clipped = {}, {}
for label, name, sets in (("report, continuous", "forward", ()),
                          ("report weights, lqrd 200 Hz", "forward", ("controller.rate=200.0",)),
                          ("report weights, lqrd 200 Hz, rotor limits", "forward",
                           ("controller.rate=200.0", "motors={}")),
                          ("mambo-200hz", "mambo-200hz", ())):
    stages, sim = fly(name, *sets)
    u_trim = stages.linear.u_trim
    room = motors.headroom(motors.actuators_of(MAMBO), u_trim)
    peak = np.abs(sim.u - u_trim).max(axis=0)
    cases[label] = np.array([peak[j] / min(room[n]) for j, n in enumerate(INPUT_NAMES)])
    actuators = stages.loop.actuators
    clipped[label] = np.zeros(4, dtype=bool)  # per input: a rotor at its limit when the input peaked
    if actuators is not None:
        thrust = actuators.commands(sim.u)
        tol = 1e-9 * float(np.max(actuators.hi))
        at_limit = ((thrust <= actuators.lo + tol) | (thrust >= actuators.hi - tol)).any(axis=1)
        clipped[label] = at_limit[np.abs(sim.u - u_trim).argmax(axis=0)]
    saturated = motors.saturation_fraction(actuators, sim.u) if actuators is not None else None
    print(f"{label}: status {sim.status} ({sim.message}); peak |du| = "
          + ", ".join(f"{n} {peak[j]:.4g}" for j, n in enumerate(INPUT_NAMES))
          + "; / headroom = " + ", ".join(f"{r:.3g}" for r in cases[label])
          + (f"; saturated {max(saturated.values()) * 100:.3g} % (worst rotor)" if saturated else ""))
mambo, mambo_sim = stages, sim  # the last case
print("report gains run at 200 Hz:",
      fly("forward", "controller.rate=200.0", "controller.design=continuous")[1].message)

fig = Figure(figsize=(8.0, 3.8), layout="constrained")
ax = fig.subplots()
width = 0.8 / len(cases)
for k, (label, ratio) in enumerate(cases.items()):
    bars = ax.bar(np.arange(4) + (k - (len(cases) - 1) / 2) * width, ratio, width, label=label)
    for bar, at_limit in zip(bars, clipped[label]):
        if at_limit:  # the law asked more than this: the rotors gave what they had
            bar.set_hatch("////")
            bar.set_edgecolor("k")
ax.axhline(1.0, color="k", lw=1.0, ls="--")
ax.set_yscale("log")
ax.set_xticks(range(4), [f"{n}" for n in INPUT_NAMES])
ax.set_ylabel("peak |u - u_trim| / rotor headroom")
ax.grid(True, axis="y", which="both", alpha=0.3)
handles, _ = ax.get_legend_handles_labels()
key = Patch(facecolor="white", edgecolor="k", hatch="////", label="clipped: a rotor at its limit at the peak")
ax.legend(handles=[*handles, key], fontsize=8, frameon=False, loc="upper left")
fig.suptitle("What each design asks of the Mambo's rotors (report's initial offset); above 1: impossible,\n"
             "hatched: the input applied, clipped at a rotor's limit (the law asked for more)")
save(fig, "peak-demand.png")

# 2. mambo-200hz from the report's initial offset: attitude and altitude errors, rotor thrusts
fig = Figure(figsize=(8.0, 6.0), layout="constrained")
ax = fig.subplots(3, 1, sharex=True)
err = mambo_sim.x - mambo_sim.x_ref
for name in ("phi", "theta", "psi"):
    ax[0].plot(mambo_sim.t, np.rad2deg(err[:, STATE_INDEX[name]]), lw=1.2, label=name)
ax[0].set_ylabel("attitude error [deg]")
ax[1].plot(mambo_sim.t, err[:, STATE_INDEX["pD"]], lw=1.2, label="pD error")
ax[1].set_ylabel("pD error [m]")
thrust = mambo.loop.actuators.commands(mambo_sim.u)
for i in range(4):
    ax[2].plot(mambo_sim.t, thrust[:, i], lw=1.0, label=f"rotor {i + 1}")
ax[2].axhline(MAMBO.max_thrust, color="k", ls="--", lw=1.0, label="limit")
ax[2].set_ylabel("rotor thrust [N]")
ax[2].set_xlabel("time [s]")
for a, where in zip(ax, ("upper right", "upper right", "center right")):  # the rotors' legend below their limit line
    a.grid(True, alpha=0.3)
    a.legend(fontsize=8, frameon=False, loc=where, ncol=5)
fig.suptitle("mambo-200hz: report's offset, 200 Hz discrete LQR, rotor limits, noise (seed 1)")
save(fig, "mambo-response.png")

# 3. The roll loop's margins (Bode and Nyquist), on the design model
loops = qc.margins(mambo.design, mambo.decoupled, mambo.linear.A, mambo.linear.B)
roll = next(m for m in loops if m.loop == "roll" and m.model == "design")
save(plots.margins_figure(roll, title="mambo-200hz"), "mambo-roll-margins.png")

# 4. A vehicle 10 % heavier than the design model, in hover without noise: plain LQR against LQI
runs = {}
heavier = config.load("mambo-200hz").vehicle.mass * 1.1
for label, weights in (("plain LQR", "{Q: [4.0, 4.0], R: [25.0]}"),
                       ("LQI (integral of pD)", "{Q: [4.0, 4.0, 1.0], R: [25.0], integral: [pD]}")):
    _, sim = fly("mambo-200hz", "trim.velocity_ned=[0.0, 0.0, 0.0]", f"lqr.altitude={weights}",
                 "simulation.duration=15.0", "simulation.initial_offset={}", "simulation.noise=null",
                 f"simulation.plant={{mass: {heavier!r}}}")
    runs[label] = sim
    pd = STATE_INDEX["pD"]
    print(f"{label}: final pD error {(sim.x[-1, pd] - sim.x_ref[-1, pd]) * 1000:.4g} mm")

fig = Figure(figsize=(8.0, 3.4), layout="constrained")
ax = fig.subplots()
for label, sim in runs.items():
    pd = STATE_INDEX["pD"]
    ax.plot(sim.t, (sim.x[:, pd] - sim.x_ref[:, pd]) * 100, lw=1.4, label=label)
ax.axhline(0.0, color="0.3", lw=0.8)
ax.set_xlabel("time [s]")
ax.set_ylabel("altitude error pD [cm] (positive: low)")
ax.grid(True, alpha=0.3)
ax.legend(fontsize=8, frameon=False)
fig.suptitle("Vehicle 10 % heavier than the design model (hover, mambo-200hz weights, no noise)")
save(fig, "lqi-mass-error.png")
