"""Stability margins of a loop broken at the plant input, as values, and what they are judged against.

:class:`LoopMargins` holds a loop's gain, phase, disk and delay margins (MATLAB ``allmargin``/``diskmargin``
conventions) and judges them against the continuous LQR guarantee and the classical flight-control
requirement (:data:`THIN_GAIN_MARGIN_DB`, :data:`THIN_PHASE_MARGIN_DEG`); an unstable loop has no margin
(:func:`no_margin`). The loops themselves are :mod:`quadctl.design.broken_loops`; their margins are found on
the loop's frequency response by :mod:`quadctl.design.margin_search`. What each margin means and how the
loops are broken is in the docs, docs/internals.md ("Stability margins"). What the margins say (the
findings), and every loop of a design computed and judged, is :mod:`quadctl.design.margin_findings`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

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


def gain_db(g: float) -> float:
    """A loop-gain factor in dB (0 -> -inf, inf -> inf)."""
    return 20 * math.log10(g) if g > 0 and math.isfinite(g) else (math.inf if g == math.inf else -math.inf)
