"""Many closed-loop simulations at once: SIMD "lanes" generated from the CasADi model.

A sweep simulates thousands of designs of the same structure (same gain sparsity, no
saturation, continuous feedback). Here the closed-loop RK4 step is built symbolically from
:func:`quadctl.model.build_model` (the one copy of the equations) and the plain LQR law
``u = u_trim - K (x - x_trim - x_rate t)``, and its CasADi instruction list (an SSA program of
scalar operations) is emitted as C in which every variable holds one value per *lane*: the
body becomes a loop over :data:`LANES` cases that the C compiler vectorizes, sin, cos and tan
included (glibc's vector math library). Each lane is one case with its own constants, step
size, step count and stride; lanes that finish or diverge freeze while the others go on.

The loop contract per lane is that of :meth:`quadctl.codegen.CompiledLoop.run` (the driver in
``_driver.c``): the same recorded rows (steps ``0, stride, 2 stride, ...`` and the last), the
same stop at the first state outside ``[lo, hi]``, the same input on the final row.

Fallbacks, each tried in order: the vectorized build; a portable build (same C, no SIMD
declarations, no ``-march=native``); and, without a C compiler (or with
``QUADCTL_NO_COMPILE=1``), CasADi's interpreter running the same functions one case at a time.
"""

from __future__ import annotations

import ctypes
import hashlib
import platform
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.codegen import FINGERPRINT, compile_cached, find_compiler, record_rows
from quadctl.layout import N_INPUTS, N_STATES
from quadctl.model import N_DISTURBANCES, N_PARAMS, build_model

ca = lazy_import("casadi")  # loaded on first use: see quadctl._lazy
LANE_FINGERPRINT = hashlib.sha256(FINGERPRINT.encode() + Path(__file__).read_bytes()).hexdigest()
"""Cache key part of the lane libraries: the scalar generator's and this file, as imported (see
:data:`quadctl.codegen.SCALAR_SOURCES`)."""

LANES = 8
"""Cases per vectorized call: one AVX-512 register of doubles, or two AVX2 ones."""
C_LONG = np.dtype(f"i{ctypes.sizeof(ctypes.c_long)}")
"""numpy's twin of C ``long`` (the driver's integer type)."""

LANE_LAYOUT: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("x_ref", (N_STATES,)),        # reference state at t = 0 (the trim)
    ("x_rate", (N_STATES,)),       # reference drift: x_ref(t) = x_ref + x_rate t
    ("u_trim", (N_INPUTS,)),
    ("K", (N_INPUTS, N_STATES)),   # column-major
    ("params", (N_PARAMS,)),       # Vehicle.vector()
)
"""The per-case constant vector ``c`` of the lane functions."""

SIMD_FLAGS = ("-O3", "-march=native", "-ffp-contract=off", "-fno-math-errno", "-fno-builtin-sin",
              "-fno-builtin-cos", "-fno-builtin-tan", "-fopenmp-simd", "-fPIC", "-shared")
"""``-fno-builtin-sin/cos`` keep GCC from fusing sin and cos into one scalar ``sincos`` call (it
has no vector form); ``-ffp-contract=off`` keeps a*b+c rounded as written (no FMA), so the lanes
round like the scalar loop; no ``-ffast-math``: NaN still propagates and stops a diverging lane."""
PORTABLE_FLAGS = ("-O3", "-fno-math-errno", "-fPIC", "-shared")

_SIMD_DECLARATIONS = """\
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
/* glibc's libmvec has vector variants of these: declaring them lets GCC vectorize the lane loop */
double sin(double) __attribute__((simd("notinbranch"), const, nothrow));
double cos(double) __attribute__((simd("notinbranch"), const, nothrow));
double tan(double) __attribute__((simd("notinbranch"), const, nothrow));
#endif
"""

