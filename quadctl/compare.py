"""Laws side by side: the config's LQR design and flight stacks' PID cascades on one plant.

Every law flies the same plant (the setup's, with its rotors and delay), from the same initial
offset, along the same reference (a mission), through the same wind and the same noise: one
exogenous clock for all (the noise's period, else the LQR controller's, else the default), so each
run reads the same realization (:attr:`Comparison.disturbances` holds its digest, per law). Each
run is summarized by the same metrics (:data:`METRICS`), its cost on the config's LQR weights, and
each law's loops by their margins, each broken at a plant input with the rest of the loop closed (the
LQR design's on the coupled model, :func:`quadctl.design.margin_findings.all_margins`; a cascade's lifted to its
frame, :func:`quadctl.sim.cascade_margins.cascade_margins`): the same functions, comparable numbers.

``design --full`` sets two designs side by side the same way: the decoupled LQR and one coupled LQR of
the same cost, both flown on the nonlinear model from the configured offset (:func:`compare_full`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from quadctl.config.pid import NEEDS_ROTORS, PRESET_NAMES, resolve
from quadctl.design import Design, coupled
from quadctl.design.margins import least_margins
from quadctl.errors import ArgumentError, ConfigError
from quadctl.layout import INPUT_NAMES, STATE_INDEX
from quadctl.linear.filters import Section
from quadctl.linear.linearize import LinearModel
from quadctl.metrics import (
    NOISE_LIMITED_WORDS,
    Disturbance,
    disturbed_settling,
    lqr_cost,
    overshoot,
    settling_time,
    summarize,
)
from quadctl.physics.motors import has_rotors
from quadctl.physics.noise import exogenous_period
from quadctl.pipeline import Stages, closed_loop_of, noisy, pid_loop_of, simulation_of, twin_of, twin_settling
from quadctl.setup import Setup
from quadctl.sim.cascade_margins import cascade_margins
from quadctl.sim.exogenous import ExoStream
from quadctl.sim.loop import ClosedLoop
from quadctl.sim.run import SimResult, simulate, stop_cause
from quadctl.text.messages import hint

METRICS: tuple[tuple[str, str, str], ...] = (
    ("position_rms", "m", "RMS over the run of |p - p_ref|"),
    ("position_peak", "m", "largest |p - p_ref|"),
    ("attitude_rms", "rad", "RMS over the run of |(phi, theta, psi) - reference|"),
    ("settling", "s", "time after which |p - p_ref| stays within 2 % of its peak (None: never, or noise-limited: "
                      "settling_noise_limited)"),
    ("altitude_overshoot", "%", "largest excursion of pD past its reference, in % of the initial error"),
    ("rotor_peak", "1", "largest rotor thrust over the rotors' largest (motors.max_thrust; None: no motors:)"),
    ("rotor_rms", "1", "RMS over the run and the rotors of thrust over the largest (None: no motors:)"),
    ("saturated", "s", "time with a rotor at a thrust limit (within 0.1 % of its range; None: no motors:)"),
    ("cost", "1", "integral of e' Q e + du' R du dt on the config's LQR weights"),
    ("gain_margin", "dB", "least gain change, up or down, that destabilizes a loop broken at a plant input "
                          "(None: an unstable loop, closed_loop_stable false, or no loops)"),
    ("phase_margin", "deg", "least phase margin of the loops broken at the plant inputs (None: as gain_margin)"),
)
"""Each metric of a run: name, unit, meaning."""
CLOSED_LOOP_STABLE = "every loop of the law, unbroken, is stable (None: no loops); false: no margins"
"""The meaning of a law's ``closed_loop_stable`` in ``compare.json`` (beside its margins)."""
SATURATION_BAND = 1e-3
"""A rotor counts as at its limit within this fraction of its thrust range."""


@dataclass(frozen=True)
class LawRun:
    """One law's run in a comparison.

    Attributes
    ----------
    name : str
        ``lqr`` or ``pid:<preset>``.
    title : str
    rate : float or None
        Hz of the law's base loop (None: continuous).
    loop : ClosedLoop
    run : SimResult
    metrics : dict
        :data:`METRICS` by name.
    disturbances : str
        sha256 of the exogenous rows (noise, wind) the run read, over its duration.
    margins : tuple of quadctl.design.margins.LoopMargins
        The law's loops, each broken at a plant input with the rest of the loop closed.
    """

    name: str
    title: str
    rate: float | None
    loop: ClosedLoop
    run: SimResult
    metrics: dict
    disturbances: str
    margins: tuple = ()


