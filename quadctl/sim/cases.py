"""The stack of cases every runner takes (native or interpreted): one case is a stack of one, and a
run of one fixed step is a schedule of one segment."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.native.compile import C_LONG


@dataclass(frozen=True)
class Cases:
    """``N`` cases of one :class:`~quadctl.sim.loop_spec.LoopSpec`, each run through up to ``S`` segments
    of its own, one after another from where the last ended: RK4 at a fixed step is one segment;
    ETDRK4's graded schedule a segment per step size, each with its own constants (the φ-functions of
    its step).

    Attributes
    ----------
    x0 : (N, nx) ndarray
        Loop state ``[x; z]`` at the first segment's step ``k0``.
    c : (S, N, nc) ndarray
        Each segment's constants of each case (:func:`~quadctl.sim.loop_layout.pack_constants`).
    dt : (S, N) ndarray
        Step, s.
    n : (S, N) int ndarray
        Steps to take; 0: the case has no segment ``s`` (its schedule ended before).
    stride : (S, N) int ndarray
        Record the steps whose absolute index is a multiple of this.
    hold : (S, N) int ndarray
        Steps per controller sample (1 for continuous feedback). ``k0`` is a multiple of it.
    k0 : (S, N) int ndarray
        Absolute index, in the segment's own step, of its first step (``t = dt * (k0 + k)``).
    lo, hi : (N, nx) ndarray
        A case stops at the first state outside ``[lo, hi]`` (NaN always stops it).
    exo : list of (rows, n_exo) ndarray, or None
        Exogenous samples of each case over its whole run, rows from absolute sample ``exo_first``;
        step ``kk`` takes sample ``floor(kk dt / exo_period + 1e-9)`` (clipped to the rows given).
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
    k0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    exo: list | None = None
    exo_first: np.ndarray | None = None
    exo_period: np.ndarray | None = None

    @classmethod
    def of(cls, x0, c, dt, n, stride, lo, hi, *, hold=1, k0=0, exo=None, exo_first=0,
           exo_period=1.0) -> Cases:
        """One segment a case: per-case values (``c`` (N, nc), the others (N,); scalars broadcast)."""
        x0 = np.atleast_2d(np.asarray(x0, dtype=float))
        c = np.atleast_2d(np.asarray(c, dtype=float))
        return cls.graded(x0, c[None], np.asarray(dt, dtype=float)[None], np.asarray(n)[None],
                          np.asarray(stride)[None], np.asarray(k0)[None], lo, hi, hold=np.asarray(hold)[None],
                          exo=exo, exo_first=exo_first, exo_period=exo_period)

    @classmethod
    def graded(cls, x0, c, dt, n, stride, k0, lo, hi, *, hold=1, exo=None, exo_first=0,
               exo_period=1.0) -> Cases:
        """Per-segment values (``c`` (S, N, nc), the others (S, N); scalars broadcast) and per-case ones
        (``x0``, ``lo``, ``hi`` (N, nx), ``exo_first``, ``exo_period`` (N,))."""
        c = np.asarray(c, dtype=float)
        S, N = c.shape[:2]
        x0 = np.atleast_2d(np.asarray(x0, dtype=float))
        x0 = np.ascontiguousarray(np.broadcast_to(x0, (N, x0.shape[-1])))

        def per_segment(v, dtype):
            return np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=dtype), (S, N)))

        def per_case(v, dtype):
            return np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=dtype), (N,)))

        lo, hi = (np.ascontiguousarray(np.broadcast_to(np.atleast_2d(np.asarray(b, dtype=float)), x0.shape))
                  for b in (lo, hi))
        return cls(x0=x0, c=np.ascontiguousarray(c), dt=per_segment(dt, float), n=per_segment(n, C_LONG),
                   stride=per_segment(stride, C_LONG), hold=per_segment(hold, C_LONG), k0=per_segment(k0, C_LONG),
                   lo=lo, hi=hi, exo=None if exo is None else [np.ascontiguousarray(e, dtype=float) for e in exo],
                   exo_first=per_case(exo_first, C_LONG), exo_period=per_case(exo_period, float))

    def __len__(self) -> int:
        return self.c.shape[1]

    @property
    def segments(self) -> int:
        """``S``: the most segments a case has."""
        return self.c.shape[0]

    def starting(self, x0, exo=None) -> Cases:
        """These cases from the states ``x0`` (N, nx) (and with the exogenous rows ``exo``, if given),
        sharing what a runner kept of them (:meth:`memo`: their marshalled steps and constants)."""
        fields = dict(self.__dict__)
        fields.pop("_memo", None)
        fields["x0"] = np.ascontiguousarray(np.atleast_2d(np.asarray(x0, dtype=float)))
        if exo is not None:
            fields["exo"] = [np.ascontiguousarray(e, dtype=float) for e in exo]
        out = Cases(**fields)
        object.__setattr__(out, "_memo", self.__dict__.setdefault("_memo", {}))
        return out

    def memo(self, key, make):
        """``make()``, kept with these cases (and the copies :meth:`starting` makes) under ``key``: a
        runner's marshalled arrays of their steps and constants, made once for cases run again from
        other states (a loop's kept ETDRK4 setup)."""
        store = self.__dict__.setdefault("_memo", {})
        if key not in store:
            store[key] = make()
        return store[key]

    @property
    def last(self) -> np.ndarray:
        """(N,) the index of each case's last segment (its last with steps; -1: none)."""
        taken = self.n > 0
        return np.where(taken.any(axis=0), self.segments - 1 - np.argmax(taken[::-1], axis=0), -1)

    def exo_index(self, i: int, steps: np.ndarray, s: int = 0) -> np.ndarray:
        """Row of case ``i``'s exogenous samples that each absolute step in ``steps`` (of segment ``s``) takes."""
        j = np.floor(steps.astype(float) * self.dt[s, i] / self.exo_period[i] + 1e-9).astype(np.int64)
        return np.clip(j - self.exo_first[i], 0, len(self.exo[i]) - 1)

    def rows(self, i: int) -> int:
        """The records case ``i``'s run writes at most: each segment's (:func:`record_rows`), one fewer
        a later segment (its first is the last one's final record)."""
        counts = [record_rows(int(self.k0[s, i]), int(self.n[s, i]), int(self.stride[s, i]))
                  for s in range(self.segments) if self.n[s, i] > 0]
        return max(1, sum(counts) - max(len(counts) - 1, 0))


def record_rows(k0: int, n: int, stride: int) -> int:
    """Rows recorded for steps ``k0 .. k0 + n - 1`` at ``stride``: the multiples, and the last."""
    if n <= 0:
        return 1
    first = -(-k0 // stride)
    last = (k0 + n - 1) // stride
    return max(0, last - first + 1) + 1
