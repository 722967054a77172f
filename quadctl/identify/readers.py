"""Flight-log readers: every format into one :class:`~quadctl.identify.flight_log.FlightLog`.

:func:`read_log` picks the reader: :func:`read_crazyflie` (the microSD deck's binary log, below),
:func:`quadctl.identify.csv_log.read_csv` and :func:`quadctl.identify.ulog.read_ulog` (PX4, through
``pyulog``). The formats are in the docs, docs/guide/identify.md and docs/internals.md ("Identification").
"""

from __future__ import annotations

import hashlib
import math
import os
import struct
import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np

from quadctl.artifacts.places import reason_of
from quadctl.errors import LogError
from quadctl.identify.csv_log import read_csv
from quadctl.identify.flight_log import CSV_COLUMNS, FlightLog, checked, log_error
from quadctl.identify.ulog import read_ulog

STANDARD_GRAVITY = 9.80665
"""m/s^2 per g: the Crazyflie's accelerometer reads in units of g."""
CRAZYFLIE_MAGIC = 0xBC
CRAZYFLIE_PWM_MAX = 65535
CRAZYFLIE_ACC_LOWPASS_HZ = 30.0
CRAZYFLIE_GYRO_LOWPASS_HZ = 80.0
"""Hz: the second-order low-passes (``lpf2p``, at its 1 kHz sensor rate) the Crazyflie's sensor driver runs on
the accelerometer and the gyro before anything reads or logs them (bitcraze/crazyflie-firmware,
src/hal/src/sensors_bmi088_bmp3xx.c ``ACCEL_LPF_CUTOFF_FREQ``, ``GYRO_LPF_CUTOFF_FREQ``; the same in the
other sensor drivers). The accelerometer's lags the logged thrust by about 7.5 ms (sqrt(2) / (2 pi 30 Hz))."""
CRAZYFLIE_EVENT = 0xFFFF
"""The event id of the fixed-frequency records."""
_CRAZYFLIE_TYPES = {"b": "<i1", "B": "<u1", "h": "<i2", "H": "<u2", "i": "<i4", "I": "<u4", "f": "<f4",
                    "q": "<i8", "Q": "<u8", "d": "<f8"}
_CRAZYFLIE_NEEDS = ("acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z",
                    "motor.m1", "motor.m2", "motor.m3", "motor.m4")


def read_crazyflie(path) -> FlightLog:
    """Read a Crazyflie microSD "fixedFrequency" binary log (layout: the module's docstring).

    Converts g to m/s^2 (x 9.80665), deg/s to rad/s, the Crazyflie's FLU body frame to FRD (y and z
    negated) and PWM 0-65535 to [0, 1]; ``motor.m1..m4`` become rotors 1-4 (the Crazyflie's order is
    front right, rear right, rear left, front left: ``motors.numbering: crazyflie``).

    Raises
    ------
    LogError
        Not such a log, truncated, a failed CRC, or a variable missing.
    """
    data = Path(path).read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    if len(data) < 9 or data[0] != CRAZYFLIE_MAGIC:
        raise log_error(path, "not a Crazyflie microSD log (its first byte is not 0xBC)",
                    "give a log the microSD deck wrote, or convert it to the CSV format (quadctl identify --help)")
    body, trailer = data[:-4], data[-4:]
    if zlib.crc32(body) != struct.unpack("<I", trailer)[0]:
        raise log_error(path, "the CRC-32 at the end does not match the log (truncated or corrupted)",
                    "copy the file from the microSD card again; a log cut short has no valid end")
    try:
        events, offset = _crazyflie_header(body)
    except (struct.error, ValueError, UnicodeDecodeError):
        raise log_error(path, "the header of the Crazyflie log is malformed",
                        "copy the file from the card again") from None
    if CRAZYFLIE_EVENT not in events:
        raise log_error(path, "no fixedFrequency records in the log", "log with the microSD deck's fixedFrequency mode")
    names = events[CRAZYFLIE_EVENT]
    missing = [n for n in _CRAZYFLIE_NEEDS if n not in dict(names)]
    if missing:
        raise log_error(path, f"the log has no {', '.join(missing)}",
                    "add them to the microSD deck's config.txt (acc.x, acc.y, acc.z, gyro.x, gyro.y, gyro.z, "
                    "motor.m1 .. motor.m4) and fly again")
    if len(events) > 1:
        raise log_error(path, "event-triggered records besides the fixed-frequency ones",
                    "log the fixedFrequency mode alone, or convert the log to the CSV format")
    dtype = np.dtype([("event", "<u2"), ("us", "<u8")] + [(n, _CRAZYFLIE_TYPES[k]) for n, k in names])
    size = len(body) - offset
    if size % dtype.itemsize:
        raise log_error(path, f"{size} bytes of records is not a whole number of {dtype.itemsize}-byte records",
                    "copy the file from the microSD card again")
    rec = np.frombuffer(body, dtype=dtype, offset=offset)
    if np.any(rec["event"] != CRAZYFLIE_EVENT):
        raise log_error(path, "a record with an unknown event id (the records are misaligned)",
                    "copy the file from the microSD card again")
    t = rec["us"].astype(float) * 1e-6
    flu_to_frd = np.array([1.0, -1.0, -1.0])
    acc = np.column_stack([rec[f"acc.{a}"] for a in "xyz"]).astype(float) * STANDARD_GRAVITY * flu_to_frd
    gyro = np.column_stack([rec[f"gyro.{a}"] for a in "xyz"]).astype(float) * (math.pi / 180.0) * flu_to_frd
    cmd = np.column_stack([rec[f"motor.m{i}"] for i in range(1, 5)]).astype(float) / CRAZYFLIE_PWM_MAX
    log = checked(path, t, acc, gyro, cmd, "crazyflie", digest, (
        "time: us -> s", "acc: g -> m/s^2 (x 9.80665), FLU -> FRD (y, z negated)",
        "gyro: deg/s -> rad/s, FLU -> FRD (q, r negated)", "motor.m1..m4: PWM / 65535 -> cmd_1..cmd_4",
        f"acc and gyro as the firmware logs them, low-passed at {CRAZYFLIE_ACC_LOWPASS_HZ:g} and "
        f"{CRAZYFLIE_GYRO_LOWPASS_HZ:g} Hz (second order): the fit models both"))
    return replace(log, acc_lowpass_hz=CRAZYFLIE_ACC_LOWPASS_HZ, gyro_lowpass_hz=CRAZYFLIE_GYRO_LOWPASS_HZ)


