"""A simulation as rows and sentences: the step, the response metrics, the inputs and their
limits, the noise, the estimator, the wind and the integrators."""

from __future__ import annotations

import math

from quadctl.layout import INPUT_NAMES, STATE_NAMES, unit_of
from quadctl.metrics import NOISE_LIMITED_WORDS
from quadctl.present.cells import Mark, Table, eig, num, percent


def step_text(sim) -> str:
    """The RK4 step and why: ``dt = 3.45e-05 s (auto; stable up to ..., fastest eigenvalue ... in roll)``;
    ETDRK4's schedule: ``dt from 6.1e-07 s to 0.01 s in 15 segments (auto; RK4 would be stable up to ...)``."""
    plan = sim.plan
    if plan.method == "etdrk4":
        steps = [s.dt for s in plan.schedule]
        span = (f"dt = {steps[0]:.4g} s" if len(steps) == 1 else
                f"dt from {min(steps):.3g} s to {max(steps):.3g} s in {len(steps)} segments")
        return (f"{span} ({'auto' if plan.auto else 'given'}; RK4 would be stable up to {plan.max_stable_dt:.4g} s, "
                f"fastest eigenvalue {eig(plan.fastest_eigenvalue)} rad/s)")
    return (f"dt = {sim.dt:.4g} s ({'auto' if plan.auto else 'given'}; stable up to {plan.max_stable_dt:.4g} s, "
            f"fastest eigenvalue {eig(plan.fastest_eigenvalue)} rad/s in {plan.fastest_owner})")


def step_span(sim) -> str:
    """The steps in short: ``dt 3.45e-05 s``, or ETDRK4's graded ``dt 6.1e-07 .. 0.01 s``."""
    steps = [s.dt for s in sim.plan.schedule] if sim.plan.method == "etdrk4" else [sim.dt]
    return f"dt {steps[0]:.3g} s" if len(set(steps)) == 1 else f"dt {min(steps):.3g} .. {max(steps):.3g} s"


def integrator_name(sim) -> str:
    """``RK4`` or ``ETDRK4`` (``simulation.method``)."""
    return "ETDRK4" if sim.plan.method == "etdrk4" else "RK4"


def controller_text(flight: dict, sim) -> str | None:
    """A sampled controller's rate and hold (None for a continuous one): the design's, or the PID cascade's
    when it flies."""
    ctl = flight["controller"]
    if ctl.get("flies") == "pid":  # the cascade flies at its own rate, not the design's
        rate = 1.0 / ctl["sample_time"]
        return (f"controller: the {ctl['cascade']} cascade at {rate:g} Hz (controller.flies: pid), zero-order "
                f"hold: one sample every {ctl['hold_steps']} {integrator_name(sim)} steps of {sim.dt:.4g} s")
    if not ctl.get("rate"):
        return None
    if sim.plan.method == "etdrk4" and len(sim.plan.schedule) > 1:
        return (f"controller: {ctl['design']} design at {ctl['rate']:g} Hz, zero-order hold: ETDRK4 steps of the "
                f"plant between samples, {ctl['hold_steps']} of {sim.dt:.4g} s per sample at the end")
    return (f"controller: {ctl['design']} design at {ctl['rate']:g} Hz, zero-order hold: one sample every "
            f"{ctl['hold_steps']} {integrator_name(sim)} steps of {sim.dt:.4g} s")


NOISE_LIMITED_NOTE = (f"noise: noise-limited: {NOISE_LIMITED_WORDS}: the band lies within the noise, so it has no "
                      "settling time (read the RMS over the second half, or run without noise)")
"""The metrics table's footnote on a settling time shown as ``noise``."""


def settling_cell(metrics: dict, name: str) -> str:
    """A state's settling time as the tables show it: s, ``noise`` (noise-limited) or '-'."""
    if name in metrics.get("noise_limited", ()):
        return "noise"
    return num(metrics["settling_time"].get(name))


def metrics_table(metrics: dict) -> Table:
    rows = tuple((n, unit_of(n), settling_cell(metrics, n), num(metrics["overshoot"].get(n), 3),
                  num(metrics["peak_error"][n]), num(metrics["final_error"][n])) for n in STATE_NAMES)
    caption = "settling: within 2 % of the state's largest error; '-' never settled or n/a"
    if metrics.get("noise_limited"):
        caption += f"; {NOISE_LIMITED_NOTE}"
    return Table("metrics-table", "Closed-loop response (error from the reference)",
                 ("state", "unit", "settling (s)", "overshoot (%)", "peak |error|", "final error"), rows,
                 caption=caption, align="llrrrr")


def inputs_table(metrics: dict, u_trim, peak_delta: dict) -> Table:
    return Table("inputs-table", "Inputs", ("input", "unit", "trim", "peak magnitude", "peak |u - u_trim|"),
                 tuple((n, unit_of(n), num(u_trim[j]), num(metrics["peak"][n]), num(peak_delta[n]))
                       for j, n in enumerate(INPUT_NAMES)), align="llrrr")


def cost_sentence(metrics: dict) -> str:
    return f"Cost of the run, integral of e'Qe + du'R du dt: {num(metrics['cost'])}."


