"""Stability margins of each regulated loop, broken at the plant input.

Gain, phase, disk and delay margins and the return difference of each loop (MATLAB
``allmargin``/``diskmargin`` conventions), continuous or sampled, with the delay, the rotors' lag and
the gyro filter in the loop; the loops through a Kalman filter (:func:`lqg_loops`); an unstable loop
has no margin (:func:`no_margin`). What each margin means and how the loops are broken is in the
docs, docs/internals.md ("Stability margins"). What the margins say (the findings), and every loop of
a design computed and judged, is :mod:`quadctl.design.margin_findings`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.design import linear_loop, lqg_loop
from quadctl.layout import INPUT_INDEX, STATE_INDEX
from quadctl.linear.stability import free_positions, is_stable

scipy = lazy_import("scipy")  # loaded on first use (then scipy.linalg on access): quadctl._lazy

LQR_GAIN_MARGIN_DB = (20 * math.log10(0.5), math.inf)
"""Guaranteed gain margin of continuous LQR: from -6.02 dB to infinity."""
LQR_PHASE_MARGIN_DEG = 60.0
"""Guaranteed phase margin of continuous LQR (single input, ``R`` diagonal)."""
THIN_GAIN_MARGIN_DB = 6.0
"""dB: a loop whose gain can rise (or fall) by less than this before it goes unstable has a thin gain margin.
The classical requirement on flight control loops: MIL-F-9490D ("Flight Control Systems - Design,
Installation and Test of Piloted Aircraft, General Specification for", 1975) asks 6 dB of gain margin
and 45 deg of phase margin."""
THIN_PHASE_MARGIN_DEG = 30.0
"""deg: a loop with less phase margin than this has a thin phase margin: a lower bar than MIL-F-9490D's
45 deg, the least a flight stack's rate loop is commonly tuned to; a loop between the two is not flagged."""
GUARANTEE_TOL = 1e-6
"""Relative slack when comparing with the guarantee (the guarantee is met with equality at high
frequency for a loop whose ``|1 + L|`` tends to 1)."""
POINTS_PER_DECADE = 200
"""Frequency grid density before crossings are refined by root finding (rad/s, log spaced)."""
GRID_SPAN = 100.0
"""The grid reaches from the slowest nonzero loop eigenvalue / 100 to the fastest x 100."""


@dataclass(frozen=True, eq=False)
class LoopMargins:
    """Margins of one loop broken at one input.

    Attributes
    ----------
    loop : str
        Subsystem name.
    input : str
        The input the loop is broken at.
    model : str
        ``design`` (the subsystem the LQR was designed on) or ``coupled`` (the 12-state linear
        model with the other loops closed).
    sample_time : float or None
        s for a sampled loop (``L(z)``), None for continuous.
    stable : bool
        The closed loop (``g = 1``) is stable. When it is not, it has no margin: every margin below
        and every frequency is None (:func:`no_margin`).
    gain_margin_db : (float, float) or (None, None)
        (lower, upper) in dB; ``-inf`` / ``+inf`` when there is no critical gain on that side.
    phase_crossover_freqs : (float or None, float or None)
        rad/s of the phase crossovers that set them (None: no such crossover).
    phase_margin_deg : float or None
        ``inf`` when ``|L|`` never crosses 1.
    gain_crossover_freq : float or None
        rad/s of the gain crossover (``|L| = 1``) that sets it.
    disk_alpha : float or None
        Balanced disk margin ``alpha``.
    disk_gain_db : (float, float) or (None, None)
        The disk's gain range in dB.
    disk_phase_deg : float or None
    disk_freq : float or None
        rad/s where the disk margin is smallest.
    min_return_difference : float
        ``min |1 + L|`` on the grid: a property of the curve, reported for any loop (an unstable
        loop's curve may stay far from -1; it still has no margin).
    freq : (n,) ndarray
        The frequency grid (rad/s).
    response : (n,) complex ndarray
        ``L`` on it (for Bode and Nyquist plots).
    findings : tuple of quadctl.design.margin_findings.Finding
        Comparison with the LQR guarantee, the causes of any shortfall, the gyro filter's lag and the
        saturation the disk margin covers, as values (:class:`quadctl.design.margin_findings.Finding`;
        their sentences: :func:`quadctl.present.loops.note`).
    delay_margin : float or None
        s of extra delay before instability (None: ``|L|`` never crosses 1, or unstable).
    delay_samples : int
        Samples of configured delay included in the loop.

    Examples
    --------
    >>> import quadctl as qc
    >>> stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    >>> roll = qc.margins(stages.design, stages.decoupled, stages.linear.A, stages.linear.B)[1]
    >>> roll.loop, roll.input, roll.gain_margin_db, roll.phase_margin_deg > 60
    ('roll', 'A', (-inf, inf), True)
    """

    loop: str
    input: str
    model: str
    sample_time: float | None
    stable: bool
    gain_margin_db: tuple[float, float] | tuple[None, None]
    phase_crossover_freqs: tuple[float | None, float | None]
    phase_margin_deg: float | None
    gain_crossover_freq: float | None
    disk_alpha: float | None
    disk_gain_db: tuple[float, float] | tuple[None, None]
    disk_phase_deg: float | None
    disk_freq: float | None
    min_return_difference: float
    freq: np.ndarray = field(repr=False)
    response: np.ndarray = field(repr=False)
    findings: tuple = ()  # of quadctl.design.margin_findings.Finding, which imports this module
    delay_margin: float | None = None
    delay_samples: int = 0

    @property
    def delay_margin_samples(self) -> float | None:
        """The delay margin in controller samples (sampled loops)."""
        if self.delay_margin is None or not self.sample_time:
            return None
        return self.delay_margin / self.sample_time

    @property
    def meets_lqr_guarantee(self) -> bool:
        """Gain margin within [-6 dB, inf) and phase margin >= 60 deg (and stable)."""
        if not self.stable:
            return False
        lower, upper = self.gain_margin_db
        gm_ok = lower <= LQR_GAIN_MARGIN_DB[0] * (1 - GUARANTEE_TOL) and upper == math.inf
        pm_ok = self.phase_margin_deg >= LQR_PHASE_MARGIN_DEG * (1 - GUARANTEE_TOL)
        return gm_ok and pm_ok

    @property
    def thin(self) -> tuple[str, ...]:
        """Which margins of a stable loop are below the classical requirement: ``"gain"`` (a gain change
        of less than :data:`THIN_GAIN_MARGIN_DB` either way), ``"phase"`` (less than
        :data:`THIN_PHASE_MARGIN_DEG`). An unstable loop has none to speak of (it fails as unstable)."""
        if not self.stable:
            return ()
        lower, upper = self.gain_margin_db
        out = []
        if upper < THIN_GAIN_MARGIN_DB or lower > -THIN_GAIN_MARGIN_DB:
            out.append("gain")
        if self.phase_margin_deg < THIN_PHASE_MARGIN_DEG:
            out.append("phase")
        return tuple(out)

    def as_dict(self) -> dict:
        """JSON-ready summary (the curves left out); infinite margins stay ``inf`` floats (the
        artifact writer spells them ``"inf"``), a frequency that does not apply is None, and so is every
        margin of an unstable loop (``stable`` False beside them)."""
        return {
            "loop": self.loop, "input": self.input, "model": self.model, "sample_time": self.sample_time,
            "stable": self.stable,
            "gain_margin_lower_db": self.gain_margin_db[0], "gain_margin_upper_db": self.gain_margin_db[1],
            "gain_margin_lower_freq": self.phase_crossover_freqs[0],
            "gain_margin_upper_freq": self.phase_crossover_freqs[1],
            "phase_margin_deg": self.phase_margin_deg, "gain_crossover_freq": self.gain_crossover_freq,
            "disk_margin_alpha": self.disk_alpha, "disk_gain_margin_db": list(self.disk_gain_db),
            "disk_phase_margin_deg": self.disk_phase_deg, "disk_margin_freq": self.disk_freq,
            "min_return_difference": self.min_return_difference,
            "delay_samples": self.delay_samples,
            "delay_margin": {"s": self.delay_margin, "samples": self.delay_margin_samples},
            "meets_lqr_guarantee": self.meets_lqr_guarantee, "thin": list(self.thin),
            "findings": [f.as_dict() for f in self.findings],
        }


def least_margins(margins) -> tuple[float, float] | tuple[None, None]:
    """``(gain dB, phase deg)``: the least gain change, up or down, that destabilizes one of ``margins``'
    loops, and their least phase margin (what the sweep's margin columns and ``quadctl compare`` show);
    ``(None, None)`` when one of the loops is unstable (it has no margin, :func:`no_margin`).

    Examples
    --------
    >>> from types import SimpleNamespace as M
    >>> least_margins([M(stable=True, gain_margin_db=(-8.0, 12.0), phase_margin_deg=40.0),
    ...                M(stable=True, gain_margin_db=(-float("inf"), 7.0), phase_margin_deg=65.0)])
    (7.0, 40.0)
    >>> least_margins([M(stable=True, gain_margin_db=(-8.0, 12.0), phase_margin_deg=40.0),
    ...                M(stable=False, gain_margin_db=(None, None), phase_margin_deg=None)])
    (None, None)
    """
    if not all(m.stable for m in margins):
        return None, None
    return (float(min(min(-m.gain_margin_db[0], m.gain_margin_db[1]) for m in margins)),
            float(min(m.phase_margin_deg for m in margins)))


def thin_loops(margins) -> list[LoopMargins]:
    """The stable loops with a gain or phase margin below the classical requirement (:attr:`LoopMargins.thin`)."""
    return [m for m in margins if m.thin]


# ---------------------------------------------------------------------------------------
# The loop transfer function


@dataclass(frozen=True, eq=False)
class BrokenLoop:
    """``L = k (sI - A)^-1 b`` (or in ``z`` with ``sample_time``): a loop broken at one input."""

    A: np.ndarray
    b: np.ndarray
    k: np.ndarray
    sample_time: float | None = None

    def __call__(self, w) -> np.ndarray:
        """``L`` at frequencies ``w`` (rad/s), complex, same shape as ``w``."""
        w = np.atleast_1d(np.asarray(w, dtype=float))
        s = np.exp(1j * w * self.sample_time) if self.sample_time else 1j * w
        n = self.A.shape[0]
        M = s[:, None, None] * np.eye(n) - self.A[None, :, :]
        x = np.linalg.solve(M, np.broadcast_to(self.b, (len(w), n))[..., None])[..., 0]
        return x @ self.k

    def closed_loop_eigenvalues(self, gain: float = 1.0) -> np.ndarray:
        return np.linalg.eigvals(linear_loop.close(self.A, self.b[:, None], gain * self.k[None, :]))

    def is_stable(self, gain: float = 1.0) -> bool:
        return bool(np.all(is_stable(self.closed_loop_eigenvalues(gain), discrete=bool(self.sample_time))))


def broken_loop(A, B, K, j: int, sample_time: float | None = None) -> BrokenLoop:
    """The loop of ``u = -K x`` broken at input ``j``, the other inputs' loops closed.

    Parameters
    ----------
    A : (n, n) array_like
        Plant (discrete ``Ad`` with ``sample_time``).
    B : (n, m) array_like
    K : (m, n) array_like
    j : int
        Input to break at.
    sample_time : float, optional
        s; given, ``A`` and ``B`` are the ZOH plant.
    """
    A, B, K = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (A, B, K))
    return BrokenLoop(A=linear_loop.broken(A, B, K, j), b=B[:, j].copy(), k=K[j, :].copy(), sample_time=sample_time)


