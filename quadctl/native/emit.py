"""C source of CasADi SX functions evaluated on several cases ("lanes") at once.

A CasADi SX function is a straight-line program of scalar operations (its instruction list).
:func:`emit` writes it as a C function whose body is a loop over ``lanes`` cases, every
variable holding one value per lane: the C compiler vectorizes that loop (sin and cos included,
through glibc's vector math library) when ``lanes > 1``, and with ``lanes = 1`` it is the plain
one-case function. Arguments are lane-major within each element: element ``j`` of argument
``i`` for lane ``l`` is ``i<i>[j * lanes + l]``.

The operations are CasADi's, spelled as its virtual machine computes them (``if_else_zero(c, x)``
is ``c == 0 ? 0 : x``, comparisons give 1.0 or 0.0), so compiled and interpreted runs round alike.
Every branch is a select the lane loop vectorizes: ``fmin(a, b)`` is ``b < a ? b : a`` (C's ``fmin``
but for a NaN operand, which it passes on where ``fmin`` drops it: a run with a NaN state has stopped),
``and``/``or`` nest their selects instead of short-circuiting.

A :class:`Dialect` says how the C spells its scalars: the engine's is plain ``double`` with a
vectorized lane loop (:data:`ENGINE`); :mod:`quadctl.export` spells a scalar type and math
functions chosen when the file is compiled (``double`` or ``float``), warning-free under
``-std=c99 -Wall -Wextra -pedantic``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache

from quadctl._lazy import lazy_import

ca = lazy_import("casadi")  # loaded on first use: see quadctl._lazy

SIMD_DECLARATIONS = """\
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
/* the lanes' step holds ~160 values a lane across its vector sin and cos calls (which keep no
   vector register): schedule before allocating registers, minding pressure, so fewer spill */
#pragma GCC optimize ("schedule-insns", "sched-pressure")
/* glibc's libmvec has vector variants of these: declaring them lets GCC vectorize the lane loop */
double sin(double) __attribute__((simd("notinbranch"), const, nothrow));
double cos(double) __attribute__((simd("notinbranch"), const, nothrow));
double tan(double) __attribute__((simd("notinbranch"), const, nothrow));
#endif
"""
"""Put before the emitted functions of a vectorized build (GCC on x86-64 Linux only). Besides the
vector sin, cos and tan it turns on GCC's register-pressure-aware scheduling before register
allocation (``-fschedule-insns -fsched-pressure``, off by default on x86), for the functions that
follow: it only reorders independent operations, so every value is the same (the plain sweep's
summaries bit for bit); with driver.c's leaner step, the plain sweep's lanes take 5-7 % more steps
a CPU second (its cases in the lanes alone, GCC 12, AVX2, best of 12-15 alternated rounds on a
shared machine): the generated step's work values spill to the stack around every vector call.
Here, not in the compile flags, so that a compiler other than GCC never meets the flags."""


@dataclass(frozen=True)
class Dialect:
    """How emitted C spells its scalars (the default, :data:`ENGINE`, is the simulation engine's).

    Attributes
    ----------
    real : str
        The scalar type of arguments and work variables.
    literal : str
        Format of a numeric literal; ``{}`` is its Python ``repr`` (``"QUADCTL_LIT({})"``).
    call : str
        Format of a math function's name; ``{}`` is the C99 double name (``"QUADCTL_FN({})"``,
        which a float build spells ``sinf``).
    pragma : bool
        Mark the lane loop ``#pragma omp simd`` (without OpenMP, ``-Wall`` warns of it).
    named : tuple of (float, str)
        Constants spelled by a name (a macro) instead of their value.
    mark_used : bool
        Open the function with ``(void)i0;`` ... for every argument, so that one it never reads
        (an empty exogenous input) is no warning under ``-Wextra``.
    """

    real: str = "double"
    literal: str = "{}"
    call: str = "{}"
    pragma: bool = True
    named: tuple[tuple[float, str], ...] = ()
    mark_used: bool = False

    def constant(self, value: float) -> str:
        """The C text of a constant of the function."""
        for known, name in self.named:
            if value == known:
                return name
        return self.literal.format(repr(float(value)))


ENGINE = Dialect()
"""The simulation engine's C: ``double`` lanes, vectorized."""

_CALL = re.compile(r"\b([a-z]+)\(")
_LITERAL = re.compile(r"\b\d+\.\d+\b")


@lru_cache(maxsize=8)
def _spelled(dialect: Dialect) -> dict[int, str]:
    """:func:`_templates` with the dialect's literals and math calls."""
    def spell(template: str) -> str:
        template = _CALL.sub(lambda m: dialect.call.format(m.group(1)) + "(", template)
        return _LITERAL.sub(lambda m: dialect.literal.format(m.group(0)), template)

    return {op: spell(template) for op, template in _templates().items()}


