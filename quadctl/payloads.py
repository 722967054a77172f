"""What each artifact of a run folder holds: a stage's result as the JSON payload (or the ``.npz``
arrays) that :class:`quadctl.workspace.Workspace` writes, with names and units.

One function per artifact, pure (numbers in, a dict out): the workspace decides when to write and
where; :func:`quadctl.artifacts.jsonable` makes the dicts JSON. The reading side (what a later stage
takes back) is :data:`quadctl.artifacts.SCHEMAS`.
"""

from __future__ import annotations

import numpy as np

from quadctl import artifacts
from quadctl.design import Design
from quadctl.design.discrete import realizable_frequency
from quadctl.design.margins import LQR_GAIN_MARGIN_DB, LQR_PHASE_MARGIN_DEG
from quadctl.layout import INPUT_NAMES, INPUT_UNITS, STATE_NAMES, STATE_UNITS
from quadctl.linear.analysis import Checks
from quadctl.linear.stability import is_stable
from quadctl.sim import etdrk4_plan

ESTIMATOR_CHECK = "estimator"
"""checks' key of the measured set (``estimator.measure``) on the coupled model."""

_c = artifacts.complex_values  # eigenvalues: [re, im] pairs in JSON even when all are real


def trim(setup, trim) -> dict:
    """``trim.json``."""
    return {
        "x": trim.x, "u": trim.u, "xdot": trim.xdot, "residual": trim.residual,
        "iterations": trim.iterations, "velocity_ned": setup.velocity_ned,
        "wind_ned": setup.trim_wind,  # m/s: the steady wind trimmed in (trim.wind), else zero
        "state": dict(zip(STATE_NAMES, trim.x)), "input": dict(zip(INPUT_NAMES, trim.u)),
        "units": {**STATE_UNITS, **INPUT_UNITS}}


def linear(linear) -> dict:
    """``linear.npz``'s arrays."""
    return {
        "A": linear.A, "B": linear.B, "x_trim": linear.x_trim, "u_trim": linear.u_trim,
        "x_rate": linear.x_rate,
        "state_names": np.array(STATE_NAMES), "input_names": np.array(INPUT_NAMES),
        "state_units": np.array([STATE_UNITS[s] for s in STATE_NAMES]),
        "input_units": np.array([INPUT_UNITS[i] for i in INPUT_NAMES])}


def subsystems(dec) -> dict:
    """``subsystems.json``."""
    return {
        "subsystems": {s.name: {"states": s.states, "inputs": s.inputs, "A": s.A, "B": s.B,
                                "C": s.C, "regulated": s.regulated} for s in dec.subsystems},
        "dropped": [{"name": d.name, "matrix": d.matrix, "row": d.row, "column": d.column,
                     "value": d.value, "relative": d.relative, "unit": d.unit}
                    for d in dec.dropped]}


def checks(setup, checks: dict, regulated, warnings, vehicle) -> dict:
    """``checks.json``: the rank checks, the rate warnings of an emulated design, the vehicle's loop."""
    est, timing = setup.estimator, setup.timing
    return {
        "subsystems": {n: _checks_payload(c, n in regulated) for n, c in checks.items()
                       if n not in ("full", ESTIMATOR_CHECK)},
        "full": _checks_payload(checks["full"], True),
        ESTIMATOR_CHECK: None if est is None else {
            "measured": est.measured, **_checks_payload(checks[ESTIMATOR_CHECK], False)},
        "rate": None if timing.rate is None else {
            "rate": timing.rate, "design": "discrete" if timing.design_rate is not None else "continuous",
            "realizable_frequency": realizable_frequency(timing.rate),
            "warnings": [{"loop": w.loop, "pole": w.pole, "factor": w.factor,
                          "sampled_spectral_radius": w.sampled_radius, "sampled_stable": w.sampled_stable}
                         for w in warnings]},
        "closed_loop": None if vehicle is None else {
            **_vehicle_loop_payload(vehicle), "rotor_time_constant": setup.rotor_time_constant,
            "rotor_lag": setup.rotor_lag, "delay_samples": timing.delay_samples}}


def design(setup, des: Design, kal) -> dict:
    """``design.json``: the gains, weights and eigenvalues; ``kal``, the Kalman filter (or None)."""
    return {
        "subsystems": {s.name: {"states": s.states, "inputs": s.inputs, "Q": s.Q, "R": s.R,
                                "K": s.K, "P": s.P, "closed_loop_eigenvalues": _c(s.eigenvalues),
                                "riccati_residual": s.residual} for s in des.subsystems},
        "K_block": des.K_block, "Q_block": des.Q_block, "R_block": des.R_block,
        "full_closed_loop_eigenvalues": _c(des.full_eigenvalues),
        "marginal_states": des.marginal_states, "stable": des.stable,
        "rotor_lag": {"mode": setup.rotor_lag, "time_constant": setup.rotor_time_constant,
                      "design_time_constant": des.lag_time_constant,
                      "Kv_block": des.Kv_block if des.lag_time_constant is not None else None,
                      "measured": ("the controller's own model of the lag, propagated from its commands"
                                   if des.lag_time_constant is not None else None)},
        **_flight_design_payload(des), "estimator": _estimator_payload(kal),
        "units": {**STATE_UNITS, **INPUT_UNITS}}  # a gain K[input, state] is in input unit / state unit


