"""Compile the generated loop C once per machine and keep it in the platform's cache folder.

A library's cache key is what its source is made from, not the source: :data:`FINGERPRINT`
(the files the C is generated from, as this process imported them, and the installed CasADi),
the loop's :class:`~quadctl.sim.loop_spec.LoopSpec`, the lane count, the flags, the compiler, the
platform and, for ``-march=native`` (:data:`MARCH`), the CPU. So a cached library loads without building any
CasADi function. Libraries are compiled under a unique temporary name and renamed into place,
so concurrent processes and threads never load a half-written file; no working directory is
ever changed. Libraries of other fingerprints (an older quadctl or CasADi) that were not used
for :data:`EVICT_AFTER_DAYS` days are deleted when a new one is compiled.

A compiler that is missing, or present but failing (a macOS ``cc`` stub without the command
line tools, a broken ``$CC``), raises :class:`CompileError`; the engine then runs the same loop
in CasADi's virtual machine and says so once.
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
import time
from collections.abc import Callable
from contextlib import contextmanager
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

C_LONG = np.dtype(f"i{ctypes.sizeof(ctypes.c_long)}")
"""numpy's twin of C ``long`` (the integer type of the generated code's drivers)."""

MARCH_ENV = "QUADCTL_MARCH"
"""The environment variable that names the CPU the vectorized and one-case native builds target (GCC's
``-march``: ``x86-64-v3``, ``znver3``, ...) in place of this one (``native``, its default): a compile cache
shared by machines of several CPUs, or a tool that does not run every instruction of this CPU
(Valgrind 3.19 has no AVX-512: ``benchmarks/instructions.py`` counts under ``x86-64-v3`` there). Read
once, on import."""


def _march() -> tuple[str, str | None]:
    """``-march=`` of :data:`MARCH_ENV` (``-march=native`` when unset or not a plain name), and the
    value refused (None: none)."""
    value = os.environ.get(MARCH_ENV, "").strip()
    ok = all(ch.isalnum() or ch in "-_.+" for ch in value) and not value.startswith("-")
    return f"-march={value if value and ok else 'native'}", (None if ok else value)


MARCH, MARCH_REFUSED = _march()
"""The ``-march`` flag of :data:`SIMD_FLAGS` and :data:`NATIVE_FLAGS` (:data:`MARCH_ENV`), and a value of
:data:`MARCH_ENV` that is not a plain name (not given to the compiler: the engine says so once)."""
PORTABLE_FLAGS = ("-O2", "-ffp-contract=off", "-fno-math-errno", "-fPIC", "-shared")
"""``-ffp-contract=off`` keeps a*b+c rounded as written (no FMA), so compiled and interpreted runs
round alike; no ``-ffast-math``: NaN still propagates and stops a diverging run. ``-O2``: the one-case
RK4 loop (straight-line scalar code) steps as fast as at ``-O3`` and compiles in about half the
time."""
SIMD_FLAGS = PORTABLE_FLAGS[:1] + (MARCH, "-fno-builtin-sin", "-fno-builtin-cos",
                                   "-fno-builtin-tan", "-fopenmp-simd", "-fno-trapping-math") + PORTABLE_FLAGS[1:]
"""The vectorized lanes: ``-fno-builtin-sin/cos`` keep GCC from fusing sin and cos into one scalar
``sincos`` call (it has no vector form). ``-fno-trapping-math`` lets GCC evaluate both sides of a
select (the saturation's and the law's comparisons, :mod:`quadctl.native.emit`), which is what
vectorizing a loop with selects takes; no value changes (quadctl reads no floating-point exception
flag). Their ``#pragma omp simd`` loops are vectorized at ``-O2`` as at ``-O3``, in three quarters
of the compile time."""
NATIVE_FLAGS = ("-O3", MARCH) + PORTABLE_FLAGS[1:]
"""One case of ETDRK4 for this CPU (its stages' dense matrix-vector products in ``driver.c``,
GCC's fused ``sincos``): faster a step than :data:`PORTABLE_FLAGS`, with the same roundings
(``-ffp-contract=off``, no vector sines in one lane); ``-O3`` vectorizes those products, which
``-O2`` leaves scalar."""
EVICT_AFTER_DAYS = 30
"""Cached libraries of another fingerprint unused for this long are deleted."""
GENERATOR_SOURCES = ("_lazy.py", "layout.py", "physics/model.py", "sim/builder.py", "sim/loop_spec.py",
                     "sim/loop_layout.py", "native/emit.py", "sim/cases.py", "native/compile.py", "sim/native.py",
                     "sim/lane_metrics.py",
                     "sim/driver.c", "design/gain_table.py", "metrics.py", "native/mapped.py",
                     "native/pointwise.py", "physics/motors.py", "errors.py", "sim/pid.py", "sim/pid_mixing.py",
                     "config/pid.py", "physics/flatness.py", "physics/reference_rows.py", "physics/trajectory.py")
"""The files a library's C is generated from (``tests/house/test_structure.py`` checks that this lists
everything those modules import from quadctl). Read once, when this module is imported: the cache
key hashes the code this process runs, and ``driver.c`` is compiled from the same bytes."""


class CompileError(RuntimeError):
    """No working C compiler: the message says which and why (one line)."""


def cache_dir() -> Path:
    """``$QUADCTL_CACHE``, else the platform's per-user cache folder, then ``quadctl``.

    Linux and BSD: ``$XDG_CACHE_HOME`` or ``~/.cache``; macOS: ``~/Library/Caches``; Windows:
    ``%LOCALAPPDATA%``.
    """
    env = os.environ.get("QUADCTL_CACHE")
    if env:
        return Path(env)
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "quadctl"


def find_compiler() -> str | None:
    """Path of the C compiler to try (``$CC``, ``cc``, ``gcc``, ``clang``), or None.

    ``QUADCTL_NO_COMPILE=1`` says there is none (tests use it to compare both paths).
    """
    if os.environ.get("QUADCTL_NO_COMPILE") == "1":
        return None
    for cand in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if cand and shutil.which(cand):
            return shutil.which(cand)
    return None


def casadi_stamp() -> str:
    """Identifies the installed CasADi without importing it (~0.1 s): its module file's path, size
    and modification time (a reinstall changes them), else its version from the package metadata."""
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


def _read_sources() -> dict[str, bytes]:
    package = resources.files("quadctl")
    return {name: package.joinpath(name).read_bytes() for name in GENERATOR_SOURCES}


def fingerprint(sources: dict[str, bytes], casadi: str) -> str:
    """sha256 of source files (name -> contents) and a CasADi stamp."""
    digest = hashlib.sha256(casadi.encode())
    for name in sorted(sources):
        digest.update(name.encode() + b"\0" + sources[name] + b"\0")
    return digest.hexdigest()


_SOURCES = _read_sources()
DRIVER_SOURCE = _SOURCES["sim/driver.c"].decode()
FINGERPRINT = fingerprint(_SOURCES, casadi_stamp())
_LOCK = threading.Lock()
_FAILED: dict[tuple, str] = {}
"""(compiler, flags) -> why that failed in this process (not tried again)."""


@lru_cache(maxsize=1)
def cpu_tag() -> str:
    """What ``-march=native`` depends on: the machine and its CPU feature flags (a named :data:`MARCH`:
    the machine alone, the same library on every CPU that runs it)."""
    if MARCH != "-march=native":
        return platform.machine()
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


def compile_cached(make_source: Callable[[], str], flags: tuple[str, ...], key: str) -> Path:
    """Compile ``make_source()`` into a shared library once per machine; its path.

    Parameters
    ----------
    make_source : callable
        Returns the C source; called only when the library is not cached.
    flags : tuple of str
    key : str
        Everything the source is generated from beyond :data:`FINGERPRINT`.

    Raises
    ------
    CompileError
        No compiler, or it failed (now or earlier in this process).
    """
    compiler = find_compiler()
    if compiler is None:
        raise CompileError("no C compiler found (looked for $CC, cc, gcc, clang)")
    tried = (compiler, flags)
    if tried in _FAILED:
        raise CompileError(_FAILED[tried])
    digest = hashlib.sha256("\0".join((FINGERPRINT, key, " ".join(flags), compiler, sys.platform,
                                       platform.machine())).encode()).hexdigest()
    folder = cache_dir()
    suffix = ".dll" if sys.platform == "win32" else ".so"
    library = folder / f"qc_{FINGERPRINT[:12]}_{digest[:16]}{suffix}"
    if library.exists():
        _touch(library)
        return library
    with _LOCK:
        if library.exists():
            return library
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CompileError(f"cannot create the compile cache {folder}: {exc.strerror}") from None
        with _machine_lock(library):
            if library.exists():  # another process compiled it while this one waited
                _touch(library)
                return library
            _compile(make_source, flags, compiler, library)
        evict_stale(folder)
    return library


def _compile(make_source: Callable[[], str], flags: tuple[str, ...], compiler: str, library: Path) -> None:
    """Compile ``make_source()`` to ``library`` under a temporary name, renamed into place."""
    folder, suffix, tried = library.parent, library.suffix, (compiler, flags)
    fd, src_name = tempfile.mkstemp(prefix=f"{library.stem}.", suffix=".c", dir=folder)
    src, tmp_lib = Path(src_name), Path(src_name).with_suffix(suffix + ".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(make_source())
        try:
            proc = subprocess.run([compiler, *flags, str(src), "-o", str(tmp_lib), "-lm"],
                                  capture_output=True, text=True, timeout=600)
        except (OSError, subprocess.SubprocessError) as exc:
            _FAILED[tried] = f"the C compiler {compiler} could not run ({exc})"
            raise CompileError(_FAILED[tried]) from None
        if proc.returncode != 0:
            said = " ".join((proc.stderr or proc.stdout or "").split())[:300] or "no message"
            _FAILED[tried] = f"the C compiler {compiler} failed (exit {proc.returncode}: {said})"
            raise CompileError(_FAILED[tried])
        os.replace(tmp_lib, library)
    finally:
        src.unlink(missing_ok=True)
        tmp_lib.unlink(missing_ok=True)


@contextmanager
def _machine_lock(library: Path):
    """Held while ``library`` is compiled, by one process of the machine at a time (POSIX
    ``flock``; elsewhere no lock: two processes may then both compile it, and either's file is
    good): a sweep's worker processes wait for one to compile and then load its library."""
    try:
        import fcntl
    except ImportError:  # Windows
        yield
        return
    lock = library.with_name(library.name + ".lock")
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        lock.unlink(missing_ok=True)  # a process waiting on it re-checks for the library once it has the lock
        os.close(fd)


def evict_stale(folder: Path, now: float | None = None) -> list[Path]:
    """Delete cached libraries of other fingerprints unused for :data:`EVICT_AFTER_DAYS`; them."""
    now = time.time() if now is None else now
    gone = []
    for path in [*folder.glob("qc_*"), *folder.glob("qb_*")]:
        if path.name.startswith(f"qc_{FINGERPRINT[:12]}_"):
            continue
        try:
            if now - path.stat().st_mtime > EVICT_AFTER_DAYS * 86400:
                path.unlink()
                gone.append(path)
        except OSError:
            pass
    return gone


def _touch(path: Path) -> None:
    """Mark a library used (its age decides eviction); a read-only cache is fine."""
    try:
        os.utime(path)
    except OSError:
        pass