# ---------------------------------------------------------------------------------------
# Margins


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


def disk_gain_range_db(alpha: float) -> tuple[float, float]:
    """The balanced disk's gain range ``[(2 - a)/(2 + a), (2 + a)/(2 - a)]`` in dB (``a >= 2``: up
    to ``+inf``)."""
    g_lo = (2 - alpha) / (2 + alpha)
    g_hi = (2 + alpha) / (2 - alpha) if alpha < 2 else math.inf
    return gain_db(g_lo), gain_db(g_hi)


def no_margin(**labels) -> LoopMargins:
    """The margins of an unstable closed loop: none, every margin and its frequency None.

    A margin is how far a stable loop is from instability; a loop unstable at the nominal gain is
    on the other side already, so none of its margins exists. Zero would read as "at the edge of
    stability", which it is not: ``stable`` (False) and the findings say what it is. MATLAB's
    ``diskmargin`` (Robust Control Toolbox, ``help diskmargin``: "the largest perturbation size ALPHA
    for which the feedback loop remains stable") finds no such ALPHA for it; ``allmargin`` keeps listing
    the crossings beside ``Stable = 0`` and ``margin`` warns "The closed-loop system is unstable.", but a
    crossing of an unstable loop is where stability would *return*, not a margin, and a table that
    printed it as one would read as robustness. Tables say ``unstable`` in its cells, JSON has null.
    """
    return LoopMargins(stable=False, gain_margin_db=(None, None), phase_crossover_freqs=(None, None),
                       phase_margin_deg=None, gain_crossover_freq=None, disk_alpha=None,
                       disk_gain_db=(None, None), disk_phase_deg=None, disk_freq=None, delay_margin=None, **labels)


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


