"""Compiled closed-loop RK4 steps, generated from the CasADi model.

The step functions are built symbolically from :func:`quadctl.model.build_model` (never a
second copy of the equations), exported with CasADi's C code generator, compiled once with
the system C compiler together with the small loop in ``_driver.c``, and cached on disk
keyed by a hash of what the source is generated from (:data:`FINGERPRINT` and the variant), so a
cached library loads without CasADi. Without a C compiler, the same CasADi functions
run in CasADi's own virtual machine from a Python loop: same results, slower.

Constants the step reads are packed into one vector ``c`` (layout :data:`CONST_LAYOUT`, then
:func:`const_layout` for a controller with integrators). The gain's sparsity pattern, the
saturation mode and the integrated states are baked into the generated code, so a
block-diagonal gain costs only its nonzeros.

Controller states. An LQI controller (``lqr.<subsystem>.integral``) carries ``nz`` integrator
states ``z`` next to the 12 plant states; the loop then integrates ``X = [x; z]`` (``nz + 12``
numbers). With continuous feedback, ``dz/dt = -(x_i - x_ref_i)`` is integrated by the same RK4
step as the plant; with a zero-order hold, ``z`` is a forward-Euler accumulator updated once per
controller sample, ``z <- z - Ts (x_i - x_ref_i)`` (MATLAB ``lqi`` for discrete systems). Either
way the integration of ``z`` stops while saturation alters an input that ``z`` drives
(conditional-integration anti-wind-up, gated by the ``antiwindup`` constant).
"""

from __future__ import annotations

import ctypes
import hashlib
import importlib.machinery
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.layout import N_INPUTS, N_STATES
from quadctl.model import N_DISTURBANCES, N_PARAMS, build_model

ca = lazy_import("casadi")  # loaded on first use: see quadctl._lazy

CONST_LAYOUT: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("x_ref", (N_STATES,)),        # reference state at t = 0
    ("x_rate", (N_STATES,)),       # reference drift (m/s on positions): x_ref(t) = x_ref + x_rate t
    ("u_trim", (N_INPUTS,)),
    ("K", (N_INPUTS, N_STATES)),   # u = u_trim - K (x - x_ref(t)), stored column-major
    ("params", (N_PARAMS,)),
    ("mix", (N_INPUTS, N_INPUTS)),      # [T, A, E, R] -> actuator commands (motors mode)
    ("mix_inv", (N_INPUTS, N_INPUTS)),  # actuator commands -> [T, A, E, R]
    ("lo", (N_INPUTS,)),           # actuator lower limits (box: on T, A, E, R)
    ("hi", (N_INPUTS,)),
)
INTEGRAL_CONSTANTS = (
    ("Ki", lambda nz: (N_INPUTS, nz)),          # u -= Ki z, column-major
    ("antiwindup", lambda nz: (nz, N_INPUTS)),  # 1 where input j's saturation freezes integrator i
    ("Ts", lambda nz: (1,)),                    # controller sample time (s) of the held accumulator
)
"""Constants appended after :data:`CONST_LAYOUT` when the controller has ``nz > 0`` integrators."""
ANTIWINDUP_TOL = 1e-10
"""An input counts as saturated when clipping changed it by more than this (N or N m): far above
the round-off of mixing and unmixing (~1e-15), far below any clip that matters."""
SATURATION_MODES = ("none", "box", "motors")
COMPILE_FLAGS = ("-O3", "-fno-math-errno", "-fPIC", "-shared")
"""-fno-math-errno lets sin/cos inline and pair; no -ffast-math, so NaN still propagates."""


def const_layout(nz: int = 0) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """The constant layout of a controller with ``nz`` integrator states (``CONST_LAYOUT`` when 0)."""
    if nz == 0:
        return CONST_LAYOUT
    return CONST_LAYOUT + tuple((name, shape(nz)) for name, shape in INTEGRAL_CONSTANTS)


def const_size(nz: int = 0) -> int:
    return sum(int(np.prod(shape)) for _, shape in const_layout(nz))


