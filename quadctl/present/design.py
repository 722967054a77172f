"""A design as rows: weights, gains (K beside Ki and Kv), K_block, and the coupled closed loop as
MATLAB's ``damp`` reads it (pole, natural frequency, damping ratio, time constant)."""

from __future__ import annotations

import math

import numpy as np

from quadctl.layout import INPUT_NAMES, STATE_NAMES, unit_of
from quadctl.linear import stability
from quadctl.present.cells import Mark, Table, eig, eigs, num, vector, weights


def discrete_sentence(des) -> str | None:
    """What a discrete design is (None for a continuous one)."""
    if not des.rate:
        return None
    return (f"Discrete design at {des.rate:g} Hz (lqrd: ZOH plant, cost integrated over {1e3 / des.rate:.4g} ms); "
            "eigenvalues shown as ln(z)/Ts in rad/s.")


def plant_and_timing(setup) -> str:
    """The rotors' lag, what the design does with it, and the delay: one sentence."""
    tau, delay, timing = setup.rotor_time_constant, setup.timing.delay_samples, setup.timing
    if tau is None:
        lag = "Rotors: instantaneous (no motors.time_constant)"
    elif setup.rotor_lag == "include":
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
    return f"{lag}; {dl}."


def weights_table(des) -> Table:
    rows = []
    for s in des.subsystems:
        states = " ".join(s.states) + ("" if not s.integral else " + int " + " ".join(s.integral))
        rows.append((s.name, states, " ".join(s.inputs), weights(s.Q), weights(s.R)))
    return Table("weights-table", "LQR weights per subsystem (cost: integral of x'Qx + u'Ru)",
                 ("subsystem", "states", "input", "Q", "R"), tuple(rows), align="lllll")


def gains_table(des) -> Table:
    """Each subsystem's K, its integral gain Ki (LQI) and lag gain Kv where the design has them,
    its closed-loop eigenvalues and Riccati residual."""
    integral = any(s.integral for s in des.subsystems)
    lagged = des.lag_time_constant is not None
    rows = []
    for s in des.subsystems:
        rows.append((s.name, " ".join(s.states), " ".join(s.inputs), vector(s.K),
                     *([vector(s.Ki) if s.Ki is not None else "-"] if integral else []),
                     *([vector(s.Kv)] if lagged else []), eigs(s.eigenvalues), f"{s.residual:.1e}"))
    law = "u = -K x" + (" - Kv v" if lagged else "") + (" - Ki z" if integral else "")
    notes = (["Ki: the gain on the integral z of the error (LQI)."] if integral else []) + \
            (["Kv: the gain on the lag states v (the inputs the rotors reach, from trim)."] if lagged else [])
    return Table("design-table", f"LQR per subsystem ({law}, K = R^-1 B' P)",
                 ("subsystem", "states", "input", "K", *(["Ki"] if integral else []), *(["Kv"] if lagged else []),
                  "closed-loop eigenvalues (rad/s)", "Riccati residual"), tuple(rows),
                 caption=" ".join(notes + ["Riccati residual: relative residual of the Riccati equation at its "
                                           "solution (0 for an exact solution)."]),
                 align="llll" + "l" * (integral + lagged) + "wr")


def gain_matrix_table(des) -> Table:
    """``K_block`` and ``Ki_block`` transposed: a row per state (then per integrator), a column per input."""
    K = np.hstack([des.K_block, des.Ki_block]) if des.integral_states else des.K_block
    names = list(STATE_NAMES) + [f"int {s}" for s in des.integral_states]
    rows = tuple((name, *("·" if K[j, i] == 0 else f"{K[j, i]:.4g}" for j in range(K.shape[0])))
                 for i, name in enumerate(names))
    return Table("kblock-table", "K_block" + (" and Ki_block" if des.integral_states else "")
                 + ", transposed: a row per state, a column per input (· is an exact zero)",
                 ("", *INPUT_NAMES), rows)


