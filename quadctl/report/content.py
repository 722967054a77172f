"""The report's sections, built from a workspace's stage results (and nothing else).

Numbers are written as the stage commands print them (``quadctl trim``: 6 significant digits;
gains, metrics: 4; margins: 3), so a value read in the report can be found in the terminal and in
the artifacts.
"""

from __future__ import annotations

import io
import math

import numpy as np

from quadctl.layout import INPUT_NAMES, STATE_NAMES, unit_of
from quadctl.report.document import Code, Figure, Items, Row, Section, Table, Text

TOP_DROPPED = 8
"""Dropped coupling terms listed, per matrix (A, B), largest first (as ``quadctl decouple``)."""
SIM_DPI, MARGINS_DPI = 90, 80
"""Figure resolutions: readable on screen and in print, the whole report under a few MB."""


# -- numbers, as the commands print them ------------------------------------------------------


def num(value, digits: int = 4) -> str:
    if value is None:
        return "-"
    if isinstance(value, (complex, np.complexfloating)):
        return eig(value)
    if not math.isfinite(value):
        return str(value)
    return f"{value + 0.0:.{digits}g}"  # + 0.0: no "-0"


def eig(e) -> str:
    e = complex(e)
    e = complex(e.real + 0.0, e.imag + 0.0)  # no "-0"
    return f"{e.real:.5g}" if abs(e.imag) < 1e-9 else f"{e.real:.5g} {'+' if e.imag >= 0 else '-'} {abs(e.imag):.5g}j"


def eigs(values) -> str:
    return ", ".join(eig(e) for e in values)


def db(value) -> str:
    if value is None:
        return "-"
    return f"{value:+.3g}" if math.isfinite(value) else ("+inf" if value > 0 else "-inf")


def yes(flag: bool) -> str:
    return "yes" if flag else "no"


def weights(mat) -> str:
    """A weight matrix: ``diag(50, 1)`` when diagonal, else its rows."""
    mat = np.atleast_2d(np.asarray(mat, dtype=float))
    if np.count_nonzero(mat - np.diag(np.diag(mat))) == 0:
        d = np.diag(mat)
        return num(d[0]) if d.size == 1 else "diag(" + ", ".join(num(v) for v in d) + ")"
    return "[" + "; ".join(", ".join(num(v) for v in row) for row in mat) + "]"


def vector(values, digits: int = 4) -> str:
    return "[" + ", ".join(num(float(v), digits) for v in np.ravel(values)) + "]"


def _percent(share) -> str:
    return "-" if share is None else f"{share * 100:.3g} %"


def _png(fig, dpi: int) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


# -- sections ---------------------------------------------------------------------------------


def configuration(ws, label: str) -> Section:
    given = ws.source_text if ws.source_text is not None else "# built in Python: no YAML text given\n"
    return Section("config", "Configuration", (
        Text(f"Config {ws.cfg.name!r} read from {label}; config_hash {ws.cfg.digest()} (sha256 of the "
             "validated config). Both texts are kept in the run folder: config.yaml and config.resolved.yaml."),
        Row((Code(f"As given ({label})", given),
             Code("As resolved: validated, every default filled in", ws.cfg.to_yaml()))),
    ))


def trim(ws) -> Section:
    t = ws.trim
    states = tuple((n, f"{t.x[i]:.6g}", unit_of(n), num(t.xdot[i], 3)) for i, n in enumerate(STATE_NAMES))
    inputs = tuple((n, f"{t.u[j]:.6g}", unit_of(n)) for j, n in enumerate(INPUT_NAMES))
    v = ws.setup.velocity_ned
    return Section("trim", "Trim", (
        Text(f"Equilibrium at velocity_ned {vector(v)} m/s: thrust T = {t.u[0]:.6g} N, pitch theta = "
             f"{t.x[7]:.6g} rad. Residual max|dx/dt| = {t.residual:.2e} (non-position states) after "
             f"{t.iterations} Newton iterations."),
        Row((Table("trim-state-table", "State at the trim", ("state", "value", "unit", "dx/dt"), states,
                   caption="dx/dt: the residual; the positions move at the flight velocity.", align="lrlr"),
             Table("trim-input-table", "Input at the trim", ("input", "value", "unit"), inputs, align="lrl"))),
    ))


