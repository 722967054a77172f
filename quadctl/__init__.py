"""quadctl: trim, linearize, decouple, check, design and simulate LQR controllers for quadcopters.

A pure library (no printing, no terminal) under a thin command line (:mod:`quadctl.cli`, which
nothing here imports). Modules, each importing only those above it:

- :mod:`~quadctl.layout`: state and input names, units, index maps (declared once)
- :mod:`~quadctl.errors`: the error classes (each with its exit code) and the notice warning
- helpers that import nothing of quadctl's or only the above: :mod:`~quadctl.messages` (values, key
  paths and hints as messages show them), :mod:`~quadctl.yamlio` (YAML read with line numbers),
  :mod:`~quadctl.escape` (text made safe per output format), :mod:`~quadctl._lazy` (modules loaded
  on first use), :mod:`~quadctl.pointwise` (a CasADi function over many points, a row a point)
- :mod:`~quadctl.config`: the YAML config (its own map): the schema (``config.schema``), the weight
  rules (``config.weights``), a schema error in one line (``config.describe``), the checks across fields
  (``config.checks``), the schema shown (``config.render``), finding and loading a config and the bundled
  ones (``config.loading``); :mod:`~quadctl.notices`: what a valid config took by default or likely got in
  the wrong unit; :mod:`~quadctl.overrides`: values put in at a key path before validation (``--set KEY=VALUE``)
- :mod:`~quadctl.model`: the CasADi model, the only place the equations of motion live
- :mod:`~quadctl.motors`, :mod:`~quadctl.noise`, :mod:`~quadctl.wind`: rotors and mixing; seeded noise
  streams; steady wind, gusts and Dryden turbulence
- :mod:`~quadctl.trajectory`, :mod:`~quadctl.flatness`: a reference's path (setpoints, a waypoint
  mission's minimum-jerk or minimum-snap legs) and its differential-flatness feedforward
- :mod:`~quadctl.problem`: the config made into numbers once: the :class:`~quadctl.problem.Setup`
  every stage takes (:func:`~quadctl.problem.setup_of`)
- :mod:`~quadctl.linear.trim`, :mod:`~quadctl.linear.linearize`, :mod:`~quadctl.decouple`: equilibrium,
  Jacobians (with the reference drift), the partition into subsystems and what it drops
- :mod:`~quadctl.stability`: the one stability test (and its margins) and the one rule for free positions
- :mod:`~quadctl.analysis`: controllability, observability, PBH, with a stated rank tolerance
- :mod:`~quadctl.design`: the LQR family (its own map): Riccati solves (``lqr.riccati``), integral
  action (``lqr.integral``), the rotors' lag (``lqr.lag``), zero-order hold and ``lqrd``
  (``lqr.discrete``), the linear closed loop of a design (``lqr.linear_loop``), the decoupled design
  (``lqr.decoupled``), one LQR on the coupled model (``lqr.coupled``)
- :mod:`~quadctl.estimator`: the steady-state Kalman filter of an LQG loop (discrete filter form or
  Kalman-Bucy) and the observability of the measured set
- :mod:`~quadctl.design.margins`: loop margins (with the filter in the loop for LQG)
- :mod:`~quadctl.sim`: the simulation engine (step planning, the one closed-loop builder, compile
  and cache, native and interpreted runners, one case or many lanes; :mod:`~quadctl.sim.run`: the
  closed loop and one run of it); :mod:`~quadctl.metrics`: a run's step-response metrics
- :mod:`~quadctl.pipeline`: the stages chained from a setup (pure functions; :class:`~quadctl.pipeline.Stages`,
  the one chain each stage computed once, that the workspace and the export take)
- :mod:`~quadctl.threads`: one BLAS thread while many small matrices are solved (it loads the
  libraries whose pools it limits: SciPy's, the Riccati solvers', the simulation engine's)
- :mod:`~quadctl.sweep`: many designs at once (spec, batched evaluation, runner, outputs, store)
- :mod:`~quadctl.scheduling`: a gain schedule across the envelope (trims and batched designs at each
  value, the gain table, the frozen-point checks); :mod:`~quadctl.transition`: a reference flown with
  the schedule and with the fixed design
- :mod:`~quadctl.starter`: a commented config to start a vehicle from (``quadctl init``)
- :mod:`~quadctl.provenance`: the software versions and the C compiler an artifact records
- :mod:`~quadctl.artifacts`, :mod:`~quadctl.payloads`, :mod:`~quadctl.workspace`, :mod:`~quadctl.plots`:
  the run directory (its own map: provenance record, JSON values, places and names, atomic writing,
  checked reading, the folder's lock), what each artifact holds, the chain of stages with a
  run folder, figures (they read results only; :mod:`~quadctl.plots` has its own map)
- :mod:`~quadctl.present`: each stage result as tables and sentences, written once: what the terminal
  (:mod:`quadctl.cli`, rich styling only) and the report (escaping and markup only) both render
- :mod:`~quadctl.report`: every stage of a run in one self-contained HTML page and a Markdown twin
- :mod:`~quadctl.export`: the design to the vehicle (a C99 controller emitted from the simulation's
  own law, the design as MATLAB ``.mat`` or JSON); :mod:`~quadctl.interop`: python-control systems
"""

__version__ = "0.1.0"
