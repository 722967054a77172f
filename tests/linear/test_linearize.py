"""linearize: the drift of its operating point, and its arguments (what is not the operating point's finite numbers
is refused by name)."""

from __future__ import annotations

import numpy as np
import pytest

from quadctl.errors import ArgumentError, ArgumentTypeError
from quadctl.layout import POSITION
from quadctl.linear.linearize import linearize
from quadctl.linear.trim import solve_trim
from quadctl.physics.model import Vehicle

HOVER_U = [0.068 * 9.81, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("x,u,wind,label", [
    (np.zeros(11), HOVER_U, None, "x_trim"),         # CasADi's 'mismatching shape' RuntimeError
    (np.zeros(12), HOVER_U[:3], None, "u_trim"),
    (np.zeros((1, 12)), HOVER_U, None, "x_trim"),
    (np.full(12, np.nan), HOVER_U, None, "x_trim"),  # a model of NaN, returned
    (np.zeros(12), [np.inf, 0, 0, 0], None, "u_trim"),
    (np.zeros(12), HOVER_U, [1.0, 0.0], "wind_ned"),
    (np.zeros(12), HOVER_U, [np.nan, 0.0, 0.0], "wind_ned"),
    (["a"] * 12, HOVER_U, None, "x_trim"),
])
def test_linearize_refuses_an_operating_point_that_is_not_finite_numbers_of_its_size(x, u, wind, label):
    with pytest.raises(ArgumentError, match=f"linearize: {label} must be"):
        linearize(x, u, Vehicle(), wind)


def test_linearize_refuses_what_is_not_a_vehicle():
    with pytest.raises(ArgumentTypeError, match="linearize takes a Vehicle"):
        linearize(np.zeros(12), HOVER_U, {"mass": 0.068})


def test_linearize_takes_lists_and_integers():
    lin = linearize([0] * 12, HOVER_U, Vehicle(), wind_ned=[0, 0, 0])
    assert lin.A.shape == (12, 12) and lin.B.shape == (12, 4) and lin.x_trim.dtype == float


@pytest.mark.parametrize("velocity, yaw, wind", [
    ([1.0, 0.0, 0.0], 0.0, None),          # the report's forward flight
    ([0.6, -0.8, -0.3], 0.7, None),        # climbing, heading off the velocity
    ([-0.5, 0.4, 0.2], -2.0, [1.5, -1.0, 0.0]),  # descending in a steady wind
])
def test_the_reference_drifts_at_the_trims_ground_velocity(velocity, yaw, wind):
    """x_ref(t) = x_trim + x_rate t: the positions move at the velocity over the ground the trim was asked
    for (NED, whatever the heading and the wind), and nothing else drifts."""
    vehicle = Vehicle(drag=(0.22, 0.25, 0.05))
    trim = solve_trim(velocity, yaw, [0.0, 0.0, -1.0], vehicle, wind_ned=wind)
    rate = linearize(trim.x, trim.u, vehicle, wind).x_rate
    np.testing.assert_allclose(rate[POSITION], velocity, rtol=0, atol=1e-12)  # a rotation and back: round-off
    assert not np.any(np.delete(rate, np.arange(12)[POSITION]))