def pack_constants(**values) -> np.ndarray:
    """Pack named constants into the ``c`` vector (missing ones: zero; ``mix``: identity).

    A controller with integrators passes ``Ki`` (4, nz); ``nz`` is read from its shape, and
    ``antiwindup`` (nz, 4) and ``Ts`` (s) then belong to the layout too.
    """
    nz = np.shape(values["Ki"])[1] if "Ki" in values else 0
    out = []
    for name, shape in const_layout(nz):
        default = np.eye(N_INPUTS) if name in ("mix", "mix_inv") else np.zeros(shape)
        arr = np.asarray(values.pop(name, default), dtype=float)
        if arr.shape != shape:
            raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
        out.append(arr.ravel(order="F"))
    if values:
        raise ValueError(f"unknown constants: {sorted(values)}")
    return np.concatenate(out)


@dataclass(frozen=True)
class StepFunctions:
    """The CasADi functions of one variant (gain pattern, saturation mode, integrated states).

    ``X = [x; z]`` is the plant state followed by the ``nz`` integrator states.
    """

    step: ca.Function      # (X, t, dt, c, d, nm) -> (X_next, u): continuous feedback in every RK4 stage
    ctrl: ca.Function      # (x_meas, z, t, c) -> (u, z_next): one controller sample (z_next = z + Ts dz)
    step_ol: ca.Function   # (x, u, dt, c, d) -> x_next: the plant under a held input
    nz: int = 0


def build_step_functions(pattern: tuple[bool, ...], saturation: str,
                         integral: tuple[int, ...] = ()) -> StepFunctions:
    """Closed-loop RK4 step functions.

    Parameters
    ----------
    pattern : tuple of 48 bool
        Sparsity of the (4, 12) state gain, column-major.
    saturation : {"none", "box", "motors"}
    integral : tuple of int
        Plant-state index integrated by each controller integrator (empty: no integrators).
    """
    if saturation not in SATURATION_MODES:
        raise ValueError(f"saturation must be one of {SATURATION_MODES}")
    nz = len(integral)
    f = build_model().f_disturbed
    c = ca.SX.sym("c", const_size(nz))
    parts = {}
    offset = 0
    for name, shape in const_layout(nz):
        size = int(np.prod(shape))
        block = c[offset:offset + size]
        parts[name] = ca.reshape(block, *shape) if len(shape) == 2 else block
        offset += size
    mask = ca.DM(np.reshape(np.asarray(pattern, dtype=float), (N_INPUTS, N_STATES), order="F"))
    gain = parts["K"] * mask  # structural zeros vanish from the generated code

    def saturate(cmd):
        if saturation == "none":
            return cmd
        act = parts["mix"] @ cmd if saturation == "motors" else cmd
        act = ca.if_else(act < parts["lo"], parts["lo"], act)
        act = ca.if_else(act > parts["hi"], parts["hi"], act)
        return parts["mix_inv"] @ act if saturation == "motors" else act

    def control(x_meas, z, t):
        """(u, dz/dt): the saturated input and the integrators' rates (anti-wind-up applied)."""
        err = x_meas - (parts["x_ref"] + parts["x_rate"] * t)
        cmd = parts["u_trim"] - gain @ err
        if nz == 0:
            return saturate(cmd), ca.SX(0, 1)
        cmd = cmd - parts["Ki"] @ z
        u_sat = saturate(cmd)
        rate = -ca.vertcat(*[err[i] for i in integral])  # MATLAB lqi: dz/dt = r - y
        if saturation != "none":
            clipped = ca.if_else(ca.fabs(u_sat - cmd) > ANTIWINDUP_TOL, 1, 0)
            frozen = parts["antiwindup"] @ clipped
            rate = ca.if_else(frozen > 0.5, 0, rate)
        return u_sat, rate

    X = ca.SX.sym("x", N_STATES + nz)
    x, z = X[:N_STATES], X[N_STATES:]
    xo = ca.SX.sym("xo", N_STATES)
    xm = ca.SX.sym("xm", N_STATES)
    zs = ca.SX.sym("z", nz)
    u = ca.SX.sym("u", N_INPUTS)
    t = ca.SX.sym("t")
    dt = ca.SX.sym("dt")
    d = ca.SX.sym("d", N_DISTURBANCES)
    nm = ca.SX.sym("nm", N_STATES)
    p = parts["params"]

    def rk4(rhs, y):
        k1 = rhs(y, t)
        k2 = rhs(y + dt / 2 * k1, t + dt / 2)
        k3 = rhs(y + dt / 2 * k2, t + dt / 2)
        k4 = rhs(y + dt * k3, t + dt)
        return y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def closed_rhs(ys, ts):
        xs, zz = ys[:N_STATES], ys[N_STATES:]
        u_now, z_rate = control(xs + nm, zz, ts)
        xdot = f(xs, u_now, p, d)
        return ca.vertcat(xdot, z_rate) if nz else xdot

    x_cl = rk4(closed_rhs, X)
    x_ol = rk4(lambda xs, ts: f(xs, u, p, d), xo)
    u_ctrl, z_rate = control(xm, zs, t)
    z_next = zs + parts["Ts"] * z_rate if nz else zs
    return StepFunctions(
        step=ca.Function("qc_step", [X, t, dt, c, d, nm], [x_cl, control(x + nm, z, t)[0]]),
        ctrl=ca.Function("qc_ctrl", [xm, zs, t, c], [u_ctrl, z_next]),
        step_ol=ca.Function("qc_step_ol", [xo, u, dt, c, d], [x_ol]),
        nz=nz,
    )


