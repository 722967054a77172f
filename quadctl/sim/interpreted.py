"""The runner without a C compiler: the same loop functions in CasADi's virtual machine.

:func:`block` joins :data:`UNROLL` steps (whole controller periods for a held loop) into one CasADi
function, and ``mapaccum`` chains :data:`BLOCKS` of those, so one call runs thousands of steps
straight into numpy arrays; Python then does per chunk, vectorized, what ``driver.c`` does per step
(the bounds check, the recorded rows, the final row). The numbers are the compiled runner's (the same
operations in the same order, :mod:`quadctl.native.emit`), except that a case's zero constants are
folded into its block (``x_ref + 0 t`` costs nothing; the same value up to the sign of a zero).
"""

from __future__ import annotations

import contextlib
import math
from functools import lru_cache

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.layout import N_INPUTS
from quadctl.physics.reference_rows import in_force
from quadctl.sim.builder import LoopFunctions, build
from quadctl.sim.cases import Cases
from quadctl.sim.loop_layout import N_REFERENCE
from quadctl.sim.loop_spec import LoopSpec

ca = lazy_import("casadi")  # loaded on first use: see quadctl._lazy

UNROLL = 16
"""Steps per block at least: a block call has a fixed cost besides its arithmetic, comparable to a
few steps', and constant subexpressions are shared within a block, so longer blocks run faster a
step (16 steps faster than 8)."""
BLOCKS = (128, 8)
"""Blocks chained by one ``mapaccum`` call: the long chain while it fits the steps left, then the
short one (at most a short chain's worth of steps computed past the end and dropped)."""


@lru_cache(maxsize=32)
def block(spec: LoopSpec, hold: int, zeros: tuple[int, ...] = ()):
    """``(X, T (1, U), dt, c, E (n_exo, U)) -> (X_end, Xs (nx, U), Us (4, U))``.

    ``U`` steps: a multiple of ``hold`` (held loops: one controller sample every ``hold`` steps,
    the block starting on one) and at least :data:`UNROLL`. ``Xs`` holds the state before each
    step, ``Us`` the input applied during it. The entries ``zeros`` of ``c`` are taken as 0 (the
    case's ``c`` must be zero there: see :func:`zero_constants`).
    """
    funcs: LoopFunctions = build(spec)
    per = hold if spec.held else 1
    U = per * max(1, math.ceil(UNROLL / per))
    X0 = ca.SX.sym("X", spec.nx)
    T = ca.SX.sym("T", 1, U)
    dt = ca.SX.sym("dt")
    c = ca.SX.sym("c", spec.n_constants)
    E = ca.SX.sym("E", spec.n_exo, U)
    folded = ca.SX(c)
    for i in zeros:
        folded[i] = 0
    X, xs, us = X0, [], []
    u_held = None
    for j in range(U):
        xs.append(X)
        if spec.held:
            if j % per == 0:
                u_held, X = funcs.law(X, T[j], folded, E[:, j])
            X = funcs.plant(X, u_held, dt, folded, E[:, j])
            us.append(u_held)
        else:
            X, u = funcs.step(X, T[j], dt, folded, E[:, j])
            us.append(u)
    outputs = [X, ca.horzcat(*xs), ca.horzcat(*us)]
    return U, ca.Function("qc_block", [X0, T, dt, c, E], ca.cse(outputs))


@lru_cache(maxsize=64)
def chain(spec: LoopSpec, hold: int, blocks: int, zeros: tuple[int, ...] = ()):
    """``(U, F)``: :func:`block` chained ``blocks`` times by ``mapaccum`` (state accumulated)."""
    U, fn = block(spec, hold, zeros)
    return U, fn.mapaccum("qc_chain", blocks, [0], [0])


def as_read(spec: LoopSpec, rows: np.ndarray, at, over=None) -> np.ndarray:
    """The exogenous ``rows`` (n, n_exo) as the loop functions read them at the times ``at`` (n,) s, for
    steps whose midpoints are ``over`` (n,) s: a reference's expansions chosen from the tabulated row
    (:func:`quadctl.physics.reference_rows.in_force`, what ``driver.c``'s ``qc_exo_row`` does per lane)."""
    if not spec.reference:
        return rows
    start = spec.n_exo - N_REFERENCE
    return np.hstack([rows[:, :start], in_force(rows[:, start:], at, over)])


def zero_constants(c: np.ndarray) -> tuple[int, ...]:
    """Indices of the entries of a case's constants ``c`` that are zero (folded into its block)."""
    return tuple(int(i) for i in np.flatnonzero(np.asarray(c) == 0))


