"""Sampled-data LQR: zero-order-hold discretization, MATLAB ``lqrd``/``dlqr``, and what a rate realizes.

A flight computer updates its command at ``rate`` Hz and holds it in between (a zero-order
hold, ZOH). Over one sample ``Ts = 1 / rate`` the linear plant ``x' = A x + B u`` becomes

    x[k+1] = Ad x[k] + Bd u[k],   Ad = e^(A Ts),   Bd = integral_0^Ts e^(A s) ds B.

MATLAB conventions throughout:

- ``dlqr(Ad, Bd, Q, R, N)``: ``u[k] = -K x[k]`` minimizes ``sum x'Qx + u'Ru + 2 x'Nu``;
  ``K = (Bd'P Bd + R)^-1 (Bd'P Ad + N')``, ``P`` the stabilizing solution of the DARE.
- ``lqrd(A, B, Q, R, Ts)``: the discrete regulator whose cost equals the *continuous* cost
  ``integral x'Qx + u'Ru dt`` of the sampled-and-held signals: the weights are integrated
  over one sample (Van Loan's matrix exponential), which adds a cross term ``Nd`` and makes
  ``Rd`` grow with ``Q``. As ``Ts -> 0`` its gain tends to the continuous ``lqr`` gain.

Eigenvalues of a discrete loop are ``z``; they are also reported as the equivalent
continuous eigenvalues ``s = ln(z) / Ts`` (rad/s), so that discrete and continuous designs
read on one scale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.errors import DesignError
from quadctl.stability import UNIT_CIRCLE_MARGIN, is_stable

scipy = lazy_import("scipy")  # loaded on first use (then scipy.linalg on access): quadctl._lazy

DARE_RTOL = 1e-8
"""Largest accepted relative DARE residual (same meaning as ``lqr.RICCATI_RTOL``)."""
SAMPLES_PER_POLE = 10.0
"""A sampled loop realizes a closed-loop pole ``s`` when ``|s| <= 2 pi rate / SAMPLES_PER_POLE``:
the rule of thumb of sampling at least ten times the fastest closed-loop frequency (Franklin,
Powell & Workman, *Digital Control of Dynamic Systems*, ch. 11, recommend 10 to 40). Beyond it the
ZOH's half-sample delay costs more than ``360 / (2 * 10) = 18`` degrees of phase at that pole."""


