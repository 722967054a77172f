"""Integral action (LQI): a model mismatch's steady error goes to zero; anti-wind-up under saturation."""

from __future__ import annotations

import numpy as np
import pytest
from _solve import cfg_dict, run, solve

from quadctl.design import integral
from quadctl.layout import INPUT_INDEX, STATE_INDEX

MASS_ERROR = 1.10
"""The simulated vehicle is 10 % heavier than the design model."""


def _hover(integrate: bool, **sim) -> dict:
    data = cfg_dict("hover")
    data["simulation"].update({"duration": 12.0, "initial_offset": {}, "plant": {"mass": 0.068 * MASS_ERROR}},
                              **sim)
    if integrate:
        data["lqr"]["altitude"] = {"Q": [50.0, 1.0, 20.0], "R": [1.0], "integral": ["pD"]}
    return data


def test_augmented_plant_matches_matlab_lqi():
    Aa, Ba = integral.augment([[0.0, 1.0], [0.0, -2.0]], [[0.0], [3.0]], integral.selector(["a", "b"], ["a"]))
    np.testing.assert_array_equal(Aa, [[0, 1, 0], [0, -2, 0], [-1, 0, 0]])
    np.testing.assert_array_equal(Ba, [[0], [3], [0]])
    Ad, Bd = integral.augment_discrete([[1.0]], [[0.5]], [[1.0]], 0.01)
    np.testing.assert_array_equal(Ad, [[1, 0], [-0.01, 1]])


def test_plain_lqr_leaves_the_hand_derived_steady_error_and_lqi_removes_it():
    """Hover, 10 % heavier: thrust must rise by 0.1 m g; plain LQR gets it from a steady altitude
    error e = 0.1 m g / |K_pD| (about 9.4 mm below the reference); LQI's integrator supplies it."""
    cfg, des, _, plain = run(_hover(False))
    k_pd = des["altitude"].K[0, 0]
    expected = 0.1 * 0.068 * 9.81 / abs(k_pd)
    err_plain = plain.x[-1, STATE_INDEX["pD"]] - plain.x_ref[-1, STATE_INDEX["pD"]]
    assert err_plain == pytest.approx(expected, rel=1e-3)
    cfg, des, loop, lqi = run(_hover(True))
    assert lqi.status == "ok" and des.integral_states == ("pD",)
    err_lqi = lqi.x[-1, STATE_INDEX["pD"]] - lqi.x_ref[-1, STATE_INDEX["pD"]]
    assert abs(err_lqi) < 1e-3 * expected, err_lqi
    # the integrator holds the missing thrust: -Ki z = 0.1 m g
    assert -des.Ki_block[INPUT_INDEX["T"], 0] * lqi.z[-1, 0] == pytest.approx(0.1 * 0.068 * 9.81, rel=1e-3)


def test_lqi_at_200hz_on_the_mambo_design_removes_the_error_too():
    data = cfg_dict("mambo-200hz")
    data["simulation"].update({"duration": 15.0, "noise": None, "plant": {"mass": 0.068 * MASS_ERROR}})
    _, des, _, sim = run(data)
    data["lqr"]["altitude"] = {"Q": [4.0, 4.0], "R": [25.0]}
    _, des_plain, _, plain = run(data)
    pd = STATE_INDEX["pD"]
    err_plain = plain.x[-1, pd] - plain.x_ref[-1, pd]
    err_lqi = sim.x[-1, pd] - sim.x_ref[-1, pd]
    assert err_plain > 0.05  # a soft altitude loop: 10 % of the weight costs decimetres
    assert abs(err_lqi) < 1e-3 * err_plain, (err_plain, err_lqi)


def test_anti_windup_freezes_the_integrator_while_thrust_is_clipped():
    """Thrust limited below what the heavier vehicle needs: it sinks, the thrust stays clipped,
    and the integrator must not move while it is (conditional integration)."""
    data = _hover(True, duration=2.0)
    data["limits"] = {"T": [0.0, 1.05 * 0.068 * 9.81]}
    _, _, loop, sim = run(data)
    clipped = sim.u[:, INPUT_INDEX["T"]] >= loop.actuators.hi[INPUT_INDEX["T"]] - 1e-12
    both = clipped[:-1] & clipped[1:]
    assert both.sum() > 0.5 * len(both)
    dz = np.diff(sim.z[:, 0])
    assert np.all(dz[both] == 0.0)
    assert np.any(dz[~clipped[:-1]] != 0.0)  # and it does integrate when the input is free


def test_the_discrete_lqi_gain_tends_to_the_continuous_one_as_the_rate_rises():
    """mambo-200hz's altitude LQI (integral of pD) designed at 1 and 10 kHz against MATLAB ``lqi``'s
    continuous gain, solved here by SciPy on the augmented plant ``[[A, 0], [-C, 0]]``: the discrete
    design (``lqrd`` weights for the plant, the integrator rows ``Q Ts``, forward-Euler accumulator)
    converges to it at first order in ``Ts`` (a gap ten times smaller at ten times the rate; second
    order would give 100), and at 10 kHz ``Kx`` and ``Ki`` are within 0.1 % of it (measured 0.036 %:
    3.6e-3 at 1 kHz, 3.6e-4 at 10 kHz). Integrator weights not scaled by ``Ts``, or an accumulator
    without ``Ts``, leave the gap from 1 to 10 kHz shrinking 0.2 to 5 times, not 10."""
    import scipy.linalg

    from quadctl.design import design

    setup, trim, linear, dec, _ = solve(cfg_dict("mambo-200hz"))
    sub = dec["altitude"]
    assert setup.integral["altitude"] == ("pD",)
    Q, R = setup.weights["altitude"]
    Aa, Ba = integral.augment(sub.A, sub.B, integral.selector(sub.states, ["pD"]))
    P = scipy.linalg.solve_continuous_are(Aa, Ba, Q, R)
    K_c = np.linalg.solve(R, Ba.T @ P)  # [Kx, Ki]
    gaps = []
    for rate in (1e3, 1e4):
        des = design(dec, linear.A, linear.B, setup.weights, rate=rate, integral=setup.integral)
        K_d = np.hstack([des["altitude"].K, des["altitude"].Ki])
        gaps.append(np.abs(K_d - K_c) / np.abs(K_c))
    ratio = gaps[0] / gaps[1]
    assert np.all((8 < ratio) & (ratio < 12)), f"gap at 1 kHz / at 10 kHz: {ratio.round(2)}"
    assert gaps[1].max() < 1e-3, f"relative gap at 10 kHz: {gaps[1]}"
