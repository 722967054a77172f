"""The inputs and outputs of the loop contract every runner keeps (native or interpreted)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.native.compile import C_LONG


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


@dataclass(frozen=True)
class Segments:
    """``N`` cases of one :class:`~quadctl.sim.builder.LoopSpec`, each run through up to ``S``
    segments of its own (ETDRK4's graded schedule: each segment its own step and constants), one
    after another from where the last ended.

    Attributes
    ----------
    c : (S, N, nc) ndarray
        Each segment's constants of each case.
    dt : (S, N) ndarray
        s.
    n : (S, N) int ndarray
        Steps; 0: the case has no segment ``s`` (its schedule ended before).
    stride, hold, k0 : (S, N) int ndarray
        As :class:`Cases`' (``k0``: the absolute index, in the segment's own step, of its first step).
    lo, hi : (N, nx) ndarray
    exo : list of (rows, n_exo) ndarray, or None
        The exogenous rows of each case over its whole run, from absolute sample ``exo_first``.
    exo_first : (N,) int ndarray
    exo_period : (N,) ndarray
        s.
    """

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
    def of(cls, c, dt, n, stride, k0, lo, hi, *, hold=1, exo=None, exo_first=0, exo_period=1.0) -> Segments:
        """Stack per-segment values ((S, N), scalars broadcast) and per-case ones ((N,))."""
        c = np.asarray(c, dtype=float)
        S, N = c.shape[:2]

        def ints(v):
            return np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=C_LONG), (S, N)))

        lo, hi = (np.ascontiguousarray(np.atleast_2d(np.asarray(b, dtype=float))) for b in (lo, hi))
        return cls(c=np.ascontiguousarray(c), dt=np.ascontiguousarray(np.broadcast_to(np.asarray(dt, dtype=float),
                                                                                   (S, N))),
                   n=ints(n), stride=ints(stride), hold=ints(hold), k0=ints(k0),
                   lo=np.ascontiguousarray(np.broadcast_to(lo, (N, lo.shape[-1]))),
                   hi=np.ascontiguousarray(np.broadcast_to(hi, (N, hi.shape[-1]))),
                   exo=None if exo is None else [np.ascontiguousarray(e, dtype=float) for e in exo],
                   exo_first=np.ascontiguousarray(np.broadcast_to(np.asarray(exo_first, dtype=C_LONG), (N,))),
                   exo_period=np.ascontiguousarray(np.broadcast_to(np.asarray(exo_period, dtype=float), (N,))))

    def __len__(self) -> int:
        return self.c.shape[1]

    def memo(self, key, make):
        """``make()``, kept with these segments under ``key`` (a runner's marshalled arrays of them: made
        once for segments a cached plan runs again)."""
        store = self.__dict__.setdefault("_memo", {})
        if key not in store:
            store[key] = make()
        return store[key]

    @property
    def last(self) -> np.ndarray:
        """(N,) the index of each case's last segment (its last with steps; -1: none)."""
        S = self.n.shape[0]
        taken = self.n > 0
        return np.where(taken.any(axis=0), S - 1 - np.argmax(taken[::-1], axis=0), -1)

    def segment(self, s: int, x0) -> Cases:
        """Segment ``s`` of every case as :class:`Cases` from the states ``x0`` (N, nx)."""
        return Cases(x0=np.ascontiguousarray(x0, dtype=float), c=self.c[s], dt=self.dt[s], n=self.n[s],
                     stride=self.stride[s], hold=self.hold[s], lo=self.lo, hi=self.hi, k0=self.k0[s],
                     exo=self.exo, exo_first=self.exo_first, exo_period=self.exo_period)


def run_segments_by_calls(run, segments: Segments, x0) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """``run`` (a runner) through ``segments`` one call a segment: per case ``(done, t, xs, us)``,
    steps completed, recorded times (s), loop states (r, nx) and inputs (r, 4); a segment's final
    record is dropped where the next one starts (the same state), and a case stops at its last
    segment or where a segment stops early (it left its bounds)."""
    x = np.array(x0, dtype=float, ndmin=2)
    N = len(segments)
    last = segments.last
    parts = [([], [], []) for _ in range(N)]
    total, alive = np.zeros(N, dtype=int), last >= 0
    for s in range(segments.n.shape[0]):
        if not alive.any():
            break
        live = alive & (segments.n[s] > 0)
        cases = segments.segment(s, x)
        cases = Cases(**{**cases.__dict__, "n": np.where(live, cases.n, 0).astype(C_LONG)})
        for j, (done, ks, xs, us) in enumerate(run.run(cases)):
            if not live[j]:
                continue
            total[j] += done
            end = s == last[j] or done < segments.n[s, j]
            keep = len(ks) if end else len(ks) - 1
            parts[j][0].append(segments.dt[s, j] * ks[:keep])
            parts[j][1].append(xs[:keep])
            parts[j][2].append(us[:keep])
            x[j] = xs[-1]
            alive[j] = not end
    return [(int(total[j]), *(np.concatenate(p) for p in parts[j])) for j in range(N)]