def _crazyflie_header(body: bytes):
    """``({event id: [(variable, type letter), ...]}, offset of the first record)``."""
    (count,) = struct.unpack_from("<H", body, 3)
    offset, events = 5, {}
    for _ in range(count):
        (event,) = struct.unpack_from("<H", body, offset)
        end = body.index(b"\0", offset + 2)
        offset = end + 1
        (n,) = struct.unpack_from("<H", body, offset)
        offset += 2
        names = []
        for _ in range(n):
            end = body.index(b"\0", offset)
            text = body[offset:end].decode("ascii")
            offset = end + 1
            if not (text.endswith(")") and text[-3] == "(" and text[-2] in _CRAZYFLIE_TYPES):
                raise ValueError(text)
            names.append((text[:-3], text[-2]))
        events[event] = names
    return events, offset


def read_log(path, columns: dict[str, str] | None = None) -> FlightLog:
    """Read a log of any supported format, told apart by its first bytes and then its suffix.

    Raises
    ------
    LogError
        The file is missing, empty or of no supported format, or ``columns`` are given for a log that is
        not a CSV.
    """
    p = Path(path)
    if os.path.isdir(p):  # os.path's tests: a name too long for the system is no such file, where Path's raise
        raise LogError(f"{path}: is a folder, not a flight log; give the path of a log file in it")
    if not os.path.exists(p):
        raise LogError(f"{path}: no such file; give the path of a flight log")
    if not os.path.isfile(p):
        raise LogError(f"{path}: not a file (a device or a pipe); give the path of the flight log the vehicle wrote")
    try:
        with open(p, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        raise LogError(f"{path}: cannot read the log ({reason_of(exc)}); check the file") from None
    if not head:
        raise log_error(path, "an empty file", "give the log the vehicle wrote")
    binary = ("a ULog", read_ulog) if head[:7] == b"ULog\x01\x12\x35" else \
        ("a Crazyflie microSD log", read_crazyflie) if head[0] == CRAZYFLIE_MAGIC else None
    if binary and columns:  # its fields are named by its format: a mapping would be silently ignored
        raise LogError(f"{path}: is {binary[0]}, whose fields quadctl reads by their own names: --columns maps "
                       "the columns of a CSV log only; leave it out")
    if binary:
        return binary[1](path)
    if p.suffix.lower() in (".csv", ".txt") or b"," in head:
        return read_csv(path, columns)
    raise log_error(path, "not a Crazyflie microSD log, a ULog nor a CSV",
                f"convert it to a CSV with the columns {', '.join(CSV_COLUMNS)}")