def decoupling(ws) -> Section:
    dec = ws.decoupled
    subs = tuple((s.name, " ".join(s.states), " ".join(s.inputs) + ("" if s.regulated else " (from A)"),
                  yes(s.regulated), eigs(np.linalg.eigvals(s.A))) for s in dec.subsystems)
    dropped = [d for kind in ("A", "B") for d in [d for d in dec.dropped if d.matrix == kind][:TOP_DROPPED]]
    blocks = [
        Table("subsystems-table", "Subsystems (diagonal blocks of A, matching columns of B)",
              ("subsystem", "states", "inputs", "regulated", "open-loop eigenvalues (rad/s)"), subs, align="llllw"),
    ]
    if dec.dropped:
        worst = max(dec.dropped, key=lambda d: d.relative)
        blocks.insert(0, Text(f"The partition drops {len(dec.dropped)} coupling terms of A and B; the largest, "
                              f"{worst.name} = {worst.value:.4g} {worst.unit}, is {worst.relative * 100:.3g} % of "
                              f"the largest entry of {worst.matrix}. The design is checked on the coupled model."))
        blocks.append(Table(
            "dropped-table", f"Largest coupling terms dropped (top {TOP_DROPPED} of A and of B; "
                             f"{len(dec.dropped)} in all)",
            ("term", "matrix", "value", "unit", "|value| / max|matrix|"),
            tuple((d.name, d.matrix, f"{d.value:.4g}", d.unit, f"{d.relative:.2e}") for d in dropped),
            caption="d(w)/d(theta) reads: the derivative of dw/dt with respect to theta.", align="llrlr"))
    else:
        blocks.insert(0, Text("The partition drops no coupling term: the subsystems are exactly decoupled."))
    return Section("decoupling", "Decoupling", tuple(blocks))


def checks(ws) -> Section:
    report = ws.checks
    regulated = {s.name for s in ws.decoupled.regulated}
    rows = []
    for name, c in report.checks.items():
        label = name if name == "full" or name in regulated else f"{name}*"
        rows.append((label, f"{c.ctrb.rank}/{c.n}", f"{c.obsv.rank}/{c.n}", f"{c.ctrb.tolerance:.0e}",
                     yes(c.controllable), yes(c.observable), yes(c.stabilizable), yes(c.detectable)))
    failed = [n for n in regulated if not report.checks[n].stabilizable]
    blocks = [Text("Every regulated subsystem is stabilizable." if not failed else
                   "Not stabilizable: " + "; ".join(
                       f"{n} (mode {eig(report.checks[n].unstabilizable_modes[0].eigenvalue)} in "
                       f"{', '.join(report.checks[n].unstabilizable_modes[0].states)})" for n in failed),
                   "ok" if not failed else "fail"),
              Table("checks-table", "Controllability and observability",
                    ("system", "ctrb rank", "obsv rank", "tol", "controllable", "observable", "stabilizable",
                     "detectable"), tuple(rows),
                    caption=f"Kalman matrix rank by SVD, counting singular values > tol = max(shape) * eps * "
                            f"sigma_max (eps = {np.finfo(float).eps:.3g}); verdicts by PBH at each eigenvalue; "
                            "stable means Re < 0; * analysed only.", align="lrrrllll")]
    if report.rate is not None:
        if report.rate_warnings:
            blocks.append(Text(f"Rate warnings: the continuous design run at {report.rate:g} Hz.", "warning"))
            blocks.append(Items(tuple(w.message(report.rate) for w in report.rate_warnings)))
        else:
            blocks.append(Text(f"Controller rate {report.rate:g} Hz: no rate warning (every loop it closes is "
                               "slow enough for it, or the design is discrete at that rate)."))
    if report.vehicle_loop is not None:
        loop = report.vehicle_loop
        blocks.append(Text(loop.summary()[0].upper() + loop.summary()[1:] + ".", "ok" if loop.stable else "fail"))
    return Section("checks", "Checks", tuple(blocks))


