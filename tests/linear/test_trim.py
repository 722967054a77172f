"""Trim: the report's numbers, hover, residuals across flight conditions, no-equilibrium cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadctl.errors import ArgumentError, ArgumentTypeError, TrimError
from quadctl.layout import STATE_INDEX
from quadctl.linear.trim import RESIDUAL_TOL, solve_trim
from quadctl.physics.model import Vehicle, evaluate


def test_report_forward_trim_to_four_digits():
    t = solve_trim([1.0, 0.0, 0.0], 0.0, [0, 0, -1], Vehicle())
    assert round(t.x[STATE_INDEX["theta"]], 4) == -0.2119
    assert round(t.u[0], 4) == 0.6522
    theta = t.x[STATE_INDEX["theta"]]
    # closed forms of the balance (docs/model.md): T = m g cos(theta) and 0.22 cos^2(theta) = -sin(theta)
    assert t.u[0] == pytest.approx(0.068 * 9.81 * math.cos(theta), rel=1e-12)
    assert 0.22 * math.cos(theta) ** 2 == pytest.approx(-math.sin(theta), rel=1e-12)
    np.testing.assert_allclose(t.x[[3, 5]], [math.cos(theta), math.sin(theta)], rtol=1e-12)


def test_hover_is_mg():
    v = Vehicle(mass=0.1, gravity=9.8)
    t = solve_trim([0, 0, 0], 0.4, [1, 2, -3], v)
    assert t.u[0] == pytest.approx(0.98, rel=1e-14)
    np.testing.assert_allclose(t.x[6:8], 0.0, atol=1e-14)
    np.testing.assert_allclose(t.x[:3], [1, 2, -3])


@pytest.mark.parametrize("velocity,yaw", [
    ([1, 0, 0], 0.0), ([0, 2, 0], 0.3), ([3, -2, -1], -2.0), ([0, 0, -2], 1.0),
    ([5, 5, 0.5], 3.0), ([0.2, 0.1, 1.5], -0.7), ([8, 0, 0], 0.0),
])
def test_equilibrium_residual_and_position_rate(velocity, yaw):
    v = Vehicle(drag=(0.22, 0.25, 0.05))
    t = solve_trim(velocity, yaw, [0, 0, -1], v)
    xdot = evaluate(t.x, t.u, v)
    assert np.abs(xdot[3:]).max() < RESIDUAL_TOL
    np.testing.assert_allclose(xdot[:3], velocity, atol=1e-12)  # moves at the asked velocity
    assert t.x[STATE_INDEX["psi"]] == yaw and t.u[0] > 0 and not np.any(t.u[1:])


def test_heading_rotates_the_problem_not_the_answer():
    """Flying along the heading gives the same attitude and thrust for any heading."""
    base = solve_trim([2, 0, 0], 0.0, [0, 0, 0], Vehicle())
    for psi in (0.5, 2.0, -2.5):
        t = solve_trim([2 * math.cos(psi), 2 * math.sin(psi), 0], psi, [0, 0, 0], Vehicle())
        np.testing.assert_allclose(t.x[6:8], base.x[6:8], atol=1e-12)
        assert t.u[0] == pytest.approx(base.u[0], rel=1e-12)


def test_climb_with_body_z_drag_past_its_limit_has_no_equilibrium():
    with pytest.raises(TrimError, match=r"no equilibrium at velocity_ned \[0, 0, -10\].*thrust .* <= 0"):
        solve_trim([0, 0, -10], 0.0, [0, 0, 0], Vehicle(drag=(0.2, 0.2, 0.2)))


def test_speed_beyond_the_euler_range_is_refused_with_the_angle():
    with pytest.raises(TrimError, match=r"needs pitch -8\d\.\d deg, beyond the 80 deg"):
        solve_trim([200, 0, 0], 0.0, [0, 0, 0], Vehicle())


@pytest.mark.parametrize("speed,ramp", [
    (3.0, r"the solver's ramp reached 25 % of it and stalled at 50 %"),
    (5.0, r"the solver's ramp stalled at its first step, 25 % of it"),
])
def test_non_convergence_names_the_requested_velocity_and_how_far_the_ramp_got(speed, ramp):
    """It named the ramp's intermediate speed ([1.25, 0, 0] for a requested [5, 0, 0]) as if requested."""
    vehicle = Vehicle(drag=(1.0, 1.0, 1.0))
    with pytest.raises(TrimError, match=rf"^trim\.velocity_ned = \[{speed:g}, 0, 0\] m/s: trim did not converge; "
                                        rf"{ramp} \(residual .* m/s\^2 after \d+ iterations\); try a lower speed"):
        solve_trim([speed, 0, 0], 0.0, [0, 0, -1], vehicle)
    if "reached 25 %" in ramp:  # the quarter of the speed the message says was reached is an equilibrium
        t = solve_trim([0.25 * speed, 0, 0], 0.0, [0, 0, -1], vehicle)
        assert t.residual <= RESIDUAL_TOL


