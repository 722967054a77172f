"""A log on a uniform time grid: its sensors' filters, the gyro differentiated, the rotor commands through
the rotors' lag, and the windows a fit takes.

:func:`on_grid` resamples a log; :func:`lagged` runs the commands through the rotors' first-order lag
and a pure delay, with their derivatives (the rotor model of Eschmann, Albani & Loianno, IROS 2024, in
the docs, docs/internals.md, "Identification").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.errors import LogError

scipy = lazy_import("scipy")

ANGULAR_ACCELERATION_CUTOFF = 20.0
"""Hz: the gyro is low-passed (zero phase, 2nd-order Butterworth) before it is differentiated; the
model's torque goes through the same filter, so the fit compares like with like."""
LEAD_IN = 2.0
"""s of the log before (and after) a window that a fit computes through: the lag's memory (its
time constant, tens of ms) and the low-pass filter's settle in it to far below the noise."""
COMMANDS_SEEN = 0.99
"""A log sampled at this share of the vehicle's command rate or more (its median rate rounded) sees every
command it flew: :func:`on_grid` holds them between samples."""
_LAG_DELAY_STEP = 1e-4
"""s: the central difference of the lag in the delay (exact for a linearly interpolated command)."""


@dataclass(frozen=True)
class Grid:
    """A log on a uniform time grid (the lag is then one recursive filter).

    Attributes
    ----------
    t : (N,) ndarray
        s.
    dt : float
        s.
    acc, gyro : (N, 3) ndarray
        Linearly interpolated.
    alpha : (N, 3) ndarray
        Angular acceleration, rad/s^2: the gyro low-passed (:data:`ANGULAR_ACCELERATION_CUTOFF`), differentiated.
    cmd : (N, 4) ndarray
        Held (a command is a step until the next), or, with ``linear_commands``, linear between samples.
    acc_lowpass_hz, gyro_lowpass_hz : float or None
        The low-passes the vehicle ran on its sensors before it logged them
        (:attr:`quadctl.identify.flight_log.FlightLog.acc_lowpass_hz`): :meth:`as_logged` applies them.
    linear_commands : bool
        The commands moved between the log's samples (its controller changes them more often than the log
        samples them): the rotors' lag takes them linear from one sample to the next (:meth:`lagged`).
    """

    t: np.ndarray
    dt: float
    acc: np.ndarray
    gyro: np.ndarray
    alpha: np.ndarray
    cmd: np.ndarray
    acc_lowpass_hz: float | None = None
    gyro_lowpass_hz: float | None = None
    linear_commands: bool = False

    def lagged(self, time_constant: float, delay: float = 0.0, *, in_delay: bool = True):
        """The grid's commands through the rotors' lag (:func:`lagged`), held or linear between samples as the
        grid takes them (:attr:`linear_commands`)."""
        return lagged(self.cmd, self.dt, time_constant, delay, in_delay=in_delay, linear=self.linear_commands)

    def around(self, windows, margin: float = LEAD_IN) -> Grid:
        """The grid from ``margin`` s before the first window to ``margin`` after the last (the lag and
        the low-pass filter settle in the margin; nothing outside it changes the fit)."""
        t0 = min(a for a, _ in windows) - margin
        t1 = max(b for _, b in windows) + margin
        keep = slice(int(np.searchsorted(self.t, t0)), int(np.searchsorted(self.t, t1, side="right")))
        return replace(self, t=self.t[keep], acc=self.acc[keep], gyro=self.gyro[keep], alpha=self.alpha[keep],
                       cmd=self.cmd[keep])

    def as_logged(self, values: np.ndarray, sensor: str) -> np.ndarray:
        """``values`` (on axis 0, this grid's samples) through the low-pass the vehicle ran on ``sensor``
        (``"acc"`` or ``"gyro"``) before logging it, causal, from rest at its first value; unchanged when it
        ran none. A model's prediction so filtered compares with the log without the filter's lag."""
        hz = self.acc_lowpass_hz if sensor == "acc" else self.gyro_lowpass_hz
        if hz is None:
            return values
        b, a = _butter_at(float(hz), float(self.dt))
        rest = scipy.signal.lfilter_zi(b, a).reshape((-1,) + (1,) * (values.ndim - 1)) * values[:1]
        return scipy.signal.lfilter(b, a, values, axis=0, zi=rest)[0]

    def lowpass(self, values: np.ndarray) -> np.ndarray:
        """The zero-phase filter applied to the gyro, on axis 0 of ``values``."""
        b, a = _butter(self.dt)
        return scipy.signal.filtfilt(b, a, values, axis=0)


@lru_cache(maxsize=8)
def _butter(dt: float):
    return scipy.signal.butter(2, ANGULAR_ACCELERATION_CUTOFF * 2.0 * dt)


@lru_cache(maxsize=8)
def _butter_at(hz: float, dt: float):
    """``(b, a)``: the second-order Butterworth low-pass at ``hz`` (analog), carried to the sample time ``dt``
    (s) by the bilinear transform. The vehicle ran its filter at its own sensor rate (the Crazyflie's ``lpf2p``
    at 1 kHz); a log may be sampled slower, down to a rate whose Nyquist frequency is below the cutoff (an
    80 Hz gyro filter in a 100 Hz log), where a digital design at the log's rate does not exist. The analog
    filter on the log's rate holds at any rate: its lag at low frequencies (``sqrt(2) / (2 pi hz)``) is kept
    exactly. Not prewarped, as ``lpf2p`` is at its rate: at 1 kHz that moves the cutoff by 0.3 % at 30 Hz and
    2 % at 80 Hz (0.05 ms of the gyro filter's 2.8 ms lag)."""
    b, a = scipy.signal.butter(2, 2.0 * math.pi * hz, analog=True)
    return scipy.signal.bilinear(b, a, fs=1.0 / dt)


