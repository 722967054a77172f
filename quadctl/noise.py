"""Process and sensor noise for the simulation, reproducible from a seed.

Noise is zero-mean Gaussian, drawn every ``period`` seconds and held in between (band-limited
to about ``1 / (2 period)`` Hz). Because the samples live on their own clock, the realization
of a seed does not depend on the RK4 step: a finer ``dt`` integrates the same noise more
accurately instead of drawing a different one.

- Process noise: a body-frame force (N) and torque (N m), added to the vehicle's own
  (``disturbance`` of :func:`quadctl.model.dynamics_expression`).
- Sensor noise: added to the state the controller measures (state units); the plant is not
  touched, the controller acts on what it sees.

Both arrays are drawn from one ``numpy.random.default_rng(seed)`` stream in a fixed order
(all process samples, then all sensor samples, full width), so enabling one kind of noise does
not change the other's realization. The same seed and numpy version give an identical run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl.layout import N_STATES, STATE_INDEX, STATE_NAMES
from quadctl.model import N_DISTURBANCES

DEFAULT_PERIOD = 0.005
"""s between noise samples when the controller is continuous (the Mambo's 200 Hz sensor loop)."""


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
        period = noise_cfg.period or (1.0 / rate if rate else DEFAULT_PERIOD)
        return cls(seed=int(noise_cfg.seed), process_std=np.array([*noise_cfg.force, *noise_cfg.torque], float),
                   sensor_std=sensor, period=float(period))

    @property
    def active(self) -> bool:
        return bool(np.any(self.process_std > 0) or np.any(self.sensor_std > 0))


def realize(spec: NoiseSpec, n: int, dt: float) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Per-step disturbance and measurement noise arrays for ``n`` RK4 steps of ``dt``.

    Returns
    -------
    dist : (n, 6) ndarray or None
        None when there is no process noise.
    meas : (n, 12) ndarray or None
        None when there is no sensor noise.
    """
    samples = int(math.floor((max(n, 1) - 1) * dt / spec.period + 1e-9)) + 1
    rng = np.random.default_rng(spec.seed)
    process = rng.standard_normal((samples, N_DISTURBANCES)) * spec.process_std
    sensor = rng.standard_normal((samples, N_STATES)) * spec.sensor_std
    index = np.minimum(np.floor(np.arange(n) * dt / spec.period + 1e-9).astype(np.int64), samples - 1)
    dist = np.ascontiguousarray(process[index]) if np.any(spec.process_std > 0) else None
    meas = np.ascontiguousarray(sensor[index]) if np.any(spec.sensor_std > 0) else None
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
