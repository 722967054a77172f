"""The design as data: one table of named fields, written as a MATLAB v5 ``.mat`` or as JSON.

:func:`fields` is the one list of what leaves quadctl (each field with its value, unit and
meaning); :func:`mat_variables` and :func:`json_payload` only spell it for MATLAB
(:func:`scipy.io.savemat`: matrices as matrices, vectors as columns, names as cell arrays, the
subsystems as a struct, ``Ts = 0`` for a continuous design as MATLAB's ``ss`` has it) and for
JSON (every field with its unit, shape and description; complex numbers as ``[re, im]``).

In MATLAB::

    d = load('quadctl_controller.mat');
    sys = ss(d.A, d.B, eye(12), 0, 'StateName', d.state_names, 'InputName', d.input_names);
    u = d.u_trim - d.K * (x - (d.x_trim + d.x_rate * t));   % plus - d.Ki * z with integrators

An LQG config (``estimator:``) adds the struct ``estimator``: the Kalman filter the law closes
through (its form, model, gains, covariances), the law acting on its estimate of ``x - x_ref(t)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from quadctl.artifacts import jsonable
from quadctl.design.gain_table import OUTSIDE, VARIABLES
from quadctl.export.bundle import Export, require_export
from quadctl.layout import INPUT_NAMES, INPUT_UNITS, STATE_NAMES, STATE_UNITS
from quadctl.text.escape import matlab_field
from quadctl.version import __version__

FORMAT = "quadctl-controller"
FORMAT_VERSION = 1
"""Bumped when a field changes meaning or shape."""
MAT_FILE, JSON_FILE = "quadctl_controller.mat", "quadctl_controller.json"


@dataclass(frozen=True)
class Field:
    """One exported quantity.

    Attributes
    ----------
    name : str
        A MATLAB identifier.
    value : ndarray, str, list of str or dict
        Arrays keep their shape (vectors are 1-D); ``list of str`` is a cell array; a dict of
        dicts is a struct of structs (the subsystems).
    unit : str
    description : str
    """

    name: str
    value: Any
    unit: str
    description: str


def fields(exp: Export) -> list[Field]:
    """Everything the ``.mat`` and the JSON hold, in order.

    Parameters
    ----------
    exp : Export

    Returns
    -------
    list of Field
    """
    require_export(exp, "fields")
    loop, des, lin = exp.loop, exp.design, exp.linear
    nz = len(loop.integral_states)
    Ki = np.asarray(loop.Ki if nz else np.zeros((len(INPUT_NAMES), 0)), dtype=float).reshape(len(INPUT_NAMES), nz)
    Ts = exp.sample_time
    domain = "z (sampled loop on the zero-order-hold plant)" if Ts else "s, rad/s (continuous loop)"
    subsystems = {}
    for sub in des.subsystems:
        subsystems[matlab_field(sub.name)] = {
            "states": list(sub.states), "inputs": list(sub.inputs), "integral": list(sub.integral),
            "Q": np.asarray(sub.Q, dtype=float), "R": np.asarray(sub.R, dtype=float),
            "K": np.asarray(sub.K, dtype=float),
            "Ki": np.asarray(sub.Ki if sub.Ki is not None else np.zeros((len(sub.inputs), 0)), dtype=float),
            "eig_cl": np.asarray(sub.eigenvalues_z if sub.eigenvalues_z is not None else sub.eigenvalues)}
    units = [STATE_UNITS[s] for s in STATE_NAMES]
    return [*_base_fields(exp, loop, des, lin, Ki, Ts, domain, subsystems, units), *_estimator_fields(loop),
            *_schedule_fields(loop), *_gyro_filter_fields(loop, Ts)]


def _base_fields(exp, loop, des, lin, Ki, Ts, domain, subsystems, units) -> list[Field]:
    """The fields of every export (the full-state law, the trim, the names, the provenance)."""
    return [
        Field("A", np.asarray(lin.A, dtype=float), "1/s (state units per state unit)",
              "continuous linearization about the trim: d(dx)/dt = A dx + B du, dx = x - x_ref(t), du = u - u_trim"),
        Field("B", np.asarray(lin.B, dtype=float), "state units / s per input unit",
              "input matrix of the linearization"),
        Field("Q", np.asarray(des.Q_block, dtype=float), "1 / state unit^2",
              "the regulated subsystems' state weights assembled (12 x 12; integrator weights are per subsystem)"),
        Field("R", np.asarray(des.R_block, dtype=float), "1 / input unit^2", "the input weights assembled (4 x 4)"),
        Field("K", np.asarray(loop.K, dtype=float), "input unit per state unit",
              "state gain: u = u_trim - K (x - x_ref(t)) - Ki z (4 x 12)"),
        Field("Ki", Ki, "input unit per (state unit s)", "integrator gain (4 x nz), one column per integral_states"),
        Field("Kv", np.asarray(loop.Kv if loop.Kv is not None else np.zeros((4, 4)), dtype=float),
              "input unit per input unit", "gain on the controller's rotor lag model l: u -= Kv l (4 x 4; zero "
              "unless rotor_lag is include)"),
        Field("rotor_lag", exp.setup.rotor_lag, "", "ignore: the design's rotors are instantaneous; include: designed "
              "with the lag, the controller propagates its model l (see law)"),
        Field("rotor_time_constant", float(loop.rotor_time_constant or 0.0), "s",
              "first-order lag of each rotor's thrust (motors.time_constant); 0: instantaneous"),
        Field("delay_samples", int(loop.delay_samples), "samples", "controller.delay: the vehicle's, from measurement "
              "to actuation; not part of the law (simulate applies each command this many samples later)"),
        Field("integral_states", list(loop.integral_states), "",
              "the state each integrator integrates: dz/dt = -(x_i - x_ref_i(t))"),
        Field("x_trim", np.asarray(loop.x_trim, dtype=float), "state units", "the trim state: x_ref(0)"),
        Field("u_trim", np.asarray(loop.u_trim, dtype=float), "input units", "the trim input"),
        Field("x_rate", np.asarray(loop.x_rate, dtype=float), "state units / s",
              "drift of the trim reference: x_ref(t) = x_trim + x_rate t (the trim velocity on positions); a "
              "config that flies simulation.reference takes x_ref(t) from it instead (see law)"),
        Field("Ts", float(Ts or 0.0), "s", "controller sample time; 0: continuous feedback (MATLAB's convention)"),
        Field("rate", float(exp.rate or 0.0), "Hz", "controller rate; 0: continuous feedback"),
        Field("design", exp.mode, "",
              "discrete (designed at the rate: lqrd), emulated (continuous design sampled) or continuous"),
        Field("state_names", list(STATE_NAMES), "", "the order of x"),
        Field("state_units", units, "", "unit of each state"),
        Field("input_names", list(INPUT_NAMES), "", "the order of u"),
        Field("input_units", [INPUT_UNITS[i] for i in INPUT_NAMES], "", "unit of each input"),
        Field("eig_cl", exp.closed_loop_eigenvalues(), domain.split(" (")[0],
              f"eigenvalues of the linear closed loop of [x; z] as exported, in {domain}"),
        Field("subsystems", subsystems, "as the fields above",
              "per regulated subsystem: states, inputs, integral, Q (of [states; integrals]), R, K, Ki, "
              "eig_cl (its closed-loop eigenvalues: z when designed at a rate, else s)"),
        Field("law", exp.law(), "", "the control law the C export applies and quadctl simulate runs"),
        Field("config_name", exp.name, "", "the quadctl config"),
        Field("config_hash", exp.config_hash or "", "", "sha256 of the validated config"),
        Field("quadctl_version", __version__, "", "the quadctl that exported this"),
    ]


def _estimator_fields(loop) -> list[Field]:
    """The Kalman filter of an LQG loop (``estimator:``) as one struct; none without a filter."""
    kal = loop.estimator
    if kal is None:
        return []
    discrete = kal.discrete
    filt = {
        "form": kal.form,
        "gain_form": ("filter (measurement-update) gain M of MATLAB dlqe: x_hat[k|k] = x_hat[k|k-1] + "
                      "M (y[k] - C x_ref(t) - C x_hat[k|k-1]); the law acts on x_hat[k|k]; then x_hat[k+1|k] = "
                      "Ae x_hat[k|k] + Be (u - u_trim) with the applied u; predictor gain L = Ae M"
                      if discrete else "Kalman-Bucy gain L of MATLAB lqe: dx_hat/dt = Ae x_hat + Be (u - u_trim) "
                      "+ L (y - C x_ref(t) - C x_hat); the law acts on x_hat"),
        "coordinates": "x_hat estimates x - x_ref(t) on the linear model about the trim; it starts at 0"
                       + ("" if kal.rate_filter is None else
                          f"; with the gyro filter ({kal.rate_filter.describe()}) in the model, "
                          "x_hat = [x - x_ref(t); g] (the 12 states, then the filter's, 'states'), a measured rate "
                          "is the filtered rate, c g + d r (C's rows read g), and the law acts on the first 12"),
        "states": list(kal.state_names),
        "measured": list(kal.measured),
        "measured_index": np.array([STATE_NAMES.index(s) + 1 for s in kal.measured], dtype=float),
        "sample_time": float(kal.sample_time or 0.0),
        "Ae": np.asarray(kal.A, dtype=float), "Be": np.asarray(kal.B, dtype=float),
        "C": np.asarray(kal.C, dtype=float), "G": np.asarray(kal.G, dtype=float),
        "Qn": np.asarray(kal.Qn, dtype=float), "Rn": np.asarray(kal.Rn, dtype=float),
        "gain": np.asarray(kal.gain, dtype=float), "predictor_gain": np.asarray(kal.predictor_gain, dtype=float),
        "P": np.asarray(kal.P, dtype=float), "Z": np.asarray(kal.Z, dtype=float),
        "eig": np.asarray(kal.eigenvalues),
    }
    return [Field("estimator", filt, "state units; Qn (N, N m)^2, Rn measured units^2"
                  + (" per sample" if discrete else " x s (intensities)"),
                  "the steady-state Kalman filter the law closes through (LQG): form (filter: discrete, "
                  "dlqe; kalman-bucy: continuous, lqe), gain_form, measured (the states y holds, in order; "
                  "measured_index 1-based into x), states (the ne states of x_hat: the 12 of x, then a gyro "
                  "filter's when controller.filters is set), Ae (ne x ne) and Be (ne x 4) its model (the "
                  "zero-order-hold model at Ts, or A, B; with the gyro filter after the plant's rates), C (ny x ne), "
                  "G (ne x 6) and Qn (6 x 6) the process noise (body force, "
                  "torque), Rn (ny x ny) the sensor noise, gain (ne x ny: M, or L), predictor_gain (L = Ae M, "
                  "or L), P (a priori, or the error covariance), Z (a posteriori P - M C P, or P), eig (of "
                  "Ae - L C: z, or s)")]


def _gyro_filter_fields(loop, Ts) -> list[Field]:
    """The gyro filter the law runs (``controller.filters``) as one struct, at the export's timing; none without."""
    filt = getattr(loop, "rate_filter", None)
    if filt is None:
        return []
    form = filt.form(Ts or None)
    value = {"filters": filt.describe(), "A": np.asarray(form.A, dtype=float), "b": np.asarray(form.b, dtype=float),
             "c": np.asarray(form.c, dtype=float), "d": float(form.d)}
    return [Field("gyro_filter", value, "A, b, c, d: per rate, rad/s in and out",
                  "the filter on each measured body rate r (p, q, r): y = c g + d r and g <- A g + b r at each sample "
                  "(dg/dt = A g + b r when continuous), y in place of r in the law, g starting at 0")]


