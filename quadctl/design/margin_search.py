"""The margins of a broken loop, found on its frequency response.

:func:`loop_margins` scans ``L`` on a log-spaced grid (:func:`frequency_grid`), refines every phase and gain
crossover by root finding and the disk margin's peak by bounded minimization, and reads the gain, phase,
delay and disk margins from them (MATLAB ``allmargin``/``diskmargin`` conventions); an unstable loop has none
(:func:`quadctl.design.margins.no_margin`).
"""

from __future__ import annotations

import math

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.design.broken_loops import BrokenLoop
from quadctl.design.margins import LoopMargins, disk_gain_range_db, gain_db, no_margin

scipy = lazy_import("scipy")  # loaded on first use (then scipy.linalg on access): quadctl._lazy

POINTS_PER_DECADE = 200
"""Frequency grid density before crossings are refined by root finding (rad/s, log spaced)."""
GRID_SPAN = 100.0
"""The grid reaches from the slowest nonzero loop eigenvalue / 100 to the fastest x 100."""


def loop_margins(loop: BrokenLoop, *, name: str = "loop", input_name: str = "u", model: str = "design",
                 grid: np.ndarray | None = None) -> LoopMargins:
    """Gain, phase and disk margins of a broken loop.

    Parameters
    ----------
    loop : BrokenLoop
    name, input_name, model : str
        Labels.
    grid : (n,) array_like, optional
        Frequencies (rad/s) to scan; default from the loop's eigenvalues (:func:`frequency_grid`).

    Returns
    -------
    LoopMargins
        ``findings`` empty (see :func:`quadctl.design.margin_findings.findings`).

    Examples
    --------
    An integrator with a first-order lag, ``L = sqrt(2) / (s (s + 1))``, crosses ``|L| = 1`` at
    ``w = 1`` with phase ``-90 - 45`` deg: phase margin 45 deg; its phase never reaches -180 deg,
    so the gain margin is infinite.

    >>> A = np.array([[0.0, 1.0], [0.0, -1.0]]); b = np.array([0.0, 1.0]); k = np.array([2 ** 0.5, 0.0])
    >>> m = loop_margins(BrokenLoop(A, b, k))
    >>> round(m.phase_margin_deg, 6), round(m.gain_crossover_freq, 6), m.gain_margin_db
    (45.0, 1.0, (-inf, inf))

    The same loop with positive feedback is unstable: it has no margin at all.

    >>> bad = loop_margins(BrokenLoop(A, b, -k))
    >>> bad.stable, bad.gain_margin_db, bad.phase_margin_deg, bad.disk_alpha, bad.delay_margin
    (False, (None, None), None, None, None)
    """
    w = frequency_grid(loop) if grid is None else np.asarray(grid, dtype=float)
    Lw = loop(w)
    rd = float(np.min(np.abs(1 + Lw)))
    rd = min(rd, _refine_min(lambda x: float(np.abs(1 + loop(x))[0]), w, np.abs(1 + Lw)))
    labels = dict(loop=name, input=input_name, model=model, sample_time=loop.sample_time,
                  min_return_difference=rd, freq=w, response=Lw)
    if not loop.is_stable():
        return no_margin(**labels)
    lower, upper, w_lower, w_upper = _gain_margins(loop, w, Lw)
    pm, w_pm = _phase_margin(loop, w, Lw)
    dm = _delay_margin(loop, w, Lw)
    alpha, w_disk = _disk_margin(loop, w)
    return LoopMargins(
        stable=True, gain_margin_db=(lower, upper), phase_crossover_freqs=(w_lower, w_upper),
        phase_margin_deg=pm, gain_crossover_freq=w_pm, disk_alpha=alpha,
        disk_gain_db=disk_gain_range_db(alpha), disk_phase_deg=math.degrees(2 * math.atan(alpha / 2)),
        disk_freq=w_disk, delay_margin=dm, **labels)


def frequency_grid(loop: BrokenLoop) -> np.ndarray:
    """Log-spaced rad/s covering the loop's dynamics (``GRID_SPAN`` beyond its eigenvalues).

    A sampled loop's grid ends exactly at the Nyquist frequency ``pi / Ts``.
    """
    eig = np.concatenate([np.linalg.eigvals(loop.A), loop.closed_loop_eigenvalues()])
    if loop.sample_time:
        with np.errstate(divide="ignore", invalid="ignore"):  # a delay's shift states sit at z = 0
            eig = np.log(eig.astype(complex)) / loop.sample_time
    mags = np.abs(eig[np.isfinite(eig)])
    mags = mags[mags > 1e-9]
    lo = (mags.min() if mags.size else 1.0) / GRID_SPAN
    hi = (mags.max() if mags.size else 1.0) * GRID_SPAN
    if loop.sample_time:
        hi = math.pi / loop.sample_time
        lo = min(lo, hi / 1e3)
    decades = max(math.log10(hi / lo), 1.0)
    w = np.logspace(math.log10(lo), math.log10(hi), int(decades * POINTS_PER_DECADE) + 1)
    if loop.sample_time:
        w[-1] = math.pi / loop.sample_time
    return w


