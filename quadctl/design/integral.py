"""Integral action (LQI, as MATLAB ``lqi``): a subsystem augmented with the integral of some states.

Continuous: ``dz/dt = -(x_I - x_I,ref)``, the plant ``[[A, 0], [-C, 0]]``, ``[[B], [0]]``; discrete
(a controller at ``rate`` Hz): the forward-Euler accumulator ``z[k+1] = z[k] - Ts (x_I[k] -
x_I,ref)``, the ZOH plant ``[[Ad, 0], [-Ts C, I]]``, ``[[Bd], [0]]``, which the simulation runs
exactly (:mod:`quadctl.sim.builder`). See docs/internals.md ("Integral action").
"""

from __future__ import annotations

import numpy as np


def selector(states, integral) -> np.ndarray:
    """``C`` (ni, n): rows of the identity that pick the integrated states out of ``states``."""
    states = list(states)
    return np.eye(len(states))[[states.index(s) for s in integral]].reshape(len(integral), len(states))


def augment(A, B, C) -> tuple[np.ndarray, np.ndarray]:
    """Continuous LQI plant ``([[A, 0], [-C, 0]], [[B], [0]])``.

    Parameters
    ----------
    A : (..., n, n) array_like
    B : (..., n, m) array_like
        Leading dimensions (a stack of plants) broadcast.
    C : (ni, n) or (..., ni, n) array_like
        Selects the integrated states (one selector, or one per plant of the stack).

    Returns
    -------
    (..., n + ni, n + ni) ndarray, (..., n + ni, m) ndarray

    Examples
    --------
    >>> Aa, Ba = augment([[0.0]], [[1.0]], [[1.0]])
    >>> Aa.tolist(), Ba.tolist()
    ([[0.0, 0.0], [-1.0, 0.0]], [[1.0], [0.0]])
    """
    A, B, C = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (A, B, C))
    n, m = B.shape[-2:]
    ni = C.shape[-2] if C.size else 0
    lead = np.broadcast_shapes(A.shape[:-2], B.shape[:-2], C.shape[:-2] if ni else ())
    Aa = np.zeros((*lead, n + ni, n + ni))
    Aa[..., :n, :n] = A
    if ni:
        Aa[..., n:, :n] = -C
    Ba = np.zeros((*lead, n + ni, m))
    Ba[..., :n, :] = B
    return Aa, Ba


def augment_discrete(Ad, Bd, C, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Discrete LQI plant with the forward-Euler accumulator: ``([[Ad, 0], [-Ts C, I]], [[Bd], [0]])``."""
    Aa, Ba = augment(Ad, Bd, np.asarray(C, dtype=float) * Ts)
    n = np.atleast_2d(Ad).shape[-1]
    Aa[..., n:, n:] = np.eye(Aa.shape[-1] - n)
    return Aa, Ba


def discrete_weights(Qd, Nd, Q, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Augmented discrete weights for :func:`augment_discrete`.

    The plant block is ``lqrd``'s ``Qd`` (the continuous cost integrated over a sample); the rows
    and columns of the integrators are the continuous ``Q``'s times ``Ts`` (rectangle rule: the
    accumulator is constant over the sample). ``Nd`` gets zero rows for the integrators.

    Parameters
    ----------
    Qd : (..., n, n) array_like
    Nd : (..., n, m) array_like
    Q : (..., n + ni, n + ni) array_like
        The continuous weight of ``[x; z]`` from the config. Leading dimensions broadcast.
    Ts : float
        s.
    """
    Qd, Nd, Q = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (Qd, Nd, Q))
    n, m = Nd.shape[-2:]
    lead = np.broadcast_shapes(Qd.shape[:-2], Nd.shape[:-2], Q.shape[:-2])
    Qa = np.broadcast_to(Q * Ts, (*lead, *Q.shape[-2:])).copy()
    Qa[..., :n, :n] = Qd
    Na = np.zeros((*lead, Q.shape[-1], m))
    Na[..., :n, :] = Nd
    return Qa, Na
