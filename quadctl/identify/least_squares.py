"""The fits' least squares: a bounded Levenberg-Marquardt solver, and the covariance of its answer.

:func:`sandwich` is the least-squares covariance with the residuals' autocorrelation taken into account
(a Newey-West sum); the fits (:mod:`quadctl.identify.estimate`) take their 95 % intervals from it.
"""

from __future__ import annotations

import math

import numpy as np

BANDWIDTH_FACTOR = 2
"""The Newey-West sum runs to this many times the residual's correlation length."""


def sandwich(jac: np.ndarray, res: np.ndarray) -> tuple[np.ndarray, int]:
    """The least-squares covariance ``H^-1 S H^-1`` with ``S`` a Newey-West (Bartlett) sum of the
    residual's scores over their autocorrelation.

    Parameters
    ----------
    jac : (N, r, k) ndarray
        ``d residual / d parameters`` at each sample.
    res : (N, r) ndarray

    Returns
    -------
    covariance : (k, k) ndarray
    bandwidth : int
        The lag the sum runs to: twice the lag where the residual's autocorrelation first falls below 0.05.
    """
    n = res.shape[0]
    scores = np.einsum("nrk,nr->nk", jac, res)
    flat = jac.reshape(-1, jac.shape[2])
    hess_inv = np.linalg.inv(flat.T @ flat)
    bandwidth = BANDWIDTH_FACTOR * correlation_length(res)
    size = 1 << int(math.ceil(math.log2(n + bandwidth + 1)))
    spec = np.fft.rfft(scores, size, axis=0)
    # gamma[l, a, b] = sum_t scores[t + l, a] scores[t, b], every lag at once
    gamma = np.fft.irfft(spec[:, :, None] * spec[:, None, :].conj(), size, axis=0)[: bandwidth + 1]
    weights = 1.0 - np.arange(bandwidth + 1) / (bandwidth + 1.0)
    s = gamma[0] + np.einsum("l,lab->ab", weights[1:], gamma[1:] + gamma[1:].transpose(0, 2, 1))
    cov = hess_inv @ s @ hess_inv
    return (cov + cov.T) / 2.0 * n / max(n - jac.shape[2], 1), bandwidth


def correlation_length(res: np.ndarray) -> int:
    """Samples until the residual's autocorrelation (averaged over its columns) first falls below 0.05."""
    r = res - res.mean(axis=0)
    n = r.shape[0]
    size = 1 << int(math.ceil(math.log2(2 * n)))
    spec = np.fft.rfft(r, size, axis=0)
    acf = np.fft.irfft(np.abs(spec) ** 2, size, axis=0)[:n].sum(axis=1)
    acf = acf / acf[0] if acf[0] > 0 else np.zeros(n)
    below = np.nonzero(acf < 0.05)[0]
    return int(max(1, min(below[0] if below.size else n // 5, n // 5)))


def levenberg_marquardt(residual_and_jacobian, x0: np.ndarray, scale: np.ndarray, lower: np.ndarray,
                         iterations: int = 50):
    """Minimize ``|r(x)|^2`` from ``x0`` (``scale``: typical sizes; ``lower``: bounds held by clipping)."""
    x = x0.copy()
    r, j = residual_and_jacobian(x)
    cost = float(np.sum(r ** 2))
    mu = 1e-3
    for _ in range(iterations):
        js = j * scale
        g = js.T @ r
        h = js.T @ js
        step = -np.linalg.solve(h + mu * np.diag(np.diag(h)), g) * scale
        trial = np.maximum(x + step, lower)
        r_t, j_t = residual_and_jacobian(trial)
        cost_t = float(np.sum(r_t ** 2))
        if cost_t < cost:
            done = cost - cost_t < 1e-9 * cost  # a relative 1e-9 of the cost: far inside any interval
            x, r, j, cost, mu = trial, r_t, j_t, cost_t, max(mu / 5.0, 1e-9)
            if done:
                break
        else:
            mu *= 10.0
            if mu > 1e8:
                break
    return x
