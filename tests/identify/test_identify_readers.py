"""Flight-log readers: the Crazyflie microSD binary log, the CSV format, units and frames, bad input."""

from __future__ import annotations

import math
import os
import struct
import warnings
import zlib

import numpy as np
import pytest
from _paths import DATA

from quadctl.errors import LogError
from quadctl.identify.csv_log import parse_columns, read_csv
from quadctl.identify.flight_log import CSV_COLUMNS, FlightLog
from quadctl.identify.readers import read_crazyflie, read_log

FLIGHTS = DATA / "crazyflie-flights"


def crazyflie_bytes(records, names=("acc.x(f)", "acc.y(f)", "acc.z(f)", "gyro.x(f)", "gyro.y(f)", "gyro.z(f)",
                                    "motor.m1(I)", "motor.m2(I)", "motor.m3(I)", "motor.m4(I)"), crc=True):
    """A microSD log written from the format's description (independent of the reader)."""
    head = bytes([0xBC]) + struct.pack("<HH", 2, 1) + struct.pack("<H", 0xFFFF) + b"fixedFrequency\0"
    head += struct.pack("<H", len(names)) + b"".join(n.encode() + b"\0" for n in names)
    fmt = "<HQ" + "".join(n[-2] for n in names)
    body = head + b"".join(struct.pack(fmt, 0xFFFF, *rec) for rec in records)
    return body + struct.pack("<I", zlib.crc32(body) if crc else zlib.crc32(body) ^ 1)


@pytest.fixture(scope="module")
def log10():
    return read_crazyflie(FLIGHTS / "log10")


def test_crazyflie_log_sizes_and_rate(log10):
    assert log10.t.size == 50496
    assert log10.t[0] == 0 and log10.clock_at_start == pytest.approx(26.333702)  # t from the first sample
    assert 1000 < log10.provenance()["rate_hz"] < 1020
    assert log10.sha256 == __import__("hashlib").sha256((FLIGHTS / "log10").read_bytes()).hexdigest()


def test_crazyflie_log_on_the_ground_reads_minus_g_and_no_rates(log10):
    """Before take-off (motors off) the FRD accelerometer reads (0, 0, -g) and the gyro nothing."""
    ground = log10.cmd.max(axis=1) == 0
    ground[log10.t + log10.clock_at_start > 30] = False
    assert ground.sum() > 3000
    assert np.median(log10.acc[ground], axis=0) == pytest.approx([0, 0, -9.81], abs=0.2)
    assert np.abs(np.median(log10.gyro[ground], axis=0)).max() < 0.01


@pytest.mark.parametrize("acc, gyro, pwm, want_acc, want_gyro", [
    ((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0, 0, 0, 0), (0.0, 0.0, -9.80665), (0.0, 0.0, 0.0)),
    ((0.5, 0.25, 0.0), (90.0, 45.0, -180.0), (65535, 0, 32768, 1), (4.903325, -2.4516625, 0.0),
     (math.pi / 2, -math.pi / 4, math.pi)),
])
def test_crazyflie_units_and_frame(tmp_path, acc, gyro, pwm, want_acc, want_gyro):
    """g -> m/s^2, deg/s -> rad/s, FLU (y left, z up) -> FRD, PWM 0-65535 -> [0, 1]."""
    path = tmp_path / "log"
    path.write_bytes(crazyflie_bytes([(1000, *acc, *gyro, *pwm), (2000, *acc, *gyro, *pwm)]))
    log = read_crazyflie(path)
    assert log.t == pytest.approx([0.0, 1e-3]) and log.clock_at_start == pytest.approx(1e-3)  # us -> s, from the start
    assert log.acc[0] == pytest.approx(want_acc, rel=1e-6, abs=1e-9)
    assert log.gyro[0] == pytest.approx(want_gyro, rel=1e-6, abs=1e-9)
    assert log.cmd[0] == pytest.approx(np.array(pwm) / 65535)


def test_csv_written_from_the_binary_log_reads_back_the_same(tmp_path, log10):
    path = tmp_path / "log10.csv"
    log10.to_csv(path)
    back = read_log(path)
    assert back.format == "csv"
    for name in ("t", "acc", "gyro", "cmd"):
        np.testing.assert_array_equal(getattr(back, name), getattr(log10, name))


