"""quadctl as a library: the report's design in a dozen lines.

Run: python examples/library_quickstart.py
"""

from quadctl import config, pipeline
from quadctl.layout import STATE_NAMES
from quadctl.problem import setup_of

setup = setup_of(config.load("forward"))            # the bundled report case (1 m/s north)
trim = pipeline.trim_of(setup)                      # theta = -0.2119 rad, T = 0.6522 N
linear = pipeline.linear_of(setup, trim)            # exact CasADi Jacobians
decoupled = pipeline.decoupled_of(setup, linear)    # the report's five subsystems
design = pipeline.design_of(setup, decoupled, linear)

print(f"trim: theta = {trim.x[STATE_NAMES.index('theta')]:.4f} rad, T = {trim.u[0]:.4f} N")
for sub in design.subsystems:
    print(f"{sub.name:9s} K = {sub.K.round(4).tolist()}")
print("largest dropped coupling:", decoupled.dropped[0].name, f"{decoupled.dropped[0].value:.3f}")
print("stable on the coupled model:", design.stable)

loop = pipeline.loop_of(setup, linear, design)
sim = pipeline.simulation_of(setup, loop)
print(f"simulated {sim.steps} RK4 steps (dt = {sim.dt:.3g} s): {sim.status}, "
      f"{sim.steps_per_second / 1e6:.1f} M steps/s")
