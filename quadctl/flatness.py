"""The differential-flatness feedforward: the state and input that fly a path of flat outputs.

A quadrotor's position ``p(t)`` and yaw ``psi(t)`` determine everything else. From the model of
:mod:`quadctl.model` (no second copy of its equations):

- roll, pitch and thrust ``z = [phi, theta, T]`` solve ``G(z, s) = R_b^E a_b(z, s) - a = 0``, with
  ``a_b`` the body-velocity rows of ``f`` at zero body rate (the specific force plus gravity: the
  rotor drag sees the body velocity ``R_E^b v``), ``s = [v, psi, a]`` (Newton, as the trim; the trim
  is the case ``a = 0``);
- their rates and accelerations follow by the implicit function theorem from the jerk, snap and yaw
  derivatives; the body rates are ``omega = H(phi, theta) [phi', theta', psi']``
  (:func:`quadctl.model.euler_rates_matrix`), the body velocity ``R_E^b v``;
- the torques are those for which ``f``'s body-rate rows equal ``omega'`` (they enter ``f`` affinely).

Then ``f(x_ref, u_ref) = d x_ref / dt`` along the path: flown from ``x_ref(0)`` with no
disturbance, the feedforward alone tracks it and the feedback sees no error.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.errors import TrimError
from quadctl.layout import GRAVITY, MASS, N_INPUTS, N_STATES
from quadctl.model import N_PARAMS, build_model, euler_rates_matrix, rotation_earth_to_body
from quadctl.pointwise import Pointwise
from quadctl.trajectory import FlatPath

ca = lazy_import("casadi")  # loaded on first use: see quadctl._lazy

NEWTON_TOL = 1e-12
"""m/s^2: the largest ``|G|`` accepted."""
MAX_ITER = 50


@lru_cache(maxsize=1)
def _functions():
    """``(balance, feedforward)``: ``balance(z, s, params) -> (G, dG/dz)`` and
    ``feedforward(z, s, sdot, sddot, p, params) -> (x, u)``."""
    model = build_model()
    z = ca.SX.sym("z", 3)
    s = ca.SX.sym("s", 7)  # v (3), psi, a (3)
    sd = ca.SX.sym("sd", 7)
    sdd = ca.SX.sym("sdd", 7)
    pos = ca.SX.sym("pos", 3)
    params = ca.SX.sym("params", N_PARAMS)
    phi, theta, thrust = z[0], z[1], z[2]
    v, psi, a = s[0:3], s[3], s[4:7]
    r_eb = rotation_earth_to_body(phi, theta, psi)
    x_still = ca.vertcat(pos, r_eb @ v, phi, theta, psi, ca.DM.zeros(3))
    vel_dot = model.f(x_still, ca.vertcat(thrust, ca.DM.zeros(3)), params)[3:6]
    G = r_eb.T @ vel_dot - a
    Gz, Gs = ca.jacobian(G, z), ca.jacobian(G, s)
    balance = ca.Function("flat_balance", [z, s, params], [G, Gz])
    zd_sym = ca.SX.sym("zd", 3)
    zd = -ca.solve(Gz, Gs @ sd)
    H = Gz @ zd_sym + Gs @ sd  # d/dt G along the path (zero)
    zdd = -ca.solve(Gz, ca.jacobian(H, z) @ zd_sym + ca.jacobian(H, s) @ sd + Gs @ sdd)
    zdd = ca.substitute(zdd, zd_sym, zd)
    angles = ca.vertcat(phi, theta)
    euler_dot = ca.vertcat(zd[0], zd[1], sd[3])
    euler_ddot = ca.vertcat(zdd[0], zdd[1], sdd[3])
    Hm = euler_rates_matrix(phi, theta)
    ed = ca.SX.sym("ed", 3)  # the Euler rates as free symbols: d/dt H = sum_k dH/d angle_k angle_k'
    omega = Hm @ euler_dot
    omega_dot = ca.substitute(ca.jacobian(Hm @ ed, angles) @ zd[0:2], ed, euler_dot) + Hm @ euler_ddot
    x = ca.vertcat(pos, r_eb @ v, phi, theta, psi, omega)
    torque = ca.SX.sym("M", 3)
    rates = model.f(x, ca.vertcat(thrust, torque), params)[9:12]
    Jm = ca.jacobian(rates, torque)
    M = ca.solve(Jm, omega_dot - ca.substitute(rates, torque, ca.DM.zeros(3)))
    u = ca.vertcat(thrust, M)
    feed = ca.Function("flat_feedforward", [z, s, sd, sdd, pos, params], [ca.cse(x), ca.cse(u)])
    return balance, feed


def feedforward(path: FlatPath, params, pointwise=Pointwise, remedy=None) -> tuple[np.ndarray, np.ndarray]:
    """The reference state and input along ``path``.

    Parameters
    ----------
    path : FlatPath
        ``n`` samples of position (and derivatives to snap) and yaw (and two derivatives).
    params : (8,) array_like
        :meth:`quadctl.model.Vehicle.vector` of the model the controller assumes.
    pointwise : callable
        ``pointwise(fn)`` evaluates a CasADi function over the points (a row a point):
        :class:`quadctl.pointwise.Pointwise` (CasADi's ``map``), or the compiled
        :func:`quadctl.sim.mapped.mapped` (the same numbers).
    remedy : callable, optional
        ``remedy(t)``: the fix a refusal at ``t`` s names (:meth:`quadctl.trajectory.Reference.remedy`: a
        setpoint's velocity, a mission's speed); default a mission's.

    Returns
    -------
    x : (n, 12) ndarray
    u : (n, 4) ndarray

    Raises
    ------
    TrimError
        No roll, pitch and thrust produce the path's acceleration (Newton did not converge).
    """
    balance, feed = (pointwise(fn) for fn in _functions())
    n = len(path.t)
    P = path.position
    s = np.vstack([P[1].T, path.yaw[0][None], P[2].T])
    sd = np.vstack([P[2].T, path.yaw[1][None], P[3].T])
    sdd = np.vstack([P[3].T, path.yaw[2][None], P[4].T])
    params = np.asarray(params, dtype=float)
    z = np.tile(np.array([[0.0], [0.0], [params[MASS] * params[GRAVITY]]]), (1, n))  # start at hover thrust
    s, sd, sdd, z = s.T, sd.T, sdd.T, z.T  # a row a point
    for _ in range(MAX_ITER):
        G, J = balance(z, s, params)
        resid = np.abs(G).max(axis=1)
        if resid.max() <= NEWTON_TOL:
            break
        jac = J.reshape(n, 3, 3).transpose(0, 2, 1)  # each point's (3, 3) column-major
        z = z + np.linalg.solve(jac, -G[:, :, None])[:, :, 0]
    else:
        worst = int(np.argmax(resid))
        raise TrimError(
            f"simulation.reference: no roll, pitch and thrust fly the reference at t = {path.t[worst]:.4g} s "
            f"(acceleration {_fmt(P[2][worst])} m/s^2 at velocity {_fmt(P[1][worst])} m/s); "
            + (remedy(float(path.t[worst])) if remedy is not None else
               "lower simulation.reference.speed or space the waypoints further apart"))
    x, u = feed(z, s, sd, sdd, P[0], params)
    return x.reshape(n, N_STATES), u.reshape(n, N_INPUTS)


def _fmt(v) -> str:
    return "[" + ", ".join(f"{float(c):.3g}" for c in v) + "]"
