"""The 12-state nonlinear quadcopter model of docs/model.md, as CasADi functions.

This is the only place the equations of motion live. Everything numeric (trim,
Jacobians, the compiled simulation) is generated from the functions built here.

Conventions: NED earth frame, FRD body frame, 3-2-1 Euler angles, states and
inputs ordered as in :mod:`quadctl.layout`. Thrust ``T`` acts along body -z
(``F_T = [0, 0, -T]``), correcting the report's sign.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from quadctl import layout
from quadctl._lazy import lazy_import
from quadctl.errors import ArgumentError
from quadctl.layout import N_INPUTS, N_STATES, PARAMETER_NAMES

ca = lazy_import("casadi")  # loaded on first use: see quadctl._lazy

N_PARAMS = len(PARAMETER_NAMES)
MAX_TILT = np.deg2rad(80.0)
"""Roll or pitch beyond this is refused: the Euler kinematics are singular at 90 deg."""
N_DISTURBANCES = 6
"""Body-frame disturbance force (N, 3) and torque (N m, 3) added to the dynamics."""
DISTURBANCE_FORCE = slice(0, 3)
DISTURBANCE_TORQUE = slice(3, 6)
N_WIND = 3
"""Wind velocity, NED earth frame (m/s): the air's velocity over the ground."""


@dataclass(frozen=True)
class Vehicle:
    """Vehicle parameters (SI units).

    Parameters
    ----------
    mass : float
        kg.
    gravity : float
        m/s^2.
    inertia : (3,) tuple of float
        Diagonal of J, ``(Jxx, Jyy, Jzz)``, kg m^2.
    drag : (3,) tuple of float
        Diagonal of Kc; the rotor drag force is ``-T Kc (V_b - R_E^b w)`` with ``w`` the wind
        (1/(m/s), per newton of thrust).
    products : (3,) tuple of float
        Off-diagonal entries of the tensor J, ``(Jxy, Jxz, Jyz)``, kg m^2: J itself, not the
        products of inertia ``∫ x y dm`` (``Jxy = -∫ x y dm``). Zero: a diagonal J.

    Examples
    --------
    The defaults are the Parrot Mambo's; a config's ``vehicle:`` gives another:

    >>> import quadctl as qc
    >>> qc.Vehicle().mass, qc.Vehicle(mass=0.5).inertia_tensor().shape
    (0.068, (3, 3))
    """

    mass: float = 0.068
    gravity: float = 9.81
    inertia: tuple[float, float, float] = (0.69e-4, 0.775e-4, 1.5e-4)
    drag: tuple[float, float, float] = (0.22, 0.22, 0.0)
    products: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        """Refuse a vehicle no model can fly (a config's are checked with their keys before this; a vehicle
        made in Python meets this): an :class:`~quadctl.errors.ArgumentError` (a ``ValueError``) naming the field."""
        try:
            values = self.vector()
            given = (self.mass, self.gravity, *self.inertia, *self.drag, *self.products)
            numeric = all(isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_)) for v in given)
            if values.shape != (N_PARAMS,) or not numeric:  # float() takes '0.5' and True: not numbers here
                raise ValueError
        except (TypeError, ValueError):
            raise ArgumentError(f"Vehicle: every parameter must be a number (mass, gravity, three each of inertia, "
                                f"drag and products), got {self!r}") from None
        if not np.all(np.isfinite(values)):
            raise ArgumentError(f"Vehicle: every parameter must be finite, got {self!r}")
        if not values[0] > 0.0 or not np.all(np.asarray(self.inertia, dtype=float) > 0.0):
            raise ArgumentError(f"Vehicle: mass (kg) and the inertia's diagonal (kg m^2) must be positive, got mass "
                                f"{self.mass!r} and inertia {self.inertia!r}")
        smallest = float(np.linalg.eigvalsh(self.inertia_tensor())[0])
        if not smallest > 0.0:  # as a config's full tensor is checked: J^-1 of the model would be no rigid body's
            raise ArgumentError(f"Vehicle: the inertia tensor is not positive definite (smallest principal moment "
                                f"{smallest:.4g} kg m^2): the products {self.products!r} are too large for the "
                                f"moments {self.inertia!r}; check their units (kg m^2) and signs")

    def vector(self) -> np.ndarray:
        """Parameters as the (11,) vector the CasADi functions take (order: ``PARAMETER_NAMES``)."""
        return np.array([self.mass, self.gravity, *self.inertia, *self.drag, *self.products], dtype=float)

    def inertia_tensor(self) -> np.ndarray:
        """J (3, 3), kg m^2."""
        (jxx, jyy, jzz), (jxy, jxz, jyz) = self.inertia, self.products
        return np.array([[jxx, jxy, jxz], [jxy, jyy, jyz], [jxz, jyz, jzz]], dtype=float)


