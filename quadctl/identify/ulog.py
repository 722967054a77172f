"""PX4's ULog flight logs, read through the optional ``pyulog`` package (:func:`read_ulog`), and where a
log cut short ends (:func:`ulog_end`)."""

from __future__ import annotations

import contextlib
import hashlib
import io
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadctl.errors import LogError, QuadctlNotice
from quadctl.identify.flight_log import FlightLog, checked, log_error
from quadctl.present import identify as shown

ULOG_CORRUPTION_WORDS = ("corruption", "sync")
"""A line pyulog prints with one of these (``File corruption detected ...``, ``Failed to find sync ...``)
says the file is damaged or cut short."""
ULOG_HEADER_BYTES = 16
"""A ULog's file header (magic, version, start time stamp); its messages follow to the end of the file, each a
3-byte header (uint16 size of the payload that follows, uint8 type letter) and its payload."""
ULOG_DATA_TYPES = b"ALC"
"""The message types that open the data section (a subscription, a logged string, a tagged one): the
definitions before it (flag bits, formats, info, parameters) hold no samples."""
ULOG_TOPICS = {"sensor_combined": ("accelerometer_m_s2", "gyro_rad"), "actuator_motors": "control"}
"""The ULog topics read: the IMU's specific force (m/s^2, FRD) and rates (rad/s, FRD), and the
motor commands ``control[0..3]`` in [0, 1] (PX4's motor order)."""


@dataclass(frozen=True)
class UlogEnd:
    """Where a ULog that looks cut short ends (:func:`ulog_end`); offsets in bytes from the file's start."""

    size: int
    """The file's bytes."""
    at: int | None
    """The message the file ends inside (None: it ends after a whole message)."""
    declared: int | None
    """The payload bytes that message's header declares (None: the file ends inside its 3-byte header)."""
    data_at: int | None
    """The first message of the data section (None: the file ends before it)."""


def ulog_end(raw: bytes) -> UlogEnd | None:
    """None for a ULog whose messages end with the file, else where it looks cut short.

    A complete ULog's last message ends where the file does (the logger writes whole messages) and it
    has a data section; a log cut short (a full card, the power lost, a partial copy) ends inside a
    message, or before its data section. Data appended after a crash (the flag bits' appended offsets,
    where the part before may stop inside a message) is walked from the last offset.
    """
    pos, data_at = ULOG_HEADER_BYTES, None
    if raw[ULOG_HEADER_BYTES + 2:ULOG_HEADER_BYTES + 3] == b"B" and len(raw) >= ULOG_HEADER_BYTES + 3 + 40:
        appended = [o for o in struct.unpack_from("<3Q", raw, ULOG_HEADER_BYTES + 3 + 16) if 0 < o <= len(raw)]
        if appended:
            pos = data_at = max(appended)
    while pos + 3 <= len(raw):
        size, kind = struct.unpack_from("<HB", raw, pos)
        if data_at is None and kind in ULOG_DATA_TYPES:
            data_at = pos
        if pos + 3 + size > len(raw):
            return UlogEnd(size=len(raw), at=pos, declared=size, data_at=data_at)
        pos += 3 + size
    if pos < len(raw):
        return UlogEnd(size=len(raw), at=pos, declared=None, data_at=data_at)
    return None if data_at is not None else UlogEnd(size=len(raw), at=None, declared=None, data_at=None)


def read_ulog(path) -> FlightLog:
    """Read a PX4 ULog through the optional ``pyulog`` package (:data:`ULOG_TOPICS`).

    The motor commands are interpolated onto the IMU's time stamps (held, not blended: a command
    is a step). PX4 already logs FRD and SI units; its motor order is ``motors.numbering: px4``.

    Raises
    ------
    LogError
        ``pyulog`` not installed, or a topic missing (said as a truncated or corrupt file when pyulog
        found it damaged, as a file cut short when it ends inside a message or before its data: :func:`ulog_end`).

    Warns
    -----
    QuadctlNotice
        pyulog found the file damaged, or it looks cut short, but both topics were read (pyulog's own lines
        never reach stdout).
    """
    try:
        from pyulog import ULog
    except ImportError:
        raise LogError(f"{path}: reading a ULog needs the pyulog package; pip install '.[identify]' in the quadctl "
                       "checkout (or pip install 'quadctl[identify]'), or convert the log to the CSV format") from None
    raw = Path(path).read_bytes()
    said = io.StringIO()  # pyulog prints what it finds wrong on stdout (which --json owns)
    try:
        with contextlib.redirect_stdout(said):
            ulog = ULog(str(path), list(ULOG_TOPICS))
    except Exception as exc:  # pyulog raises plain exceptions for a broken file
        raise log_error(path, f"not a readable ULog ({exc})", "copy the log from the vehicle again") from None
    corruption = [line.strip() for line in said.getvalue().splitlines()
                  if any(word in line.lower() for word in ULOG_CORRUPTION_WORDS)]
    topics = {d.name: d.data for d in ulog.data_list if d.multi_id == 0}
    end = ulog_end(raw)  # pyulog stops silently where a message runs past the file's end
    for topic in ULOG_TOPICS:
        if topic not in topics and corruption:
            raise log_error(path, shown.ulog_corrupt(corruption[0], topic), "copy the log from the vehicle again")
        if topic not in topics and end:
            raise LogError(f"{path}: {shown.ulog_cut_short(topic=topic, **vars(end))}")
        if topic not in topics:
            raise log_error(path, f"the ULog has no {topic} topic",
                        "log it (SDLOG_PROFILE: system identification) or convert the log to the CSV format")
    if corruption:
        warnings.warn(QuadctlNotice(shown.ulog_read_past_corruption(Path(path).name, corruption[0])), stacklevel=2)
    imu, motors = topics["sensor_combined"], topics["actuator_motors"]
    origin = int(imu["timestamp"][0])  # us; subtracted as integers (a time stamp may be an epoch's 1.7e15 us)
    t = (imu["timestamp"].astype(np.int64) - origin) * 1e-6
    acc = np.column_stack([imu[f"accelerometer_m_s2[{i}]"] for i in range(3)]).astype(float)
    gyro = np.column_stack([imu[f"gyro_rad[{i}]"] for i in range(3)]).astype(float)
    tm = (motors["timestamp"].astype(np.int64) - origin) * 1e-6
    idx = np.clip(np.searchsorted(tm, t, side="right") - 1, 0, tm.size - 1)
    cmd = np.column_stack([np.nan_to_num(motors[f"control[{i}]"].astype(float))[idx] for i in range(4)])
    keep = t >= tm[0]
    if end and np.any(keep):
        warnings.warn(QuadctlNotice(shown.ulog_read_cut_short(Path(path).name, float(t[keep][-1]), **vars(end))),
                      stacklevel=2)
    return checked(path, t[keep], acc[keep], gyro[keep], np.clip(cmd[keep], 0.0, 1.0), "ulog",
                    hashlib.sha256(raw).hexdigest(),
                    ("time: us -> s", "sensor_combined: m/s^2 and rad/s, FRD, as logged",
                     "actuator_motors.control[0..3] held onto the IMU's samples, clipped to [0, 1]"), origin * 1e-6)