def _plant_and_timing(ws) -> Text:
    """The rotors' lag, what the design does with it, and the delay: one sentence."""
    tau, delay, timing = ws.setup.rotor_time_constant, ws.setup.timing.delay_samples, ws.setup.timing
    if tau is None:
        lag = "Rotors: instantaneous (no motors.time_constant)"
    elif ws.setup.rotor_lag == "include":
        lag = (f"Rotor time constant {tau * 1e3:.4g} ms (motors.time_constant), included in the design "
               "(controller.rotor_lag: include: each input lags in the design model; the controller feeds back "
               "its own model of the lag through Kv)")
    else:
        lag = (f"Rotor time constant {tau * 1e3:.4g} ms (motors.time_constant), ignored by the design "
               "(controller.rotor_lag: ignore): only the simulated plant and the margins have it")
    if delay:
        when = f"{delay} sample{'s' if delay > 1 else ''} ({delay * timing.sample_time * 1e3:.4g} ms)"
        dl = f"delay {when} from measurement to actuation (controller.delay), in the simulation and the margins"
    else:
        dl = "no delay (controller.delay)"
    return Text(f"{lag}; {dl}.")


def design(ws) -> Section:
    des = ws.design
    blocks = [_plant_and_timing(ws)]
    if des.rate:
        blocks.append(Text(f"Discrete design at {des.rate:g} Hz (lqrd: ZOH plant, cost integrated over "
                           f"{1e3 / des.rate:.4g} ms); eigenvalues shown as ln(z)/Ts in rad/s."))
    weights_rows, gain_rows = [], []
    for s in des.subsystems:
        states = " ".join(s.states) + ("" if not s.integral else " + int " + " ".join(s.integral))
        weights_rows.append((s.name, states, " ".join(s.inputs), weights(s.Q), weights(s.R)))
        gain_rows.append((s.name, vector(s.K), "-" if s.Ki is None else vector(s.Ki),
                          *([vector(s.Kv)] if des.lag_time_constant is not None else []), eigs(s.eigenvalues),
                          f"{s.residual:.1e}"))
    lagged = des.lag_time_constant is not None
    blocks.append(Table("weights-table", "LQR weights per subsystem (cost: integral of x'Qx + u'Ru)",
                        ("subsystem", "states", "input", "Q", "R"), tuple(weights_rows), align="lllll"))
    blocks.append(Table("design-table", "Gains per subsystem (u = -K x, K = R^-1 B' P)",
                        ("subsystem", "K", "Ki", *(["Kv"] if lagged else []), "closed-loop eigenvalues (rad/s)",
                         "Riccati residual"),
                        tuple(gain_rows),
                        caption="Ki: the gain on the integral of the error (LQI). "
                                + ("Kv: the gain on the lag states (the inputs the rotors reach, from trim). "
                                   if lagged else "")
                                + "Riccati residual: relative residual of the Riccati equation at the solution P "
                                  "(0 for an exact solution).",
                        align="llllwr" if lagged else "lllwr"))
    cols = list(STATE_NAMES) + [f"int {s}" for s in des.integral_states]
    K = np.hstack([des.K_block, des.Ki_block]) if des.integral_states else des.K_block
    blocks.append(Table("kblock-table", "K_block: a row per input, a column per state (0 is an exact zero)",
                        ("input", *cols), tuple((name, *(f"{K[j, i]:.4g}" for i in range(K.shape[1])))
                                                for j, name in enumerate(INPUT_NAMES))))
    marginal = f" (marginal by design: {', '.join(des.marginal_states)})" if des.marginal_states else ""
    ordered = sorted(des.full_eigenvalues, key=lambda z: (z.real, z.imag))
    if des.stable:
        blocks.append(Text(f"Stable on the coupled 12-state linear model{marginal}; slowest pole "
                           f"{max(e.real for e in des.core_eigenvalues):.3g} rad/s.", "ok"))
    else:
        blocks.append(Text("Every subsystem is stable alone, but the assembled gain is UNSTABLE on the coupled "
                           "12-state model (the dropped couplings matter).", "fail"))
    blocks.append(Text(f"Closed-loop eigenvalues of A - B K_block on the coupled model (rad/s): {eigs(ordered)}."))
    blocks.extend(_estimator(ws))
    return Section("design", "Design", tuple(blocks))


