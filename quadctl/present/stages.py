"""The first stages as rows and sentences: the trim, the decoupling, controllability and observability,
and the check stage's verdicts (rate warnings, the loop the vehicle flies, why the check fails)."""

from __future__ import annotations

import math

import numpy as np

from quadctl.design.discrete import SAMPLES_PER_POLE
from quadctl.layout import INPUT_NAMES, STATE_INDEX, STATE_NAMES, unit_of
from quadctl.linear import stability
from quadctl.present import design, flight, loops
from quadctl.present.cells import Mark, Table, eig, eigs, num, vector, yes

TOP_DROPPED = 8
"""Dropped coupling terms listed, per matrix (A, B), largest first."""


def trim_tables(trim) -> tuple[Table, Table]:
    """The state (value, unit, residual dx/dt) and the input at the trim; values with 6 digits."""
    states = tuple((n, f"{trim.x[i]:.6g}", unit_of(n), num(trim.xdot[i], 3)) for i, n in enumerate(STATE_NAMES))
    inputs = tuple((n, f"{trim.u[j]:.6g}", unit_of(n)) for j, n in enumerate(INPUT_NAMES))
    return (Table("trim-state-table", "State at the trim", ("state", "value", "unit", "dx/dt"), states,
                  caption="dx/dt: the residual; the positions move at the flight velocity.", align="lrlr"),
            Table("trim-input-table", "Input at the trim", ("input", "value", "unit"), inputs, align="lrl"))


def trim_sentence(trim, velocity_ned) -> str:
    """The equilibrium in one sentence: velocity, thrust, pitch, residual, iterations."""
    return (f"Equilibrium at velocity_ned {vector(velocity_ned)} m/s: thrust T = {trim.u[0]:.6g} N, pitch theta = "
            f"{trim.x[7]:.6g} rad. Residual max|dx/dt| = {trim.residual:.2e} (non-position states) after "
            f"{trim.iterations} Newton iterations.")


def subsystems_table(dec) -> Table:
    rows = tuple((s.name, " ".join(s.states), " ".join(s.inputs) + ("" if s.regulated else " (from A)"),
                  yes(s.regulated), eigs(np.linalg.eigvals(s.A))) for s in dec.subsystems)
    return Table("subsystems-table", "Subsystems (diagonal blocks of A, matching columns of B)",
                 ("subsystem", "states", "inputs", "regulated", "open-loop eigenvalues (rad/s)"), rows,
                 align="llllw")


def dropped_table(dec, top: int = TOP_DROPPED) -> Table:
    dropped = [d for kind in ("A", "B") for d in [d for d in dec.dropped if d.matrix == kind][:top]]
    return Table("dropped-table", f"Largest coupling terms the partition drops (top {top} of A and of B; "
                                  f"{len(dec.dropped)} in all)",
                 ("term", "matrix", "value", "unit", "|value| / max|matrix|"),
                 tuple((d.name, d.matrix, f"{d.value:.4g}", d.unit, f"{d.relative:.2e}") for d in dropped),
                 caption="d(w)/d(theta) reads: the derivative of dw/dt with respect to theta.", align="llrlr")


def dropped_sentence(dec) -> str:
    """How much the partition drops: the largest term against its matrix."""
    if not dec.dropped:
        return "The partition drops no coupling term: the subsystems are exactly decoupled."
    worst = max(dec.dropped, key=lambda d: d.relative)
    return (f"The partition drops {len(dec.dropped)} coupling terms of A and B; the largest, {worst.name} = "
            f"{worst.value:.4g} {worst.unit}, is {worst.relative * 100:.3g} % of the largest entry of "
            f"{worst.matrix}. The design is checked on the coupled model.")


def checks_table(checks: dict, regulated) -> Table:
    """A row per subsystem (``*``: analysed only) and the full model: ranks, tolerance, verdicts."""
    rows = []
    for name, c in checks.items():
        label = name if name == "full" or name in regulated else f"{name}*"
        rows.append((label, f"{c.ctrb.rank}/{c.n}", f"{c.obsv.rank}/{c.n}", f"{c.ctrb.tolerance:.0e}",
                     f"{c.controllable_dim}, {c.observable_dim}",
                     yes(c.controllable), yes(c.observable), yes(c.stabilizable), yes(c.detectable)))
    return Table("checks-table", "Controllability and observability",
                 ("system", "ctrb", "obsv", "tol", "staircase", "controllable", "observable", "stabilizable",
                  "detectable"),
                 tuple(rows), caption="ctrb/obsv: Kalman matrix rank by SVD, counting singular values > tol = "
                 f"max(shape) * eps * sigma_max (eps = {np.finfo(float).eps:.3g}); staircase: the dimensions of "
                 "the controllable and the observable subspace, by orthogonal transformations; verdicts by PBH at "
                 "each eigenvalue and by the staircase (a mode either finds out of reach or sight counts); a mode "
                 f"is unstable when {stability.criterion()}; * analysed only", align="lrrrrllll")


