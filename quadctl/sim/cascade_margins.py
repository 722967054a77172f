"""Margins of a PID cascade's loops, broken at each plant input with the whole cascade closed around it.

Every margin is exact, read from the cascade lifted to its frame (:mod:`quadctl.sim.cascade_lift`, where
it is time-invariant): stability, poles and the gain margins from the lifted loop's poles
(:func:`exact_gain_margins`); the phase and disk margins from its characteristic loci, the eigenvalues of
the frame's transfer matrix (:func:`loci_margins`: a constant gain on the input is that gain on every
sample, so it commutes with the lifted loop); the delay margin the least extra delay of the held input
that makes the lifted loop unstable (:func:`exact_delay_margin`). The method and its references are in
the docs, docs/internals.md ("Margins of a PID cascade").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.design.margin_search import POINTS_PER_DECADE
from quadctl.design.margins import LoopMargins, disk_gain_range_db, gain_db, no_margin
from quadctl.layout import INPUT_NAMES
from quadctl.linear.stability import is_stable
from quadctl.sim.cascade_lift import LOCI_INFINITE, Lifted, LiftedLoop, lifted

scipy = lazy_import("scipy")

GAIN_SCAN = np.logspace(-3, 3, 241)
"""Loop-gain factors scanned outward from 1 for the exact gain margins (0.001 to 1000, 40 per decade: a band
of instability narrower than 6 % in gain between two stable ones would be missed), then bisected."""
FREQUENCY_AGREEMENT_DB = 1e-3
"""dB: a gain margin's frequency is that of the loci's crossing of the real axis when the gain read there is
within this of :func:`exact_gain_margins` (whose bisection stops where a pole is within the stability test's
1e-9 of the unit circle: for a slow pole near ``z = 1``, ~1e-5 dB from the crossing); otherwise none is given."""
LOCI_POINTS_PER_DECADE = 20
"""Frame frequencies ``theta`` per decade at which the characteristic loci are computed before each crossing
is refined by root finding and each least value by minimization: two crossings closer than a step apart (a
locus grazing ``|lam| = 1`` or the real axis) could be missed."""
DELAY_SCAN = (1 / 16) * 1.1 ** np.arange(90)
"""Delays in base samples scanned for the exact delay margin (1/16 to ~300 samples, 10 % apart), then refined
to the edge: a band of instability narrower than 10 % in delay between two stable ones would be missed."""


def exact_gain_margins(loop: LiftedLoop) -> tuple[float, float]:
    """(lower, upper) dB: the constant gains nearest 1, below and above, at which the lifted loop loses
    stability (``-inf`` / ``+inf``: none within :data:`GAIN_SCAN`). The loop is stable at gain 1."""

    def edge(a, b):  # a stable, b not
        for _ in range(45):  # the bracket's ratio to its 2^-45th power: ~1e-13 dB for a decade
            m = math.sqrt(a * b)
            a, b = (m, b) if loop.is_stable(m) else (a, m)
        return math.sqrt(a * b)

    upper = lower = None
    above = GAIN_SCAN[GAIN_SCAN > 1]
    prev = 1.0
    for g in above:
        if not loop.is_stable(g):
            upper = edge(prev, g)
            break
        prev = g
    prev = 1.0
    for g in GAIN_SCAN[GAIN_SCAN < 1][::-1]:
        if not loop.is_stable(g):
            lower = edge(prev, g)
            break
        prev = g
    return (gain_db(lower) if lower else -math.inf, gain_db(upper) if upper else math.inf)


@dataclass(frozen=True)
class LociMargins:
    """Margins from the characteristic loci of a lifted loop (:func:`loci_margins`); frequencies in rad/s of
    the base rate (:func:`base_frequency`), None where there is no such point."""

    gain_margin_db: tuple[float, float]
    phase_crossover_freqs: tuple[float | None, float | None]
    phase_margin_deg: float
    gain_crossover_freq: float | None
    disk_alpha: float
    disk_freq: float | None
    min_return_difference: float


def loci_margins(loop: LiftedLoop, points_per_decade: int = LOCI_POINTS_PER_DECADE) -> LociMargins:
    """Gain, phase and disk margins of a lifted loop from its characteristic loci (module docstring).

    A constant gain ``g`` (complex: gain and phase) on the broken input is ``g I`` on the frame's samples and
    commutes with the loop: the loop closed through it has a pole on the unit circle exactly where
    ``-1/g`` is an eigenvalue ``lam`` of ``L(e^(j theta))``
    (:meth:`~quadctl.sim.cascade_lift.LiftedLoop.lifted_response`'s sign), so the
    destabilizing gains on the circle are ``g = -1/lam``, ``theta`` in ``[0, pi]`` (the loci over
    ``(pi, 2 pi)`` are the conjugates). Crossings of ``|lam| = 1`` and of the real axis are found on a log
    grid of ``theta`` and refined by root finding; the disk margin's minimum by bounded minimization.

    Parameters
    ----------
    loop : LiftedLoop
        A loop stable at gain 1.
    points_per_decade : int
        Grid density in ``theta`` before refinement.

    Returns
    -------
    LociMargins
        Gain margins nearest 1 (dB), the smallest ``|arg g|`` with ``|g| = 1`` (deg; ``inf``: none), the
        smallest balanced disk ``alpha`` (:func:`quadctl.design.margins.disk_gain_range_db`) and
        ``min |1 + lam|``.
    """

    theta = loop.frame_grid(points_per_decade)
    lam = loop.loci(theta)
    if not np.all(np.isfinite(lam[0])):  # z = 1 a pole the pencil cannot separate (a singular pencil): left out
        theta, lam = theta[1:], lam[1:]

    def eig(t):
        return loop.loci(t, vectors=True)

    def mag(lams):  # changes sign where one |lam| crosses 1: symmetric in the eigenvalues, so no tracking
        with np.errstate(divide="ignore"):
            return np.prod(np.where(lams == 0, -1.0, np.log(np.abs(lams))), axis=-1)

    def imag(lams):  # changes sign where one lam crosses the real axis (those taken as 0 or infinite aside)
        return np.prod(np.where((lams == 0) | (np.abs(lams) >= LOCI_INFINITE), 1.0, lams.imag), axis=-1)

    def refine(fn, k):  # None: the sign change was rounding (the ends, computed alone, agree)
        a, b = theta[k], theta[k + 1]
        f = lambda t: float(fn(loop.loci(t)[0]))  # noqa: E731
        if (f(a) > 0) == (f(b) > 0):
            return None
        return float(scipy.optimize.brentq(f, a, b, xtol=1e-14, rtol=1e-14, maxiter=200))

    pm, w_pm = math.inf, None
    for t in (t for t in (refine(mag, k) for k in _sign_changes(mag(lam))) if t is not None):
        vals, vecs = eig(t)
        with np.errstate(divide="ignore"):
            i = int(np.argmin(np.abs(np.log(np.abs(vals)))))
        phase = math.degrees(abs(float(np.angle(-1.0 / vals[i]))))
        if phase < pm:
            pm, w_pm = phase, base_frequency(loop, t, vecs[:, i])
    gains = []  # (critical gain, rad/s): -1/λ real and positive, λ an eigenvalue of L (its loci)
    for t in (t for t in (refine(imag, k) for k in _sign_changes(imag(lam))) if t is not None):
        L_eig, vecs = eig(t)
        with np.errstate(divide="ignore", invalid="ignore"):
            i = int(np.nanargmin(np.abs(L_eig.imag) / np.abs(L_eig)))
        if L_eig[i].real < 0 and abs(L_eig[i].imag) <= 1e-9 * abs(L_eig[i]):
            gains.append((-1.0 / L_eig[i].real, base_frequency(loop, t, vecs[:, i])))
    for end in {theta[0], theta[-1]} & {0.0, math.pi}:  # z = 1, -1: L is real, its real eigenvalues real gains
        L_eig, vecs = eig(end)
        for i in np.nonzero((np.abs(L_eig.imag) <= 1e-12 * np.abs(L_eig)) & (L_eig.real < 0)
                            & (np.abs(L_eig) < LOCI_INFINITE))[0]:
            gains.append((-1.0 / L_eig[i].real, base_frequency(loop, end, vecs[:, i])))
    above = min((g for g in gains if g[0] > 1), default=None)
    below = max((g for g in gains if g[0] < 1), default=None)

    def disk(lams):  # the balanced disk through -1/lam: alpha = 2 |1 + lam| / |1 - lam|
        with np.errstate(divide="ignore"):
            return np.min(2 * np.abs(1 + lams) / np.abs(1 - lams), axis=-1)

    alpha, t_disk = _least(disk, lam, theta, loop.loci)
    rd, _ = _least(lambda lams: np.min(np.abs(1 + lams), axis=-1), lam, theta, loop.loci)
    vals, vecs = eig(t_disk)
    i = int(np.argmin(disk(vals[:, None])))
    return LociMargins(
        gain_margin_db=(gain_db(below[0]) if below else -math.inf, gain_db(above[0]) if above else math.inf),
        phase_crossover_freqs=(below[1] if below else None, above[1] if above else None),
        phase_margin_deg=pm, gain_crossover_freq=w_pm, disk_alpha=alpha,
        disk_freq=base_frequency(loop, t_disk, vecs[:, i]), min_return_difference=rd)


def _sign_changes(v) -> np.ndarray:
    pos = v > 0
    return np.nonzero(pos[:-1] != pos[1:])[0]


def _least(fn, lam, theta, loci, near: float = 1.1, candidates: int = 3) -> tuple[float, float]:
    """``(min, theta)`` of ``fn`` of the loci: the grid's least few local minima within ``near`` times its least,
    each refined by bounded minimization between its neighbours (two nearly equal minima both)."""
    vals = fn(lam)
    n = len(theta)
    local = [k for k in range(n) if vals[k] <= vals[max(k - 1, 0)] and vals[k] <= vals[min(k + 1, n - 1)]
             and vals[k] <= near * vals.min()]
    best = (float("inf"), float(theta[0]))
    for k in sorted(local, key=lambda k: vals[k])[:candidates]:
        best = min(best, (float(vals[k]), float(theta[k])))
        lo, hi = theta[max(k - 1, 0)], theta[min(k + 1, n - 1)]
        res = scipy.optimize.minimize_scalar(lambda t: float(fn(loci(t)[0])), bounds=(lo, hi), method="bounded",
                                             options={"xatol": 1e-10 * hi})
        best = min(best, (float(res.fun), float(res.x)))
    return best


def base_frequency(loop: LiftedLoop, theta: float, v) -> float:
    """rad/s at the base rate of the input ``v`` (``N`` samples of one frame, repeated times ``e^(j theta)``
    each frame): the input is a sum of the ``N`` sinusoids ``e^(j w_k k Ts)``, ``w_k = (theta + 2 pi k) / (N Ts)``,
    that the base rate tells apart; the one of largest amplitude, folded into ``[0, pi / Ts]``. For ``N = 1``
    it is ``theta / Ts``."""
    N, Ts = loop.frame, loop.sample_time
    k = np.arange(N)
    F = np.exp(1j * np.outer(k, theta + 2 * math.pi * k) / N)  # F[p, k] = e^(j w_k p Ts)
    c = np.linalg.solve(F, np.asarray(v, dtype=complex))
    w = (theta + 2 * math.pi * int(np.argmax(np.abs(c)))) / N
    return abs(math.remainder(w, 2 * math.pi)) / Ts


def exact_delay_margin(lift: Lifted, j: int) -> float | None:
    """s: the least extra delay of input ``j``'s held command
    (:meth:`~quadctl.sim.cascade_lift.Lifted.delayed_frame_map`) that puts a pole of the lifted loop on the unit
    circle, scanned over :data:`DELAY_SCAN` then bisected (None: none within the scan, or no continuous plant).
    The loop is stable without it."""
    if lift.plant_rates is None:
        return None
    Ts = lift.sample_time

    def stable(tau):
        return bool(np.all(is_stable(np.linalg.eigvals(lift.delayed_frame_map(j, tau)), discrete=True)))

    def radius(tau):
        return float(np.max(np.abs(np.linalg.eigvals(lift.delayed_frame_map(j, tau))))) - 1.0

    prev = 0.0
    for tau in DELAY_SCAN * Ts:
        if not stable(tau):
            # the spectral radius is continuous in the delay: its crossing of 1 in the bracket is the edge
            return float(scipy.optimize.brentq(radius, prev, float(tau), xtol=1e-13 * tau, rtol=1e-13))
        prev = float(tau)
    return None


def cascade_margins(loop, *, title: str = "PID", lift: Lifted | None = None) -> list:
    """Margins of every input's loop of a PID cascade, broken at the plant input (``model = "cascade"``).

    Parameters
    ----------
    loop : quadctl.sim.loop.ClosedLoop
        A loop flying a PID cascade (:func:`quadctl.pipeline.pid_loop_of`).
    title : str
        The law's name, for the loop's label.
    lift : quadctl.sim.cascade_lift.Lifted, optional
        :func:`~quadctl.sim.cascade_lift.lifted` ``loop``, when already computed.

    Returns
    -------
    list of quadctl.design.margins.LoopMargins
        One per input ``T, A, E, R``, every margin exact: the gain margins from the lifted loop's poles
        (:func:`exact_gain_margins`; their frequencies the loci's where they agree, :data:`FREQUENCY_AGREEMENT_DB`),
        phase and disk margins from its characteristic loci (:func:`loci_margins`), the delay margin the least
        extra delay of the held input (:func:`exact_delay_margin`); ``freq`` and ``response`` the fundamental
        harmonic (:class:`~quadctl.sim.cascade_lift.LiftedLoop`, for the plots). A delay (``loop.delay_samples``,
        the cascade's samples) is in every loop, before the break: the margins are beyond it, as the LQR loops' are.
    """
    from threadpoolctl import threadpool_limits

    lift = lifted(loop) if lift is None else lift
    # hundreds of small eigenproblems (36 to 100 wide): BLAS threads only contend (quadctl.threads says why)
    with threadpool_limits(limits=1):
        return [_input_margins(loop, lift, j, inp, title) for j, inp in enumerate(INPUT_NAMES)]


def _input_margins(loop, lift: Lifted, j: int, inp: str, title: str):

    broken = lift.broken(j)
    w = broken.grid(POINTS_PER_DECADE)
    labels = dict(loop=title, input=inp, model="cascade", sample_time=broken.sample_time, freq=w,
                  response=broken(w), delay_samples=loop.delay_samples)
    loci = loci_margins(broken)
    if not broken.is_stable():
        return no_margin(min_return_difference=loci.min_return_difference, **labels)
    exact = exact_gain_margins(broken)
    # the loci's crossing of the real axis names the frequency where it gives the exact margin
    freqs = tuple(w if w is not None and abs(a - b) <= FREQUENCY_AGREEMENT_DB else None
                  for w, a, b in zip(loci.phase_crossover_freqs, exact, loci.gain_margin_db))
    return LoopMargins(
        stable=True, gain_margin_db=exact, phase_crossover_freqs=freqs, phase_margin_deg=loci.phase_margin_deg,
        gain_crossover_freq=loci.gain_crossover_freq, disk_alpha=loci.disk_alpha,
        disk_gain_db=disk_gain_range_db(loci.disk_alpha),
        disk_phase_deg=math.degrees(2 * math.atan(loci.disk_alpha / 2)), disk_freq=loci.disk_freq,
        min_return_difference=loci.min_return_difference, delay_margin=exact_delay_margin(lift, j), **labels)
