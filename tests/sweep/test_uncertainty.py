"""Uncertainty studies: sweeps of the simulated vehicle only, one design, every case in the lanes.

Which parameters are plant-side (:func:`quadctl.sweep.uncertainty.plant_side`); rows of mass, inertia,
rotor time constant and delay variations against the one-case path; the design made once per
distinct problem; a design that includes the rotors' lag in an uncertainty sweep; the bands file
with its names and units.
"""

from __future__ import annotations

import numpy as np
import pytest
from _paths import ROOT
from _solve import max_rel_diff

from quadctl import artifacts, config, sweep
from quadctl.sweep.uncertainty import plant_side

MATCH_RTOL = 1e-9
"""Lanes and the one-case loop do the same arithmetic in another order (SIMD lanes, a batched
Riccati solver); as in tests/sweep/test_sweep.py, round-off amplified by the loop over thousands of steps."""
TRACE_ATOL = 1e-6
"""Trajectories are kept as float32 (seven digits): the two paths' agree to its rounding (state units)."""
VEHICLE = {"simulation.plant.mass": [0.061, 0.075],            # kg: the design's 0.068 -10 %, +10 %
           "simulation.plant.inertia[0]": [6.2e-5, 7.6e-5],    # kg m^2: Jxx -10 %, +10 %
           "motors.time_constant": [0.02, 0.04],               # s, a lag the design ignores
           "controller.delay": [0.0, 0.005]}                   # s: none, and one sample at 200 Hz
"""Every plant-side kind of parameter, two values each: 16 cases of mambo-200hz."""
SHORT = {"simulation.duration": 0.6}


@pytest.fixture(scope="module")
def mambo():
    data = config.load("mambo-200hz").model_dump(mode="json")
    data["motors"]["time_constant"] = 0.03  # so the lag's time constant has a base value to vary
    data["controller"]["rotor_lag"] = "ignore"
    return config.from_dict(data, "mambo-lag.yaml")


@pytest.mark.parametrize("path, rotor_lag, expected", [
    (("simulation", "noise", "seed"), "ignore", True),
    (("simulation", "plant", "mass"), "ignore", True),
    (("simulation", "plant", "inertia", 0), "ignore", True),
    (("simulation", "initial_offset", "phi"), "ignore", True),
    (("simulation", "wind", "turbulence", "seed"), "ignore", True),  # any environment key under simulation.
    (("simulation", "duration"), "ignore", False),                    # the run's length, not the vehicle
    (("simulation", "dt"), "ignore", False),
    (("controller", "delay"), "ignore", True),
    (("controller", "delay", "samples"), "include", True),
    (("motors", "time_constant"), "ignore", True),
    (("motors", "time_constant"), "include", False),                  # the design is made for it
    (("vehicle", "mass"), "ignore", False),                           # the design model
    (("lqr", "roll", "Q", 1), "ignore", False),
    (("controller", "rate"), "ignore", False),
])
def test_which_parameters_are_plant_side(path, rotor_lag, expected):
    assert plant_side(path, rotor_lag) is expected


@pytest.mark.parametrize("path, values, uncertainty", [
    ("simulation.noise.seed", [1, 2], True),
    ("simulation.noise.period", [0.005, 0.01], False),           # the filter's sample period
    ("simulation.noise.force[0]", [0.001, 0.002], False),        # the process noise it assumes
    ("simulation.noise.sensor.phi", [0.001, 0.002], False),      # a measured state's noise
    ("simulation.plant.mass", [0.06, 0.07], True),
])
def test_the_noise_a_kalman_filter_assumes_is_part_of_the_design(path, values, uncertainty):
    """mambo-lqg's filter sets no noise of its own: it takes simulation.noise's, so varying that
    changes its gain, and such a sweep is no uncertainty study (one design, many vehicles)."""

    lqg = config.load(str(ROOT / "docs" / "configs" / "mambo-lqg.yaml"))
    assert lqg.estimator.force is None and not lqg.estimator.sensor
    assert sweep.from_dict({"parameters": {path: values}}, lqg, "u.yaml").uncertainty is uncertainty


def test_a_set_that_touches_the_estimator_makes_every_noise_value_but_the_seed_the_filters():

    lqg = config.load(str(ROOT / "docs" / "configs" / "mambo-lqg.yaml"))
    for path, values, uncertainty in (("simulation.noise.force[0]", [0.001, 0.002], False),
                                      ("simulation.noise.seed", [1, 2], True)):
        spec = sweep.from_dict({"parameters": {path: values}, "set": {"estimator.force": [0.001, 0.001, 0.001]}},
                               lqg, "u.yaml")
        assert spec.uncertainty is uncertainty, path