def stabilizable_sentence(checks: dict, regulated) -> Mark:
    failed = [n for n in regulated if not checks[n].stabilizable]
    if not failed:
        return Mark("Every regulated subsystem is stabilizable.", "ok")
    return Mark("Not stabilizable: " + "; ".join(
        f"{n} (mode {eig(checks[n].unstabilizable_modes[0].eigenvalue)} in "
        f"{', '.join(checks[n].unstabilizable_modes[0].states)})" for n in failed), "fail")


CHECKS_PASSED = "every regulated subsystem stabilizable"
"""A passed check stage in one line (``quadctl run``, the report's summary)."""
UNSTABLE_DESIGN = "unstable on the coupled 12-state model"
"""Why ``run``, ``report`` and ``export`` stop after the design stage."""


def unstable_cascade_text(title: str, radius: float, frame_s: float) -> str:
    """Why a flight of a PID cascade (``controller.flies: pid``) fails although its run may have ended: the
    cascade's closed loop about hover, lifted to its ``frame_s`` s frame, has spectral ``radius`` >= 1."""
    growth = (f"a mode that doubles every {frame_s * math.log(2) / math.log(radius):.3g} s" if radius > 1
              else "a mode that does not decay")
    return (f"the PID cascade ({title}) is unstable about hover: its closed loop, linearized and lifted to its "
            f"{frame_s * 1e3:.3g} ms frame, has spectral radius {radius:.5g} ({growth}); a run that ended has "
            "not grown yet. quadctl margins shows each of its loops")


def unstable_cascade_gate(radius: float, frame_s: float) -> str:
    """A sweep case's failure for a PID cascade unstable about hover (:func:`unstable_cascade_text`, short)."""
    return f"the PID cascade is unstable about hover (spectral radius {radius:.5g} per {frame_s * 1e3:.3g} ms frame)"


def trim_summary(trim) -> str:
    """The trim in one line: ``T = 0.6522 N, phi = 0.0000 rad, theta = -0.2119 rad, residual 1.6e-15``."""
    phi, theta = trim.x[STATE_INDEX["phi"]], trim.x[STATE_INDEX["theta"]]
    return f"T = {trim.u[0]:.4f} N, phi = {phi:.4f} rad, theta = {theta:.4f} rad, residual {trim.residual:.1e}"


def decouple_summary(dec) -> str:
    """``5 subsystems, 10 terms dropped``."""
    n_subs, n_dropped = len(dec.subsystems), len(dec.dropped)
    return f"{n_subs} subsystem{'s' if n_subs != 1 else ''}, {n_dropped} term{'s' if n_dropped != 1 else ''} dropped"


def stage_summary(ws, stage: str) -> str:
    """A stage's result in one line, as ``quadctl run`` ticks it off and the report's summary lists it."""

    if stage == "trim":
        return trim_summary(ws.trim)
    if stage == "linearize":
        return f"A {ws.linear.A.shape}, B {ws.linear.B.shape}"
    if stage == "decouple":
        return decouple_summary(ws.decoupled)
    if stage == "check":
        return CHECKS_PASSED
    if stage == "design":
        return design.summary(ws.design)
    if stage == "margins":
        return loops.summary(ws.margins, discrete=ws.setup.law == "pid" or ws.design.rate is not None)
    sim = ws.simulation.sim
    return (f"{sim.steps} {flight.integrator_name(sim)} steps, {flight.step_span(sim)}, "
            f"{sim.steps_per_second / 1e6:.2f} M steps/s")


# ---------------------------------------------------------------------------------------
# The check stage's verdicts in words: the rate warnings, the loop the vehicle flies, the failures


