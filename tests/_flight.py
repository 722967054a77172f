"""Helpers shared by the flight tests: a config solved through the pipeline, cached per session."""

from __future__ import annotations

import copy
import json
from functools import cache

from quadctl import config, pipeline


def cfg_dict(bundled: str, **changes) -> dict:
    """A bundled config as a mutable dict, with top-level ``changes`` merged in."""
    data = copy.deepcopy(config.load(bundled).model_dump(mode="json"))
    data.update(changes)
    return data


@cache
def _solved(text: str):
    cfg = config.from_dict(json.loads(text), "<test>")
    trim = pipeline.trim_of(cfg)
    linear = pipeline.linear_of(cfg, trim)
    dec = pipeline.decoupled_of(cfg, linear)
    des = pipeline.design_of(cfg, dec, linear)
    return cfg, trim, linear, dec, des


def solve(data: dict):
    """(cfg, trim, linear, decoupled, design) of a config dict (cached by content)."""
    return _solved(json.dumps(data, sort_keys=True))


def run(data: dict):
    """(cfg, design, loop, sim) of a config dict through the pipeline."""
    cfg, trim, linear, dec, des = solve(data)
    loop = pipeline.loop_of(cfg, linear, des, pipeline.reference_rate(trim))
    return cfg, des, loop, pipeline.simulation_of(cfg, loop)
