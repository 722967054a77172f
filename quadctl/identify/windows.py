"""Which stretches of a log to fit, and which parameters its excitation supports.

A log's flight is where the mean rotor command is above :data:`AIRBORNE_COMMAND` (short dips, a
throw or a free fall, are kept), cut :data:`AFTER_TAKEOFF` after each take-off (ground effect)
and :data:`BEFORE_LANDING` before each landing, and away from violent samples (a crash). Each stage
takes the log whose commands excite it most (the rotors' collective, differential and yaw
combinations), and refuses when none excites it enough, when the motors sit at full command, or
when a sensor drops out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.errors import LogError

AIRBORNE_COMMAND = 0.1
"""Mean rotor command (normalized) above which the vehicle counts as flying."""
DIP = 1.0
"""s: a shorter drop of the command (a free fall) stays inside the flight."""
AFTER_TAKEOFF = 1.0
"""s cut after a take-off (ground effect)."""
BEFORE_LANDING = 0.5
"""s cut before a landing or a crash."""
VIOLENT_RATE = 17.0
"""rad/s (about 1000 deg/s): a sample this fast, or above :data:`VIOLENT_ACCELERATION`, is a crash."""
VIOLENT_ACCELERATION = 4 * 9.81
"""m/s^2."""
SHORTEST = 2.0
"""s: a shorter flight is no window."""
EXCITATION = {"thrust": 0.05, "attitude": 0.03, "yaw": 0.05}
"""Least standard deviation of each stage's command combination (normalized command) that supports it."""
SATURATED = 0.999
"""A command at or above this is at full throttle."""
SATURATED_SHARE = 0.05
"""A window with more of its samples at full throttle is refused (the thrust there is unknown)."""
SENSOR_GAP = 0.02
"""s: a longer gap between samples (or a sensor frozen this long) is a dropped sensor."""


def flights(log) -> list[tuple[float, float]]:
    """The log's flights, trimmed (module docstring), as ``(t0, t1)`` in s."""
    t = log.t
    airborne = log.cmd.mean(axis=1) > AIRBORNE_COMMAND
    idx = np.nonzero(airborne)[0]
    if idx.size == 0:
        return []
    # close short dips
    gaps = np.nonzero(np.diff(idx) > 1)[0]
    segments, start = [], idx[0]
    for g in gaps:
        if t[idx[g + 1]] - t[idx[g]] > DIP:
            segments.append((start, idx[g]))
            start = idx[g + 1]
    segments.append((start, idx[-1]))
    violent = np.nonzero((np.abs(log.gyro).max(axis=1) > VIOLENT_RATE)
                         | (np.linalg.norm(log.acc, axis=1) > VIOLENT_ACCELERATION))[0]
    out = []
    for a, b in segments:
        t0, t1 = t[a] + AFTER_TAKEOFF, t[b] - BEFORE_LANDING
        hits = violent[(t[violent] >= t[a]) & (t[violent] <= t[b])]
        if hits.size:
            t1 = min(t1, t[hits[0]] - BEFORE_LANDING)
        if t1 - t0 >= SHORTEST:
            out.append((float(t0), float(t1)))
    return out


def cut_by_a_crash(log) -> str | None:
    """Why a log that flies has no flight (:func:`flights`): a crash's sample (:data:`VIOLENT_RATE`,
    :data:`VIOLENT_ACCELERATION`) right after take-off, which a gyro in deg/s reads at any turn; None when
    the log has a flight, never flies, or its flights are short for another reason."""
    airborne = np.nonzero(log.cmd.mean(axis=1) > AIRBORNE_COMMAND)[0]
    if airborne.size == 0 or flights(log):
        return None
    rate = np.abs(log.gyro).max(axis=1)
    force = np.linalg.norm(log.acc, axis=1)
    violent = airborne[(rate[airborne] > VIOLENT_RATE) | (force[airborne] > VIOLENT_ACCELERATION)]
    if violent.size == 0:
        return None
    k = int(violent[0])
    what = (f"the gyro reads {rate[k]:.4g} rad/s (above {VIOLENT_RATE:g}, about 1000 deg/s)" if rate[k] > VIOLENT_RATE
            else f"the accelerometer reads {force[k]:.3g} m/s^2 (above {VIOLENT_ACCELERATION:.3g})")
    return (f"{log.name}'s flight ends as a crash at t = {log.t[k]:.4g} s, {log.t[k] - log.t[airborne[0]]:.3g} s "
            f"after take-off, where {what}: if it did not crash, check the units (a gyro in deg/s reads so at any "
            "turn; give rad/s)")


