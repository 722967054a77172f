"""A gain schedule's table: gains at points of one scheduling variable, and their interpolation.

:class:`GainTable` is what every user of a schedule takes (the schedule stage and its artifacts, the
simulated loop, the exported C): the values, the gain at each, and one piecewise cubic in SciPy's
:class:`~scipy.interpolate.PPoly` layout for every interpolation (:data:`INTERPOLATIONS`), held at
the ends (:data:`OUTSIDE`). :func:`scheduling_value` reads the variable (:data:`VARIABLES`) from a
state. See docs/guide/scheduling.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from quadctl.errors import ArgumentError
from quadctl.layout import STATE_NAMES
from quadctl.physics.model import rotation_earth_to_body

INTERPOLATIONS = ("nearest", "linear", "cubic")
"""How gains are interpolated between the schedule's values."""
VARIABLES = {"speed": "m/s", "climb": "m/s", "yaw": "rad"}
"""The scheduling variables and their units."""
OUTSIDE = "the end point's gain (the table is held, never extrapolated)"
"""What the table gives outside ``[values[0], values[-1]]``."""

_U, _PHI = STATE_NAMES.index("u"), STATE_NAMES.index("phi")


def scheduling_value(variable: str, x, heading: float, lib=np):
    """The scheduling variable of state ``x`` (12,): NumPy arrays, or CasADi symbols with ``lib=casadi``.

    Parameters
    ----------
    variable : {'speed', 'climb', 'yaw'}
        ``speed``: the earth-frame velocity along the horizontal unit vector of ``heading`` (m/s);
        ``climb``: ``-vD`` (m/s, up positive); ``yaw``: ``psi`` (rad).
    x : (12,) array or CasADi column
        The state in ``STATE_NAMES`` order (body velocities ``u, v, w`` and ZYX Euler angles).
    heading : float or CasADi scalar
        rad from north, the direction ``speed`` is measured along.
    lib : module
        ``numpy`` (returns a float) or ``casadi`` (returns an expression). The rotation is the
        model's (:func:`quadctl.physics.model.rotation_earth_to_body`).
    """
    if variable not in VARIABLES:
        raise ArgumentError(f"unknown scheduling variable {variable!r}: use one of {', '.join(VARIABLES)}")
    psi = x[_PHI + 2]
    if variable == "yaw":
        return psi
    velocity_ned = rotation_earth_to_body(x[_PHI], x[_PHI + 1], psi).T @ x[_U:_U + 3]
    if lib is np:
        velocity_ned = np.asarray(velocity_ned, dtype=float).ravel()
    return flight_value(variable, velocity_ned, psi, heading, lib)


def flight_value(variable: str, velocity_ned, yaw, heading: float, lib=np):
    """The scheduling variable of a flight condition: its earth-frame velocity ``velocity_ned`` (3,)
    m/s and ``yaw`` rad (``speed``: along ``heading``; ``climb``: ``-vD``; ``yaw``: ``yaw``)."""
    if variable == "yaw":
        return yaw
    if variable == "climb":
        return -velocity_ned[2]
    return lib.cos(heading) * velocity_ned[0] + lib.sin(heading) * velocity_ned[1]


def scheduling_values(variable: str, xs, heading: float) -> np.ndarray:
    """(n,) :func:`scheduling_value` of each row of ``xs`` (n, 12) (a run's states), by one mapped
    CasADi function of the same expression."""
    xs = np.atleast_2d(np.asarray(xs, dtype=float))
    return np.asarray(_mapped_value(variable, len(xs))(xs.T, heading), dtype=float).ravel()


@lru_cache(maxsize=8)
def _mapped_value(variable: str, n: int):
    import casadi as ca

    x, heading = ca.SX.sym("x", len(STATE_NAMES)), ca.SX.sym("heading")
    return ca.Function("scheduling_value", [x, heading], [scheduling_value(variable, x, heading, lib=ca)]).map(n)


