"""The full inertia tensor (products of inertia): the rigid-body equations, the Jacobians, the
config syntax and its validation, and the diagonal case unchanged to the last bit."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from _finite_differences import assert_jacobians_match_central_differences
from _rotation import body_to_earth

from quadctl import layout
from quadctl.config import bundled, parse
from quadctl.errors import ConfigError
from quadctl.layout import STATE_INDEX
from quadctl.physics.model import Vehicle, build_model, evaluate
from quadctl.setup import setup_of

# Förster (2015), the Crazyflie 2.0's identified tensor, kg m^2 (the entries of J as he gives them)
CRAZYFLIE_J = np.array([[16.571710, 0.830806, 0.718277],
                        [0.830806, 16.655602, 1.800197],
                        [0.718277, 1.800197, 29.261652]]) * 1e-6
TILTED_J = np.array([[6.9e-5, 0.9e-5, -1.2e-5], [0.9e-5, 7.75e-5, 0.6e-5], [-1.2e-5, 0.6e-5, 1.5e-4]])
"""The Mambo's moments with large products of both signs (still positive definite)."""


def _full(j: np.ndarray, **kw) -> Vehicle:
    return Vehicle(inertia=tuple(np.diag(j)), products=(j[0, 1], j[0, 2], j[1, 2]), **kw)


def _random_point(rng):
    x = rng.normal(size=12) * 0.3
    x[STATE_INDEX["theta"]] = rng.uniform(-1.0, 1.0)
    x[9:12] = rng.normal(size=3) * 3.0
    u = np.array([rng.uniform(0.3, 1.0), *rng.normal(size=3) * 1e-3])
    return x, u


@pytest.mark.parametrize("j", [CRAZYFLIE_J, TILTED_J], ids=["crazyflie", "tilted"])
def test_rates_solve_euler_equation_with_full_tensor(j):
    """omega_dot = J^-1 (M - omega x J omega), against numpy's solve of the 3 x 3 system."""
    rng = np.random.default_rng(3)
    vehicle = _full(j)
    for _ in range(20):
        x, u = _random_point(rng)
        w, m = x[9:12], u[1:4]
        expected = np.linalg.solve(j, m - np.cross(w, j @ w))
        np.testing.assert_allclose(evaluate(x, u, vehicle)[9:12], expected, rtol=1e-12, atol=1e-12 * np.abs(
            expected).max())


@pytest.mark.parametrize("seed", range(4))
def test_jacobians_match_central_differences_with_full_tensor(seed):
    rng = np.random.default_rng(seed)
    x, u = _random_point(rng)
    vehicle = _full(TILTED_J, drag=(0.22, 0.3, 0.1))
    a, b = assert_jacobians_match_central_differences(x, u, vehicle)
    # the products couple the rate rows: B's torque block is J^-1, not a diagonal
    np.testing.assert_allclose(b[9:12, 1:4], np.linalg.inv(TILTED_J), rtol=1e-12)


def test_torque_free_body_conserves_earth_frame_angular_momentum_with_full_tensor():
    """M = 0: the angular momentum in the earth frame, R_b^E J omega, is constant (a vector, so a wrong
    product term or a wrong attitude kinematics moves it), and so is the energy 0.5 omega' J omega."""
    vehicle = _full(TILTED_J)
    f, p = build_model().f, vehicle.vector()
    x = np.zeros(12)
    x[9:12] = [3.0, -2.0, 1.5]
    x[STATE_INDEX["theta"]] = 0.2
    h0 = body_to_earth(*x[6:9]) @ TILTED_J @ x[9:12]
    e0 = 0.5 * x[9:12] @ TILTED_J @ x[9:12]
    dt = 1e-4
    for _ in range(3000):  # 0.3 s of RK4 (theta stays far from 90 deg)
        k1 = np.asarray(f(x, np.zeros(4), p)).ravel()
        k2 = np.asarray(f(x + dt / 2 * k1, np.zeros(4), p)).ravel()
        k3 = np.asarray(f(x + dt / 2 * k2, np.zeros(4), p)).ravel()
        k4 = np.asarray(f(x + dt * k3, np.zeros(4), p)).ravel()
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    h1 = body_to_earth(*x[6:9]) @ TILTED_J @ x[9:12]
    assert abs(x[STATE_INDEX["theta"]]) < 1.3
    np.testing.assert_allclose(h1, h0, rtol=0, atol=1e-9 * np.linalg.norm(h0))
    assert 0.5 * x[9:12] @ TILTED_J @ x[9:12] == pytest.approx(e0, rel=1e-9)
    assert not np.allclose(x[9:12], [3.0, -2.0, 1.5], rtol=0.1)  # the body did tumble


