"""Seeded process and sensor noise: reproducible, on its own clock, with the stated spread."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _solve import cfg_dict, run

from quadctl.physics import noise


def _noisy(seed: int) -> dict:
    data = cfg_dict("mambo-200hz")
    data["simulation"]["duration"] = 3.0
    data["simulation"]["noise"]["seed"] = seed
    return data


def test_same_seed_same_run_bit_for_bit():
    runs = [run(_noisy(3))[3] for _ in range(2)]
    runs.append(run(_noisy(4))[3])
    assert np.array_equal(runs[0].x, runs[1].x) and np.array_equal(runs[0].u, runs[1].u)
    assert not np.array_equal(runs[0].x, runs[2].x)
    assert runs[0].noise_seed == 3


def test_the_realization_does_not_depend_on_the_rk4_step():
    spec = noise.NoiseSpec(seed=5, process_std=np.full(6, 0.1), sensor_std=np.full(12, 0.2), period=0.005)
    d1, m1 = noise.realize(spec, 400, 0.001)
    d2, m2 = noise.realize(spec, 800, 0.0005)
    np.testing.assert_array_equal(d1, d2[::2])
    np.testing.assert_array_equal(m1, m2[::2])
    assert np.all(d1[:5] == d1[0]) and not np.all(d1[5] == d1[0])  # held for one period


def test_one_kind_of_noise_does_not_change_the_other():
    both = noise.NoiseSpec(seed=9, process_std=np.full(6, 0.1), sensor_std=np.full(12, 0.2), period=0.01)
    only = noise.NoiseSpec(seed=9, process_std=np.zeros(6), sensor_std=np.full(12, 0.2), period=0.01)
    assert noise.realize(only, 100, 0.01)[0] is None
    np.testing.assert_array_equal(noise.realize(both, 100, 0.01)[1], noise.realize(only, 100, 0.01)[1])


def test_samples_have_the_configured_standard_deviation():
    std = np.array([0.5, 0.0, 2.0, 1e-3, 0.0, 0.1])
    spec = noise.NoiseSpec(seed=11, process_std=std, sensor_std=np.zeros(12), period=1.0)
    dist, _ = noise.realize(spec, 20000, 1.0)
    # 20000 draws: the sample std is within 3 % of the truth (its own std is ~0.5 %)
    np.testing.assert_allclose(dist.std(axis=0), std, rtol=0.03)


def test_rms_deviation_of_a_sine_is_amplitude_over_root_two():
    t = np.linspace(0, 10, 100001)
    x = np.zeros((len(t), 12))
    x[:, 3] = 0.4 * np.sin(2 * math.pi * t)
    rms = noise.rms_deviation(t, x, np.zeros_like(x))
    assert rms["u"] == pytest.approx(0.4 / math.sqrt(2), rel=1e-4) and rms["pN"] == 0.0
    assert noise.rms_deviation(t, x, np.zeros_like(x), t_from=5.0)["u"] == pytest.approx(0.4 / math.sqrt(2), rel=1e-4)


def test_sensor_noise_alone_moves_the_vehicle_through_the_controller():
    data = cfg_dict("mambo-200hz")
    data["simulation"].update({"duration": 3.0, "initial_offset": {}})
    data["simulation"]["noise"] = {"seed": 2, "sensor": {"phi": 0.01}}
    cfg, _, loop, sim = run(data)
    from quadctl import run_summary

    rms = run_summary.flight_summary(cfg, loop, sim)["rms_error"]
    assert rms["phi"] > 1e-4 and rms["psi"] < 1e-9  # roll is disturbed, yaw untouched
