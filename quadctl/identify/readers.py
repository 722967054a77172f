"""Flight-log readers: every format into one :class:`FlightLog` in SI units and quadctl's frames.

A :class:`FlightLog` holds time (s, from the log's first sample: every reader's ``t`` starts at 0,
and :attr:`FlightLog.clock_at_start` keeps the log's own clock there), the specific force (m/s^2)
and the body rates (rad/s) in the FRD body frame, and the four rotor commands normalized to [0, 1]
in the config's numbering; each reader says what it converted (:attr:`FlightLog.conversions`).
:func:`read_log` picks the reader: :func:`read_crazyflie` (the microSD deck's binary log),
:func:`read_csv` and :func:`read_ulog` (PX4, through ``pyulog``). The formats are in the docs,
docs/guide/identify.md and docs/internals.md ("Identification").
"""

from __future__ import annotations

import codecs
import contextlib
import csv
import hashlib
import io
import math
import struct
import warnings
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from quadctl.errors import LogError, QuadctlNotice
from quadctl.present import identify as shown

STANDARD_GRAVITY = 9.80665
"""m/s^2 per g: the Crazyflie's accelerometer reads in units of g."""
CSV_COLUMNS = ("t", "acc_x", "acc_y", "acc_z", "gyro_p", "gyro_q", "gyro_r", "cmd_1", "cmd_2", "cmd_3", "cmd_4")
"""The CSV's columns (units and frame: the module's docstring)."""
CSV_FILTER_LINE = "# lowpass:"
"""A CSV comment line that says which low-passes the vehicle ran on its sensors before it logged them:
``# lowpass: acc_lowpass_hz=30 gyro_lowpass_hz=80`` (second-order Butterworth cutoffs, Hz), as a Crazyflie's
log written as a CSV carries them (:meth:`FlightLog.to_csv`). Without it a CSV's sensors are as measured."""
CSV_FILTER_KEYS = ("acc_lowpass_hz", "gyro_lowpass_hz")
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
        predicted thrust and torques through the same filter (:mod:`quadctl.identify.estimate`), so that
        the filter's lag is not taken for the rotors'.
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


def _fail(path, what: str, fix: str) -> LogError:
    return LogError(f"{path}: {what}; {fix}")


