"""Windows from a log's excitation, which stage takes which log, and the refusals that say why."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from _paths import DATA

from quadctl.config import load
from quadctl.errors import LogError
from quadctl.identify import windows as win
from quadctl.identify.flight_log import FlightLog
from quadctl.identify.measurement import Airframe
from quadctl.identify.readers import read_log

FLIGHTS = DATA / "crazyflie-flights"
CRAZYFLIE = Airframe.from_config(load("crazyflie"))
"""The crazyflie config's rotors, in the Crazyflie's numbering: its logs' motor.m1..m4 as they are."""


@pytest.fixture(scope="module")
def flights():
    return [read_log(FLIGHTS / n) for n in ("log10", "log15", "log16")]


def hover(seconds=20.0, rate=1000.0, collective=0.0, yaw=0.0):
    """A log flown from t = 2 s to 2 s before its end; the collective or yaw command moving by the given amplitude."""
    t = np.arange(int(seconds * rate)) / rate
    wave = np.sign(np.sin(2 * np.pi * 0.7 * t))
    cmd = np.full((t.size, 4), 0.6) + collective * wave[:, None] + yaw * wave[:, None] * np.array([1, -1, 1, -1])
    cmd[(t < 2) | (t > seconds - 2)] = 0.0
    rng = np.random.default_rng(0)
    acc = np.tile([0.0, 0.0, -9.81], (t.size, 1)) + rng.normal(0, 0.1, (t.size, 3))
    return FlightLog(t=t, acc=acc, gyro=rng.normal(0, 0.01, (t.size, 3)), cmd=cmd, path="hover.csv", format="csv",
                     sha256="")


def test_flights_found_after_take_off_and_before_the_crash(flights):
    log10, _, log16 = flights
    (t0, t1), = win.flights(log10)
    clock10, clock16 = log10.clock_at_start, log16.clock_at_start  # the Crazyflie's clock, as the paper gives times
    assert t0 + clock10 == pytest.approx(32.44, abs=0.05) and t1 + clock10 == pytest.approx(68.49, abs=0.05)  # crash
    assert [round(a + clock16) for a, _ in win.flights(log16)] == [32, 45]  # two flights


def test_each_stage_takes_the_log_flown_for_it(flights):
    plan = win.plan(flights, None, CRAZYFLIE)
    assert {stage: i for stage, (i, _) in plan.chosen.items()} == {"thrust": 0, "attitude": 1, "yaw": 2}
    assert plan.refused == {}


def test_the_stages_weigh_the_commands_by_the_configs_rotor_numbering(flights):
    """The three flights with their rotors in PX4's order (front right, rear left, front left, rear right), as a
    PX4 ULog or a CSV so numbered carries them, and the config numbered so: each stage takes the log flown for it,
    with the same excitation. Weighed in the Crazyflie's order whatever the config said, roll and pitch were
    refused ("no log excites it", 0.0276 at most) and the yaw was fitted to log15, which rolls and pitches."""
    cfg = load("crazyflie")
    px4 = cfg.model_copy(update={"motors": cfg.motors.model_copy(update={"numbering": "px4"})})
    reordered = [dataclasses.replace(log, cmd=log.cmd[:, [0, 2, 3, 1]]) for log in flights]
    want = win.plan(flights, None, CRAZYFLIE)
    got = win.plan(reordered, None, Airframe.from_config(px4))
    assert {stage: i for stage, (i, _) in got.chosen.items()} == {"thrust": 0, "attitude": 1, "yaw": 2}
    for g, w in zip(got.excitation, want.excitation):
        assert g == pytest.approx(w, rel=1e-12)


def test_a_log_that_only_moves_the_thrust_refuses_the_others():
    plan = win.plan([hover(collective=0.15)], None, CRAZYFLIE)
    assert set(plan.chosen) == {"thrust"}
    assert "no log excites it" in plan.refused["attitude"] and "no log excites it" in plan.refused["yaw"]


def test_a_log_without_excitation_is_refused():
    with pytest.raises(LogError, match=r"hover.csv: nothing to identify \(thrust: no log excites it.*--window"):
        win.plan([hover()], None, CRAZYFLIE)


def test_without_thrust_no_other_stage():
    with pytest.raises(LogError, match=r"no log excites the thrust, which every other stage needs"):
        win.plan([hover(yaw=0.1)], None, CRAZYFLIE)


def test_saturated_motors_refused():
    log = hover(collective=0.15)
    cmd = log.cmd.copy()
    cmd[(log.t > 5) & (log.t < 7)] = 1.0
    with pytest.raises(LogError, match=r"hover.csv: nothing to identify \(thrust: .*the motors are at full command in "
                                       r"\d+.?\d* % of the window .*choose --window"):
        win.plan([FlightLog(**{**log.__dict__, "cmd": cmd})], None, CRAZYFLIE)