@dataclass(frozen=True)
class Comparison:
    """Every law's run, and what they shared."""

    config: str
    duration: float
    exo_period: float
    laws: tuple[LawRun, ...]
    noise_seed: int | None
    wind_seed: int | None

    @property
    def identical_disturbances(self) -> bool:
        """Every law read the same noise and wind rows."""
        return len({law.disturbances for law in self.laws}) == 1

    @property
    def design_failures(self) -> list[str]:
        """Why the config's LQR design failed, one line each: its run stopped (diverged, or out of the
        model's valid range), or its closed loop is unstable; empty when it did not, or was not flown. A
        cascade's failure is not listed: it is the comparison's finding about that cascade."""
        out = []
        for law in self.laws:
            if law.name != "lqr":
                continue
            if law.run.status != "ok":  # what the run saved is not kept: compare.json has its metrics
                out.append(f"lqr: {stop_cause(law.run.message)}")
            if law.margins and not all(m.stable for m in law.margins):
                out.append("lqr: the closed loop is unstable (no margins)")
        return out


def parse_law(text: str) -> tuple[str, str | None]:
    """``lqr`` or ``pid:<preset>`` as ``(kind, preset)``.

    Raises
    ------
    ArgumentError
        Anything else.
    """

    kind, _, preset = text.partition(":")
    if kind == "lqr" and not preset:
        return "lqr", None
    if kind == "pid" and preset in PRESET_NAMES:
        return "pid", preset
    near = hint(text.lower(), ["lqr", *(f"pid:{name}" for name in PRESET_NAMES)], cutoff=0.75)  # pid:crazyfly,
    near = f"; {near}" if near.startswith("did you mean") else ""  # PID:px4; not pid:betaflight for pid:crazyflie
    raise ArgumentError(f"law {text!r}: use lqr or pid:<preset> with a preset of {', '.join(PRESET_NAMES)}{near}")


DEFAULT_LAWS = ("pid:crazyflie",)
"""The laws flown beside the LQR design when none are named."""


def compare(stages: Stages, laws=DEFAULT_LAWS, duration: float | None = None) -> Comparison:
    """The config's LQR design and each of ``laws`` flown on the setup's plant, side by side.

    Parameters
    ----------
    stages : Stages
        The config's stages (its setup, trim and LQR design).
    laws : sequence of str
        ``pid:<preset>`` (the config's ``controller.pid`` values apply to its own preset) or ``lqr``;
        the LQR design always flies first.
    duration : float, optional
        s; None: the config's.

    Returns
    -------
    Comparison

    Raises
    ------
    ConfigError
        A PID cascade among ``laws`` and no rotors (``motors:``) for it to command: before any run.
    ArgumentError
        A law that is not ``lqr`` or ``pid:<preset>``.
    """

    setup = stages.setup
    names = ["lqr", *[law for law in laws if parse_law(law)[0] != "lqr"]]
    cascades = [name for name in names if parse_law(name)[0] == "pid"]
    if cascades and not has_rotors(setup.actuators):
        raise ConfigError(f"compare: law {cascades[0]}: {NEEDS_ROTORS}, or compare the LQR design alone "
                          "(--law lqr)")
    duration = setup.duration if duration is None else float(duration)
    lqr = stages.lqr_loop
    noise, wind = setup.noise, setup.wind
    period = exogenous_period(noise.period if noise is not None else None, lqr.rate)
    reference = setup.flown_reference
    twin = twin_of(setup)  # turbulence: each law's late settling is read against its run without it
    out = []
    for name in dict.fromkeys(names):
        kind, preset = parse_law(name)
        if kind == "lqr":
            loop, title = lqr, "LQR (" + ("continuous" if lqr.rate is None else f"{lqr.rate:g} Hz") + ")"
            margins = plant_input_loops(stages.lqr_margins)
        else:
            own = setup.pid if setup.pid is not None and setup.pid.preset == preset else resolve(preset)
            loop, title = pid_loop_of(setup, stages.linear, own), f"{own.title} PID"
            margins = (stages.pid_margins if own is setup.pid
                       else cascade_margins(loop, title=preset))
        x0, common = setup.initial_state(loop.x_trim), {"max_samples": setup.max_samples, "reference": reference,
                                                         "exo_rate": 1.0 / period}
        run = simulate(loop, x0, duration, setup.dt, noise=noise, wind=wind, **common)
        calm = None if twin is None else simulate(loop, x0, duration, setup.dt, noise=twin.noise, wind=twin.wind,
                                                  **common)
        metrics = metrics_of(run, loop, setup.Q_block, setup.R_block, noisy(setup), calm) | margin_summary(margins)
        out.append(LawRun(name=name, title=title, rate=loop.rate, loop=loop, run=run, metrics=metrics,
                          disturbances=disturbance_digest(noise, wind, loop.rate, period, duration),
                          margins=tuple(margins)))
    return Comparison(config=setup.name, duration=duration, exo_period=period, laws=tuple(out),
                      noise_seed=noise.seed if noise is not None else None,
                      wind_seed=wind.seed if wind is not None else None)