def combinations(log, airframe) -> dict[str, np.ndarray]:
    """The command combinations each stage needs moving: collective, roll, pitch, yaw.

    Each weighs rotor ``i``'s command by where it acts, from the ``airframe``'s rotors in the log's (the
    config's) numbering (:class:`quadctl.identify.measurement.Airframe`: ``positions``, ``spins``): roll by
    ``-y_i``, pitch by ``x_i``, yaw by the spin, each scaled to ``+-1/4`` at the farthest rotor (an x layout:
    ``(c1 + c2 - c3 - c4) / 4`` and the like)."""
    positions, spins = airframe.positions, airframe.spins
    c = log.cmd
    x, y = positions[:, 0], positions[:, 1]
    return {"collective": c.mean(axis=1), "roll": c @ (-y / np.abs(y).max() / 4),
            "pitch": c @ (x / np.abs(x).max() / 4), "yaw": c @ (np.asarray(spins, dtype=float) / 4)}


def excitation(log, windows, airframe) -> dict[str, float]:
    """Per stage, the standard deviation of its command combination (:func:`combinations`) inside ``windows``."""
    mask = np.zeros(log.t.shape, dtype=bool)
    for t0, t1 in windows:
        mask |= (log.t >= t0) & (log.t <= t1)
    if mask.sum() < 2:
        return dict.fromkeys(EXCITATION, 0.0)
    s = {k: float(v[mask].std()) for k, v in combinations(log, airframe).items()}
    return {"thrust": s["collective"], "attitude": min(s["roll"], s["pitch"]), "yaw": s["yaw"]}


def dominance(exc: dict[str, float]) -> dict[str, float]:
    """How much each stage's excitation stands out from the others' (the log was flown for it)."""
    tiny = 1e-12
    return {"thrust": exc["thrust"] / (exc["attitude"] + exc["yaw"] + tiny),
            "attitude": exc["attitude"] / (exc["thrust"] + tiny),
            "yaw": exc["yaw"] / (exc["attitude"] + tiny)}


@dataclass(frozen=True)
class Plan:
    """Which log and windows each stage fits, and why a stage is refused."""

    chosen: dict  # stage -> (log index, windows)
    refused: dict  # stage -> reason
    excitation: list  # per log: {stage: std}


def plan(logs, windows, airframe) -> Plan:
    """Choose each stage's log and windows (``windows``: None, or per log a list of ``(t0, t1)`` or None for
    automatic), the excitation weighed by the ``airframe``'s rotors in the logs' numbering (:func:`combinations`).

    Raises
    ------
    LogError
        No log supports any stage (no flight, no excitation), or given windows that overlap or lie
        outside their log (:func:`check_windows`): the message names the files and the fix.
    """
    per_log = []
    for i, log in enumerate(logs):
        given = windows[i] if windows and windows[i] is not None else None
        if given is not None:
            check_windows(log, given)
        wins = given if given is not None else flights(log)
        per_log.append(wins)
    exc = [excitation(log, w, airframe) for log, w in zip(logs, per_log)]
    chosen, refused = {}, {}
    for stage, least in EXCITATION.items():
        candidates = [i for i in range(len(logs)) if exc[i][stage] >= least]
        if not candidates:
            best = max(e[stage] for e in exc) if exc else 0.0
            refused[stage] = (f"no log excites it: its command combination moves by {best:.3g} at most "
                              f"(std, normalized command), below {least:g}")
            continue
        i = max(candidates, key=lambda k: dominance(exc[k])[stage])
        problem = _problem(logs[i], per_log[i])
        if problem:
            refused[stage] = f"{logs[i].name}: {problem}"
            continue
        chosen[stage] = (i, per_log[i])
    if not chosen:
        names = ", ".join(log.name for log in logs)
        why = "; ".join(f"{s}: {r}" for s, r in refused.items())
        crashed = [c for i, log in enumerate(logs) if not (windows and windows[i] is not None)
                   for c in [cut_by_a_crash(log)] if c]
        fix = "; ".join(crashed) if crashed else ("give a log of a flight that moves the rotors (a thrust, roll-pitch "
                                                  "or yaw excitation), or --window t0:t1 around one")
        raise LogError(f"{names}: nothing to identify ({why}); {fix}")
    if "thrust" not in chosen:
        for stage in ("attitude", "yaw"):
            if stage in chosen:
                del chosen[stage]
                refused[stage] = "it needs the rotors' thrust curve and lag, and no log excites thrust"
        if not chosen:
            names = ", ".join(log.name for log in logs)
            raise LogError(f"{names}: no log excites the thrust, which every other stage needs; add a log with "
                           "climbs and descents (the collective command moving)")
    return Plan(chosen=chosen, refused=refused, excitation=exc)


