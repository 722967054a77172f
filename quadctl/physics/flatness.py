"""The differential-flatness feedforward: the state and input that fly a path of flat outputs.

A quadrotor's position ``p(t)`` and yaw ``psi(t)`` determine everything else. From the model of
:mod:`quadctl.physics.model` (no second copy of its equations):

- roll, pitch and thrust ``z = [phi, theta, T]`` solve ``G(z, s) = R_b^E a_b(z, s) - a = 0``, with
  ``a_b`` the body-velocity rows of ``f`` at zero body rate (the specific force plus gravity: the
  rotor drag sees the body velocity ``R_E^b v``), ``s = [v, psi, a]`` (Newton, as the trim; the trim
  is the case ``a = 0``);
- their rates and accelerations follow by the implicit function theorem from the jerk, snap and yaw
  derivatives; the body rates are ``omega = H(phi, theta) [phi', theta', psi']``
  (:func:`quadctl.physics.model.euler_rates_matrix`), the body velocity ``R_E^b v``;
- the torques are those for which ``f``'s body-rate rows equal ``omega'`` (they enter ``f`` affinely).

Then ``f(x_ref, u_ref) = d x_ref / dt`` along the path: flown from ``x_ref(0)`` with no
disturbance, the feedforward alone tracks it and the feedback sees no error. The loop reads it
tabulated, from :mod:`quadctl.physics.reference_rows`.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.errors import TrimError
from quadctl.layout import GRAVITY, MASS, N_INPUTS, N_STATES
from quadctl.native.pointwise import Pointwise
from quadctl.physics.model import MAX_TILT, N_PARAMS, build_model, euler_rates_matrix, rotation_earth_to_body
from quadctl.physics.trajectory import FlatPath

ca = lazy_import("casadi")  # loaded on first use: see quadctl._lazy

NEWTON_TOL = 1e-12
"""m/s^2: the largest ``|G|`` accepted."""
MAX_ITER = 50


@lru_cache(maxsize=1)
def _functions():
    """``(balance, feedforward)``: ``balance(z, s, params) -> (G, Newton's step -(dG/dz)^-1 G)`` (the
    3 x 3 solve in the compiled point, by minors as CasADi solves a 3 x 3; a singular or non-finite
    Jacobian gives a step that is not finite) and
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
    balance = ca.Function("flat_balance", [z, s, params], [G, -ca.solve(Gz, G)])
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
    """The reference state and input along ``path``, on the physical branch of the flatness map.

    The force balance ``G(z, s) = 0`` has more than one root (at 10.5 m/s north on the report's
    vehicle: pitch -0.9386 rad with thrust +0.3942 N, and pitch -2.2030 rad with -0.3942 N, upside
    down). The physical one is the root continued along the path from hover: the points are solved in
    time order, in blocks of :data:`BLOCK`, each block by Newton from the root of the point before it
    (the first from hover at its heading, a root of ``G`` at zero velocity and acceleration), and where
    Newton does not land on a root with positive thrust and roll and pitch within +-90 deg (a step of
    the reference, the first point), by continuation: the flight condition moved from the last point's
    to the point's in steps, each solved from the one before (:func:`_continued`). Roll and pitch stay
    within +-90 deg, so they are continuous along the path (never wrapped); yaw is the path's.

    The stack of one of :func:`feedforward_of` (many paths solved together).

    Parameters
    ----------
    path : FlatPath
        ``n`` samples of position (and derivatives to snap) and yaw (and two derivatives).
    params : (8,) array_like
        :meth:`quadctl.physics.model.Vehicle.vector` of the model the controller assumes.
    pointwise : callable
        ``pointwise(fn)`` evaluates a CasADi function over the points (a row a point):
        :class:`quadctl.native.pointwise.Pointwise` (CasADi's ``map``), or the compiled
        :func:`quadctl.native.mapped.mapped` (the same numbers).
    remedy : callable, optional
        ``remedy(t)``: the fix a refusal at ``t`` s names (:meth:`quadctl.physics.trajectory.Reference.remedy`: a
        setpoint's velocity, a mission's speed); default a mission's.

    Returns
    -------
    x : (n, 12) ndarray
    u : (n, 4) ndarray

    Raises
    ------
    TrimError
        At some point no roll and pitch within :data:`quadctl.physics.model.MAX_TILT` of level (and positive
        thrust) fly the path's acceleration: the message names the time (the steepest point's), the
        acceleration and velocity asked and the attitude they need.

    Examples
    --------
    >>> from quadctl.physics.model import Vehicle
    >>> from quadctl.physics.trajectory import setpoint_reference
    >>> ref = setpoint_reference([{"t": 0.0, "velocity": [10.5, 0.0, 0.0]}], [0, 0, -1], [0, 0, 0], 0.0)
    >>> x, u = feedforward(ref.flat([1.0]), Vehicle().vector())
    >>> round(float(x[0, 7]), 4), round(float(u[0, 0]), 4)
    (-0.9386, 0.3942)
    """
    (got,) = feedforward_of([path], [params], pointwise, [remedy])
    if isinstance(got, TrimError):
        raise got
    return got