_DRIVER = r"""
/* Lane driver: x0, lo, hi are [12][QB_L] (state-major), c is [QB_NC][QB_L], dt/n/stride are [QB_L].
 * Records into xs [QB_L][12][rows_max], us [QB_L][4][rows_max], ks [QB_L][rows_max]: per lane, each
 * state's samples are contiguous (what the metrics reduce over). */
void qb_run(const double* x0, const double* dt, const long* n, const long* stride, const double* c,
            const double* lo, const double* hi, long rows_max,
            double* xs, double* us, long* ks, long* n_rec, long* done) {
  double X[12 * QB_L], XN[12 * QB_L], XF[12 * QB_L], U[4 * QB_L], UF[4 * QB_L], T[QB_L];
  long countdown[QB_L], rows[QB_L];
  int active[QB_L], inb[QB_L], n_active = 0;
  memcpy(X, x0, sizeof X);
  memcpy(XF, x0, sizeof XF);
  for (int l = 0; l < QB_L; ++l) {
    active[l] = n[l] > 0; inb[l] = 1; rows[l] = 0; countdown[l] = 0; done[l] = 0;
    n_active += active[l];
  }
  for (long k = 0; n_active > 0; ++k) {
    double bad[QB_L];
    int rec = 0;
    for (int l = 0; l < QB_L; ++l) {
      T[l] = dt[l] * (double)k;
      bad[l] = 0.0;
      rec |= active[l] && countdown[l] == 0;
    }
    qb_step(X, T, dt, c, XN, U);
    if (rec) {
      for (int l = 0; l < QB_L; ++l) {
        if (!active[l] || countdown[l] != 0) continue;
        double* xr = xs + l * 12 * rows_max + rows[l];
        double* ur = us + l * 4 * rows_max + rows[l];
        for (int i = 0; i < 12; ++i) xr[i * rows_max] = X[i * QB_L + l];
        for (int i = 0; i < 4; ++i) ur[i * rows_max] = U[i * QB_L + l];
        ks[l * rows_max + rows[l]] = k;
        rows[l]++;
        countdown[l] = stride[l];
      }
    }
    /* bounds of every lane at once (vectorized; NaN compares false, so it counts as out) */
    for (int i = 0; i < 12; ++i)
      for (int l = 0; l < QB_L; ++l) {
        double v = XN[i * QB_L + l];
        bad[l] += (v >= lo[i * QB_L + l] && v <= hi[i * QB_L + l]) ? 0.0 : 1.0;
      }
    memcpy(X, XN, sizeof X);
    for (int l = 0; l < QB_L; ++l) {
      if (!active[l]) continue;
      countdown[l]--;
      if (bad[l] != 0.0 || k + 1 == n[l]) {
        /* the lane is done: keep its final state, and restart it from x0 so that it goes on
           computing harmless numbers (a runaway lane would drag the vector math into its slow
           paths for huge or NaN arguments) */
        active[l] = 0; n_active--;
        done[l] = k + 1;
        if (bad[l] != 0.0) {
          inb[l] = 0;
          for (int i = 0; i < 4; ++i) UF[i * QB_L + l] = U[i * QB_L + l];
        }
        for (int i = 0; i < 12; ++i) {
          XF[i * QB_L + l] = X[i * QB_L + l];
          X[i * QB_L + l] = x0[i * QB_L + l];
        }
      }
    }
  }
  /* the final state, with the input the law gives there (or, past the bounds, the last one) */
  for (int l = 0; l < QB_L; ++l) T[l] = dt[l] * (double)done[l];
  qb_ctrl(XF, T, c, U);
  for (int l = 0; l < QB_L; ++l) {
    double* xr = xs + l * 12 * rows_max + rows[l];
    double* ur = us + l * 4 * rows_max + rows[l];
    for (int i = 0; i < 12; ++i) xr[i * rows_max] = XF[i * QB_L + l];
    for (int i = 0; i < 4; ++i) ur[i * rows_max] = inb[l] ? U[i * QB_L + l] : UF[i * QB_L + l];
    ks[l * rows_max + rows[l]] = done[l];
    n_rec[l] = rows[l] + 1;
  }
}
"""


def lane_const_size() -> int:
    return sum(int(np.prod(shape)) for _, shape in LANE_LAYOUT)


def pack_lane_constants(x_ref, x_rate, u_trim, K, params) -> np.ndarray:
    """The ``c`` vector of one case (layout :data:`LANE_LAYOUT`)."""
    values = {"x_ref": x_ref, "x_rate": x_rate, "u_trim": u_trim, "K": K, "params": params}
    out = []
    for name, shape in LANE_LAYOUT:
        arr = np.asarray(values[name], dtype=float)
        if arr.shape != shape:
            raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
        out.append(arr.ravel(order="F"))
    return np.concatenate(out)


