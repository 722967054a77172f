"""The CasADi model: Jacobians, kinematics, conservation laws, the report's equilibrium."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from _finite_differences import assert_jacobians_match_central_differences
from _rotation import body_to_earth as rotation_body_to_earth

from quadctl.layout import STATE_INDEX
from quadctl.physics.model import Vehicle, build_model, euler_rates_matrix, evaluate, rotation_earth_to_body


def _random_point(rng):
    x = rng.normal(size=12) * 0.3
    x[STATE_INDEX["theta"]] = rng.uniform(-1.0, 1.0)  # stay off the Euler singularity
    u = np.array([rng.uniform(0.3, 1.0), *rng.normal(size=3) * 1e-3])
    return x, u


@pytest.mark.parametrize("seed", range(6))
def test_jacobians_match_central_differences(seed):
    rng = np.random.default_rng(seed)
    x, u = _random_point(rng)
    assert_jacobians_match_central_differences(x, u, Vehicle(drag=(0.22, 0.3, 0.1)))  # a nonzero Kz: every drag term


def test_euler_rate_inverse_matches_H():
    """The closed-form H^-1 in the dynamics inverts docs/model.md's H: H @ (dphi, dtheta, dpsi) = omega."""
    rng = np.random.default_rng(1)
    for _ in range(20):
        x, u = _random_point(rng)
        euler_dot = evaluate(x, u, Vehicle())[6:9]
        h = np.asarray(ca.DM(euler_rates_matrix(x[6], x[7])))
        np.testing.assert_allclose(h @ euler_dot, x[9:12], atol=1e-12)


def test_rotation_is_orthonormal_and_321():
    r = np.asarray(ca.DM(rotation_earth_to_body(0.3, -0.2, 1.1)))
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(r) == pytest.approx(1.0)
    # pure yaw rotates north into the body x axis at -psi
    ry = np.asarray(ca.DM(rotation_earth_to_body(0.0, 0.0, 0.5)))
    np.testing.assert_allclose(ry @ [1, 0, 0], [math.cos(0.5), -math.sin(0.5), 0], atol=1e-15)


def test_thrust_points_up_and_hover_balances():
    """F_T = [0, 0, -T]: at T = m g the level vehicle holds still; at T = 0 it falls at g."""
    v = Vehicle()
    x = np.zeros(12)
    hover = evaluate(x, [v.mass * v.gravity, 0, 0, 0], v)
    np.testing.assert_allclose(hover, 0.0, atol=1e-15)
    fall = evaluate(x, [0, 0, 0, 0], v)
    assert fall[STATE_INDEX["w"]] == pytest.approx(v.gravity)  # body z is down


def test_report_equilibrium_balances_only_with_corrected_thrust_sign():
    """docs/model.md: the report's trim (theta = -0.2119, T = m g cos theta) is exact with -T, not with +T."""
    v = Vehicle()
    theta = -0.2119
    x = np.zeros(12)
    x[[3, 5, 7]] = math.cos(theta), math.sin(theta), theta
    thrust = v.mass * v.gravity * math.cos(theta)
    xdot = evaluate(x, [thrust, 0, 0, 0], v)
    assert np.abs(xdot[3:]).max() < 1e-3  # 4-digit theta: residual of order 1e-4
    # the report's literal +T (equivalently -T into the corrected model) gives ~2 g cos(theta) in w
    wrong = evaluate(x, [-thrust, 0, 0, 0], Vehicle(drag=(-0.22, -0.22, 0.0)))
    assert wrong[STATE_INDEX["w"]] == pytest.approx(2 * v.gravity * math.cos(theta), rel=1e-3)