def _estimator(ws) -> tuple:
    """The Kalman filter of an LQG config: what it measures, its form and its eigenvalues."""
    from quadctl import pipeline

    kal = pipeline.estimator_of(ws.setup, ws.linear)
    if kal is None:
        return ()
    est = ws.setup.estimator
    if kal.discrete:
        form = (f"the discrete filter at {1 / kal.sample_time:g} Hz (MATLAB dlqe conventions): the gain is the "
                "filter (measurement-update) gain M, x_hat[k|k] = x_hat[k|k-1] + M (y[k] - C x_hat[k|k-1]); the "
                "law acts on x_hat[k|k]; eigenvalues of Ad - Ad M C shown as ln(z)/Ts in rad/s")
        shown = np.log(kal.eigenvalues.astype(complex)) / kal.sample_time
    else:
        form = "the Kalman-Bucy filter (MATLAB lqe): dx_hat/dt = A x_hat + B du + L (y - C x_hat)"
        shown = kal.eigenvalues
    rows = tuple((name, unit_of(name), num(std)) for name, std in zip(est.measured, est.sensor_std))
    return (Text(f"The law closes through a steady-state Kalman filter (LQG), {form}; Riccati residual "
                 f"{kal.residual:.1e}."),
            Table("estimator-table", "What the filter measures (estimator.measure)", ("state", "unit", "noise std"),
                  rows, caption="Process noise: body force std " + vector(est.process_std[:3]) + " N, torque std "
                  + vector(est.process_std[3:]) + " N m.", align="llr"),
            Text(f"Estimator eigenvalues (rad/s): {eigs(sorted(shown, key=lambda z: (z.real, z.imag)))}."))


