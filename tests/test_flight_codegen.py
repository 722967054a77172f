"""The compiled loop and its Python mirror agree with a held input, integrators, saturation and noise."""

from __future__ import annotations

import numpy as np
import pytest
from _flight import cfg_dict, solve

from quadctl import codegen, pipeline
from quadctl.simulate import simulate


def _both(data, monkeypatch, duration):
    cfg, trim, linear, _, des = solve(data)
    loop = pipeline.loop_of(cfg, linear, des, pipeline.reference_rate(trim))
    x0 = pipeline.initial_state(cfg, linear.x_trim)
    spec = pipeline.noise_of(cfg)
    compiled = simulate(loop, x0, duration, cfg.simulation.dt, noise=spec)
    monkeypatch.setenv("QUADCTL_NO_COMPILE", "1")
    codegen.get_loop.cache_clear()
    try:
        interpreted = simulate(loop, x0, duration, cfg.simulation.dt, noise=spec)
    finally:
        codegen.get_loop.cache_clear()
    assert compiled.backend == "compiled" and interpreted.backend == "casadi"
    return compiled, interpreted


@pytest.mark.compiler
@pytest.mark.parametrize("case", ["held, rotors, LQI, noise", "continuous, box limits, LQI, noise"])
def test_compiled_and_interpreted_loops_agree(case, monkeypatch):
    if case.startswith("held"):
        data, duration = cfg_dict("mambo-200hz"), 0.3
    else:
        data = cfg_dict("hover", limits={"T": [0.0, 1.5], "A": [-0.05, 0.05]})  # A clips, T does not
        data["lqr"]["altitude"] = {"Q": [50.0, 1.0, 20.0], "R": [1.0], "integral": ["pD"]}
        data["simulation"]["initial_offset"] = {"pD": 0.05, "phi": 0.1}
        data["simulation"]["noise"] = {"seed": 4, "force": [0.01, 0.01, 0.01], "sensor": {"phi": 0.01}}
        duration = 0.02
    compiled, interpreted = _both(data, monkeypatch, duration)
    diff = max(np.abs(compiled.x - interpreted.x).max(), np.abs(compiled.z - interpreted.z).max())
    assert diff < 1e-12, f"Max diff is {diff:.4E}"
    np.testing.assert_allclose(compiled.u, interpreted.u, atol=1e-12)
    assert compiled.z.shape[1] == 1 and np.any(compiled.z != 0)
    if case.startswith("continuous"):
        assert np.abs(compiled.u[:, 1]).max() == pytest.approx(0.05)  # the box clipped A