def gain_db(g: float) -> float:
    """A loop-gain factor in dB (0 -> -inf, inf -> inf)."""
    return 20 * math.log10(g) if g > 0 and math.isfinite(g) else (math.inf if g == math.inf else -math.inf)


# ---------------------------------------------------------------------------------------
# Loops of a design


def design_loops(design, decoupled, A, B, sample_time: float | None = None, delay_samples: int = 0,
                 rotor_time_constant: float | None = None, rate_filter=None):
    """Yield ``(name, input, model, BrokenLoop)`` for every regulated loop of ``design``.

    ``model = "design"``: the subsystem alone (with its integrators), the loop the LQR guarantee
    is about. ``model = "coupled"``: the 12-state linear model, every other loop closed, position
    states that nothing feeds back left out. With ``sample_time`` (s: the controller's period, the
    design's own for a discrete design, or the rate a continuous design is run at) the loops are
    sampled, with ``delay_samples`` of delay on every input (:func:`quadctl.design.linear_loop.delayed`);
    ``rotor_time_constant`` puts the rotors' lag on every input (:func:`quadctl.design.lag.lagged`);
    ``rate_filter`` (:class:`quadctl.linear.filters.RateFilter`) the gyro filter in the law's rate path, in
    its continuous form or at ``sample_time``.
    """
    Ts = sample_time
    form = rate_filter.form(Ts) if rate_filter is not None else None
    for sub in design.subsystems:
        Aa, Ba, Ka = linear_loop.subsystem(sub, decoupled[sub.name], Ts, delay_samples=delay_samples,
                                           rotor_time_constant=rotor_time_constant, rate_filter=form)
        for j, inp in enumerate(sub.inputs):
            yield sub.name, inp, "design", broken_loop(Aa, Ba, Ka, j, Ts)
    Af, Bf, Kf = linear_loop.vehicle(design, A, B, Ts, delay_samples, rotor_time_constant, rate_filter=form)
    for sub in design.subsystems:
        for inp in sub.inputs:
            yield sub.name, inp, "coupled", broken_loop(Af, Bf, Kf, INPUT_INDEX[inp], Ts)