def plant_input_loops(margins) -> list:
    """The LQR design's loops broken at a plant input with every other loop closed, as the vehicle has them:
    with the Kalman filter in them (``lqg``) when there is one, else on the coupled model."""
    for model in ("lqg", "coupled", "design"):
        chosen = [m for m in margins if m.model == model]
        if chosen:
            return chosen
    return []


def margin_summary(margins) -> dict:
    """``gain_margin`` (dB: the least gain change, up or down, that destabilizes one of the loops) and
    ``phase_margin`` (deg: the least) of ``margins``, and ``closed_loop_stable``, whether each loop is stable;
    with an unstable loop the margins are None (it has none: :func:`quadctl.design.margins.no_margin`)
    and ``closed_loop_stable`` False; without loops all three are None."""
    if not margins:
        return {"gain_margin": None, "phase_margin": None, "closed_loop_stable": None}
    return (dict(zip(("gain_margin", "phase_margin"), least_margins(margins)))
            | {"closed_loop_stable": all(m.stable for m in margins)})


def disturbance_digest(noise, wind, rate, period: float, duration: float) -> str:
    """sha256 of the noise and wind rows a run of ``duration`` s on the exogenous clock of ``period``
    reads (as :func:`quadctl.sim.run.simulate` draws them for a loop of ``rate`` Hz with that clock)."""
    active = (noise is not None and noise.active) or (wind is not None and wind.active)
    if not active:
        return hashlib.sha256(b"none").hexdigest()
    stream = ExoStream(noise if noise is not None and noise.active else None,
                       wind if wind is not None and wind.active else None, 1.0 / period)
    rows = stream.samples(0, int(np.ceil(duration / period)))
    return hashlib.sha256(np.ascontiguousarray(rows, dtype=float).tobytes()).hexdigest()


NOISE_LIMITED = (f"true: |p - p_ref| is noise-limited ({NOISE_LIMITED_WORDS}: quadctl.metrics.noise_limited), so it "
                 "has no settling time (settling None); a trend that ends outside the band beyond the noise's "
                 "reach, a drift, never settled (false); with turbulence, a law whose run without its random "
                 "disturbances does not settle never settled (false)")
"""compare.json's meaning of a law's ``settling_noise_limited``."""


def metrics_of(run: SimResult, loop: ClosedLoop, Q, R, noisy: int = Disturbance.QUIET,
               twin: SimResult | None = None) -> dict:
    """:data:`METRICS` of one run, and ``settling_noise_limited``: whether a ``noisy`` run's (a
    :class:`~quadctl.metrics.Disturbance`, :func:`quadctl.pipeline.noisy`; True: noise) settling is
    noise-limited (:func:`quadctl.metrics.noise_limited`); with turbulence, against ``twin``, the run
    of the same law without its random disturbances (:func:`quadctl.pipeline.twin_of`)."""
    t = run.t
    err = run.x - run.x_ref
    pos = _position_error(run)
    att = np.linalg.norm(err[:, STATE_INDEX["phi"]:STATE_INDEX["psi"] + 1], axis=1)
    cost = lqr_cost(t, err, run.u - loop.u_trim, np.asarray(Q), np.asarray(R))
    settled = settling_time(t, pos) if run.status == "ok" else None
    twin_settled = None
    if twin is not None:
        twin_settled = twin.status == "ok" and settling_time(twin.t, _position_error(twin)) is not None
    # a drift (a position the law leaves free, in a wind) trends out of its band: it never settled
    limited = False
    if run.status == "ok" and noisy:
        settled, limited = disturbed_settling(t, pos, settled, noisy, twin_settled)
    return {"position_rms": _rms(pos, t), "position_peak": float(pos.max()), "attitude_rms": _rms(att, t),
            "settling": settled, "settling_noise_limited": bool(limited),
            "altitude_overshoot": overshoot(err[:, STATE_INDEX["pD"]]),
            **rotor_use(run, loop), "cost": cost if np.isfinite(cost) else None, "status": run.status}


def _position_error(run: SimResult) -> np.ndarray:
    """``|p - p_ref|`` (m) at each record of ``run``."""
    return np.linalg.norm(run.x[:, :3] - run.x_ref[:, :3], axis=1)


def _rms(v, t) -> float:
    """RMS over the run (trapezoidal in ``t``); a run of one sample, that sample's magnitude."""
    return float(np.sqrt(np.trapezoid(v * v, t) / (t[-1] - t[0]))) if t[-1] > t[0] else float(abs(v[0]))