def test_diagonal_tensor_is_bit_identical_to_the_diagonal_equations():
    """With no products, f and the Jacobians equal, to the last bit, the rate equation
    ``(M - omega x (J omega)) / J`` that quadctl used before the products existed."""
    x, u, p = ca.SX.sym("x", 12), ca.SX.sym("u", 4), ca.SX.sym("p", len(layout.PARAMETER_NAMES))
    w, inertia = x[layout.BODY_RATES], p[layout.INERTIA]
    old = (u[layout.TORQUES] - ca.cross(w, inertia * w)) / inertia
    reference = ca.Function("old", [x, u, p], [old, ca.jacobian(old, x), ca.jacobian(old, u)])
    model = build_model()
    rng = np.random.default_rng(11)
    vehicle = Vehicle()
    assert vehicle.products == (0.0, 0.0, 0.0)
    for _ in range(50):
        xv, uv = _random_point(rng)
        f_old, a_old, b_old = (np.asarray(m) for m in reference(xv, uv, vehicle.vector()))
        a, b = (np.asarray(m) for m in model.jacobians(xv, uv, vehicle.vector()))
        assert np.array_equal(np.asarray(model.f(xv, uv, vehicle.vector())).ravel()[9:12], f_old.ravel())
        assert np.array_equal(a[9:12], a_old) and np.array_equal(b[9:12], b_old)


def _config(inertia: str):
    return parse(bundled("hover").text.replace("inertia: [6.9e-5, 7.75e-5, 1.5e-4]", f"inertia: {inertia}"),
                 "c.yaml")


def test_config_takes_a_full_tensor_and_a_diagonal_matrix_equals_the_diagonal_list():
    full = setup_of(_config("[[6.9e-5, 0.9e-5, -1.2e-5], [0.9e-5, 7.75e-5, 0.6e-5], [-1.2e-5, 0.6e-5, 1.5e-4]]"))
    np.testing.assert_array_equal(full.vehicle.inertia_tensor(), TILTED_J)
    assert full.plant.products == full.vehicle.products
    as_matrix = setup_of(_config("[[6.9e-5, 0, 0], [0, 7.75e-5, 0], [0, 0, 1.5e-4]]"))
    assert np.array_equal(as_matrix.vehicle.vector(), setup_of(_config("[6.9e-5, 7.75e-5, 1.5e-4]")).vehicle.vector())


@pytest.mark.parametrize(("inertia", "match"), [
    ("[[6.9e-5, 0.9e-5, 0], [0.8e-5, 7.75e-5, 0], [0, 0, 1.5e-4]]",
     r"^c\.yaml: vehicle\.inertia = .*: not symmetric: vehicle\.inertia\[0\]\[1\] = 9e-06 but "
     r"vehicle\.inertia\[1\]\[0\] = 8e-06; .*give both the same value$"),
    ("[[6.9e-5, 8e-5, 0], [8e-5, 7.75e-5, 0], [0, 0, 1.5e-4]]",
     r"^c\.yaml: vehicle\.inertia = .*: not positive definite \(smallest principal moment -6\.863e-06 kg m\^2\).*"
     r"check their units \(kg m\^2\) and signs"),
    ("[[6.9e-5, 0, 0], [0, 7.75e-5, 0], [0, 0, 3e-4]]",
     r"^c\.yaml: vehicle\.inertia = .*: no rigid body has the principal moments J1 \+ J2 = 0\.0001465 below "
     r"J3 = 0\.0003 kg m\^2 .*check the products of inertia"),
    ("[[6.9e-5, 0], [0, 7.75e-5]]", r"^c\.yaml: vehicle\.inertia = .*: must be \[Jxx, Jyy, Jzz\] or 3 rows"),
    ("[6.9e-5, 7.75e-5]", r"^c\.yaml: vehicle\.inertia = .*: must be \[Jxx, Jyy, Jzz\] or 3 rows"),
    ("[[6.9e-5, 0, 0], [0, -7.75e-5, 0], [0, 0, 1.5e-4]]",
     r"^c\.yaml: vehicle\.inertia\[1\]\[1\] = -7\.75e-05: a moment of inertia must be greater than 0"),
    ("[6.9e-5, 0, 1.5e-4]", r"^c\.yaml: vehicle\.inertia\[1\] = 0(\.0)?: must be greater than 0 \(kg m\^2"),
])
def test_impossible_tensor_is_refused_naming_the_key_value_and_fix(inertia, match):
    with pytest.raises(ConfigError, match=match):
        _config(inertia)


def test_a_full_tensor_reaches_the_linear_model_the_decoupling_and_the_design():
    """hover with a roll-yaw product Jxz: B's torque block is J^-1 (an independent inverse), the
    decoupling lists the roll-yaw terms it drops, and the design is still stable on the coupled model."""
    from _solve import solve

    tensor = "[[6.9e-5, 0, 1.2e-5], [0, 7.75e-5, 0], [1.2e-5, 0, 1.5e-4]]"
    setup, trim, linear, dec, design = solve(_config(tensor).model_dump(mode="json"))
    j = np.array([[6.9e-5, 0, 1.2e-5], [0, 7.75e-5, 0], [1.2e-5, 0, 1.5e-4]])
    np.testing.assert_allclose(linear.B[9:12, 1:4], np.linalg.inv(j), rtol=1e-12)
    dropped = {(d.row, d.column) for d in dec.dropped}
    assert ("p", "R") in dropped and ("r", "A") in dropped, dropped
    assert design.stable
    _, _, diagonal, dec_diagonal, _ = solve(_config("[6.9e-5, 7.75e-5, 1.5e-4]").model_dump(mode="json"))
    assert not any(d.column in ("A", "R") and d.row in ("p", "r") for d in dec_diagonal.dropped)
