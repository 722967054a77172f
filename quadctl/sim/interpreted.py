"""The runner without a C compiler: the same loop functions in CasADi's virtual machine.

Stepping in Python would cost ~10 µs of interpreter overhead a step. Instead :func:`block` joins
:data:`UNROLL` steps (whole controller periods for a held loop) into one CasADi function, and
``mapaccum`` chains :data:`BLOCKS` of those, so CasADi runs thousands of steps per call. Python
then does per chunk, vectorized, what ``driver.c`` does per step: the bounds check, the recorded
rows and the final row. The numbers are those of the compiled runner (same operations in the
same order; see :mod:`quadctl.sim.emit`).
"""

from __future__ import annotations

import contextlib
import math
from functools import lru_cache

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.layout import N_INPUTS
from quadctl.sim.builder import LoopFunctions, LoopSpec, build
from quadctl.sim.cases import Cases

ca = lazy_import("casadi")  # loaded on first use: see quadctl._lazy

UNROLL = 8
"""Steps per CasADi call at least: one call costs ~8 µs besides its arithmetic (~3 µs a step)."""
BLOCKS = (256, 8)
"""Blocks chained by one ``mapaccum`` call: the long chain while it fits the steps left, then the
short one (at most a short chain's worth of steps computed past the end and dropped)."""


@lru_cache(maxsize=16)
def block(spec: LoopSpec, hold: int):
    """``(X, T (1, U), dt, c, E (n_exo, U), lo, hi) -> (X_end, Xs (nx, U), Us (4, U), inside (1, U))``.

    ``U`` steps: a multiple of ``hold`` (held loops: one controller sample every ``hold`` steps,
    the block starting on one) and at least :data:`UNROLL`. ``Xs`` holds the state before each
    step, ``Us`` the input applied during it, ``inside`` 1 where the state after it is within
    ``[lo, hi]`` (the bounds check is done here: converting every state to numpy would cost a
    fifth of the run).
    """
    funcs: LoopFunctions = build(spec)
    per = hold if spec.held else 1
    U = per * max(1, math.ceil(UNROLL / per))
    X0 = ca.SX.sym("X", spec.nx)
    T = ca.SX.sym("T", 1, U)
    dt = ca.SX.sym("dt")
    c = ca.SX.sym("c", spec.n_constants)
    E = ca.SX.sym("E", spec.n_exo, U)
    lo, hi = ca.SX.sym("lo", spec.nx), ca.SX.sym("hi", spec.nx)
    X, xs, us, inside = X0, [], [], []
    u_held = None
    for j in range(U):
        xs.append(X)
        if spec.held:
            if j % per == 0:
                u_held, X = funcs.law(X, T[j], c, E[:, j])
            X = funcs.plant(X, u_held, dt, c, E[:, j])
            us.append(u_held)
        else:
            X, u = funcs.step(X, T[j], dt, c, E[:, j])
            us.append(u)
        inside.append(ca.mmin((X >= lo) * (X <= hi)))
    outputs = [X, ca.horzcat(*xs), ca.horzcat(*us), ca.horzcat(*inside)]
    return U, ca.Function("qc_block", [X0, T, dt, c, E, lo, hi], ca.cse(outputs))


@lru_cache(maxsize=32)
def chain(spec: LoopSpec, hold: int, blocks: int):
    """``(U, F)``: :func:`block` chained ``blocks`` times by ``mapaccum`` (state accumulated)."""
    U, fn = block(spec, hold)
    return U, fn.mapaccum("qc_chain", blocks, [0], [0])


@contextlib.contextmanager
def ctrl_c_after_the_call():
    """Hold SIGINT back while CasADi evaluates, and let it through after.

    A SIGINT that lands inside a CasADi call is lost (measured: a Ctrl-C of a long interpreted run
    was ignored 1 time in 8, the run going on to its end); blocked, it stays pending and Python
    raises KeyboardInterrupt as soon as the call returns (a call is a few ms). Where the platform
    has no ``pthread_sigmask`` (Windows) this does nothing.
    """
    import signal
    import threading

    if not hasattr(signal, "pthread_sigmask") or threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


class InterpretedRunner:
    """Runs :class:`~quadctl.sim.cases.Cases` one at a time in CasADi's virtual machine."""

    backend = "casadi"

    def __init__(self, spec: LoopSpec, reason: str = ""):
        self.spec = spec
        self.reason = reason
        """Why this runner and not the compiled one."""

    def iter_run(self, cases: Cases):
        """Same contract as :meth:`quadctl.sim.native.NativeRunner.iter_run`."""
        for i in range(len(cases)):
            yield (i, *self._one(cases, i))

    def run(self, cases: Cases):
        return [result for _, *result in self.iter_run(cases)]

    def _one(self, cases: Cases, i: int):
        spec = self.spec
        hold = int(cases.hold[i]) if spec.held else 1
        k0, n, stride, dt = int(cases.k0[i]), int(cases.n[i]), int(cases.stride[i]), float(cases.dt[i])
        if spec.held and k0 % hold:
            raise ValueError(f"a held loop starts on a controller sample: k0 = {k0} is not a multiple of {hold}")
        c, lo, hi = cases.c[i], cases.lo[i], cases.hi[i]
        x = np.array(cases.x0[i], dtype=float)
        ks, xs, us = [], [], []
        taken, bad = 0, False
        u_last = np.zeros(N_INPUTS)
        while taken < n and not bad:
            U, fn = chain(spec, hold, BLOCKS[0])
            if n - taken < U * BLOCKS[0]:
                U, fn = chain(spec, hold, BLOCKS[1])
            width = U * (BLOCKS[0] if n - taken >= U * BLOCKS[0] else BLOCKS[1])
            steps = k0 + taken + np.arange(width)
            E = np.zeros((spec.n_exo, width))
            if spec.n_exo:
                E = np.ascontiguousarray(cases.exo[i][cases.exo_index(i, steps)].T)
            with ctrl_c_after_the_call():
                x_end, X, Uin, inside = fn(x, dt * steps.astype(float)[None, :], dt, c, E, lo, hi)
            m = min(width, n - taken)
            outside = inside.full().ravel()[:m] == 0
            if outside.any():
                m = int(np.argmax(outside)) + 1
                bad = True
            first = (-(k0 + taken)) % stride
            if first < m:
                rows = ca.Slice(first, m, stride)
                ks.append(steps[first:m:stride])
                xs.append(X[:, rows].full().T)
                us.append(Uin[:, rows].full().T)
            u_last = Uin[:, m - 1].full().ravel()
            x = _after(X, x_end, m, width)
            taken += m
        last = k0 + taken
        if bad or (spec.held and last % hold):
            u_final = u_last
        else:
            e = np.zeros(spec.n_exo)
            if spec.n_exo:
                e = cases.exo[i][cases.exo_index(i, np.array([max(last - 1, 0)]))[0]]
            u_final = np.asarray(build(spec).law(x, dt * float(last), c, e)[0]).ravel()
        ks.append(np.array([last], dtype=np.int64))
        xs.append(x[None, :])
        us.append(u_final[None, :])
        return taken, np.concatenate(ks), np.concatenate(xs), np.concatenate(us)


def _after(X, x_end, m: int, width: int) -> np.ndarray:
    """The state after step ``m - 1`` of a chunk: the next step's start, or the chunk's end."""
    return (x_end[:, -1] if m == width else X[:, m]).full().ravel()