def _schedule_fields(loop) -> list[Field]:
    """The gain table of a scheduled loop (``schedule:``) as one struct; none with fixed gains."""

    table = loop.schedule
    if table is None:
        return []
    value = {"variable": table.variable, "interpolation": table.interpolation, "outside": OUTSIDE,
             "heading": float(loop.schedule_heading), "values": np.asarray(table.values, dtype=float),
             "gains": np.asarray(table.gains, dtype=float), "breaks": np.asarray(table.breaks, dtype=float),
             "coefficients": np.asarray(table.coefficients, dtype=float)}
    return [Field("schedule", value, f"values and breaks {VARIABLES[table.variable]}; gains as K (then Ki)",
                  "the gain schedule the law flies in place of K (and Ki when gains has 12 + nz columns): "
                  "G(v) at v, the variable (speed along heading rad, climb, yaw) of x_ref(t); gains (n x 4 x m) "
                  "the designs at values, interpolated as one piecewise cubic, G(v) = sum_k coefficients(k, i) "
                  "(v - breaks(i))^(3 - k) on the piece i that holds v (k, i 0-based here), v held to "
                  "[breaks(1), breaks(end)]")]


def mat_variables(exp: Export) -> dict[str, Any]:
    """The variables of the ``.mat`` (for :func:`scipy.io.savemat` with ``oned_as="column"``)."""
    require_export(exp, "mat_variables")
    out = {f.name: _mat(f.value) for f in fields(exp)}
    out["units"] = {f.name: f.unit for f in fields(exp)}
    out["descriptions"] = {f.name: f.description for f in fields(exp)}
    return out


