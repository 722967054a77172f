"""The sensor filters a flight stack runs on its gyro: low-pass and notch, as one state space per axis.

The same filter runs on each body rate ``p, q, r``: sections ``(A, b, c, d)`` cascaded (low-pass, then
notch), continuous, or discrete at the controller's period with the output taking the current sample
(no added delay): the first-order PT1 with its exact pole (:func:`lowpass1`), the bilinear
Butterworth (:func:`lowpass2`) and notch (:func:`notch`) biquads prewarped at their frequency. All
start at rest. :func:`with_rate_filter`, :func:`series` and :func:`filtered_output` put a filter into
a loop or a Kalman filter's model. See docs/guide/vehicle.md ("Gyro filters").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

RATE_STATES = ("p", "q", "r")
"""The states the gyro filter runs on (the body rates)."""


@dataclass(frozen=True)
class Section:
    """One filter stage as configured: ``kind`` ``lowpass`` (``frequency`` the cutoff, ``order`` 1 or 2)
    or ``notch`` (``frequency`` its centre, ``bandwidth`` its -3 dB width), Hz."""

    kind: str
    frequency: float
    order: int = 2
    bandwidth: float = 0.0

    def form(self, sample_time: float | None) -> StateSpace:
        """The section's state space, continuous (``sample_time`` None) or at ``sample_time`` s."""
        if self.kind == "lowpass":
            return (lowpass1 if self.order == 1 else lowpass2)(self.frequency, sample_time)
        return notch(self.frequency, self.bandwidth, sample_time)

    def describe(self) -> str:
        if self.kind == "lowpass":
            return f"{'first' if self.order == 1 else 'second'}-order low-pass at {self.frequency:g} Hz"
        return f"notch at {self.frequency:g} Hz ({self.bandwidth:g} Hz wide)"


@dataclass(frozen=True)
class StateSpace:
    """A SISO filter ``(A, b, c, d)`` (``sample_time`` None: continuous)."""

    A: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: float
    sample_time: float | None = None

    @property
    def order(self) -> int:
        return self.A.shape[0]

    def response(self, w) -> np.ndarray:
        """The frequency response at ``w`` (rad/s): ``c (sI - A)^-1 b + d`` at ``s = j w``, or ``z = e^(j w Ts)``.

        Examples
        --------
        >>> f = lowpass1(10.0, None)
        >>> bool(np.isclose(np.angle(f.response(2 * np.pi * 10.0)), -np.pi / 4))
        True
        """
        w = np.atleast_1d(np.asarray(w, dtype=float))
        s = np.exp(1j * w * self.sample_time) if self.sample_time else 1j * w
        n = self.order
        out = np.empty(w.shape, dtype=complex)
        for i, si in enumerate(s):
            out[i] = self.c @ np.linalg.solve(si * np.eye(n) - self.A, self.b) + self.d
        return out


def lowpass1(cutoff: float, sample_time: float | None) -> StateSpace:
    """First-order low-pass at ``cutoff`` Hz: ``wc / (s + wc)``, or the matched-pole PT1 (module doc)."""
    wc = 2 * math.pi * cutoff
    if sample_time is None:
        return StateSpace(np.array([[-wc]]), np.array([wc]), np.array([1.0]), 0.0)
    a = math.exp(-wc * sample_time)
    return StateSpace(np.array([[a]]), np.array([1 - a]), np.array([a]), 1 - a, sample_time)


def _biquad(b0, b1, b2, a1, a2, sample_time) -> StateSpace:
    """``(b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2)`` in direct form II transposed:
    ``y = b0 r + s1``, ``s1 <- b1 r - a1 y + s2``, ``s2 <- b2 r - a2 y``."""
    return StateSpace(np.array([[-a1, 1.0], [-a2, 0.0]]), np.array([b1 - a1 * b0, b2 - a2 * b0]),
                      np.array([1.0, 0.0]), b0, sample_time)


