"""Sweeps: many designs of one config, varied by key path, with metrics, gates and executors.

Each case is the config with the sweep's values put in and validated again; a chunk of cases is
designed and simulated together (batched Riccati solves, SIMD lanes), or one by one through
:mod:`quadctl.pipeline` with ``fast=False``. The sweep file, the metrics and uncertainty studies are in
the docs, docs/guide/sweeps.md; how a sweep is fast, docs/internals.md ("How a sweep runs").

Modules, each importing only those above it:

- :mod:`~quadctl.sweep.config_tree`: a config as a mapping, values read and put in by key path
- :mod:`~quadctl.sweep.gates`: the metrics of a case, the gates on them, verdict and ranking
- :mod:`~quadctl.sweep.spec`: a validated sweep as data: its parameters, its cases, the whole sweep
- :mod:`~quadctl.sweep.uncertainty`: what a varied key reaches (the simulated vehicle only, or the design)
- :mod:`~quadctl.sweep.sweep_file`: the sweep file (parameters, values, gates) parsed and checked
- :mod:`~quadctl.sweep.lane_jobs`: a designed case made ready for the lanes: its loop, step plan, bounds, rows
- :mod:`~quadctl.sweep.batched`: designs, verdicts and lane simulations of many cases at once
- :mod:`~quadctl.sweep.prepare`: a chunk's cases made ready to design: their setups, the plants they fly
- :mod:`~quadctl.sweep.rows`: a case's row, the verdicts of the law that flies, a Monte Carlo's trajectory
- :mod:`~quadctl.sweep.lane_rows`: the batched path: a chunk's cases designed together, flown in the lanes, as rows
- :mod:`~quadctl.sweep.evaluate`: a chunk of cases, batched or one by one, as rows judged by the gates
- :mod:`~quadctl.sweep.runner`: chunks on local processes or a Dask cluster
- :mod:`~quadctl.sweep.outputs`: sweep.csv, the summary, the plots, Monte Carlo bands
- :mod:`~quadctl.sweep.store`: the run directory (journal, ``--resume``) and :func:`execute`
"""

from quadctl.sweep.config_tree import assign
from quadctl.sweep.evaluate import ChunkResult, ChunkTask, evaluate_chunk
from quadctl.sweep.gates import Gate, judge, margin, metric_columns, regulated_states
from quadctl.sweep.outputs import MonteCarloBands, montecarlo_bands, summarize, to_csv
from quadctl.sweep.rows import MC_POINTS
from quadctl.sweep.runner import SweepResult, run
from quadctl.sweep.spec import Case, Parameter, SweepSpec
from quadctl.sweep.store import PARTS, SweepOutcome, SweepStore, execute
from quadctl.sweep.sweep_file import from_dict, load, parse

__all__ = [
    "MC_POINTS", "PARTS", "Case", "ChunkResult", "ChunkTask", "Gate", "MonteCarloBands", "Parameter",
    "SweepOutcome", "SweepResult", "SweepSpec", "SweepStore", "assign", "evaluate_chunk", "execute",
    "from_dict", "judge", "load", "margin", "metric_columns", "montecarlo_bands", "parse", "regulated_states", "run",
    "summarize", "to_csv",
]