def test_a_csv_saved_by_a_spreadsheet_with_a_byte_order_mark_and_crlf_reads_the_same(tmp_path, log10):
    """Excel's "CSV UTF-8" opens with a byte order mark: the header's first name read as '\\ufefft', and the
    log was refused, "no column 't' (the header has \\ufefft, ...)", with a --columns fix no one can type."""
    plain = tmp_path / "plain.csv"
    log10.to_csv(plain)
    excel = tmp_path / "excel.csv"
    excel.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes().replace(b"\n", b"\r\n"))
    back = read_log(excel)
    for name in ("t", "acc", "gyro", "cmd"):
        np.testing.assert_array_equal(getattr(back, name), getattr(log10, name))


def test_a_utf16_csv_reads_the_same(tmp_path, log10):
    """A CSV saved as UTF-16 with its byte order mark (Excel's "Unicode Text", some loggers' exports) read as
    UTF-8: every other byte a NUL, refused for "no column 't' (the header has \ufffd\ufffdt\x00,\x00a..."."""
    plain = tmp_path / "plain.csv"
    log10.to_csv(plain)
    wide = tmp_path / "wide.csv"
    wide.write_bytes(plain.read_text().encode("utf-16"))
    back = read_log(wide)
    for name in ("t", "acc", "gyro", "cmd"):
        np.testing.assert_array_equal(getattr(back, name), getattr(log10, name))
    assert (back.acc_lowpass_hz, back.gyro_lowpass_hz) == (30.0, 80.0)


def test_csv_columns_mapped(tmp_path):
    names = ["time", *CSV_COLUMNS[1:]]
    path = tmp_path / "renamed.csv"
    path.write_text(",".join(names) + "\n0,0,0,-9.81,0,0,0,0.5,0.5,0.5,0.5\n0.001,0,0,-9.81,0,0,0,0.5,0.5,0.5,0.6\n")
    log = read_csv(path, parse_columns(["t=time"]))
    assert log.cmd[1, 3] == 0.6 and log.t[1] == 0.001


def test_two_names_mapped_onto_one_column_are_refused(tmp_path):
    """--columns acc_x=acc_y read acc_y as both axes and the file's acc_x nowhere, without a word."""
    path = tmp_path / "x.csv"
    path.write_text(",".join(CSV_COLUMNS) + "\n0,0,0,-9.81,0,0,0,0.5,0.5,0.5,0.5\n")
    with pytest.raises(LogError, match=r"^--columns reads acc_x and acc_y from the one column 'acc_y' of \S*x.csv; "
                                       r"map each to a column of its own$"):
        read_csv(path, parse_columns(["acc_x=acc_y"]))


