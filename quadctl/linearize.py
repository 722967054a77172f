"""Jacobian linearization of the model at an operating point."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.layout import POSITION
from quadctl.model import Vehicle, build_model


@dataclass(frozen=True)
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
        m/s NED: the steady wind of a trim in wind (:func:`quadctl.trim.solve_trim`); None: still air.

    Returns
    -------
    LinearModel
    """
    x_trim = np.asarray(x_trim, dtype=float)
    u_trim = np.asarray(u_trim, dtype=float)
    model = build_model()
    if wind_ned is None or not np.any(wind_ned):
        a, b = model.jacobians(x_trim, u_trim, vehicle.vector())
        xdot = np.asarray(model.f(x_trim, u_trim, vehicle.vector()), dtype=float).ravel()
    else:
        wind = np.asarray(wind_ned, dtype=float)
        a, b = model.jacobians_wind(x_trim, u_trim, vehicle.vector(), wind)
        xdot = np.asarray(model.f_wind(x_trim, u_trim, vehicle.vector(), wind), dtype=float).ravel()
    x_rate = np.zeros_like(xdot)
    x_rate[POSITION] = xdot[POSITION]
    return LinearModel(A=np.asarray(a, dtype=float), B=np.asarray(b, dtype=float),
                       x_trim=x_trim, u_trim=u_trim, x_rate=x_rate)
