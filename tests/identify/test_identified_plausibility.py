"""An identified value that is not physically possible is not written into identified.yaml: the config's value
stays there with a comment saying why, identified.json flags it, and identify exits 1 after writing."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from _paths import DATA
from typer.testing import CliRunner

from quadctl.cli.app import app
from quadctl.config import locate, parse
from quadctl.identify.config_edits import changes, identified_config
from quadctl.identify.estimate import Estimate
from quadctl.identify.flight_log import FlightLog
from quadctl.identify.measurement import PARAMETERS, Airframe
from quadctl.identify.plausibility import RULES, Rule, judge
from quadctl.identify.results import Identification, payload
from quadctl.present.identify import sentences


@pytest.mark.parametrize("name, value, interval, plausible", [
    ("T_m", 0.0725, (0.069, 0.076), True),
    ("T_m", 0.008, (-0.0041, 0.0201), False),  # the sample ULog's: the interval reaches below zero
    ("T_m", 0.01, (0.0, 0.02), False),  # reaching zero is not above it
    ("Jxx", 1.3e-5, (1.2e-5, 1.4e-5), True),
    ("Jyy", 1.3e-5, (-1e-6, 2.7e-5), False),
    ("k_m", 0.006, (-0.001, 0.013), False),
    ("max_thrust", 0.14, (0.07, 0.22), True),  # the 27 g Crazyflie's rotors hover at 0.0662 N each
    ("max_thrust", 0.07, (0.0661, 0.0739), False),  # four rotors at full command may not lift it
    ("max_thrust", 0.06, (0.059, 0.061), False),  # they do not: positive and narrow, below the weight
    ("delay", 0.002, (-0.001, 0.005), True),  # a delay may be none: its value, not its interval, is judged
    ("delay", -0.001, (-0.004, 0.002), False),
    ("c1", -0.12, (-0.25, 0.006), True),  # a coefficient of the curve has no sign of its own
    ("bias_A", -2e-4, (-3e-4, -1e-4), True),
])
def test_each_rule_judges_the_interval_or_the_value(name, value, interval, plausible):
    assert judge(name, value, interval, hover=0.027 * 9.81 / 4) is plausible


def test_every_identified_parameter_has_a_rule():
    fitted = set(PARAMETERS) | {"T_m", "delay"}
    assert fitted | {"max_thrust"} == set(RULES)
    assert {n for n, r in RULES.items() if r is Rule.POSITIVE} == {"T_m", "Jxx", "Jyy", "Jzz", "k_m"}
    assert {n for n, r in RULES.items() if r is Rule.LIFTS} == {"max_thrust"}


def _fit(stage, names, values, std, windows=((1.0, 2.0),)):
    std = np.asarray(std, float)
    return Estimate(stage=stage, names=tuple(names), values=np.array(values, float), std=std,
                        covariance=np.diag(std ** 2), windows=list(windows), t=np.zeros(2),
                        measured=np.zeros((2, 1)), predicted=np.zeros((2, 1)), rows=("x",), rms=0.0, bandwidth=1,
                        extra={"rms_without_lag": 1.0} if stage == "thrust" else {})


def _identification(t_m_std=1e-4, jxx_std=1e-7, k_m_std=1e-5, delay=False, c2=0.12, c1=-0.01):
    """crazyflie's airframe, a thrust, attitude and yaw fit with the given stds (1.96 std past the value: the
    interval reaches zero) and quadratic coefficient (the thrust at full command is c2 + 0.01 N)."""
    from quadctl import config

    log = FlightLog(t=np.arange(2.0), acc=np.zeros((2, 3)), gyro=np.zeros((2, 3)), cmd=np.zeros((2, 4)),
                    path="log", format="csv", sha256="")
    cfg = config.load("crazyflie")
    names = ("c0", "c1", "c2", "T_m") + (("delay",) if delay else ())
    thrust = _fit("thrust", names, (0.02, c1, c2, 0.07) + ((0.017,) if delay else ()),
                  (1e-4, 1e-4, 1e-4, t_m_std) + ((1e-3,) if delay else ()))
    fits = {"thrust": thrust,
            "attitude": _fit("attitude", ("Jxx", "Jyy"), (1.3e-5, 1.38e-5), (jxx_std, 1e-7)),
            "yaw": _fit("yaw", ("k_m",), (0.0062,), (k_m_std,))}
    return Identification(logs=[log], fits=fits, refused={}, stage_logs={"thrust": 0, "attitude": 0, "yaw": 0},
                          airframe=Airframe.from_config(cfg), config_name="crazyflie",
                          controller_rate=cfg.controller.rate)


@pytest.mark.parametrize("kind, args, kept, config_value", [
    ("motor lag", {"t_m_std": 0.05},  # the inertia and k_m are fitted to torques of rotors lagged by T_m
     ("motors.time_constant", "controller.rotor_lag", "vehicle.inertia", "motors.torque_coefficient"),
     lambda c: (c.motors.time_constant, c.controller.rotor_lag, c.vehicle.inertia, c.motors.torque_coefficient)),
    ("roll inertia", {"jxx_std": 1e-5}, ("vehicle.inertia",), lambda c: c.vehicle.inertia),
    ("torque coefficient", {"k_m_std": 0.004}, ("motors.torque_coefficient",),
     lambda c: c.motors.torque_coefficient),
])
def test_a_value_whose_interval_reaches_zero_leaves_the_configs_and_says_why(kind, args, kept, config_value):
    """The identified config keeps the config's value of each key the implausible value would have set (the
    lag's design option with the lag, and the values fitted through the lag), says why above it, and loads;
    the other values are written."""
    ident = _identification(**args)
    base = locate("crazyflie").text
    text = identified_config(base, ident, "x")
    got, was = parse(text, "x"), parse(base, "crazyflie")
    assert config_value(got) == config_value(was), kind
    assert text.count("not identified: ") == len(kept)
    done = payload(ident, "crazyflie.yaml", written=text)
    assert done["identified_yaml_sha256"] == __import__("hashlib").sha256(text.encode()).hexdigest()
    assert list(done["not_written"]) == list(kept)
    assert len(done["implausible"]) == 1
    flagged = [p for s in done["stages"].values() for n, p in s["parameters"].items() if not p["plausible"]]
    assert len(flagged) == 1 and flagged[0]["rule"] == "positive" and flagged[0]["interval95"][0] <= 0
    assert got.motors.max_thrust == pytest.approx(0.13, rel=1e-3)  # the plausible values are written


def test_a_full_command_thrust_that_does_not_lift_the_vehicle_is_not_written_and_says_why():
    """The 27 g Crazyflie (m g / 4 = 0.0662 N a rotor) with a curve that gives 0.06 N at full command: its interval
    (a std of 1.7e-4 N) lies above zero but below the hover thrust. The config's max_thrust stays, and the line
    identify ends with (exit 1) names the bound; at 0.13 N the curve lifts it and is written."""
    from quadctl.present.identify import implausible

    ident = _identification(c2=0.05)
    entry = ident.entries()["max_thrust"]
    assert entry["interval95"][0] > 0 and entry["rule"] == "lifts" and not entry["plausible"]
    assert entry["hover_thrust"] == pytest.approx(0.027 * 9.81 / 4)
    base = locate("crazyflie").text
    text = identified_config(base, ident, "x")
    assert parse(text, "x").motors.max_thrust == parse(base, "crazyflie").motors.max_thrust
    assert "# max_thrust: not identified: max_thrust = 0.06 N" in text
    assert "# thrust_curve: not identified: max_thrust = 0.06 N" in text  # the curve goes with its full thrust
    assert parse(text, "x").motors.thrust_curve is None
    done = payload(ident, "crazyflie.yaml", written=text)
    assert done["implausible"] == ["max_thrust"]
    assert list(done["not_written"]) == ["motors.max_thrust", "motors.thrust_curve"]
    assert re.match(r"^not plausible: max_thrust = 0\.06 N \(95 %: 0\.0596\d* to 0\.0603\d* N\) is a rotor's thrust "
                    r"at full command whose 95 % interval reaches its share of the weight \(m g / 4 = 0\.06622 N, "
                    r"the config's mass and gravity\) or below: four rotors at full command may not lift the vehicle; "
                    r"runs/x/identified\.yaml leaves motors\.max_thrust, motors\.thrust_curve as the config has them "
                    r"\(identified\.json flags it\): "
                    r"check vehicle\.mass and vehicle\.gravity against the vehicle flown \(--set vehicle\.mass=KG\), "
                    r"or fit a log that climbs at full command \(a curve the log did not fly there is extrapolated\)$",
                    implausible(done, "runs/x"))
    assert _identification(c2=0.12).entries()["max_thrust"]["plausible"]


def test_a_thrust_curve_that_falls_is_written_neither_nor_its_full_command_thrust():
    """A curve whose slope c1 + 2 c2 s is negative at s = 0.1 (-0.12 + 0.052 N) is no rotor's, plausible as its
    full-command thrust (0.16 N) is: the config keeps its own curve and max_thrust, together (writing the new
    max_thrust beside a config's curve would make a config that does not load), and a sentence says why."""
    from quadctl.present.identify import sentences

    ident = _identification(c1=-0.12, c2=0.26)
    assert ident.implausible() == ()
    base = locate("crazyflie").text
    text = identified_config(base, ident, "x")
    got = parse(text, "x")
    assert got.motors.max_thrust == parse(base, "crazyflie").motors.max_thrust and got.motors.thrust_curve is None
    assert "# thrust_curve: not written: the identified curve [0.02, -0.12, 0.26] N is no rotor's: its slope " \
           "c1 + 2 c2 s is -0.068 N at s = 0.1" in text
    done = payload(ident, "crazyflie.yaml", written=text)
    assert done["not_written"] == {"motors.max_thrust": ["c0", "c1", "c2"], "motors.thrust_curve": ["c0", "c1", "c2"]}
    said = [x for x in sentences(done) if x.startswith("Not written, motors.thrust_curve and motors.max_thrust: ")]
    assert len(said) == 1 and "the config's thrust curve and max_thrust stay" in said[0]
    assert got.motors.time_constant == pytest.approx(0.07)  # the rest is written


def test_the_torque_coefficient_keeps_the_configs_jzz_when_the_inertia_is_not_written():
    """A yaw log fixes k_m / Jzz: with the inertia kept (Jxx not plausible), Jzz is the config's and k_m is
    written as fitted (with a plausible inertia Jzz is lowered to Jxx + Jyy and k_m with it)."""
    kept = changes(_identification(jxx_std=1e-5))
    assert float(kept[("motors", "torque_coefficient")][0]) == pytest.approx(0.0062, rel=1e-3)
    written = changes(_identification())
    assert float(written[("motors", "torque_coefficient")][0]) == pytest.approx(
        0.0062 * (1.3e-5 + 1.38e-5) / 29.261652e-6, rel=1e-3)


def test_a_lag_on_the_fits_floor_is_not_written_however_narrow_its_interval():
    """The fit holds T_m at two samples or more: a value there is the floor (the data want less), not an
    estimate, even when its interval lies above zero."""
    ident = _identification()
    thrust = ident.fits["thrust"]
    thrust.floors["T_m"] = 0.07  # the fitted 0.07 s, std 1e-4 s: well above zero, but on the floor
    entry = ident.entries()["T_m"]
    assert entry["passes_rule"] and entry["fit_floor"] == 0.07 and not entry["plausible"]
    got = changes(ident)
    assert got[("motors", "time_constant")][0] is None
    assert "is on the fit's floor (0.07 s, two samples of the log" in got[("motors", "time_constant")][1]
    thrust.floors["T_m"] = 0.004  # off the floor: written
    assert changes(ident)[("motors", "time_constant")][0] == "0.07"


def test_a_delay_fitted_with_an_implausible_lag_is_not_written():
    """The delay and T_m trade against each other: a delay fitted beside a lag the log does not resolve is not
    written either, and the delay's own sentence gives way to the one that says what was kept."""
    ident = _identification(t_m_std=0.05, delay=True)
    got = changes(ident)
    assert got[("controller", "delay")][0] is None and "T_m = 0.07 s" in got[("controller", "delay")][1]
    done = payload(ident, "crazyflie.yaml")
    assert "controller.delay" in done["not_written"] and done["delay_written"]["samples"] is None
    assert not any("delay" in s for s in sentences(done))
    assert parse(identified_config(locate("crazyflie").text, ident, "x"), "x").controller.delay_samples() == 0


def test_the_sample_ulogs_unresolved_motor_lag_is_not_written_and_identify_exits_1(tmp_path):
    """The PX4 sample flown with crazyflie's config: T_m = 0.008 s, its interval from -0.0041 s. The files are
    written (the config's lag kept), identified.json flags T_m, and one line says what and why (exit 1)."""
    pytest.importorskip("pyulog")
    out = tmp_path / "o"
    res = CliRunner().invoke(app, ["identify", str(DATA / "px4-ulog" / "sample_px4_events.ulg"), "-c", "crazyflie",
                                   "-o", str(out), "--json"])
    assert res.exit_code == 1, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and re.match(
        r"^quadctl: check failed: not plausible: T_m = 0\.008 s \(95 %: -0\.004\d* to 0\.02\d* s\) is a positive "
        r"quantity whose 95 % interval reaches zero or below, and on the fit's floor \(0\.008 s, two samples of "
        r"the log: the log resolves nothing shorter\); .*identified\.yaml leaves "
        r"motors\.time_constant, controller\.rotor_lag as the config has them \(identified\.json flags it\)",
        lines[0]), lines
    done = json.loads(res.stdout)
    assert done == json.loads((out / "identified.json").read_text())
    t_m = done["stages"]["thrust"]["parameters"]["T_m"]
    assert t_m["plausible"] is False and t_m["interval95"][0] < 0 < t_m["interval95"][1]
    assert t_m["fit_floor"] == pytest.approx(2 / 250)  # two samples at the log's 250 Hz
    assert done["implausible"] == ["T_m"]
    text = (out / "identified.yaml").read_text()
    assert "time_constant: 0.008" not in text and "rotor_lag: include" not in text
    assert "# time_constant: not identified: T_m = 0.008 s" in text
    cfg = parse(text, "identified.yaml")
    assert cfg.motors.time_constant == parse(locate("crazyflie").text, "c").motors.time_constant
    # its curve falls from 0.08 N at s = 0 to 0.062 N at s = 0.33, inside the commands it flew (0.12 to 0.54):
    # no rotor's, so neither it nor its full-command thrust is written (the config's stay)
    assert cfg.motors.max_thrust == parse(locate("crazyflie").text, "c").motors.max_thrust
    assert cfg.motors.thrust_curve is None and "motors.thrust_curve" in done["not_written"]


def test_the_closing_line_names_what_was_kept_or_that_nothing_was_to_be_written():
    from quadctl.present.identify import implausible

    p = {"value": -0.001, "interval95": [-0.004, 0.002], "unit": "s", "rule": "non-negative", "passes_rule": False,
         "fit_floor": None, "plausible": False}
    done = {"stages": {"thrust": {"parameters": {"delay": p}}}, "implausible": ["delay"], "not_written": {}}
    assert implausible(done, "runs/x") == (
        "not plausible: delay = -0.001 s (95 %: -0.004 to 0.002 s) is negative, which it cannot be; "
        "runs/x/identified.yaml does not take it (identified.json flags it): fit a window that excites it more "
        "(--window), or a longer log")
    done["not_written"] = {"controller.delay": ["delay"]}
    assert "runs/x/identified.yaml leaves controller.delay as the config has it (" in implausible(done, "runs/x")


@pytest.mark.slow  # the exit-1 path is the sample ULog's above; this is the lift rule through the command
def test_a_curve_that_cannot_lift_the_configs_weight_is_not_written_and_identify_exits_1(tmp_path):
    """log10's curve (0.138 N a rotor at full command) and the Crazyflie under 22 m/s^2 (0.149 N a rotor at hover):
    the fit ignores gravity (an accelerometer does not feel it), the rule does not."""
    out = tmp_path / "o"
    res = CliRunner().invoke(app, ["identify", str(DATA / "crazyflie-flights" / "log10"), "-c", "crazyflie",
                                   "--window", "8.67:38.67", "--set", "vehicle.gravity=22", "-o", str(out)])
    assert res.exit_code == 1, res.output
    assert "max_thrust = 0.1382 N (95 %: 0.1359 to 0.1405 N) is a rotor's thrust at full command" in res.stderr
    assert "(m g / 4 = 0.1485 N," in res.stderr
    assert "leaves motors.max_thrust, motors.thrust_curve as the config has them" in res.stderr
    done = json.loads((out / "identified.json").read_text())
    assert done["implausible"] == ["max_thrust"]
    cfg = parse((out / "identified.yaml").read_text(), "identified.yaml")
    assert cfg.motors.max_thrust == parse(locate("crazyflie").text, "c").motors.max_thrust
    assert cfg.motors.time_constant == pytest.approx(0.0651, abs=5e-4)  # the plausible values are written