def on_grid(log, rate: float | None = None, command_rate: float | None = None) -> Grid:
    """The log resampled at ``rate`` (Hz; default its median rate rounded to 10 Hz).

    ``command_rate`` (Hz, :attr:`quadctl.identify.measurement.Airframe.command_rate`) is how often the vehicle
    changes its commands. A log that samples them at least that often sees each step: they are held between
    samples. A log that samples them less often (a 100 Hz log of a 500 Hz controller) sees a command that moved
    since its last sample: they are taken linear between samples (:attr:`Grid.linear_commands`); held, they
    would lag the rotors by half a sample more than they do, and the fit would take it off the rotors' lag."""
    if rate is None:
        rate = max(10.0, round(1.0 / float(np.median(np.diff(log.t))) / 10.0) * 10.0)
    dt = 1.0 / rate
    t = log.t[0] + dt * np.arange(int(math.floor((log.t[-1] - log.t[0]) / dt)) + 1)
    acc = np.column_stack([np.interp(t, log.t, log.acc[:, i]) for i in range(3)])
    gyro = np.column_stack([np.interp(t, log.t, log.gyro[:, i]) for i in range(3)])
    linear = command_rate is not None and rate < COMMANDS_SEEN * command_rate
    if linear:
        cmd = np.column_stack([np.interp(t, log.t, log.cmd[:, i]) for i in range(4)])
    else:
        cmd = log.cmd[np.clip(np.searchsorted(log.t, t, side="right") - 1, 0, log.t.size - 1)]
    grid = Grid(t=t, dt=dt, acc=acc, gyro=gyro, alpha=np.zeros_like(gyro), cmd=cmd,
                acc_lowpass_hz=log.acc_lowpass_hz, gyro_lowpass_hz=log.gyro_lowpass_hz, linear_commands=linear)
    return replace(grid, alpha=np.gradient(grid.lowpass(gyro), dt, axis=0))


def lagged(cmd: np.ndarray, dt: float, time_constant: float, delay: float = 0.0, *, in_delay: bool = True,
           linear: bool = False):
    """The commands delayed by ``delay`` and lagged through ``time_constant``: exact for commands held from
    one sample to the next or, with ``linear``, moving linearly from one sample to the next.

    Returns
    -------
    z, dz_dT, dz_dd : (N, 4) ndarray
        The lagged commands and their derivatives in the time constant and the delay (1/s; None
        without ``in_delay``).
    """
    a = math.exp(-dt / time_constant)
    da = a * dt / time_constant ** 2  # da/dT
    # z_k = a z_{k-1} + (1 - a) u_{k-1} + b (u_k - u_{k-1}): b = 0 for a held command; for a linear one,
    # the lag's response to the ramp, b = 1 - (T / dt) (1 - a)
    b = 1.0 - time_constant / dt * (1.0 - a) if linear else 0.0
    db = -(1.0 - a) / dt + time_constant / dt * da if linear else 0.0  # db/dT

    def run(d):
        shifted = _delayed(cmd, d / dt)
        # from rest at the first command (z_0 = u_0)
        z = scipy.signal.lfilter([b, 1 - a - b], [1.0, -a], shifted - shifted[0], axis=0) + shifted[0]
        return z, shifted

    z, shifted = run(delay)
    # dz_k/dT = a dz_{k-1}/dT + da/dT (z_{k-1} - u_{k-1}) + db/dT (u_k - u_{k-1})
    drive = np.vstack([np.zeros((1, 4)), (z[:-1] - shifted[:-1]) * da + np.diff(shifted, axis=0) * db])
    dz_dt = scipy.signal.lfilter([1.0], [1.0, -a], drive, axis=0)
    if not in_delay:
        return z, dz_dt, None
    h = _LAG_DELAY_STEP
    dz_dd = (run(delay + h)[0] - run(max(delay - h, 0.0))[0]) / (delay + h - max(delay - h, 0.0))
    return z, dz_dt, dz_dd


def _delayed(cmd: np.ndarray, shift: float) -> np.ndarray:
    """``cmd`` shifted later by ``shift`` samples (linear between samples; the first value before)."""
    if shift <= 0:
        return cmd
    n = cmd.shape[0]
    s = np.arange(n) - shift
    lo = np.clip(np.floor(s).astype(int), 0, n - 1)
    hi = np.clip(lo + 1, 0, n - 1)
    w = np.clip(s - np.floor(s), 0.0, 1.0)[:, None]
    out = (1 - w) * cmd[lo] + w * cmd[hi]
    out[s < 0] = cmd[0]
    return out


def window_mask(t: np.ndarray, windows) -> np.ndarray:
    """True at samples inside any ``(t0, t1)`` of ``windows``."""
    mask = np.zeros(t.shape, dtype=bool)
    for t0, t1 in windows:
        mask |= (t >= t0) & (t <= t1)
    return mask


def require_window(grid: Grid, windows, path: str, stage: str, minimum: float = 1.0) -> None:
    """Raise LogError when the windows hold less than ``minimum`` seconds of the log."""
    have = window_mask(grid.t, windows).sum() * grid.dt
    if have < minimum:
        spans = ", ".join(f"{a:g}:{b:g}" for a, b in windows) or "none"
        raise LogError(f"{path}: the {stage} window ({spans}) holds {have:.3g} s of the log "
                       f"(from {grid.t[0]:.4g} to {grid.t[-1]:.4g} s), less than {minimum:g} s; "
                       "give --window t0:t1 inside the flight")
