"""Process and sensor noise for the simulation, reproducible from a seed.

Zero-mean Gaussian, drawn every ``period`` seconds and held in between, on its own clock (a seed's
realization does not depend on the RK4 step): a body force (N) and torque (N m) added to the
vehicle's (``disturbance`` of :func:`quadctl.physics.model.dynamics_expression`), and sensor noise added to
what the controller measures. Two independent streams spawned from the seed, drawn as the run needs
them (:class:`NoiseStream`). See docs/internals.md ("Noise").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl.layout import N_STATES, STATE_INDEX, STATE_NAMES
from quadctl.physics.model import N_DISTURBANCES

DEFAULT_PERIOD = 0.005
"""s between noise samples when the controller is continuous (the Mambo's 200 Hz sensor loop)."""


def exogenous_period(period: float | None, rate: float | None) -> float:
    """s between the samples of the exogenous inputs (noise, wind, a reference's rows): the noise's
    own ``period`` if given, else the controller's sample time, else :data:`DEFAULT_PERIOD`."""
    return float(period or (1.0 / rate if rate else DEFAULT_PERIOD))


@dataclass(frozen=True)
class NoiseSpec:
    """Noise intensities and the seed.

    Attributes
    ----------
    seed : int
    process_std : (6,) ndarray
        Standard deviation of body force (N, 3) and torque (N m, 3).
    sensor_std : (12,) ndarray
        Standard deviation of each measured state (state units).
    period : float
        s between samples.
    """

    seed: int
    process_std: np.ndarray
    sensor_std: np.ndarray
    period: float

    @classmethod
    def from_config(cls, noise_cfg, rate: float | None = None) -> NoiseSpec:
        """From ``simulation.noise``; the period defaults to the controller's (or 5 ms)."""
        sensor = np.zeros(N_STATES)
        for name, std in noise_cfg.sensor.items():
            sensor[STATE_INDEX[name]] = std
        period = exogenous_period(noise_cfg.period, rate)
        return cls(seed=int(noise_cfg.seed), process_std=np.array([*noise_cfg.force, *noise_cfg.torque], float),
                   sensor_std=sensor, period=float(period))

    @property
    def active(self) -> bool:
        return bool(np.any(self.process_std > 0) or np.any(self.sensor_std > 0))


class NoiseStream:
    """The noise samples of a spec, drawn in order as a run needs them (memory bounded by a chunk).

    Sample ``j`` (held over ``[j period, (j + 1) period)``) is one row of :data:`quadctl.sim.loop_layout.EXO_LAYOUT`:
    the body force and torque (N, N m), then the sensor noise of the 12 states. Process and
    sensor noise come from two independent streams spawned from the seed
    (``numpy.random.SeedSequence(seed).spawn(2)``), so enabling one does not change the other,
    and the realization does not depend on how a run is cut into chunks, nor on the RK4 step.
    """

    def __init__(self, spec: NoiseSpec):
        self.spec = spec
        process, sensor = np.random.SeedSequence(spec.seed).spawn(2)
        self._process = np.random.default_rng(process)
        self._sensor = np.random.default_rng(sensor)
        self._first = 0
        self._rows = np.zeros((0, N_DISTURBANCES + N_STATES))

    def samples(self, first: int, last: int) -> np.ndarray:
        """Rows ``first .. last`` (inclusive); ``first`` never goes back before an earlier call's."""
        if first < self._first:
            raise ValueError(f"noise sample {first} was already dropped (stream at {self._first})")
        have = self._first + len(self._rows)
        if last >= have:
            count = last + 1 - have
            rows = np.empty((len(self._rows) + count, N_DISTURBANCES + N_STATES))
            rows[:len(self._rows)] = self._rows
            np.multiply(self._process.standard_normal((count, N_DISTURBANCES)), self.spec.process_std,
                        out=rows[len(self._rows):, :N_DISTURBANCES])
            np.multiply(self._sensor.standard_normal((count, N_STATES)), self.spec.sensor_std,
                        out=rows[len(self._rows):, N_DISTURBANCES:])
            self._rows = rows
        self._rows = self._rows[first - self._first:]
        self._first = first
        return self._rows[:last + 1 - first]

    def rows(self, k0: int, m: int, dt: float) -> tuple[int, np.ndarray]:
        """(first sample index, rows) covering RK4 steps ``k0 .. k0 + m - 1`` of ``dt``."""
        index = np.floor(np.array([k0, k0 + max(m, 1) - 1], dtype=float) * dt / self.spec.period + 1e-9)
        first, last = int(index[0]), int(index[1])
        return first, self.samples(first, last)


def realize(spec: NoiseSpec, n: int, dt: float) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Per-step disturbance (n, 6) and sensor noise (n, 12) of ``n`` RK4 steps of ``dt`` (None where
    that noise is off): what :class:`NoiseStream` gives a run, step by step (for tests and plots)."""
    stream = NoiseStream(spec)
    first, rows = stream.rows(0, n, dt)
    index = np.floor(np.arange(n) * dt / spec.period + 1e-9).astype(np.int64) - first
    per_step = rows[np.minimum(index, len(rows) - 1)]
    dist = np.ascontiguousarray(per_step[:, :N_DISTURBANCES]) if np.any(spec.process_std > 0) else None
    meas = np.ascontiguousarray(per_step[:, N_DISTURBANCES:]) if np.any(spec.sensor_std > 0) else None
    return dist, meas


def rms_deviation(t, x, x_ref, t_from: float = 0.0) -> dict[str, float]:
    """Root-mean-square of ``x - x_ref`` per state over ``t >= t_from`` (state units).

    Samples are equally spaced (the run's records), so the plain mean is the time average.
    """
    t = np.asarray(t)
    keep = t >= t_from - 1e-12
    err = (np.asarray(x) - np.asarray(x_ref))[keep]
    if err.shape[0] == 0:
        return {name: math.nan for name in STATE_NAMES}
    rms = np.sqrt(np.mean(err ** 2, axis=0))
    return {name: float(rms[i]) for i, name in enumerate(STATE_NAMES)}
