"""Equilibrium (trim) solving for hover and constant-velocity flight.

Given the earth-frame velocity ``V^E``, heading ``psi`` and position (and optionally a steady
wind, which the rotor drag sees through the air-relative velocity), find roll, pitch
and thrust such that every state derivative but position is zero (position grows at
``V^E``). Body rates and torques are zero at any such trim. Newton's method on the
three force-balance equations, with exact CasADi Jacobians and a velocity homotopy
when the direct solve does not converge.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.errors import ArgumentError, ArgumentTypeError, TrimError
from quadctl.layout import INPUT_INDEX, N_INPUTS, N_STATES, POSITION_STATES, STATE_INDEX
from quadctl.physics.model import MAX_TILT, N_PARAMS, Vehicle, build_model, rotation_earth_to_body

ca = lazy_import("casadi")  # loaded on first use: see quadctl._lazy

RESIDUAL_TOL = 1e-10
"""Largest |dx/dt| (non-position states) accepted as an equilibrium, in SI units."""
_POSITION = [STATE_INDEX[s] for s in POSITION_STATES]
_NON_POSITION = [i for i in range(N_STATES) if i not in _POSITION]


@dataclass(frozen=True, eq=False)
class Trim:
    """An equilibrium of the model.

    Attributes
    ----------
    x : (12,) ndarray
        Trim state (``STATE_NAMES`` order).
    u : (4,) ndarray
        Trim input ``[T, A, E, R]`` (N, N m).
    xdot : (12,) ndarray
        ``f(x, u)``: the position rows equal ``V^E``, the rest is the residual.
    residual : float
        ``max |xdot|`` over the non-position states.
    iterations : int
        Newton iterations used.

    Examples
    --------
    A hover holds the weight: thrust ``m g``, level.

    >>> import quadctl as qc
    >>> hover = qc.trim([0, 0, 0], 0.0, [0, 0, -1], qc.Vehicle())
    >>> round(float(hover.u[0]), 5), hover.residual
    (0.66708, 0.0)
    >>> x, u = hover  # unpacks as (x, u)
    """

    x: np.ndarray
    u: np.ndarray
    xdot: np.ndarray
    residual: float
    iterations: int

    def __iter__(self):
        return iter((self.x, self.u))


@lru_cache(maxsize=1)
def _force_balance() -> ca.Function:
    """``g(z=[phi, theta, T], v_e, psi, params, wind) -> body force / m (3,)`` and its Jacobian."""
    z = ca.SX.sym("z", 3)
    v_e = ca.SX.sym("v_e", 3)
    psi = ca.SX.sym("psi")
    params = ca.SX.sym("p", N_PARAMS)
    wind = ca.SX.sym("w", 3)
    x = ca.vertcat(ca.DM.zeros(3), rotation_earth_to_body(z[0], z[1], psi) @ v_e,
                   z[0], z[1], psi, ca.DM.zeros(3))
    u = ca.vertcat(z[2], ca.DM.zeros(3))
    vel_dot = build_model().f_wind(x, u, params, wind)[3:6]
    return ca.Function("trim_newton", [z, v_e, psi, params, wind], [vel_dot, ca.jacobian(vel_dot, z)])


def solve_trim(velocity_ned, yaw: float, position_ned, vehicle: Vehicle,
               *, wind_ned=None, max_iter: int = 50) -> Trim:
    """Solve the trim for a constant earth-frame velocity and heading.

    Parameters
    ----------
    velocity_ned : (3,) array_like
        m/s, NED (down positive: a climb has negative ``vD``).
    yaw : float
        Heading psi, rad.
    position_ned : (3,) array_like
        m; sets the trim position (it does not enter the dynamics).
    vehicle : Vehicle
    wind_ned : (3,) array_like, optional
        m/s, a steady wind (NED) to trim in; the vehicle holds ``velocity_ned`` over the ground.
        Hovering in a horizontal wind ``w`` (``Kz = 0``, nose into it) it pitches into the wind with
        ``tan θ = T Kx w / (m g)`` and ``T = m g cos θ``.

    Returns
    -------
    Trim

    Raises
    ------
    TrimError
        No equilibrium exists (with the reason) or Newton did not converge.
    ArgumentError
        ``velocity_ned``, ``position_ned`` or ``wind_ned`` is not three finite numbers, ``yaw`` not one, or
        ``max_iter`` not a whole number of 1 or more (a ``ValueError``).
    ArgumentTypeError
        ``vehicle`` is not a :class:`~quadctl.physics.model.Vehicle` (a ``TypeError``).

    Examples
    --------
    >>> t = solve_trim([1, 0, 0], 0.0, [0, 0, -1], Vehicle())
    >>> round(float(t.x[7]), 4), round(float(t.u[0]), 4)
    (-0.2119, 0.6522)
    """
    v_e, wind, yaw, position_ned = _checked(velocity_ned, wind_ned, yaw, position_ned, vehicle)
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise ArgumentError(f"trim: max_iter must be a whole number of Newton iterations, 1 or more, got {max_iter!r}")
    params = vehicle.vector()
    newton = _in_wind(wind)
    z = np.array([0.0, 0.0, vehicle.mass * vehicle.gravity])
    total = 0
    reached = 0.0
    # Homotopy in the speed (and the wind): solve at growing fractions of V^E, each from the last.
    for fraction in (1.0,) if _converges(newton, z, v_e, yaw, params, max_iter) else (
            0.25, 0.5, 0.75, 1.0):
        newton = _in_wind(fraction * wind)
        z, iters, resid = _newton(newton, z, fraction * v_e, yaw, params, max_iter)
        total += iters
        if not resid <= RESIDUAL_TOL:
            ramp = (f"the solver's ramp reached {reached:.0%} of it and stalled at {fraction:.0%}" if reached
                    else f"the solver's ramp stalled at its first step, {fraction:.0%} of it")
            raise TrimError(
                f"trim.velocity_ned = {_fmt(v_e)} m/s" + (f" in wind {_fmt(wind)} m/s" if wind.any() else "")
                + f": trim did not converge; {ramp.replace('%', ' %')} (residual {resid:.2e} m/s^2 after "
                f"{iters} iterations); try a lower speed or check the vehicle parameters (vehicle.drag, vehicle.mass)")
        reached = fraction
    found = _trims_at(np.reshape(z, (1, 3)), v_e[None], [yaw], position_ned, vehicle, wind, [total])[0]
    if isinstance(found, TrimError):
        raise found
    return found


def solve_trims(velocities_ned, yaws, position_ned, vehicle: Vehicle, *, wind_ned=None,
                max_iter: int = 50) -> list:
    """:func:`solve_trim` of many flight conditions at once: a Trim, or the TrimError it raises, each.

    The damped Newton of :func:`solve_trim` runs on every point together (the force balance mapped
    over the points: one CasADi call an iteration), each point taking its own steps and
    backtracking, so a point converges to what :func:`solve_trim` finds from the same start. A
    point it does not converge goes through :func:`solve_trim` itself (its homotopy in the speed,
    its error), and every point passes the same physical checks.

    Parameters
    ----------
    velocities_ned : (N, 3) array_like
        m/s, NED.
    yaws : (N,) array_like
        rad.
    position_ned : (3,) array_like
    vehicle : Vehicle
    wind_ned : (3,) array_like, optional
        m/s, one steady wind for every point.

    Returns
    -------
    list of (Trim or TrimError)
    """
    V = np.atleast_2d(np.asarray(velocities_ned, dtype=float))
    psi = np.asarray(yaws, dtype=float).ravel()
    N = len(V)
    wind = np.zeros(3) if wind_ned is None else np.asarray(wind_ned, dtype=float)
    params = vehicle.vector()
    balance = _mapped_balance(N)

    def residuals(z):
        g, jac = balance(z.T, V.T, psi[None, :], params, wind)
        return np.asarray(g, dtype=float).T, np.asarray(jac, dtype=float).reshape(3, N, 3).transpose(1, 0, 2)

    z = np.tile([0.0, 0.0, vehicle.mass * vehicle.gravity], (N, 1))
    done = np.zeros(N, bool)  # converged (or given up: stalled below)
    stalled = np.zeros(N, bool)
    iterations = np.full(N, max_iter)
    for it in range(1, max_iter + 1):
        g, jac = residuals(z)
        resid = np.abs(g).max(axis=1)
        newly = ~done & (resid <= RESIDUAL_TOL * 1e-2)
        iterations[newly] = it - 1
        done |= newly
        if done.all():
            break
        live = np.nonzero(~done)[0]
        try:
            step = np.linalg.solve(jac[live], -g[live][..., None])[..., 0]
        except np.linalg.LinAlgError:  # a singular Jacobian: those points go one by one
            stalled[live], done[live] = True, True
            break
        moved = np.zeros(len(live), bool)
        for scale in (1.0, 0.5, 0.25, 0.125, 0.0625):
            trial = z.copy()
            trial[live] = z[live] + scale * step
            inside = (np.abs(trial[live, 1]) < np.pi / 2) & (np.abs(trial[live, 0]) < np.pi)
            better = inside & ~moved & (np.abs(residuals(trial)[0][live]).max(axis=1) < resid[live])
            z[live[better]] = trial[live[better]]
            moved |= better
            if moved.all():
                break
        stalled[live[~moved]], done[live[~moved]] = True, True
    g = residuals(z)[0]
    converged = ~stalled & (np.abs(g).max(axis=1) <= RESIDUAL_TOL)
    out: list = [None] * N
    ok = np.nonzero(converged)[0]
    if ok.size:
        for k, found in zip(ok, _trims_at(z[ok], V[ok], psi[ok], position_ned, vehicle, wind, iterations[ok])):
            out[k] = found
    for k in np.nonzero(~converged)[0]:
        try:
            out[k] = solve_trim(V[k], psi[k], position_ned, vehicle, wind_ned=wind_ned, max_iter=max_iter)
        except TrimError as exc:
            out[k] = exc
    return out


@lru_cache(maxsize=8)
def _mapped_balance(n: int):
    """The force balance of :func:`_force_balance` mapped over ``n`` points (the wind and the
    parameters shared)."""
    return _force_balance().map(n)


def _trims_at(z, V, psi, position_ned, vehicle: Vehicle, wind, iterations) -> list:
    """The Trim of each converged force balance ``z[k] = [phi, theta, T]`` (N, 3), or the TrimError of
    its physical checks: the states and their residuals in one mapped call of :func:`_trim_state`."""
    N = len(z)
    x, xdot = (np.asarray(a, dtype=float).T for a in _trim_state(N)(
        z.T, V.T, np.reshape(psi, (1, N)), np.asarray(position_ned, dtype=float), vehicle.vector(), wind))
    out: list = []
    for k in range(N):
        try:
            _check_physical(*z[k], V[k], vehicle, wind)
        except TrimError as exc:
            out.append(exc)
            continue
        u = np.zeros(N_INPUTS)
        u[INPUT_INDEX["T"]] = z[k, 2]
        out.append(Trim(x=x[k], u=u, xdot=xdot[k], residual=float(np.abs(xdot[k, _NON_POSITION]).max()),
                        iterations=int(iterations[k])))
    return out


@lru_cache(maxsize=8)
def _trim_state(n: int) -> ca.Function:
    """``(z=[phi, theta, T], v_e, psi, position, params, wind) -> (x, f(x, u))`` of a trim, mapped over ``n`` points."""
    z, v_e, pos, wind = ca.SX.sym("z", 3), ca.SX.sym("v_e", 3), ca.SX.sym("pos", 3), ca.SX.sym("w", 3)
    psi, params = ca.SX.sym("psi"), ca.SX.sym("p", N_PARAMS)
    x = ca.vertcat(pos, rotation_earth_to_body(z[0], z[1], psi) @ v_e, z[0], z[1], psi, ca.DM.zeros(3))
    u = ca.vertcat(z[2], ca.DM.zeros(3))
    one = ca.Function("trim_state", [z, v_e, psi, pos, params, wind], [x, build_model().f_wind(x, u, params, wind)])
    return one if n == 1 else one.map(n)


def _checked(velocity_ned, wind_ned, yaw, position_ned, vehicle):
    """:func:`solve_trim`'s arguments as floats, or the ArgumentError (ArgumentTypeError) naming the one
    that is not finite numbers of its shape: NaN went through Newton and came out as a Trim of NaN."""
    if not isinstance(vehicle, Vehicle):
        raise ArgumentTypeError(f"trim takes a Vehicle, qc.Vehicle(mass=...) or setup.vehicle; "
                                f"got {type(vehicle).__name__}")
    out = []
    for label, value, shape in (("velocity_ned", velocity_ned, (3,)), ("wind_ned", wind_ned, (3,)),
                                ("yaw", yaw, ()), ("position_ned", position_ned, (3,))):
        if value is None and label == "wind_ned":
            out.append(np.zeros(3))
            continue
        want = "one number (rad)" if shape == () else "three numbers (NED)"
        try:
            arr = np.asarray(value)
            ok = arr.shape == shape and arr.dtype.kind in "biuf"
            arr = arr.astype(float) if ok else arr
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ArgumentError(f"trim: {label} must be {want}, got {value!r}")
        if not np.all(np.isfinite(arr)):
            raise ArgumentError(f"trim: {label} must be finite, got {value!r}")
        out.append(arr if shape else float(arr))
    return tuple(out)


def _in_wind(wind):
    """The force balance (and Jacobian) in the steady wind ``wind`` (NED, m/s)."""
    balance = _force_balance()
    return lambda z, v_e, psi, params: balance(z, v_e, psi, params, wind)


def _newton(newton, z, v_e, yaw, params, max_iter):
    """Damped Newton on the force balance; returns (z, iterations, residual)."""
    resid = np.inf
    for it in range(1, max_iter + 1):
        g, jac = (np.asarray(a, dtype=float) for a in newton(z, v_e, yaw, params))
        g = g.ravel()
        resid = float(np.abs(g).max())
        if resid <= RESIDUAL_TOL * 1e-2:
            return z, it - 1, resid
        try:
            step = np.linalg.solve(jac, -g)
        except np.linalg.LinAlgError:
            return z, it, resid
        # Backtrack so each step reduces the residual (and stays off the Euler singularity).
        for scale in (1.0, 0.5, 0.25, 0.125, 0.0625):
            trial = z + scale * step
            if abs(trial[1]) < np.pi / 2 and abs(trial[0]) < np.pi:
                g_new = np.asarray(newton(trial, v_e, yaw, params)[0], dtype=float).ravel()
                if np.abs(g_new).max() < resid:
                    z = trial
                    break
        else:
            return z, it, resid
    g = np.asarray(newton(z, v_e, yaw, params)[0], dtype=float).ravel()
    return z, max_iter, float(np.abs(g).max())


def _converges(newton, z, v_e, yaw, params, max_iter) -> bool:
    return _newton(newton, z, v_e, yaw, params, max_iter)[2] <= RESIDUAL_TOL


def _check_physical(phi, theta, thrust, v_e, vehicle: Vehicle, wind) -> None:
    where = f"velocity_ned {_fmt(v_e)} m/s" + (f" in wind {_fmt(wind)} m/s" if np.any(wind) else "")
    if thrust <= 0:
        raise TrimError(
            f"no equilibrium at {where}: it needs thrust {thrust:.3g} N <= 0 "
            "(the rotor drag along body z outgrows the thrust at this vertical speed); "
            "choose a slower vertical speed or a smaller vehicle.drag[2]")
    for name, angle in (("roll", phi), ("pitch", theta)):
        if abs(angle) > MAX_TILT:
            raise TrimError(
                f"no usable equilibrium at {where}: it needs {name} "
                f"{np.rad2deg(angle):.1f} deg, beyond the {np.rad2deg(MAX_TILT):.0f} deg the Euler-angle "
                "model supports; choose a lower " + ("airspeed" if np.any(wind) else "speed"))


def _fmt(v) -> str:
    return "[" + ", ".join(f"{float(c):g}" for c in v) + "]"
