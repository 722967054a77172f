"""The checks after the schema: rules across fields, names that must exist, bounds in context.

:func:`check_semantics` runs on every validated config; each failure is one
:class:`~quadctl.errors.ConfigError` line naming the file, the key path, the value and the fix. The
bounds of values by unit (the longest run, the largest initial offset, a position's, a velocity's, a
heading's and a time's limit) are :mod:`quadctl.config.unit_limits`'s.
"""

from __future__ import annotations

import math
import re
from typing import Any

from quadctl.artifacts.places import OWN_FIGURES
from quadctl.config.controller_schema import MAX_DELAY_SAMPLES, DelaySamples, EstimatorConfig
from quadctl.config.pid import NEEDS_ROTORS, rate_problem, resolve
from quadctl.config.schema import SUBSYSTEM_NAME_PATTERN, Config, ScheduleConfig
from quadctl.config.simulation_schema import MAX_WIND_ALTITUDE, ReferenceConfig
from quadctl.config.unit_limits import check_initial_offset, check_unit_limits
from quadctl.config.vehicle_checks import check_inertia, check_rotors, check_thrust_curve
from quadctl.config.weights import check_weight
from quadctl.errors import ConfigError
from quadctl.layout import INPUT_NAMES, SENSOR_GROUPS, STATE_NAMES, STATE_UNITS
from quadctl.text.messages import show
from quadctl.text.messages import unknown as _unknown

DELAY_SAMPLES_TOL = 1e-9
"""A delay in seconds is a whole number of samples when ``delay * rate`` is within this (relative)
of an integer: float round-off of ``0.005 * 200``, never a real fraction of a sample."""


def _safe_name(name: str) -> str:
    """A name close to ``name`` that :data:`SUBSYSTEM_NAME_PATTERN` allows (for the message's fix)."""
    safe = re.sub(r"[^A-Za-z0-9_]+", "_", name).strip("_") or "subsystem"
    return (safe if safe[0].isalpha() else f"s_{safe}")[:63]


