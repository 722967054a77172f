"""The runner for a loop spec: compiled where a C compiler works, else CasADi's VM (one notice).

:func:`runner` gives the fastest runner that builds here for a :class:`LoopSpec` and a lane
count: ``lanes = 1`` is the one-case loop (``quadctl simulate``), ``lanes = LANES`` the SIMD
lanes a sweep runs. Both are generated from :func:`quadctl.sim.builder.build`; the interpreted
fallback runs the same functions.
"""

from __future__ import annotations

import warnings
from functools import cache, lru_cache

from quadctl.errors import QuadctlNotice
from quadctl.native.compile import (
    MARCH,
    MARCH_ENV,
    MARCH_REFUSED,
    NATIVE_FLAGS,
    PORTABLE_FLAGS,
    SIMD_FLAGS,
    CompileError,
    compile_cached,
    cpu_tag,
    find_compiler,
)
from quadctl.sim.builder import build
from quadctl.sim.interpreted import InterpretedRunner
from quadctl.sim.loop_spec import LoopSpec
from quadctl.sim.native import NativeRunner, library_source

LANES = 8
"""Cases per vectorized call: one AVX-512 register of doubles, or two AVX2 ones."""


class CompilerNotice(QuadctlNotice):
    """No working C compiler: the loop runs in CasADi's virtual machine (the same results to round-off, slower)."""


VM_COST = "the same results to round-off, 6x slower or more"
"""What running in CasADi's virtual machine costs, as the notices say it (docs/performance.md, one
simulation of the forward config: 0.95 M against 5.7 M steps/s compiled; a sweep's SIMD lanes lose more)."""


class MarchNotice(CompilerNotice):
    """:data:`~quadctl.native.compile.MARCH_ENV` not used as given: not a target's name, or a target
    the compiler refuses."""


_NOT_A_NAME = (f"{MARCH_ENV}={MARCH_REFUSED!r} is not a target's name (x86-64-v3, znver4, ...): built for this "
              "CPU (native)")
"""The :class:`MarchNotice` of a :data:`~quadctl.native.compile.MARCH_ENV` that is not a plain name."""


def _refused(reason: str) -> str:
    """The :class:`MarchNotice` of a named target the compiler refused, saying ``reason``."""
    return (f"{MARCH_ENV}: the compiler refused {MARCH} ({reason.splitlines()[0][:160]}); the loop is built "
            "for any CPU instead (slower)")


@cache
def _march_notice(text: str) -> None:
    """Say once per process that :data:`~quadctl.native.compile.MARCH_ENV` was not used as given."""
    warnings.warn(MarchNotice(text), stacklevel=4)


def say_march() -> None:
    """Say now what building the SIMD lanes would say of :data:`~quadctl.native.compile.MARCH_ENV`
    (a :class:`MarchNotice`, once per process; nothing when it is unset or a target the compiler
    takes). A sweep says it before its worker processes start, and they ignore their own.

    A named target is tried by compiling one line with the lanes' flags (cached like any library, and
    a refusal remembered by the process and the workers it forks, which then build for any CPU
    without trying it again).
    """
    if MARCH_REFUSED is not None:
        _march_notice(_NOT_A_NAME)
    elif MARCH != "-march=native" and find_compiler() is not None:
        try:
            compile_cached(lambda: "int quadctl_march_probe;\n", SIMD_FLAGS, "march probe")
        except CompileError as exc:
            _march_notice(_refused(str(exc)))


@lru_cache(maxsize=64)
def runner(spec: LoopSpec, lanes: int = 1):
    """A :class:`NativeRunner` (``backend`` ``"compiled"`` or ``"compiled-simd"``) or, when no C
    compiler works, an :class:`InterpretedRunner` (``"casadi"``), after a :class:`CompilerNotice`.

    Compiles at most once per spec and lane count per machine (see :mod:`quadctl.native.compile`).
    """
    variants = [(False, PORTABLE_FLAGS, "compiled")]
    if lanes > 1:
        variants.insert(0, (True, SIMD_FLAGS, "compiled-simd"))
    elif spec.method == "etdrk4":  # one case for this CPU (NATIVE_FLAGS), else the portable build
        variants.insert(0, (False, NATIVE_FLAGS, "compiled"))
    reason = ""
    for simd, flags, backend in variants:
        native = flags is not PORTABLE_FLAGS
        key = f"{spec.key()} lanes={lanes} simd={int(simd)} {cpu_tag() if native else ''}"
        if native and MARCH_REFUSED is not None:
            _march_notice(_NOT_A_NAME)
        try:
            library = compile_cached(lambda s=simd: library_source(build(spec), lanes, s), flags, key)
            return NativeRunner(library, spec, lanes, backend)
        except CompileError as exc:
            reason = str(exc)
            if native and MARCH != "-march=native" and find_compiler() is not None:  # else no compiler to refuse it
                _march_notice(_refused(reason))
            if not native:
                break
        except OSError as exc:  # built but does not load (a foreign or broken library)
            reason = f"the compiled loop does not load ({exc})"
    warnings.warn(CompilerNotice(f"{reason}: running the loop in CasADi's virtual machine ({VM_COST})"),
                  stacklevel=2)
    return InterpretedRunner(spec, reason)
