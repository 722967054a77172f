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


def max_rel_diff(rows_a, rows_b, skip=("path",)) -> tuple[float, str]:
    """Largest relative difference over the numeric cells of two sweeps' rows, and where; the
    other cells must be equal (``skip``: columns left out, the path each case took by default)."""
    worst, where = 0.0, ""
    for a, b in zip(rows_a, rows_b, strict=True):
        assert a.keys() == b.keys()
        for key in a:
            if key in skip:
                continue
            va, vb = a[key], b[key]
            if isinstance(va, float) and isinstance(vb, float):
                d = abs(va - vb) / max(abs(vb), 1e-12)
                if d > worst:
                    worst, where = d, f"case {a['case']} {key}: {va!r} vs {vb!r}"
            else:
                assert va == vb, f"case {a['case']} {key}: {va!r} vs {vb!r}"
    return worst, where


def lane_cases(jobs, max_samples: int, noisy: bool = True):
    """The :class:`quadctl.sim.cases.Cases` of lane jobs ``(plan, c, x0, lo, hi, exo, exo_first, noise)``
    (a test's own cases, built as a sweep chunk builds them; ``noise`` None without one)."""
    import numpy as np

    from quadctl.sim.cases import Cases
    from quadctl.sim.plan import record_stride

    return Cases.of(np.stack([j[2] for j in jobs]), np.stack([j[1] for j in jobs]), [j[0].dt for j in jobs],
                    [j[0].n_steps for j in jobs], [record_stride(j[0].n_steps, max_samples) for j in jobs],
                    np.stack([j[3] for j in jobs]), np.stack([j[4] for j in jobs]),
                    hold=[max(j[0].hold, 1) for j in jobs], exo=[j[5] for j in jobs] if noisy else None,
                    exo_first=[j[6] for j in jobs], exo_period=[j[7].period if j[7] else 1.0 for j in jobs])
