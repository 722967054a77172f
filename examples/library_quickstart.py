"""quadctl as a library: the report's design in a dozen lines.

The bundled forward config (the report's 1 m/s forward flight) through the public face: its trim,
the gains of its five decoupled LQR loops, the largest coupling the decoupling drops, the check on
the coupled model, and the configured nonlinear run.

Run from a clone: ``python examples/library_quickstart.py`` prints them (it draws no figure).
"""

import quadctl as qc
from quadctl import pipeline
from quadctl.layout import STATE_NAMES

stages = qc.Stages(qc.setup_of(qc.load_config("forward")))  # the bundled report case (1 m/s north)
trim = stages.trim                                          # theta = -0.2119 rad, T = 0.6522 N
decoupled = stages.decoupled                                # the report's five subsystems
design = stages.design                                      # exact CasADi Jacobians, one LQR per subsystem

print(f"trim: theta = {trim.x[STATE_NAMES.index('theta')]:.4f} rad, T = {trim.u[0]:.4f} N")
for sub in design.subsystems:
    print(f"{sub.name:9s} K = {sub.K.round(4).tolist()}")
print("largest dropped coupling:", decoupled.dropped[0].name, f"{decoupled.dropped[0].value:.3f}")
print("stable on the coupled model:", design.stable)

sim = pipeline.simulation_of(stages.setup, stages.loop)    # the configured run (noise, wind, reference)
print(f"simulated {sim.steps} RK4 steps (dt = {sim.dt:.3g} s): {sim.status}, "
      f"{sim.steps_per_second / 1e6:.1f} M steps/s")