@dataclass(frozen=True)
class GainTable:
    """Gains at the scheduling values and the piecewise cubic between them.

    Attributes
    ----------
    variable : str
        One of :data:`VARIABLES`.
    values : (n,) ndarray
        The scheduling values, strictly increasing, ``n >= 2`` (the variable's unit).
    gains : (n, 4, m) ndarray
        The gain at each value: ``u = u_ref - G(v) [x - x_ref; z]`` with ``G`` the 4x12 block gain
        (columns in ``STATE_NAMES`` order) followed by any integrator gains.
    interpolation : str
        One of :data:`INTERPOLATIONS`.
    breaks : (p + 1,) ndarray
        Where the pieces begin and end (the values; for ``nearest``, the midpoints between them).
    coefficients : (4, p, 4, m) ndarray
        ``G(v) = sum_k coefficients[k, i] (v - breaks[i])^(3 - k)`` on piece ``i``.
    """

    variable: str
    values: np.ndarray
    gains: np.ndarray
    interpolation: str
    breaks: np.ndarray
    coefficients: np.ndarray

    @classmethod
    def of(cls, variable: str, values, gains, interpolation: str = "linear") -> GainTable:
        """The table of ``gains`` (n, 4, m) at ``values`` (n,), interpolated as ``interpolation``.

        Raises
        ------
        ArgumentError
            An unknown ``variable`` or ``interpolation``, fewer than two values or values not increasing, or
            ``gains`` of another shape (the message names the argument).
        """
        if variable not in VARIABLES:
            raise ArgumentError(f"GainTable.of: unknown scheduling variable {variable!r}: use one of "
                                f"{', '.join(VARIABLES)}")
        if interpolation not in INTERPOLATIONS:
            raise ArgumentError(f"GainTable.of: unknown interpolation {interpolation!r}: use one of "
                                f"{', '.join(INTERPOLATIONS)}")
        values = np.asarray(values, dtype=float)
        gains = np.asarray(gains, dtype=float)
        if values.ndim != 1 or len(values) < 2 or not np.all(np.isfinite(values)):
            raise ArgumentError(f"GainTable.of: values = {values.tolist()}: a gain table needs at least two finite "
                                "scheduling values, in a 1-D array")
        if np.any(np.diff(values) <= 0):
            raise ArgumentError(f"GainTable.of: values = {values.tolist()}: the scheduling values must increase "
                                "strictly; sort them and drop repeats")
        if gains.ndim != 3 or gains.shape[:2] != (len(values), 4):
            raise ArgumentError(f"GainTable.of: gains has shape {gains.shape}, expected ({len(values)}, 4, m): "
                                "one 4-row gain per value")
        breaks, coefficients = _pieces(values, gains, interpolation)
        return cls(variable, values, gains, interpolation, breaks, coefficients)

    def at(self, v) -> np.ndarray:
        """(4, m), or (k, 4, m) for ``k`` values: the gain at ``v``, held at the grid's ends."""
        v = np.clip(np.asarray(v, dtype=float), self.breaks[0], self.breaks[-1])
        i = np.clip(np.searchsorted(self.breaks, v, side="right") - 1, 0, len(self.breaks) - 2)
        s = (v - self.breaks[i])[..., None, None]
        c = self.coefficients[:, i]
        return ((c[0] * s + c[1]) * s + c[2]) * s + c[3]


def _pieces(values: np.ndarray, gains: np.ndarray, interpolation: str) -> tuple[np.ndarray, np.ndarray]:
    """(breaks, coefficients) of the piecewise cubic (:class:`GainTable`)."""
    n = len(values)
    if interpolation == "cubic":
        from scipy.interpolate import CubicSpline

        spline = CubicSpline(values, gains, axis=0)
        return np.array(spline.x), np.array(spline.c)
    if interpolation == "linear":
        coefficients = np.zeros((4, n - 1) + gains.shape[1:])
        coefficients[2] = np.diff(gains, axis=0) / np.diff(values)[:, None, None]
        coefficients[3] = gains[:-1]
        return values.copy(), coefficients
    midpoints = (values[:-1] + values[1:]) / 2
    breaks = np.concatenate([values[:1], midpoints, values[-1:]])
    coefficients = np.zeros((4, n) + gains.shape[1:])
    coefficients[3] = gains
    return breaks, coefficients