@dataclass(frozen=True)
class LaneFunctions:
    """``step(x, t, dt, c) -> (x_next, u)`` and ``ctrl(x, t, c) -> u`` for one gain pattern."""

    step: ca.Function
    ctrl: ca.Function


@lru_cache(maxsize=8)
def build_lane_functions(pattern: tuple[bool, ...]) -> LaneFunctions:
    """Closed-loop RK4 step and control law for a gain sparsity ``pattern`` (48 bools, column-major).

    Structural zeros of the gain vanish from the expression graph (so from the generated code).
    """
    f = build_model().f_disturbed
    c = ca.SX.sym("c", lane_const_size())
    parts, offset = {}, 0
    for name, shape in LANE_LAYOUT:
        size = int(np.prod(shape))
        block = c[offset:offset + size]
        parts[name] = ca.reshape(block, *shape) if len(shape) == 2 else block
        offset += size
    mask = ca.DM(np.reshape(np.asarray(pattern, dtype=float), (N_INPUTS, N_STATES), order="F"))
    gain = parts["K"] * mask
    no_disturbance = ca.DM.zeros(N_DISTURBANCES)
    x = ca.SX.sym("x", N_STATES)
    t = ca.SX.sym("t")
    dt = ca.SX.sym("dt")

    def control(xs, ts):
        return parts["u_trim"] - gain @ (xs - (parts["x_ref"] + parts["x_rate"] * ts))

    def rhs(xs, ts):
        return f(xs, control(xs, ts), parts["params"], no_disturbance)

    k1 = rhs(x, t)
    k2 = rhs(x + dt / 2 * k1, t + dt / 2)
    k3 = rhs(x + dt / 2 * k2, t + dt / 2)
    k4 = rhs(x + dt * k3, t + dt)
    x_next = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    # common subexpressions merged (the RK4 stages repeat the same products and trig): the same
    # values, about 11 % fewer operations
    step_out = ca.cse([x_next, control(x, t)])
    return LaneFunctions(step=ca.Function("qb_step", [x, t, dt, c], step_out),
                         ctrl=ca.Function("qb_ctrl", [x, t, c], [ca.cse(control(x, t))]))


# ---------------------------------------------------------------------------------------
# C emission from CasADi's instruction list

@lru_cache(maxsize=1)
def _c_operators() -> tuple[dict[int, str], dict[int, str]]:
    """CasADi operation codes -> C: (binary infix operators, unary functions)."""
    binary = {ca.OP_ADD: "+", ca.OP_SUB: "-", ca.OP_MUL: "*", ca.OP_DIV: "/"}
    unary = {ca.OP_SIN: "sin", ca.OP_COS: "cos", ca.OP_TAN: "tan", ca.OP_SQRT: "sqrt",
             ca.OP_FABS: "fabs", ca.OP_EXP: "exp", ca.OP_LOG: "log"}
    return binary, unary


def emit_lanes(fn: ca.Function, name: str, lanes: int = LANES) -> str:
    """C source of ``fn`` (an SX function) evaluated on ``lanes`` cases at once.

    Every input and output is lane-major within each element: element ``j`` of input ``i``
    for lane ``l`` is ``in_i[j * lanes + l]``. Raises ValueError on an operation it does not
    know (the caller then falls back to CasADi's interpreter).
    """
    binary, unary = _c_operators()
    n_in, n_out = fn.n_in(), fn.n_out()
    args = [f"const double* restrict i{k}" for k in range(n_in)] + \
           [f"double* restrict o{k}" for k in range(n_out)]
    body = []
    for k in range(fn.n_instructions()):
        op = fn.instruction_id(k)
        ins = fn.instruction_input(k)
        out = fn.instruction_output(k)
        if op == ca.OP_INPUT:
            line = f"w{out[0]} = i{ins[0]}[{ins[1]} * {lanes} + l];"
        elif op == ca.OP_OUTPUT:
            line = f"o{out[0]}[{out[1]} * {lanes} + l] = w{ins[0]};"
        elif op == ca.OP_CONST:
            line = f"w{out[0]} = {float(fn.instruction_constant(k))!r};"
        elif op in binary:
            line = f"w{out[0]} = w{ins[0]} {binary[op]} w{ins[1]};"
        elif op in unary:
            line = f"w{out[0]} = {unary[op]}(w{ins[0]});"
        elif op == ca.OP_NEG:
            line = f"w{out[0]} = -w{ins[0]};"
        elif op == ca.OP_TWICE:
            line = f"w{out[0]} = 2.0 * w{ins[0]};"
        elif op == ca.OP_SQ:
            line = f"w{out[0]} = w{ins[0]} * w{ins[0]};"
        elif op == ca.OP_INV:
            line = f"w{out[0]} = 1.0 / w{ins[0]};"
        else:
            raise ValueError(f"{name}: CasADi operation {op} has no lane form")
        body.append("    " + line)
    work = ", ".join(f"w{i}" for i in range(max(fn.sz_w(), 1)))
    return (f"static void {name}({', '.join(args)}) {{\n"
            "#pragma omp simd\n"
            f"  for (int l = 0; l < {lanes}; ++l) {{\n"
            f"    double {work};\n" + "\n".join(body) + "\n  }\n}\n")