def lqg_loops(design, A, B, kal):
    """Yield ``(name, input, "lqg", BrokenLoop)``: every regulated input's loop with the Kalman filter in it.

    Loop state ``[x; x_hat; z]`` (``x_hat`` a priori for the discrete filter), the command
    ``c = -Kc [x; x_hat; z]`` (continuous: ``Kc = [0, K, Ki]``; discrete: the law on
    ``xc = M C x + (I - M C) x_hat``, ``Kc = [K M C, K (I - M C), Ki]``), the plant given ``c``
    except at the broken input ``j`` (given ``v``), the estimator and the integrators fed ``c`` and
    ``xc``. Positions nothing feeds back are left out in the coordinates ``[x; x - x_hat; z]``
    (there they drive nothing), as on the full-state coupled loop. With a gyro filter in the Kalman
    filter's model (``kal.rate_filter``) ``x`` is ``[x; g]``: the filter runs on the plant's rates and the
    estimator measures its output, so the loop broken at the plant input has both in it.

    Parameters
    ----------
    design : quadctl.design.Design
    A, B : (12, 12), (12, 4) array_like
        The continuous coupled linear model.
    kal : quadctl.design.kalman.Kalman
    """
    A = np.asarray(A, dtype=float)
    K, ints = design.K_block, design.integral_states
    nz, n, Ts = len(ints), kal.n_estimate, kal.sample_time  # n: the 12 states, and the gyro filter's modelled
    Z = np.zeros
    base, Bp, Be, Kc = lqg_loop.lqg(design, A, B, kal)
    T = np.eye(2 * n + nz)
    T[n:2 * n, :n], T[n:2 * n, n:2 * n] = np.eye(n), -np.eye(n)  # [x; x - x_hat; z]; T^-1 = T
    free = [STATE_INDEX[s] for s in free_positions(A, reads=(K,), integral_states=ints)]
    keep = [i for i in range(2 * n + nz) if i not in free]
    for sub in design.subsystems:
        for inp in sub.inputs:
            j = INPUT_INDEX[inp]
            others = Bp.copy()
            others[:, j] = 0.0
            Aa = linear_loop.close(base, np.vstack([others, Be, Z((nz, Bp.shape[1]))]), Kc)
            b = np.concatenate([Bp[:, j], Z(n), Z(nz)])
            At, bt, kt = T @ Aa @ T, T @ b, Kc[j] @ T
            yield sub.name, inp, "lqg", BrokenLoop(A=At[np.ix_(keep, keep)], b=bt[keep], k=kt[keep],
                                                   sample_time=Ts)