def check_semantics(cfg: Config, label: str) -> None:
    def fail(path: str, value: Any, why: str) -> None:
        error = ConfigError(f"{label}: {path} = {show(value)}: {why}")
        error.key = path
        raise error

    folded: dict[str, str] = {}  # a name's file name where file names ignore case (macOS, Windows) -> the name
    for name in cfg.subsystems or {}:
        if not re.fullmatch(SUBSYSTEM_NAME_PATTERN, name):
            raise ConfigError(f"{label}: subsystems: {name!r} is not a usable subsystem name: it must start with a "
                              "letter and use only letters, digits and '_' (at most 63 characters: it names "
                              f"files, C and MATLAB fields); rename it, e.g. `{_safe_name(name)}`")
        own = name.casefold()
        if own in OWN_FIGURES:
            same = ("" if own == name else
                    f", one file with plots/{name}.png where file names ignore case (macOS, Windows)")
            raise ConfigError(f"{label}: subsystems: {name!r} is the name of a figure quadctl draws of its own "
                              f"(plots/{own}.png{same}), which would take the place of this subsystem's; rename it, "
                              f"e.g. `{name}_loop`")
        other = folded.setdefault(own, name)
        if other != name:
            raise ConfigError(f"{label}: subsystems: {other!r} and {name!r} differ only in case: their figures "
                              f"(plots/{other}.png, plots/{name}.png) are one file where file names ignore case "
                              f"(macOS, Windows); rename one, e.g. `{name}_2`")
    partition = cfg.partition()
    where = "subsystems" if cfg.subsystems is not None else "subsystems (the report's default)"
    seen_states: dict[str, str] = {}
    seen_inputs: dict[str, str] = {}
    for name, sub in partition.items():
        for i, state in enumerate(sub.states):
            if state not in STATE_NAMES:
                fail(f"subsystems.{name}.states[{i}]", state, _unknown(state, STATE_NAMES, "state"))
            if state in seen_states:
                fail(f"subsystems.{name}.states[{i}]", state,
                     f"state already in subsystem `{seen_states[state]}`; each state belongs to one subsystem")
            seen_states[state] = name
        allowed = INPUT_NAMES if sub.regulate else INPUT_NAMES + STATE_NAMES
        for i, inp in enumerate(sub.inputs):
            if inp not in allowed:
                kind = "input" if sub.regulate else "input or state"
                fail(f"subsystems.{name}.inputs[{i}]", inp, _unknown(inp, allowed, kind))
            if inp in INPUT_NAMES:
                if inp in seen_inputs:
                    fail(f"subsystems.{name}.inputs[{i}]", inp,
                         f"input already drives subsystem `{seen_inputs[inp]}`; give each input to one subsystem")
                seen_inputs[inp] = name
            elif inp in sub.states:
                fail(f"subsystems.{name}.inputs[{i}]", inp, "a subsystem's own state cannot be its input")
        for i, out in enumerate(sub.outputs or []):
            if out not in sub.states:
                fail(f"subsystems.{name}.outputs[{i}]", out,
                     f"outputs must be states of this subsystem: {', '.join(sub.states)}")
    regulated = {n: s for n, s in partition.items() if s.regulate}
    for inp in INPUT_NAMES:
        if inp not in seen_inputs:
            fail(where, sorted(regulated), f"input `{inp}` is not assigned to any regulated subsystem; "
                 "add it to one subsystem's inputs")
    for name in cfg.lqr:
        if name not in partition:  # a key, not a value: named as an unknown key is
            raise ConfigError(f"{label}: lqr.{name}: {_unknown(name, list(regulated), 'regulated subsystem')}")
        if not partition[name].regulate:
            raise ConfigError(f"{label}: lqr.{name}: this subsystem has regulate: false; remove its weights "
                              "or regulate it")
    for name, sub in regulated.items():
        if name not in cfg.lqr:
            fail("lqr", sorted(cfg.lqr), f"regulated subsystem `{name}` has no weights; "
                 f"add lqr.{name} with Q ({len(sub.states)} values) and R ({len(sub.inputs)})")
        weights = cfg.lqr[name]
        for i, state in enumerate(weights.integral):
            if state not in sub.states:
                fail(f"lqr.{name}.integral[{i}]", state,
                     f"not a state of subsystem `{name}`; integrate one of {', '.join(sub.states)}")
            if state in weights.integral[:i]:
                fail(f"lqr.{name}.integral[{i}]", state, "listed twice; integrate each state once")
        if weights.bryson is not None:
            _check_bryson(cfg, name, sub, weights, fail)
            continue
        for key in ("Q", "R"):
            if getattr(weights, key) is None:
                fail(f"lqr.{name}", weights.model_dump(exclude_none=True),
                     f"has no {key}: give Q ({len(sub.states) + len(weights.integral)} values) and R "
                     f"({len(sub.inputs)}), or the rule bryson: {{errors: [...], headroom: 0.2}}")
        check_weight(weights.Q, len(sub.states) + len(weights.integral), f"lqr.{name}.Q", label,
                     definite=False, names=[*sub.states, *(f"integral of {s}" for s in weights.integral)])
        check_weight(weights.R, len(sub.inputs), f"lqr.{name}.R", label, definite=True,
                     names=sub.inputs)
    _check_reference(cfg.simulation.reference, fail)
    check_unit_limits(cfg, fail)  # the absolute rule of each unit before the mission's reach, relative to it
    _check_reach(cfg, fail)
    _check_schedule(cfg.schedule, fail)
    check_initial_offset(cfg, fail)
    check_inertia(cfg, fail)
    _check_controller_and_actuators(cfg, fail)
    _check_delay(cfg, fail)
    _check_pid(cfg, fail)
    _check_filters(cfg, fail)
    _check_method(cfg, fail)
    if cfg.controller.rotor_lag == "include" and (cfg.motors is None or cfg.motors.time_constant is None):
        fail("controller.rotor_lag", "include", "needs the rotors' lag to include: set motors.time_constant (s), "
             "or use rotor_lag: ignore")


def _check_bryson(cfg: Config, name: str, sub, weights, fail) -> None:
    """``lqr.<name>.bryson``: in place of Q and R, one error per state and integral, and inputs with a range."""
    if weights.Q is not None or weights.R is not None:
        fail(f"lqr.{name}.bryson", weights.bryson.model_dump(), "gives Q and R from the vehicle: remove Q and R, "
             "or remove bryson")
    n = len(sub.states) + len(weights.integral)
    names = [*sub.states, *(f"integral of {s}" for s in weights.integral)]
    if len(weights.bryson.errors) != n:
        fail(f"lqr.{name}.bryson.errors", weights.bryson.errors,
             f"expected {n} values (the largest acceptable error of {', '.join(names)}), got "
             f"{len(weights.bryson.errors)}")
    unbounded = [i for i in sub.inputs if cfg.motors is None and (
        cfg.limits is None or i not in cfg.limits or not all(math.isfinite(v) for v in cfg.limits[i]))]
    if unbounded:
        fail(f"lqr.{name}.bryson", weights.bryson.model_dump(),
             f"takes R from the headroom of {', '.join(unbounded)}, which nothing limits: set motors: (or limits: "
             f"for {', '.join(unbounded)}), or give Q and R")