def margins(ws) -> Section:
    from quadctl import plots

    loops = ws.margins
    rate = ws.setup.timing.rate
    kind = f"sampled at {rate:g} Hz (L(z), hold included)" if rate else "continuous (L(s))"
    classic, disk = [], []
    for m in loops:
        lo, hi = m.gain_margin_db
        at = " / ".join(num(w, 3) for w in m.phase_crossover_freqs if w is not None) or "-"
        loop = f"{m.loop} ({m.input})"
        classic.append((loop, m.model, f"{db(lo)} / {db(hi)}", at, num(m.phase_margin_deg, 3),
                        num(m.gain_crossover_freq, 3)))
        d_lo, d_hi = m.disk_gain_db
        symmetric = d_lo is not None and d_hi is not None and abs(d_lo + d_hi) < 1e-6 * max(1.0, abs(d_hi))
        verdict = "met" if m.meets_lqr_guarantee else ("unstable" if not m.stable else "short")
        disk_gm = f"±{abs(d_hi):.3g}" if symmetric else f"{db(d_lo)} / {db(d_hi)}"
        disk.append((loop, m.model, num(m.disk_alpha, 3), disk_gm, num(m.disk_phase_deg, 3),
                     num(m.min_return_difference, 3), verdict))
    met = sum(m.meets_lqr_guarantee for m in loops)
    unstable = [f"{m.loop} ({m.model})" for m in loops if not m.stable]
    blocks = [
        Text(f"Each regulated loop broken at its plant input, {kind}, on the subsystem it was designed on "
             f"(design) and on the coupled model with the other loops closed (coupled): {met} of {len(loops)} "
             "meet the continuous LQR guarantee (gain margin -6.02 dB to infinity, phase margin >= 60 deg)."),
        Table("margins-table", f"Stability margins; {kind}", ("loop", "model", "GM dB", "at rad/s", "PM deg",
                                                               "at rad/s"), tuple(classic),
              caption="GM: lower / upper gain margin in dB ('-' is infinite), at the phase crossovers; PM at the "
                      "gain crossover.", align="llrrrr"),
        Table("disk-table", "Disk margins and the continuous LQR guarantee",
              ("loop", "model", "alpha", "disk GM dB", "disk PM deg", "min|1+L|", "guarantee"), tuple(disk),
              caption="Continuous LQR guarantees GM <= -6.02 / inf dB, PM >= 60 deg, |1+L| >= 1.",
              align="llrrrrl"),
    ]
    blocks.insert(0, _plant_and_timing(ws))
    blocks.append(Table(
        "delay-margin-table", "Delay margins: the extra delay each loop tolerates (PM / crossover frequency)",
        ("loop", "model", "configured delay (samples)", "delay margin ms", "samples"),
        tuple((f"{m.loop} ({m.input})", m.model, str(m.delay_samples),
               num(None if m.delay_margin is None else m.delay_margin * 1e3, 3), num(m.delay_margin_samples, 3))
              for m in loops),
        caption="Beyond the configured delay (controller.delay), already in every loop; '-': |L| never crosses 1.",
        align="llrrr"))
    if unstable:
        blocks.append(Text(f"Unstable loop(s): {', '.join(unstable)}.", "fail"))
    notes = _margin_notes(loops)
    if notes:
        blocks.append(Items(notes))
    shown = {m.loop: m for m in loops if m.model == "design"}
    shown.update({m.loop: m for m in loops if m.model == "coupled"})  # the coupled loop where there is one
    for m in shown.values():
        fig = plots.margins_figure(m, title=ws.setup.name)
        blocks.append(Figure(f"margins-{m.loop}", f"Bode and Nyquist plots of the {m.loop} loop broken at "
                                                  f"{m.input} ({m.model} model).", _png(fig, MARGINS_DPI)))
    return Section("margins", "Margins", tuple(blocks))


def _margin_notes(loops) -> tuple[str, ...]:
    """Each loop's notes; a coupled loop's only where they differ from its design loop's (numbers aside)."""
    import re

    def shape(notes):
        return tuple(re.sub(r"[-+]?\d[\d.e+-]*", "#", n) for n in notes)

    design = {(m.loop, m.input): shape(m.notes) for m in loops if m.model == "design"}
    lines = [f"{m.loop} ({m.model}, {m.input}): {note}" for m in loops
             if not (m.model == "coupled" and design.get((m.loop, m.input)) == shape(m.notes)) for note in m.notes]
    if lines and any(m.model == "coupled" for m in loops):
        lines.append("Coupled loops not listed read as their design loops (the same verdict and causes).")
    return tuple(lines)


