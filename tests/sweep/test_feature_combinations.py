"""Every loop feature at once: each runner and the sweep's lanes agree on one loop that has them all.

Each feature is tested alone where it is built (test_engine, test_wind, test_estimator,
test_rotor_lag_design); this file flies them together, the case their separate tests cannot see:
rotor lag included in the design, a sample of delay, LQI, process and sensor noise, a Kalman
filter, and wind (steady, a gust and Dryden turbulence) in one loop.
"""

from __future__ import annotations

import numpy as np
import pytest
from _solve import cfg_dict, max_rel_diff, solve, without_compiler

from quadctl import config, pipeline, sweep

SENSORS = {"pN": 0.01, "pE": 0.01, "pD": 0.01, "phi": 0.002, "theta": 0.002, "psi": 0.005,
           "p": 0.005, "q": 0.005, "r": 0.005}


def _everything(duration: float = 0.4) -> dict:
    """crazyflie-wind with the rotors' lag included, one sample of delay, LQI, noise and a Kalman filter."""
    data = cfg_dict("crazyflie-wind", estimator={"measure": ["imu", "mocap"]})
    data["controller"].update(rotor_lag="include", delay={"samples": 1})
    data["motors"]["time_constant"] = 0.02
    data["lqr"]["altitude"]["integral"] = ["pD"]
    data["lqr"]["altitude"]["Q"] = [4.0, 4.0, 1.0]
    data["simulation"].update(duration=duration, initial_offset={"phi": 0.05}, noise={
        "seed": 3, "force": [0.002] * 3, "torque": [1e-5] * 3, "sensor": dict(SENSORS)})
    data["simulation"]["wind"]["gusts"][0]["start"] = 0.1
    return data


def test_the_loop_with_every_feature_has_every_state():
    setup, _, linear, _, des = solve(_everything())
    spec = pipeline.loop_of(setup, linear, des).spec(noise=True, wind=True)
    assert (spec.rotors, spec.lag_model, spec.delay, spec.nz, spec.wind, spec.noise) == (True, True, 1, 1, True, True)
    assert spec.nx == 12 + 4 + 1 + 4 + 4 + 12  # [x; f; z; l; b; xh]


@pytest.mark.compiler
def test_compiled_and_interpreted_runs_agree_with_every_feature(monkeypatch):
    setup, trim, linear, dec, des = solve(_everything())
    loop = pipeline.loop_of(setup, linear, des)
    compiled = pipeline.simulation_of(setup, loop)
    interpreted = without_compiler(monkeypatch, lambda: pipeline.simulation_of(setup, loop))
    assert (compiled.backend, interpreted.backend, compiled.status) == ("compiled", "casadi", "ok")
    worst = max(np.abs(getattr(compiled, k) - getattr(interpreted, k)).max()
                for k in ("x", "u", "z", "rotor_thrust", "lag_model", "x_hat", "wind"))
    assert worst < 1e-12, f"Max diff is {worst:.4E}"
    for name in ("rotor_thrust", "lag_model", "x_hat", "wind", "z"):  # every part of the loop moved
        assert np.ptp(getattr(compiled, name)) > 0, name


@pytest.mark.compiler
def test_a_sweep_with_every_feature_runs_in_the_lanes_with_the_one_by_one_rows():
    cfg = config.from_dict(_everything(0.3))
    spec = sweep.from_dict({"parameters": {"lqr.roll.R[0]": [2.0e5, 8.0e5],
                                           "simulation.wind.turbulence.seed": [1, 2]}}, cfg, "test.yaml")
    fast = sweep.run(cfg, spec, jobs=1)
    slow = sweep.run(cfg, spec, jobs=1, fast=False)
    assert fast.stats["backend"] == ["compiled-simd"]
    # the lag-augmented designs are solved one by one (and say so); the runs fly in the lanes
    assert {r["path"] for r in fast.rows} == {"one-by-one: the design includes the rotors' lag"}
    assert {r["status"] for r in fast.rows} == {"ok"}
    worst, where = max_rel_diff(fast.rows, slow.rows)
    assert worst < 1e-9, f"Max diff is {worst:.4E} at {where}"
