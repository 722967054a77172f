"""Helpers shared by the flight tests: a config solved through the pipeline, cached per session."""

from __future__ import annotations

import copy
import json
from functools import cache

from quadctl import config, pipeline
from quadctl.setup import resolve


def cfg_dict(bundled: str, **changes) -> dict:
    """A bundled config as a mutable dict, with top-level ``changes`` merged in."""
    data = copy.deepcopy(config.load(bundled).model_dump(mode="json"))
    data.update(changes)
    return data


@cache
def _solved(text: str):
    setup = resolve(config.from_dict(json.loads(text), "<test>"))
    trim = pipeline.trim_of(setup)
    linear = pipeline.linear_of(setup, trim)
    dec = pipeline.decoupled_of(setup, linear)
    des = pipeline.design_of(setup, dec, linear)
    return setup, trim, linear, dec, des


def solve(data: dict):
    """(setup, trim, linear, decoupled, design) of a config dict (cached by content)."""
    return _solved(json.dumps(data, sort_keys=True))


def run(data: dict):
    """(setup, design, loop, sim) of a config dict through the pipeline."""
    setup, trim, linear, dec, des = solve(data)
    loop = pipeline.loop_of(setup, linear, des)
    return setup, des, loop, pipeline.simulation_of(setup, loop)


def bundled_subsystems(names=("forward", "hover", "mambo-200hz")):
    """(setup, regulated subsystem) of every bundled config in ``names``: the plants the Riccati tests
    design for."""
    for name in names:
        setup = resolve(config.load(name))
        linear = pipeline.linear_of(setup, pipeline.trim_of(setup))
        for sub in pipeline.decoupled_of(setup, linear).regulated:
            yield setup, sub