def rotation_earth_to_body(phi, theta, psi):
    """``R_E^b = R(phi) R(theta) R(psi)`` (report eq. 1), as a CasADi 3 x 3 expression."""
    cph, sph = ca.cos(phi), ca.sin(phi)
    cth, sth = ca.cos(theta), ca.sin(theta)
    cps, sps = ca.cos(psi), ca.sin(psi)
    r_phi = ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, cph, sph), ca.horzcat(0, -sph, cph))
    r_theta = ca.vertcat(ca.horzcat(cth, 0, -sth), ca.horzcat(0, 1, 0), ca.horzcat(sth, 0, cth))
    r_psi = ca.vertcat(ca.horzcat(cps, sps, 0), ca.horzcat(-sps, cps, 0), ca.horzcat(0, 0, 1))
    return r_phi @ r_theta @ r_psi


def euler_rates_matrix(phi, theta):
    """``H(phi, theta)`` with ``omega = H [phi_dot, theta_dot, psi_dot]`` (docs/model.md; report eq. 7 corrected)."""
    cph, sph = ca.cos(phi), ca.sin(phi)
    cth, sth = ca.cos(theta), ca.sin(theta)
    return ca.vertcat(
        ca.horzcat(1, 0, -sth),
        ca.horzcat(0, cph, sph * cth),
        ca.horzcat(0, -sph, cph * cth),
    )


def dynamics_expression(x, u, params, disturbance, wind=None):
    """Right-hand side ``f(x, u)`` of docs/model.md (the report's eqs. 1-8) as a CasADi expression.

    The rotor drag acts on the velocity relative to the air, ``V_b - R_E^b w``: in still air
    (``wind`` None or zero) it is docs/model.md's ``-T Kc V_b``; a vehicle moving with the wind feels none.

    Parameters
    ----------
    x : (12,) casadi SX
        State, ordered as ``STATE_NAMES``.
    u : (4,) casadi SX
        Input ``[T, A, E, R]`` in N and N m.
    params : (11,) casadi SX
        ``[mass, gravity, Jxx, Jyy, Jzz, Kx, Ky, Kz, Jxy, Jxz, Jyz]`` (``PARAMETER_NAMES``).
    disturbance : (6,) casadi SX
        Body force (N) and torque (N m) added to the vehicle's own.
    wind : (3,) casadi SX, optional
        Wind velocity, NED (m/s); None: still air.

    Returns
    -------
    (12,) casadi SX
        ``dx/dt``.
    """
    vel_b = x[layout.VELOCITY]
    phi, theta, psi = ca.vertsplit(x[layout.ATTITUDE])
    omega = x[layout.BODY_RATES]
    thrust, torque = u[layout.THRUST], u[layout.TORQUES]
    mass, gravity = params[layout.MASS], params[layout.GRAVITY]
    inertia, products = params[layout.INERTIA], params[layout.PRODUCTS]
    drag = params[layout.DRAG]

    r_eb = rotation_earth_to_body(phi, theta, psi)
    pos_dot = r_eb.T @ vel_b

    force_thrust = ca.vertcat(0, 0, -thrust)
    air_b = vel_b if wind is None else vel_b - r_eb @ wind  # velocity relative to the air, body frame
    force_drag = -thrust * drag * air_b
    force_gravity = r_eb @ ca.vertcat(0, 0, mass * gravity)
    force = force_thrust + force_drag + force_gravity + disturbance[DISTURBANCE_FORCE]
    vel_dot = force / mass - ca.cross(omega, vel_b)

    # H^-1 omega in closed form (H is the matrix of euler_rates_matrix); tan theta = sin / cos.
    p, q, r = ca.vertsplit(omega)
    cph, sph = ca.cos(phi), ca.sin(phi)
    cth, sth = ca.cos(theta), ca.sin(theta)
    yaw_pitch_part = (q * sph + r * cph) / cth
    euler_dot = ca.vertcat(
        p + yaw_pitch_part * sth,
        q * cph - r * sph,
        yaw_pitch_part,
    )

    moment = torque + disturbance[DISTURBANCE_TORQUE]
    omega_dot = _rigid_body_rates(omega, moment, inertia, products)
    # one sin and one cos per angle: cse merges the copies made above and in the rotation
    return ca.cse(ca.vertcat(pos_dot, vel_dot, euler_dot, omega_dot))