def _f_of_docs_model_md(x, u, vehicle, d, wind):
    """docs/model.md's equations of motion written again in numpy: R_b^E as the three turns of the 3-2-1
    sequence (yaw, then pitch, then roll), the Euler rates by solving H, the rates by solving J."""
    (u_b, v_b, w_b), (phi, theta, psi), omega = x[3:6], x[6:9], x[9:12]
    thrust, moment = u[0], u[1:4]

    body_to_earth = rotation_body_to_earth(phi, theta, psi)
    earth_to_body = body_to_earth.T
    vel = np.array([u_b, v_b, w_b])
    air = vel - earth_to_body @ wind
    force = (np.array([0.0, 0.0, -thrust]) - thrust * np.asarray(vehicle.drag) * air
             + earth_to_body @ [0.0, 0.0, vehicle.mass * vehicle.gravity] + d[:3])
    h = np.array([[1.0, 0.0, -np.sin(theta)],
                  [0.0, np.cos(phi), np.sin(phi) * np.cos(theta)],
                  [0.0, -np.sin(phi), np.cos(phi) * np.cos(theta)]])
    j = vehicle.inertia_tensor()
    return np.concatenate([body_to_earth @ vel, force / vehicle.mass - np.cross(omega, vel), np.linalg.solve(h, omega),
                           np.linalg.solve(j, moment + d[3:] - np.cross(omega, j @ omega))])


@pytest.mark.parametrize("vehicle", [
    Vehicle(drag=(0.22, 0.31, 0.07)),
    Vehicle(mass=0.5, gravity=9.7, drag=(0.1, 0.02, 0.3), products=(0.9e-5, -1.2e-5, 0.6e-5)),
], ids=["diagonal", "tensor"])
def test_f_is_the_equations_of_docs_model_md_written_again_in_numpy(vehicle):
    """Every term of f (rotation, thrust, rotor drag on the air-relative velocity with its own Kx, Ky, Kz,
    gravity, disturbance, omega x V, the Euler rates, Euler's equations) against docs/model.md in numpy, at
    random states off every axis, with wind. The two differ by round-off of their largest terms (the rates'
    J^-1 M and omega x J omega / J, of order 100 rad/s^2 here): 1e-12 of those."""
    rng = np.random.default_rng(12)
    model = build_model()
    for _ in range(20):
        x, u = _random_point(rng)
        x[9:12] *= 10.0  # rates of a few rad/s: the gyroscopic term counts
        d = np.r_[rng.normal(size=3) * 0.05, rng.normal(size=3) * 1e-4]
        wind = rng.normal(size=3) * 2.0
        got = np.asarray(model.f_disturbed_wind(x, u, vehicle.vector(), d, wind)).ravel()
        want = _f_of_docs_model_md(x, u, vehicle, d, wind)
        j = vehicle.inertia_tensor()
        scale = max(1.0, np.abs(want).max(), np.abs(np.linalg.solve(j, u[1:4])).max(),
                    np.abs(np.linalg.solve(j, np.cross(x[9:12], j @ x[9:12]))).max())
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * scale)


def test_the_disturbance_adds_its_force_over_the_mass_and_its_torque_through_the_inertia():
    """docs/model.md: F_d joins the forces over m (V^b' gains F_d / m) and M_d the moments (omega' gains
    J^-1 M_d), in the body frame, with the signs they are given; nothing else moves. Both enter linearly,
    so the difference from the undisturbed f is exactly that (the full tensor solved by numpy)."""
    rng = np.random.default_rng(4)
    j = np.array([[6.9e-5, 0.9e-5, -1.2e-5], [0.9e-5, 7.75e-5, 0.6e-5], [-1.2e-5, 0.6e-5, 1.5e-4]])
    for vehicle in (Vehicle(), Vehicle(inertia=tuple(np.diag(j)), products=(j[0, 1], j[0, 2], j[1, 2]))):
        model = build_model()
        for _ in range(5):
            x, u = _random_point(rng)
            d = np.r_[rng.normal(size=3) * 0.05, rng.normal(size=3) * 1e-4]  # N, N m
            moved = np.asarray(model.f_disturbed(x, u, vehicle.vector(), d)).ravel() - evaluate(x, u, vehicle)
            expected = np.zeros(12)
            expected[3:6] = d[:3] / vehicle.mass
            expected[9:12] = np.linalg.solve(vehicle.inertia_tensor(), d[3:])
            # round-off of f's own entries (rates of order |x| / J), not of the difference
            scale = np.abs(evaluate(x, u, vehicle)).max() + np.abs(expected).max()
            np.testing.assert_allclose(moved, expected, rtol=0, atol=1e-12 * scale)