def _check_schedule(schedule: ScheduleConfig | None, fail) -> None:
    """``schedule.values``: strictly increasing."""
    if schedule is None:
        return
    for i in range(1, len(schedule.values)):
        if schedule.values[i] <= schedule.values[i - 1]:
            fail(f"schedule.values[{i}]", schedule.values[i],
                 f"not above values[{i - 1}] = {show(schedule.values[i - 1])}; list the values increasing, each once")


def _check_reference(ref: ReferenceConfig | None, fail) -> None:
    """``simulation.reference``: setpoints or waypoints (not both, not neither), setpoints in time order."""
    if ref is None:
        return
    where = "simulation.reference"
    if (ref.setpoints is None) == (ref.waypoints is None):
        fail(where, "both" if ref.setpoints is not None else "neither",
             "give either setpoints (steps at times t) or waypoints (a mission), one of the two")
    if not (ref.setpoints or ref.waypoints):
        fail(f"{where}.{'setpoints' if ref.setpoints is not None else 'waypoints'}", [], "empty; list at least one")
    for i, sp in enumerate(ref.setpoints or []):
        if sp.position is None and sp.velocity is None and sp.yaw is None:
            fail(f"{where}.setpoints[{i}]", {"t": sp.t}, "sets nothing; give position, velocity or yaw")
        if i and sp.t <= ref.setpoints[i - 1].t:
            fail(f"{where}.setpoints[{i}].t", sp.t,
                 f"not after setpoints[{i - 1}].t = {show(ref.setpoints[i - 1].t)}; list setpoints in increasing t")


MAX_REACH = 10.0
"""How far a mission's waypoint may lie along the mission from its start, in units of what its peak
speed covers in the run (``speed * duration``): a waypoint ten times past what the run can fly is a
position in millimetres or a slipped digit, not a mission (one run short of it is the verdict's)."""


def _check_reach(cfg: Config, fail) -> None:
    """The range rule of a mission's positions: each waypoint within :data:`MAX_REACH` times
    ``speed * duration`` of the trim position, along the legs before it."""
    ref = cfg.simulation.reference
    if ref is None or not ref.waypoints:
        return
    reach = ref.speed * cfg.simulation.duration
    start = cfg.trim.position_ned
    here, along, far = start, 0.0, (-1.0, 0)
    for i, wp in enumerate(ref.waypoints):
        along += math.dist(here, wp.position)  # overflow-safe: a slip of 1e300 m is named, not inf
        here = wp.position
        far = max(far, (math.dist(start, wp.position), -i))  # the farthest so far, the first of equals
        if along > MAX_REACH * reach:
            # name the waypoint farthest from the start: a slipped waypoint makes the legs to it and from it
            # long, so the sum first passes the bound at the waypoint after it, which is as the user wrote it
            k = -far[1]
            culprit = ref.waypoints[k].position
            metres = ", ".join(f"{c / 1000:.4g}" for c in culprit)
            mm = f"for millimetres write [{metres}], else " if along / 1000 <= MAX_REACH * reach else ""
            where = (f"{along:.5g} m from the start along the mission" if k == i else
                     f"{far[0]:.5g} m from the start, the farthest waypoint of a mission {along:.5g} m long by "
                     f"waypoints[{i}]")
            fail(f"simulation.reference.waypoints[{k}].position", culprit,
                 f"{where}, more than {MAX_REACH:g} times the {reach:.4g} m "
                 f"that simulation.reference.speed = {ref.speed:g} m/s covers in simulation.duration = "
                 f"{cfg.simulation.duration:g} s; positions are in m: {mm}correct the slip, or raise "
                 "the speed or the duration")


def _check_method(cfg: Config, fail) -> None:
    """``simulation.method: etdrk4``: its tolerance only with ``dt: auto``; a continuous loop with a Kalman
    filter and the rotors' lag has no linear part (a sampled one's is the plant's)."""
    sim = cfg.simulation
    if sim.method == "rk4":
        if sim.tolerance is not None:
            fail("simulation.tolerance", sim.tolerance, "sets the step schedule of method etdrk4: set "
                 "simulation.method: etdrk4, or remove the tolerance")
        return
    if sim.tolerance is not None and sim.dt != "auto":
        fail("simulation.tolerance", sim.tolerance, f"sets the step schedule of dt: auto, and simulation.dt is "
             f"{sim.dt:g} s: remove one of them")
    if (cfg.controller.rate is None and cfg.estimator is not None and cfg.motors is not None
            and cfg.motors.time_constant is not None):
        fail("simulation.method", sim.method, "has no linear part for a Kalman filter with the rotors' lag: "
             "use method: rk4, or remove motors.time_constant")