def _mat(value):
    if isinstance(value, dict):
        return {k: _mat(v) for k, v in value.items()}
    if isinstance(value, list):  # a cell array (savemat writes an object array as a cell)
        cell = np.empty((len(value), 1), dtype=object)
        for i, v in enumerate(value):
            cell[i, 0] = v
        return cell
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        return float(value)  # MATLAB: int64 * double is int64 (d.delay_samples * d.Ts would be 0): doubles only
    if isinstance(value, np.ndarray) and np.issubdtype(value.dtype, np.integer):
        return value.astype(float)
    return value


def write_mat(path, exp: Export) -> None:
    """Write the MATLAB v5 ``.mat`` of ``exp`` to ``path`` (a file or a binary file object)."""
    from scipy.io import savemat

    savemat(path, mat_variables(exp), format="5", oned_as="column", long_field_names=True)


def json_payload(exp: Export, meta: dict | None = None) -> dict:
    """The JSON of ``exp``: ``fields``, each with ``value``, ``unit`` and ``description``, and an array
    field also its ``shape`` (numpy's) and ``complex`` (its values are ``[re, im]`` pairs).

    Parameters
    ----------
    exp : Export
    meta : dict, optional
        Provenance to put at the top (:func:`quadctl.artifacts.metadata`).
    """
    require_export(exp, "json_payload")

    body = {}
    for f in fields(exp):
        value = f.value
        entry = {"unit": f.unit, "description": f.description}
        if isinstance(value, np.ndarray):
            entry["shape"] = list(value.shape)
            entry["complex"] = bool(np.iscomplexobj(value))
        body[f.name] = {**entry, "value": jsonable(value)}
    return {**(meta or {}), "format": FORMAT, "export_format_version": FORMAT_VERSION,
            "law": exp.law(), "complex_numbers": "[re, im]", "fields": body}