def margins(setup, des: Design, result, vehicle) -> dict:
    """``margins.json``: every loop's margins (``result``) and the vehicle's loop."""
    timing = setup.timing
    return {
        "rate": timing.rate, "design": "discrete" if des.rate else "continuous",
        "delay_samples": timing.delay_samples, "rotor_time_constant": setup.rotor_time_constant,
        "rotor_lag": setup.rotor_lag,
        **({"gyro_filter": setup.rate_filter.describe()} if setup.rate_filter is not None else {}),
        "closed_loop": _vehicle_loop_payload(vehicle),
        "guarantee": {"gain_margin_db": list(LQR_GAIN_MARGIN_DB), "phase_margin_deg": LQR_PHASE_MARGIN_DEG},
        "estimator": None if setup.estimator is None else {
            "measured": setup.estimator.measured, "model": "lqg",
            "broken": "at the plant input, Kalman filter in the loop fed the commanded input"},
        "loops": [m.as_dict() for m in result]}


def cascade_margins(setup, lift, result) -> dict:
    """``margins.json`` of a PID cascade: each input's loop (``result``) and the lifted closed loop
    (:class:`quadctl.sim.cascade_lift.Lifted`)."""
    gains = setup.pid
    n_att, n_pos = gains.ratios
    eig = lift.poles
    return {
        "law": "pid", "preset": gains.preset, "title": gains.title, "rate": float(gains["rate_hz"]),
        "samples_per_update": {"attitude": n_att, "position": n_pos},
        "delay_samples": result[0].delay_samples if result else 0,
        "closed_loop": {
            "what": "the cascade linearized about hover with the plant's zero-order hold, lifted to its frame of "
                    f"{n_pos} base samples (every hold exact); states nothing reads left out",
            "domain": "z", "sample_time": lift.frame * lift.sample_time, "eigenvalues": _c(eig),
            "stable": bool(np.all(is_stable(eig, discrete=True))), "spectral_radius": float(np.abs(eig).max())},
        "exact": {"stability": True, "gain_margins": True, "phase_disk_delay_margins": True},
        "loops": [m.as_dict() for m in result]}


def design_full(fd, comparison: dict) -> dict:
    """``design_full.json``: the coupled design and its comparison with the decoupled one."""
    return {
        "K": fd.K, "Ki": fd.Ki, "integral_states": fd.integral_states, "states": fd.states,
        "left_out": fd.left_out, "Q": fd.Q, "R": fd.R, "P": fd.P,
        "closed_loop_eigenvalues": _c(fd.eigenvalues), "stable": fd.stable, "rate": fd.rate,
        "riccati_residual": fd.residual,
        "position": ("left out: " + ", ".join(fd.left_out) + " (no weight, no dynamics); "
                     if fd.left_out else "") + "weighted positions regulated about the moving reference",
        "comparison": comparison}


def simulation_arrays(sim, loop) -> dict:
    """``sim.npz``'s arrays, with the units of ``t`` and ``dt`` (``t_unit``), of the states' columns (``x``,
    ``x_ref``, ``x_hat``: ``state_units``) and of the inputs' (``u``, ``u_ref``: ``input_units``), from the layout."""
    return {
        "t": sim.t, "x": sim.x, "u": sim.u, "x_ref": sim.x_ref, "dt": np.array(sim.dt),
        "stride": np.array(sim.stride),
        "status": np.array(sim.status), "state_names": np.array(STATE_NAMES),
        "input_names": np.array(INPUT_NAMES), "t_unit": np.array("s"),
        "state_units": np.array([STATE_UNITS[s] for s in STATE_NAMES]),
        "input_units": np.array([INPUT_UNITS[i] for i in INPUT_NAMES]), "z": sim.z,
        "integral_states": np.array(loop.integral_states, dtype=str),
        "rotor_thrust": sim.rotor_thrust, "rotor_thrust_unit": np.array("N"),  # empty: instantaneous rotors
        "rotor_names": np.array([f"rotor {i + 1}" for i in range(sim.rotor_thrust.shape[1])], dtype=str),
        "u_ref": sim.u_ref,  # empty without simulation.reference: the feedforward input (N, N m)
        "x_hat": sim.x_hat,  # empty without an estimator: x_hat[k|k-1] held (sampled) or Kalman-Bucy's
        "wind": sim.wind, "wind_unit": np.array("m/s"),  # empty: still air
        "wind_names": np.array(["wind N", "wind E", "wind D"] if len(sim.wind) else [], dtype=str)}