def _check_filters(cfg: Config, fail) -> None:
    """``controller.filters``: each frequency below the Nyquist frequency of a sampled controller, and a
    notch narrower than twice its centre."""
    filters, rate = cfg.controller.filters, cfg.controller.rate
    if filters is None:
        return
    for key, section, field in (("gyro", filters.gyro, "cutoff"), ("notch", filters.notch, "center"),
                                ("d_term", filters.d_term, "cutoff")):
        value = getattr(section, field) if section is not None else None
        if value is not None and rate is not None and value >= rate / 2:
            fail(f"controller.filters.{key}.{field}", value, f"Hz is not below the Nyquist frequency of the "
                 f"controller's {rate:g} Hz ({rate / 2:g} Hz): a sampled filter cannot reach it; lower it, or "
                 "raise controller.rate")
    if filters.notch is not None and filters.notch.bandwidth >= 2 * filters.notch.center:
        fail("controller.filters.notch.bandwidth", filters.notch.bandwidth,
             f"Hz is not below twice the centre ({2 * filters.notch.center:g} Hz): the notch would cut down to "
             "0 Hz; narrow it")
    if filters.gyro is not None or filters.notch is not None:
        for name, weights in cfg.lqr.items():
            for i, state in enumerate(weights.integral):
                if state in ("p", "q", "r"):
                    fail(f"lqr.{name}.integral[{i}]", state, "integrates a body rate, which the law takes through "
                         "controller.filters' gyro filter: its integrator is not modelled on the filtered rate; "
                         "integrate an angle or a position, or remove the gyro filter")


def _check_delay(cfg: Config, fail) -> None:
    """``controller.delay``: needs a rate, and is a whole number of samples at it."""
    delay, rate = cfg.controller.delay, cfg.controller.rate
    if delay is None:
        return
    shown = delay.model_dump() if isinstance(delay, DelaySamples) else delay
    if rate is None:
        fail("controller.delay", shown, "a delay is counted in controller samples: set controller.rate (Hz), "
             "or remove the delay")
    if isinstance(delay, DelaySamples):
        return
    n = delay * rate
    whole = round(n)
    if abs(n - whole) > DELAY_SAMPLES_TOL * max(1.0, n):
        lo, hi = math.floor(n), math.ceil(n)
        fail("controller.delay", delay,
             f"is {n:.6g} samples at {rate:g} Hz; the simulated delay is a whole number of samples: use "
             f"{lo / rate:.6g} s ({{samples: {lo}}}) or {hi / rate:.6g} s ({{samples: {hi}}})")
    if whole > MAX_DELAY_SAMPLES:
        fail("controller.delay", delay, f"is {whole} samples at {rate:g} Hz, more than the {MAX_DELAY_SAMPLES} "
             f"samples ({MAX_DELAY_SAMPLES / rate:g} s) quadctl simulates; controller.delay is in seconds (5 ms is "
             "0.005): shorten it")


def _check_pid(cfg: Config, fail) -> None:
    """``controller.flies: pid`` and ``controller.pid``: rotors to command, rates that nest, a delay whole at them."""

    ctl = cfg.controller
    if ctl.pid is not None:
        gains = resolve(ctl.pid.preset, attitude=ctl.pid.attitude)
        try:
            gains = gains.with_values(**ctl.pid.values)
        except ValueError as exc:
            fail("controller.pid.values", ctl.pid.values, str(exc))
        problem = rate_problem(gains)
        if problem:
            fail("controller.pid.values", ctl.pid.values, problem + ": change the rates")
    if ctl.flies == "pid" and cfg.motors is None:
        fail("controller.flies", "pid", f"{NEEDS_ROTORS}, or fly lqr")
    if ctl.flies == "pid" and ctl.filters is not None:
        fail("controller.filters", "(set)", "a PID cascade runs its flight stack's own gyro and D-term filters "
             "(controller.pid's preset): remove controller.filters, or fly lqr")
    if ctl.flies == "pid" and cfg.simulation.method == "etdrk4":
        fail("simulation.method", "etdrk4", "ETDRK4 integrates the LQR loop's linear part exactly; a PID cascade "
             "flies with RK4: set simulation.method: rk4 (or remove it), or fly lqr")