def simulation(ws) -> Section:
    from quadctl import plots

    flown = ws.simulation
    sim, metrics, plan = flown.sim, flown.metrics, flown.sim.plan
    how = "auto" if plan.auto else "given"
    blocks = [Text(
        f"Fixed-step RK4 of the full nonlinear closed loop: dt = {sim.dt:.4g} s ({how}; stable up to "
        f"{plan.max_stable_dt:.4g} s, fastest eigenvalue {eig(plan.fastest_eigenvalue)} rad/s in "
        f"{plan.fastest_owner}), {sim.steps} steps to t = {float(sim.t[-1]):.4g} s, {sim.backend} loop.")]
    ctl = flown.flight["controller"]
    if ctl.get("rate"):
        blocks.append(Text(f"Controller: {ctl['design']} design at {ctl['rate']:g} Hz, zero-order hold: one "
                           f"sample every {ctl['hold_steps']} RK4 steps."))
    blocks.append(Text(f"{sim.status}: {sim.message}", "ok" if sim.status == "ok" else "fail"))
    rows = tuple((n, unit_of(n), num(metrics["settling_time"].get(n)), num(metrics["overshoot"].get(n), 3),
                  num(metrics["peak_error"][n]), num(metrics["final_error"][n])) for n in STATE_NAMES)
    blocks.append(Table("metrics-table", "Closed-loop response (error from the reference)",
                        ("state", "unit", "settling (s)", "overshoot (%)", "peak |error|", "final error"), rows,
                        caption="Settling: within 2 % of the state's largest error; '-' never settled, or the state "
                                "is not regulated.", align="llrrrr"))
    u_trim = ws.linear.u_trim
    peak_delta = flown.flight["peak_delta"]
    blocks.append(Table("inputs-table", "Inputs", ("input", "unit", "trim", "peak magnitude", "peak |u - u_trim|"),
                        tuple((n, unit_of(n), num(u_trim[j]), num(metrics["peak"][n]), num(peak_delta[n]))
                              for j, n in enumerate(INPUT_NAMES)), align="llrrr"))
    blocks.append(Text(f"Cost of the run, integral of e'Qe + du'R du dt: {num(metrics['cost'])}."))
    for name, fig in plots.simulation_figures(sim, ws.setup.partition, u_trim, title=ws.setup.name).items():
        what = "the four inputs against time, trim dashed" if name == "inputs" else \
            "the wind the plant felt against time (NED, m/s)" if name == "wind" else \
            f"the {name} subsystem's states and their reference against time (angles in degrees)"
        blocks.append(Figure(f"sim-{name}", f"Simulation: {what}.", _png(fig, SIM_DPI)))
    return Section("simulation", "Simulation", tuple(blocks))