def cache_dir() -> Path:
    """Where compiled steps are kept: ``$QUADCTL_CACHE``, else ``~/.cache/quadctl``."""
    env = os.environ.get("QUADCTL_CACHE")
    base = Path(env) if env else Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "quadctl"
    return base


def find_compiler() -> str | None:
    """The C compiler to use (``$CC``, ``cc``, ``gcc``, ``clang``), or None.

    ``QUADCTL_NO_COMPILE=1`` forces the CasADi fallback (tests use it to compare both paths).
    """
    if os.environ.get("QUADCTL_NO_COMPILE") == "1":
        return None
    for cand in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if cand and shutil.which(cand):
            return shutil.which(cand)
    return None


def record_rows(n: int, stride: int) -> int:
    """Rows the loop records for ``n`` steps at ``stride``: steps 0, stride, ... and the last."""
    return (n - 1) // stride + 2 if n > 0 else 1


class CompiledLoop:
    """A compiled variant: :meth:`run` integrates ``n`` steps in C."""

    backend = "compiled"

    def __init__(self, library: Path, nz: int = 0):
        self.nz = nz
        self._lib = ctypes.CDLL(str(library))
        dp = ctypes.POINTER(ctypes.c_double)
        lp = ctypes.POINTER(ctypes.c_long)
        self._run = self._lib.qc_run
        self._run.restype = ctypes.c_long
        self._run.argtypes = [dp, ctypes.c_double, ctypes.c_double, ctypes.c_long, dp, dp, dp,
                              ctypes.c_long, ctypes.c_long, dp, dp, dp, dp, lp, lp]

    def run(self, x0, t0, dt, n, c, dist, meas, hold, stride, lo, hi):
        """Integrate ``n`` steps of ``dt`` from ``x0``.

        Parameters
        ----------
        x0, lo, hi : (12 + nz,) ndarray
            Initial state ``[x; z]`` and the bounds that stop the run (NaN always stops it).
        dist : (n, 6) ndarray or None
            Body force and torque disturbance of each step (N, N m).
        meas : (n, 12) ndarray or None
            Measurement noise added to the state the controller sees at each step.
        hold : int
            0: feedback inside every RK4 stage; k > 0: a controller sample every k steps, held.

        Returns
        -------
        (done, ks, xs, us) : steps completed, recorded step indices (r,), states (r, 12 + nz),
        inputs (r, 4).
        """
        rows = record_rows(n, stride)
        xs = np.empty((rows, N_STATES + self.nz))
        us = np.empty((rows, N_INPUTS))
        ks = np.empty(rows, dtype=np.int_)
        n_rec = ctypes.c_long(0)
        ptr = _pointer
        done = int(self._run(ptr(np.ascontiguousarray(x0, dtype=float)), float(t0), float(dt),
                             int(n), ptr(c), ptr(dist), ptr(meas), int(hold), int(stride),
                             ptr(lo), ptr(hi), ptr(xs), ptr(us),
                             ks.ctypes.data_as(ctypes.POINTER(ctypes.c_long)), ctypes.byref(n_rec)))
        r = n_rec.value
        return done, ks[:r], xs[:r], us[:r]


