"""benchmarks/case_stages.py, the timer of a sweep case's stages (docs/performance.md): each stage it
names is one a sweep runs, none counted inside another, and the sweep is left as it was."""

from __future__ import annotations

import dataclasses
import sys

from _paths import ROOT

from quadctl import config, sweep
from quadctl.sim import native
from quadctl.sweep import batched, prepare


def test_each_stage_the_timer_names_runs_and_none_is_counted_inside_another():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import case_stages

    cfg = config.load("mambo-200hz")
    spec = dataclasses.replace(sweep.load(ROOT / "benchmarks" / "mambo-1000.yaml", cfg), samples=16)
    before = (batched.design_all, prepare.CaseSetups.all, native.NativeRunner._call)
    total, per, steps = case_stages.stages(cfg, spec, runs=1)
    assert steps == 2_000
    assert all(per[name] > 0 for name in case_stages.STAGES), per  # each entered: a stage the sweep runs
    # the chunk's own rest and what lies outside the chunks are what the named stages leave: below zero
    # if a stage were counted inside another
    assert per["the rest of a chunk"] >= 0 and per["outside the chunks"] >= 0, per
    assert (batched.design_all, prepare.CaseSetups.all, native.NativeRunner._call) == before
