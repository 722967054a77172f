"""What a loop's stability margins say, as values: the findings, and every loop of a design judged.

Each :class:`Finding` is one fact about a loop's margins (:class:`quadctl.design.margins.LoopMargins`):
how it stands against the continuous LQR guarantee, the cause of a shortfall, the gyro filter's lag at
the crossover, the saturation the disk margin covers, and what a Kalman filter in the loop costs
(:func:`lqg_findings`). Their sentences are written in :mod:`quadctl.present.loops`.
:func:`all_margins` computes the margins of every regulated loop of a design
(:mod:`quadctl.design.broken_loops`, :mod:`quadctl.design.margin_search`) and gives each its findings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np

from quadctl.design.broken_loops import design_loops, lqg_loops
from quadctl.design.decoupled import Design
from quadctl.design.kalman import Kalman
from quadctl.design.margin_search import loop_margins
from quadctl.design.margins import GUARANTEE_TOL, LQR_GAIN_MARGIN_DB, LQR_PHASE_MARGIN_DEG, LoopMargins
from quadctl.design.riccati import real_array
from quadctl.errors import ArgumentError, ArgumentTypeError
from quadctl.layout import INPUT_UNITS, N_INPUTS, N_STATES
from quadctl.linear.decouple import Decoupled
from quadctl.linear.filters import RateFilter
from quadctl.physics.motors import Actuators, headroom

# ---------------------------------------------------------------------------------------
# Findings: what a loop's margins say, as values (their sentences: quadctl.present.loops)


@dataclass(frozen=True)
class Finding:
    """One fact about a loop's margins: its ``kind`` and its numbers (units in the field names).
    :func:`quadctl.present.loops.note` words each kind; :meth:`as_dict` is what margins.json holds."""

    kind: ClassVar[str] = ""

    def as_dict(self) -> dict:
        """``{"kind": ..., field: value}``, tuples as lists (JSON)."""
        return {"kind": self.kind, **{k: list(v) if isinstance(v, tuple) else v
                                      for k, v in ((f.name, getattr(self, f.name)) for f in fields(self))}}


@dataclass(frozen=True)
class UnstableLoop(Finding):
    """The closed loop (``g = 1``) is unstable: no margin; sampled or not, with its delay."""

    kind: ClassVar[str] = "unstable"
    sampled: bool
    delay_samples: int
    ignored_rotor_lag_s: float | None = None
    """s: the rotors' lag in the loop that the design leaves out (``controller.rotor_lag: ignore``); None: none."""


@dataclass(frozen=True)
class HoldPhase(Finding):
    """A discrete design's loop: the phase the hold's half-sample delay takes at the gain crossover,
    ``hold_phase_deg = degrees(crossover_rad_s * sample_time_s / 2)``."""

    kind: ClassVar[str] = "hold_phase"
    crossover_rad_s: float
    sample_time_s: float
    hold_phase_deg: float


@dataclass(frozen=True)
class GuaranteeMet(Finding):
    """A continuous design's loop meets the continuous LQR guarantee."""

    kind: ClassVar[str] = "guarantee_met"


@dataclass(frozen=True)
class GuaranteeShort(Finding):
    """A continuous design's loop short of the guarantee: each margin that misses it (None: that one meets it)."""

    kind: ClassVar[str] = "guarantee_short"
    upper_gain_margin_db: float | None
    lower_gain_margin_db: float | None
    phase_margin_deg: float | None


@dataclass(frozen=True)
class EmulatedHold(Finding):
    """Cause of a shortfall: continuous gains run sampled at ``rate_hz``; the hold's half-sample phase at the
    crossover (None: ``|L|`` never crosses 1)."""

    kind: ClassVar[str] = "cause_emulated_hold"
    rate_hz: float
    crossover_rad_s: float | None
    hold_phase_deg: float | None


@dataclass(frozen=True)
class CouplingCause(Finding):
    """Cause of a coupled loop's shortfall: the couplings the decoupled design ignores."""

    kind: ClassVar[str] = "cause_coupling"


