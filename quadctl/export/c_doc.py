"""The exported C header's documentation comments: the paragraphs that say what the generated
controller does (its gain schedule, the rotors' lag, the Kalman filter, the gyro filter, the delay)
and the tables of its state and input, each written from the loop it documents.

:func:`quadctl.export.c.sources` fills the header template (``templates/quadctl_controller.h``) with them.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np

from quadctl.design.gain_table import OUTSIDE, VARIABLES
from quadctl.layout import N_STATES, STATE_UNITS
from quadctl.text.escape import c_comment


def doc_lines(lines) -> str:
    """Lines of a header comment (each wrapped at 94 columns, keeping its indent)."""
    out = []
    for line in lines:
        indent = " " * (len(line) - len(line.lstrip(" ")))
        out += textwrap.wrap(line, 94, subsequent_indent=indent) or [""]
    return "\n".join((" *   " + line).rstrip() for line in out)


def schedule_doc(loop, reference: bool) -> str:
    """The header's paragraph on the gain schedule: the table, where it lives, how the law reads it."""

    table = loop.schedule
    if table is None:
        return " *   None: the gains are constants (K, Ki in qc_c)."
    unit = VARIABLES[table.variable]
    pieces, columns = len(table.breaks) - 1, table.coefficients.shape[-1]
    read = {"speed": f"the horizontal velocity of x_ref(t) along the heading {loop.schedule_heading:g} rad (m/s)"
                     + (", turned with the reference's yaw (its yaw less the trim's added)" if reference else ""),
            "climb": "the climb rate of x_ref(t), -vD (m/s, up positive)",
            "yaw": "the yaw psi of x_ref(t) (rad)"}[table.variable]
    source = "ref->x, the reference given" if reference else "x_trim + x_rate t"
    text = (f"The gains are scheduled on {table.variable} ({unit}): designs at v = "
            + ", ".join(f"{v:g}" for v in table.values)
            + f" {unit}, {table.interpolation} interpolation between them; outside them {OUTSIDE}. v is {read}, "
            f"x_ref(t) being {source}: the gain moves with the command, not with the measured state. "
            f"G(v) (4 x {columns}: K" + (", then Ki" if columns > N_STATES else "") + ") replaces the constant "
            f"gain{'s' if columns > N_STATES else ''} of the law: the piecewise cubic G(v) = sum_k "
            "schedule_coefficients[k, i] (v - schedule_breaks[i])^(3 - k) on the piece i with schedule_breaks[i] "
            f"<= v < schedule_breaks[i + 1] (v held to [{table.breaks[0]:g}, {table.breaks[-1]:g}]), {pieces} "
            f"pieces, its breaks and coefficients ({4} x {pieces} x 4 x {columns}, column-major) constants of qc_c "
            "(quadctl.design.gain_table.GainTable, the one `quadctl simulate` flies). qc_law evaluates it at "
            "each sample.")
    return "\n".join(" *   " + line for line in textwrap.wrap(c_comment(text), 94))


def lag_doc(loop, Ts: float) -> str:
    """The header's paragraph on the rotors' lag: what the law does with it."""
    tau = loop.lag_model_time_constant
    if loop.Kv is None:
        lines = ["The design ignores the rotors' lag (controller.rotor_lag: ignore): no lag state here; the",
                 "simulation's rotors lag by motors.time_constant if the config sets one."]
    else:
        a = math.exp(-Ts / tau)
        lines = [f"The design includes the rotors' {tau:g} s lag (controller.rotor_lag: include). The controller",
                 "does not measure the thrust the rotors reach: it keeps a model of it, l (the struct's l[], the",
                 "deviation of [T, A, E, R] from trim), advanced each sample from the command it returns by the",
                 f"lag's exact zero-order hold, l <- a l + (1 - a)(u - u_trim), a = exp(-Ts/tau) = {a:.9g}, and",
                 "fed back through Kv. quadctl_init starts it at 0: the rotors at their trim thrust."]
    return "\n".join(" *   " + line for line in lines)


