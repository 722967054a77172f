"""The inputs and outputs of the loop contract every runner keeps (native or interpreted)."""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np

C_LONG = np.dtype(f"i{ctypes.sizeof(ctypes.c_long)}")
"""numpy's twin of C ``long`` (the driver's integer type)."""


@dataclass(frozen=True)
class Cases:
    """``N`` cases of one :class:`~quadctl.sim.builder.LoopSpec`, each run from step ``k0``.

    Attributes
    ----------
    x0 : (N, nx) ndarray
        Loop state ``[x; z]`` at step ``k0``.
    c : (N, nc) ndarray
        Constants (:func:`~quadctl.sim.builder.pack_constants`).
    dt : (N,) ndarray
        RK4 step, s.
    n : (N,) int ndarray
        Steps to take.
    stride : (N,) int ndarray
        Record the steps whose absolute index is a multiple of this.
    hold : (N,) int ndarray
        RK4 steps per controller sample (1 for continuous feedback). ``k0`` is a multiple of it.
    lo, hi : (N, nx) ndarray
        A case stops at the first state outside ``[lo, hi]`` (NaN always stops it).
    k0 : (N,) int ndarray
        Absolute index of the first step (``t = dt * (k0 + k)``).
    exo : list of (rows, n_exo) ndarray, or None
        Exogenous samples of each case, rows from absolute sample ``exo_first``; step ``kk``
        takes sample ``floor(kk dt / exo_period + 1e-9)`` (clipped to the rows given).
    exo_first : (N,) int ndarray
    exo_period : (N,) ndarray
        s.
    """

    x0: np.ndarray
    c: np.ndarray
    dt: np.ndarray
    n: np.ndarray
    stride: np.ndarray
    hold: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    k0: np.ndarray
    exo: list | None = None
    exo_first: np.ndarray | None = None
    exo_period: np.ndarray | None = None

    @classmethod
    def of(cls, x0, c, dt, n, stride, lo, hi, *, hold=1, k0=0, exo=None, exo_first=0,
           exo_period=1.0) -> Cases:
        """Stack per-case values (scalars broadcast to every case)."""
        x0 = np.atleast_2d(np.asarray(x0, dtype=float))
        N = len(x0)

        def ints(v):
            return np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=C_LONG), (N,)))

        def floats(v, shape=(N,)):
            return np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=float), shape))

        width = x0.shape[1]
        return cls(x0=np.ascontiguousarray(x0), c=np.atleast_2d(np.asarray(c, dtype=float)),
                   dt=floats(dt), n=ints(n), stride=ints(stride), hold=ints(hold),
                   lo=floats(lo, (N, width)), hi=floats(hi, (N, width)), k0=ints(k0),
                   exo=None if exo is None else [np.ascontiguousarray(e, dtype=float) for e in exo],
                   exo_first=ints(exo_first), exo_period=floats(exo_period))

    def __len__(self) -> int:
        return len(self.dt)

    def exo_index(self, i: int, steps: np.ndarray) -> np.ndarray:
        """Row of case ``i``'s exogenous samples that each absolute step in ``steps`` takes."""
        j = np.floor(steps.astype(float) * self.dt[i] / self.exo_period[i] + 1e-9).astype(np.int64)
        return np.clip(j - self.exo_first[i], 0, len(self.exo[i]) - 1)


def record_rows(k0: int, n: int, stride: int) -> int:
    """Rows recorded for steps ``k0 .. k0 + n - 1`` at ``stride``: the multiples, and the last."""
    if n <= 0:
        return 1
    first = -(-k0 // stride)
    last = (k0 + n - 1) // stride
    return max(0, last - first + 1) + 1