def _checked(path, t, acc, gyro, cmd, fmt, digest, conversions, clock: float = 0.0) -> FlightLog:
    """The arrays as a FlightLog, after the checks every format shares, its time from the first sample
    (``clock``, s: the log's clock at ``t = 0`` of the given ``t``)."""
    if t.size < 2:
        raise _fail(path, f"{t.size} sample(s), too few to identify anything", "give a log of a flight")
    arrays = {"time": t, "accelerometer": acc, "gyro": gyro, "motor commands": cmd}
    for what, values in arrays.items():
        if not np.all(np.isfinite(values)):
            k = int(np.argwhere(~np.isfinite(np.atleast_2d(values.T).T))[0][0])
            raise _fail(path, f"a non-finite {what} value in sample {k + 1}", "repair or cut the log there")
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        raise _fail(path, f"time does not increase at sample {k + 2} (t = {t[k + 1]:.6g} s after {t[k]:.6g} s)",
                    "sort the samples by time or drop the repeated ones")
    if np.any(cmd < -1e-9) or np.any(cmd > 1 + 1e-9):
        raise _fail(path, f"rotor commands outside [0, 1] (from {cmd.min():.4g} to {cmd.max():.4g})",
                    "normalize the commands to [0, 1] (a PWM 0-65535 divided by 65535)")
    return FlightLog(t=t - t[0], acc=acc, gyro=gyro, cmd=cmd, path=str(path), format=fmt, sha256=digest,
                     conversions=(shown.time_from_start(clock + float(t[0])), *conversions),
                     clock_at_start=clock + float(t[0]))


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
        raise _fail(path, "not a Crazyflie microSD log (its first byte is not 0xBC)",
                    "give a log the microSD deck wrote, or convert it to the CSV format (quadctl identify --help)")
    body, trailer = data[:-4], data[-4:]
    if zlib.crc32(body) != struct.unpack("<I", trailer)[0]:
        raise _fail(path, "the CRC-32 at the end does not match the log (truncated or corrupted)",
                    "copy the file from the microSD card again; a log cut short has no valid end")
    try:
        events, offset = _crazyflie_header(body)
    except (struct.error, ValueError, UnicodeDecodeError):
        raise _fail(path, "the header of the Crazyflie log is malformed", "copy the file from the card again") from None
    if CRAZYFLIE_EVENT not in events:
        raise _fail(path, "no fixedFrequency records in the log", "log with the microSD deck's fixedFrequency mode")
    names = events[CRAZYFLIE_EVENT]
    missing = [n for n in _CRAZYFLIE_NEEDS if n not in dict(names)]
    if missing:
        raise _fail(path, f"the log has no {', '.join(missing)}",
                    "add them to the microSD deck's config.txt (acc.x, acc.y, acc.z, gyro.x, gyro.y, gyro.z, "
                    "motor.m1 .. motor.m4) and fly again")
    if len(events) > 1:
        raise _fail(path, "event-triggered records besides the fixed-frequency ones",
                    "log the fixedFrequency mode alone, or convert the log to the CSV format")
    dtype = np.dtype([("event", "<u2"), ("us", "<u8")] + [(n, _CRAZYFLIE_TYPES[k]) for n, k in names])
    size = len(body) - offset
    if size % dtype.itemsize:
        raise _fail(path, f"{size} bytes of records is not a whole number of {dtype.itemsize}-byte records",
                    "copy the file from the microSD card again")
    rec = np.frombuffer(body, dtype=dtype, offset=offset)
    if np.any(rec["event"] != CRAZYFLIE_EVENT):
        raise _fail(path, "a record with an unknown event id (the records are misaligned)",
                    "copy the file from the microSD card again")
    t = rec["us"].astype(float) * 1e-6
    flu_to_frd = np.array([1.0, -1.0, -1.0])
    acc = np.column_stack([rec[f"acc.{a}"] for a in "xyz"]).astype(float) * STANDARD_GRAVITY * flu_to_frd
    gyro = np.column_stack([rec[f"gyro.{a}"] for a in "xyz"]).astype(float) * (math.pi / 180.0) * flu_to_frd
    cmd = np.column_stack([rec[f"motor.m{i}"] for i in range(1, 5)]).astype(float) / CRAZYFLIE_PWM_MAX
    log = _checked(path, t, acc, gyro, cmd, "crazyflie", digest, (
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


def read_csv(path, columns: dict[str, str] | None = None) -> FlightLog:
    """Read the CSV format (:data:`CSV_COLUMNS`; units and frame: the module's docstring).

    Parameters
    ----------
    columns : dict, optional
        quadctl's column name -> the file's (``{"t": "time_s"}``); the others keep their names.

    Raises
    ------
    LogError
        A column missing, a value that is not a number.
    """
    columns = dict(columns or {})
    unknown = sorted(set(columns) - set(CSV_COLUMNS))
    if unknown:
        raise LogError(f"--columns names {', '.join(unknown)}, not a column of the CSV format; "
                       f"map these: {', '.join(CSV_COLUMNS)}")
    raw = Path(path).read_bytes()
    # a byte order mark: UTF-8's is Excel's "CSV UTF-8"; UTF-16's its "Unicode Text" and some loggers' exports
    utf16 = raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE))
    text = raw.decode("utf-16" if utf16 else "utf-8-sig", errors="replace").splitlines()
    lines = [line for line in text if line.strip() and not line.lstrip().startswith("#")]
    filters = _csv_filters(path, [line.strip() for line in text if line.strip().startswith(CSV_FILTER_LINE)])
    if not lines:
        raise _fail(path, "an empty CSV", f"write a header line with {', '.join(CSV_COLUMNS)} and the samples")
    header = [h.strip() for h in next(csv.reader(lines[:1]))]
    other = next((sep for sep in (";", "\t") if len(header) == 1 and sep in lines[0]), None)
    if other is not None:  # a spreadsheet's export where the comma is the decimal mark
        raise _fail(path, f"its columns are separated by {'a semicolon' if other == ';' else 'tabs'}, not commas",
                    "save it with commas between the values and a point as the decimal mark")
    where = {}
    for name in CSV_COLUMNS:
        given = columns.get(name, name)
        if given not in header:
            via = f" (mapped from {name})" if name in columns else ""
            raise _fail(path, f"no column {given!r}{via} (the header has {', '.join(header)})",
                        f"rename the column or map it: --columns {name}=YOUR_NAME")
        where[name] = header.index(given)
    try:  # no data lines: no samples (loadtxt would warn, on stderr, before the one line that says so)
        values = (np.loadtxt(lines[1:], delimiter=",", usecols=[where[n] for n in CSV_COLUMNS], ndmin=2)
                  if lines[1:] else np.empty((0, len(CSV_COLUMNS))))
    except (ValueError, IndexError):
        rows = csv.reader(lines[1:])
        bad = next((i for i, row in enumerate(rows) if not _numeric_row(row, where.values())), 0)
        raise _fail(path, f"data line {bad + 1} is not {len(header)} numbers", "repair or remove that line") from None
    values = values.reshape(-1, len(CSV_COLUMNS))
    _check_gravity(path, values[:, 3])
    said = tuple(f"{k.split('_')[0]} low-passed at {v:g} Hz (second order) before it was logged, as the CSV's "
                 f"{CSV_FILTER_LINE!r} line says: the fit models it" for k, v in filters.items())
    log = _checked(path, values[:, 0], values[:, 1:4], values[:, 4:7], values[:, 7:11], "csv",
                   hashlib.sha256(raw).hexdigest(),
                   ("as written: s, m/s^2 and rad/s in FRD, commands in [0, 1]", *said))
    _check_time_unit(path, log.t)
    return replace(log, **filters)


