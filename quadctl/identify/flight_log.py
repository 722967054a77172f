"""One flight log in SI units and quadctl's frames (:class:`FlightLog`), whatever format it came in, and the
checks every reader shares (:func:`checked`).

A :class:`FlightLog` holds time (s, from the log's first sample: every reader's ``t`` starts at 0,
and :attr:`FlightLog.clock_at_start` keeps the log's own clock there), the specific force (m/s^2)
and the body rates (rad/s) in the FRD body frame, and the four rotor commands normalized to [0, 1]
in the config's numbering; each reader says what it converted (:attr:`FlightLog.conversions`).
Its CSV form (:meth:`FlightLog.to_csv`, :data:`CSV_COLUMNS`) is what :mod:`quadctl.identify.csv_log` reads.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadctl.errors import LogError
from quadctl.present import identify as shown

CSV_COLUMNS = ("t", "acc_x", "acc_y", "acc_z", "gyro_p", "gyro_q", "gyro_r", "cmd_1", "cmd_2", "cmd_3", "cmd_4")
"""The CSV's columns (units and frame: the module's docstring)."""
CSV_FILTER_LINE = "# lowpass:"
"""A CSV comment line that says which low-passes the vehicle ran on its sensors before it logged them:
``# lowpass: acc_lowpass_hz=30 gyro_lowpass_hz=80`` (second-order Butterworth cutoffs, Hz), as a Crazyflie's
log written as a CSV carries them (:meth:`FlightLog.to_csv`). Without it a CSV's sensors are as measured."""
CSV_FILTER_KEYS = ("acc_lowpass_hz", "gyro_lowpass_hz")


@dataclass(frozen=True)
class FlightLog:
    """One flight, in SI units and the FRD body frame.

    Attributes
    ----------
    t : (N,) ndarray
        s from the log's first sample (``t[0] == 0``), strictly increasing.
    acc : (N, 3) ndarray
        Specific force, m/s^2, FRD (``-g`` on z at hover).
    gyro : (N, 3) ndarray
        Body rates ``p, q, r``, rad/s, FRD.
    cmd : (N, 4) ndarray
        Rotor commands in [0, 1], rotor 1 first.
    path : str
    format : str
        ``crazyflie``, ``csv`` or ``ulog``.
    sha256 : str
        Of the file's bytes.
    conversions : tuple of str
        What the reader converted (units, frame, numbering), one phrase each.
    clock_at_start : float
        s: the log's own clock at its first sample (a Crazyflie's time since boot, a ULog's time stamp).
    acc_lowpass_hz, gyro_lowpass_hz : float or None
        Hz: the second-order Butterworth low-pass the vehicle ran on its accelerometer and gyro before it
        logged them (the Crazyflie's sensor driver's); None: logged as measured. The fit passes its
        predicted thrust and torques through the same filter (:meth:`quadctl.identify.grid.Grid.as_logged`),
        so that the filter's lag is not taken for the rotors'.
    """

    t: np.ndarray
    acc: np.ndarray
    gyro: np.ndarray
    cmd: np.ndarray
    path: str
    format: str
    sha256: str
    conversions: tuple[str, ...] = field(default=())
    clock_at_start: float = 0.0
    acc_lowpass_hz: float | None = None
    gyro_lowpass_hz: float | None = None

    @property
    def name(self) -> str:
        return Path(self.path).name

    def provenance(self) -> dict:
        """The log's identity for ``identified.json``."""
        return {"path": self.path, "format": self.format, "sha256": self.sha256, "samples": int(self.t.size),
                "t_start": float(self.t[0]), "t_end": float(self.t[-1]), "clock_at_start_s": self.clock_at_start,
                "rate_hz": float((self.t.size - 1) / (self.t[-1] - self.t[0])), "conversions": list(self.conversions),
                "acc_lowpass_hz": self.acc_lowpass_hz, "gyro_lowpass_hz": self.gyro_lowpass_hz}

    def to_csv(self, path) -> None:
        """Write the log as the CSV format's columns (:data:`CSV_COLUMNS`), full precision, the sensors'
        low-passes (:data:`CSV_FILTER_LINE`) on a comment line above them."""
        data = np.column_stack([self.t, self.acc, self.gyro, self.cmd])
        with open(path, "w", newline="") as fh:
            said = {k: getattr(self, k) for k in CSV_FILTER_KEYS if getattr(self, k) is not None}
            if said:
                fh.write(CSV_FILTER_LINE + " " + " ".join(f"{k}={v:g}" for k, v in said.items()) + "\n")
            fh.write(",".join(CSV_COLUMNS) + "\n")
            np.savetxt(fh, data, delimiter=",", fmt="%.17g")


ACC_RANGE = 1e4
"""m/s^2: an accelerometer sample beyond this (1000 g; a flight controller's IMU reads 16 to 24 g) is corrupt."""
GYRO_RANGE = 1e3
"""rad/s: a gyro sample beyond this (57,000 deg/s; a flight controller's gyro reads 2000 to 4000 deg/s) is corrupt,
or in deg/s."""


def log_error(path, what: str, fix: str) -> LogError:
    """The one line a reader refuses a log with: the file, what is wrong, the fix."""
    return LogError(f"{path}: {what}; {fix}")


def checked(path, t, acc, gyro, cmd, fmt, digest, conversions, clock: float = 0.0) -> FlightLog:
    """The arrays as a FlightLog, after the checks every format shares, its time from the first sample
    (``clock``, s: the log's clock at ``t = 0`` of the given ``t``)."""
    if t.size < 2:
        raise log_error(path, f"{t.size} sample(s), too few to identify anything", "give a log of a flight")
    arrays = {"time": t, "accelerometer": acc, "gyro": gyro, "motor commands": cmd}
    for what, values in arrays.items():
        if not np.all(np.isfinite(values)):
            k = int(np.argwhere(~np.isfinite(np.atleast_2d(values.T).T))[0][0])
            raise log_error(path, f"a non-finite {what} value in sample {k + 1}", "repair or cut the log there")
    for what, values, unit, bound in (("accelerometer", acc, "m/s^2", ACC_RANGE), ("gyro", gyro, "rad/s", GYRO_RANGE)):
        beyond = np.abs(values) > bound
        if np.any(beyond):
            k, i = (int(v) for v in np.argwhere(beyond)[0])
            raise log_error(path, f"{what} value {values[k, i]:.4g} {unit} in sample {k + 1}, beyond any IMU's "
                            f"range (±{bound:g} {unit})", "repair or cut the log there, or check its units")
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        raise log_error(path, f"time does not increase at sample {k + 2} (t = {t[k + 1]:.6g} s after {t[k]:.6g} s)",
                    "sort the samples by time or drop the repeated ones")
    if np.any(cmd < -1e-9) or np.any(cmd > 1 + 1e-9):
        raise log_error(path, f"rotor commands outside [0, 1] (from {cmd.min():.4g} to {cmd.max():.4g})",
                    "normalize the commands to [0, 1] (a PWM 0-65535 divided by 65535)")
    return FlightLog(t=t - t[0], acc=acc, gyro=gyro, cmd=cmd, path=str(path), format=fmt, sha256=digest,
                     conversions=(shown.time_from_start(clock + float(t[0])), *conversions),
                     clock_at_start=clock + float(t[0]))