def damp_table(des) -> Table:
    """The coupled closed loop's poles as MATLAB's ``damp`` gives them, lowest natural frequency first.

    A discrete design's poles are its ``z``, read as ``s = ln(z) / Ts``; the verdict is
    :func:`quadctl.linear.stability.is_stable`'s, a free position's pole at 0 is marginal by design.
    """

    discrete = des.full_eigenvalues_z is not None
    d = stability.damp(des.full_eigenvalues_z if discrete else des.full_eigenvalues,
                       des.sample_time if discrete else None)
    rows = []
    for i in range(len(d.s)):
        s = d.s[i]
        if abs(s) < 1e-9 and des.marginal_states:
            verdict = Mark("marginal: unregulated position")
        elif stability.is_stable(d.z[i] if discrete else s, discrete=discrete):
            verdict = Mark("stable", "ok")
        else:
            verdict = Mark("unstable", "fail")
        zeta = "-" if math.isnan(d.zeta[i]) else f"{d.zeta[i] + 0.0:.3g}"
        rows.append((*([eig(d.z[i])] if discrete else []), eig(s), num(d.wn[i], 5), zeta, num(d.tau[i]), verdict))
    where = ("with the rotors' lag, [x; v" + ("; z]" if des.integral_states else "]") + ": A - B [K_block, Kv_block]"
             if des.lag_time_constant is not None else
             "[x; z]: A - B [K_block, Ki_block]" if des.integral_states else "A - B K_block")
    return Table("damp-table", f"Coupled closed loop {where}: poles, natural frequency, damping (MATLAB damp)",
                 (*(["pole z"] if discrete else []), "pole (rad/s)", "wn (rad/s)", "zeta", "tau (s)", "verdict"),
                 tuple(rows), caption=("s = ln(z)/Ts; " if discrete else "")
                 + "wn = |s|, zeta = -Re(s)/|s|, tau = -1/Re(s); lowest wn first, as MATLAB's damp",
                 align="r" * (4 + discrete) + "l")


def summary(des) -> str:
    """A stable design in one line: ``stable on the coupled model; slowest pole -2.39 rad/s``."""
    return f"stable on the coupled model; slowest pole {max(e.real for e in des.core_eigenvalues):.3g} rad/s"


def stability_sentence(des) -> Mark:
    """The design's verdict on the coupled model, with its slowest pole."""
    if des.stable:
        marginal = f" (marginal by design: {', '.join(des.marginal_states)})" if des.marginal_states else ""
        return Mark(f"Stable on the coupled 12-state linear model{marginal}; slowest pole "
                    f"{max(e.real for e in des.core_eigenvalues):.3g} rad/s.", "ok")
    return Mark("Every subsystem is stable alone, but the assembled gain is UNSTABLE on the coupled 12-state "
                "model (the dropped couplings matter).", "fail")


def estimator_blocks(setup, kal) -> tuple:
    """The Kalman filter of an LQG config: a sentence on its form, what it measures, its eigenvalues."""
    est = setup.estimator
    if kal.discrete:
        form = (f"the discrete filter at {1 / kal.sample_time:g} Hz (MATLAB dlqe conventions): the gain is the "
                "filter (measurement-update) gain M, x_hat[k|k] = x_hat[k|k-1] + M (y[k] - C x_hat[k|k-1]); the "
                "law acts on x_hat[k|k]; eigenvalues of Ad - Ad M C shown as ln(z)/Ts in rad/s")
        shown = np.log(kal.eigenvalues.astype(complex)) / kal.sample_time
    else:
        form = "the Kalman-Bucy filter (MATLAB lqe): dx_hat/dt = A x_hat + B du + L (y - C x_hat)"
        shown = kal.eigenvalues
    rows = tuple((name, unit_of(name), num(std)) for name, std in zip(est.measured, est.sensor_std))
    gyro = ("" if kal.rate_filter is None else
            f" Its model includes the gyro filter ({kal.rate_filter.describe()}): it measures the filtered rates "
            f"the flight computer sees and estimates the filter's {kal.n_estimate - len(STATE_NAMES)} states too; "
            "the gyro's noise is taken white at the filter's output.")
    return (f"The law closes through a steady-state Kalman filter (LQG), {form}; Riccati residual "
            f"{kal.residual:.1e}.{gyro}",
            Table("estimator-table", "What the filter measures (estimator.measure)", ("state", "unit", "noise std"),
                  rows, caption="Process noise: body force std " + vector(est.process_std[:3]) + " N, torque std "
                  + vector(est.process_std[3:]) + " N m.", align="llr"),
            f"Estimator eigenvalues (rad/s): {eigs(sorted(shown, key=lambda z: (z.real, z.imag)))}.")
