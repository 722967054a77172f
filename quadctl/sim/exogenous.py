"""The exogenous inputs of a run on one clock: noise, wind and a flown reference's rows drawn in order
(:class:`ExoStream`), chunk by chunk for a long run so memory does not grow with the duration, and the
wind the plant felt (:func:`wind_felt`).
"""
from __future__ import annotations

import numpy as np

from quadctl.errors import TrimError
from quadctl.physics.noise import NoiseSpec, NoiseStream, exogenous_period
from quadctl.physics.wind import WindSpec, WindStream


class ExoStream:
    """The exogenous rows of a run (:func:`quadctl.sim.loop_layout.exo_layout`) on one clock, drawn in order.

    Row ``j`` holds over ``[j period, (j + 1) period)``: the noise's sample ``j``
    (:class:`quadctl.physics.noise.NoiseStream`), then the wind at ``t = j period``
    (:class:`quadctl.physics.wind.WindStream`). The clock is the noise's period, else the controller's, else
    :data:`quadctl.physics.noise.DEFAULT_PERIOD`: never the RK4 step, so a seed gives the same run at any ``dt``.
    """

    def __init__(self, noise: NoiseSpec | None, wind: WindSpec | None, rate: float | None = None,
                 reference=None):
        self.period = exogenous_period(noise.period if noise is not None else None, rate)
        self.noise = NoiseStream(noise) if noise is not None else None
        self.wind = WindStream(wind, self.period) if wind is not None else None
        self.reference = reference
        """:class:`quadctl.physics.reference_rows.FlownReference` whose rows end each row, or None."""

    def index(self, steps, dt: float) -> np.ndarray:
        """The row each absolute RK4 step of ``dt`` takes (as the runners count)."""
        return np.floor(np.asarray(steps, dtype=float) * dt / self.period + 1e-9).astype(np.int64)

    def samples(self, first: int, last: int) -> np.ndarray:
        """Rows ``first .. last`` (inclusive); ``first`` never goes back before an earlier call's (the stack
        of one of :meth:`samples_of`).

        Raises
        ------
        TrimError
            The reference's path needs an attitude beyond the model's.
        """
        (got,) = ExoStream.samples_of([self], [(first, last)])
        if isinstance(got, TrimError):
            raise got
        return got

    @staticmethod
    def samples_of(streams, spans) -> list:
        """:meth:`samples` of many streams (``spans``: each one's ``(first, last)``), their references'
        rows tabulated together (:meth:`quadctl.physics.reference_rows.FlownReference.rows_of`, the rows each
        has alone): per stream its rows, or the TrimError refusing its reference."""
        parts: list = [[] for _ in streams]
        flying: dict[type, list] = {}  # the references' kind -> the streams that fly one
        for k, (stream, (first, last)) in enumerate(zip(streams, spans)):
            if stream.noise is not None:
                parts[k].append(stream.noise.samples(first, last))
            if stream.wind is not None:
                parts[k].append(stream.wind.samples(first, last))
            if stream.reference is not None:
                flying.setdefault(type(stream.reference), []).append(k)
        for kind, members in flying.items():
            tabulated = kind.rows_of([streams[k].reference for k in members],
                                     [np.arange(spans[k][0], spans[k][1] + 1) for k in members],
                                     [streams[k].period for k in members])
            for k, got in zip(members, tabulated):
                parts[k] = got if isinstance(got, TrimError) else [*parts[k], got]
        return [part if isinstance(part, TrimError) else np.hstack(part) for part in parts]

    def span(self, k0: int, m: int, dt: float) -> tuple[int, int]:
        """(first, last): the rows covering RK4 steps ``k0 .. k0 + m - 1`` of ``dt``."""
        first, last = (int(j) for j in self.index([k0, k0 + max(m, 1) - 1], dt))
        return first, last

    def rows(self, k0: int, m: int, dt: float) -> tuple[int, np.ndarray]:
        """(first row index, rows) covering RK4 steps ``k0 .. k0 + m - 1`` of ``dt``."""
        first, last = self.span(k0, m, dt)
        return first, self.samples(first, last)


def wind_felt(wind: WindSpec, period: float, ks, dt: float, block: int = 256) -> np.ndarray:
    """(len(ks), 3) m/s NED: the wind the plant felt over each absolute step in ``ks`` (increasing) of
    a run whose exogenous clock has ``period`` s; a fresh stream, ``block`` steps at a time (memory
    bounded by a block's span)."""
    stream = WindStream(wind, period)
    ks = np.asarray(ks)
    out = np.empty((len(ks), 3))
    for a in range(0, len(ks), block):
        j = np.floor(ks[a:a + block].astype(float) * dt / period + 1e-9).astype(np.int64)
        out[a:a + block] = stream.samples(int(j[0]), int(j[-1]))[j - j[0]]
    return out
