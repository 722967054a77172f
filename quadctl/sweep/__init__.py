"""Sweeps: many designs of one config, varied by key path, with metrics, gates and executors.

A sweep file names config values to vary by their key path (``lqr.roll.Q[1]``,
``vehicle.mass``), each as a list, a range or (random mode) a distribution, and gates on the
metrics of every case. Each case is the base config with those values put in, validated again
by :func:`quadctl.config.from_dict`, so every case is a valid config or a row that says why not.

Per case: trim, linearize, decouple, LQR design, the coupled closed-loop eigenvalues, a nonlinear
RK4 simulation and its metrics. Cases run in chunks, on local processes or a Dask cluster, and
a chunk computes its cases together (:mod:`~quadctl.sweep.batched`): the small Riccati equations
in batched solves (continuous, or discrete at the controller rate), the simulations
:data:`~quadctl.sim.engine.LANES` at a time in SIMD code generated from the one closed-loop
definition (:mod:`quadctl.sim`), with every feature a config can have (rate and hold, motors and
saturation, integral action, noise). ``fast=False`` runs each case through
:mod:`quadctl.pipeline` instead: the reference the batched path is tested against.

The sweep file::

    mode: grid                  # or random (then samples and seed)
    samples: 1000               # random mode: number of cases
    seed: 1                     # random mode: the same seed gives the same cases
    parameters:                 # key path -> values
      lqr.roll.Q[1]: [10, 50, 100]                                  # a list
      lqr.altitude.R[0]: {from: 0.1, to: 10, num: 5, scale: log}   # a range (scale: linear or log)
      vehicle.mass: {distribution: normal, mean: 0.068, std: 0.003} # random mode only
    set:                        # optional: values every case gets
      simulation.duration: 5.0
    gates:                      # metric -> {min, max} (or {equals} for stable and status)
      settling_time.pD: {max: 3.0}
      peak.T: {max: 1.5}
    require_ok: true            # a case must also design, be stable and simulate to the end
    chunk_size: 32              # optional: cases per task

Distributions (random mode): ``uniform {low, high}``, ``loguniform {low, high}``,
``normal {mean, std}``, ``choice {values}``. In random mode a list is a uniform choice and a
range is sampled uniformly on ``[from, to]`` (log-uniformly with ``scale: log``).

A sweep whose parameters are all plant-side (:func:`~quadctl.sweep.spec.plant_side`: the noise
seed, ``simulation.plant`` mass and inertia errors, the rotor time constant a design ignores, the
delay, any ``simulation.`` key but the run's length and step and the noise a Kalman filter takes
from it) is an uncertainty study, a Monte
Carlo when its values are drawn (:attr:`SweepSpec.monte_carlo`): its cases share one design (the
chunk designs each distinct problem once), run in the lanes (grouped by loop structure: one group
per delay), and each keeps the deviation of its regulated states from the reference on a common
grid of :data:`MC_POINTS` times; the run directory gets ``montecarlo.png`` and ``montecarlo.npz``,
the percentile bands of those deviations against time (:func:`montecarlo_bands`), naming the
parameters varied.

Modules, each importing only those above it:

- :mod:`~quadctl.sweep.gates`: the metrics of a case, the gates on them, verdict and ranking
- :mod:`~quadctl.sweep.spec`: the sweep file (parameters, values, gates) parsed and checked
- :mod:`~quadctl.sweep.batched`: designs, verdicts and lane simulations of many cases at once
- :mod:`~quadctl.sweep.evaluate`: a chunk of cases, batched or one by one, as rows
- :mod:`~quadctl.sweep.runner`: chunks on local processes or a Dask cluster
- :mod:`~quadctl.sweep.outputs`: sweep.csv, the summary, the plots, Monte Carlo bands
- :mod:`~quadctl.sweep.store`: the run directory (journal, ``--resume``) and :func:`execute`
"""

from quadctl.sweep.evaluate import MC_POINTS, ChunkResult, ChunkTask, evaluate_chunk
from quadctl.sweep.gates import Gate, judge, margin, metric_columns, regulated_states
from quadctl.sweep.outputs import MonteCarloBands, montecarlo_bands, summarize, to_csv
from quadctl.sweep.runner import SweepResult, run
from quadctl.sweep.spec import Case, Parameter, SweepSpec, assign, from_dict, load, parse
from quadctl.sweep.store import PARTS, SweepOutcome, SweepStore, execute

__all__ = [
    "MC_POINTS", "PARTS", "Case", "ChunkResult", "ChunkTask", "Gate", "MonteCarloBands", "Parameter",
    "SweepOutcome", "SweepResult", "SweepSpec", "SweepStore", "assign", "evaluate_chunk", "execute",
    "from_dict", "judge", "load", "margin", "metric_columns", "montecarlo_bands", "parse", "regulated_states", "run",
    "summarize", "to_csv",
]