@pytest.mark.parametrize("wind", [None, [2.0, -1.0, 0.5]])
def test_batched_trims_are_the_one_point_trims(wind):
    """solve_trims runs the same damped Newton on all points at once: the same trims, bit for bit and
    in as many iterations, and the same refusal where there is none (a tilt beyond the model's, a
    speed the direct Newton misses and the homotopy solves)."""
    from quadctl.errors import TrimError
    from quadctl.linear.trim import solve_trims

    V = [[s * np.cos(0.3), s * np.sin(0.3), vd] for s in np.linspace(0.0, 30.0, 12) for vd in (-2.0, 0.0, 1.5)]
    V += [[200.0, 0.0, 0.0], [0.0, 0.0, 50.0], [120.0, 0.0, 0.0]]
    yaws = np.linspace(-1.0, 1.0, len(V))
    yaws[-3] = yaws[-1] = 0.0
    found = solve_trims(V, yaws, [0.0, 0.0, -1.0], Vehicle(), wind_ned=wind)
    refused = 0
    for v, yaw, got in zip(V, yaws, found):
        try:
            ref = solve_trim(v, yaw, [0.0, 0.0, -1.0], Vehicle(), wind_ned=wind)
        except TrimError as exc:
            assert isinstance(got, TrimError) and str(got) == str(exc)
            refused += 1
            continue
        np.testing.assert_array_equal(got.x, ref.x)
        np.testing.assert_array_equal(got.u, ref.u)
        np.testing.assert_array_equal(got.xdot, ref.xdot)
        assert (got.iterations, got.residual) == (ref.iterations, ref.residual)
    assert refused == 1  # 200 m/s; in still air 120 m/s is solved by the homotopy (the direct Newton misses it)


@pytest.mark.parametrize("velocity,yaw,position,wind", [
    ([np.nan, 0, 0], 0.0, [0, 0, 0], None),   # NaN ran through Newton and came out a Trim of NaN
    ([1, 0, 0], 0.0, [0, 0, 0], [np.inf, 0, 0]),
    ([1, 0, 0], float("nan"), [0, 0, 0], None),
    ([1, 0, 0], 0.0, [0, 0, np.nan], None),
    ([1, 0], 0.0, [0, 0, 0], None),           # CasADi's 'mismatching shape' RuntimeError
    ([1, 0, 0], [0.0], [0, 0, 0], None),
    ([1, 0, 0], 0.0, None, None),
    (["1", 0, 0], 0.0, [0, 0, 0], None),
])
def test_trim_refuses_arguments_that_are_not_finite_numbers_of_their_shape(velocity, yaw, position, wind):
    with pytest.raises(ArgumentError, match="trim: (velocity_ned|yaw|position_ned|wind_ned) must be"):
        solve_trim(velocity, yaw, position, Vehicle(), wind_ned=wind)


@pytest.mark.parametrize("max_iter", [0, -1, 1.5])
def test_trim_refuses_a_max_iter_that_is_not_a_whole_number_of_one_or_more(max_iter):
    """0 and -1 were a TrimError blaming the speed and the vehicle ('after -1 iterations'), 1.5 Python's
    TypeError."""
    with pytest.raises(ArgumentError, match=rf"^trim: max_iter must be a whole number .*got {max_iter!r}$"):
        solve_trim([1, 0, 0], 0.0, [0, 0, 0], Vehicle(), max_iter=max_iter)


def test_trim_refuses_what_is_not_a_vehicle():
    with pytest.raises(ArgumentTypeError, match="trim takes a Vehicle"):
        solve_trim([0, 0, 0], 0.0, [0, 0, 0], {"mass": 0.068})