def test_dropped_sensor_refused():
    log = hover(collective=0.15)
    keep = (log.t < 8) | (log.t > 8.05)
    cut = FlightLog(t=log.t[keep], acc=log.acc[keep], gyro=log.gyro[keep], cmd=log.cmd[keep], path="hover.csv",
                    format="csv", sha256="")
    with pytest.raises(LogError, match=r"thrust: .*no samples for 5\d ms at t = 7.999 s \(a dropped sensor\)"):
        win.plan([cut], None, CRAZYFLIE)


def test_frozen_gyro_refused():
    log = hover(collective=0.15)
    gyro = log.gyro.copy()
    gyro[(log.t > 8) & (log.t < 8.1)] = gyro[8000]
    with pytest.raises(LogError, match=r"thrust: .*the gyro repeats one value for 9\d samples \(a dropped sensor\)"):
        win.plan([FlightLog(**{**log.__dict__, "gyro": gyro})], None, CRAZYFLIE)


@pytest.mark.parametrize("text, want", [("35:65", [(35.0, 65.0)]), ("32:38,45:49", [(32.0, 38.0), (45.0, 49.0)])])
def test_window_option(text, want):
    assert win.parse_window(text) == want


@pytest.mark.parametrize("text", ["65:35", "35", "a:b", "1:2,3"])
def test_window_option_refused(text):
    with pytest.raises(LogError, match=r"is not t0:t1 with t0 < t1"):
        win.parse_window(text)


@pytest.mark.parametrize("given, count, said", [(["8.67:38.67"], 2, "given once for 2 log(s)"),
                                                (["1:2", "3:4"], 1, "given 2 times for 1 log(s)")])
def test_window_option_once_per_log(given, count, said):
    from quadctl.identify.results import windows_per_log

    with pytest.raises(LogError, match=re.escape(f"--window {said}; give it once per LOG")):
        windows_per_log(given, count)


@pytest.mark.parametrize("windows, match", [
    ([(5.0, 10.0), (9.0, 12.0)], r"hover.csv: --window 5:10 and 9:12 overlap \(t 9 to 10 s would count twice\)"),
    ([(9.0, 12.0), (3.0, 15.0)], r"--window 3:15 and 9:12 overlap"),  # one inside the other, given in any order
    ([(30.0, 40.0)], r"hover.csv: --window 30:40 lies outside the log, which spans t 0 to 20 s"),
    ([(15.0, 30.0)], r"hover.csv: --window 15:30 reaches outside the log, which spans t 0 to 20 s"),  # fitted on 15-20
])
def test_given_windows_that_overlap_or_miss_the_log_are_refused(windows, match):
    with pytest.raises(LogError, match=match):
        win.plan([hover(collective=0.15)], [windows], CRAZYFLIE)


def test_a_window_ending_on_the_span_as_printed_is_inside():
    """The span's end read off the message (4 digits, rounded up by under a sample) is still the log's end."""
    log = hover(collective=0.15)
    end = float(f"{log.t[-1] + 0.4 * (log.t[1] - log.t[0]):.4g}")
    assert end > log.t[-1]
    win.plan([log], [[(5.0, end)]], CRAZYFLIE)


def test_touching_windows_are_one_stretch_of_the_log():
    plan = win.plan([hover(collective=0.15)], [[(5.0, 10.0), (10.0, 15.0)]], CRAZYFLIE)
    assert plan.chosen["thrust"] == (0, [(5.0, 10.0), (10.0, 15.0)])


def test_a_gyro_in_degrees_per_second_is_named_not_taken_for_no_excitation(flights):
    """log10 with its gyro in deg/s: every turn reads as a crash's rate, the flight is cut just after take-off
    and the refusal said only that no log excites anything. It says where the flight was cut, why, and the
    units to check; the logs as read (rad/s) have their flights."""
    log10 = flights[0]
    degrees = FlightLog(**{**log10.__dict__, "gyro": np.degrees(log10.gyro)})
    with pytest.raises(LogError, match=r"log10's flight ends as a crash at t = [\d.]+ s, [\d.]+ s after take-off, "
                                       r"where the gyro reads [\d.]+ rad/s \(above 17, about 1000 deg/s\): if it did "
                                       r"not crash, check the units \(a gyro in deg/s"):
        win.plan([degrees], None, CRAZYFLIE)
    assert all(win.cut_by_a_crash(log) is None for log in flights)