def _csv_filters(path, lines) -> dict[str, float]:
    """The low-passes a CSV's :data:`CSV_FILTER_LINE` lines give: ``{key: Hz}``.

    Raises
    ------
    LogError
        A key that is not one of :data:`CSV_FILTER_KEYS`, or a value that is not a positive number.
    """
    out = {}
    for line in lines:
        for item in line[len(CSV_FILTER_LINE):].split():
            key, eq, value = item.partition("=")
            try:
                hz = float(value) if eq and key in CSV_FILTER_KEYS else None
            except ValueError:
                hz = None
            if hz is None or not math.isfinite(hz) or hz <= 0:
                keys = ", ".join(CSV_FILTER_KEYS)
                raise _fail(path, f"{CSV_FILTER_LINE} {item!r} is not KEY=HZ with a key of {keys} and a positive "
                                  "cutoff", f"write e.g. {CSV_FILTER_LINE} acc_lowpass_hz=30 gyro_lowpass_hz=80, or "
                                  "remove the line")
            out[key] = hz
    return out


def _check_gravity(path, acc_z) -> None:
    """Refuse a CSV whose ``acc_z`` is not about -g most of the time, as a resting or hovering accelerometer
    reads in FRD m/s^2: about -1 or +1 is g (a Crazyflie logs g), about +9.8 a z axis up (FLU). Either fitted
    a thrust curve 9.8 times too small, or negative, and the refusal blamed the config's mass."""
    if acc_z.size == 0:
        return
    median = float(np.median(acc_z))
    to_frd = "negate acc_y, acc_z, gyro_q and gyro_r for FRD (-9.81 on acc_z at rest or hover)"  # z up (FLU)
    if 0.4 < abs(median) < 2.5:
        raise _fail(path, f"acc_z reads {median:.3g} at its median, about {'-' if median < 0 else '+'}1: the "
                    "accelerometer in g, not m/s^2", "multiply acc_x, acc_y, acc_z by 9.80665" +
                    ("" if median < 0 else f", and {to_frd}"))
    if median > 4.9:
        raise _fail(path, f"acc_z reads {median:.3g} m/s^2 at its median, about +g: its z axis points up (FLU), "
                    "not down", to_frd)