@dataclass(frozen=True)
class GyroFilterLag(Finding):
    """The gyro filter's phase lag at the crossover of a loop that feeds back a body rate."""

    kind: ClassVar[str] = "gyro_filter_lag"
    gyro_filter: str
    crossover_rad_s: float
    phase_lag_deg: float


@dataclass(frozen=True)
class SaturationCover(Finding):
    """The input's headroom from trim (the other inputs at trim), the disk's least gain ``g_min`` (the circle
    criterion keeps the loop stable while the effective gain stays above it), the command it covers
    (``headroom / g_min``) and what the configured initial offset asks for (None: not given); all in ``unit``."""

    kind: ClassVar[str] = "saturation"
    input: str
    unit: str
    headroom: float
    disk_gain_min: float
    covered_command: float
    initial_demand: float | None

    @property
    def within(self) -> bool | None:
        """The initial demand is within the covered command (None: no demand given)."""
        return None if self.initial_demand is None else self.initial_demand <= self.covered_command

    def as_dict(self) -> dict:
        return {**super().as_dict(), "initial_demand_within": self.within}


@dataclass(frozen=True)
class LqgUnstable(Finding):
    """The loop through the Kalman filter on ``measured`` is unstable: no margin."""

    kind: ClassVar[str] = "lqg_unstable"
    measured: tuple[str, ...]


@dataclass(frozen=True)
class LqgEstimator(Finding):
    """An estimator in the loop: the LQR guarantee does not hold (Doyle 1978); the filter's form, what it
    measures, the gyro filter in its model (None: none), and whether the loop meets the guarantee anyway."""

    kind: ClassVar[str] = "lqg_estimator"
    measured: tuple[str, ...]
    filter_form: str
    gyro_filter: str | None
    meets_guarantee: bool


@dataclass(frozen=True)
class LqgAgainstFullState(Finding):
    """The LQG loop's margins beside the full-state coupled loop's on the same input."""

    kind: ClassVar[str] = "lqg_vs_full_state"
    phase_margin_deg: float
    full_state_phase_margin_deg: float
    gain_margin_db: tuple[float, float]
    full_state_gain_margin_db: tuple[float, float]
    disk_alpha: float
    full_state_disk_alpha: float


@dataclass(frozen=True)
class LqgLeftOut(Finding):
    """What the full-state loops include that the LQG loop leaves out: the rotors' lag, the delay."""

    kind: ClassVar[str] = "lqg_left_out"
    rotor_lag: bool
    delay_samples: int



def lqg_findings(m: LoopMargins, full: LoopMargins | None, kal, delay_samples: int = 0,
                 rotor_time_constant: float | None = None) -> tuple[Finding, ...]:
    """What the estimator cost ``m`` against the full-state loop ``full`` (Doyle 1978)."""
    measured = tuple(kal.measured)
    if not m.stable:
        return (LqgUnstable(measured),)
    out: list[Finding] = [LqgEstimator(
        measured, kal.form, kal.rate_filter.describe() if kal.rate_filter is not None else None,
        m.meets_lqr_guarantee)]
    if full is not None and full.stable:
        out.append(LqgAgainstFullState(m.phase_margin_deg, full.phase_margin_deg, m.gain_margin_db,
                                       full.gain_margin_db, m.disk_alpha, full.disk_alpha))
    if rotor_time_constant is not None or delay_samples:
        out.append(LqgLeftOut(rotor_time_constant is not None, delay_samples))
    return tuple(out)


def hold_phase_deg(crossover_rad_s: float, sample_time_s: float) -> float:
    """deg: the phase a zero-order hold's half-sample delay takes at ``crossover_rad_s``."""
    return math.degrees(crossover_rad_s * sample_time_s / 2)


