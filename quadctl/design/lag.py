"""The rotors' first-order lag in linear models: the plant augmented with one lag state per input.

With all rotors sharing the time constant ``tau`` and the mixer constant, ``df/dt = (mix u - f) / tau``
is, in the virtual inputs ``v = mix_inv f = [T, A, E, R]``, ``dv/dt = (u - v) / tau``: each input
lags independently, so every subsystem of a decoupled model augments on its own inputs and the
partition stays decoupled:

    d/dt [x; v] = [[A, B], [0, -I / tau]] [x; v] + [[0], [I / tau]] u.

Used by the design (``controller.rotor_lag: include``: LQR on this model, :mod:`quadctl.design`) and
by the margins (the lag in every loop, :mod:`quadctl.design.broken_loops`).
"""

from __future__ import annotations

import math

import numpy as np


def lagged(A, B, time_constant: float | None):
    """``(A, B)`` of a continuous plant whose inputs pass through ``1 / (tau s + 1)`` each.

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    time_constant : float or None
        s; None returns the plant unchanged.

    Returns
    -------
    (n + m, n + m) ndarray, (n + m, m) ndarray
        The state ``[x; v]``: ``dx/dt = A x + B v``, ``dv/dt = (u - v) / tau``.

    Examples
    --------
    >>> Al, Bl = lagged([[0.0]], [[1.0]], 0.5)
    >>> Al.tolist(), Bl.ravel().tolist()
    ([[0.0, 1.0], [0.0, -2.0]], [0.0, 2.0])
    """
    A, B = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (A, B))
    if time_constant is None:
        return A, B
    n, m = B.shape
    Al = np.zeros((n + m, n + m))
    Al[:n, :n], Al[:n, n:] = A, B
    Al[n:, n:] = -np.eye(m) / time_constant
    return Al, np.vstack([np.zeros((n, m)), np.eye(m) / time_constant])


def model_pole(time_constant: float, sample_time: float | None = None) -> float:
    """The lag model's pole: ``-1 / tau`` (rad/s), or ``exp(-Ts / tau)`` sampled (its exact ZOH)."""
    if sample_time is None:
        return -1.0 / time_constant
    return math.exp(-sample_time / time_constant)


def scalar_integrator_gain(q: float, r: float, time_constant: float) -> tuple[float, float]:
    """Closed-form LQR gain ``[k_x, k_v]`` of a lagged integrator, ``x' = v``, ``v' = (u - v) / tau``,
    with ``Q = diag(q, 0)``, ``R = r``.

    The return-difference equation gives the closed-loop polynomial ``s^2 + c1 s + c0`` with
    ``c0 = a sqrt(q / r)``, ``c1 = sqrt(a^2 + 2 c0)``, ``a = 1 / tau``; matching it with
    ``det(sI - A + B K) = s^2 + a (1 + k_v) s + a k_x``:
    ``k_x = sqrt(q / r)``, ``k_v = sqrt(1 + 2 tau sqrt(q / r)) - 1`` (``k_v -> 0`` as ``tau -> 0``).

    >>> scalar_integrator_gain(4.0, 1.0, 1.5)
    (2.0, 1.6457513110645907)
    """
    kx = math.sqrt(q / r)
    return kx, math.sqrt(1.0 + 2.0 * time_constant * kx) - 1.0