def _check_controller_and_actuators(cfg: Config, fail) -> None:
    """Controller rate and delay, motors, limits and noise: the keys that only make sense together."""
    if cfg.motors is not None and cfg.limits is not None:
        fail("limits", cfg.limits, "give either motors: (limits from the rotors) or limits:, not both")
    if cfg.motors is not None:
        check_rotors(cfg.motors, fail)
    if cfg.motors is not None and cfg.motors.min_thrust >= cfg.motors.max_thrust:
        fail("motors.min_thrust", cfg.motors.min_thrust,
             f"must be below motors.max_thrust = {cfg.motors.max_thrust:g} N")
    if cfg.motors is not None:
        check_thrust_curve(cfg.motors, fail)
    for name, (low, high) in (cfg.limits or {}).items():
        if name not in INPUT_NAMES:
            fail(f"limits.{name}", [low, high], _unknown(name, INPUT_NAMES, "input"))
        if not low < high:
            fail(f"limits.{name}", [low, high], "must be [low, high] with low < high")
    noise = cfg.simulation.noise
    for state, value in (noise.sensor if noise else {}).items():
        if state not in STATE_NAMES:
            fail(f"simulation.noise.sensor.{state}", value, _unknown(state, STATE_NAMES, "state"))
    if cfg.estimator is not None:
        _check_estimator(cfg.estimator, noise, fail)
    _check_wind(cfg, fail)


def _check_estimator(est: EstimatorConfig, noise, fail) -> None:
    """Known names, a sensor noise for every measured state, some process noise."""
    known = tuple(SENSOR_GROUPS) + STATE_NAMES
    for i, item in enumerate(est.measure):
        if item not in known:
            fail(f"estimator.measure[{i}]", item, _unknown(item, known, "state or sensor group"))
    for state, value in est.sensor.items():
        if state not in STATE_NAMES:
            fail(f"estimator.sensor.{state}", value, _unknown(state, STATE_NAMES, "state"))
    given = noise.sensor if noise is not None else {}
    for state in est.measured():
        if est.sensor.get(state, given.get(state, 0.0)) <= 0:
            fail("estimator.measure", est.measure,
                 f"{state} is measured but has no sensor noise: give estimator.sensor.{state} or "
                 f"simulation.noise.sensor.{state} (> 0, {STATE_UNITS[state]})")
    force = est.force if est.force is not None else (noise.force if noise is not None else [0.0] * 3)
    torque = est.torque if est.torque is not None else (noise.torque if noise is not None else [0.0] * 3)
    if not any(v > 0 for v in (*force, *torque)):
        fail("estimator.force", force, "the filter needs process noise: give estimator.force and estimator.torque "
             "(N, N m) or simulation.noise.force/torque; with none it would trust its model and ignore every sensor")


def _check_wind(cfg: Config, fail) -> None:
    """``simulation.wind`` and ``trim.wind``: the keys that only make sense together."""
    wind = cfg.simulation.wind
    if cfg.trim.wind and (wind is None or not any(wind.steady)):
        fail("trim.wind", True, "needs a steady wind to trim in: set simulation.wind.steady, or trim.wind: false")
    turb = wind.turbulence if wind is not None else None
    if turb is None:
        return
    where = "simulation.wind.turbulence"
    explicit = turb.sigma is not None or turb.length_scale is not None
    if turb.intensity is not None and explicit:
        fail(f"{where}.intensity", turb.intensity, "give either intensity (with altitude) or sigma and "
             "length_scale, not both")
    if turb.intensity is None and not explicit:
        fail(where, turb.model_dump(exclude_none=True), "needs intensity: light|moderate|severe, or sigma and "
             "length_scale")
    if explicit and (turb.sigma is None or turb.length_scale is None):
        missing = "sigma" if turb.sigma is None else "length_scale"
        fail(f"{where}.{missing}", None, "sigma and length_scale go together: give both (or intensity)")
    if explicit and turb.altitude is not None:
        fail(f"{where}.altitude", turb.altitude, "sets the scales of an intensity only; remove it with sigma")
    if turb.intensity is not None and turb.altitude is None and -cfg.trim.position_ned[2] <= 0:
        fail(f"{where}.altitude", None, f"the trim's altitude {-cfg.trim.position_ned[2]:g} m is not above "
             "ground: give the turbulence's altitude (m)")
    if turb.intensity is not None and turb.altitude is None and -cfg.trim.position_ned[2] > MAX_WIND_ALTITUDE:
        fail(f"{where}.altitude", None, f"the trim's altitude {-cfg.trim.position_ned[2]:g} m is above the "
             f"low-altitude model's {MAX_WIND_ALTITUDE:g} m (1000 ft): give sigma and length_scale instead")
