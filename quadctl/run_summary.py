"""What a flown run's ``sim.json`` reports beside its metrics: the flight (controller sampling, saturation,
noise, estimation, integrators: :func:`flight_summary`), the wind and the speeds (:func:`wind_summary`), the
tracking of a reference (:func:`tracking_summary`) and a mission's verdict (:func:`mission_check`,
:class:`MissionVerdict`), and the gain schedule flown (:func:`schedule_summary`). Pure functions of the
setup, the loop and the run; no I/O.
"""

from __future__ import annotations

from enum import Enum

import numpy as np

from quadctl.design.gain_table import OUTSIDE, VARIABLES
from quadctl.layout import INPUT_NAMES, STATE_NAMES
from quadctl.physics import motors, trajectory
from quadctl.physics.model import Vehicle, build_model
from quadctl.setup import Setup
from quadctl.sim.loop import ClosedLoop
from quadctl.sim.run import SimResult


def schedule_summary(loop: ClosedLoop) -> dict | None:
    """``sim.json``'s ``gain_schedule``: the gain table the loop flew (variable, unit, values,
    interpolation, what holds outside them, what the variable is read from); None: fixed gains."""

    table = loop.schedule
    if table is None:
        return None
    return {"variable": table.variable, "units": VARIABLES[table.variable], "values": table.values.tolist(),
            "interpolation": table.interpolation, "outside": OUTSIDE, "heading": loop.schedule_heading,
            "scheduled_on": "the reference the law uses (x_ref(t))",
            "integrator_gains": bool(table.coefficients.shape[-1] > len(STATE_NAMES))}


def tracking_summary(setup: Setup, sim: SimResult) -> dict | None:
    """``sim.json``'s ``reference``: the position tracking error ``|p - p_ref|`` (m; RMS over time,
    peak and final) and, for a mission, each waypoint with the time it was first reached within the
    tolerance (in order; None: never) and its closest approach (m) and when (s)
    (:class:`quadctl.physics.trajectory.Approach`); None without a reference."""
    if setup.reference is None or len(sim.t) == 0:
        return None
    return tracking_of(setup.reference, sim.t, sim.x, sim.x_ref)


def tracking_of(ref, t, x, x_ref) -> dict:
    """:func:`tracking_summary` of the path ``ref`` (:class:`quadctl.physics.trajectory.Reference`) flown as
    ``x`` ((n, 12), at the times ``t``) against the reference ``x_ref`` the law used."""

    err = np.linalg.norm(x[:, :3] - x_ref[:, :3], axis=1)
    out = {"kind": "waypoints" if ref.legs else "setpoints",
           "position_error": {"rms": float(np.sqrt(np.mean(err ** 2))), "peak": float(err.max()),
                              "final": float(err[-1]), "units": "m"}}
    if ref.legs:
        met = trajectory.waypoint_approaches(ref, t, x[:, :3])
        out["tolerance"] = ref.tolerance
        out["waypoints"] = [{"position": list(leg.position), "yaw": leg.yaw, "leg_start": leg.start,
                             "leg_end": leg.end, "hold": leg.hold, "reached": a.reached, "closest": a.closest,
                             "closest_at": a.closest_at}
                            for leg, a in zip(ref.legs, met)]
        out["all_reached"] = all(a.reached is not None for a in met)
        out["mission_end"] = ref.end
    return out