class InterpretedLoop:
    """The loop of ``_driver.c`` in Python, evaluating the CasADi functions (no C compiler)."""

    backend = "casadi"

    def __init__(self, funcs: StepFunctions):
        self._f = funcs
        self.nz = funcs.nz

    def run(self, x0, t0, dt, n, c, dist, meas, hold, stride, lo, hi):
        """Same contract as :meth:`CompiledLoop.run`."""
        zero6, zero12 = np.zeros(N_DISTURBANCES), np.zeros(N_STATES)
        ns = N_STATES

        def ctrl(xx, mk, t):
            u, z_new = self._f.ctrl(xx[:ns] + mk, xx[ns:], t, c)
            return np.asarray(u).ravel(), np.asarray(z_new).ravel()

        x = np.array(x0, dtype=float)
        u_hold = np.zeros(N_INPUTS)
        u_now = u_hold
        ks, xs, us = [], [], []
        in_bounds = True
        k = 0
        while k < n:
            t = t0 + dt * k
            dk = dist[k] if dist is not None else zero6
            mk = meas[k] if meas is not None else zero12
            if hold > 0:
                z_new = x[ns:]
                if k % hold == 0:
                    u_hold, z_new = ctrl(x, mk, t)
                u_now = u_hold
                x_plant = np.asarray(self._f.step_ol(x[:ns], u_hold, dt, c, dk)).ravel()
                x_next = np.concatenate([x_plant, z_new])
            else:
                x_next, u_now = (np.asarray(v).ravel() for v in self._f.step(x, t, dt, c, dk, mk))
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
        if not in_bounds or (hold > 0 and k % hold != 0):
            us.append(u_hold if hold > 0 else u_now)
        else:
            mk = meas[k - 1] if (meas is not None and k > 0) else zero12
            us.append(ctrl(x, mk, t0 + dt * k)[0])
        return k, np.array(ks), np.array(xs).reshape(len(xs), ns + self.nz), np.array(us)


def _pointer(arr):
    if arr is None:
        return None
    if not (isinstance(arr, np.ndarray) and arr.dtype == np.float64 and arr.flags.c_contiguous):
        raise TypeError("expected a C-contiguous float64 array")
    return arr.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


@lru_cache(maxsize=32)
def get_loop(pattern: tuple[bool, ...], saturation: str = "none", integral: tuple[int, ...] = ()):
    """The loop for a gain pattern, saturation mode and integrated states: compiled if a C
    compiler exists.

    Compiles at most once per variant per machine (cached in :func:`cache_dir`); a cached
    library loads without building the CasADi functions at all.
    """
    compiler = find_compiler()
    if compiler is None:
        return InterpretedLoop(build_step_functions(pattern, saturation, integral))
    key = f"{FINGERPRINT} qc {saturation} {''.join('1' if b else '0' for b in pattern)} {integral}"
    library = compile_cached(lambda: loop_source(build_step_functions(pattern, saturation, integral)),
                             COMPILE_FLAGS, compiler, "qc", key)
    return CompiledLoop(library, len(integral))


def loop_source(funcs: StepFunctions) -> str:
    """C source of one variant: CasADi's generated step functions, their work sizes, ``_driver.c``."""
    with tempfile.TemporaryDirectory(prefix="quadctl-gen-") as tmp:
        gen = ca.CodeGenerator("qc_gen.c", {"with_header": False, "main": False})
        for fn in (funcs.step, funcs.ctrl, funcs.step_ol):
            gen.add(fn)
        cwd = os.getcwd()
        try:
            os.chdir(tmp)
            gen.generate()
        finally:
            os.chdir(cwd)
        generated = (Path(tmp) / "qc_gen.c").read_text()
    fns = (funcs.step, funcs.ctrl, funcs.step_ol)
    sizes = (f"#define QC_NZ {funcs.nz}\n"
             f"#define QC_SZ_ARG {max(f.sz_arg() for f in fns)}\n"
             f"#define QC_SZ_RES {max(f.sz_res() for f in fns)}\n"
             f"#define QC_SZ_IW {max(f.sz_iw() for f in fns)}\n"
             f"#define QC_SZ_W {max(f.sz_w() for f in fns)}\n")
    return generated + "\n" + sizes + _SOURCES["_driver.c"].decode()