def simulation(sim, summary: dict, flight: dict) -> dict:
    """``sim.json``: the run's status, step, metrics (``summary``) and flight numbers."""
    return {
        "status": sim.status, "message": sim.message, "dt": sim.dt, "steps": sim.steps,
        "stride": sim.stride, "samples": len(sim.t),
        "duration": float(sim.t[-1]), "backend": sim.backend,
        "dt_auto": sim.plan.auto, "max_stable_dt": sim.plan.max_stable_dt, "method": sim.plan.method,
        "schedule": etdrk4_plan.summary(sim.plan),
        "fastest_eigenvalue": sim.plan.fastest_eigenvalue,
        "fastest_subsystem": sim.plan.fastest_owner,
        "metrics": summary, "units": {**STATE_UNITS, **INPUT_UNITS}, **flight}


def _estimator_payload(kal) -> dict | None:
    """design.json's ``estimator``: the Kalman filter, its form stated (None without ``estimator:``)."""
    if kal is None:
        return None
    discrete = kal.discrete
    return {
        "form": kal.form,
        "gain_form": ("filter (measurement-update) gain M of MATLAB dlqe: x_hat[k|k] = x_hat[k|k-1] + "
                      "M (y[k] - C x_hat[k|k-1]); the law acts on x_hat[k|k]; predictor gain L = Ad M"
                      if discrete else "Kalman-Bucy gain L of MATLAB lqe: dx_hat/dt = A x_hat + B du + "
                      "L (y - C x_hat)"),
        "coordinates": "deviation from the trim reference x_ref(t), on the linear model about the trim",
        "measured": kal.measured, "states": kal.state_names, "sample_time": kal.sample_time,
        "A": kal.A, "B": kal.B, "C": kal.C, "G": kal.G, "Qn": kal.Qn, "Rn": kal.Rn,
        "noise_convention": ("covariance per sample (noise held over each controller period)" if discrete
                             else "intensity sigma^2 * noise period (held noise's low-frequency spectrum)"),
        "gain": kal.gain, "predictor_gain": kal.predictor_gain,
        "P": kal.P, "Z": kal.Z,
        "covariance": ("P a priori, Z = P - M C P a posteriori" if discrete else "P = Z error covariance"),
        "eigenvalues": _c(kal.eigenvalues),
        "eigenvalues_of": "Ad - L C (z)" if discrete else "A - L C (s)",
        "riccati_residual": kal.residual,
    }


def _flight_design_payload(des: Design) -> dict:
    """design.json keys of sampled and LQI designs: rate, integrators, discrete eigenvalues."""
    return {
        "rate": des.rate, "discrete": des.rate is not None,
        "Ki_block": des.Ki_block, "integral_states": des.integral_states,
        "full_closed_loop_eigenvalues_z": _c(des.full_eigenvalues_z),
        "subsystem_integrals": {s.name: {"integral": s.integral, "Ki": s.Ki,
                                         "closed_loop_eigenvalues_z": _c(s.eigenvalues_z)}
                                for s in des.subsystems},
    }


def _checks_payload(c: Checks, regulated: bool) -> dict:
    return {
        "n_states": c.n, "regulated": regulated,
        "ctrb_rank": c.ctrb.rank, "obsv_rank": c.obsv.rank,
        "ctrb_singular_values": c.ctrb.singular_values, "obsv_singular_values": c.obsv.singular_values,
        "tolerance": {"ctrb": c.ctrb.tolerance, "obsv": c.obsv.tolerance,
                      "rule": "singular values > max(shape) * eps * sigma_max"},
        "controllable": c.controllable, "observable": c.observable,
        "stabilizable": c.stabilizable, "detectable": c.detectable,
        "pbh": [{"eigenvalue": m.eigenvalue, "ctrb_rank": m.rank, "controllable": m.passed,
                 "states": m.states} for m in c.pbh_ctrb],
        "pbh_obsv": [{"eigenvalue": m.eigenvalue, "obsv_rank": m.rank, "observable": m.passed,
                      "states": m.states} for m in c.pbh_obsv],
        "staircase": {"controllable_dim": c.controllable_dim, "observable_dim": c.observable_dim,
                      "uncontrollable": [{"eigenvalue": m.eigenvalue, "states": m.states} for m in c.lost_ctrb],
                      "unobservable": [{"eigenvalue": m.eigenvalue, "states": m.states} for m in c.lost_obsv]},
    }