def feedforward_of(paths, params, pointwise=Pointwise, remedies=None) -> list:
    """:func:`feedforward` of many paths at once: per path ``(x, u)``, or the :class:`TrimError` refusing it.

    The paths are solved in lockstep: block ``b`` of every path still flying in one :func:`_continued`
    (each row from its own path's start root and flight condition, with its own ``params``), and the
    feedforward of every point in one call of the compiled map. Each point's Newton is its own (its
    iterations, its 3 x 3 solve, the map a point at a time), so a path's rows are those it has alone,
    to the last bit; a refused path drops out, the others go on.

    Parameters
    ----------
    paths : list of FlatPath
    params : list of (8,) array_like
        Each path's model parameters (:func:`feedforward`).
    pointwise : callable
        As :func:`feedforward`'s.
    remedies : list of callable or None, optional
        Each path's ``remedy`` (:func:`feedforward`); default a mission's for all.

    Returns
    -------
    list
        Per path, ``(x (n, 12), u (n, 4))`` or the TrimError :func:`feedforward` raises for it.
    """
    if not paths:
        return []
    balance, feed = (pointwise(fn) for fn in _functions())
    k = len(paths)
    remedies = [None] * k if remedies is None else list(remedies)
    params = np.array([np.asarray(p, dtype=float) for p in params]).reshape(k, -1)
    n = [len(path.t) for path in paths]
    s, sd, sdd = [], [], []
    for path in paths:
        P = path.position
        s.append(np.vstack([P[1].T, path.yaw[0][None], P[2].T]).T)  # a row a point
        sd.append(np.vstack([P[2].T, path.yaw[1][None], P[3].T]).T)
        sdd.append(np.vstack([P[3].T, path.yaw[2][None], P[4].T]).T)
    order = [np.argsort(path.t, kind="stable") for path in paths]
    z = [np.empty((m, 3)) for m in n]
    out: list = [None] * k
    z_prev = np.zeros((k, 3))
    z_prev[:, 2] = params[:, MASS] * params[:, GRAVITY]  # hover: a root at zero velocity and acceleration
    s_prev = np.zeros((k, 7))
    for c in range(k):
        s_prev[c, 3] = s[c][order[c][0], 3] if n[c] else 0.0  # hover at the first point's heading
    for start in range(0, max(n, default=0), BLOCK):
        flying = [c for c in range(k) if out[c] is None and start < n[c]]
        if not flying:
            break
        rows = [order[c][start:start + BLOCK] for c in flying]
        sizes = [len(r) for r in rows]
        case = np.repeat(np.arange(len(flying)), sizes)
        got, lost = _continued(balance, z_prev[flying][case], s_prev[flying][case],
                               np.vstack([s[c][r] for c, r in zip(flying, rows)]), params[flying][case], case)
        for c, r, a, b in zip(flying, rows, np.cumsum(sizes) - sizes, np.cumsum(sizes)):  # a path's rows: a:b
            if lost[a:b].any():
                out[c] = _refusal(paths[c], r[np.argmax(lost[a:b])], None, remedies[c])
                continue
            z[c][r] = got[a:b]
            z_prev[c], s_prev[c] = got[b - 1], s[c][r[-1]]
    for c in range(k):
        if out[c] is None and n[c]:
            steepness = np.maximum(np.abs(z[c][:, 0]), np.abs(z[c][:, 1]))
            if steepness.max() > MAX_TILT:
                worst = int(np.argmax(steepness))
                out[c] = _refusal(paths[c], worst, z[c][worst], remedies[c])
    good = [c for c in range(k) if out[c] is None]
    if good:
        sizes = [n[c] for c in good]
        x, u = feed(*(np.vstack([part[c] for c in good]) for part in (z, s, sd, sdd)),
                    np.vstack([paths[c].position[0] for c in good]), np.repeat(params[good], sizes, axis=0))
        ends = np.cumsum(sizes)[:-1]
        for c, xc, uc in zip(good, np.split(x, ends), np.split(u, ends)):
            out[c] = (xc.reshape(n[c], N_STATES), uc.reshape(n[c], N_INPUTS))
    return out


BLOCK = 64
"""Points solved together (0.32 s of a reference on the 5 ms clock), each block from the root of the
point before it: Newton's start is then within a block's motion of every point's root."""
MIN_FRACTION = 2.0 ** -20
"""The smallest step of :func:`_continued`'s continuation (a fraction of the way between two points'
flight conditions); below it, the physical root has left the region: the reference is refused."""


def _physical(z) -> np.ndarray:
    """(m,) bool: the roots ``z`` (m, 3) with positive thrust and roll and pitch within +-90 deg (not
    inverted): the branch of the flatness map a quadrotor flies."""
    return (z[:, 2] > 0) & (np.abs(z[:, 0]) < np.pi / 2) & (np.abs(z[:, 1]) < np.pi / 2) & np.isfinite(z).all(axis=1)