def _rigid_body_rates(omega, moment, diagonal, products):
    """``J^-1 (M - omega x J omega)`` for the full tensor J, as a CasADi expression.

    J = D + P with D its diagonal and P its off-diagonal part. ``J omega_dot = v`` is solved as
    ``(I + D^-1 P) omega_dot = D^-1 v`` with the adjugate of the 3 x 3 matrix ``I + D^-1 P``. For a
    diagonal J (P = 0) every extra term is an exact zero and the determinant exactly 1, so ``f``
    and its Jacobians are ``v / D`` to the last bit, as before the products of inertia existed
    (only the sign of a few zeros of A, ``-0.0`` or ``0.0``, can differ).
    """
    jxy, jxz, jyz = ca.vertsplit(products)
    p, q, r = ca.vertsplit(omega)
    # v = M - omega x (J omega) = M + (P omega) x omega - omega x (D omega); the first for P = 0 is an exact zero
    products_omega = ca.vertcat(jxy * q + jxz * r, jxy * p + jyz * r, jxz * p + jyz * q)
    scaled = (moment + ca.cross(products_omega, omega) - ca.cross(omega, diagonal * omega)) / diagonal  # D^-1 v
    jxx, jyy, jzz = ca.vertsplit(diagonal)
    a, b = jxy / jxx, jxz / jxx  # I + D^-1 P = [[1, a, b], [c, 1, d], [e, f, 1]]
    c, d = jxy / jyy, jyz / jyy
    e, f = jxz / jzz, jyz / jzz
    adjugate = ca.vertcat(
        ca.horzcat(1 - d * f, b * f - a, a * d - b),
        ca.horzcat(d * e - c, 1 - b * e, b * c - d),
        ca.horzcat(c * f - e, a * e - f, 1 - a * c),
    )
    det = (1 - d * f) - a * (c - d * e) + b * (c * f - e)
    y0, y1, y2 = ca.vertsplit(scaled)
    return ca.vertcat(*((adjugate[i, 0] * y0 + adjugate[i, 1] * y1 + adjugate[i, 2] * y2) / det for i in range(3)))


@dataclass(frozen=True)
class Model:
    """Named CasADi functions of the model, built once.

    Attributes
    ----------
    f : casadi.Function
        ``f(x[12], u[4], p[11]) -> xdot[12]``.
    f_disturbed : casadi.Function
        ``f(x[12], u[4], p[11], d[6]) -> xdot[12]``.
    jacobians : casadi.Function
        ``(x, u, p) -> (A[12x12], B[12x4])``, exact automatic derivatives.
    f_wind : casadi.Function
        ``f(x[12], u[4], p[11], w[3]) -> xdot[12]``: in a wind ``w`` (NED, m/s).
    jacobians_wind : casadi.Function
        ``(x, u, p, w) -> (A[12x12], B[12x4])`` in the wind ``w`` (the linearization at a trim in wind).
    f_disturbed_wind : casadi.Function
        ``f(x[12], u[4], p[11], d[6], w[3]) -> xdot[12]``: disturbance ``d`` and wind ``w`` (the loops with wind).
    """

    f: ca.Function
    f_disturbed: ca.Function
    jacobians: ca.Function
    f_wind: ca.Function
    jacobians_wind: ca.Function
    f_disturbed_wind: ca.Function


@lru_cache(maxsize=1)
def build_model() -> Model:
    """Build the symbolic model (cached: the same functions are returned on every call)."""
    x = ca.SX.sym("x", N_STATES)
    u = ca.SX.sym("u", N_INPUTS)
    p = ca.SX.sym("p", N_PARAMS)
    d = ca.SX.sym("d", N_DISTURBANCES)
    w = ca.SX.sym("w", N_WIND)
    rhs_d = dynamics_expression(x, u, p, d)  # still air: the expressions (and code) of a loop without wind
    rhs = ca.substitute(rhs_d, d, ca.DM.zeros(N_DISTURBANCES))
    rhs_dw = dynamics_expression(x, u, p, d, w)
    rhs_w = ca.substitute(rhs_dw, d, ca.DM.zeros(N_DISTURBANCES))
    f = ca.Function("quad_f", [x, u, p], [rhs], ["x", "u", "p"], ["xdot"])
    f_dist = ca.Function("quad_fd", [x, u, p, d], [rhs_d], ["x", "u", "p", "d"], ["xdot"])
    f_air = ca.Function("quad_fa", [x, u, p, d, w], [rhs_dw], ["x", "u", "p", "d", "w"], ["xdot"])
    jac = ca.Function(
        "quad_jac", [x, u, p], [ca.jacobian(rhs, x), ca.jacobian(rhs, u)],
        ["x", "u", "p"], ["A", "B"],
    )
    f_wind = ca.Function("quad_fw", [x, u, p, w], [rhs_w], ["x", "u", "p", "w"], ["xdot"])
    jac_wind = ca.Function("quad_jacw", [x, u, p, w], [ca.jacobian(rhs_w, x), ca.jacobian(rhs_w, u)],
                           ["x", "u", "p", "w"], ["A", "B"])
    return Model(f=f, f_disturbed=f_dist, jacobians=jac, f_wind=f_wind, jacobians_wind=jac_wind,
                 f_disturbed_wind=f_air)


def evaluate(x: np.ndarray, u: np.ndarray, vehicle: Vehicle) -> np.ndarray:
    """``f(x, u)`` as a (12,) numpy array."""
    return np.asarray(build_model().f(x, u, vehicle.vector())).ravel()