def lowpass2(cutoff: float, sample_time: float | None) -> StateSpace:
    """Second-order Butterworth low-pass at ``cutoff`` Hz: ``wc^2 / (s^2 + sqrt(2) wc s + wc^2)``, or its
    prewarped bilinear biquad (module doc)."""
    wc = 2 * math.pi * cutoff
    if sample_time is None:
        return StateSpace(np.array([[0.0, 1.0], [-wc * wc, -math.sqrt(2) * wc]]), np.array([0.0, wc * wc]),
                          np.array([1.0, 0.0]), 0.0)
    K = math.tan(math.pi * cutoff * sample_time)
    norm = 1.0 / (1.0 + math.sqrt(2) * K + K * K)
    b0 = K * K * norm
    return _biquad(b0, 2 * b0, b0, 2 * (K * K - 1) * norm, (1 - math.sqrt(2) * K + K * K) * norm, sample_time)


def notch(center: float, bandwidth: float, sample_time: float | None) -> StateSpace:
    """Notch at ``center`` Hz, ``bandwidth`` Hz wide at -3 dB (``Q = center / bandwidth``):
    ``(s^2 + w0^2) / (s^2 + (w0 / Q) s + w0^2)``, or its bilinear biquad with the centre and the
    bandwidth prewarped (PX4's ``NotchFilter``, SciPy's ``iirnotch``): ``alpha = tan(pi bandwidth Ts)``,
    ``beta = -cos(2 pi center Ts)``, ``(1 + 2 beta z^-1 + z^-2) / ((1 + alpha) + 2 beta z^-1 + (1 - alpha) z^-2)``."""
    w0, Q = 2 * math.pi * center, center / bandwidth
    if sample_time is None:
        return StateSpace(np.array([[0.0, 1.0], [-w0 * w0, -w0 / Q]]), np.array([0.0, 1.0]),
                          np.array([0.0, -w0 / Q]), 1.0)
    alpha, beta = math.tan(math.pi * bandwidth * sample_time), -math.cos(2 * math.pi * center * sample_time)
    b0 = 1.0 / (1.0 + alpha)
    return _biquad(b0, 2 * beta * b0, b0, 2 * beta * b0, (1 - alpha) * b0, sample_time)


def cascade(first: StateSpace, then: StateSpace) -> StateSpace:
    """``then`` after ``first``: state ``[g1; g2]``."""
    n1, n2 = first.order, then.order
    A = np.zeros((n1 + n2, n1 + n2))
    A[:n1, :n1], A[n1:, :n1], A[n1:, n1:] = first.A, np.outer(then.b, first.c), then.A
    return StateSpace(A, np.concatenate([first.b, then.b * first.d]), np.concatenate([then.d * first.c, then.c]),
                      then.d * first.d, first.sample_time)


@dataclass(frozen=True)
class RateFilter:
    """The filters on the gyro (``controller.filters``), in the order they run; ``form`` gives their state space.

    Examples
    --------
    >>> f = RateFilter((Section("lowpass", 40.0, 2), Section("notch", 120.0, bandwidth=40.0)))
    >>> f.form(1 / 500).order, f.describe()
    (4, 'second-order low-pass at 40 Hz, then notch at 120 Hz (40 Hz wide)')
    """

    sections: tuple[Section, ...]

    @property
    def order(self) -> int:
        """Filter states per axis."""
        return sum(1 if s.kind == "lowpass" and s.order == 1 else 2 for s in self.sections)

    def form(self, sample_time: float | None) -> StateSpace:
        """The cascade's state space, continuous or at ``sample_time`` s (cached)."""
        return _form(self, sample_time)

    def describe(self) -> str:
        return ", then ".join(s.describe() for s in self.sections)


@lru_cache(maxsize=64)
def _form(filt: RateFilter, sample_time: float | None) -> StateSpace:
    out = None
    for section in filt.sections:
        f = section.form(sample_time)
        out = f if out is None else cascade(out, f)
    return out


def rate_filter_of(filters) -> RateFilter | None:
    """The gyro's :class:`RateFilter` of ``controller.filters`` (None: no filter on the gyro)."""
    if filters is None:
        return None
    sections = []
    if filters.gyro is not None:
        sections.append(Section("lowpass", float(filters.gyro.cutoff), int(filters.gyro.order)))
    if filters.notch is not None:
        sections.append(Section("notch", float(filters.notch.center), bandwidth=float(filters.notch.bandwidth)))
    return RateFilter(tuple(sections)) if sections else None


