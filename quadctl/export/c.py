"""The controller as C99: one header and one source, generated from the simulation's control law.

The law is not written here: :func:`sources` builds the ``law`` function of the loop's
:class:`~quadctl.sim.builder.LoopSpec` (the gain's sparsity, the saturation mode, the
integrators, sampled) with :func:`quadctl.sim.builder.build`, the function ``quadctl simulate``
compiles, and emits it with :func:`quadctl.sim.emit.emit` in a :class:`~quadctl.sim.emit.Dialect`
whose scalar type, literals and math functions the compiler chooses: ``double``, or ``float``
with ``-DQUADCTL_FLOAT``. The loop's constant vector (trim, reference drift, gains, anti-wind-up
mask, mixing, limits, sample time) is baked in as a ``static const`` array. Everything around
the law (``templates/quadctl_controller.h`` and ``.c``: the struct, init, step, mix) is a C
template in the package; sizes, names and offsets come from :mod:`quadctl.layout` and
:func:`quadctl.sim.builder.constant_layout`.

Why emit, and not CasADi's own ``CodeGenerator`` (checked with CasADi 3.8): its ``casadi_real:
float`` option types the work variables as float but keeps double literals
(``1.0000000000000001e-01``) and double math (``sin``), so a float build still computes in double,
and its calling convention (pointer arrays, work vectors, ``mem``, checkout and release entry
points) leaves parameters unused that ``-Wextra -Werror`` refuses. ``emit`` writes one
straight-line function, the one the engine compiles, warning-free under ``-std=c99 -Wall -Wextra
-pedantic`` in both precisions.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import replace
from importlib import resources
from string import Template

import numpy as np

from quadctl import __version__
from quadctl.export import Export
from quadctl.layout import INPUT_NAMES, INPUT_UNITS, N_INPUTS, N_STATES, STATE_NAMES, STATE_UNITS
from quadctl.motors import SPINS
from quadctl.sim.builder import ANTIWINDUP_TOL, build, constant_layout

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


def sources(exp: Export) -> dict[str, str]:
    """The C files of the exported controller: ``{file name: text}``.

    Parameters
    ----------
    exp : Export
        A sampled design (``exp.rate`` set: :func:`quadctl.export.prepare` with a rate).

    Returns
    -------
    dict of str -> str
        :data:`HEADER` and :data:`SOURCE`.

    Raises
    ------
    ValueError
        ``exp`` is continuous (nothing to sample), or the law has an operation ``emit`` cannot write.
    ConfigError
        The loop closes through a Kalman filter (``estimator:``), which the C controller does not carry.
    """
    from quadctl.sim.emit import Dialect, emit

    if exp.sample_time is None:
        raise ValueError("a C controller samples: prepare the export with a rate")
    loop, Ts = exp.loop, exp.sample_time
    if loop.estimator is not None:
        from quadctl.errors import ConfigError

        raise ConfigError("estimator: the C controller acts on the measured full state; exporting the Kalman "
                          "filter is not built: use --to json or --to mat (design.json holds the filter), or "
                          "remove estimator: to export the full-state law")
    if loop.rotor_time_constant is not None:  # the rotors' lag is the vehicle's, not the law's: no rotor states
        act = loop.actuators
        loop = replace(loop, actuators=replace(act, motors=replace(act.motors, time_constant=None)))
    delay = loop.delay_samples
    loop = replace(loop, delay_samples=0)  # so is the delay: the vehicle's computer and bus add it
    spec = loop.spec(noise=False)  # a design with the rotors' lag keeps its lag model: controller states
    c = loop.constants(Ts)
    nz, nl = len(loop.integral_states), spec.n_lag
    dialect = Dialect(real="quadctl_real", literal="QUADCTL_LIT({})", call="QUADCTL_FN({})", pragma=False,
                      named=((ANTIWINDUP_TOL, "QUADCTL_ANTIWINDUP_TOL"),), mark_used=True)
    law = emit(build(spec).law, "qc_law", 1, dialect)
    offsets = _offsets(nz, spec.lag_model)
    act = loop.actuators
    rotors = ""
    if act is not None and act.mode == "motors":
        rotors = (f"#define QUADCTL_N_ROTORS {len(act.names)}\n"
                  "/* rotors (FRD body frame, numbered clockwise from above; thrust along body -z) */\n"
                  + "".join(f"/*   rotor {i + 1}: x = {x:+.6g} m, y = {y:+.6g} m, spins "
                            f"{'counter-clockwise' if s > 0 else 'clockwise'} seen from above */\n"
                            for i, ((x, y), s) in enumerate(zip(act.motors.positions(), SPINS))))
    tol_float = float_tolerance(act)
    values = {
        "CONFIG": exp.name, "VERSION": __version__, "CONFIG_HASH": exp.config_hash or "not recorded",
        "TS": repr(Ts), "RATE": repr(float(exp.rate)),
        "STATE_TABLE": _table(STATE_NAMES, STATE_UNITS, loop.x_trim, loop.x_rate, "x"),
        "INPUT_TABLE": _table(INPUT_NAMES, INPUT_UNITS, loop.u_trim, None, "u"),
        "LAW": "\n".join(" *   " + line for line in textwrap.wrap(exp.law(), 94)),
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
        "LAG_DOC": _lag_doc(loop, Ts),
        "DELAY_DOC": _delay_doc(delay, Ts),
        "STATE_DEFINES": "".join(f"#define QUADCTL_X_{n.upper()} {i}  /* {n} ({STATE_UNITS[n]}) */\n"
                                 for i, n in enumerate(STATE_NAMES)).rstrip("\n"),
        "INPUT_DEFINES": "".join(f"#define QUADCTL_U_{n} {i}  /* {n} ({INPUT_UNITS[n]}) */\n"
                                 for i, n in enumerate(INPUT_NAMES)),
        "ROTOR_DEFINES": rotors,
        "INTEGRAL_DOC": (": of " + ", ".join(f"-(x[{n}] - x_ref_{n})" for n in loop.integral_states)
                         + " (state units x s)") if nz else " (none in this design: unused)",
        "CONSTANT_DEFINES": "\n".join(f"#define QC_{name.upper()} {start}  /* {name} {'x'.join(map(str, shape))} */"
                                      for name, shape, start in offsets),
        "CONSTANTS": _constants(c, offsets),
        "LAW_FUNCTION": law,
    }
    package = resources.files("quadctl")
    return {name: Template(package.joinpath(f"{TEMPLATES}/{name}").read_text(encoding="utf-8")).substitute(values)
            for name in (HEADER, SOURCE)}


def float_tolerance(actuators) -> float:
    """Clip tolerance of the float build (see :data:`FLOAT_ROUNDOFF_ULPS`), N or N m."""
    if actuators is None:
        return ANTIWINDUP_TOL
    bound = np.maximum(np.abs(np.where(np.isfinite(actuators.lo), actuators.lo, 0.0)),
                       np.abs(np.where(np.isfinite(actuators.hi), actuators.hi, 0.0)))
    scale = float(np.max(np.abs(actuators.mix_inv) @ bound)) or 1.0
    return float(f"{FLOAT_ROUNDOFF_ULPS * FLT_EPSILON * scale:.2g}")


def _lag_doc(loop, Ts: float) -> str:
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


def _delay_doc(delay: int, Ts: float) -> str:
    """The header's paragraph on the delay: the law is the law before it."""
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


def _offsets(nz: int, lag_model: bool = False) -> list[tuple[str, tuple[int, ...], int]]:
    """(name, shape, first index) of each block of the constant vector."""
    out, start = [], 0
    for name, shape in constant_layout(nz, lag_model=lag_model):
        out.append((name, shape, start))
        start += int(np.prod(shape))
    return out


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


def _table(names, units, trim, rate, symbol: str) -> str:
    rows = []
    for i, name in enumerate(names):
        drift = f", drifting {rate[i]:+.6g} {units[name]}/s" if rate is not None and rate[i] != 0 else ""
        rows.append(f" *   {symbol}[{i:2d}] {name:<6} {units[name]:<6} trim {trim[i]:+.9g}{drift}")
    return "\n".join(rows)
