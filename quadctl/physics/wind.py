"""Wind for the simulation: steady wind, discrete 1-cosine gusts and Dryden turbulence (numpy only).

The wind is the air's velocity over the ground, NED (m/s), sampled on the exogenous clock
(:class:`WindStream`); turbulence is seen at :func:`reference_speed`. The gust (MIL-F-8785C
§3.7.3.4) and the Dryden model (MIL-HDBK-1797 §B.4.4) with their formulas and sources are in the
docs, docs/internals.md ("Wind").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

FT = 0.3048
"""m per ft (exact)."""
KNOT = 1852.0 / 3600.0
"""m/s per knot (exact)."""
W20 = {"light": 15 * KNOT, "moderate": 30 * KNOT, "severe": 45 * KNOT}
"""Wind speed at 20 ft (m/s) of each turbulence intensity, MIL-HDBK-1797 figure 262 (MIL-F-8785C §3.7.2.3)."""
MIN_ALTITUDE_FT = 10.0
"""ft: the low-altitude scales are taken at no less than this. ``L_w = h / 2`` goes to zero at the ground
(white turbulence); 10 ft is half the 20 ft reference height the intensities are given at."""
MAX_ALTITUDE_FT = 1000.0
"""ft: the top of the low-altitude model (MIL-HDBK-1797 §B.4.4.1)."""
MIN_REFERENCE_SPEED = 1.0
"""m/s: the floor of the reference speed that turns the spatial spectra into time. A hovering vehicle
in still mean air has none; at 1 m/s the vertical turbulence at 10 ft stays correlated for
``2 L_w / V`` = 3 s (its double pole is at ``V / (2 L_w)``), slower than every loop quadctl designs."""
TURBULENCE_PERIOD = 0.01
"""s between turbulence samples (linear in between). At the fastest reference speeds a config allows
(50 m/s at 10 ft, where ``2 L_w = h`` = 3.05 m puts the vertical spectrum's double pole ``V / (2 L_w)``
at 2.6 Hz), 100 Hz resolves the spectrum to 40 times its corner."""
AXES = ("n", "e", "d")
"""Components of the wind, NED."""


@dataclass(frozen=True)
class Gust:
    """One 1-cosine gust (MIL-F-8785C §3.7.3.4), in time.

    Attributes
    ----------
    start : float
        s.
    length : float
        s to rise to the amplitude (``d_m`` over the speed), and to fall back.
    amplitude : (3,) tuple of float
        m/s, NED.
    hold : float
        s at the amplitude between rise and fall (``inf``: the specification's gust, which stays).
    """

    start: float
    length: float
    amplitude: tuple[float, float, float]
    hold: float = 0.0

    def shape(self, t) -> np.ndarray:
        """The gust's fraction of its amplitude at times ``t`` (s): 0 to 1."""
        t = np.asarray(t, dtype=float)
        s = (t - self.start) / self.length
        rise = 0.5 * (1.0 - np.cos(np.pi * np.clip(s, 0.0, 1.0)))
        if math.isinf(self.hold):
            return np.where(s <= 0.0, 0.0, rise)
        back = s - 1.0 - self.hold / self.length
        fall = 0.5 * (1.0 + np.cos(np.pi * np.clip(back, 0.0, 1.0)))
        return np.where(s <= 0.0, 0.0, np.where(back <= 0.0, rise, np.where(back < 1.0, fall, 0.0)))

    def velocity(self, t) -> np.ndarray:
        """(n, 3) m/s NED at times ``t`` (n,)."""
        return self.shape(t)[:, None] * np.asarray(self.amplitude, dtype=float)[None, :]


@dataclass(frozen=True)
class Turbulence:
    """Dryden turbulence: intensities and scales per axis, the reference speed, the seed.

    Attributes
    ----------
    sigma : (3,) tuple of float
        m/s, standard deviations of ``u, v, w`` (along the mean wind, across it, down).
    length : (3,) tuple of float
        m, ``L_u, L_v, L_w`` in MIL-HDBK-1797's form (see the module).
    speed : float
        m/s, the reference airspeed turning the spatial spectra into time.
    heading : float
        rad, direction of ``u`` from north (towards east).
    seed : int
    period : float
        s between samples.
    """

    sigma: tuple[float, float, float]
    length: tuple[float, float, float]
    speed: float
    heading: float = 0.0
    seed: int = 0
    period: float = TURBULENCE_PERIOD

    def to_ned(self) -> np.ndarray:
        """(3, 3): ``[u, v, w]`` (along the mean wind, right of it, down) to NED."""
        c, s = math.cos(self.heading), math.sin(self.heading)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def filters(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per axis ``(A, B, C)``: the forming filter ``dx = A x dt + B dW``, ``y = C x`` with the
        Dryden spectrum in time at :attr:`speed` and variance ``sigma^2`` (white noise of unit intensity)."""
        out = []
        for axis in range(3):
            a = self.speed / self.length[axis]  # rad/s: the spectrum's corner
            if axis == 0:  # H(s) = k / (s + a): first order
                A, B, C = np.array([[-a]]), np.array([[1.0]]), np.array([[1.0]])
            else:  # 1797's (1 + 12 (L W)^2) / (1 + 4 (L W)^2)^2 = |(1 + 2 sqrt3 s/a) / (1 + 2 s/a)^2|^2, s = i omega
                b = a / 2.0  # double pole at V / (2 L)
                A = np.array([[0.0, 1.0], [-b * b, -2.0 * b]])
                B = np.array([[0.0], [1.0]])
                C = np.array([[b * b, math.sqrt(3.0) * b]])  # zero at -b / sqrt3 = -V / (2 sqrt3 L)
            P = _stationary(A, B)
            C = C * (self.sigma[axis] / math.sqrt(float((C @ P @ C.T)[0, 0])))
            out.append((A, B, C))
        return out

    def psd(self, f) -> np.ndarray:
        """(n, 3) one-sided PSD of ``u, v, w`` at frequencies ``f`` (Hz), (m/s)^2/Hz: the handbook's
        spectra at :attr:`speed`, ``S(f) = 2 pi Phi(W = 2 pi f / V) / V`` (``Phi`` one-sided in W)."""
        f = np.asarray(f, dtype=float)
        out = np.empty((len(f), 3))
        for axis in range(3):
            L, sig = self.length[axis], self.sigma[axis]
            x = L * 2.0 * np.pi * f / self.speed  # L W
            if axis == 0:
                phi = sig ** 2 * (2 * L / np.pi) / (1 + x ** 2)
            else:
                phi = sig ** 2 * (2 * L / np.pi) * (1 + 12 * x ** 2) / (1 + 4 * x ** 2) ** 2
            out[:, axis] = 2 * np.pi * phi / self.speed
        return out


def _stationary(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The stationary covariance ``P`` of ``dx = A x dt + B dW`` (``A P + P A' + B B' = 0``) for the
    two forming filters, in closed form: ``1 / (2 a)`` for ``A = [-a]``; ``diag(1 / (4 b^3), 1 / (4 b))``
    for the double pole ``A = [[0, 1], [-b^2, -2 b]]``, ``B = [0, 1]'``."""
    if len(A) == 1:
        return np.array([[float(B[0, 0]) ** 2 / (-2.0 * float(A[0, 0]))]])
    b = -float(A[1, 1]) / 2.0
    return np.diag([1.0 / (4.0 * b ** 3), 1.0 / (4.0 * b)])


def _transition(A: np.ndarray, T: float) -> np.ndarray:
    """``expm(A T)`` of a forming filter, in closed form: ``exp(-a T)``; for the double pole ``-b``,
    ``exp(-b T) [[1 + b T, T], [-b^2 T, 1 - b T]]``."""
    if len(A) == 1:
        return np.array([[math.exp(float(A[0, 0]) * T)]])
    b = -float(A[1, 1]) / 2.0
    return math.exp(-b * T) * np.array([[1.0 + b * T, T], [-b * b * T, 1.0 - b * T]])


def low_altitude(intensity: str, altitude: float) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """``(sigma, L)`` per axis (m/s, m) of the MIL-HDBK-1797 low-altitude model.

    MIL-HDBK-1797 §B.4.4.1 (its "2L" form of the Dryden spectra): ``L_u = 2 L_v = h / (0.177 +
    0.000823 h)^1.2`` and ``2 L_w = h`` (h in ft); both lateral and vertical scales are half of
    MIL-F-8785C §3.7.2.3's ``L_v = L_u``, ``L_w = h``, which go with its own form of the spectra.

    Parameters
    ----------
    intensity : {"light", "moderate", "severe"}
    altitude : float
        m above ground; the scales are taken at :data:`MIN_ALTITUDE_FT` at least.

    Examples
    --------
    >>> sigma, L = low_altitude("moderate", 30 * 0.3048)
    >>> round(sigma[2], 3), round(L[2] / 0.3048, 1)
    (1.543, 15.0)
    """
    h = max(altitude / FT, MIN_ALTITUDE_FT)
    sigma_w = 0.1 * W20[intensity]
    sigma_u = sigma_w / (0.177 + 0.000823 * h) ** 0.4
    L_u = h / (0.177 + 0.000823 * h) ** 1.2 * FT
    return (sigma_u, sigma_u, sigma_w), (L_u, L_u / 2.0, h / 2.0 * FT)


def reference_speed(trim_velocity_ned, steady_ned) -> float:
    """m/s: the trim's airspeed ``|V_ground - w_steady|``, at least :data:`MIN_REFERENCE_SPEED`."""
    air = np.asarray(trim_velocity_ned, dtype=float) - np.asarray(steady_ned, dtype=float)
    return max(float(np.linalg.norm(air)), MIN_REFERENCE_SPEED)


def mean_wind_heading(trim_velocity_ned, steady_ned) -> float:
    """rad from north of the horizontal wind relative to the vehicle at trim (``u`` of the turbulence);
    north when the relative wind is vertical or zero."""
    rel = np.asarray(steady_ned, dtype=float) - np.asarray(trim_velocity_ned, dtype=float)
    if math.hypot(rel[0], rel[1]) < 1e-12:
        return 0.0
    return math.atan2(rel[1], rel[0])


@dataclass(frozen=True)
class WindSpec:
    """The wind of a run.

    Attributes
    ----------
    steady : (3,) tuple of float
        m/s, NED.
    gusts : tuple of Gust
    turbulence : Turbulence or None
    """

    steady: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gusts: tuple[Gust, ...] = ()
    turbulence: Turbulence | None = None

    @property
    def active(self) -> bool:
        return bool(any(self.steady) or self.gusts or self.turbulence is not None)

    @property
    def seed(self) -> int | None:
        return self.turbulence.seed if self.turbulence is not None else None


class TurbulenceStream:
    """The turbulence samples of a :class:`Turbulence`, drawn in order as a run needs them.

    Sample ``i`` is the turbulence at ``t = i period`` (NED, m/s). Each axis draws from its own
    stream spawned from the seed: first its stationary start, then one normal vector per sample, so
    the numbers do not depend on how many samples a call asks for.
    """

    def __init__(self, turb: Turbulence):
        self.turb = turb
        self._rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(turb.seed).spawn(3)]
        self._steps = []
        self._state = []
        for (A, B, C), rng in zip(turb.filters(), self._rngs):
            P = _stationary(A, B)
            Ad = _transition(A, turb.period)
            Qd = P - Ad @ P @ Ad.T  # the process noise that keeps the sampled state stationary
            Qd = (Qd + Qd.T) / 2
            self._steps.append((Ad, np.linalg.cholesky(Qd), C.ravel()))
            self._state.append(np.linalg.cholesky(P) @ rng.standard_normal(len(A)))
        self._rotate = turb.to_ned()
        self._first = 0
        self._rows = np.zeros((0, 3))
        self._next = 0  # the sample the filter states are at

    def samples(self, first: int, last: int) -> np.ndarray:
        """(last - first + 1, 3) samples ``first .. last`` (NED, m/s); ``first`` never goes back
        before an earlier call's."""
        if first < self._first:
            raise ValueError(f"turbulence sample {first} was already dropped (stream at {self._first})")
        if last >= self._next:
            fresh = np.empty((last + 1 - self._next, 3))
            for axis, ((Ad, Lq, C), rng) in enumerate(zip(self._steps, self._rngs)):
                fresh[:, axis] = _filter(Ad, Lq, C, self._state, axis, rng, len(fresh))
            R = self._rotate  # elementwise, not a BLAS product: the same bits whatever the chunk's size
            ned = np.column_stack([R[i, 0] * fresh[:, 0] + R[i, 1] * fresh[:, 1] + R[i, 2] * fresh[:, 2]
                                   for i in range(3)])
            self._rows = np.vstack([self._rows, ned])
            self._next = last + 1
        self._rows = self._rows[first - self._first:]
        self._first = first
        return self._rows[:last + 1 - first]

    def at(self, t: np.ndarray) -> np.ndarray:
        """(n, 3) turbulence at increasing times ``t`` (s), linear between samples."""
        s = np.asarray(t, dtype=float) / self.turb.period
        i = np.floor(s + 1e-9).astype(np.int64)
        frac = np.clip(s - i, 0.0, 1.0)[:, None]
        rows = self.samples(int(i[0]), int(i[-1]) + 1)
        j = i - i[0]
        return rows[j] * (1.0 - frac) + rows[j + 1] * frac


def _filter(Ad, Lq, C, states, axis, rng, count) -> np.ndarray:
    """``count`` outputs of one axis's discrete filter from ``states[axis]`` (advanced in place)."""
    white = rng.standard_normal((count, len(Ad))).tolist()
    x = states[axis]
    out = np.empty(count)
    if len(Ad) == 1:
        a, c, q, xv = float(Ad[0, 0]), float(C[0]), float(Lq[0, 0]), float(x[0])
        for k in range(count):
            out[k] = c * xv
            xv = a * xv + q * white[k][0]
        states[axis] = np.array([xv])
        return out
    a00, a01, a10, a11 = (float(v) for v in Ad.ravel())
    q00, q10, q11 = float(Lq[0, 0]), float(Lq[1, 0]), float(Lq[1, 1])  # lower Cholesky factor of Qd
    c0, c1 = float(C[0]), float(C[1])
    x0, x1 = float(x[0]), float(x[1])
    for k in range(count):
        out[k] = c0 * x0 + c1 * x1
        n0, n1 = white[k]
        x0, x1 = a00 * x0 + a01 * x1 + q00 * n0, a10 * x0 + a11 * x1 + q10 * n0 + q11 * n1
    states[axis] = np.array([x0, x1])
    return out


class WindStream:
    """The wind of a :class:`WindSpec` at the samples of a clock of ``period`` seconds, in order.

    Sample ``j`` is ``w(j period)`` (NED, m/s): steady + gusts + turbulence. The samples depend on
    the spec and the period only (not on the RK4 step, nor on how a run asks for them).
    """

    def __init__(self, spec: WindSpec, period: float):
        self.spec, self.period = spec, float(period)
        self._turb = TurbulenceStream(spec.turbulence) if spec.turbulence is not None else None

    def samples(self, first: int, last: int) -> np.ndarray:
        """(last - first + 1, 3) m/s NED at ``t = j period``, ``j = first .. last``."""
        t = np.arange(first, last + 1, dtype=np.int64) * self.period
        return self.at(t)

    def at(self, t) -> np.ndarray:
        """(n, 3) m/s NED at increasing times ``t`` (s)."""
        t = np.asarray(t, dtype=float)
        out = np.broadcast_to(np.asarray(self.spec.steady, dtype=float), (len(t), 3)).copy()
        for gust in self.spec.gusts:
            out += gust.velocity(t)
        if self._turb is not None and len(t):
            out += self._turb.at(t)
        return out


def wind_of(wind_cfg, trim_velocity_ned, trim_altitude: float) -> WindSpec | None:
    """The :class:`WindSpec` of ``simulation.wind`` (None when absent or all zero).

    Parameters
    ----------
    wind_cfg : quadctl.config.WindConfig or None
    trim_velocity_ned : (3,) array_like
        m/s, the trim's ground velocity (for the turbulence's reference speed and axes).
    trim_altitude : float
        m, the default altitude of an intensity's scales.
    """
    if wind_cfg is None:
        return None
    steady = tuple(float(w) for w in wind_cfg.steady)
    gusts = tuple(Gust(start=g.start, length=g.length, amplitude=tuple(g.amplitude), hold=g.hold)
                  for g in wind_cfg.gusts)
    turb, tc = None, wind_cfg.turbulence
    if tc is not None:
        if tc.intensity is not None:
            sigma, length = low_altitude(tc.intensity, tc.altitude if tc.altitude is not None else trim_altitude)
        else:
            sigma, length = tuple(tc.sigma), tuple(tc.length_scale)
        speed = tc.airspeed if tc.airspeed is not None else reference_speed(trim_velocity_ned, steady)
        turb = Turbulence(sigma=tuple(float(s) for s in sigma), length=tuple(float(v) for v in length),
                          speed=float(speed), heading=mean_wind_heading(trim_velocity_ned, steady), seed=tc.seed)
    spec = WindSpec(steady=steady, gusts=gusts, turbulence=turb)
    return spec if spec.active else None