def flight(ws) -> Section:
    flown = ws.simulation
    fl = flown.flight
    blocks = []
    sat = fl.get("saturation")
    u_trim = ws.linear.u_trim
    if sat:
        motors = sat["mode"] == "motors"
        trims = sat["trim_rotor_thrust"] if motors else list(u_trim)
        rows = []
        for i, name in enumerate(sat["actuators"]):
            unit = "N" if motors else unit_of(name)
            lo, hi, trim_i = sat["low"][i], sat["high"][i], trims[i]
            peak, low_cmd = sat["peak_command"][name], sat["min_command"][name]
            up = (peak - trim_i) / (hi - trim_i) if math.isfinite(hi) and hi > trim_i else None
            down = (trim_i - low_cmd) / (trim_i - lo) if math.isfinite(lo) and trim_i > lo else None
            row = [name, f"{num(lo)} to {num(hi)} {unit}", num(trim_i), f"{num(low_cmd)} / {num(peak)}",
                   f"{_percent(up)} / {_percent(down)}", f"{sat['fraction'][name] * 100:.3g} %"]
            if motors:
                row.append(num(sat["peak_rotor_speed"][name]))
            rows.append(tuple(row))
        cols = ["actuator", "limits", "trim", "min / max command", "headroom used up / down", "time at a limit"]
        cols += ["peak speed (rad/s)"] if motors else []
        blocks.append(Table(
            "headroom-table", "Rotor thrusts against their limits (mix, clip, unmix)" if motors else
            "Inputs against their box limits", tuple(cols), tuple(rows),
            caption="Headroom used: the share of the range from the trim to the limit that the largest command "
                    "(up) and the smallest (down) take; 100 % is at the limit, where the command is clipped. "
                    f"Flagged when an actuator is at a limit more than {sat['flag_above'] * 100:g} % of the run.",
            align="ll" + "r" * (len(cols) - 2)))
        if sat["saturates"]:
            worst = max(sat["fraction"], key=sat["fraction"].get)
            blocks.append(Text(f"The design saturates: {worst} is at a limit {sat['fraction'][worst] * 100:.3g} % "
                               "of the run; lower the gains (larger R) or the initial offset.", "warning"))
        else:
            blocks.append(Text("No actuator is at a limit for long: the design flies within its actuators.", "ok"))
    else:
        peaks = ", ".join(f"{n} {num(fl['peak_delta'][n])} {unit_of(n)}" for n in INPUT_NAMES)
        blocks.append(Text(f"No actuator limits in this config (motors: or limits:): the inputs are not clipped. "
                           f"Peak |u - u_trim|: {peaks}."))
    noise = fl.get("noise")
    title = (f"RMS deviation from the reference, with noise (seed {noise['seed']})" if noise else
             "RMS deviation from the reference (no noise: the deterministic run)")
    blocks.append(Table("rms-table", title, ("state", "unit", "whole run", "second half"),
                        tuple((n, unit_of(n), num(fl["rms_error"][n]), num(fl["rms_error_second_half"][n]))
                              for n in STATE_NAMES), align="llrr"))
    est = fl.get("estimation")
    if est:
        blocks.append(Table(
            "estimation-table",
            f"Estimation error x - x_hat ({est['form']} form; measured: {' '.join(est['measured'])})",
            ("state", "unit", "RMS whole run", "RMS second half", "predicted std"),
            tuple((n, unit_of(n), num(est["rms_error"][n]), num(est["rms_error_second_half"][n]),
                   num(est["predicted_std"][n])) for n in STATE_NAMES),
            caption="Predicted: the steady Kalman covariance (a priori for a sampled filter), for the noise the "
                    "filter assumes.", align="llrrr"))
    wind = fl.get("wind")
    if wind:
        from quadctl.pipeline import wind_line

        line = wind_line(wind)
        blocks.append(Text(line[0].upper() + line[1:] + "."))
        blocks.append(Table("speeds-table", "Ground speed and airspeed", ("speed", "unit", "max", "RMS"),
                            tuple((label, "m/s", num(wind[key]["max"]), num(wind[key]["rms"]))
                                  for key, label in (("ground_speed", "ground speed"), ("airspeed", "airspeed"))),
                            align="llrr"))
    ints = fl["integral"]
    if ints["states"]:
        parts = ", ".join(f"integral of {s} = {num(v)}" for s, v in ints["final"].items())
        blocks.append(Text(f"Integral action (LQI, anti-wind-up by conditional integration): final {parts}."))
    if fl.get("plant"):
        blocks.append(Text("Simulated plant differs from the design model: " + ", ".join(
            f"{k} = {v}" for k, v in fl["plant"].items()) + "."))
    return Section("flight", "Flight numbers", tuple(blocks))


def software(meta: dict, command_line: str, out) -> Section:
    sw = meta.get("software", {})
    rows = [(name, version) for name, version in sw.items()]
    comp = meta.get("compiler")
    compiler = (f"{comp['path']}: {comp['version']}" if isinstance(comp, dict) else
                {"none": "none: the loop ran in CasADi's virtual machine",
                 "not used": "not used: no closed loop was simulated"}.get(comp, str(comp)))
    rows.append(("C compiler", compiler))
    return Section("software", "Software and command", (
        Table("software-table", "Software versions", ("component", "version"), tuple(rows), align="ll"),
        Items((f"Command line: {command_line}", f"Run folder: {out}", f"quadctl {meta.get('quadctl_version')}, "
               f"artifact format {meta.get('format_version')}, created {meta.get('created')} (UTC)")),
    ))