def rotor_use(run: SimResult, loop: ClosedLoop) -> dict:
    """``rotor_peak``, ``rotor_rms`` and ``saturated`` of one run; None without rotors (no ``motors:``:
    the plant takes the inputs themselves)."""
    act = loop.actuators
    if not has_rotors(act):
        return {"rotor_peak": None, "rotor_rms": None, "saturated": None}
    t = run.t
    rotors = run.u @ act.mix.T
    top = float(np.max(act.hi))
    span = act.hi - act.lo
    at_limit = np.any((rotors <= act.lo + SATURATION_BAND * span) | (rotors >= act.hi - SATURATION_BAND * span),
                      axis=1)
    dt = np.diff(t, append=t[-1])
    return {"rotor_peak": float(rotors.max() / top),
            "rotor_rms": _rms(np.sqrt(np.mean((rotors / top) ** 2, axis=1)), t),
            "saturated": float(np.sum(dt[at_limit]))}


def payload(comparison: Comparison) -> dict:
    """``compare.json``: each law's metrics with the units, and the disturbances they shared."""
    return {
        "config": comparison.config, "duration": comparison.duration,
        "units": {name: unit for name, unit, _ in METRICS} | {"duration": "s", "exo_period": "s", "rate": "Hz"},
        "meaning": {name: meaning for name, _, meaning in METRICS} | {"closed_loop_stable": CLOSED_LOOP_STABLE,
                                                                       "settling_noise_limited": NOISE_LIMITED,
                                                                       "gyro_filter": GYRO_FILTER,
                                                                       "gyro_lowpass_hz": GYRO_LOWPASS},
        "exo_period": comparison.exo_period, "noise_seed": comparison.noise_seed, "wind_seed": comparison.wind_seed,
        "identical_disturbances": comparison.identical_disturbances,
        "laws": [{"name": law.name, "title": law.title, "rate": law.rate, "disturbances": law.disturbances,
                  "gyro_filter": gyro_filter_of(law.loop), "gyro_lowpass_hz": stack_lowpass_of(law.loop),
                  **law.metrics,
                  "margins": [m.as_dict() for m in law.margins]} for law in comparison.laws],
    }


GYRO_FILTER = ("the filters the law reads the body rates through (the LQR design: controller.filters; a PID "
               "cascade: its stack's gyro low-pass, gyro_lpf_hz); None: raw rates")
"""compare.json's meaning of a law's ``gyro_filter``."""


GYRO_LOWPASS = "Hz: a PID cascade's stack's second-order gyro low-pass (gyro_lpf_hz); None: none, or the LQR design"
"""compare.json's meaning of a law's ``gyro_lowpass_hz``."""


def stack_lowpass_of(loop: ClosedLoop) -> float | None:
    """Hz of the second-order gyro low-pass a PID cascade's stack runs (:data:`GYRO_LOWPASS`); None: none, or
    not a cascade."""
    if loop.law is None:
        return None
    hz = float(loop.law["gyro_lpf_hz"])
    return hz if hz > 0 else None


def gyro_filter_of(loop: ClosedLoop) -> str | None:
    """The filters ``loop``'s law reads the body rates through, in words (:data:`GYRO_FILTER`); None: raw rates."""
    if loop.law is not None:  # a PID cascade: its stack's low-pass
        hz = stack_lowpass_of(loop)
        return Section("lowpass", hz, 2).describe() if hz is not None else None
    return loop.rate_filter.describe() if loop.rate_filter is not None else None


def compare_full(setup: Setup, linear: LinearModel, des: Design):
    """``design --full``: one coupled LQR with the same cost, both simulated on the nonlinear model.

    Both runs start from the configured offset on the configured plant and actuators, *without*
    noise, so settling times and peaks measure the designs, not one noise realization.

    Returns
    -------
    (FullDesign, dict)
        The full design and :func:`quadctl.design.coupled.compare` of the two runs (``decoupled``, ``full``),
        with each run's metrics and status.
    """

    if des.lag_time_constant is not None:
        raise ConfigError("controller.rotor_lag = include: design --full (one coupled LQR) is built for designs "
                          "without the rotors' lag only; run it with rotor_lag: ignore, or drop --full")
    fd = coupled.full_design(des, linear.A, linear.B)
    dx0 = setup.initial_offset
    Q = des.Q_block
    runs = {}
    for label, K, Ki in (("decoupled", des.K_block, des.Ki_block), ("full", fd.K, fd.Ki)):
        loop = closed_loop_of(setup, linear, K, Ki=Ki, integral_states=des.integral_states)
        sim = simulation_of(setup, loop, noise=False)
        met = summarize(sim, linear.u_trim, Q, des.R_block, setup.regulated, noisy=noisy(setup, noise=False),
                        twin=twin_settling(setup, loop))
        met["peak_delta"] = {name: float(np.abs(sim.u[:, j] - linear.u_trim[j]).max())
                             for j, name in enumerate(INPUT_NAMES)}
        met["linear_cost"] = coupled.linear_cost(linear.A, linear.B, K, Ki, des, dx0)
        met["backend"] = sim.backend
        runs[label] = met
    return fd, coupled.compare(runs, setup.regulated)