def lane_source(funcs: LaneFunctions, simd: bool) -> str:
    """The whole C file: declarations, the two lane functions, the driver."""
    head = ("/* generated by quadctl.batch_codegen from quadctl.model: do not edit */\n"
            "#include <math.h>\n#include <string.h>\n"
            f"#define QB_L {LANES}\n#define QB_NC {lane_const_size()}\n")
    if simd:
        head += _SIMD_DECLARATIONS
    return (head + emit_lanes(funcs.step, "qb_step") + emit_lanes(funcs.ctrl, "qb_ctrl") + _DRIVER)


def _cpu_tag() -> str:
    """What ``-march=native`` depends on: the machine and its CPU feature flags."""
    flags = ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("flags"):
                    flags = line
                    break
    except OSError:
        pass
    return platform.machine() + hashlib.sha256(flags.encode()).hexdigest()[:12]


class CompiledLanes:
    """A compiled lane library: :meth:`run` integrates up to :data:`LANES` cases per C call."""

    def __init__(self, library: Path, backend: str):
        self.backend = backend
        self._lib = ctypes.CDLL(str(library))
        dp = ctypes.POINTER(ctypes.c_double)
        lp = ctypes.POINTER(ctypes.c_long)
        self._run = self._lib.qb_run
        self._run.restype = None
        self._run.argtypes = [dp, dp, lp, lp, dp, dp, dp, ctypes.c_long, dp, dp, lp, lp, lp]

    def run(self, x0, dt, n, c, stride, lo, hi) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
        """Simulate ``N`` cases.

        Parameters
        ----------
        x0, lo, hi : (N, 12) ndarray
            Initial states, and the bounds that stop a case (NaN always stops it).
        dt : (N,) ndarray
            Step of each case (s).
        n : (N,) int ndarray
            Steps of each case.
        c : (N, nc) ndarray
            Constants of each case (:func:`pack_lane_constants`).
        stride : (N,) int ndarray
            Record every ``stride``-th step.

        Returns
        -------
        list of (done, ks, xs, us)
            Per case, as :meth:`quadctl.codegen.CompiledLoop.run` returns them.
        """
        return [(done, ks.copy(), xs.copy(), us.copy())
                for _, done, ks, xs, us in self.iter_run(x0, dt, n, c, stride, lo, hi)]

    def iter_run(self, x0, dt, n, c, stride, lo, hi):
        """Like :meth:`run`, lazily: yields ``(index, done, ks, xs, us)`` per case.

        The arrays are views into one buffer that the next group of :data:`LANES` cases
        overwrites: use them (or copy them) before asking for the next group. Reusing the
        buffer saves the page faults of fresh memory, which cost as much as the integration.
        ``xs`` (r, 12) and ``us`` (r, 4) are transposes of state-major buffers: ``xs.T`` is
        contiguous, which is the layout per-state reductions want.
        """
        x0, dt, c, lo, hi = (np.asarray(a, dtype=float) for a in (x0, dt, c, lo, hi))
        n = np.asarray(n, dtype=C_LONG)
        stride = np.asarray(stride, dtype=C_LONG)
        total = len(dt)
        if total == 0:
            return
        rows_max = max(record_rows(int(k), int(s)) for k, s in zip(n, stride))
        xs = np.empty((LANES, N_STATES, rows_max))
        us = np.empty((LANES, N_INPUTS, rows_max))
        ks = np.empty((LANES, rows_max), dtype=C_LONG)
        n_rec = np.empty(LANES, dtype=C_LONG)
        done = np.empty(LANES, dtype=C_LONG)
        for start in range(0, total, LANES):
            sl = slice(start, min(start + LANES, total))
            used = sl.stop - sl.start
            self._call(x0[sl], dt[sl], n[sl], c[sl], stride[sl], lo[sl], hi[sl], rows_max,
                       xs, us, ks, n_rec, done)
            for l in range(used):
                r = int(n_rec[l])
                yield start + l, int(done[l]), ks[l, :r], xs[l, :, :r].T, us[l, :, :r].T

    def _call(self, x0, dt, n, c, stride, lo, hi, rows_max, xs, us, ks, n_rec, done):
        pad = LANES - len(dt)

        def lanes(arr, fill=None):
            if pad:
                arr = np.concatenate([arr, np.repeat(arr[:1] if fill is None else fill, pad, axis=0)])
            return np.ascontiguousarray(arr.T) if arr.ndim == 2 else np.ascontiguousarray(arr)

        dp = ctypes.POINTER(ctypes.c_double)
        lp = ctypes.POINTER(ctypes.c_long)

        def p(a, kind=dp):
            return a.ctypes.data_as(kind)

        args = [lanes(x0), lanes(dt), lanes(n, np.zeros(1, dtype=C_LONG)), lanes(stride), lanes(c),
                lanes(lo), lanes(hi)]
        self._run(p(args[0]), p(args[1]), p(args[2], lp), p(args[3], lp), p(args[4]), p(args[5]),
                  p(args[6]), rows_max, p(xs), p(us), p(ks, lp), p(n_rec, lp), p(done, lp))


