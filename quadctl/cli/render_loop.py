"""Rich renderings of a closed loop's numbers: sampling, margins, saturation, noise, integrators, the full design."""

from __future__ import annotations

import math

from rich.table import Table

from quadctl.cli.render import eig, num
from quadctl.layout import INPUT_NAMES, STATE_NAMES, unit_of


def _db(value: float) -> str:
    if value == 0:
        return "0"
    return f"{value:+.3g}" if math.isfinite(value) else ("+inf" if value > 0 else "-inf")


def margins_table(margins, rate=None) -> list[Table]:
    """Two tables that fit 80 columns: classical margins, then disk margin and the LQR guarantee."""
    kind = f"sampled at {rate:g} Hz (L(z), hold included)" if rate else "continuous (L(s))"
    classic = Table(title=f"Stability margins, each loop broken at its plant input; {kind}",
                    title_justify="left", caption="GM: lower / upper gain margin in dB (inf: no critical gain on that "
                    "side), at the phase crossovers; PM at the gain crossover; an unstable loop has "
                    "no margin (0)", caption_justify="left")
    for col, right in (("loop", False), ("model", False), ("GM dB", True), ("at rad/s", True),
                       ("PM deg", True), ("at rad/s ", True)):
        classic.add_column(col, justify="right" if right else "left")
    disk = Table(title="Disk margins and the continuous LQR guarantee", title_justify="left",
                 caption="continuous LQR guarantees GM <= -6.02 / inf dB, PM >= 60 deg, |1+L| >= 1",
                 caption_justify="left")
    for col, right in (("loop", False), ("model", False), ("alpha", True), ("disk GM dB", True),
                       ("disk PM", True), ("min|1+L|", True), ("guarantee", False)):
        disk.add_column(col, justify="right" if right else "left")
    for m in margins:
        lo, hi = m.gain_margin_db
        at = " / ".join(num(w, 3) for w in m.phase_crossover_freqs if w is not None) or "-"
        verdict = ("[green]met[/green]" if m.meets_lqr_guarantee else
                   ("[red]unstable[/red]" if not m.stable else "[yellow]short[/yellow]"))
        loop = f"{m.loop} ({m.input})"
        classic.add_row(loop, m.model, f"{_db(lo)} / {_db(hi)}", at, num(m.phase_margin_deg, 3),
                        num(m.gain_crossover_freq, 3))
        d_lo, d_hi = m.disk_gain_db
        symmetric = d_lo is not None and d_hi is not None and abs(d_lo + d_hi) < 1e-6 * max(1.0, abs(d_hi))
        disk_gm = "0" if d_hi == 0 else (f"±{abs(d_hi):.3g}" if symmetric else f"{_db(d_lo)} / {_db(d_hi)}")
        disk.add_row(loop, m.model, num(m.disk_alpha, 3), disk_gm,
                     num(m.disk_phase_deg, 3), num(m.min_return_difference, 3), verdict)
    return [classic, disk]


def margin_notes(margins) -> list[str]:
    """The notes of each loop; a coupled loop's only when they differ from its design loop's."""
    design_notes = {(m.loop, m.input): _strip_numbers(m.notes) for m in margins if m.model == "design"}
    lines = []
    for m in margins:
        if m.model == "coupled" and design_notes.get((m.loop, m.input)) == _strip_numbers(m.notes):
            continue
        for note in m.notes:
            lines.append(f"{m.loop} ({m.model}, {m.input}): {note}")
    if any(m.model == "coupled" for m in margins):
        lines.append("coupled loops not listed read as their design loops (same verdict and causes)")
    return lines


def _strip_numbers(notes) -> tuple[str, ...]:
    import re

    return tuple(re.sub(r"[-+]?\d[\d.e+-]*", "#", n) for n in notes)


def controller_line(flight: dict, sim) -> str | None:
    ctl = flight["controller"]
    if not ctl.get("rate"):
        return None
    return (f"controller: {ctl['design']} design at {ctl['rate']:g} Hz, zero-order hold: one sample every "
            f"{ctl['hold_steps']} RK4 steps of {sim.dt:.4g} s")


def saturation_table(flight: dict) -> Table | None:
    sat = flight.get("saturation")
    if not sat:
        return None
    motors = sat["mode"] == "motors"
    unit = "N" if motors else ""
    table = Table(title=("Rotor thrusts (mix, clip, unmix)" if motors else "Input limits (box)"),
                  title_justify="left",
                  caption=f"flagged when an actuator is at a limit more than {sat['flag_above'] * 100:g} % of the run",
                  caption_justify="left")
    cols = ["actuator", "low", "high", "min command", "max command", "time saturated"]
    if motors:
        cols.append("peak speed rad/s")
    for col in cols:
        table.add_column(col, justify="left" if col == "actuator" else "right")
    for i, name in enumerate(sat["actuators"]):
        u = unit or unit_of(name)
        frac = sat["fraction"][name]
        shown = f"{frac * 100:.3g} %"
        if frac > sat["flag_above"]:
            shown = f"[red]{shown}[/red]"
        row = [name, f"{num(sat['low'][i])} {u}", f"{num(sat['high'][i])} {u}", num(sat["min_command"][name]),
               num(sat["peak_command"][name]), shown]
        if motors:
            row.append(num(sat["peak_rotor_speed"][name]))
        table.add_row(*row)
    return table