def findings(m: LoopMargins, design, emulated_rate=None, actuators=None, u_trim=None,
             initial_demand=None, rate_filter=None, rotor_time_constant=None) -> tuple[Finding, ...]:
    """``m`` against the LQR guarantee, the cause of any shortfall, the gyro filter's lag and the saturation.

    A discrete design's loop is not compared: the guarantee is a property of continuous state
    feedback that sampling does not keep (:mod:`quadctl.present.loops` says so once); its finding is
    the phase the hold takes at the crossover (:class:`HoldPhase`).
    """
    lower, upper = m.gain_margin_db
    if not m.stable:
        ignored = rotor_time_constant if rotor_time_constant and getattr(design, "lag_time_constant", None) is None \
            else None
        return (UnstableLoop(bool(m.sample_time), m.delay_samples, ignored),)
    out: list[Finding] = []
    wc = m.gain_crossover_freq
    if m.sample_time and design.rate is not None:  # a discrete design: the guarantee is not the sampled loop's
        if wc:
            out.append(HoldPhase(wc, m.sample_time, hold_phase_deg(wc, m.sample_time)))
    elif m.meets_lqr_guarantee:
        out.append(GuaranteeMet())
    else:
        out.append(GuaranteeShort(
            upper if math.isfinite(upper) else None,
            lower if lower > LQR_GAIN_MARGIN_DB[0] * (1 - GUARANTEE_TOL) else None,
            m.phase_margin_deg if m.phase_margin_deg < LQR_PHASE_MARGIN_DEG * (1 - GUARANTEE_TOL) else None))
        if m.sample_time:
            out.append(EmulatedHold(emulated_rate, wc or None, hold_phase_deg(wc, m.sample_time) if wc else None))
        elif m.model == "coupled":
            out.append(CouplingCause())
    out.extend(_filter_lag(m, design, rate_filter))
    if actuators is not None and u_trim is not None:
        out.extend(_saturation(m, actuators, u_trim, initial_demand))
    return tuple(out)


def _filter_lag(m: LoopMargins, design, rate_filter) -> list[Finding]:
    """The gyro filter's phase lag at the crossover of a loop whose subsystem feeds back a body rate."""
    wc = m.gain_crossover_freq
    subs = {sub.name: sub for sub in design.subsystems}
    if rate_filter is None or not wc or m.loop not in subs or not set(subs[m.loop].states) & {"p", "q", "r"}:
        return []
    lag = -math.degrees(float(np.angle(rate_filter.form(m.sample_time).response(wc)[0])))
    return [GyroFilterLag(rate_filter.describe(), wc, lag)]


def _saturation(m, actuators, u_trim, initial_demand) -> list[Finding]:

    down, up = headroom(actuators, u_trim)[m.input]
    room = min(down, up)
    g_min = 10 ** (m.disk_gain_db[0] / 20)
    if not math.isfinite(room):
        return []
    covered = room / g_min if g_min > 0 else math.inf
    demand = (initial_demand or {}).get(m.input)
    return [SaturationCover(m.input, INPUT_UNITS[m.input], room, g_min, covered,
                            None if demand is None else float(demand))]


# ---------------------------------------------------------------------------------------
# Every loop of a design, judged


