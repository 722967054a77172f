"""The full 12-state LQR against the decoupled design: never worse on the linear model."""

from __future__ import annotations

import numpy as np
import pytest
from _solve import cfg_dict, solve

from quadctl import compare, config
from quadctl.design import coupled, riccati_residual
from quadctl.layout import STATE_INDEX
from quadctl.setup import setup_of


@pytest.mark.parametrize("name", ["forward", "mambo-200hz"])
def test_full_design_cost_never_exceeds_the_decoupled_one(name):
    """Both minimize the same cost; the full LQR is its optimum on the coupled linear model."""
    setup, trim, linear, _, des = solve(cfg_dict(name))
    fd = coupled.full_design(des, linear.A, linear.B)
    assert fd.stable
    dx0 = setup.initial_offset
    j_dec = coupled.linear_cost(linear.A, linear.B, des.K_block, des.Ki_block, des, dx0)
    j_full = coupled.linear_cost(linear.A, linear.B, fd.K, fd.Ki, des, dx0)
    assert j_full <= j_dec * (1 + 1e-9)
    rng = np.random.default_rng(0)
    for _ in range(5):  # any offset, not just the configured one
        dx = rng.normal(size=12) * 0.1
        dx[[STATE_INDEX["pN"], STATE_INDEX["pE"]]] = 0.0
        assert coupled.linear_cost(linear.A, linear.B, fd.K, fd.Ki, des, dx) <= \
            coupled.linear_cost(linear.A, linear.B, des.K_block, des.Ki_block, des, dx) * (1 + 1e-9)


def test_full_design_leaves_unweighted_positions_out_and_solves_the_care():
    _, _, linear, _, des = solve(cfg_dict("forward"))
    fd = coupled.full_design(des, linear.A, linear.B)
    assert fd.left_out == ("pN", "pE") and "pD" in fd.states
    assert not np.any(fd.K[:, [STATE_INDEX["pN"], STATE_INDEX["pE"]]])
    keep = [STATE_INDEX[s] for s in fd.states]
    assert riccati_residual(linear.A[np.ix_(keep, keep)], linear.B[keep], fd.Q, fd.R, fd.P) < 1e-8
    # the full gain uses couplings the decoupled one cannot: thrust reacts to pitch
    assert abs(fd.K[0, STATE_INDEX["theta"]]) > 0.1


def test_compare_reports_a_winner_and_a_ratio_per_criterion():
    cfg, trim, linear, _, des = solve(cfg_dict("mambo-200hz"))
    data = cfg_dict("mambo-200hz")
    data["simulation"]["duration"] = 4.0
    setup = setup_of(config.from_dict(data))
    fd, comparison = compare.compare_full(setup, linear, des)
    assert set(comparison["designs"]) == {"decoupled", "full"}
    lin = comparison["better"]["linear_cost"]
    assert lin["winner"] in ("full", None) and lin["ratio"] >= 1.0
    for run in comparison["designs"].values():
        assert run["status"] == "ok" and run["peak_input"]["T"] > 0
