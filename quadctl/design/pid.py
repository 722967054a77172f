"""PID loops on one axis, in closed form: what the flight stacks' cascades are built from.

An axis is a double integrator ``m x'' = u`` (a quadcopter's altitude about hover, or an attitude
axis with ``m`` its inertia). :func:`axis_loop` closes a PID on its position, or a P on its
position over a PI(D) on its velocity (the stacks' cascade), continuous or sampled by the stacks'
own difference equations (:mod:`quadctl.sim.pid`: backward-Euler integral, derivative on the
measurement by a backward difference, zero-order hold), and returns the closed loop's matrix, whose
eigenvalues are its poles.
"""

from __future__ import annotations

import numpy as np

from quadctl.errors import ArgumentError


def axis_loop(mass: float, kp: float, ki: float, kd: float = 0.0, *, outer: float | None = None,
              sample_time: float | None = None) -> np.ndarray:
    """The closed-loop matrix of a PID (``outer`` None) or a P-over-PID cascade on ``m x'' = u``.

    Parameters
    ----------
    mass : float
        ``m`` (kg, or kg m^2 on an attitude axis).
    kp, ki, kd : float
        The (inner) PID's gains: ``u = kp e + ki integral(e) + kd d``, ``d`` the derivative of minus the
        measured value (no setpoint kick).
    outer : float, optional
        The outer P's gain (1/s): the inner PID regulates the velocity to ``v_sp = -outer x``; None: the
        PID regulates the position, ``e = -x``.
    sample_time : float, optional
        s: the law sampled with a zero-order hold (the stacks' difference equations); None: continuous.

    Returns
    -------
    A : ndarray
        Continuous: (3, 3) on ``[x, v, integral]``. Sampled: (4, 4) on ``[x, v, integral, previous
        measurement]``, the map of one sample.

    Raises
    ------
    ArgumentError
        ``kd`` of a continuous cascade (``outer`` given, no ``sample_time``).

    Examples
    --------
    A PID on ``x'' = u`` has the poles of ``s^3 + kd s^2 + kp s + ki``:

    >>> A = axis_loop(1.0, 3.0, 1.0, 3.0)
    >>> np.allclose(np.sort_complex(np.linalg.eigvals(A)), np.sort_complex(np.roots([1, 3, 3, 1])), atol=1e-4)
    True
    """
    m = float(mass)
    if sample_time is None:
        if outer is None:  # e = -x, d = -v; integral' = e
            u = np.array([-kp, -kd, ki])
        else:  # e = -outer x - v, d = -v' is not a state: kd acts through -u/m (kd = 0 for the stacks' cascades)
            if kd:
                raise ArgumentError(f"axis_loop: kd = {kd!r} with outer: a continuous cascade's inner D acts on the "
                                    "acceleration; give sample_time (s), or kd = 0")
            u = np.array([-kp * outer, -kp, ki])
        A = np.zeros((3, 3))
        A[0, 1] = 1.0
        A[1] = u / m
        A[2] = [-1.0, 0.0, 0.0] if outer is None else [-outer, -1.0, 0.0]
        return A
    T = float(sample_time)
    # state [x, v, i, y_prev] at sample k (i, y_prev: the controller's before the sample). At the sample:
    # e = -x (or -outer x - v), i+ = i + e T, d = -(y - y_prev)/T with y = x (or v), u = kp e + ki i+ + kd d;
    # then the plant under the held u: x+ = x + T v + T^2/(2m) u, v+ = v + T/m u.
    if outer is None:
        e, y = np.array([-1.0, 0, 0, 0]), np.array([1.0, 0, 0, 0])
    else:
        e, y = np.array([-outer, -1.0, 0, 0]), np.array([0, 1.0, 0, 0])
    i_new = np.array([0, 0, 1.0, 0]) + T * e
    d = -(y - np.array([0, 0, 0, 1.0])) / T
    u = kp * e + ki * i_new + kd * d
    A = np.zeros((4, 4))
    A[0] = np.array([1.0, T, 0, 0]) + T * T / (2 * m) * u
    A[1] = np.array([0, 1.0, 0, 0]) + T / m * u
    A[2] = i_new
    A[3] = y
    return A