@pytest.mark.parametrize("damage, match", [
    (lambda b: b[: len(b) // 2], r"log: the CRC-32 at the end does not match .*copy the file"),
    (lambda b: b[:500] + bytes([b[500] ^ 0xFF]) + b[501:], r"log: the CRC-32 .*truncated or corrupted"),
    (lambda b: b"\x00" + b[1:], r"log: not a Crazyflie microSD log, a ULog nor a CSV; convert it"),
    (lambda b: b"", r"log: an empty file"),
])
def test_damaged_crazyflie_log_refused(tmp_path, damage, match):
    good = crazyflie_bytes([(1000 * k, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0) for k in range(1, 50)])
    path = tmp_path / "log"
    path.write_bytes(damage(good))
    with pytest.raises(LogError, match=match):
        read_log(path)


@pytest.mark.parametrize("name, text, match", [
    ("x.csv", ",".join(CSV_COLUMNS) + "\n", r"x.csv: 0 sample\(s\), too few to identify anything; give a log"),
    ("x.csv", ",".join(CSV_COLUMNS) + "\n\n  \n# a comment\n", r"x.csv: 0 sample\(s\), too few"),
    ("x.csv", "", r"x.csv: an empty file; give the log"),
    ("log", crazyflie_bytes([]), r"log: 0 sample\(s\), too few"),
])
def test_a_log_without_samples_is_one_error_and_no_warning(tmp_path, name, text, match):
    """A header and no data (blank and comment lines are no data): the reader's error alone, no library warning
    printed before it (a warning here is raised, and is not the LogError)."""
    path = tmp_path / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(LogError, match=match):
            read_log(path)


def test_crazyflie_log_without_the_motors_refused(tmp_path):
    names = ("acc.x(f)", "acc.y(f)", "acc.z(f)", "gyro.x(f)", "gyro.y(f)", "gyro.z(f)")
    path = tmp_path / "log"
    path.write_bytes(crazyflie_bytes([(1000, 0, 0, 1, 0, 0, 0), (2000, 0, 0, 1, 0, 0, 0)], names=names))
    with pytest.raises(LogError, match=r"no motor.m1, motor.m2, motor.m3, motor.m4; add them to the microSD"):
        read_log(path)


@pytest.mark.parametrize("text, match", [
    ("t,acc_x,acc_y,acc_z,gyro_p,gyro_q,gyro_r,cmd_1,cmd_2,cmd_3\n0,0,0,0,0,0,0,0,0,0\n",
     r"x.csv: no column 'cmd_4' .*--columns cmd_4=YOUR_NAME"),
    (",".join(CSV_COLUMNS) + "\n0,0,0,0,0,0,0,0,0,0,0\n0.1,0,0,0,0,0,0,0,x,0,0\n", r"x.csv: data line 2 is not"),
    (",".join(CSV_COLUMNS) + "\n0,0,0,0,0,0,0,0,0,0,0\n0,0,0,0,0,0,0,0,0,0,0\n", r"time does not increase at sample 2"),
    (",".join(CSV_COLUMNS) + "\n0,0,0,0,0,0,0,0,0,0,0\n0.1,0,0,0,0,0,0,0,0.5,0,0,7\n",
     r"x.csv: data line 2 is not 11 numbers \(it has 12 values\); repair or remove that line"),
    (",".join(CSV_COLUMNS) + "\n0,0,0,0,0,0,0,0,0,0,0\n0.1,0,0,0,0,0,0,0,0.5,0\n",
     r"x.csv: data line 2 is not 11 numbers \(it has 10 values\)"),
    (";".join(CSV_COLUMNS) + "\n0;0;0;0;0;0;0;0;0;0;0\n", r"^\S*x.csv: its columns are separated by a semicolon, not "
                                                        r"commas; save it with commas between the values and a point"),
    ("\t".join(CSV_COLUMNS) + "\n0\t0\t0\t0\t0\t0\t0\t0\t0\t0\t0\n", r"x.csv: its columns are separated by tabs"),
    ("# lowpass: acc_lowpass_hz=-30\n" + ",".join(CSV_COLUMNS) + "\n0,0,0,-9.8,0,0,0,0,0,0,0\n",
     r"x.csv: # lowpass: 'acc_lowpass_hz=-30' is not KEY=HZ with a key of acc_lowpass_hz, gyro_lowpass_hz and a "
     r"positive cutoff; write e.g."),
    (",".join(CSV_COLUMNS) + "\n0,0,0,0,0,0,0,0,0,0,0\n1,0,0,0,0,0,0,300,0,0,0\n", r"outside \[0, 1\].*65535"),
])
def test_bad_csv_refused(tmp_path, text, match):
    path = tmp_path / "x.csv"
    path.write_text(text)
    with pytest.raises(LogError, match=match):
        read_log(path)


@pytest.mark.parametrize("factor, match", [
    (1e3, r"x.csv: t steps by 0.989 at its median, 1.01 samples a second if t is in s, where a flight log's IMU "
          r"gives 100 or more: t looks in ms; divide t by 1000 \(the CSV's t is in s\)$"),
    (1e6, r"x.csv: t steps by 989 at its median, .*: t looks in µs; divide t by 1e6"),
    (50.0, r"x.csv: t steps by 0.0495 s at its median, 20.2 samples a second: every step is longer than a dropped "
           r"sensor's gap \(20 ms\), too coarse to resolve the rotors' lag; give the log at the rate its IMU samples"),
])
def test_a_csv_time_in_ms_or_too_coarse_is_refused_with_the_unit(tmp_path, log10, factor, match):
    """A CSV's t in ms (a 1 kHz log stepping by 1) read as s made every sample a dropped sensor: identify said
    "no samples for 5.98e+03 ms at t = 4.222e+04 s (a dropped sensor)" and blamed the excitation."""
    path = tmp_path / "x.csv"
    FlightLog(**{**log10.__dict__, "t": log10.t * factor}).to_csv(path)
    with pytest.raises(LogError, match=match):
        read_log(path)


def test_a_slow_csv_in_ms_is_not_told_to_divide_by_a_million(tmp_path, log10):
    """A 40 Hz log in ms steps by 25: it was read as µs ("divide t by 1e6"), and so divided it passed as a 40 kHz
    log. In ms it is 40 samples a second, too coarse, which the check says once t is divided by 1000."""
    path = tmp_path / "x.csv"
    every = slice(None, None, 25)
    slow = {**log10.__dict__, "t": log10.t[every], "acc": log10.acc[every], "gyro": log10.gyro[every],
            "cmd": log10.cmd[every]}
    FlightLog(**{**slow, "t": slow["t"] * 1e3}).to_csv(path)
    with pytest.raises(LogError, match=r"x.csv: t steps by 24.7 at its median, .*: t looks in ms; divide t by 1000"):
        read_log(path)
    FlightLog(**slow).to_csv(path)
    with pytest.raises(LogError, match=r"x.csv: t steps by 0.0247 s at its median, .* too coarse"):
        read_log(path)


@pytest.mark.parametrize("scale, flip, match", [
    (1 / 9.80665, 1, r"x.csv: acc_z reads -0.99 at its median, about -1: the accelerometer in g, not m/s\^2; multiply"),
    (1 / 9.80665, -1, r"about \+1: the accelerometer in g.*and negate acc_y, acc_z, gyro_q and gyro_r for FRD"),
    (1.0, -1, r"acc_z reads 9.71 m/s\^2 at its median, about \+g: its z axis points up \(FLU\), not down; negate"),
])
def test_a_csv_accelerometer_in_g_or_with_z_up_is_refused(tmp_path, log10, scale, flip, match):
    """log10 written as a CSV in g (the Crazyflie's own unit) was fitted: a thrust curve 9.8 times too small,
    refused for the config's mass; with z up, a negative one. Each is the CSV's unit or axis, said so."""
    path = tmp_path / "x.csv"
    FlightLog(**{**log10.__dict__, "acc": log10.acc * scale * np.array([1, flip, flip])}).to_csv(path)
    with pytest.raises(LogError, match=match):
        read_log(path)


@pytest.mark.parametrize("sensor, value, match", [
    ("acc", 1e308, r"x.csv: accelerometer value 1e\+308 m/s\^2 in sample 5001, beyond any IMU's range "
                   r"\(±10000 m/s\^2\)"),
    ("gyro", -2000.0, r"x.csv: gyro value -2000 rad/s in sample 5001, beyond any IMU's range \(±1000 rad/s\); .*units"),
])
def test_a_sample_no_imu_reads_is_refused(tmp_path, log10, sensor, value, match):
    """One corrupt accelerometer sample of 1e308 m/s^2 was fitted, NumPy's overflow warning printed and exit 0;
    a gyro column in deg/s read as rad/s reaches 2000. Either is one line naming the sample."""
    path = tmp_path / "x.csv"
    bad = getattr(log10, sensor).copy()
    bad[5000, 0] = value
    FlightLog(**{**log10.__dict__, sensor: bad}).to_csv(path)
    with pytest.raises(LogError, match=match):
        read_log(path)


def test_columns_option_refuses_unknown_names(tmp_path):
    with pytest.raises(LogError, match=r"--columns 'tee' is not NAME=COLUMN"):
        parse_columns(["tee"])
    with pytest.raises(LogError, match=r"^--columns maps cmd_1 twice, to m1 and to m2; give each NAME once$"):
        parse_columns(["cmd_1=m1", "t=time,cmd_1=m2"])
    assert parse_columns(["cmd_1=m2,cmd_2=m1", "cmd_1=m2"]) == {"cmd_1": "m2", "cmd_2": "m1"}  # a swap; a repeat
    path = tmp_path / "x.csv"
    path.write_text(",".join(CSV_COLUMNS) + "\n")
    with pytest.raises(LogError, match=r"--columns names time, not a column of the CSV format"):
        read_csv(path, {"time": "t"})


ULOG = DATA / "px4-ulog" / "sample_px4_events.ulg"


def test_ulog_read_through_pyulog():
    pytest.importorskip("pyulog")
    log = read_log(ULOG)
    assert log.format == "ulog" and log.t.size > 7000
    assert np.all(np.diff(log.t) > 0)
    assert np.median(log.acc, axis=0) == pytest.approx([0, 0, -9.81], abs=0.2)  # FRD, as PX4 logs it
    flying = log.cmd.mean(axis=1) > 0.3
    assert flying.sum() > 1000 and np.median(log.acc[flying, 2]) == pytest.approx(-9.81, abs=0.5)  # hover
    assert 0.4 < np.median(log.cmd[flying]) < 0.7


def test_ulog_without_pyulog_says_how_to_install(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "pyulog", None)
    with pytest.raises(LogError, match=r"sample_px4_events.ulg: reading a ULog needs the pyulog package; pip install"):
        read_log(ULOG)


def test_a_truncated_ulog_is_said_to_be_truncated_and_pyulog_prints_nothing(tmp_path, capsys):
    """Cut inside its definitions, pyulog prints "File corruption detected ..." and reads no topic."""
    pytest.importorskip("pyulog")
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(ULOG.read_bytes()[:20000])
    with pytest.raises(LogError, match=r"cut.ulg: the ULog is truncated or corrupt \(pyulog: File corruption detected"
                                       r".*\), so its sensor_combined topic cannot be read; copy the log"):
        read_log(cut)
    assert capsys.readouterr().out == ""  # stdout is --json's


def _ulog_messages(*messages):
    """A ULog's bytes from the file format's description (independent of pyulog and the reader): the 16-byte
    header, then each ``(type letter, payload)`` as a uint16 payload size, the letter and the payload."""
    out = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0)
    return out + b"".join(struct.pack("<HB", len(p), ord(k)) + p for k, p in messages)


def _boundaries(raw):
    pos, ends = 16, []
    while pos < len(raw):
        pos += 3 + struct.unpack_from("<H", raw, pos)[0]
        ends.append(pos)
    return ends


def test_a_ulog_is_complete_only_where_a_message_of_its_data_section_ends():
    """Cut at every byte: whole (None) only at a message's end after the data section began; elsewhere where it
    stops, inside which message, how many bytes it declares."""
    from quadctl.identify.ulog import ulog_end

    flags = bytes(16) + struct.pack("<3Q", 0, 0, 0)
    raw = _ulog_messages(("B", flags), ("F", b"imu:uint64_t timestamp;float x;"), ("I", b"\x0bchar[3] ver" + b"1.0"),
                         ("A", b"\x00\x01\x00imu"), ("D", b"\x01\x00" + bytes(12)), ("D", b"\x01\x00" + bytes(12)))
    ends = _boundaries(raw)
    data_at = ends[2]  # the subscription "A" opens the data section
    for n in range(16, len(raw) + 1):
        end = ulog_end(raw[:n])
        assert (end is None) == (n in ends and n > data_at), n
        if end is None:
            continue
        assert end.size == n and end.data_at == (data_at if n >= data_at + 3 else None), n  # its type letter read
        inside = [a for a, b in zip([16, *ends], ends) if a < n < b]
        assert end.at == (inside[0] if inside else None), n
        assert end.declared == (struct.unpack_from("<H", raw, end.at)[0] if inside and n - end.at >= 3 else None)


def test_a_ulog_with_data_appended_after_a_crash_is_walked_from_the_appended_data():
    """The part before the flag bits' appended offset may stop inside a message (the format allows it)."""
    from quadctl.identify.ulog import ulog_end

    head = _ulog_messages(("B", bytes(56)), ("A", b"\x00\x01\x00imu"), ("D", b"\x01\x00" + bytes(12)))
    broken = head[:-5]  # the logger stopped inside this message
    appended = struct.pack("<HB", 14, ord("D")) + b"\x01\x00" + bytes(12)
    flags = bytes(16) + struct.pack("<3Q", len(broken), 0, 0)
    raw = broken[:19] + flags + broken[19 + 40:] + appended
    assert ulog_end(raw) is None and ulog_end(raw[:-1]).at == len(broken)


@pytest.mark.parametrize("size, said", [
    (5000, r"it ends after 5000 bytes, inside the message at byte 4217, which declares 844 bytes and has 780 \(64 "
           r"missing\), before its data section begins, so it holds no sensor_combined samples"),
    (4217, r"it ends after 4217 bytes, before its data section begins, so it holds no sensor_combined samples"),
    (16, r"it ends after 16 bytes, before its data section begins"),
])
def test_a_ulog_cut_short_before_its_data_is_said_so_not_sent_to_a_logging_profile(tmp_path, size, said):
    """pyulog reads these without a word of corruption: no topic, and the file ends inside a message or before
    any data. The fix is the whole file, not a logging profile."""
    pytest.importorskip("pyulog")
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(ULOG.read_bytes()[:size])
    with pytest.raises(LogError, match=r"cut.ulg: the ULog looks cut short: " + said + r".*; copy the whole log from"
                                       r" the vehicle again") as err:
        read_log(cut)
    assert "SDLOG_PROFILE" not in str(err.value)


def test_a_complete_ulog_without_the_imu_topic_is_sent_to_the_logging_profile(tmp_path):
    """A whole log (pyulog writes the sample's actuator_motors alone) that never logged sensor_combined."""
    pyulog = pytest.importorskip("pyulog")
    from quadctl.identify.ulog import ulog_end

    whole = tmp_path / "motors-only.ulg"
    pyulog.ULog(str(ULOG), ["actuator_motors"]).write_ulog(str(whole))
    assert ulog_end(whole.read_bytes()) is None and ulog_end(ULOG.read_bytes()) is None
    with pytest.raises(LogError, match=r"motors-only.ulg: the ULog has no sensor_combined topic; log it "
                                       r"\(SDLOG_PROFILE"):
        read_log(whole)


def test_a_ulog_cut_short_in_its_data_is_read_with_a_notice_of_where_it_ends(tmp_path):
    pytest.importorskip("pyulog")
    from quadctl.errors import QuadctlNotice

    raw = ULOG.read_bytes()
    cut = tmp_path / "half.ulg"
    cut.write_bytes(raw[: len(raw) // 2])
    with pytest.warns(QuadctlNotice, match=r"half.ulg: the ULog looks cut short: it ends after 781573 bytes, inside "
                                           r"the message at byte 781570, which declares 144 bytes and has 0 \(144 "
                                           r"missing\), in its data section \(from byte 85398\); its samples end "
                                           r"there, at t = 14.63 s"):
        log = read_log(cut)
    assert log.t[-1] == pytest.approx(14.63, abs=0.01)


def test_a_ulog_pyulog_read_past_damage_gives_a_notice_not_stdout(monkeypatch, capsys):
    pyulog = pytest.importorskip("pyulog")
    from quadctl.errors import QuadctlNotice

    real = pyulog.ULog

    def damaged(*args, **kwargs):
        print("File corruption detected while reading file data!")
        return real(*args, **kwargs)

    monkeypatch.setattr(pyulog, "ULog", damaged)
    with pytest.warns(QuadctlNotice, match=r"sample_px4_events.ulg: the ULog is damaged \(pyulog: File corruption"):
        log = read_log(ULOG)
    assert log.t.size > 7000 and capsys.readouterr().out == ""


def test_a_folder_or_a_missing_path_is_named_as_what_it_is(tmp_path):
    (tmp_path / "logs").mkdir()
    with pytest.raises(LogError, match=r"logs: is a folder, not a flight log; give the path of a log file in it"):
        read_log(tmp_path / "logs")
    with pytest.raises(LogError, match=r"gone.csv: no such file; give the path of a flight log"):
        read_log(tmp_path / "gone.csv")
    with pytest.raises(LogError, match=r"^/dev/null: not a file \(a device or a pipe\); give the path of the flight "
                                       r"log the vehicle wrote$"):  # it said "no such file" of a path that is there
        read_log("/dev/null")


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root reads any file")
def test_an_unreadable_log_is_named_with_the_reason(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text(",".join(CSV_COLUMNS) + "\n")
    path.chmod(0)
    with pytest.raises(LogError, match=r"x.csv: cannot read the log \(Permission denied\); check the file$"):
        read_log(path)


def test_a_ulog_is_timed_from_its_first_sample_not_its_epoch_stamps():
    """The sample log's time stamps read like 1.7e9 s (an epoch): its t starts at 0, the stamp kept aside."""
    pytest.importorskip("pyulog")
    log = read_log(ULOG)
    assert log.t[0] == 0 and 30 < log.t[-1] < 32
    assert log.clock_at_start == pytest.approx(1710773350.354, abs=1e-3)
    assert np.diff(log.t).min() > 1e-3  # 250 Hz steps, whole microseconds (no float cancellation at 1.7e9 s)


@pytest.mark.parametrize("log", [FLIGHTS / "log10", DATA / "px4-ulog" / "sample_px4_events.ulg"])
def test_columns_given_for_a_binary_log_are_refused_not_ignored(log):
    """--columns maps a CSV's columns; a Crazyflie or ULog file names its fields itself: one line, not a
    mapping silently dropped."""
    with pytest.raises(LogError, match=r"whose fields quadctl reads by their own names: --columns maps the columns "
                                       r"of a CSV log only"):
        read_log(log, {"t": "time_s"})
