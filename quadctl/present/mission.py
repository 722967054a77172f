"""A flown reference as rows and sentences: the waypoints of a mission (where, when reached, how
close) and the position tracking error, from a run's tracking summary
(:func:`quadctl.run_summary.tracking_of`, ``sim.json``'s ``reference``)."""

from __future__ import annotations

import math

from quadctl.present.cells import Mark, Table, num
from quadctl.run_summary import MissionVerdict


def tracking_sentence(tracking: dict) -> str:
    """The position tracking error ``|p - p_ref|``: its RMS over the run, peak and final value."""
    err = tracking["position_error"]
    return (f"tracking error |p - p_ref|: rms {err['rms']:.3g} m, peak {err['peak']:.3g} m, "
            f"final {err['final']:.3g} m")


def waypoints_sentence(tracking: dict) -> Mark:
    """How many of a mission's waypoints were reached, in order, within its tolerance, and when; a
    verdict: ``ok`` every one, ``fail`` one or more missed."""
    wps = tracking["waypoints"]
    reached = [(i, w["reached"]) for i, w in enumerate(wps) if w["reached"] is not None]
    within = f"within {tracking['tolerance']:g} m"
    if not reached:
        said = f"none of {len(wps)} reached {within}"
    elif len(reached) == len(wps):
        said = f"{len(wps)} of {len(wps)} reached {within}, at " + ", ".join(f"{t:.3f} s" for _, t in reached)
    else:  # name the ones reached: the others are the warning's
        said = (f"{len(reached)} of {len(wps)} reached {within}: "
                + ", ".join(f"waypoints[{i}] at {t:.3f} s" for i, t in reached))
    return Mark(f"waypoints: {said} (mission ends at {tracking['mission_end']:.4g} s)",
                "ok" if len(reached) == len(wps) else "fail")


def tracking_lines(tracking: dict) -> list[str]:
    """A run's reference in sentences: for a mission, its waypoints (:func:`waypoints_sentence`),
    then the tracking error (:func:`tracking_sentence`)."""
    lines: list[str] = [tracking_sentence(tracking)]
    if "waypoints" in tracking:
        lines.insert(0, waypoints_sentence(tracking))
    return lines


def waypoints_table(tracking: dict) -> Table | None:
    """A mission's waypoints, one row each: the position and yaw flown to, when the reference
    arrives (the leg's end), when the vehicle reached it within the tolerance and its closest
    approach (:class:`quadctl.physics.trajectory.Approach`); None for setpoints. A waypoint never reached is
    marked ``fail`` in both columns."""
    if "waypoints" not in tracking:
        return None
    tol = tracking["tolerance"]
    rows = []
    for i, w in enumerate(tracking["waypoints"]):
        missed = w["reached"] is None
        closest = w.get("closest")
        near = "leg not flown" if closest is None else f"{num(closest, 3)} at {num(w['closest_at'], 4)} s"
        rows.append((f"waypoints[{i}]", ", ".join(num(c) for c in w["position"]),
                     f"{num(w['yaw'], 4)} ({num(math.degrees(w['yaw']), 4)} deg)", num(w["leg_end"], 4),
                     Mark("never" if missed else num(w["reached"], 4), "fail" if missed else "ok"),
                     Mark(near, "fail" if missed else "")))
    return Table("waypoints-table", f"Waypoints, reached within {tol:g} m (simulation.reference.tolerance)",
                 ("waypoint", "position N, E, D (m)", "yaw (rad)", "reference arrives (s)", "reached at (s)",
                  "closest approach (m)"), tuple(rows),
                 caption="reached at: the first time within the tolerance, from the leg's start and not before the "
                         "waypoint before it was reached; closest approach: the least distance over the same span, "
                         "and when (leg not flown: the run ended before the leg began)",
                 align="llrrrr")


def mission_text(tracking: dict | None) -> str | None:
    """Why a mission failed (:func:`quadctl.run_summary.mission_check`'s verdict in ``tracking``): what was
    missed, then the cause the run shows and its fix; None: every waypoint reached (or no mission)."""

    if not tracking or tracking.get("verdict", MissionVerdict.REACHED.value) == MissionVerdict.REACHED.value:
        return None
    verdict, tol, end = MissionVerdict(tracking["verdict"]), tracking["tolerance"], tracking["mission_end"]
    waypoints, missed = tracking["waypoints"], tracking["missed"]
    if missed:
        wp = waypoints[missed[0]]
        what = (f"simulation.reference.waypoints[{missed[0]}] [{', '.join(f'{c:g}' for c in wp['position'])}] was "
                f"never reached within {tol:g} m ({len(missed)} of {len(waypoints)} missed)")
    else:
        what = (f"the final tracking error {tracking['position_error']['final']:.3g} m is above "
                f"simulation.reference.tolerance {tol:g} m")
    if verdict is MissionVerdict.NOT_REGULATED:
        states = tracking["unregulated"]
        named = ", ".join(states)
        are, its = ("are", "their errors") if len(states) > 1 else ("is", "its error")
        cause = (f"position {named} {are} in no regulated subsystem of the partition, so no gain acts on {its}: "
                 f"add {named} to a regulated subsystem's states (as docs/configs/hover-hold.yaml does: pN with "
                 "pitch, pE with roll, pD with altitude)")
    elif verdict is MissionVerdict.LEFT_VALID_RANGE:
        cause = "the vehicle left the model's valid range before the mission ended (the run's message says where)"
    elif verdict is MissionVerdict.SATURATED:
        cause = ("the inputs were at their limits for part of the run (see the saturation): lower "
                 "simulation.reference.speed, or weigh the inputs more (lqr R)")
    elif verdict is MissionVerdict.RUN_ENDS_BEFORE_MISSION:
        cause = (f"the run ends at {tracking['duration']:.4g} s, before the mission does ({end:.4g} s): lengthen "
                 f"simulation.duration to at least {end:.4g} s")
    else:
        cause = (f"the whole mission was flown (it ends at {end:.4g} s) and the vehicle stayed off: loosen "
                 "simulation.reference.tolerance, give the waypoint a hold, or weigh the position errors more "
                 "(lqr Q on pN, pE, pD)")
    return f"{what}: {cause}"


def run_line(status: str, message: str, mission_failed: bool) -> str:
    """The line that closes a simulation's output: its status and what it says; a run that completed
    but did not fly its mission is not called ok (the failed check follows it)."""
    return f"{'mission not flown' if status == 'ok' and mission_failed else status}: {message}"


def ignored_steps_text(ignored) -> str | None:
    """The warning on setpoints that step the positions ``ignored``
    (:func:`quadctl.run_summary.ignored_position_steps`); None when there are none."""
    if not ignored:
        return None
    names = ", ".join(ignored)
    return (f"simulation.reference.setpoints step position {names}, in no regulated subsystem of the partition: "
            f"no gain acts on its error, so the vehicle does not follow the step; add {names} to a regulated "
            "subsystem's states (as docs/configs/hover-hold.yaml does), or command a velocity")
