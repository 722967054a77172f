"""The simulation engine: one closed-loop definition, compiled or interpreted, one case or many.

Modules, each importing only those above it:

- :mod:`~quadctl.sim.plan`: the RK4 step a loop needs (from its spectrum) or a user's step checked
- :mod:`~quadctl.sim.builder`: the one closed-loop definition (:class:`LoopSpec` -> CasADi functions of one step)
- :mod:`~quadctl.sim.etdrk4_plan`: the exponential integrator's step schedule and its φ-functions
- :mod:`~quadctl.sim.cases`: what every runner takes, a stack of cases (:class:`Cases`: N cases, each through
  its segments; one case is a stack of one, a fixed step one segment)
- :mod:`~quadctl.sim.lane_metrics`: a run's metrics summed in the lanes as they step, read back
- :mod:`~quadctl.sim.native`: the compiled runner (``driver.c``: 1 lane for one case, 8 for sweeps)
- :mod:`~quadctl.sim.interpreted`: the same loop in CasADi's virtual machine, without a compiler
- :mod:`~quadctl.sim.engine`: :func:`runner`, the fastest runner that builds here
- :mod:`~quadctl.sim.run`: the closed loop (:class:`ClosedLoop`) and its runs, RK4 or ETDRK4: one entry for a
  stack of them (:func:`stack_of`, :func:`run_stack`; :func:`simulate_stack`), :func:`simulate` the stack of one

A new loop feature is one change to :func:`quadctl.sim.builder.build` plus its config; every
runner, one case or many lanes, compiled or not, gets it from there.
"""
