"""The simulation engine: one closed-loop definition, compiled or interpreted, one case or many.

Modules, each importing only those above it:

- :mod:`~quadctl.sim.plan`: the RK4 step a loop needs (from its spectrum) or a user's step checked
- :mod:`~quadctl.sim.loop_layout`: the layouts of a loop's constant vector and of its exogenous row per step
- :mod:`~quadctl.sim.loop_spec`: a loop's structure (:class:`LoopSpec`, what is baked into its code)
- :mod:`~quadctl.sim.builder`: the one closed-loop definition (:class:`LoopSpec` -> CasADi functions of one step)
- :mod:`~quadctl.sim.etdrk4_plan`: the exponential integrator's step schedule
- :mod:`~quadctl.sim.etdrk4_matrices`: the matrices of its steps, from the φ-functions of the loop's linear part
- :mod:`~quadctl.sim.cases`: what every runner takes, a stack of cases (:class:`Cases`: N cases, each through
  its segments; one case is a stack of one, a fixed step one segment)
- :mod:`~quadctl.sim.lane_metrics`: a run's metrics summed in the lanes as they step, read back
- :mod:`~quadctl.sim.native`: the compiled runner (``driver.c``: 1 lane for one case, 8 for sweeps)
- :mod:`~quadctl.sim.interpreted`: the same loop in CasADi's virtual machine, without a compiler
- :mod:`~quadctl.sim.engine`: :func:`runner`, the fastest runner that builds here
- :mod:`~quadctl.sim.loop`: the closed loop (:class:`~quadctl.sim.loop.ClosedLoop`): its linear parts, the
  constants of its code, its bounds and its RK4 step
- :mod:`~quadctl.sim.exogenous`: a run's exogenous inputs on one clock (:class:`~quadctl.sim.exogenous.ExoStream`:
  noise, wind, a flown reference's rows), drawn chunk by chunk
- :mod:`~quadctl.sim.stack_run`: a stack of runs ready for a runner (:class:`~quadctl.sim.stack_run.Stack`) and its
  run (:func:`~quadctl.sim.stack_run.run_stack`: a long run of one case in chunks, for Ctrl-C)
- :mod:`~quadctl.sim.etdrk4_stack`: ETDRK4 for loops: a loop's linear part and graded schedule
  (:func:`~quadctl.sim.etdrk4_stack.exponential_plan`) and their stacks
  (:func:`~quadctl.sim.etdrk4_stack.exponential_stack`: the φ-functions of the loops' linear parts on the stack of
  them; the stack of one a loop keeps)
- :mod:`~quadctl.sim.stack`: the one entry that makes a stack of loops for either integrator, RK4 or ETDRK4
  (:func:`~quadctl.sim.stack.stack_of`, RK4's :func:`~quadctl.sim.stack.rk4_cases`;
  :func:`~quadctl.sim.stack.simulate_stack`)
- :mod:`~quadctl.sim.run`: one run, the stack of one (:func:`~quadctl.sim.run.simulate`, its
  :class:`~quadctl.sim.run.SimResult` and :func:`~quadctl.sim.run.verdict`)

A new loop feature is one change to :func:`quadctl.sim.builder.build` plus its config; every
runner, one case or many lanes, compiled or not, gets it from there.
"""