def check_windows(log, windows) -> None:
    """Refuse given windows that overlap (touching ones are fine) or reach outside the log's span (by more
    than a sample: an end read off the span as printed, rounded, is still inside).

    A sample in two windows would count twice in the fit (and its lag restart inside the other window); a
    window past the log's end would be fitted on what it holds and reported as given.

    Raises
    ------
    LogError
        Naming the two overlapping windows, or the window outside and the log's span.
    """
    step = float(np.median(np.diff(log.t))) if log.t.size > 1 else 0.0
    for a, b in windows:
        where = "lies outside" if b <= log.t[0] or a >= log.t[-1] else \
            "reaches outside" if a < log.t[0] - step or b > log.t[-1] + step else None
        if where:
            raise LogError(f"{log.name}: --window {a:g}:{b:g} {where} the log, which spans t {log.t[0]:.4g} "
                           f"to {log.t[-1]:.4g} s (from its first sample); choose t0:t1 inside it")
    ordered = sorted(windows)
    for (a, b), (c, d) in zip(ordered, ordered[1:]):
        if c < b:
            raise LogError(f"{log.name}: --window {a:g}:{b:g} and {c:g}:{d:g} overlap (t {c:g} to {min(b, d):g} s "
                           f"would count twice); join them ({a:g}:{max(b, d):g}) or let them touch "
                           f"({a:g}:{b:g},{b:g}:{max(b, d):g})")


def _problem(log, windows) -> str | None:
    """Why the log's windows cannot be fitted (saturation, a dropped sensor), or None."""
    mask = np.zeros(log.t.shape, dtype=bool)
    for t0, t1 in windows:
        mask |= (log.t >= t0) & (log.t <= t1)
    idx = np.nonzero(mask)[0]
    if idx.size < 2:
        return "the window holds no samples"
    share = float((log.cmd[idx] >= SATURATED).any(axis=1).mean())
    if share > SATURATED_SHARE:
        return (f"the motors are at full command in {share * 100:.3g} % of the window (more than "
                f"{SATURATED_SHARE * 100:g} %): the thrust there is unknown; choose --window t0:t1 without it")
    inside = idx[1:][np.diff(idx) == 1]
    gaps = log.t[inside] - log.t[inside - 1]
    if gaps.size and gaps.max() > SENSOR_GAP:
        k = inside[int(np.argmax(gaps))]
        return (f"no samples for {gaps.max() * 1e3:.3g} ms at t = {log.t[k - 1]:.4g} s (a dropped sensor); "
                "choose --window t0:t1 around it")
    for what, values in (("gyro", log.gyro), ("accelerometer", log.acc)):
        frozen = np.all(np.diff(values[idx], axis=0) == 0, axis=1)
        run = _longest_run(frozen)
        if run and run * float(np.median(np.diff(log.t))) > SENSOR_GAP:
            return (f"the {what} repeats one value for {run} samples (a dropped sensor); "
                    "choose --window t0:t1 around it")
    return None


def _longest_run(flags: np.ndarray) -> int:
    best = cur = 0
    for f in flags:
        cur = cur + 1 if f else 0
        best = max(best, cur)
    return best


def parse_window(text: str) -> list[tuple[float, float]]:
    """``"35:65"`` or ``"32:38,45:49"`` -> ``[(35.0, 65.0)]`` ... (the ``--window`` option).

    Raises
    ------
    LogError
        Not ``t0:t1`` numbers with ``t0 < t1``.
    """
    out = []
    for part in text.split(","):
        a, colon, b = part.partition(":")
        try:
            t0, t1 = float(a), float(b)
        except ValueError:
            t0 = t1 = float("nan")
        if not colon or not (t0 < t1):
            raise LogError(f"--window {text!r}: {part!r} is not t0:t1 with t0 < t1 (s from the log's first sample, "
                           "as identify shows times); write e.g. --window 8.67:38.67 or --window 15.1:21.1,28.1:32.1")
        out.append((t0, t1))
    return out
