"""The CSV flight-log format (:data:`~quadctl.identify.flight_log.CSV_COLUMNS`: s, m/s^2 and rad/s in FRD,
rotor commands in [0, 1]), what a spreadsheet makes of it, and ``--columns``, which maps a file's own names."""

from __future__ import annotations

import codecs
import csv
import hashlib
import itertools
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from quadctl.errors import LogError
from quadctl.identify.flight_log import CSV_COLUMNS, CSV_FILTER_KEYS, CSV_FILTER_LINE, FlightLog, checked, log_error


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
        raise log_error(path, "an empty CSV", f"write a header line with {', '.join(CSV_COLUMNS)} and the samples")
    header = [h.strip() for h in next(csv.reader(lines[:1]))]
    other = next((sep for sep in (";", "\t") if len(header) == 1 and sep in lines[0]), None)
    if other is not None:  # a spreadsheet's export where the comma is the decimal mark
        raise log_error(path, f"its columns are separated by {'a semicolon' if other == ';' else 'tabs'}, not commas",
                    "save it with commas between the values and a point as the decimal mark")
    where = {}
    for name in CSV_COLUMNS:
        given = columns.get(name, name)
        if given not in header:
            via = f" (mapped from {name})" if name in columns else ""
            raise log_error(path, f"no column {given!r}{via} (the header has {', '.join(header)})",
                        f"rename the column or map it: --columns {name}=YOUR_NAME")
        where[name] = header.index(given)
    shared = next(((a, b) for a, b in itertools.combinations(CSV_COLUMNS, 2) if where[a] == where[b]), None)
    if shared:  # --columns acc_x=acc_y: acc_y read twice, and acc_x's own column nowhere, without a word
        a, b = shared
        raise LogError(f"--columns reads {a} and {b} from the one column {header[where[a]]!r} of {path}; "
                       f"map each to a column of its own")
    # a line with more values than the header names (a value split in two by a thousands separator, a
    # column added mid-file) would be read shifted, or its extra values dropped, without a word
    ragged = next((i for i, line in enumerate(lines[1:]) if line.count(",") != len(header) - 1), None)
    if ragged is not None:
        raise log_error(path, f"data line {ragged + 1} is not {len(header)} numbers (it has "
                              f"{lines[ragged + 1].count(',') + 1} values)", "repair or remove that line")
    try:  # no data lines: no samples (loadtxt would warn, on stderr, before the one line that says so)
        values = (np.loadtxt(lines[1:], delimiter=",", usecols=[where[n] for n in CSV_COLUMNS], ndmin=2)
                  if lines[1:] else np.empty((0, len(CSV_COLUMNS))))
    except (ValueError, IndexError):
        rows = csv.reader(lines[1:])
        bad = next((i for i, row in enumerate(rows) if not _numeric_row(row, where.values())), 0)
        raise log_error(path, f"data line {bad + 1} is not {len(header)} numbers",
                        "repair or remove that line") from None
    values = values.reshape(-1, len(CSV_COLUMNS))
    _check_gravity(path, values[:, 3])
    said = tuple(f"{k.split('_')[0]} low-passed at {v:g} Hz (second order) before it was logged, as the CSV's "
                 f"{CSV_FILTER_LINE!r} line says: the fit models it" for k, v in filters.items())
    log = checked(path, values[:, 0], values[:, 1:4], values[:, 4:7], values[:, 7:11], "csv",
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
                raise log_error(path, f"{CSV_FILTER_LINE} {item!r} is not KEY=HZ with a key of {keys} and a positive "
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
        raise log_error(path, f"acc_z reads {median:.3g} at its median, about {'-' if median < 0 else '+'}1: the "
                    "accelerometer in g, not m/s^2", "multiply acc_x, acc_y, acc_z by 9.80665" +
                    ("" if median < 0 else f", and {to_frd}"))
    if median > 4.9:
        raise log_error(path, f"acc_z reads {median:.3g} m/s^2 at its median, about +g: its z axis points up (FLU), "
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
        raise log_error(path, f"t steps by {step:.3g} s at its median, {1 / step:.3g} samples a second: every step is "
                          f"longer than a dropped sensor's gap ({SENSOR_GAP * 1e3:g} ms), too coarse to resolve the "
                          "rotors' lag", "give the log at the rate its IMU samples (100 Hz or more)")
    # an IMU's 100 Hz to 10 kHz steps by 0.1 to 10 in ms, by 100 to 10 000 in µs; between, a slow log in ms (which
    # the check then finds too coarse) is likelier than one past 10 kHz in µs
    unit, factor = ("µs", "1e6") if step >= 100.0 else ("ms", "1000")
    raise log_error(path, f"t steps by {step:.3g} at its median, {1 / step:.3g} samples a second if t is in s, where a "
                      f"flight log's IMU gives 100 or more: t looks in {unit}",
                f"divide t by {factor} (the CSV's t is in s)")


def _numeric_row(row, indices) -> bool:
    try:
        [float(row[i]) for i in indices]
    except (ValueError, IndexError):
        return False
    return True


def parse_columns(items) -> dict[str, str]:
    """``["t=time", "cmd_1=m1"]`` -> ``{"t": "time", "cmd_1": "m1"}`` (the ``--columns`` option).

    Raises
    ------
    LogError
        An item without ``=``, or a name mapped to two columns.
    """
    out = {}
    for item in items or ():
        for part in item.split(","):
            name, eq, given = part.partition("=")
            if not eq or not name.strip() or not given.strip():
                raise LogError(f"--columns {part!r} is not NAME=COLUMN; write e.g. --columns t=time_s,cmd_1=m1")
            name, given = name.strip(), given.strip()
            if out.get(name, given) != given:  # the later would win without a word
                raise LogError(f"--columns maps {name} twice, to {out[name]} and to {given}; give each NAME once")
            out[name] = given
    return out