class _Chain:
    """One chain's inputs and outputs as numpy arrays that CasADi reads and writes in place.

    CasADi stores matrices column-major, so its ``(k, W)`` matrices are numpy's C-ordered
    ``(W, k)``: row ``j`` of :attr:`xs` is the state before step ``j``, and one more row past the
    chain holds the state after its last step.
    """

    def __init__(self, fn, U: int, blocks: int, spec: LoopSpec, c: np.ndarray, dt: float):
        self.width = U * blocks
        self.x0 = np.zeros(spec.nx)
        self.t = np.zeros(self.width)
        self.e = np.zeros((self.width, spec.n_exo))
        self.xs = np.zeros((self.width + 1, spec.nx))
        self.us = np.zeros((self.width, N_INPUTS))
        self._ends = np.zeros((blocks, spec.nx))
        self._keep = [np.full(blocks, dt), np.ascontiguousarray(np.tile(np.asarray(c, dtype=float), blocks))]
        self._buffer, self._eval = fn.buffer()
        for k, arr in enumerate([self.x0, self.t, *self._keep, self.e]):
            self._buffer.set_arg(k, memoryview(arr))
        for k, arr in enumerate([self._ends, self.xs[:self.width], self.us]):
            self._buffer.set_res(k, memoryview(arr))

    def __call__(self) -> None:
        with ctrl_c_after_the_call():
            self._eval()
        self.xs[self.width] = self._ends[-1]


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
    """Runs :class:`~quadctl.sim.cases.Cases` one at a time in CasADi's virtual machine (a case's
    segments one call each)."""

    backend = "casadi"

    def __init__(self, spec: LoopSpec, reason: str = ""):
        self.spec = spec
        self.reason = reason
        """Why this runner and not the compiled one."""

    def iter_run(self, cases: Cases):
        """Same contract as :meth:`quadctl.sim.native.NativeRunner.iter_run` (a case's segments one
        after another, each from where the last ended)."""
        for i in range(len(cases)):
            yield (i, *self._walk(cases, i))

    def run(self, cases: Cases):
        return [result for _, *result in self.iter_run(cases)]

    def _walk(self, cases: Cases, i: int):
        """``(done, t, xs, us)`` of case ``i`` through its segments: a segment's final record dropped
        where the next one starts (the same state), the case stopping at its last segment or where a
        segment stops early (it left its bounds)."""
        last = int(cases.last[i])
        if last < 0:
            done, ks, xs, us = self._one(cases, i, 0, cases.x0[i])
            return done, cases.dt[0, i] * ks, xs, us
        x = cases.x0[i]
        total, parts = 0, ([], [], [])
        for s in range(last + 1):
            if cases.n[s, i] <= 0:
                continue
            done, ks, xs, us = self._one(cases, i, s, x)
            total += done
            end = s == last or done < cases.n[s, i]
            keep = len(ks) if end else len(ks) - 1
            for part, rows in zip(parts, (cases.dt[s, i] * ks[:keep], xs[:keep], us[:keep])):
                part.append(rows)
            if end:
                break
            x = xs[-1]
        return (total, *(np.concatenate(p) for p in parts))

    def _one(self, cases: Cases, i: int, s: int, x0):
        """``(done, ks, xs, us)`` of segment ``s`` of case ``i`` from the loop state ``x0``."""
        spec = self.spec
        hold = int(cases.hold[s, i]) if spec.held else 1
        k0, n, stride, dt = int(cases.k0[s, i]), int(cases.n[s, i]), int(cases.stride[s, i]), float(cases.dt[s, i])
        if spec.held and k0 % hold:
            raise ValueError(f"a held loop starts on a controller sample: k0 = {k0} is not a multiple of {hold}")
        c, lo, hi = cases.c[s, i], cases.lo[i], cases.hi[i]
        zeros = zero_constants(c)
        chains: dict[int, _Chain] = {}
        x = np.array(x0, dtype=float)
        ks, xs, us = [], [], []
        taken, bad = 0, False
        u_last = np.zeros(N_INPUTS)
        while taken < n and not bad:
            U, _ = block(spec, hold, zeros)
            blocks = BLOCKS[0] if n - taken >= U * BLOCKS[0] else BLOCKS[1]
            if blocks not in chains:
                chains[blocks] = _Chain(chain(spec, hold, blocks, zeros)[1], U, blocks, spec, c, dt)
            run = chains[blocks]
            width = run.width
            steps = k0 + taken + np.arange(width)
            run.x0[:] = x
            run.t[:] = dt * steps.astype(float)
            if spec.n_exo:
                run.e[:] = as_read(spec, cases.exo[i][cases.exo_index(i, steps, s)], run.t, run.t + dt / 2)
            run()
            m = min(width, n - taken)
            after = run.xs[1:m + 1]
            outside = ~np.all((after >= lo) & (after <= hi), axis=1)
            if outside.any():
                m = int(np.argmax(outside)) + 1
                bad = True
            first = (-(k0 + taken)) % stride
            if first < m:
                ks.append(steps[first:m:stride])
                xs.append(run.xs[first:m:stride].copy())
                us.append(run.us[first:m:stride].copy())
            u_last = run.us[m - 1].copy()
            x = run.xs[m].copy()
            taken += m
        last = k0 + taken
        if bad or (spec.held and last % hold):
            u_final = u_last
        else:
            e = np.zeros(spec.n_exo)
            if spec.n_exo:
                rows = cases.exo[i][cases.exo_index(i, np.array([max(last - 1, 0)]), s)]
                e = as_read(spec, rows, dt * float(last))[0]
            u_final = np.asarray(build(spec).law(x, dt * float(last), c, e)[0]).ravel()
        ks.append(np.array([last], dtype=np.int64))
        xs.append(x[None, :])
        us.append(u_final[None, :])
        return taken, np.concatenate(ks), np.concatenate(xs), np.concatenate(us)