def rms_table(flight: dict) -> Table:
    noise = flight.get("noise") or {}
    seed = f", noise seed {noise['seed']}" if noise else ""
    turb = (flight.get("wind") or {}).get("turbulence")
    seed += f", turbulence seed {turb['seed']}" if turb else ""
    table = Table(title=f"RMS deviation from the reference{seed}", title_justify="left")
    for col in ("state", "unit", "whole run", "second half"):
        table.add_column(col, justify="left" if col in ("state", "unit") else "right")
    for name in STATE_NAMES:
        table.add_row(name, unit_of(name), num(flight["rms_error"][name]),
                      num(flight["rms_error_second_half"][name]))
    return table


def estimation_table(flight: dict) -> Table | None:
    """RMS of ``x - x_hat`` per state next to the steady filter's predicted standard deviation (LQG)."""
    est = flight.get("estimation")
    if not est:
        return None
    table = Table(title=f"Estimation error x - x_hat ({est['form']} form; measured: {' '.join(est['measured'])})",
                  title_justify="left", caption="predicted: the steady Kalman covariance (a priori for a "
                  "sampled filter), for the noise the filter assumes", caption_justify="left")
    for col in ("state", "unit", "RMS whole run", "RMS second half", "predicted std"):
        table.add_column(col, justify="left" if col in ("state", "unit") else "right")
    for name in STATE_NAMES:
        table.add_row(name, unit_of(name), num(est["rms_error"][name]), num(est["rms_error_second_half"][name]),
                      num(est["predicted_std"][name]))
    return table


def wind_line(flight: dict) -> str:
    """The wind of a run in one line (:func:`quadctl.pipeline.wind_line`)."""
    from quadctl.pipeline import wind_line

    return wind_line(flight["wind"])


def wind_table(flight: dict) -> Table:
    """Ground speed and airspeed (max, RMS) of a run in wind."""
    wind = flight["wind"]
    table = Table(title="Ground speed and airspeed", title_justify="left")
    for col in ("speed", "unit", "max", "RMS"):
        table.add_column(col, justify="left" if col in ("speed", "unit") else "right")
    for key, label in (("ground_speed", "ground speed"), ("airspeed", "airspeed")):
        table.add_row(label, "m/s", num(wind[key]["max"]), num(wind[key]["rms"]))
    return table


def integral_line(flight: dict) -> str | None:
    ints = flight["integral"]
    if not ints["states"]:
        return None
    parts = ", ".join(f"integral of {s} = {num(v)}" for s, v in ints["final"].items())
    return f"integral action (LQI, anti-wind-up by conditional integration): final {parts}"


def full_tables(fd, comparison: dict) -> list:
    table = Table(title="Full 12-state LQR on the coupled model (same Q, R)", title_justify="left",
                  caption=("left out: " + ", ".join(fd.left_out) + " (no weight, no dynamics); " if fd.left_out
                           else "") + "weighted positions are regulated about the moving reference",
                  caption_justify="left")
    table.add_column("input")
    for s in fd.states:
        table.add_column(s, justify="right")
    for s in fd.integral_states:
        table.add_column(f"int {s}", justify="right")
    for j, name in enumerate(INPUT_NAMES):
        row = [f"{fd.K[j, STATE_NAMES.index(s)]:.4g}" for s in fd.states]
        row += [f"{fd.Ki[j, i]:.4g}" for i in range(len(fd.integral_states))]
        table.add_row(name, *row)
    eigs = ", ".join(eig(e) for e in sorted(fd.core_eigenvalues, key=lambda z: (z.real, z.imag)))
    comp = Table(title="Decoupled vs full design on the nonlinear model (same initial offset, no noise)",
                 title_justify="left",
                 caption="settling: the slowest regulated state; peak: max |u - u_trim|; cost: "
                         "integral of e'Qe + du'R du on the run; linear cost: dx0' P dx0 on the coupled "
                         "linear model", caption_justify="left")
    for col in ("criterion", "decoupled", "full", "better", "by (worse / better - 1)"):
        comp.add_column(col, justify="left" if col in ("criterion", "better") else "right")
    designs = comparison["designs"]
    rows = [("settling (s)", "settling", lambda r: r["settling"]), ("cost", "cost", lambda r: r["cost"]),
            ("linear cost", "linear_cost", lambda r: r["linear_cost"])]
    rows += [(f"peak |d{n}| ({unit_of(n)})", f"peak_{n}", lambda r, n=n: r["peak_input"][n]) for n in INPUT_NAMES]
    for label, key, get in rows:
        better = comparison["better"][key]
        ratio = better["ratio"]
        by = "-" if ratio is None else ("inf" if not math.isfinite(ratio) else f"{(ratio - 1) * 100:.3g} %")
        comp.add_row(label, num(get(designs["decoupled"])), num(get(designs["full"])),
                     better["winner"] or "tie", by)
    return [table, f"full closed-loop eigenvalues (rad/s): {eigs}", comp]


def closed_loop_line(payload: dict) -> str:
    """One line on margins.json's ``closed_loop``: the loop the vehicle has (lag, lag model, delay)."""
    cl = payload["closed_loop"]
    parts = []
    if payload.get("rotor_time_constant"):
        lag = payload.get("rotor_lag", "ignore")
        parts.append(f"a {payload['rotor_time_constant'] * 1e3:.4g} ms rotor lag ({lag}d by the design)")
    if payload.get("delay_samples"):
        parts.append(f"{payload['delay_samples']} samples of delay")
    what = "closed loop" + (" with " + " and ".join(parts) if parts else "")
    if cl["domain"] == "z":
        size = f"spectral radius {cl['spectral_radius']:.6g}"
    else:
        size = f"slowest pole {cl['slowest_real_part']:.4g} rad/s"
    return f"{what}: {'stable' if cl['stable'] else 'UNSTABLE'} ({len(cl['eigenvalues'])} eigenvalues, {size})"