@lru_cache(maxsize=1)
def _templates() -> dict[int, str]:
    """CasADi operation code -> C expression template over ``{a}`` and ``{b}``."""
    return {
        ca.OP_ADD: "{a} + {b}", ca.OP_SUB: "{a} - {b}", ca.OP_MUL: "{a} * {b}", ca.OP_DIV: "{a} / {b}",
        ca.OP_NEG: "-{a}", ca.OP_TWICE: "2.0 * {a}", ca.OP_SQ: "{a} * {a}", ca.OP_INV: "1.0 / {a}",
        ca.OP_SIN: "sin({a})", ca.OP_COS: "cos({a})", ca.OP_TAN: "tan({a})", ca.OP_SQRT: "sqrt({a})",
        ca.OP_FABS: "fabs({a})", ca.OP_EXP: "exp({a})", ca.OP_LOG: "log({a})", ca.OP_FLOOR: "floor({a})",
        ca.OP_ATAN: "atan({a})", ca.OP_ATAN2: "atan2({a}, {b})",
        ca.OP_FMIN: "({b} < {a}) ? {b} : {a}", ca.OP_FMAX: "({b} > {a}) ? {b} : {a}",
        ca.OP_POW: "pow({a}, {b})", ca.OP_CONSTPOW: "pow({a}, {b})",
        ca.OP_LT: "({a} < {b}) ? 1.0 : 0.0", ca.OP_LE: "({a} <= {b}) ? 1.0 : 0.0",
        ca.OP_EQ: "({a} == {b}) ? 1.0 : 0.0", ca.OP_NE: "({a} != {b}) ? 1.0 : 0.0",
        ca.OP_NOT: "({a} == 0.0) ? 1.0 : 0.0",
        ca.OP_AND: "({a} != 0.0) ? (({b} != 0.0) ? 1.0 : 0.0) : 0.0",
        ca.OP_OR: "({a} != 0.0) ? 1.0 : (({b} != 0.0) ? 1.0 : 0.0)",
        ca.OP_IF_ELSE_ZERO: "({a} == 0.0) ? 0.0 : {b}",
    }


def emit(fn, name: str, lanes: int, dialect: Dialect = ENGINE, invariant: tuple[int, ...] = ()) -> str:
    """C source of the SX function ``fn`` as ``static void name(args...)`` over ``lanes`` cases.

    With ``invariant`` (indices of inputs that keep their values over many calls: a case's step and
    constants), the operations computed from those inputs alone are hoisted: ``name_pre(inputs...,
    p)`` computes them once into ``p`` (``name_nh`` values a lane, a macro), and ``name(args..., p)``
    reads them there instead of computing them at every call: the same operations on the same
    operands, so the same numbers.

    Parameters
    ----------
    fn : casadi.Function
        An SX function; its inputs become ``const double* i0, i1...``, its outputs ``double* o0...``.
    name : str
        The C function's name.
    lanes : int
        Cases per call (1: the one-case function).
    dialect : Dialect
        How the C spells its scalars (default: the engine's ``double``).
    invariant : tuple of int
        Inputs the hoisted operations may read (none: nothing hoisted, one function).

    Raises
    ------
    ValueError
        ``fn`` uses an operation with no C form here.
    """
    templates = _spelled(dialect)
    real = dialect.real
    args = [f"const {real}* restrict i{k}" for k in range(fn.n_in())]
    args += [f"{real}* restrict o{k}" for k in range(fn.n_out())]
    body, pre, hoisted = [], [], 0
    fixed = {}  # work slot -> its value depends on the invariant inputs alone
    for k in range(fn.n_instructions()):
        op = fn.instruction_id(k)
        ins = fn.instruction_input(k)
        out = fn.instruction_output(k)
        if op == ca.OP_INPUT:
            line = f"w{out[0]} = i{ins[0]}[{ins[1]} * {lanes} + l];"
            fixed[out[0]] = ins[0] in invariant
            if fixed[out[0]]:
                pre.append("    " + line)
        elif op == ca.OP_OUTPUT:
            line = f"o{out[0]}[{out[1]} * {lanes} + l] = w{ins[0]};"
        elif op == ca.OP_CONST:
            line = f"w{out[0]} = {dialect.constant(fn.instruction_constant(k))};"
            fixed[out[0]] = True
            pre.append("    " + line)
        elif op in templates:
            a = f"w{ins[0]}"
            b = f"w{ins[1]}" if len(ins) > 1 else ""
            line = f"w{out[0]} = {templates[op].format(a=a, b=b)};"
            fixed[out[0]] = bool(invariant) and all(fixed.get(i, False) for i in ins)
            if fixed[out[0]]:
                pre.append(f"    {line} p[{hoisted} * {lanes} + l] = w{out[0]};")
                line = f"w{out[0]} = p[{hoisted} * {lanes} + l];"
                hoisted += 1
        else:
            raise ValueError(f"{name}: CasADi operation {op} has no C form in quadctl.native.emit")
        body.append("    " + line)
    work = ", ".join(f"w{i}" for i in range(max(fn.sz_w(), 1)))
    used = "".join(f"  (void)i{k};\n" for k in range(fn.n_in())) if dialect.mark_used else ""
    loop = ("#pragma omp simd\n" if dialect.pragma else "") + f"  for (int l = 0; l < {lanes}; ++l) {{\n"
    if not invariant:
        return (f"static void {name}({', '.join(args)}) {{\n" + used + loop
                + f"    {real} {work};\n" + "\n".join(body) + "\n  }\n}\n")
    inputs = args[:fn.n_in()]
    return (f"#define {name}_nh {max(hoisted, 1)}\n"
            f"static void {name}_pre({', '.join([*inputs, f'{real}* restrict p'])}) {{\n"
            + "".join(f"  (void)i{k};\n" for k in range(fn.n_in())) + loop
            + f"    {real} {work};\n" + "\n".join(pre) + "\n  }\n}\n"
            f"static void {name}({', '.join([*args, f'const {real}* restrict p'])}) {{\n" + used
            + "  (void)p;\n" + loop + f"    {real} {work};\n" + "\n".join(body) + "\n  }\n}\n")