def _vehicle_loop_payload(loop) -> dict:
    """margins.json's and checks.json's ``closed_loop``: the loop the vehicle flies (:class:`pipeline.VehicleLoop`)."""
    Ts, eig = loop.sample_time, loop.eigenvalues
    return {
        "what": "the coupled linear loop with the rotors' lag, the controller's lag model (include), the "
                "integrators and the delay" + (", the law acting on the Kalman filter's estimate (the filter's "
                                               "states with the plant's)" if loop.estimated else "")
                + "; free positions left out",
        "domain": "z" if Ts else "s", "eigenvalues": _c(eig), "stable": loop.stable,
        "estimator": list(loop.estimated) or None,
        "spectral_radius" if Ts else "slowest_real_part": float(np.abs(eig).max() if Ts else eig.real.max()),
        "least_damping": loop.least_damping, "design_least_damping": loop.design_least_damping}


def gain_schedule(sched) -> dict:
    """``schedule.json``: the gain schedule (:class:`quadctl.schedule.envelope.Schedule`): each point's trim
    (``x``, ``u`` and by name, as ``trim.json``), its 4x12 gain ``K`` in ``design.json``'s state and
    input order (and ``Ki``, columns ``integral_states``), its verdicts or why it has no trim; the
    interpolation, what holds outside the grid, and the frozen-point checks on the finer grid."""
    checks = sched.checks
    return {
        "variable": sched.variable, "unit": sched.unit, "heading": sched.heading,
        "interpolation": sched.interpolation, "outside": sched.outside,
        "envelope": list(sched.envelope), "own_value": sched.own_value,
        "design": "discrete" if sched.sample_time is not None else "continuous", "sample_time": sched.sample_time,
        "integral_states": sched.integral_states,
        "units": {**STATE_UNITS, **INPUT_UNITS},
        "points": [_schedule_point(p) for p in sched.points],
        "checks": {
            "refinement": checks.refinement,
            "values": checks.values, "stable": checks.stable, "slowest_pole": checks.slowest,
            "least_damping": checks.least_damping, "passed": checks.passed,
            "failures": [{"value": v, "reason": why,
                          "worst_eigenvalue": None if why is not None else _c(np.array([w]))[0]}
                         for v, ok, w, why in zip(checks.values, checks.stable, checks.worst, checks.reasons)
                         if not ok]},
        "passed": sched.passed}


def _schedule_point(p) -> dict:
    out = {"value": p.value, "velocity_ned": p.velocity_ned, "yaw": p.yaw, "trimmed": p.trimmed,
           "designed": p.designed, "reason": p.reason}
    if p.trimmed:
        out.update({"x": p.trim.x, "u": p.trim.u, "residual": p.trim.residual,
                    "state": dict(zip(STATE_NAMES, p.trim.x)), "input": dict(zip(INPUT_NAMES, p.trim.u)),
                    "actuator_commands": p.actuator_commands,
                    "within_limits": True})  # a trim outside the actuator limits is no trim (its reason says so)
    if p.designed:
        out.update({"K": p.K, "Ki": p.Ki, "stable": p.stable, "closed_loop_eigenvalues": _c(p.core_eigenvalues)})
    return out


def gain_schedule_arrays(sched) -> dict:
    """``schedule.npz``'s arrays: the table (``values``, ``K`` (n, 4, 12), ``Ki``, the trims, the
    piecewise cubic's ``breaks`` and ``coefficients``), and the fine grid's values, eigenvalues
    (s, rad/s; NaN where no trim) and verdicts. ``values`` are the table's (the points that trim and
    design); ``point_values`` every value of ``schedule.values``."""
    good = [p for p in sched.points if p.designed]
    table, checks = sched.table, sched.checks
    nz = len(sched.integral_states)
    return {
        "variable": np.array(sched.variable), "unit": np.array(sched.unit),
        "interpolation": np.array(sched.interpolation), "heading": np.array(sched.heading),
        "values": table.values, "gains": table.gains,
        "K": table.gains[:, :, :len(STATE_NAMES)], "Ki": table.gains[:, :, len(STATE_NAMES):].reshape(len(good), 4, nz),
        "x_trim": np.array([p.trim.x for p in good]), "u_trim": np.array([p.trim.u for p in good]),
        "breaks": table.breaks, "coefficients": table.coefficients,
        "point_values": np.array([p.value for p in sched.points]),
        "point_trimmed": np.array([p.trimmed for p in sched.points]),
        "fine_values": checks.values, "fine_eigenvalues": checks.eigenvalues, "fine_stable": checks.stable,
        "fine_slowest_pole": checks.slowest, "fine_least_damping": checks.least_damping,
        "state_names": np.array(STATE_NAMES), "input_names": np.array(INPUT_NAMES),
        "integral_states": np.array(sched.integral_states, dtype=str)}
