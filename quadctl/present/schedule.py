"""A gain schedule as rows and sentences: its points, the envelope and the frozen-point checks."""

from __future__ import annotations

import numpy as np

from quadctl.layout import INPUT_NAMES, STATE_INDEX
from quadctl.present.cells import Mark, Table, eig, num, yes

SHOWN_GAINS = (("T", "pD"), ("E", "theta"), ("A", "phi"), ("R", "psi"))
"""The block gain entries a point's row shows (input, state): one per loop."""


def points_table(sched) -> Table:
    """A row per scheduling value: its trim (pitch, roll, thrust), a few gains, verdict or why no trim."""
    unit = sched.unit
    gains = [f"K[{i},{s}]" for i, s in SHOWN_GAINS]
    rows = []
    for p in sched.points:
        if not p.trimmed or not p.designed:
            rows.append((num(p.value), "-", "-", "-", *("-" for _ in gains), "-",
                         Mark(f"no: {_short(p.reason)}", "fail")))
            continue
        slowest = max(e.real for e in p.core_eigenvalues)
        rows.append((num(p.value), num(p.trim.x[STATE_INDEX["theta"]]), num(p.trim.x[STATE_INDEX["phi"]]),
                     num(p.trim.u[0]),
                     *(num(p.K[INPUT_NAMES.index(i), STATE_INDEX[s]]) for i, s in SHOWN_GAINS),
                     num(slowest, 3), yes(p.stable)))
    return Table("schedule-table", f"Gain schedule over {sched.variable} ({len(sched.points)} values, "
                                   f"{sched.interpolation} interpolation)",
                 (f"{sched.variable} ({unit})", "theta (rad)", "phi (rad)", "T (N)", *gains,
                  "slowest pole (rad/s)", "stable"), tuple(rows),
                 caption="K: design.json's 4x12 block gain (u = u_trim - K (x - x_trim)); stable: the design's "
                         "loop on the coupled model; no: the value has no trim or no design, and why.",
                 align="l" + "r" * (5 + len(gains)) + "w")


def _short(reason: str | None, limit: int = 100) -> str:
    text = " ".join((reason or "").split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def flight_warnings(sched) -> list[str]:
    """What a run that flies ``sched`` says about it: the values with no trim, and a schedule that fails
    the checks ``quadctl schedule`` exits 1 on (a design or a frozen-point loop unstable), flown anyway."""
    warnings = [w for w in (sched.missing(),) if w]
    if not sched.passed:
        unstable = [f"{p.value:g}" for p in sched.points if p.designed and not p.stable]
        where = "; ".join(([f"the design at {', '.join(unstable)} {sched.unit} is UNSTABLE"] if unstable else [])
                          + ([sched.checks.failures_text(sched.unit)] if not sched.checks.passed else []))
        warnings.append(f"schedule: the gains flown fail their checks ({where}); `quadctl schedule` lists "
                        "them: narrow schedule.values to where they pass, or change the weights")
    return warnings


def envelope_sentence(sched) -> str:
    """The envelope, what holds outside it, and the values with no trim."""
    lo, hi = sched.envelope
    missing = [p for p in sched.points if not p.designed]
    text = (f"Envelope: {sched.variable} {lo:g} to {hi:g} {sched.unit} ({len(sched.table.values)} of "
            f"{len(sched.points)} values trim and design); the config flies {sched.own_value:g} {sched.unit}. "
            f"Outside it the table gives {sched.outside}.")
    if missing:
        text += (f" No trim or design at {', '.join(f'{p.value:g}' for p in missing)} {sched.unit}: narrow "
                 "schedule.values to the envelope.")
    return text


def checks_sentence(sched) -> Mark:
    """The frozen-point checks' verdict: the least damping and slowest pole along the fine grid, or
    where they fail."""
    c = sched.checks
    n = len(c.values)
    if c.passed:
        k = int(np.nanargmax(c.slowest))
        grid = (f"a grid {c.refinement}x finer than the schedule" if c.refinement > 1 else
                "the schedule's own values (schedule.check: 1)")
        return Mark(f"Frozen-point checks: the interpolated gains are stable at all {n} values of {grid}; "
                    f"slowest pole {c.slowest[k]:.3g} rad/s at "
                    f"{c.values[k]:g} {sched.unit}, least damping {np.nanmin(c.least_damping):.3g}.", "ok")
    return Mark(f"Frozen-point checks FAIL at {len(c.failures())} of {n} values: {c.failures_text(sched.unit)}.",
                "fail")


def failures_table(sched) -> Table | None:
    """Each fine value where the frozen-point check fails, with its worst eigenvalue (None: none fails)."""
    c = sched.checks
    rows = tuple((num(v), Mark("no trim", "fail") if why else Mark("UNSTABLE", "fail"),
                  "-" if why else eig(w), _short(why) if why else
                  "the interpolated gain, closed on the model trimmed here, has this pole in the right half-plane")
                 for v, ok, w, why in zip(c.values, c.stable, c.worst, c.reasons) if not ok)
    if not rows:
        return None
    return Table("schedule-failures-table", "Frozen-point checks that fail",
                 (f"{sched.variable} ({sched.unit})", "verdict", "worst eigenvalue (rad/s)", "why"), rows,
                 align="lllw")


def schedule_line(schedule: dict) -> str:
    """A run's gain schedule (:func:`quadctl.pipeline.schedule_summary`) in one line (``simulate`` prints it)."""
    values = ", ".join(f"{v:g}" for v in schedule["values"])
    return (f"gains scheduled on {schedule['variable']} at {values} {schedule['units']} ({schedule['interpolation']}, "
            "held outside), read from the reference")