def _newton(balance, z, s, params) -> tuple[np.ndarray, np.ndarray]:
    """Newton on ``G(z, s) = 0`` from ``z`` (m, 3) at ``s`` (m, 7) with ``params`` ((8,), or (m, 8) a row's
    own), all rows at once, each on its own: ``(z, converged)``,
    ``converged`` (m,) the rows within :data:`NEWTON_TOL` on the physical branch (:func:`_physical`); a
    row that leaves it stops there. A row within the tolerance takes one step more, which leaves it at
    round-off (Newton's convergence is quadratic): its root then does not depend on where Newton
    started (a reference's rows tabulated in any chunks are the same numbers; with the residual of
    the tolerance left in, the model's rates of two tabulations differed by 2e-12 m/s^2, their
    curvature over a 5 ms row by 4e-10)."""
    z = z.copy()
    m = len(z)
    going = np.ones(m, dtype=bool)
    done = np.zeros(m, dtype=bool)
    for _ in range(MAX_ITER):
        idx = np.flatnonzero(going)
        if not idx.size:
            break
        G, step = balance(z[idx], s[idx], params[idx] if params.ndim == 2 else params)
        z[idx] = z[idx] + step  # on a row within the tolerance, one step more: its root to round-off
        ok = np.abs(G).max(axis=1) <= NEWTON_TOL
        done[idx[ok]] = True
        going[idx[ok]] = False
        going[idx[~_physical(z[idx])]] = False
    return z, done & _physical(z)


def _continued(balance, z0, s0, s, params, case=None) -> tuple[np.ndarray, np.ndarray]:
    """The physical roots at the points ``s`` (m, 7), each continued from its start root ``z0`` (m, 3)
    at ``s0`` (m, 7) (or one (3,) and one (7,) for all): Newton from ``z0``; a point where it fails is
    approached along ``s0 + lam (s - s0)``, ``lam`` from 0 to 1 in steps halved on a failure and doubled
    on a success, each from the last root reached. ``params``: (8,), or (m, 8) a row's own. ``case``
    (m,) ints: the path of each row (default all one): a path one of whose points is lost stops there,
    the others go on (each row's continuation is its own).

    Returns
    -------
    z : (m, 3) ndarray
    lost : (m,) bool ndarray
        Per path, at most one: of its points whose root left the physical branch on the way (their
        step fell below :data:`MIN_FRACTION`) at the first round any did, the first in order; its other
        rows are then where they stopped.
    """
    m = len(s)
    case = np.zeros(m, dtype=int) if case is None else np.asarray(case)
    z = np.array(np.broadcast_to(z0, (m, 3)), dtype=float)
    s0 = np.broadcast_to(s0, (m, 7))
    lam, step = np.zeros(m), np.ones(m)
    lost, going = np.zeros(m, dtype=bool), np.ones(m, dtype=bool)
    while True:
        active = np.flatnonzero(going & (lam < 1))
        short = active[step[active] < MIN_FRACTION]
        if short.size:  # each path with a point lost: its first, and the path stops
            paths, first = np.unique(case[short], return_index=True)
            lost[short[first]] = True
            going &= ~np.isin(case, paths)
            active = active[going[active]]
        if not active.size:
            return z, lost
        trial = np.minimum(lam[active] + step[active], 1.0)
        got, ok = _newton(balance, z[active], s0[active] + trial[:, None] * (s[active] - s0[active]),
                          params[active] if np.ndim(params) == 2 else params)
        win, lose = active[ok], active[~ok]
        z[win], lam[win] = got[ok], trial[ok]
        step[win] = np.minimum(2 * step[win], 1.0)
        step[lose] /= 2


def _refusal(path: FlatPath, k: int, z, remedy) -> TrimError:
    """The refusal of point ``k``: its time, acceleration and velocity, and the roll and pitch
    they need (``z``; None: beyond 90 deg, or no positive thrust), and ``remedy(t)``'s fix."""
    P = path.position
    fix = (remedy(float(path.t[k])) if remedy is not None
           else "lower simulation.reference.speed or space the waypoints further apart")
    asked = (f"at t = {path.t[k]:.4g} s the reference asks an acceleration of {_fmt(P[2][k])} m/s^2 at velocity "
             f"{_fmt(P[1][k])} m/s")
    limit = f"{np.rad2deg(MAX_TILT):.0f} deg"
    if z is None:
        needs = "a tilt of 90 deg or more (no attitude with upward thrust flies it)"
    else:
        tilt = np.rad2deg(np.arccos(np.clip(np.cos(z[0]) * np.cos(z[1]), -1.0, 1.0)))
        needs = f"roll {np.rad2deg(z[0]):.1f} deg and pitch {np.rad2deg(z[1]):.1f} deg (a tilt of {tilt:.1f} deg)"
    return TrimError(f"simulation.reference: {asked}, which needs {needs}, beyond the {limit} of roll or pitch "
                     f"the Euler-angle model supports; {fix}")


def _fmt(v) -> str:
    return "[" + ", ".join(f"{float(c):.3g}" for c in v) + "]"