def flight_summary(setup: Setup, loop: ClosedLoop, sim: SimResult) -> dict:
    """The flight numbers of ``sim.json``: controller sampling, saturation, noise RMS, integrators.

    Returns
    -------
    dict
        ``controller`` (rate Hz, design kind, RK4 steps per sample), ``peak_delta`` (max |u - u_trim|
        per input), ``rms_error`` and ``rms_error_second_half`` (per state, state units),
        ``saturation`` (None without actuators; else per actuator the fraction of the run at a
        limit, ``saturates`` when one exceeds 1 %, peak commands, rotor speeds), ``noise``
        (seed and period, or None), ``wind`` (:func:`wind_summary`, or None), ``estimation`` (LQG
        only: RMS of ``x - x_hat`` per state, whole run and second half, and the steady filter's
        predicted standard deviation), ``integral`` (states and final integrator values), ``plant``
        (the simulated vehicle's parameters when they differ from the design model), ``reference``
        (:func:`tracking_summary`: tracking error and waypoints; None without a reference),
        ``gain_schedule`` (:func:`schedule_summary`: the gain table flown; None: fixed gains).
    """
    from quadctl.physics import noise

    duration = float(sim.t[-1]) if len(sim.t) else 0.0
    out: dict = {
        "controller": {"rate": setup.timing.rate, "design": setup.timing.mode,
                       "hold_steps": sim.plan.hold, "sample_time": sim.plan.sample_time,
                       "flies": setup.law, "cascade": setup.pid.title if setup.law == "pid" else None},
        "peak_delta": {name: float(np.abs(sim.u[:, j] - loop.u_trim[j]).max())
                       for j, name in enumerate(INPUT_NAMES)},
        "rms_error": noise.rms_deviation(sim.t, sim.x, sim.x_ref),
        "rms_error_second_half": noise.rms_deviation(sim.t, sim.x, sim.x_ref, duration / 2),
        "saturation": None, "noise": None, "wind": wind_summary(setup, sim), "estimation": None,
        "integral": {"states": list(loop.integral_states),
                     "final": {s: float(sim.z[-1, i]) for i, s in enumerate(loop.integral_states)}},
        "plant": setup.plant_overrides or None, "reference": tracking_summary(setup, sim),
        "gain_schedule": schedule_summary(loop),
    }
    act = loop.actuators
    if act is not None:
        fractions = motors.saturation_fraction(act, sim.u)
        commands = act.commands(sim.u)
        sat = {"mode": act.mode, "actuators": list(act.names), "fraction": fractions,
               "saturates": motors.saturates(fractions), "flag_above": motors.SATURATION_FLAG,
               "low": act.lo, "high": act.hi,
               "peak_command": {n: float(commands[:, i].max()) for i, n in enumerate(act.names)},
               "min_command": {n: float(commands[:, i].min()) for i, n in enumerate(act.names)}}
        if act.motors is not None:
            speeds = act.motors.speed(commands)
            sat["peak_rotor_speed"] = {n: float(speeds[:, i].max()) for i, n in enumerate(act.names)}
            sat["trim_rotor_thrust"] = list(act.commands(loop.u_trim))
        out["saturation"] = sat
    if out["reference"] is not None and "waypoints" in out["reference"]:
        sat = out["saturation"]
        out["reference"].update(mission_check(
            out["reference"], status=sim.status, saturates=bool(sat and sat["saturates"]),
            unregulated=unregulated_positions(setup), duration=setup.duration))
    kal = loop.estimator
    if kal is not None and sim.x_hat.size:
        predicted = np.sqrt(np.maximum(np.diag(kal.P), 0.0))
        out["estimation"] = {
            "form": kal.form, "measured": list(kal.measured),
            "rms_error": noise.rms_deviation(sim.t, sim.x, sim.x_hat),
            "rms_error_second_half": noise.rms_deviation(sim.t, sim.x, sim.x_hat, duration / 2),
            "predicted_std": dict(zip(STATE_NAMES, predicted))}
    spec = setup.noise
    if spec is not None:
        out["noise"] = {"seed": spec.seed, "period": spec.period, "process_std": spec.process_std,
                        "sensor_std": dict(zip(STATE_NAMES, spec.sensor_std))}
    return out


def speeds(sim: SimResult) -> tuple[np.ndarray, np.ndarray]:
    """(ground speed, airspeed) at each recorded sample, m/s: ``|R_b^E V_b|`` from the model's position
    rates, and ``|R_b^E V_b - w|`` with the wind the plant felt (still air: the two agree)."""

    # the position rows of f are the kinematics R_b^E V_b: no parameter enters them
    vel = np.asarray(build_model().f.map(len(sim.t))(sim.x.T, sim.u.T, Vehicle().vector()), dtype=float)[:3].T
    wind = sim.wind if len(sim.wind) else np.zeros_like(vel)
    return np.linalg.norm(vel, axis=1), np.linalg.norm(vel - wind, axis=1)


def wind_summary(setup: Setup, sim: SimResult) -> dict | None:
    """``sim.json``'s ``wind``: the wind's configuration and seed, the peak wind, and the ground speed
    and airspeed (m/s: max and RMS over the run); None in still air."""
    spec = setup.wind
    if spec is None or len(sim.t) == 0:
        return None
    ground, air = speeds(sim)
    turb = spec.turbulence
    return {
        "steady": list(spec.steady), "gusts": [{"start": g.start, "length": g.length, "amplitude": list(g.amplitude),
                                                 "hold": g.hold} for g in spec.gusts],
        "turbulence": None if turb is None else {
            "seed": turb.seed, "sigma": list(turb.sigma), "length_scale": list(turb.length),
            "reference_speed": turb.speed, "heading": turb.heading, "period": turb.period},
        "trim_in_wind": bool(any(setup.trim_wind)),
        "peak_wind": float(np.linalg.norm(sim.wind, axis=1).max()),
        "ground_speed": {"max": float(ground.max()), "rms": float(np.sqrt(np.mean(ground ** 2)))},
        "airspeed": {"max": float(air.max()), "rms": float(np.sqrt(np.mean(air ** 2)))},
        "units": "m/s",
    }