def _gain_margins(loop, w, Lw):
    """(lower dB, upper dB, lower freq, upper freq) from the phase crossovers."""
    crossings = []  # (frequency, critical gain)
    im = Lw.imag
    for i in np.nonzero(np.sign(im[:-1]) * np.sign(im[1:]) < 0)[0]:
        wc = _root(lambda x: float(loop(x)[0].imag), w[i], w[i + 1])
        Lc = loop(wc)[0]
        if Lc.real < 0:
            crossings.append((wc, -1.0 / Lc.real))
    if loop.sample_time and abs(Lw[-1].imag) <= 1e-12 * max(1.0, abs(Lw[-1])) and Lw[-1].real < 0:
        crossings.append((float(w[-1]), -1.0 / Lw[-1].real))  # L is real at the Nyquist frequency
    L0 = _dc_gain(loop)
    if L0 is not None and L0 < 0:  # L is real at w = 0 too (finite where the open loop has no pole there)
        crossings.append((0.0, -1.0 / L0))
    above = [(g, wc) for wc, g in crossings if g > 1]
    below = [(g, wc) for wc, g in crossings if g < 1]
    upper = min(above) if above else None
    lower = max(below) if below else None
    return (gain_db(lower[0]) if lower else -math.inf, gain_db(upper[0]) if upper else math.inf,
            lower[1] if lower else None, upper[1] if upper else None)


def _dc_gain(loop) -> float | None:
    """``L`` at ``w = 0`` (real), or None where the open loop has a pole there (``s = 0``, ``z = 1``: an
    integrator, within the 1e-9 rad/s :func:`frequency_grid` takes as zero), which makes it infinite; the
    grid's crossings near zero frequency then stand for it. Of a :class:`BrokenLoop` (a loop of another form,
    the cascade's lifted one, keeps the grid's crossings)."""
    if not isinstance(loop, BrokenLoop):
        return None
    eig = np.linalg.eigvals(loop.A)
    if loop.sample_time:
        with np.errstate(divide="ignore", invalid="ignore"):  # a delay's shift states sit at z = 0
            eig = np.log(eig.astype(complex)) / loop.sample_time
    if np.any(np.abs(eig) <= 1e-9):
        return None
    n = loop.A.shape[0]
    at_dc = (np.eye(n) if loop.sample_time else np.zeros((n, n))) - loop.A  # s I - A at s = 0, z I - A at z = 1
    value = float(loop.k @ np.linalg.solve(at_dc, loop.b))
    return value if math.isfinite(value) else None


def _phase_margin(loop, w, Lw):
    mag = np.log(np.abs(Lw))
    best = None
    for i in _crossings(mag):
        wc = _root(lambda x: float(np.log(np.abs(loop(x)[0]))), w[i], w[i + 1])
        pm = math.degrees(math.remainder(float(np.angle(loop(wc)[0])) + math.pi, 2 * math.pi))
        if best is None or pm < best[0]:
            best = (pm, wc)
    return (best[0], best[1]) if best else (math.inf, None)


def _crossings(v) -> np.ndarray:
    """Indices ``i`` where ``v`` changes sign from ``v[i]`` to ``v[i + 1]``, a zero landing exactly on a
    grid point included (counted once, in the interval that ends on it)."""
    pos = v > 0
    return np.nonzero(pos[:-1] != pos[1:])[0]


def _delay_margin(loop, w, Lw) -> float | None:
    """s: ``min_i PM_i / w_i`` over every gain crossover (``PM_i`` in ``[0, 2 pi)`` rad)."""
    mag = np.log(np.abs(Lw))
    best = None
    for i in _crossings(mag):
        wc = _root(lambda x: float(np.log(np.abs(loop(x)[0]))), w[i], w[i + 1])
        pm = (float(np.angle(loop(wc)[0])) + math.pi) % (2 * math.pi)
        if best is None or pm / wc < best:
            best = pm / wc
    return best


def _disk_margin(loop, w):
    """Balanced disk margin: ``1 / max |S - 1/2|`` and where it is reached."""
    def peak(x):
        L = loop(x)
        return np.abs(1 / (1 + L) - 0.5)

    vals = peak(w)
    i = int(np.argmax(vals))
    best = float(vals[i])
    lo, hi = w[max(i - 1, 0)], w[min(i + 1, len(w) - 1)]
    if hi > lo:
        res = scipy.optimize.minimize_scalar(lambda lx: -float(peak(math.exp(lx))[0]),
                                             bounds=(math.log(lo), math.log(hi)), method="bounded",
                                             options={"xatol": 1e-10})
        if -res.fun > best:
            best, wbest = float(-res.fun), float(math.exp(res.x))
        else:
            wbest = float(w[i])
    else:
        wbest = float(w[i])
    return 1.0 / best, wbest


def _refine_min(fn, w, vals) -> float:
    i = int(np.argmin(vals))
    lo, hi = w[max(i - 1, 0)], w[min(i + 1, len(w) - 1)]
    if hi <= lo:
        return float(vals[i])
    res = scipy.optimize.minimize_scalar(lambda lx: fn(math.exp(lx)), bounds=(math.log(lo), math.log(hi)),
                                         method="bounded", options={"xatol": 1e-10})
    return float(min(res.fun, vals[i]))


def _root(fn, a, b) -> float:
    return float(scipy.optimize.brentq(fn, a, b, xtol=1e-14 * max(abs(a), 1.0), rtol=1e-14, maxiter=200))