def rate_warning(w, rate: float) -> str:
    """A continuous loop too fast for ``rate`` Hz (:class:`quadctl.design.discrete.RateWarning`) in one line."""

    verdict = "stays stable but its response differs from the design" if w.sampled_stable else "is UNSTABLE"
    return (f"{w.loop}: closed-loop pole {eig(w.pole)} rad/s is {w.factor:.3g}x faster than "
            f"{rate:g} Hz realizes (|s| <= 2 pi rate / {SAMPLES_PER_POLE:g} = {w.limit:.4g} rad/s); "
            f"sampled at {rate:g} Hz this loop {verdict} (spectral radius {w.sampled_radius:.3g}); "
            f"{_design_for_the_rate(rate)}")


def sampled_unstable(warnings, rate: float) -> str | None:
    """The failed-check verdict for the loops of ``warnings`` that are unstable sampled at ``rate`` Hz
    (None when every one is stable): ``check``, ``run`` and ``report`` give this same verdict."""
    unstable = [w.loop for w in warnings if not w.sampled_stable]
    if not unstable:
        return None
    return (f"sampled at {rate:g} Hz the continuous design's loop(s) {', '.join(unstable)} are UNSTABLE; "
            f"{_design_for_the_rate(rate)}")


def _design_for_the_rate(rate: float) -> str:
    """The way out of a continuous design too fast for ``rate``: both keys, since ``controller.design: discrete``
    (the default) alone designs nothing discrete without ``controller.rate``, the case of ``check --rate`` and
    ``export --rate`` on a config that has none."""
    return (f"design for the rate (controller.rate: {rate:g} with controller.design: discrete) "
            "or use smaller gains (larger R)")


def _vehicle_loop_has(loop) -> str:
    parts = []
    if loop.gyro_filter:
        parts.append(f"the gyro's {loop.gyro_filter}")
    if loop.rotor_time_constant is not None:
        how = "included in" if loop.rotor_lag == "include" else "ignored by"
        parts.append(f"the rotors' {loop.rotor_time_constant * 1e3:g} ms lag ({how} the design)")
    if loop.delay_samples:
        parts.append(f"{loop.delay_samples} sample{'s' if loop.delay_samples > 1 else ''} of delay")
    if loop.estimated:
        parts.append("the Kalman filter included (plant and estimator)")
    return " and ".join(parts)


def vehicle_loop_summary(loop) -> str:
    """The loop the vehicle flies (:class:`quadctl.pipeline.VehicleLoop`) in one line: what it has, stable
    or not, and its least damping against the design's."""
    state = "stays stable" if loop.stable else "is UNSTABLE"
    return (f"with {_vehicle_loop_has(loop)} the design's closed loop {state}: least damping "
            f"{loop.least_damping:.3g} ({loop.design_least_damping:.3g} as designed)")


def vehicle_loop_verdict(loop) -> str | None:
    """The failed-check verdict when the vehicle's loop is unstable, with the way out (None when stable)."""
    if loop.stable:
        return None
    fix = ("include the lag in the design (controller.rotor_lag: include), or lower the gains (larger R)"
           if loop.rotor_time_constant is not None and loop.rotor_lag == "ignore"
           else "raise the gyro filter's cutoff (controller.filters) or lower the gains (larger R)"
           if loop.gyro_filter and not loop.delay_samples
           else "lower the gains (larger R) or shorten the delay" if loop.delay_samples or not loop.estimated
           else "measure more states (estimator.measure) or lower the gains (larger R)")
    return f"with {_vehicle_loop_has(loop)} the design's closed loop is UNSTABLE; {fix}"


def check_failures(report) -> list[str]:
    """Each reason the check stage fails (:class:`quadctl.workspace.CheckReport`), one line each (empty when
    it passes): a regulated subsystem not stabilizable, a measured set that leaves a mode that is not stable
    unobservable, a continuous design unstable sampled at the controller rate, a loop the rotors' lag and
    the delay make unstable."""
    out = []
    for name in report.unstabilizable:
        mode = report.checks[name].unstabilizable_modes[0]
        out.append(f"subsystem {name} is not stabilizable: mode {eig(mode.eigenvalue)} in {', '.join(mode.states)}")
    if report.undetectable:
        out.append(report.undetectable)
    sampled = sampled_unstable(report.rate_warnings, report.rate or 0.0)
    if sampled:
        out.append(sampled)
    flown = vehicle_loop_verdict(report.vehicle_loop) if report.vehicle_loop is not None else None
    if flown:
        out.append(flown)
    return out


def check_verdict(report) -> str | None:
    """Why the check stage fails, on one line (None when it passes): ``run`` and ``report`` stop on it;
    ``check`` prints each of :func:`check_failures`."""
    return "; ".join(check_failures(report)) or None