class MissionVerdict(str, Enum):
    """How a mission ended (``sim.json``'s ``reference.verdict``): every waypoint reached and the final
    tracking error within the tolerance, or the first cause of a failure the run shows, in this order
    (:func:`mission_check`). Its sentence: :func:`quadctl.present.mission.mission_text`."""

    REACHED = "reached"
    """Every waypoint reached within the tolerance, the final tracking error within it."""
    NOT_REGULATED = "position_not_regulated"
    """A position the mission flies is in no regulated subsystem: no gain acts on its error."""
    LEFT_VALID_RANGE = "left_valid_range"
    """The run stopped early: the vehicle left the model's valid range (or diverged)."""
    SATURATED = "saturated"
    """The inputs were at their limits for more than :data:`quadctl.physics.motors.SATURATION_FLAG` of the run."""
    RUN_ENDS_BEFORE_MISSION = "run_ends_before_mission"
    """``simulation.duration`` ends before the mission's last leg and hold."""
    MISSED = "missed"
    """None of the causes above: the vehicle flew the whole mission and stayed farther than the tolerance."""


def unregulated_positions(setup: Setup) -> tuple[str, ...]:
    """The position states (``pN``, ``pE``, ``pD``) in no regulated subsystem of the partition that a
    mission (``setup.reference`` with waypoints) moves along: a waypoint off the trim's position there."""
    ref = setup.reference
    legs = ref.legs if ref is not None else ()
    offsets = np.abs(np.array([leg.position for leg in legs]).reshape(-1, 3) - np.asarray(setup.position_ned))
    return tuple(s for i, s in enumerate(STATE_NAMES[:3])
                 if s not in setup.regulated and (not legs or offsets[:, i].max() > 0))


def ignored_position_steps(setup: Setup) -> tuple[str, ...]:
    """The position states (``pN``, ``pE``, ``pD``) in no regulated subsystem that a setpoint's
    ``position`` steps (``setup.reference`` of setpoints): no gain acts on their error, so the vehicle
    does not follow the step. A velocity setpoint moving an unregulated position is flown by its velocity
    loop and is not counted (``crazyflie-speed-schedule``)."""
    ref = setup.reference
    if ref is None or ref.legs or not ref.pieces:
        return ()
    start = np.asarray(setup.position_ned, dtype=float)
    before = [start] + [np.asarray(a.p0, float) + np.asarray(a.v0, float) * (b.t0 - a.t0)
                        for a, b in zip(ref.pieces, ref.pieces[1:])]
    jumps = np.abs(np.array([p.p0 for p in ref.pieces], dtype=float) - np.array(before))
    return tuple(s for i, s in enumerate(STATE_NAMES[:3])
                 if s not in setup.regulated and jumps[:, i].max() > 1e-12)


def mission_check(tracking: dict, *, status: str = "ok", saturates: bool = False,
                  unregulated: tuple[str, ...] = (), duration: float | None = None) -> dict:
    """The verdict on a mission flown (:func:`tracking_summary`'s ``tracking``, with ``waypoints``): a
    waypoint never reached, or a final tracking error above the tolerance, fails; the cause is the first
    the run shows of :class:`MissionVerdict`'s.

    Parameters
    ----------
    tracking : dict
        ``waypoints`` (each with ``reached``: s, or None), ``tolerance`` (m), ``mission_end`` (s) and,
        when known, ``position_error.final`` (m; a sweep's lanes do not keep it).
    status : str
        The run's (:func:`quadctl.sim.run.verdict`): ``ok``, ``diverged`` or ``left_valid_range``.
    saturates : bool
        Some input at a limit for more than 1 % of the run.
    unregulated : tuple of str
        :func:`unregulated_positions` of the design.
    duration : float, optional
        s, the configured run (``simulation.duration``).

    Returns
    -------
    dict
        ``verdict`` (a :class:`MissionVerdict` value), ``missed`` (indices of the waypoints never
        reached), ``final_above_tolerance`` (bool), ``unregulated`` (list) and ``duration``.
    """
    missed = [i for i, w in enumerate(tracking["waypoints"]) if w["reached"] is None]
    final = tracking.get("position_error", {}).get("final")
    above = final is not None and not final <= tracking["tolerance"]
    if not missed and not above:
        verdict = MissionVerdict.REACHED
    elif unregulated:
        verdict = MissionVerdict.NOT_REGULATED
    elif status != "ok":
        verdict = MissionVerdict.LEFT_VALID_RANGE
    elif saturates:
        verdict = MissionVerdict.SATURATED
    elif duration is not None and duration < tracking["mission_end"]:
        verdict = MissionVerdict.RUN_ENDS_BEFORE_MISSION
    else:
        verdict = MissionVerdict.MISSED
    return {"verdict": verdict.value, "missed": missed, "final_above_tolerance": bool(above),
            "unregulated": list(unregulated), "duration": duration}
