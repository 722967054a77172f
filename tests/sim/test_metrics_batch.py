"""Metrics of a batch of runs (quadctl.metrics.summarize_errors, what a sweep's chunks use) are each
run's alone, to the last bit, and a sweep's rows do not depend on how its cases are batched."""

from __future__ import annotations

import json

import numpy as np
import pytest

from quadctl import config, metrics, sweep
from quadctl.layout import STATE_NAMES
from quadctl.sweep.lane_rows import MetricsBatch


def _runs(rng, B: int, r: int):
    err = rng.standard_normal((B, 12, r)) * np.exp(-np.linspace(0, rng.uniform(0, 8), r))
    err[:, 2] = 0.0                                  # a state that never moves (pD): settles at once
    err[0, 3, -1] = np.nan                           # a run that diverged
    err[-1, 5, r // 2:] = 5.0                        # one that never settles
    u = rng.standard_normal((B, 4, r))
    t = np.cumsum(rng.uniform(0.5, 1.5, (B, r)), axis=1) * 1e-3
    Q = np.zeros((B, 12, 12))
    Q[:, range(2, 12), range(2, 12)] = rng.random((B, 10))
    Q[:, 3, 4] = Q[:, 4, 3] = 0.01                    # an off-diagonal weight
    R = np.zeros((B, 4, 4))
    R[:, range(4), range(4)] = rng.random((B, 4))
    return t, err, u, rng.standard_normal((B, 4)), Q, R


@pytest.mark.parametrize("B, r", [(1, 2), (3, 17), (8, 2001), (5, 10001)])
def test_a_batch_gives_each_run_its_own_numbers(B, r):
    t, err, u, u_trim, Q, R = _runs(np.random.default_rng(B * r), B, r)
    regulated = STATE_NAMES[2:]
    together = metrics.summarize_errors(t, err, u, u_trim, Q, R, regulated, ["ok"] * B)
    alone = [metrics.summarize_errors(t[b:b + 1].copy(), err[b:b + 1].copy(), u[b:b + 1].copy(), u_trim[b:b + 1],
                                      Q[b:b + 1], R[b:b + 1], regulated, ["ok"])[0] for b in range(B)]
    assert json.dumps(together) == json.dumps(alone)  # every number, to its last digit
    assert together[-1]["settling_time"]["w"] is None and together[0]["settling_time"]["pD"] == 0.0
    if r > 2:
        assert together[0]["cost"] is None           # the diverged run's cost is not a number


def test_summarize_run_is_summarize_errors_of_one_run():
    t, err, u, u_trim, Q, R = _runs(np.random.default_rng(7), 1, 300)
    x_trim = np.linspace(-1, 1, 12)
    x_rate = np.zeros(12)
    x_rate[0] = 1.0
    x = (err[0] + x_trim[:, None] + np.outer(x_rate, t[0])).T
    one = metrics.summarize_run(t[0], x, u[0].T, (x_trim, x_rate), u_trim[0], Q[0], R[0], STATE_NAMES, "ok")
    err_again = metrics.error_into(np.empty((12, 300)), t[0], x.T, x_trim, x_rate)
    ref = metrics.summarize_errors(t, err_again[None], u, u_trim, Q, R, STATE_NAMES, ["ok"])[0]
    assert json.dumps(one) == json.dumps(ref)
    np.testing.assert_allclose(err_again, err[0], rtol=0, atol=1e-12)


def test_sweep_rows_do_not_depend_on_the_batch_size(monkeypatch):
    cfg = config.load("mambo-200hz")
    spec = sweep.from_dict({"parameters": {"lqr.roll.R[0]": [2e4, 4e4, 8e4], "simulation.noise.seed": [1, 2]},
                            "set": {"simulation.duration": 0.3}}, cfg, "test.yaml")
    eight = sweep.run(cfg, spec, jobs=1)
    monkeypatch.setattr(MetricsBatch, "SIZE", 1)
    one = sweep.run(cfg, spec, jobs=1)
    assert json.dumps(eight.rows) == json.dumps(one.rows)


def test_a_run_cut_short_has_no_settling_time_but_its_other_metrics():
    """A run that left the bounds has not shown where it settles: settling is None for every state
    (a quiet state would otherwise look settled at the step the run stopped), peaks stay."""
    rng = np.random.default_rng(3)
    t, err, u, u_trim, Q, R = _runs(rng, 2, 300)
    ok, cut = metrics.summarize_errors(t, err, u, u_trim, Q, R, STATE_NAMES, ["ok", "diverged"])
    assert ok["settling_time"]["pD"] == 0.0 and cut["settling_time"]["pD"] is None
    assert all(v is None for v in cut["settling_time"].values())
    assert cut["peak_error"]["phi"] == float(np.abs(err[1, 6]).max())