def read_sources(package, names) -> dict[str, bytes]:
    """File name -> contents, for ``names`` in ``package`` (a folder or importlib Traversable)."""
    return {name: package.joinpath(name).read_bytes() for name in names}


def fingerprint(sources: dict[str, bytes], casadi: str) -> str:
    """sha256 of source files (name -> contents) and a CasADi stamp: a compile cache key part."""
    digest = hashlib.sha256(casadi.encode())
    for name in sorted(sources):
        digest.update(name.encode() + b"\0" + sources[name] + b"\0")
    return digest.hexdigest()


def casadi_stamp() -> str:
    """Identifies the installed CasADi without importing it (~0.1 s): where its module file is, its
    size and modification time (a reinstall changes it: one recompilation), else its version from
    the package metadata (~10 ms), for installs the path finder cannot see."""
    spec = importlib.machinery.PathFinder.find_spec("casadi")  # the path, not the (lazy) module
    try:
        if spec is not None and spec.origin:
            info = os.stat(spec.origin)
            return f"{spec.origin} {info.st_size} {info.st_mtime_ns}"
    except OSError:
        pass
    from importlib import metadata  # ~10 ms: only for installs the path finder cannot see

    try:
        return f"casadi {metadata.version('casadi')}"
    except metadata.PackageNotFoundError:
        return "casadi unknown"


SCALAR_SOURCES = ("_lazy.py", "layout.py", "model.py", "codegen.py", "_driver.c")
"""The files the scalar loop's C is generated from (``tests/test_structure.py`` checks this covers
everything this module imports). They are read once, when this module is imported: the cache key
:data:`FINGERPRINT` hashes the code this process runs, and ``_driver.c`` is compiled from the same
bytes, so a file edited while a process runs never puts old code under the new key (or new under
the old)."""
_SOURCES = read_sources(resources.files("quadctl"), SCALAR_SOURCES)
FINGERPRINT = fingerprint(_SOURCES, casadi_stamp())
"""Part of every compiled library's cache key (:mod:`quadctl.batch_codegen` adds its own source)."""
_COMPILE_LOCK = threading.Lock()


def compile_cached(make_source: Callable[[], str], flags: tuple[str, ...], compiler: str, prefix: str,
                   key: str) -> Path:
    """Compile the C source ``make_source()`` into a shared library once per machine; its path.

    The cache key is what the source is made from, not the source itself, so a cached library is
    found without generating any code: ``key`` (the generator's :data:`FINGERPRINT` and everything
    it is called with, plus e.g. the CPU for ``-march=native``), flags, compiler, platform and
    machine. The library is compiled under a unique temporary name and renamed, so concurrent
    workers (processes or threads) never load a half-written file; threads of one process compile
    one at a time, and a library another compiled meanwhile is used, not rebuilt.
    """
    digest = hashlib.sha256("\0".join((key, " ".join(flags), compiler, sys.platform,
                                       platform.machine())).encode())
    folder = cache_dir()
    library = folder / f"{prefix}_{digest.hexdigest()[:20]}.so"
    if library.exists():
        return library
    with _COMPILE_LOCK:
        if library.exists():
            return library
        folder.mkdir(parents=True, exist_ok=True)
        fd, src_name = tempfile.mkstemp(prefix=f"{library.stem}.", suffix=".c", dir=folder)
        src, tmp_lib = Path(src_name), Path(src_name).with_suffix(".so.tmp")
        try:
            with os.fdopen(fd, "w") as fh:
                fh.write(make_source())
            proc = subprocess.run([compiler, *flags, str(src), "-o", str(tmp_lib), "-lm"],
                                  capture_output=True, text=True)
            if proc.returncode != 0:
                raise RuntimeError(f"C compiler failed: {proc.stderr.strip()[:500]}")
            os.replace(tmp_lib, library)
        finally:
            src.unlink(missing_ok=True)
            tmp_lib.unlink(missing_ok=True)
    return library