def filter_doc(loop, step: str, reference: bool = False) -> str:
    """The header's paragraph on the Kalman filter: its form, the measurements, one sample of it
    (``step``: the C function a sample calls; ``reference``: the law flies a reference, its filter
    predicts about ``u_ref(t)``)."""
    kal = loop.estimator
    if kal is None:
        lines = [f"None (no estimator: in the config): {step} takes the full measured state x."]
        return "\n".join(" *   " + line for line in lines)
    rho = float(np.max(np.abs(kal.eigenvalues)))
    ne, ng = kal.n_estimate, kal.n_estimate - N_STATES
    gyro = ([] if kal.rate_filter is None else textwrap.wrap(
        f"The filter's model includes the gyro filter (controller.filters: {kal.rate_filter.describe()}): xh[] is "
        f"the estimate of [x - x_ref(t); g] (QUADCTL_NE = {ne}: the 12 states, then the gyro filter's {ng}, "
        f"as the g member), and a measured rate is the filtered rate the law computes from the raw gyro "
        f"(give y the raw rates), predicted as c g_h + d r_h: those rows of C read the filter's states.", 94))
    lines = ["The law closes through a steady-state Kalman filter (estimator:), the discrete one of the",
             "zero-order-hold model at Ts in MATLAB dlqe's filter form (design.json estimator, form filter):",
             "Le = M is the filter (measurement-update) gain, the struct's xh[] the a priori estimate",
             "x_hat[k|k-1] of the deviation x - x_ref(t) (state units, the order of x), 0 after quadctl_init",
             "(the filter believes the trim, as `quadctl simulate` starts it). Each sample, with y the",
             "measured states (QUADCTL_Y_*: absolute, in state units, as the sensors give them):",
             "  xc = xh + M (y - C x_ref(t) - C xh)        update: x_hat[k|k]",
             "  u  = the law above with x - x_ref(t) = xc  (the integrators integrate xc too)",
             f"  xh <- Ae xc + Be (u_applied - {'u_ref(t)' if reference else 'u_trim'})".ljust(45)
             + "predict: x_hat[k+1|k] under the applied (clipped)",
             "                                             command" + (", the one the vehicle applies now (b[])"
                                                                       if loop.delay_samples else ""),
             *gyro,
             *textwrap.wrap(f"C picks the measured states; Ae ({ne} x {ne}), Be ({ne} x 4) and Le = M ({ne} x ny) "
                            "are constants of qc_c (column-major). The predictor gain is Ae M; the estimator's "
                            f"eigenvalues (of Ae - Ae M C) have |z| <= {rho:.6g}. Measured, in the order of y: "
                            + ", ".join(f"{n} ({STATE_UNITS[n]})" for n in kal.measured) + ".", 94)]
    return "\n".join(" *   " + line for line in lines)


def gyro_doc(loop, Ts: float, upstream: str | None = None) -> str:
    """The header's paragraph on the gyro filter (controller.filters): what the law does to the rates;
    ``upstream``, the config's filter and who runs it before the law (the flight stack's sensor driver)."""
    if upstream is not None:
        return doc_lines([f"The config's gyro filter (controller.filters: {upstream}) is the vehicle's: the "
                          "simulation and the margins have it in the loop, and the flight stack runs it before the "
                          "law. The law takes the rates p, q, r as the stack gives them, filtered; it does not "
                          "filter them again."])
    if loop.rate_filter is None:
        return doc_lines([
            "No gyro filter was configured (controller.filters): the law takes the measured rates p, q, r",
            "as they are; filter them before quadctl_step only if the simulation did."])
    form = loop.filter_form
    return doc_lines([f"The law runs the config's gyro filter (controller.filters: {loop.rate_filter.describe()}) "
                 f"on the measured rates p, q, r, at {1 / Ts:g} Hz: y = c g + d r, g <- A g + b r on each rate "
                 f"(the g member, {form.order} states per rate; qc_c's filter_A, filter_b, filter_c, filter_d), "
                 "and uses y in place of r, as `quadctl simulate` does. Give quadctl_step the raw gyro rates: do "
                 "not filter them again."])


def delay_doc(delay: int, Ts: float, filtered: bool = False) -> str:
    """The header's paragraph on the delay: the law is the law before it."""
    if delay and filtered:
        n = f"{delay} sample{'s' if delay > 1 else ''}"
        lines = [f"The config's controller.delay, {n} ({delay * Ts:.6g} s) from measurement to actuation, is",
                 "the vehicle's (its computer, bus and ESCs): quadctl_step returns the new command at once, and",
                 f"`quadctl simulate` applies each command {n} later. The Kalman filter must predict with what",
                 f"the vehicle applies, so the struct remembers the commands of the last {n} (b[], starting at",
                 "u_trim) for the filter only. Do not add a buffer to u: the vehicle has the delay already."]
        return "\n".join(" *   " + line for line in lines)
    if not delay:
        lines = ["No delay was configured (controller.delay): the simulation applies u at the instant x is",
                 "measured."]
    else:
        n = f"{delay} sample{'s' if delay > 1 else ''}"
        lines = [f"The config's controller.delay, {n} ({delay * Ts:.6g} s) from measurement to actuation, is",
                 "the vehicle's (its computer, bus and ESCs), not part of this law: quadctl_step returns the",
                 f"command at once, and `quadctl simulate` applies each command {n} later (a buffer starting",
                 "at u_trim). Do not add a buffer here: the vehicle has the delay already."]
    return "\n".join(" *   " + line for line in lines)


def vector_table(names, units, trim, rate, symbol: str) -> str:
    """The header's table of a vector (``symbol`` x or u): each entry's index, name, unit and trim, and
    its drift when ``rate`` gives one."""
    rows = []
    for i, name in enumerate(names):
        drift = f", drifting {rate[i]:+.6g} {units[name]}/s" if rate is not None and rate[i] != 0 else ""
        rows.append(f" *   {symbol}[{i:2d}] {name:<6} {units[name]:<6} trim {trim[i]:+.9g}{drift}")
    return "\n".join(rows)