def with_rate_filter(A, B, K, form: StateSpace | None, rate_columns):
    """``(A, B, K)`` of a state-feedback loop whose law takes the filtered rates in place of the states
    ``rate_columns`` (each through its own copy of ``form``): state ``[X; g]``, ``g`` one block of
    ``form.order`` per rate.

    The filter is a controller state: its rows are in ``A`` (driven by the plant's rate, continuous
    ``dg/dt = A_f g + b_f x_i``, or sampled ``g <- A_f g + b_f x_i``) and ``B`` has none, so a loop broken
    at the plant input sees its phase lag. The gain on the rate ``K_i`` becomes ``d_f K_i`` on the
    rate and ``K_i c_f`` on its filter states. ``form`` None returns the loop unchanged.

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    K : (m, n) array_like
    form : StateSpace or None
        Continuous for a continuous loop, at the loop's period for a sampled one.
    rate_columns : sequence of int
        Columns of the rates the law takes filtered.
    """
    A, B, K = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (A, B, K))
    cols = list(rate_columns)
    if form is None or not cols:
        return A, B, K
    n, m, k = A.shape[0], B.shape[1], form.order
    N = n + k * len(cols)
    Aa = np.zeros((N, N))
    Aa[:n, :n] = A
    Ka = np.hstack([K, np.zeros((m, N - n))])
    for j, i in enumerate(cols):
        g = slice(n + j * k, n + (j + 1) * k)
        Aa[g, g] = form.A
        Aa[g, i] = form.b
        Ka[:, g] = np.outer(K[:, i], form.c)
        Ka[:, i] = K[:, i] * form.d
    return Aa, np.vstack([B, np.zeros((N - n, m))]), Ka


def series(A, B, form: StateSpace | None, rate_columns):
    """``(A, B)`` of a plant followed by the filter ``form`` on each of its states ``rate_columns``: state ``[x; g]``.

    ``g`` is one block of ``form.order`` per rate, driven by the plant's rate (continuous
    ``dg/dt = A_f g + b_f x_i``, or sampled ``g <- A_f g + b_f x_i`` with ``A``, ``B`` the plant held at
    the filter's period); the input does not reach it. With :func:`filtered_output` it is the model of a
    plant whose rates are measured after the filter (what the flight computer sees), the model of a
    Kalman filter in a loop with a gyro filter. ``form`` None returns the plant unchanged.

    Examples
    --------
    >>> Aa, Ba = series([[0.0]], [[1.0]], lowpass1(1.0, None), [0])
    >>> Aa.round(4).tolist(), Ba.ravel().tolist()
    ([[0.0, 0.0], [6.2832, -6.2832]], [1.0, 0.0])
    """
    A, B = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (A, B))
    cols = list(rate_columns)
    if form is None or not cols:
        return A, B
    n, k = A.shape[0], form.order
    N = n + k * len(cols)
    Aa = np.zeros((N, N))
    Aa[:n, :n] = A
    for j, i in enumerate(cols):
        g = slice(n + j * k, n + (j + 1) * k)
        Aa[g, g] = form.A
        Aa[g, i] = form.b
    return Aa, np.vstack([B, np.zeros((N - n, B.shape[1]))])


def filtered_output(C, form: StateSpace | None, rate_columns) -> np.ndarray:
    """``C`` (p, n) of the plant's states, on :func:`series`'s state ``[x; g]``, with every row that reads a rate
    of ``rate_columns`` reading its filtered value ``c_f g + d_f x_i`` instead.

    Examples
    --------
    >>> filtered_output([[1.0, 0.0], [0.0, 1.0]], lowpass1(1.0, None), [1]).tolist()
    [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    """
    C = np.atleast_2d(np.asarray(C, dtype=float))
    cols = list(rate_columns)
    if form is None or not cols:
        return C
    n, k = C.shape[1], form.order
    Ca = np.hstack([C, np.zeros((C.shape[0], k * len(cols)))])
    for j, i in enumerate(cols):
        Ca[:, n + j * k:n + (j + 1) * k] = np.outer(C[:, i], form.c)
        Ca[:, i] = C[:, i] * form.d
    return Ca


def state_names(order: int) -> tuple[str, ...]:
    """Names of the filter's states ``g`` on the three rates, ``order`` per rate: ``g_p_0, g_p_1, ..., g_r_1``."""
    return tuple(f"g_{rate}_{m}" for rate in RATE_STATES for m in range(order))