def c2d(A, B, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretization (MATLAB ``c2d(..., 'zoh')``).

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    Ts : float
        Sample time, s.

    Returns
    -------
    Ad : (n, n) ndarray
    Bd : (n, m) ndarray

    Examples
    --------
    A double integrator: ``Ad = [[1, Ts], [0, 1]]``, ``Bd = [Ts^2/2, Ts]``.

    >>> Ad, Bd = c2d([[0, 1], [0, 0]], [[0], [1]], 0.1)
    >>> np.round(Ad, 12).tolist(), np.round(Bd, 12).ravel().tolist()
    ([[1.0, 0.1], [0.0, 1.0]], [0.005, 0.1])
    """
    A, B = _as2d(A), _as2d(B)
    n, m = B.shape
    F = np.zeros((n + m, n + m))
    F[:n, :n], F[:n, n:] = A, B
    E = scipy.linalg.expm(F * _positive_ts(Ts))
    return E[:n, :n], E[:n, n:]


def lqrd_weights(A, B, Q, R, Ts: float, N=None):
    """The ZOH plant and the discrete weights equivalent to the continuous cost (MATLAB ``lqrd``).

    ``[[Qd, Nd], [Nd', Rd]] = integral_0^Ts [[Phi, Gamma], [0, I]]' [[Q, N], [N', R]]
    [[Phi, Gamma], [0, I]] dtau`` with ``Phi = e^(A tau)``, ``Gamma = integral_0^tau e^(A s) ds B``,
    computed with Van Loan's block exponential (IEEE TAC 23, 1978).

    Returns
    -------
    Ad, Bd, Qd, Rd, Nd : ndarray
        Shapes (n, n), (n, m), (n, n), (m, m), (n, m).

    Examples
    --------
    The integrator ``x' = u``: ``Qd = q Ts``, ``Nd = q Ts^2 / 2``, ``Rd = r Ts + q Ts^3 / 3``.

    >>> _, _, Qd, Rd, Nd = lqrd_weights([[0.0]], [[1.0]], [[3.0]], [[2.0]], 0.5)
    >>> [round(float(v), 12) for v in (Qd[0, 0], Nd[0, 0], Rd[0, 0])]
    [1.5, 0.375, 1.125]
    """
    A, B, Q, R = _as2d(A), _as2d(B), _as2d(Q), _as2d(R)
    n, m = B.shape
    N = np.zeros((n, m)) if N is None else _as2d(N)
    Ts = _positive_ts(Ts)
    F = np.zeros((n + m, n + m))
    F[:n, :n], F[:n, n:] = A, B
    W = np.block([[Q, N], [N.T, R]])
    k = n + m
    vl = np.zeros((2 * k, 2 * k))
    vl[:k, :k], vl[:k, k:], vl[k:, k:] = -F.T, W, F
    E = scipy.linalg.expm(vl * Ts)
    phi = E[k:, k:]
    Wd = phi.T @ E[:k, k:]
    Wd = (Wd + Wd.T) / 2
    return phi[:n, :n], phi[:n, n:], Wd[:n, :n], Wd[n:, n:], Wd[:n, n:]


@dataclass(frozen=True)
class DlqrResult:
    """``K, P, E = dlqr(...)``: gain (m, n), DARE solution (n, n), closed-loop eigenvalues ``z`` (n,)."""

    K: np.ndarray
    P: np.ndarray
    E: np.ndarray
    residual: float

    def __iter__(self):
        return iter((self.K, self.P, self.E))


def dare_residual(A, B, Q, R, P, N=None) -> float:
    """Relative residual of ``A'PA - P - (A'PB + N)(R + B'PB)^-1 (B'PA + N') + Q = 0`` at ``P``."""
    A, B, Q, R, P = (_as2d(m) for m in (A, B, Q, R, P))
    N = np.zeros(B.shape) if N is None else _as2d(N)
    G = A.T @ P @ B + N
    terms = (A.T @ P @ A, P, G @ np.linalg.solve(R + B.T @ P @ B, G.T), Q)
    res = terms[0] - terms[1] - terms[2] + terms[3]
    scale = sum(np.linalg.norm(t, 1) for t in terms) or 1.0
    return float(np.linalg.norm(res, 1) / scale)


def dlqr(A, B, Q, R, N=None, *, name: str = "system") -> DlqrResult:
    """Discrete-time LQR (MATLAB ``dlqr``) with ``scipy.linalg.solve_discrete_are``.

    Parameters
    ----------
    A : (n, n) array_like
        Discrete state matrix.
    B : (n, m) array_like
    Q : (n, n) array_like
        Symmetric positive semidefinite.
    R : (m, m) array_like
        Symmetric positive definite.
    N : (n, m) array_like, optional
        Cross weight (``2 x' N u`` in the cost).
    name : str
        Names the system in errors.

    Returns
    -------
    DlqrResult
        ``E`` holds the eigenvalues ``z`` of ``A - B K`` (stable: ``|z| < 1``).

    Raises
    ------
    DesignError
        The DARE has no stabilizing solution.

    Examples
    --------
    The sampled integrator ``x[k+1] = x[k] + Ts u[k]`` with ``Q = q``, ``R = r`` has
    ``P = (q Ts^2 + sqrt(q^2 Ts^4 + 4 q r Ts^2)) / (2 Ts^2)`` and ``K = Ts P / (r + Ts^2 P)``;
    with ``q = r = Ts = 1``, ``P`` is the golden ratio:

    >>> K, P, E = dlqr([[1.0]], [[1.0]], [[1.0]], [[1.0]])
    >>> round(float(P[0, 0]), 10), round(float(K[0, 0]), 10)
    (1.6180339887, 0.6180339887)
    """
    A, B, Q, R = (_as2d(m) for m in (A, B, Q, R))
    N = None if N is None else _as2d(N)
    try:
        P = scipy.linalg.solve_discrete_are(A, B, Q, R, s=N)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise DesignError(f"{name}: the discrete Riccati solve failed ({exc}); check that every "
                          "unstable mode is reachable by an input and visible to Q") from None
    if not np.all(np.isfinite(P)):
        raise DesignError(f"{name}: the discrete Riccati solution is not finite; check the weights")
    P = (P + P.T) / 2
    cross = B.T @ P @ A + (N.T if N is not None else 0.0)
    K = np.linalg.solve(R + B.T @ P @ B, cross)
    E = np.linalg.eigvals(A - B @ K)
    residual = dare_residual(A, B, Q, R, P, N)
    if residual > DARE_RTOL or not all(is_stable_z(z) for z in E):
        raise DesignError(
            f"{name}: the discrete Riccati solution is not stabilizing (residual {residual:.1e}); "
            "an unstable or marginal mode is invisible to Q: give weight to the states it lives in")
    return DlqrResult(K=K, P=P, E=E, residual=residual)


def lqrd(A, B, Q, R, Ts: float, N=None, *, name: str = "system") -> DlqrResult:
    """Discrete LQR for a continuous plant sampled at ``Ts`` (MATLAB ``lqrd``).

    Parameters
    ----------
    A, B : array_like
        The continuous plant, (n, n) and (n, m).
    Q, R, N : array_like
        Continuous weights, as for ``lqr``.
    Ts : float
        s.

    Returns
    -------
    DlqrResult
        Of ``dlqr`` on :func:`lqrd_weights`.
    """
    Ad, Bd, Qd, Rd, Nd = lqrd_weights(A, B, Q, R, Ts, N)
    return dlqr(Ad, Bd, Qd, Rd, Nd, name=name)


def is_stable_z(z: complex) -> bool:
    """Strictly inside the unit circle (:func:`quadctl.stability.is_stable`, discrete)."""
    return is_stable(z, discrete=True)


def s_equivalent(z, Ts: float) -> np.ndarray:
    """``ln(z) / Ts``: the continuous eigenvalue a discrete one corresponds to (rad/s).

    ``z = 0`` (a deadbeat mode) maps to ``-inf``.
    """
    z = np.asarray(z, dtype=complex)
    with np.errstate(divide="ignore"):
        return np.log(z) / Ts


def realizable_frequency(rate: float) -> float:
    """Fastest closed-loop pole a ``rate`` Hz loop realizes, ``2 pi rate / SAMPLES_PER_POLE`` (rad/s)."""
    return 2 * math.pi * rate / SAMPLES_PER_POLE


@dataclass(frozen=True)
class RateWarning:
    """A continuous loop whose closed-loop poles are too fast for the controller rate.

    Attributes
    ----------
    loop : str
        Subsystem name, or ``"coupled"`` for the assembled 12-state loop.
    pole : complex
        The fastest continuous closed-loop pole (rad/s).
    limit : float
        :func:`realizable_frequency` of the rate (rad/s).
    factor : float
        ``|pole| / limit``: how many times too fast.
    sampled_radius : float
        Spectral radius of the loop as the flight computer runs it (the continuous gain on the
        ZOH plant, ``Ad - Bd K``); ``>= 1`` means the sampled loop is unstable.
    """

    loop: str
    pole: complex
    limit: float
    factor: float
    sampled_radius: float

    @property
    def sampled_stable(self) -> bool:
        return self.sampled_radius < 1.0 - UNIT_CIRCLE_MARGIN

    def message(self, rate: float) -> str:
        verdict = ("stays stable but its response differs from the design"
                   if self.sampled_stable else "is UNSTABLE")
        return (f"{self.loop}: closed-loop pole {_fmt(self.pole)} rad/s is {self.factor:.3g}x faster than "
                f"{rate:g} Hz realizes (|s| <= 2 pi rate / {SAMPLES_PER_POLE:g} = {self.limit:.4g} rad/s); "
                f"sampled at {rate:g} Hz this loop {verdict} (spectral radius {self.sampled_radius:.3g}); "
                "use a discrete design (controller.design: discrete) or smaller gains (larger R)")


def spectral_radius(A_cl) -> float:
    """``max |eig(A_cl)|`` of a discrete closed loop (``>= 1``: not stable)."""
    return float(np.abs(np.linalg.eigvals(_as2d(A_cl))).max())


def rate_warnings(loops, rate: float) -> list[RateWarning]:
    """Check continuous loops against a controller rate.

    Parameters
    ----------
    loops : iterable of (name, eigenvalues, sampled_closed_loop)
        Each loop's continuous closed-loop eigenvalues (rad/s), and the discrete closed-loop
        matrix of the same gains run at ``rate`` (ZOH plant, e.g. ``Ad - Bd K``).
    rate : float
        Hz.

    Returns
    -------
    list of RateWarning
        One per loop whose fastest pole exceeds :func:`realizable_frequency`, or whose sampled
        loop is unstable: subsystems fastest first, then the coupled loop.
    """
    limit = realizable_frequency(rate)
    out = []
    for name, eig, sampled in loops:
        eig = np.asarray(eig, dtype=complex)
        finite = eig[np.isfinite(eig)]
        if finite.size == 0:
            continue
        pole = complex(finite[int(np.argmax(np.abs(finite)))])
        radius = spectral_radius(sampled)
        if abs(pole) > limit or radius >= 1.0 - UNIT_CIRCLE_MARGIN:
            out.append(RateWarning(loop=name, pole=pole, limit=limit, factor=abs(pole) / limit,
                                   sampled_radius=radius))
    return sorted(out, key=lambda w: (w.loop == "coupled", -w.factor))


def _fmt(e: complex) -> str:
    return f"{e.real:.5g}" if abs(e.imag) < 1e-9 else f"{e.real:.5g}{e.imag:+.5g}j"


def _as2d(m) -> np.ndarray:
    return np.atleast_2d(np.asarray(m, dtype=float))


def _positive_ts(Ts) -> float:
    Ts = float(Ts)
    if not (Ts > 0 and math.isfinite(Ts)):
        raise ValueError(f"sample time must be a positive finite number of seconds, got {Ts!r}")
    return Ts
