"""The bundled ``drake-hover`` config reproduces the hover LQR of Drake's quadrotor example.

The reference is Drake's own answer (``tests/data/drake_hover.json``: its gain on the four rotor
thrusts and its closed-loop eigenvalues, computed by pydrake 1.51.1), not quadctl's: quadctl's gain
on ``[T, A, E, R]`` mapped through the vehicle's mixer to rotor thrusts, and its state order and
frame mapped to Drake's, must give Drake's gain. The altitude gains are also held to the closed
form of an LQR on a double integrator.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from _paths import DATA
from _solve import cfg_dict, solve

from quadctl.layout import STATE_INDEX

DRAKE = json.loads((DATA / "drake_hover.json").read_text())
RTOL = 1e-9
"""Two Riccati solvers on the same well-conditioned 12-state problem agree far below this."""
FRAME = [("pN", 1), ("pE", -1), ("pD", -1), ("phi", 1), ("theta", -1), ("psi", -1),
         ("u", 1), ("v", -1), ("w", -1), ("p", 1), ("q", -1), ("r", -1)]
"""Drake's state ``[x y z roll pitch yaw, their rates]`` (z up, y left) as quadctl's state and sign
(NED/FRD: the same vehicle turned half a turn about x; at hover the body velocities and rates are
the world's)."""


@pytest.fixture(scope="module")
def drake_design():
    setup, trim, linear, dec, des = solve(cfg_dict("drake-hover"))
    return setup, trim, linear, des


def _to_drake(setup, K_block: np.ndarray) -> np.ndarray:
    """quadctl's gain on ``[T, A, E, R]`` and its states -> Drake's gain on rotor thrusts and its states."""
    S = np.zeros((12, 12))
    for j, (name, sign) in enumerate(FRAME):
        S[STATE_INDEX[name], j] = sign
    mixer = setup.actuators.motors.mixer()  # rotor thrusts from [T, A, E, R]
    return mixer @ K_block @ S


def test_gains_through_the_mixer_are_drakes(drake_design):
    setup, trim, linear, des = drake_design
    K = _to_drake(setup, des.K_block)
    K_drake = np.array(DRAKE["K"])
    err = np.abs(K - K_drake).max() / np.abs(K_drake).max()
    assert err < RTOL, f"Max relative diff is {err:.4E}"


def test_trim_thrust_is_drakes(drake_design):
    setup, trim, linear, des = drake_design
    f0 = setup.actuators.motors.mixer() @ trim.u
    np.testing.assert_allclose(f0, DRAKE["u0"], rtol=1e-12)


def test_closed_loop_eigenvalues_are_drakes(drake_design):
    setup, trim, linear, des = drake_design
    mine = np.sort_complex(np.linalg.eigvals(linear.A - linear.B @ des.K_block))
    theirs = np.sort_complex(np.array([complex(re, im) for re, im in DRAKE["eigenvalues"]]))
    err = np.abs(mine - theirs).max() / np.abs(theirs).max()
    assert err < RTOL, f"Max relative diff is {err:.4E}"


def test_altitude_gains_are_the_double_integrator_closed_form(drake_design):
    """At hover the altitude decouples: ``m w' = -(T - m g)``. With ``Q = diag(Qz, Qw)`` and ``R_T``
    the LQR of a double integrator gives ``K_z = sqrt(Qz / R_T)``, ``K_w = sqrt(Qw / R_T + 2 m K_z)``
    and the poles of ``s^2 + (K_w / m) s + K_z / m`` (pD down, T up: both gains negative on ``T``)."""
    setup, trim, linear, des = drake_design
    m = setup.vehicle.mass
    Qz, Qw = 10.0, 1.0
    R_T = 0.25  # R = I on four rotor thrusts that add up to T: (1 / 4) T^2
    K_z = np.sqrt(Qz / R_T)
    K_w = np.sqrt(Qw / R_T + 2 * m * K_z)
    row = des.K_block[0]
    np.testing.assert_allclose([row[STATE_INDEX["pD"]], row[STATE_INDEX["w"]]], [-K_z, -K_w], rtol=RTOL)
    poles = np.roots([1.0, K_w / m, K_z / m])
    cl = np.linalg.eigvals(linear.A - linear.B @ des.K_block)
    for s in poles:
        assert np.abs(cl - s).min() < RTOL * abs(s)
