"""The controller as C99: one header and one source, generated from the simulation's control law.

:func:`sources` builds the ``law`` function of the loop's :class:`~quadctl.sim.loop_spec.LoopSpec` with
:func:`quadctl.sim.builder.build`, emits it with :func:`quadctl.native.emit.emit` (``double``, or
``float`` with ``-DQUADCTL_FLOAT``), bakes the loop's constants in and fills the C templates
(``templates/quadctl_controller.h`` and ``.c``), sizes and offsets from :mod:`quadctl.layout` and
:func:`quadctl.sim.loop_layout.constant_layout`, the header's documentation comments from
:mod:`quadctl.export.c_doc`. Why quadctl emits its own C is in the docs,
docs/internals.md ("The exported C").
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import replace
from importlib import resources
from string import Template

import numpy as np

from quadctl.errors import ArgumentError
from quadctl.export.bundle import Export, require_export
from quadctl.export.c_doc import delay_doc, doc_lines, filter_doc, gyro_doc, lag_doc, schedule_doc, vector_table
from quadctl.layout import INPUT_NAMES, INPUT_UNITS, N_INPUTS, N_STATES, STATE_NAMES, STATE_UNITS
from quadctl.native.emit import Dialect, emit
from quadctl.sim.builder import ANTIWINDUP_TOL, build
from quadctl.sim.loop_layout import constant_layout, exo_layout
from quadctl.text.escape import c_comment, c_identifier
from quadctl.version import __version__

HEADER, SOURCE = "quadctl_controller.h", "quadctl_controller.c"
"""The two files of the exported controller."""
FLOAT_ROUNDOFF_ULPS = 64
"""The float build counts an input as clipped when saturation changes it by more than
``FLOAT_ROUNDOFF_ULPS * FLT_EPSILON * scale``, ``scale`` the largest input the actuators can
produce (4 x max thrust for rotors). Mixing a command to rotor thrusts and back rounds each
input by a few ulps of that scale (two 4-term sums): 64 ulps leaves a margin of about 8, so an
unclipped input never freezes an integrator, while a clip that small (5e-6 N on a Crazyflie)
changes nothing a vehicle feels. (With the double's 1e-10, the float Mambo controller froze its
altitude integrator at nearly every sample and flew 4 mm off the double's trajectory.) The double
build keeps the simulation's :data:`~quadctl.sim.builder.ANTIWINDUP_TOL`."""
FLT_EPSILON = 2.0 ** -23
"""Spacing of float (IEEE 754 binary32) numbers at 1."""
TEMPLATES = "export/templates"


def sources(exp: Export, reference: bool | None = None, gyro_filtered_by: str | None = None) -> dict[str, str]:
    """The C files of the exported controller: ``{file name: text}``.

    Parameters
    ----------
    exp : Export
        A sampled design (``exp.rate`` set: :func:`quadctl.export.prepare` with a rate).
    reference : bool, optional
        Write the controller that takes the reference at each sample (``quadctl_step_ref``);
        None: when the config flies one (``simulation.reference``). A flight stack whose commander
        gives the setpoints wants it for any config.
    gyro_filtered_by : str, optional
        Who runs the config's gyro filter (``controller.filters``) before the law sees the rates: a flight
        stack whose sensor driver low-passes the gyro for every controller (the Crazyflie's). The filter is
        then the vehicle's, as the rotors' lag and the delay are: the C leaves it out, and its header says
        whose it is. None: the C runs it on the raw rates, as the simulation does.

    Returns
    -------
    dict of str -> str
        :data:`HEADER` and :data:`SOURCE`.

    Raises
    ------
    ArgumentError
        ``exp`` is continuous (nothing to sample), its Kalman filter is not the discrete one, or it has one and
        ``gyro_filtered_by`` says the flight stack runs the gyro filter the filter's model holds.
    ArgumentTypeError
        ``exp`` is not an :class:`~quadctl.export.Export`.
    ValueError
        The law has an operation ``emit`` cannot write (a bug).
    """

    require_export(exp, "sources")
    if exp.sample_time is None:
        raise ArgumentError("sources: exp is continuous (no rate): a C controller samples: prepare the export with a "
                            "rate, quadctl.export.prepare(setup, rate)")
    loop, Ts = exp.loop, exp.sample_time
    kal = loop.estimator
    if kal is not None and kal.form != "filter":  # prepare() designs the filter at the rate the C runs at
        raise ArgumentError(f"sources: exp's Kalman filter is of form {kal.form!r}: a C controller samples: its Kalman "
                            "filter must be the discrete one (form filter), as quadctl.export.prepare designs it")
    if loop.rotor_time_constant is not None:  # the rotors' lag is the vehicle's, not the law's: no rotor states
        act = loop.actuators
        loop = replace(loop, actuators=replace(act, motors=replace(act.motors, time_constant=None)))
    if gyro_filtered_by is not None and loop.rate_filter is not None:  # the vehicle's too: filtered once
        if kal is not None:
            raise ArgumentError("sources: gyro_filtered_by with a Kalman filter (estimator:): the filter's model "
                                "holds the gyro filter's states, estimated from the rates it filters itself; leave "
                                "out gyro_filtered_by, or export the design without the estimator")
        upstream = f"{loop.rate_filter.describe()}, {gyro_filtered_by}"
        loop = replace(loop, rate_filter=None)
    else:
        upstream = None
    delay = loop.delay_samples
    if kal is None:  # so is the delay: the vehicle's computer and bus add it
        loop = replace(loop, delay_samples=0)
    # With a filter, the controller keeps the last `delay` commands: its prediction takes the input the
    # vehicle applies now (computed `delay` samples ago), as the simulation's filter does.
    if reference is None:  # x_ref(t) and u_ref(t): inputs of each sample (quadctl_step_ref)
        reference = exp.flies_reference
    spec = loop.spec(noise=False, reference=reference)  # with the rotors' lag: its lag model, controller states
    c = loop.constants(Ts)
    nz, nl, ny, nb, ng = len(loop.integral_states), spec.n_lag, spec.ny, spec.n_buffer, spec.n_filter
    dialect = Dialect(real="quadctl_real", literal="QUADCTL_LIT({})", call="QUADCTL_FN({})", pragma=False,
                      named=((ANTIWINDUP_TOL, "QUADCTL_ANTIWINDUP_TOL"),), mark_used=True)
    law = emit(build(spec).law, "qc_law", 1, dialect)
    offsets = _offsets(nz, spec.lag_model, ny, spec.schedule_shape, spec.filter_order)
    act = loop.actuators
    rotors = ""
    if act is not None and act.mode == "motors":
        rotors = (f"#define QUADCTL_N_ROTORS {len(act.names)}\n"
                  "/* rotors (FRD body frame, in the vehicle's numbering: motors.numbering; thrust along body -z) */\n"
                  + "".join(f"/*   rotor {i + 1}: x = {x:+.6g} m, y = {y:+.6g} m, spins "
                            f"{'counter-clockwise' if s > 0 else 'clockwise'} seen from above */\n"
                            for i, ((x, y), s) in enumerate(zip(act.motors.positions(), act.motors.rotor_spins()))))
    tol_float = float_tolerance(act)
    values = {
        "CONFIG": c_comment(exp.name), "VERSION": __version__, "CONFIG_HASH": exp.config_hash or "not recorded",
        "TS": repr(Ts), "RATE": repr(float(exp.rate)),
        "STATE_TABLE": vector_table(STATE_NAMES, STATE_UNITS, loop.x_trim, loop.x_rate, "x"),
        "INPUT_TABLE": vector_table(INPUT_NAMES, INPUT_UNITS, loop.u_trim, None, "u"),
        "LAW": "\n".join(" *   " + line for line in textwrap.wrap(c_comment(exp.law()), 94)),
        "TOL_FLOAT": repr(tol_float), "TOL_DOUBLE": repr(ANTIWINDUP_TOL),
        "FLOAT_EXACT_S": f"{2 ** 24 * Ts:.4g}", "ULONG_DAYS": f"{2 ** 32 * Ts / 86400:.4g}",
        "NX": str(N_STATES), "NU": str(N_INPUTS), "NZ": str(nz), "NZ_STORAGE": str(max(nz, 1)),
        "NX_LOOP": str(spec.nx), "NC": str(len(c)), "NL": str(nl),
        "LAG_MEMBER": (f"  quadctl_real l[{nl}];  /* the rotor lag model: [T, A, E, R] the rotors reach, from trim "
                       "(N, N m x3) */\n" if nl else ""),
        "LAG_INIT": "  for (i = 0; i < QUADCTL_NL; ++i) c->l[i] = QUADCTL_LIT(0.0);\n" if nl else "",
        "LAG_LOAD": ("  for (i = 0; i < QUADCTL_NL; ++i) X[QUADCTL_NX + QUADCTL_NZ + i] = c->l[i];\n" if nl else ""),
        "LAG_STORE": ("  for (i = 0; i < QUADCTL_NL; ++i) c->l[i] = X_sampled[QUADCTL_NX + QUADCTL_NZ + i];\n"
                      if nl else ""),
        "LAG_DOC": lag_doc(loop, Ts),
        "DELAY_DOC": delay_doc(delay, Ts, kal is not None),
        "FILTER_DOC": filter_doc(loop, step_name(reference), reference),
        "SCHEDULE_DOC": schedule_doc(loop, reference),
        "NY": str(ny), "NB": str(nb),
        "STEP_ARG": "y" if ny else "x",
        "STEP_DOC": ("the measurements y\n * (QUADCTL_NY measured states, QUADCTL_Y_* order, state units)" if ny
                     else "the measured state x")
                    + ("\n * and the reference ref (x_ref(t), u_ref(t))" if reference else ""),
        "STEP_NAME": step_name(reference),
        "STEP_PROTOTYPE": (f"void {step_name(reference)}(quadctl_controller *c, const quadctl_real "
                           + ("y[QUADCTL_NY]" if ny else "x[QUADCTL_NX]")
                           + (", const quadctl_reference *ref" if reference else "") + ", quadctl_real u[QUADCTL_NU])"),
        **_reference_values(reference, "y" if ny else "x", Ts, exp.rate),
        "MEASURE_DEFINES": ("/* index of each measurement in y: the measured states, in state units */\n"
                            + "".join(f"#define QUADCTL_Y_{c_identifier(n.upper())} {i}  /* {n} ({STATE_UNITS[n]}), "
                                      f"x[{STATE_NAMES.index(n)}] */\n" for i, n in enumerate(loop.measured))
                            if ny else ""),
        "MEASURED_TABLE": ("\n/* The state index of each measurement y[i] (C picks these rows of x). */\n"
                           "static const int qc_measured[QUADCTL_NY] = {"
                           + ", ".join(str(STATE_NAMES.index(n)) for n in loop.measured) + "};\n" if ny else ""),
        "MEASUREMENT_LOAD": (("  for (i = 0; i < QUADCTL_NX; ++i) X[i] = QUADCTL_LIT(0.0);  /* the law reads only "
                              "the measured states */\n"
                              "  for (i = 0; i < QUADCTL_NY; ++i) X[qc_measured[i]] = y[i];\n") if ny else
                             "  for (i = 0; i < QUADCTL_NX; ++i) X[i] = x[i];\n"),
        "BUFFER_MEMBER": (f"  quadctl_real b[{nb}];  /* the last {delay} commands, newest first: the filter "
                          "predicts with the one the vehicle applies now */\n" if nb else ""),
        "BUFFER_INIT": ("  for (i = 0; i < QUADCTL_NB; ++i) c->b[i] = qc_c[QC_U_TRIM + i % QUADCTL_NU];"
                        "  /* the trim input, as the simulation starts */\n" if nb else ""),
        "BUFFER_LOAD": "  for (i = 0; i < QUADCTL_NB; ++i) X[QC_X_B + i] = c->b[i];\n" if nb else "",
        "BUFFER_STORE": "  for (i = 0; i < QUADCTL_NB; ++i) c->b[i] = X_sampled[QC_X_B + i];\n" if nb else "",
        "APPLIED_DECL": ", u_applied[QUADCTL_NU]" if nb else "",
        "LAW_U": "u_applied" if nb else "u",
        "COMMAND_STORE": ("  for (i = 0; i < QUADCTL_NU; ++i) u[i] = X_sampled[QC_X_B + i];  /* the new command "
                          "(u_applied: the one the filter's model applies now) */\n" if nb else ""),
        "NG": str(ng),
        "GYRO_MEMBER": (f"  quadctl_real g[{ng}];  /* the gyro filter's states, {ng // 3} per rate p, q, r (rad/s) */\n"
                        if ng else ""),
        "GYRO_INIT": ("  for (i = 0; i < QUADCTL_NG; ++i) c->g[i] = QUADCTL_LIT(0.0);  /* at rest, as the simulation "
                      "starts */\n" if ng else ""),
        "GYRO_LOAD": "  for (i = 0; i < QUADCTL_NG; ++i) X[QC_X_G + i] = c->g[i];\n" if ng else "",
        "GYRO_STORE": "  for (i = 0; i < QUADCTL_NG; ++i) c->g[i] = X_sampled[QC_X_G + i];\n" if ng else "",
        "GYRO_DOC": gyro_doc(loop, Ts, upstream),
        "NE": str(spec.n_estimate or N_STATES),
        "ESTIMATE_MEMBER": ("  quadctl_real xh[QUADCTL_NE];  /* the filter's a priori estimate of x - x_ref(t) for "
                            "this sample (state units)" + (", then of the gyro filter's states g" if ng else "")
                            + " */\n" if ny else ""),
        "ESTIMATE_INIT": ("  for (i = 0; i < QUADCTL_NE; ++i) c->xh[i] = QUADCTL_LIT(0.0);  /* the filter believes "
                          "the trim */\n" if ny else ""),
        "ESTIMATE_LOAD": "  for (i = 0; i < QUADCTL_NE; ++i) X[QC_X_XH + i] = c->xh[i];\n" if ny else "",
        "ESTIMATE_STORE": "  for (i = 0; i < QUADCTL_NE; ++i) c->xh[i] = X_sampled[QC_X_XH + i];\n" if ny else "",
        "STATE_DEFINES": "".join(f"#define QUADCTL_X_{c_identifier(n.upper())} {i}  /* {n} ({STATE_UNITS[n]}) */\n"
                                 for i, n in enumerate(STATE_NAMES)).rstrip("\n"),
        "INPUT_DEFINES": "".join(f"#define QUADCTL_U_{c_identifier(n)} {i}  /* {n} ({INPUT_UNITS[n]}) */\n"
                                 for i, n in enumerate(INPUT_NAMES)),
        "ROTOR_DEFINES": rotors,
        "TRIM_DEFINES": _trim_defines(loop.x_trim, loop.x_rate, loop.u_trim),
        "INTEGRAL_DOC": (": of " + ", ".join(f"-(x[{n}] - x_ref_{n})" for n in loop.integral_states)
                         + " (state units x s)") if nz else " (none in this design: unused)",
        "CONSTANT_DEFINES": "\n".join(f"#define QC_{name.upper()} {start}  /* {name} {'x'.join(map(str, shape))} */"
                                      for name, shape, start in offsets),
        "CONSTANTS": _constants(c, offsets),
        "LAW_FUNCTION": law,
    }
    package = resources.files("quadctl")
    templates = {name: Template(package.joinpath(f"{TEMPLATES}/{name}").read_text(encoding="utf-8"))
                 for name in (HEADER, SOURCE)}
    unpaired = {name: t.substitute(values, PAIR=PAIR_PLACEHOLDER) for name, t in templates.items()}
    pair = pair_id(unpaired)
    return {name: text.replace(PAIR_PLACEHOLDER, pair) for name, text in unpaired.items()}


PAIR_PLACEHOLDER = "QUADCTL_PAIR_ID"


def pair_id(files: dict[str, str]) -> str:
    """The number both C files carry (``QUADCTL_PAIR``): the first 32 bits of the sha256 of both
    texts (with the number itself left out), as a C literal. The source compiles only beside the
    header of the same export: a kill between the two renames, or an old file copied beside a new
    one, is a compile error (``#error``), never a controller whose header describes another law.

    >>> pair_id({"a.h": "x", "a.c": "y"})
    '0xee924d18UL'
    """
    import hashlib

    digest = hashlib.sha256()
    for name in sorted(files):
        digest.update(name.encode() + b"\0" + files[name].encode() + b"\0")
    return f"0x{digest.hexdigest()[:8]}UL"


def float_tolerance(actuators) -> float:
    """Clip tolerance of the float build (see :data:`FLOAT_ROUNDOFF_ULPS`), N or N m."""
    if actuators is None:
        return ANTIWINDUP_TOL
    bound = np.maximum(np.abs(np.where(np.isfinite(actuators.lo), actuators.lo, 0.0)),
                       np.abs(np.where(np.isfinite(actuators.hi), actuators.hi, 0.0)))
    scale = float(np.max(np.abs(actuators.mix_inv) @ bound)) or 1.0
    return float(f"{FLOAT_ROUNDOFF_ULPS * FLT_EPSILON * scale:.2g}")


def _reference_values(reference: bool, arg: str, Ts: float, rate: float) -> dict[str, str]:
    """The template's text that differs between a law that holds the trim and one that flies a reference.

    A reference is the law's exogenous row (:data:`quadctl.sim.loop_layout.REFERENCE_LAYOUT`: the
    reference expanded about a time ``t_j``), which the simulation tabulates and ``quadctl_step_ref``
    fills from the ``quadctl_reference`` it is given, expanded about the sample itself (``t_j = t``,
    no rates): the law then reads ``x_ref(t) = ref->x`` and ``u_ref(t) = ref->u``.
    """
    what = "the measurements y read" if arg == "y" else "the state measured"
    if not reference:
        return {"CALL_DOC": doc_lines([
                    "quadctl_init(&c) once, before the first sample: integrators and time to zero.",
                    f"quadctl_step(&c, {arg}, u) once every QUADCTL_SAMPLE_TIME = {Ts!r} s ({float(rate)!r} Hz), "
                    f"with {what} at that instant; apply u until the next call (zero-order hold). The reference "
                    "moves with time (x_ref(t) = x_trim + x_rate t); the controller counts its own calls, t = k Ts, "
                    "so call it at every sample, and quadctl_init again to restart the reference at t = 0.",
                    _NO_ALLOCATION]),
                "REFERENCE_DOC": "", "REFERENCE_TYPES": "", "REFERENCE_FUNCTIONS": "", "REFERENCE_DEFINITIONS": "",
                "EXO_DEFINES": "", "EXO_DECL": "", "EXO_LOAD": "", "LAW_E": "NULL"}
    n_arg = f"QUADCTL_N{arg.upper()}"
    doc = doc_lines([
        "Each sample takes the reference as a quadctl_reference (quadctl's simulation takes it from "
        "simulation.reference; a flight stack, from its commander's setpoints):",
        "  ref.x = x_ref(t), the commanded state: all 12, in the order and units of x (QUADCTL_X_*);",
        "  ref.u = u_ref(t), the feedforward input, in the order and units of u (QUADCTL_U_*);",
        "both at the sample's instant t. Along a smooth path they are its differential-flatness trim: "
        "position, velocity, attitude and body rates along the path, and the thrust and torques that fly it "
        "(quadctl.physics.flatness.feedforward: what `quadctl simulate` gives its law; sim.npz holds the run's x_ref "
        "and u_ref). The law reads nothing else of the path (no rates, no time): sample your path generator "
        "at each sample's time and hand the two vectors over. A hover trim moved to another position "
        "(u_ref = u_trim) holds that point; quadctl_reference_trim gives the trim to start from.",
        "",
        "Example: hold 1 m north of the trim and 0.5 m higher.",
        "  quadctl_controller c;",
        "  quadctl_reference ref;",
        f"  quadctl_real {arg}[{n_arg}], u[QUADCTL_NU];",
        "  quadctl_init(&c);",
        "  quadctl_reference_trim(&ref);",
        "  ref.x[QUADCTL_X_PN] += 1.0;  // m north",
        "  ref.x[QUADCTL_X_PD] -= 0.5;  // m down: 0.5 m up",
        f"  every QUADCTL_SAMPLE_TIME: read {arg}; quadctl_step_ref(&c, {arg}, &ref, u); apply u",
    ])
    defines, start = [], 0
    for name, size in exo_layout(noise=False, wind=False, reference=True):
        defines.append(f"#define QC_E_{name.upper()} {start}  /* {name} ({size}) */")
        start += size
    return {
        "CALL_DOC": doc_lines([
            "quadctl_init(&c) once, before the first sample: integrators to zero.",
            f"quadctl_step_ref(&c, {arg}, &ref, u) once every QUADCTL_SAMPLE_TIME = {Ts!r} s ({float(rate)!r} Hz), "
            f"with {what} and the reference ref at that instant (THE REFERENCE below); apply u until the next "
            "call (zero-order hold).",
            _NO_ALLOCATION]),
        "REFERENCE_DOC": " *\n * THE REFERENCE\n" + doc + "\n",
        "REFERENCE_TYPES": (
            "\n/* The reference at one sample: what quadctl_step_ref regulates to. */\n"
            "typedef struct quadctl_reference {\n"
            "  quadctl_real x[QUADCTL_NX];  /* x_ref(t): the commanded state (order and units of x: QUADCTL_X_*) */\n"
            "  quadctl_real u[QUADCTL_NU];  /* u_ref(t): the feedforward input (order and units of u: QUADCTL_U_*) */\n"
            "} quadctl_reference;\n"),
        "REFERENCE_FUNCTIONS": (
            "\n/* ref = the design's trim: x = x_trim (at t = 0), u = u_trim. A reference to edit: a hover trim\n"
            " * at another position (ref->x[QUADCTL_X_PN], ...) holds that position. */\n"
            "void quadctl_reference_trim(quadctl_reference *ref);\n"),
        "REFERENCE_DEFINITIONS": (
            "void quadctl_reference_trim(quadctl_reference *ref) {\n"
            "  int i;\n"
            "  for (i = 0; i < QUADCTL_NX; ++i) ref->x[i] = qc_c[QC_X_REF + i];\n"
            "  for (i = 0; i < QUADCTL_NU; ++i) ref->u[i] = qc_c[QC_U_TRIM + i];\n"
            "}\n\n"),
        "EXO_DEFINES": (
            "\n/* The law's exogenous row: the reference expanded about a time t_j\n"
            " * (quadctl.sim.loop_layout.REFERENCE_LAYOUT), s = t - t_j:\n"
            " *   x_ref(t) = ref_x + s (ref_rate + s ref_curvature / 2), u_ref(t) = ref_u + s ref_u_rate\n"
            " * (the step_ref_ columns: the expansion a simulated step's stages read, not the law).\n"
            " * quadctl_step_ref expands about the sample itself (t_j = t, s = 0, no rates):\n"
            " *   x_ref(t) = ref->x, u_ref(t) = ref->u. */\n"
            + "\n".join(defines) + f"\n#define QC_NE {start}\n"),
        "EXO_DECL": ", e[QC_NE]",
        "EXO_LOAD": ("  for (i = 0; i < QC_NE; ++i) e[i] = QUADCTL_LIT(0.0);\n"
                     "  e[QC_E_REF_T] = t;\n"
                     "  for (i = 0; i < QUADCTL_NX; ++i) e[QC_E_REF_X + i] = ref->x[i];\n"
                     "  for (i = 0; i < QUADCTL_NU; ++i) e[QC_E_REF_U + i] = ref->u[i];\n"),
        "LAW_E": "e",
    }


_NO_ALLOCATION = "No allocation, no global state: everything lives in the struct; one struct per vehicle."


def step_name(reference: bool) -> str:
    """The C function a sample calls: ``quadctl_step_ref`` when the law flies a reference (it takes one),
    else ``quadctl_step`` (it holds the trim)."""
    return "quadctl_step_ref" if reference else "quadctl_step"


def _offsets(nz: int, lag_model: bool = False, ny: int = 0, schedule: tuple[int, ...] = (),
             filter_order: int = 0) -> list[tuple[str, tuple[int, ...], int]]:
    """(name, shape, first index) of each block of the constant vector."""
    out, start = [], 0
    for name, shape in constant_layout(nz, lag_model=lag_model, ny=ny, schedule=schedule, filter_order=filter_order):
        out.append((name, shape, start))
        start += int(np.prod(shape))
    return out


def _trim_defines(x_trim, x_rate, u_trim) -> str:
    """The header's trim as macros: one per state and input, and brace initializers of the vectors."""
    def lit(v):
        return f"({float(v)!r})"
    lines = ["/* The trim the design holds: x_ref(t) = x_trim + x_rate t (state units), u_trim (input units).",
             " * QUADCTL_TRIM_X_<STATE>, QUADCTL_RATE_X_<STATE>, QUADCTL_TRIM_U_<INPUT>; the vectors as",
             " * initializers: quadctl_real x0[QUADCTL_NX] = QUADCTL_TRIM_X_INIT; quadctl_trim() copies both. */"]
    lines += [f"#define QUADCTL_TRIM_X_{c_identifier(n.upper())} {lit(v)}" for n, v in zip(STATE_NAMES, x_trim)]
    lines += [f"#define QUADCTL_RATE_X_{c_identifier(n.upper())} {lit(v)}" for n, v in zip(STATE_NAMES, x_rate)]
    lines += [f"#define QUADCTL_TRIM_U_{c_identifier(n)} {lit(v)}" for n, v in zip(INPUT_NAMES, u_trim)]
    lines.append("#define QUADCTL_TRIM_X_INIT {" + ", ".join(f"QUADCTL_TRIM_X_{c_identifier(n.upper())}"
                                                           for n in STATE_NAMES) + "}")
    lines.append("#define QUADCTL_RATE_X_INIT {" + ", ".join(f"QUADCTL_RATE_X_{c_identifier(n.upper())}"
                                                           for n in STATE_NAMES) + "}")
    lines.append("#define QUADCTL_TRIM_U_INIT {" + ", ".join(f"QUADCTL_TRIM_U_{c_identifier(n)}"
                                                           for n in INPUT_NAMES) + "}")
    return "\n".join(lines) + "\n"


def _literal(v: float) -> str:
    if math.isinf(v):
        return "INFINITY" if v > 0 else "-INFINITY"
    return f"QUADCTL_LIT({float(v)!r})"


def _constants(c: np.ndarray, offsets) -> str:
    lines = []
    for name, shape, start in offsets:
        size = int(np.prod(shape))
        items = [_literal(v) for v in c[start:start + size]]
        lines.append(f"  /* {name} */")
        lines += ["  " + ", ".join(items[i:i + 4]) + "," for i in range(0, size, 4)]
    return "\n".join(lines).rstrip(",")
