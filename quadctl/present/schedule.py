"""A gain schedule as rows and sentences: its points, the envelope, the frozen-point checks and its
verdict; a run's schedule and a flown transition in lines."""

from __future__ import annotations

import numpy as np

from quadctl.design.gain_table import VARIABLES
from quadctl.layout import INPUT_NAMES, STATE_INDEX
from quadctl.present.cells import Mark, Table, eig, num, yes
from quadctl.sim.run import STATUS_WORDS

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
                 align="l" + "r" * (4 + len(gains)) + "w")


def _short(reason: str | None, limit: int = 100) -> str:
    text = " ".join((reason or "").split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def frozen_failures(checks, unit: str = "") -> list[str]:
    """One line per fine value where the frozen-point check (:class:`quadctl.schedule.envelope.FrozenChecks`)
    fails: unstable (with its worst eigenvalue) or no trim; values in ``unit``."""
    out = []
    for v, ok, worst, why in zip(checks.values, checks.stable, checks.worst, checks.reasons):
        if ok:
            continue
        at = f"{v:.6g} {unit}".rstrip()
        out.append(f"at {at}: no trim inside the envelope ({why})" if why is not None else
                   f"at {at}: the interpolated gain's frozen loop is UNSTABLE (eigenvalue {eig(worst)})")
    return out


def frozen_failures_text(checks, unit: str = "", shown: int = 3) -> str:
    """The first ``shown`` :func:`frozen_failures` joined by ``; ``, and ``; ...`` when there are more."""
    fails = frozen_failures(checks, unit)
    return "; ".join(fails[:shown] + (["..."] if len(fails) > shown else []))


def missing(sched) -> str | None:
    """The values with no trim or design (:attr:`quadctl.schedule.envelope.Schedule.undesigned`), the first
    one's reason and the fix, one line (None: every value designs): what ``quadctl schedule`` and ``export``
    refuse (exit 2), ``simulate`` warns of."""
    undesigned = sched.undesigned
    if not undesigned:
        return None
    lo, hi = sched.envelope
    verb = "has" if len(undesigned) == 1 else "have"
    return (f"schedule.values: {len(undesigned)} of {len(sched.points)} values {verb} no trim or design "
            f"({', '.join(f'{p.value:g}' for p in undesigned)} {sched.unit}; the first: {undesigned[0].reason}); "
            f"the envelope is [{lo:g}, {hi:g}] {sched.unit}: narrow schedule.values to it")


def verdict(sched) -> str | None:
    """Why the schedule fails (:attr:`quadctl.schedule.envelope.Schedule.passed`), one line (None when it passes)."""
    parts = [f"the design at {p.value:.6g} {sched.unit} is UNSTABLE on the coupled model"
             for p in sched.unstable_points]
    fails = frozen_failures(sched.checks, sched.unit)
    if fails:
        parts.append(f"{len(fails)} of {len(sched.checks.values)} frozen-point checks fail: "
                     + frozen_failures_text(sched.checks, sched.unit))
    return "; ".join(parts) or None


def flight_warnings(sched) -> list[str]:
    """What a run that flies ``sched`` says about it: the values with no trim, and a schedule that fails
    the checks ``quadctl schedule`` exits 1 on (a design or a frozen-point loop unstable), flown anyway."""
    warnings = [w for w in (missing(sched),) if w]
    if not sched.passed:
        unstable = [f"{p.value:g}" for p in sched.unstable_points]
        where = "; ".join(([f"the design at {', '.join(unstable)} {sched.unit} is UNSTABLE"] if unstable else [])
                          + ([frozen_failures_text(sched.checks, sched.unit)] if not sched.checks.passed else []))
        warnings.append(f"schedule: the gains flown fail their checks ({where}); `quadctl schedule` lists "
                        "them: narrow schedule.values to where they pass, or change the weights")
    return warnings


def envelope_sentence(sched) -> str:
    """The envelope, what holds outside it, and the values with no trim."""
    lo, hi = sched.envelope
    undesigned = sched.undesigned
    text = (f"Envelope: {sched.variable} {lo:g} to {hi:g} {sched.unit} ({len(sched.table.values)} of "
            f"{len(sched.points)} values trim and design); the config flies {sched.own_value:g} {sched.unit}. "
            f"Outside it the table gives {sched.outside}.")
    if undesigned:
        text += (f" No trim or design at {', '.join(f'{p.value:g}' for p in undesigned)} {sched.unit}: narrow "
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
    return Mark(f"Frozen-point checks FAIL at {len(frozen_failures(c, sched.unit))} of {n} values: "
                f"{frozen_failures_text(c, sched.unit)}.",
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
    """A run's gain schedule (:func:`quadctl.run_summary.schedule_summary`) in one line (``simulate`` prints it)."""
    values = ", ".join(f"{v:g}" for v in schedule["values"])
    return (f"gains scheduled on {schedule['variable']} at {values} {schedule['units']} ({schedule['interpolation']}, "
            "held outside), read from the reference")


def transition_lines(summary: dict) -> list[str]:
    """A flown transition's runs (:attr:`quadctl.schedule.transition.Transition.summary`), one line per run."""

    lines = []
    for label, run in ((k, v) for k, v in summary.items() if isinstance(v, dict)):
        lines.append(f"{label}: {STATUS_WORDS[run['status']]} ({run['duration']:.3g} s), peak velocity error "
                     f"{run['velocity_error']:.3g} m/s, at a limit {100 * run['saturation']:.3g} % of the run, "
                     f"peak attitude {run['peak_attitude']:.3g} deg, {summary['variable']} flown "
                     f"{run['flown_range'][0]:.3g} to {run['flown_range'][1]:.3g} {VARIABLES[summary['variable']]}"
                     + ("" if run["on_grid"] else " (off the grid)"))
    return lines
