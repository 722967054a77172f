"""A sweep case's setup built from the base's and the varied values (quadctl.sweep.prepare.CaseSetups)
equals the one its whole config validates and resolves to, and an invalid value gives the same error."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from quadctl import config, sweep
from quadctl.errors import ConfigError
from quadctl.sweep.prepare import CaseSetups
from quadctl.sweep.runner import tasks_for


def same(a, b, where="setup") -> None:
    """Assert two setups (or parts) are equal, arrays exactly; names the first difference."""
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, (tuple, list)) and not isinstance(a, str):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray):
        assert np.array_equal(a, b), where
    else:
        assert a == b and type(a) is type(b), f"{where}: {a!r} vs {b!r}"


def task_of(name: str, parameters: dict, cases: list[tuple]):
    cfg = config.load(name)
    spec = sweep.from_dict({"parameters": {k: list(v) for k, v in parameters.items()}}, cfg, "test.yaml")
    task = tasks_for(cfg, spec, spec.cases()[:1], name, 1)[0]
    return dataclasses.replace(task, cases=tuple((i, tuple(v)) for i, v in enumerate(cases)))


MAMBO = {"lqr.roll.Q[1]": [50.0], "lqr.roll.R[0]": [4e4], "lqr.yaw.Q[0]": [25.0], "simulation.noise.seed": [1]}


@pytest.mark.parametrize("name, parameters, cases", [
    ("mambo-200hz", MAMBO, [(10.0, 12000.0, 2.5, 3), (1000.0, 130000.0, 250.0, 16), (0.0, 1.0, 0.0, 0),
                            (123.25, 4e4, 1e-15, 7.0)]),
    ("forward", {"lqr.pitch.Q[1]": [50.0], "lqr.altitude.R[0]": [1.0]}, [(5.0, 0.3), (500.0, 3.0)]),
    # with integral action (the Q of an LQI subsystem has its integrators' entries)
    ("mambo-200hz", {"lqr.altitude.Q[2]": [1.0]}, [(0.5,), (2.0,)]),
    # with wind (its own seed: the noise seed does not touch it)
    ("crazyflie-wind", {"lqr.roll.Q[1]": [50.0]}, [(5.0,), (500.0,)]),
])
def test_varied_setups_equal_the_resolved_ones(name, parameters, cases):
    task = task_of(name, parameters, cases)
    setups = CaseSetups(task)
    assert setups.kinds is not None  # these keys take the quick way
    for index, values in task.cases:
        same(setups(index, values), setups.from_config(index, values))


@pytest.mark.parametrize("values", [
    (-1.0, 4e4, 25.0, 1),        # Q entry negative: not positive semidefinite
    (50.0, 0.0, 25.0, 1),        # R entry zero: not positive definite
    (50.0, 1e300, 25.0, 1),      # outside WEIGHT_RANGE
    (float("nan"), 4e4, 25.0, 1),
    (50.0, 4e4, 25.0, -2),       # a negative seed
    (50.0, 4e4, 25.0, 1.5),      # a seed that is not whole
    (50.0, 4e4, "a", 1),         # not a number
    (True, 4e4, 25.0, 1),        # a bool is not a number in the schema
])
def test_an_invalid_value_gives_the_error_of_the_whole_validation(values):
    task = task_of("mambo-200hz", MAMBO, [values])
    setups = CaseSetups(task)
    with pytest.raises(ConfigError) as reference:
        setups.from_config(0, values)
    with pytest.raises(ConfigError) as quick:
        setups(0, values)
    assert str(quick.value) == str(reference.value)
    assert "case 0" in str(quick.value) and "\n" not in str(quick.value)


def test_other_keys_take_the_whole_validation():
    task = task_of("mambo-200hz", {"vehicle.mass": [0.07], "lqr.roll.Q[1]": [50.0]}, [(0.07, 50.0), (-1.0, 50.0)])
    setups = CaseSetups(task)
    assert setups.kinds is None
    same(setups(0, (0.07, 50.0)), setups.from_config(0, (0.07, 50.0)))
    with pytest.raises(ConfigError, match=r"case 1: vehicle\.mass = -1"):
        setups(1, (-1.0, 50.0))


@pytest.mark.parametrize("definite", [True, False])
def test_the_stacked_weight_check_passes_what_check_weight_passes(definite):
    """Each row of diagonal_weights_pass's verdict is whether check_weight raises for that diagonal:
    edges of WEIGHT_RANGE, zeros, negatives and the definiteness floor (relative to the largest)."""
    edges = [0.0, -0.0, 1e-15, 9.99e-16, 1e15, 1.01e15, -1e-15, 1.0, -1.0, 2.5, 1e-13, -1e-13, 1e-12, 5e-3]
    rng = np.random.default_rng(7)
    rows = []
    for _ in range(400):  # positive weights, one entry an edge
        row = list(10.0 ** rng.uniform(-3, 3, size=3))
        row[rng.integers(3)] = rng.choice(edges)
        rows.append(row)
    rows += [[1.0, 1e-12, 1.0], [1.0, 1.0001e-12, 1.0], [1.0, -1e-12, 1.0], [1.0, -1.0001e-12, 1.0]]

    def passes(row):
        try:
            config.check_weight([float(v) for v in row], 3, "lqr.roll.Q", "c.yaml", definite=definite,
                                names=["a", "b", "c"])
        except ConfigError:
            return False
        return True

    expected = [passes(row) for row in rows]
    assert 50 < sum(expected) < len(rows) - 50  # both verdicts well represented
    assert config.diagonal_weights_pass(np.array(rows), definite=definite).tolist() == expected