def all_margins(design, decoupled, A, B, *, emulated_rate: float | None = None, actuators=None,
                u_trim=None, initial_demand: dict | None = None, delay_samples: int = 0,
                rotor_time_constant: float | None = None, estimator=None, rate_filter=None) -> list[LoopMargins]:
    """Margins of every regulated loop of a design, on its design model and on the coupled model
    (and with the Kalman filter in the loop, ``estimator``).

    Parameters
    ----------
    design : quadctl.design.Design
    decoupled : quadctl.linear.decouple.Decoupled
    A, B : array_like
        The coupled 12-state linear model.
    emulated_rate : float, optional
        Hz at which a *continuous* design is run (``controller.design: continuous`` with a rate):
        its loops are then evaluated sampled, with the continuous gains.
    actuators : quadctl.physics.motors.Actuators, optional
        For the saturation finding (:class:`SaturationCover`).
    u_trim : (4,) array_like, optional
        For the actuators' headroom.
    initial_demand : dict, optional
        ``input -> |du|`` the configured initial offset asks for at ``t = 0`` (``|K dx0|``).
    delay_samples : int
        Controller samples of delay included in every sampled loop (``controller.delay``).
    rotor_time_constant : float, optional
        s of the rotors' lag included in every loop (``motors.time_constant``).
    estimator : quadctl.design.kalman.Kalman, optional
        The LQG loops (:func:`quadctl.design.broken_loops.lqg_loops`), each compared with the full-state coupled loop.
    rate_filter : quadctl.linear.filters.RateFilter, optional
        The gyro filter (``controller.filters``) in every loop's rate path, sampled with the loop.

    Returns
    -------
    list of quadctl.design.margins.LoopMargins
        Design-model loops first, then coupled ones, then LQG ones, each with its ``findings``
        (:func:`findings`, :func:`lqg_findings`; :mod:`quadctl.present.loops` words them).

    Raises
    ------
    ArgumentError
        ``delay_samples`` of a continuous design without ``emulated_rate``, or not a whole number; an
        ``emulated_rate`` or ``rotor_time_constant`` that is not a positive number; ``A``, ``B`` not the
        12-state model's real (12, 12) and (12, 4) matrices (a ``ValueError``).
    ArgumentTypeError
        ``design`` is not a :class:`~quadctl.design.decoupled.Design` or ``decoupled`` not a
        :class:`~quadctl.linear.decouple.Decoupled` (the stages' ``design`` and ``decoupled``), or
        ``actuators``, ``estimator``, ``rate_filter`` not of their kinds (a ``TypeError``).

    Examples
    --------
    >>> import quadctl as qc
    >>> stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    >>> loops = qc.margins(stages.design, stages.decoupled, stages.linear.A, stages.linear.B)
    >>> [(m.loop, m.model) for m in loops][:2], all(m.meets_lqr_guarantee for m in loops)
    ([('altitude', 'design'), ('roll', 'design')], True)
    """
    from dataclasses import replace

    for label, value, kind in (("design", design, Design), ("decoupled", decoupled, Decoupled)):
        if not isinstance(value, kind):
            raise ArgumentTypeError(f"margins takes the design and the decoupled model, qc.margins(stages.design, "
                                    f"stages.decoupled, stages.linear.A, stages.linear.B); {label} is "
                                    f"{type(value).__name__}")
    A = real_array(A, "A", name="margins", shape=(N_STATES, N_STATES))
    B = real_array(B, "B", name="margins", shape=(N_STATES, N_INPUTS))
    for label, value, kind in (("actuators", actuators, Actuators), ("estimator", estimator, Kalman),
                               ("rate_filter", rate_filter, RateFilter)):
        if value is not None and not isinstance(value, kind):  # an AttributeError from inside, otherwise
            raise ArgumentTypeError(f"margins: {label} must be {kind.__name__} or None, got {type(value).__name__}")
    for label, value in (("emulated_rate", emulated_rate), ("rotor_time_constant", rotor_time_constant)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float, np.integer,
                                                                                    np.floating))
                                  or not 0.0 < value < math.inf):
            raise ArgumentError(f"margins: {label} = {value!r}: must be a positive number "
                                f"({'Hz' if label == 'emulated_rate' else 's'}) or None")
    if isinstance(delay_samples, bool) or not isinstance(delay_samples, (int, np.integer)) or delay_samples < 0:
        raise ArgumentError(f"margins: delay_samples = {delay_samples!r}: must be a whole number of controller "
                            "samples, 0 or more")
    # the loops run at the design's rate, or a continuous design's gains at the emulated rate
    sample_time = design.sample_time or (1.0 / emulated_rate if emulated_rate else None)
    out = []
    if delay_samples and sample_time is None:
        raise ArgumentError(f"margins: delay_samples = {delay_samples!r} of a continuous design: a delay is counted in "
                            "controller samples; give emulated_rate (Hz), or a design at a rate")
    for name, inp, model, loop in design_loops(design, decoupled, A, B, sample_time, delay_samples,
                                               rotor_time_constant, rate_filter):
        m = replace(loop_margins(loop, name=name, input_name=inp, model=model), delay_samples=delay_samples)
        out.append(replace(m, findings=findings(m, design, emulated_rate, actuators, u_trim, initial_demand,
                                                rate_filter, rotor_time_constant)))
    if estimator is not None:
        full_state = {m.input: m for m in out if m.model == "coupled"}
        for name, inp, model, loop in lqg_loops(design, A, B, estimator):
            m = loop_margins(loop, name=name, input_name=inp, model=model)
            out.append(replace(m, findings=lqg_findings(m, full_state.get(inp), estimator, delay_samples,
                                                        rotor_time_constant)))
    return out