def headroom_table(flight: dict, u_trim) -> Table | None:
    """Each actuator against its limits: the range, trim, commands, headroom used, time at a limit."""
    sat = flight.get("saturation")
    if not sat:
        return None
    motors = sat["mode"] == "motors"
    trims = sat["trim_rotor_thrust"] if motors else list(u_trim)
    rows = []
    for i, name in enumerate(sat["actuators"]):
        unit = "N" if motors else unit_of(name)
        lo, hi, trim_i = sat["low"][i], sat["high"][i], trims[i]
        peak, low_cmd = sat["peak_command"][name], sat["min_command"][name]
        # a command that never rose above the trim used none of the room up (0 %, not a negative share)
        up = max(peak - trim_i, 0.0) / (hi - trim_i) if math.isfinite(hi) and hi > trim_i else None
        down = max(trim_i - low_cmd, 0.0) / (trim_i - lo) if math.isfinite(lo) and trim_i > lo else None
        frac = sat["fraction"][name]
        row = [name, f"{num(lo)} to {num(hi)} {unit}", num(trim_i), f"{num(low_cmd)} / {num(peak)}",
               f"{percent(up)} / {percent(down)}", Mark(percent(frac), "fail" if frac > sat["flag_above"] else "")]
        if motors:
            row.append(num(sat["peak_rotor_speed"][name]))
        rows.append(tuple(row))
    cols = ["actuator", "limits", "trim", "min / max command", "headroom used up / down", "time at a limit"]
    cols += ["peak speed (rad/s)"] if motors else []
    return Table("headroom-table", "Rotor thrusts against their limits" if motors else
                 "Inputs against their box limits", tuple(cols), tuple(rows),
                 caption="headroom used: the share of the range from the trim to the limit that the largest command "
                         "(up) and the smallest (down) take; 100 % is at the limit, where the command is clipped; "
                         f"flagged when an actuator is at a limit more than {sat['flag_above'] * 100:g} % of the run",
                 align="ll" + "r" * (len(cols) - 2))


def saturation_text(flight: dict) -> str | None:
    """The design saturates (an actuator at a limit longer than the flag): which, how long, the fix."""
    sat = flight.get("saturation")
    if not sat or not sat["saturates"]:
        return None
    worst = max(sat["fraction"], key=sat["fraction"].get)
    return (f"the design saturates: {worst} is at a limit {sat['fraction'][worst] * 100:.3g} % of the run (flag "
            f"above {sat['flag_above'] * 100:g} %); lower the gains (larger R) or the initial offset")


def rms_table(flight: dict) -> Table:
    noise = flight.get("noise") or {}
    seeds = f", noise seed {noise['seed']}" if noise else ""
    turb = (flight.get("wind") or {}).get("turbulence")
    seeds += f", turbulence seed {turb['seed']}" if turb else ""
    return Table("rms-table", f"RMS deviation from the reference{seeds or ' (no noise: the deterministic run)'}",
                 ("state", "unit", "whole run", "second half"),
                 tuple((n, unit_of(n), num(flight["rms_error"][n]), num(flight["rms_error_second_half"][n]))
                       for n in STATE_NAMES), align="llrr")


def estimation_table(flight: dict) -> Table | None:
    """RMS of ``x - x_hat`` per state next to the steady filter's predicted standard deviation (LQG)."""
    est = flight.get("estimation")
    if not est:
        return None
    return Table("estimation-table",
                 f"Estimation error x - x_hat ({est['form']} form; measured: {' '.join(est['measured'])})",
                 ("state", "unit", "RMS whole run", "RMS second half", "predicted std"),
                 tuple((n, unit_of(n), num(est["rms_error"][n]), num(est["rms_error_second_half"][n]),
                        num(est["predicted_std"][n])) for n in STATE_NAMES),
                 caption="predicted: the steady Kalman covariance (a priori for a sampled filter), for the noise "
                         "the filter assumes", align="llrrr")


def speeds_table(flight: dict) -> Table:
    """Ground speed and airspeed (max, RMS) of a run in wind."""
    wind = flight["wind"]
    return Table("speeds-table", "Ground speed and airspeed", ("speed", "unit", "max", "RMS"),
                 tuple((label, "m/s", num(wind[key]["max"]), num(wind[key]["rms"]))
                       for key, label in (("ground_speed", "ground speed"), ("airspeed", "airspeed"))), align="llrr")


def integral_text(flight: dict) -> str | None:
    ints = flight["integral"]
    if not ints["states"]:
        return None
    parts = ", ".join(f"integral of {s} = {num(v)}" for s, v in ints["final"].items())
    return f"integral action (LQI, anti-wind-up by conditional integration): final {parts}"


def wind_line(wind: dict) -> str:
    """A run's wind (:func:`quadctl.run_summary.wind_summary`) in one line: steady, gusts, turbulence, peak, and whether
    the trim is in it (``simulate`` and the report print it)."""
    def num(v):
        return f"{v:.4g}"

    parts = [f"steady [{', '.join(num(w) for w in wind['steady'])}] m/s NED"]
    if wind["gusts"]:
        parts.append(f"{len(wind['gusts'])} gust" + ("s" if len(wind["gusts"]) > 1 else ""))
    turb = wind["turbulence"]
    if turb:
        sigma = ", ".join(num(s) for s in turb["sigma"])
        parts.append(f"Dryden turbulence sigma [{sigma}] m/s at {num(turb['reference_speed'])} m/s "
                     f"(seed {turb['seed']})")
    trimmed = "trimmed in the steady wind" if wind["trim_in_wind"] else "trimmed in still air"
    return "wind: " + ", ".join(parts) + f"; peak {num(wind['peak_wind'])} m/s; {trimmed}"
