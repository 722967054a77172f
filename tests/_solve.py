"""Helpers shared by the flight tests: a config solved through the pipeline, cached per session."""

from __future__ import annotations

import copy
import json
from functools import cache

from quadctl import config, pipeline
from quadctl.setup import setup_of


def cfg_dict(bundled: str, **changes) -> dict:
    """A bundled config as a mutable dict, with top-level ``changes`` merged in."""
    data = copy.deepcopy(config.load(bundled).model_dump(mode="json"))
    data.update(changes)
    return data


@cache
def _solved(text: str):
    setup = setup_of(config.from_dict(json.loads(text), "<test>"))
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
        setup = setup_of(config.load(name))
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


LANE_RTOL = 1e-12
"""Agreement of the SIMD lanes with the one-case loop, relative to each quantity's size (at least 1).

The two differ only in sin and cos: the lanes call glibc's vector math (libmvec, up to 4 ulp)
where the one-case loop calls the scalar libm (under 1 ulp); built without the vector
declarations, the lanes equal the one-case loop bit for bit on every loop feature. A few ulps of
difference in one step is carried forward by the loop like any perturbation of its state: it
decays in a stable loop and grows with the state in a diverging one, so it stays a fixed
fraction of each quantity, about n_steps x 5 ulp at most (580 steps: 6e-13); an absolute bound
would fail on a loop that diverges to 1e5 (the forward design emulated at 2 kHz: 1.7e-10 there,
1.3e-15 of its size)."""


def lane_gap(got, want) -> float:
    """Largest ``|got - want|`` of two (rows, columns) records, each column divided by its size
    in ``want`` (its largest magnitude, at least 1): what :data:`LANE_RTOL` bounds."""
    import numpy as np

    want = np.asarray(want)
    if want.size == 0:
        return 0.0
    return float((np.abs(np.asarray(got) - want) / np.maximum(1.0, np.abs(want).max(axis=0))).max())


def lanes_and_one_case_runs(setup, spec, variants):
    """Run loop ``variants`` ``(ClosedLoop, NoiseSpec or None, duration s)`` in the SIMD lanes of
    ``spec`` (built as a sweep chunk builds its cases) and each alone through ``simulate``: yields
    ``((done, t, xs, us), SimResult)`` per variant, after checking both ran the same steps."""
    import numpy as np

    from quadctl.physics.noise import NoiseStream
    from quadctl.sim import engine
    from quadctl.sim.cases import Cases
    from quadctl.sim.plan import record_stride
    from quadctl.sim.run import simulate

    run = engine.runner(spec, engine.LANES)
    assert run.backend == "compiled-simd"
    jobs = []
    for vk, noise, dur in variants:
        plan = vk.plan(dur, setup.dt)
        lo, hi = vk.bounds(dur)
        first, exo = NoiseStream(noise).rows(0, plan.n_steps, plan.dt) if noise else (0, None)
        x0 = vk.initial_loop_state(setup.initial_state(vk.x_trim))
        jobs.append((plan, vk.constants(plan.sample_time), x0, lo, hi, exo, first, noise))
    cases = Cases.of(np.stack([j[2] for j in jobs]), np.stack([j[1] for j in jobs]), [j[0].dt for j in jobs],
                     [j[0].n_steps for j in jobs], [record_stride(j[0].n_steps, setup.max_samples) for j in jobs],
                     np.stack([j[3] for j in jobs]), np.stack([j[4] for j in jobs]),
                     hold=[max(j[0].hold, 1) for j in jobs], exo=[j[5] for j in jobs] if spec.noise else None,
                     exo_first=[j[6] for j in jobs], exo_period=[j[7].period if j[7] else 1.0 for j in jobs])
    for (vk, noise, dur), lanes in zip(variants, run.run(cases)):
        one = simulate(vk, setup.initial_state(vk.x_trim), dur, setup.dt, noise=noise, max_samples=setup.max_samples)
        done, t, _, _ = lanes
        assert done == one.steps
        np.testing.assert_array_equal(t, one.t)
        yield lanes, one


def designed_table(name: str, values, interpolation: str = "linear", **changes):
    """A speed schedule's :class:`~quadctl.design.gain_table.GainTable` of bundled config ``name``: at each
    speed (m/s, north) the config's own design trimmed there (a one-point design of the config with
    ``trim.velocity_ned = [v, 0, w]``, w its climb; the state gain, then any integrator gains), built
    apart from :func:`quadctl.schedule.envelope.schedule_of`."""
    import numpy as np

    from quadctl.design.gain_table import GainTable

    gains = []
    for v in values:
        data = cfg_dict(name, **changes)
        data["trim"]["velocity_ned"] = [float(v), 0.0, data["trim"]["velocity_ned"][2]]
        des = solve(data)[-1]
        gains.append(np.hstack([des.K_block, des.Ki_block]) if des.integral_states else des.K_block)
    return GainTable.of("speed", values, np.array(gains), interpolation)


def without_compiler(monkeypatch, run):
    """``run()`` with no C compiler (``QUADCTL_NO_COMPILE=1``): the loop in CasADi's virtual machine,
    after the one :class:`~quadctl.sim.engine.CompilerNotice` it gives; the runners' cache cleared
    before and after, so that the runs around it compile as before."""
    import pytest

    from quadctl.sim import engine

    monkeypatch.setenv("QUADCTL_NO_COMPILE", "1")
    engine.runner.cache_clear()
    try:
        with pytest.warns(engine.CompilerNotice, match="no C compiler found"):
            return run()
    finally:
        monkeypatch.delenv("QUADCTL_NO_COMPILE")
        engine.runner.cache_clear()