def _rk4_open_loop(x, u, vehicle, dt, n):
    f = build_model().f
    p = vehicle.vector()
    for _ in range(n):
        k1 = np.asarray(f(x, u, p)).ravel()
        k2 = np.asarray(f(x + dt / 2 * k1, u, p)).ravel()
        k3 = np.asarray(f(x + dt / 2 * k2, u, p)).ravel()
        k4 = np.asarray(f(x + dt * k3, u, p)).ravel()
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def test_torque_free_rotation_conserves_energy_and_momentum():
    """Euler's equations with M = 0: 0.5 w'Jw and |Jw| are invariants of the exact flow."""
    v = Vehicle()
    J = np.diag(v.inertia)
    x = np.zeros(12)
    x[9:12] = [3.0, -2.0, 1.5]
    end = _rk4_open_loop(x, np.zeros(4), v, 1e-3, 2000)
    w0, w1 = x[9:12], end[9:12]
    assert 0.5 * w1 @ J @ w1 == pytest.approx(0.5 * w0 @ J @ w0, rel=1e-9)
    assert np.linalg.norm(J @ w1) == pytest.approx(np.linalg.norm(J @ w0), rel=1e-9)


def test_free_fall_conserves_mechanical_energy_while_tumbling():
    """T = 0 (so no rotor drag): 0.5 |V|^2 - g pD is constant; the omega x V term does no work."""
    v = Vehicle()
    x = np.zeros(12)
    x[3:6] = [1.0, -0.5, 0.2]
    x[9:12] = [0.7, -0.4, 0.9]
    end = _rk4_open_loop(x, np.zeros(4), v, 1e-3, 1500)

    def energy(s):
        return 0.5 * s[3:6] @ s[3:6] - v.gravity * s[STATE_INDEX["pD"]]

    assert energy(end) == pytest.approx(energy(x), rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("wind", [None, [1.0, -2.0, 0.3]])
def test_linearize_all_is_linearize_at_each_point(wind):
    """The Jacobians mapped over points are each point's own, bit for bit, with its drift ``x_rate``."""
    from quadctl.linear.linearize import linearize, linearize_all

    rng = np.random.default_rng(7)
    points = [_random_point(rng) for _ in range(6)]
    many = linearize_all([x for x, _ in points], [u for _, u in points], Vehicle(), wind)
    assert linearize_all(np.zeros((0, 12)), np.zeros((0, 4)), Vehicle()) == []
    for (x, u), lin in zip(points, many):
        one = linearize(x, u, Vehicle(), wind)
        for name in ("A", "B", "x_trim", "u_trim", "x_rate"):
            np.testing.assert_array_equal(getattr(lin, name), getattr(one, name))
        assert np.any(lin.x_rate[:3]) and not np.any(lin.x_rate[3:])


@pytest.mark.parametrize("kwargs, match", [
    ({"mass": float("nan")}, "must be finite"),
    ({"mass": -1.0}, "must be positive, got mass -1.0"),
    ({"inertia": (1e-4, 0.0, 1e-4)}, "must be positive"),
    ({"drag": (0.2, 0.2)}, "must be a number"),
    ({"mass": "heavy"}, "must be a number"),
    ({"mass": "0.5"}, "must be a number"),                   # float() took it; the trim's m g then failed on text
    ({"inertia": ("1e-4", 1e-4, 1e-4)}, "must be a number"),
    ({"mass": True}, "must be a number"),                    # a vehicle of 1 kg
    ({"products": (1e-3, 0.0, 0.0)}, r"not positive definite \(smallest principal moment -0\.0009268 kg m\^2\)"),
])
def test_a_vehicle_no_model_can_fly_is_refused_where_it_is_made(kwargs, match):
    """A vehicle made in Python (a config's are checked with their keys) with a NaN mass, a negative one or a
    flat inertia is refused at once, not found out later as a trim that blames the rotor drag."""
    with pytest.raises(ValueError, match=match):
        Vehicle(**kwargs)