def test_a_sweep_is_an_uncertainty_study_when_every_parameter_is_plant_side(mambo):
    assert sweep.from_dict({"parameters": VEHICLE}, mambo, "u.yaml").monte_carlo
    mixed = {"parameters": {**VEHICLE, "lqr.roll.R[0]": [20000.0]}}
    assert not sweep.from_dict(mixed, mambo, "u.yaml").monte_carlo
    included = {"parameters": {"motors.time_constant": [0.02]}, "set": {"controller.rotor_lag": "include"}}
    assert not sweep.from_dict(included, mambo, "u.yaml").monte_carlo


@pytest.mark.compiler
def test_vehicle_variations_run_in_lanes_with_one_design_and_equal_the_one_case_path(mambo, tmp_path):
    """16 cases, one chunk: the four subsystems are designed once; the lanes (a group per delay)
    give the one-case rows to 1e-9 and the same trajectories."""
    spec = sweep.from_dict({"parameters": VEHICLE, "set": SHORT, "chunk_size": 16}, mambo, "u.yaml")
    fast = sweep.run(mambo, spec, jobs=1)
    slow = sweep.run(mambo, spec, jobs=1, fast=False)
    assert fast.stats["designs"] == 4 and slow.stats["designs"] == 4 * 16
    assert fast.stats["backend"] == ["compiled-simd"] and {r["path"] for r in fast.rows} == {"batched"}
    assert {r["status"] for r in fast.rows} == {"ok"}
    worst = max_rel_diff(fast.rows, slow.rows)
    assert worst[0] < MATCH_RTOL, f"Max diff is {worst[0]:.4E} at {worst[1]}"
    assert sorted(fast.traces) == sorted(slow.traces) == list(range(16))
    gap = max(np.abs(fast.traces[k] - slow.traces[k]).max() for k in fast.traces)
    assert gap < TRACE_ATOL, f"Max trace diff is {gap:.4E}"
    # physics: the cases do differ, and by what they vary (a heavier plant sags before the integrator acts)
    by = {(r["simulation.plant.mass"], r["controller.delay"]): r for r in fast.rows
          if r["simulation.plant.inertia[0]"] == 6.2e-5 and r["motors.time_constant"] == 0.02}
    assert by[(0.075, 0.0)]["peak.T"] > by[(0.061, 0.0)]["peak.T"]


@pytest.mark.compiler
def test_an_included_lag_design_flies_the_vehicle_variations_as_the_one_case_path(mambo):
    """rotor_lag include: the design (with its lag model) is made once, by the one-case design; the
    mass and delay variations run in the lanes."""
    data = {"parameters": {"simulation.plant.mass": [0.061, 0.075], "controller.delay": [0.0, 0.005]},
            "set": {**SHORT, "controller.rotor_lag": "include"}, "chunk_size": 8}
    spec = sweep.from_dict(data, mambo, "u.yaml")
    assert spec.monte_carlo
    fast = sweep.run(mambo, spec, jobs=1)
    slow = sweep.run(mambo, spec, jobs=1, fast=False)
    assert fast.stats["designs"] == 4 and fast.stats["backend"] == ["compiled-simd"]
    assert {r["path"] for r in fast.rows} == {"one-by-one: the design includes the rotors' lag"}
    worst = max_rel_diff(fast.rows, slow.rows)
    assert worst[0] < MATCH_RTOL, f"Max diff is {worst[0]:.4E} at {worst[1]}"


@pytest.mark.compiler
def test_the_bands_file_names_its_states_units_and_parameters(mambo, tmp_path):
    data = {"parameters": {"simulation.plant.mass": [0.061, 0.068, 0.075], "simulation.noise.seed": [1, 2]},
            "set": SHORT}
    spec = sweep.from_dict(data, mambo, "u.yaml")
    outcome = sweep.execute(mambo, spec, tmp_path, jobs=1)
    arrays, meta = artifacts.read_npz(tmp_path / "montecarlo.npz")
    states = list(arrays["states"])
    assert states == sweep.regulated_states(mambo)
    assert list(arrays["units"]) == [meta["units"][s] for s in states]
    assert meta["units"]["phi"] == "rad" and meta["units"]["pD"] == "m" and meta["t_unit"] == "s"
    assert list(arrays["parameters"]) == meta["parameters"] == ["simulation.plant.mass", "simulation.noise.seed"]
    assert arrays["traces"].shape == (6, sweep.MC_POINTS, len(states))
    assert np.all(np.diff(arrays["bands"], axis=0) >= 0)
    assert outcome.summary["montecarlo"]["parameters"] == ["simulation.plant.mass", "simulation.noise.seed"]
    assert (tmp_path / "montecarlo.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