def _check_time_unit(path, t) -> None:
    """Refuse a CSV whose ``t`` steps, at its median, by more than a dropped sensor's gap
    (:data:`quadctl.identify.windows.SENSOR_GAP`): every sample would be a gap. A flight log's IMU is sampled
    at 100 Hz or more, so such a ``t`` is in ms or µs, not s; the fit read it as a dropped sensor."""
    from quadctl.identify.windows import SENSOR_GAP

    steps = np.diff(t)
    if steps.size == 0 or not np.all(np.isfinite(steps)):
        return
    step = float(np.median(steps))
    if step <= SENSOR_GAP:
        return
    if step < 0.5:  # 2 to 50 samples a second: a coarse log in s, not another unit (a 1 kHz IMU in ms steps by 1)
        raise _fail(path, f"t steps by {step:.3g} s at its median, {1 / step:.3g} samples a second: every step is "
                          f"longer than a dropped sensor's gap ({SENSOR_GAP * 1e3:g} ms), too coarse to resolve the "
                          "rotors' lag", "give the log at the rate its IMU samples (100 Hz or more)")
    # an IMU's 100 Hz to 10 kHz steps by 0.1 to 10 in ms, by 100 to 10 000 in µs; between, a slow log in ms (which
    # the check then finds too coarse) is likelier than one past 10 kHz in µs
    unit, factor = ("µs", "1e6") if step >= 100.0 else ("ms", "1000")
    raise _fail(path, f"t steps by {step:.3g} at its median, {1 / step:.3g} samples a second if t is in s, where a "
                      f"flight log's IMU gives 100 or more: t looks in {unit}",
                f"divide t by {factor} (the CSV's t is in s)")


def _numeric_row(row, indices) -> bool:
    try:
        [float(row[i]) for i in indices]
    except (ValueError, IndexError):
        return False
    return True


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
        raise _fail(path, f"not a readable ULog ({exc})", "copy the log from the vehicle again") from None
    corruption = [line.strip() for line in said.getvalue().splitlines()
                  if any(word in line.lower() for word in ULOG_CORRUPTION_WORDS)]
    topics = {d.name: d.data for d in ulog.data_list if d.multi_id == 0}
    end = ulog_end(raw)  # pyulog stops silently where a message runs past the file's end
    for topic in ULOG_TOPICS:
        if topic not in topics and corruption:
            raise _fail(path, shown.ulog_corrupt(corruption[0], topic), "copy the log from the vehicle again")
        if topic not in topics and end:
            raise LogError(f"{path}: {shown.ulog_cut_short(topic=topic, **vars(end))}")
        if topic not in topics:
            raise _fail(path, f"the ULog has no {topic} topic",
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
    return _checked(path, t[keep], acc[keep], gyro[keep], np.clip(cmd[keep], 0.0, 1.0), "ulog",
                    hashlib.sha256(raw).hexdigest(),
                    ("time: us -> s", "sensor_combined: m/s^2 and rad/s, FRD, as logged",
                     "actuator_motors.control[0..3] held onto the IMU's samples, clipped to [0, 1]"), origin * 1e-6)


def read_log(path, columns: dict[str, str] | None = None) -> FlightLog:
    """Read a log of any supported format, told apart by its first bytes and then its suffix.

    Raises
    ------
    LogError
        The file is missing, empty or of no supported format, or ``columns`` are given for a log that is
        not a CSV.
    """
    p = Path(path)
    if p.is_dir():
        raise LogError(f"{path}: is a folder, not a flight log; give the path of a log file in it")
    if not p.is_file():
        raise LogError(f"{path}: no such file; give the path of a flight log")
    with open(p, "rb") as fh:
        head = fh.read(8)
    if not head:
        raise _fail(path, "an empty file", "give the log the vehicle wrote")
    binary = ("a ULog", read_ulog) if head[:7] == b"ULog\x01\x12\x35" else \
        ("a Crazyflie microSD log", read_crazyflie) if head[0] == CRAZYFLIE_MAGIC else None
    if binary and columns:  # its fields are named by its format: a mapping would be silently ignored
        raise LogError(f"{path}: is {binary[0]}, whose fields quadctl reads by their own names: --columns maps "
                       "the columns of a CSV log only; leave it out")
    if binary:
        return binary[1](path)
    if p.suffix.lower() in (".csv", ".txt") or b"," in head:
        return read_csv(path, columns)
    raise _fail(path, "not a Crazyflie microSD log, a ULog nor a CSV",
                f"convert it to a CSV with the columns {', '.join(CSV_COLUMNS)}")


def parse_columns(items) -> dict[str, str]:
    """``["t=time", "cmd_1=m1"]`` -> ``{"t": "time", "cmd_1": "m1"}`` (the ``--columns`` option).

    Raises
    ------
    LogError
        An item without ``=``.
    """
    out = {}
    for item in items or ():
        for part in item.split(","):
            name, eq, given = part.partition("=")
            if not eq or not name.strip() or not given.strip():
                raise LogError(f"--columns {part!r} is not NAME=COLUMN; write e.g. --columns t=time_s,cmd_1=m1")
            out[name.strip()] = given.strip()
    return out
