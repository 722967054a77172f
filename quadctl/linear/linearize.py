"""Jacobian linearization of the model at an operating point."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.errors import ArgumentError, ArgumentTypeError
from quadctl.layout import N_INPUTS, N_STATES, POSITION
from quadctl.physics.model import Vehicle, build_model


@dataclass(frozen=True, eq=False)
class LinearModel:
    """``d(dx)/dt = A dx + B du`` about ``(x_trim, u_trim)``.

    Attributes
    ----------
    A : (12, 12) ndarray
    B : (12, 4) ndarray
    x_trim : (12,) ndarray
    u_trim : (4,) ndarray
    x_rate : (12,) ndarray
        Drift of the operating point: the trim's position rates (its earth velocity, m/s),
        zero elsewhere. Position is not an equilibrium in forward flight; the reference the
        controller regulates to is ``x_trim + x_rate t``.

    Examples
    --------
    >>> import quadctl as qc
    >>> A, B = qc.linearize(np.zeros(12), [0.66708, 0, 0, 0], qc.Vehicle())  # unpacks as (A, B)
    >>> A.shape, B.shape
    ((12, 12), (12, 4))
    """

    A: np.ndarray
    B: np.ndarray
    x_trim: np.ndarray
    u_trim: np.ndarray
    x_rate: np.ndarray

    def __iter__(self):
        return iter((self.A, self.B))


def linearize(x_trim, u_trim, vehicle: Vehicle, wind_ned=None) -> LinearModel:
    """Exact Jacobians ``A = df/dx``, ``B = df/du`` from CasADi's automatic differentiation.

    Parameters
    ----------
    x_trim : (12,) array_like
    u_trim : (4,) array_like
    vehicle : Vehicle
    wind_ned : (3,) array_like, optional
        m/s NED: the steady wind of a trim in wind (:func:`quadctl.linear.trim.solve_trim`); None: still air.

    Returns
    -------
    LinearModel

    Raises
    ------
    ArgumentError
        ``x_trim``, ``u_trim`` or ``wind_ned`` is not 12, 4 or 3 finite numbers (a ``ValueError``).
    ArgumentTypeError
        ``vehicle`` is not a :class:`~quadctl.physics.model.Vehicle` (a ``TypeError``).

    Examples
    --------
    About a hover the thrust only lifts: ``dw/dT = -1/m`` (NED, down positive), and the pitch tilts
    the thrust into forward acceleration, ``du/dtheta = -g``.

    >>> import quadctl as qc
    >>> vehicle = qc.Vehicle()
    >>> hover = qc.trim([0, 0, 0], 0.0, [0, 0, -1], vehicle)
    >>> lin = qc.linearize(hover.x, hover.u, vehicle)
    >>> round(float(lin.B[5, 0] * vehicle.mass), 12), round(float(lin.A[3, 7]), 12)
    (-1.0, -9.81)
    """
    if not isinstance(vehicle, Vehicle):
        raise ArgumentTypeError(f"linearize takes a Vehicle, qc.Vehicle(mass=...) or setup.vehicle; "
                                f"got {type(vehicle).__name__}")
    x, u, wind = (_finite(v, label, size) for v, label, size in
                  ((x_trim, "x_trim", N_STATES), (u_trim, "u_trim", N_INPUTS), (wind_ned, "wind_ned", 3)))
    return linearize_all(x[None], u[None], vehicle, wind)[0]


def _finite(value, label: str, size: int):
    """``value`` as (size,) finite floats (None stays None), or the ArgumentError naming ``label``: a wrong
    length failed inside CasADi (RuntimeError), NaN came out as a model of NaN."""
    if value is None and label == "wind_ned":
        return None
    try:
        arr = np.asarray(value)
        ok = arr.shape == (size,) and arr.dtype.kind in "biuf"
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ArgumentError(f"linearize: {label} must be {size} numbers, got {value!r}")
    arr = arr.astype(float)
    if not np.all(np.isfinite(arr)):
        raise ArgumentError(f"linearize: {label} must be finite, got {value!r}")
    return arr


def linearize_all(x_trims, u_trims, vehicle: Vehicle, wind_ned=None) -> list[LinearModel]:
    """:func:`linearize` at many operating points of one vehicle (and one steady wind): the Jacobian
    functions mapped over the points, one CasADi call.

    Parameters
    ----------
    x_trims : (N, 12) array_like
    u_trims : (N, 4) array_like
    vehicle : Vehicle
    wind_ned : (3,) array_like, optional

    Returns
    -------
    list of LinearModel
    """
    x = np.asarray(x_trims, dtype=float)
    u = np.asarray(u_trims, dtype=float)
    n = len(x)
    if n == 0:
        return []
    model = build_model()
    if wind_ned is None or not np.any(wind_ned):
        jac, f, extra = model.jacobians, model.f, ()
    else:
        jac, f, extra = model.jacobians_wind, model.f_wind, (np.asarray(wind_ned, dtype=float),)
    if n > 1:
        jac, f = jac.map(n), f.map(n)
    a, b = (np.asarray(m, dtype=float) for m in jac(x.T, u.T, vehicle.vector(), *extra))
    xdot = np.asarray(f(x.T, u.T, vehicle.vector(), *extra), dtype=float).T
    A = a.reshape(N_STATES, n, N_STATES).transpose(1, 0, 2)
    B = b.reshape(N_STATES, n, N_INPUTS).transpose(1, 0, 2)
    out = []
    for k in range(n):
        x_rate = np.zeros(N_STATES)
        x_rate[POSITION] = xdot[k, POSITION]
        out.append(LinearModel(A=A[k].copy(), B=B[k].copy(), x_trim=x[k], u_trim=u[k], x_rate=x_rate))
    return out