class InterpretedLanes:
    """The lane loop in Python over CasADi's interpreter: one case at a time, same contract."""

    backend = "casadi"

    def __init__(self, funcs: LaneFunctions):
        self._f = funcs

    def run(self, x0, dt, n, c, stride, lo, hi):
        """Same contract as :meth:`CompiledLanes.run`."""
        return [self._one(*args) for args in zip(x0, dt, n, c, stride, lo, hi)]

    def iter_run(self, x0, dt, n, c, stride, lo, hi):
        """Same contract as :meth:`CompiledLanes.iter_run`."""
        for i, args in enumerate(zip(x0, dt, n, c, stride, lo, hi)):
            yield (i, *self._one(*args))

    def _one(self, x0, dt, n, c, stride, lo, hi):
        x = np.array(x0, dtype=float)
        ks, xs, us = [], [], []
        k, in_bounds, u_now = 0, True, None
        while k < n:
            x_next, u_now = (np.asarray(v).ravel() for v in self._f.step(x, dt * k, dt, c))
            if k % stride == 0:
                ks.append(k)
                xs.append(x)
                us.append(u_now)
            x = x_next
            k += 1
            if not np.all((x >= lo) & (x <= hi)):
                in_bounds = False
                break
        ks.append(k)
        xs.append(x)
        us.append(u_now if not in_bounds else np.asarray(self._f.ctrl(x, dt * k, c)).ravel())
        return k, np.array(ks), np.array(xs), np.array(us)


@lru_cache(maxsize=8)
def get_lanes(pattern: tuple[bool, ...]):
    """The fastest lane runner that builds here, for a gain pattern (compiled once per machine).

    Returns a :class:`CompiledLanes` (``backend`` ``"compiled-simd"`` or ``"compiled"``) or,
    without a C compiler, an :class:`InterpretedLanes` (``"casadi"``).
    """
    compiler = find_compiler()
    if compiler is None:
        return InterpretedLanes(build_lane_functions(pattern))
    pattern_bits = "".join("1" if b else "0" for b in pattern)
    for simd, flags, backend in ((True, SIMD_FLAGS, "compiled-simd"), (False, PORTABLE_FLAGS, "compiled")):
        key = f"{LANE_FINGERPRINT} qb {pattern_bits} simd={simd} {_cpu_tag() if '-march=native' in flags else ''}"
        try:
            library = compile_cached(lambda s=simd: lane_source(build_lane_functions(pattern), s),
                                     flags, compiler, "qb", key)
            return CompiledLanes(library, backend)
        except (RuntimeError, OSError, ValueError):
            continue  # this compiler cannot build (or load) the variant: try the next, then CasADi
    return InterpretedLanes(build_lane_functions(pattern))
