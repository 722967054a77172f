"""`quadctl identify`: the artifacts, the identified config that `design` takes, and bad input (exit 2)."""

from __future__ import annotations

import json
import re

import pytest
import yaml
from _paths import DATA, ROOT
from typer.testing import CliRunner

from quadctl.cli.app import app

FLIGHTS = DATA / "crazyflie-flights"


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    out = tmp_path_factory.mktemp("identified")
    res = CliRunner().invoke(app, ["identify", str(FLIGHTS / "log10"), "-c", "crazyflie", "--window", "8.67:38.67",
                                   "-o", str(out)])  # the paper's 35-65 s of the Crazyflie's clock
    assert res.exit_code == 0, res.output
    return out, res.output


def test_identify_writes_values_intervals_and_provenance(identified):
    out, text = identified
    payload = json.loads((out / "identified.json").read_text())
    thrust = payload["stages"]["thrust"]
    assert thrust["windows_s"] == [[8.67, 38.67]]
    assert payload["logs"][0]["t_start"] == 0 and payload["logs"][0]["clock_at_start_s"] == pytest.approx(26.333702)
    lo, hi = thrust["parameters"]["T_m"]["interval95"]
    assert lo < thrust["parameters"]["T_m"]["value"] < hi
    assert payload["logs"][0]["sha256"] == __import__("hashlib").sha256((FLIGHTS / "log10").read_bytes()).hexdigest()
    assert "attitude" in payload["refused"] and "yaw" in payload["refused"]  # log10 is a thrust log
    assert (out / "identify.png").read_bytes()[:4] == b"\x89PNG"


def test_identified_config_says_where_each_value_came_from_and_designs(identified):
    out, _ = identified
    text = (out / "identified.yaml").read_text()
    assert "time_constant: 0.065" in text and "identified from log10 t 8.67:38.67 s" in text
    assert "the lag of the command: docs/guide/identify.md, Which lag" in text  # the page that explains it
    assert (ROOT / "docs/guide/identify.md").read_text().count("**Which lag.**") == 1
    res = CliRunner().invoke(app, ["design", "-c", str(out / "identified.yaml"), "-o", str(out / "design")])
    assert res.exit_code == 0, res.output


def test_identified_config_carries_the_thrust_curve_whose_full_command_thrust_is_max_thrust(identified):
    """The curve as fitted (identified.json's c0, c1, c2, 4 digits each) is written beside max_thrust, which is
    that written curve at s = 1 to its last digit: loaded back, c0 + c1 + c2 is max_thrust."""
    from quadctl.config import parse

    out, _ = identified
    text = (out / "identified.yaml").read_text()
    cfg = parse(text, "identified.yaml")
    fitted = json.loads((out / "identified.json").read_text())["stages"]["thrust"]["parameters"]
    curve = cfg.motors.thrust_curve
    assert curve == pytest.approx([fitted[n]["value"] for n in ("c0", "c1", "c2")], rel=5e-4)
    assert sum(curve) == pytest.approx(cfg.motors.max_thrust, rel=1e-15, abs=0)
    lines = text.splitlines()
    at = next(k for k, ln in enumerate(lines) if ln.lstrip().startswith("max_thrust:"))
    assert lines[at + 1].lstrip().startswith("thrust_curve: [")  # beside it
    assert "c0 + c1 s + c2 s^2 at the command s (of full), identified from log10 t 8.67:38.67 s" in lines[at + 1]


def test_identify_again_keeps_the_run_of_the_identified_config_in_its_folder(identified, tmp_path):
    """identify writes no config's run, so it removes none: the identified config designed in identify's own
    folder, then identify run again there (a new fit), leaves that design and the config beside it as they
    were (a session of the vehicle's config would have removed them and written crazyflie's config there)."""
    import shutil

    out = shutil.copytree(identified[0], tmp_path / "identified")
    res = CliRunner().invoke(app, ["design", "-c", str(out / "identified.yaml"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    run = ("config.yaml", "config.resolved.yaml", "trim.json", "linear.npz", "design.json")
    before = {name: (out / name).read_bytes() for name in run}
    res = CliRunner().invoke(app, ["identify", str(FLIGHTS / "log10"), "-c", "crazyflie", "--window", "8.67:38.67",
                                   "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert {name: (out / name).read_bytes() for name in run} == before and "removed" not in res.stderr


@pytest.mark.parametrize("args, match", [
    (["--window", "65:35"], "--window '65:35': '65:35' is not t0:t1 with t0 < t1 (s from the log's first sample"),
    (["--window", "8.67-38.67"], "write e.g. --window 8.67:38.67 or"),  # an example within the log, not its clock's
    (["--window", "100:200"], "log10: --window 100:200 lies outside the log, which spans t"),
    (["--window", "35:65", "--window", "1:2"], "--window given 2 times for 1 log(s); give it once per LOG"),
    (["--window", "10:30,25:35"], "log10: --window 10:30 and 25:35 overlap"),
    (["--window", "0:5"], "nothing to identify"),  # on the ground: t is from the log's first sample
])
def test_identify_refuses_bad_windows(tmp_path, args, match):
    res = CliRunner().invoke(app, ["identify", str(FLIGHTS / "log10"), "-c", "crazyflie", "-o", str(tmp_path / "o"),
                                   *args])
    assert res.exit_code == 2
    assert match in res.output
    assert not (tmp_path / "o").exists()  # nothing half-written


def test_identify_refuses_a_corrupted_log(tmp_path):
    bad = tmp_path / "log10"
    data = bytearray((FLIGHTS / "log10").read_bytes())
    data[1000] ^= 0xFF
    bad.write_bytes(bytes(data))
    res = CliRunner().invoke(app, ["identify", str(bad), "-c", "crazyflie", "-o", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "log10: the CRC-32 at the end does not match" in res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def test_identify_refuses_a_csv_without_a_column(tmp_path):
    path = tmp_path / "flight.csv"
    path.write_text("t,acc_x,acc_y,acc_z,gyro_p,gyro_q,gyro_r,cmd_1,cmd_2,cmd_3\n0,0,0,0,0,0,0,0,0,0\n")
    res = CliRunner().invoke(app, ["identify", str(path), "-c", "crazyflie", "-o", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "flight.csv: no column 'cmd_4'" in res.output and "--columns cmd_4=YOUR_NAME" in res.output
    assert not (tmp_path / "o").exists()


def test_identify_refuses_one_log_given_twice(tmp_path):
    """The same log twice (a shell glob and its name) was fitted as two flights: each sample counted twice and
    every interval came out narrower than the flight supports."""
    copy = tmp_path / "copy-of-log10"
    copy.write_bytes((FLIGHTS / "log10").read_bytes())
    res = CliRunner().invoke(app, ["identify", str(FLIGHTS / "log10"), str(copy), "-c", "crazyflie",
                                   "-o", str(tmp_path / "o")])
    assert res.exit_code == 2, res.output
    assert re.search(r"^quadctl: error: \S*copy-of-log10: the same log as \S*log10 \(sha256 [0-9a-f]{12}\.\.\.\), "
                     r"over the same stretch; give each log once", res.output), res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def _fit(stage, names, values, windows=((1.0, 2.0),)):
    import numpy as np

    from quadctl.identify.estimate import Estimate

    k = len(names)
    return Estimate(stage=stage, names=tuple(names), values=np.array(values, float), std=np.full(k, 1e-9),
                    covariance=np.eye(k) * 1e-18, windows=list(windows), t=np.zeros(2), measured=np.zeros((2, 1)),
                    predicted=np.zeros((2, 1)), rows=("x",), rms=0.0, bandwidth=1)


@pytest.mark.parametrize("jzz, lowered", [(3e-5, True), (2e-5, False)])
def test_identified_config_keeps_a_rigid_body_and_the_yaw_ratio(jzz, lowered):
    """Jxx + Jyy identified below the config's Jzz: Jzz goes down to their sum, and the torque
    coefficient with it (a yaw log fixes k_m / Jzz)."""
    import numpy as np

    from quadctl.identify.config_edits import changes
    from quadctl.identify.flight_log import FlightLog
    from quadctl.identify.measurement import Airframe
    from quadctl.identify.results import Identification

    log = FlightLog(t=np.arange(2.0), acc=np.zeros((2, 3)), gyro=np.zeros((2, 3)), cmd=np.zeros((2, 4)),
                    path="log", format="csv", sha256="")
    airframe = Airframe(mass=0.027, gravity=9.81, positions=np.zeros((4, 2)), spins=np.ones(4),
                            inertia=np.array([1e-5, 1e-5, jzz]), torque_coefficient=0.006)
    fits = {"thrust": _fit("thrust", ("c0", "c1", "c2", "T_m"), (0.02, -0.01, 0.12, 0.07)),
            "attitude": _fit("attitude", ("Jxx", "Jyy"), (1.2e-5, 1.3e-5)),
            "yaw": _fit("yaw", ("k_m",), (0.006,))}
    ident = Identification(logs=[log], fits=fits, refused={}, stage_logs={"thrust": 0, "attitude": 0, "yaw": 0},
                           airframe=airframe, config_name="x")
    got = changes(ident)
    want_jzz = 2.5e-5 if lowered else jzz
    assert yaml.safe_load(got[("vehicle", "inertia")][0]) == [1.2e-05, 1.3e-05, want_jzz]  # floats to any reader
    assert ("Jzz lowered to Jxx + Jyy" in got[("vehicle", "inertia")][1]) is lowered
    assert float(got[("motors", "torque_coefficient")][0]) == pytest.approx(0.006 * want_jzz / jzz, rel=1e-3)


def test_identify_json_is_the_artifact_and_nothing_else(identified, tmp_path):
    out, _ = identified
    res = CliRunner().invoke(app, ["identify", str(FLIGHTS / "log10"), "-c", "crazyflie", "--window", "8.67:38.67",
                                   "-o", str(tmp_path), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout) == json.loads((tmp_path / "identified.json").read_text())


def test_identify_without_a_config_is_refused_and_names_one(tmp_path, monkeypatch):
    """The fit depends on the vehicle's mass and geometry: no default vehicle stands in for the log's."""
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(app, ["identify", str(FLIGHTS / "log10")])
    assert res.exit_code == 2
    assert len(res.output.strip().splitlines()) == 1 and "-c crazyflie" in res.output
    assert not (tmp_path / "runs").exists()
    assert "Default: forward" not in CliRunner().invoke(app, ["identify", "--help"]).output


def test_identify_json_of_a_truncated_ulog_keeps_stdout_clean(tmp_path):
    pytest.importorskip("pyulog")
    cut = tmp_path / "cut.ulg"
    cut.write_bytes((DATA / "px4-ulog" / "sample_px4_events.ulg").read_bytes()[:20000])
    res = CliRunner().invoke(app, ["identify", str(cut), "-c", "crazyflie", "--json", "-o", str(tmp_path / "o")])
    assert res.exit_code == 2 and res.stdout == ""
    assert "cut.ulg: the ULog is truncated or corrupt" in res.stderr


def test_identify_of_a_ulog_cut_short_before_its_data_says_so_in_one_line(tmp_path):
    pytest.importorskip("pyulog")
    cut = tmp_path / "cut.ulg"
    cut.write_bytes((DATA / "px4-ulog" / "sample_px4_events.ulg").read_bytes()[:5000])
    res = CliRunner().invoke(app, ["identify", str(cut), "-c", "crazyflie", "-o", str(tmp_path / "o")])
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "cut.ulg: the ULog looks cut short: it ends after 5000 bytes" in res.stderr
    assert "SDLOG_PROFILE" not in res.stderr and not (tmp_path / "o").exists()


def _delay_identification(rate):
    import numpy as np

    from quadctl.identify.flight_log import FlightLog
    from quadctl.identify.measurement import Airframe
    from quadctl.identify.results import Identification

    log = FlightLog(t=np.arange(2.0), acc=np.zeros((2, 3)), gyro=np.zeros((2, 3)), cmd=np.zeros((2, 4)),
                    path="log", format="csv", sha256="")
    airframe = Airframe(mass=0.027, gravity=9.81, positions=np.zeros((4, 2)), spins=np.ones(4),
                            inertia=np.array([1e-5, 1e-5, 2e-5]), torque_coefficient=0.006)
    thrust = _fit("thrust", ("c0", "c1", "c2", "T_m", "delay"), (0.02, -0.01, 0.12, 0.056, 0.01711))
    thrust.extra["rms_without_lag"] = 1.0
    return Identification(logs=[log], fits={"thrust": thrust}, refused={}, stage_logs={"thrust": 0},
                          airframe=airframe, config_name="crazyflie", controller_rate=rate)


def test_a_fitted_delay_is_written_as_whole_controller_samples_replacing_the_configs():
    """17.11 ms at 500 Hz is 8.55 samples: 9 written; a delay the config gave as a block is replaced whole."""
    from quadctl.config import locate, parse
    from quadctl.identify.config_edits import changes, identified_config
    from quadctl.identify.results import payload
    from quadctl.present.identify import sentences

    ident = _delay_identification(500.0)
    value, comment = changes(ident)[("controller", "delay")]
    assert value == "{samples: 9}" and "17.11 ms" in comment and "18 ms at 500 Hz" in comment
    text = locate("crazyflie").text.replace("controller:\n", "controller:\n  delay:\n    samples: 2\n", 1)
    assert parse(text, "x").controller.delay_samples() == 2
    assert parse(identified_config(text, ident, "x"), "x").controller.delay_samples() == 9
    said = sentences(payload(ident, "crazyflie.yaml"))
    written = [s for s in said if "written as controller.delay: {samples: 9}" in s]
    assert written and "quadctl compare -c" in written[0]  # the check against the cascade the vehicle flies


def test_a_fitted_delay_with_a_continuous_controller_is_not_written_and_the_user_is_told_how():
    from quadctl.identify.config_edits import changes
    from quadctl.identify.results import payload
    from quadctl.present.identify import sentences

    ident = _delay_identification(None)
    assert ("controller", "delay") not in changes(ident)
    said = sentences(payload(ident, "forward.yaml"))
    assert any("17.11 ms, is not written" in s and "controller.delay: {samples: n}" in s for s in said)


def test_a_fitted_delay_longer_than_the_config_takes_is_not_written_and_the_config_still_loads():
    """17.11 ms at 10 kHz is 171 samples, past controller.delay's 100: the identified config loads without it
    (it would not with it), and the user is told why."""
    from quadctl.config import locate, parse
    from quadctl.identify.config_edits import changes, identified_config
    from quadctl.identify.results import payload
    from quadctl.present.identify import sentences

    ident = _delay_identification(10_000.0)
    assert ("controller", "delay") not in changes(ident)
    parse(identified_config(locate("crazyflie").text, ident, "x"), "x")
    said = sentences(payload(ident, "crazyflie.yaml"))
    assert any("is 171 samples at 10000 Hz, more than controller.delay takes (100)" in s for s in said)


def test_the_identified_config_says_what_it_is_not_what_the_config_it_came_from_was():
    """A header names the base config, whose comments stay (its sources, which its values cite), but for an
    editor's schema line relative to where it lay; its description and the comment above a replaced value
    spoke of that config: they give way to a description that says identified and each value's own comment."""
    from quadctl.config import locate, parse
    from quadctl.identify.config_edits import identified_config

    text = locate("crazyflie").text
    assert "$schema=" in text and "The rotors hover at" in text and "[F]'s thrust at full PWM" in text
    out = identified_config(text, _delay_identification(500.0), "crazyflie-identified")
    assert out.startswith("# Identified by quadctl identify from log: see identified.json. The rest is the config\n"
                          "# crazyflie's, its comments speaking of its values;")
    for stale in ("$schema=", "[F]'s thrust at full PWM", "Förster 2015"):
        assert stale not in out, stale
    assert "# [F] J. Förster" in out  # the sources its values cite stay
    cfg = parse(out, "crazyflie-identified")
    assert cfg.description == "crazyflie, identified from log" and cfg.name == "crazyflie-identified"
    assert "# N/(rad/s)^2: [F]'s C_T" in out  # a comment above a value the logs leave stays


def test_set_gives_the_fit_its_values_and_identified_yaml_carries_them(identified, tmp_path):
    """--set as on every command: the fit takes the config with it (a heavier vehicle: the same accelerations
    make a thrust curve larger by the ratio of the masses, the same lag), and identified.yaml holds the value,
    saying where it came from."""
    from quadctl.config import parse

    out = tmp_path / "o"
    res = CliRunner().invoke(app, ["identify", str(FLIGHTS / "log10"), "-c", "crazyflie", "--window", "8.67:38.67",
                                   "--set", "vehicle.mass=0.03", "-o", str(out)])
    assert res.exit_code == 0, res.output
    heavy = json.loads((out / "identified.json").read_text())
    light = json.loads((identified[0] / "identified.json").read_text())
    assert heavy["set"] == ["vehicle.mass=0.03"] and heavy["held"]["mass_kg"] == 0.03
    p_heavy, p_light = heavy["stages"]["thrust"]["parameters"], light["stages"]["thrust"]["parameters"]
    for c in ("c0", "c1", "c2"):
        assert p_heavy[c]["value"] == pytest.approx(p_light[c]["value"] * 0.03 / 0.027, rel=1e-3), c
    assert p_heavy["T_m"]["value"] == pytest.approx(p_light["T_m"]["value"], rel=1e-3)
    text = (out / "identified.yaml").read_text()
    assert "mass: 0.03  # given on the command line (--set vehicle.mass=0.03)" in text
    assert parse(text, "identified.yaml").vehicle.mass == 0.03


def test_a_bad_set_is_refused_in_one_line_naming_it_and_nothing_is_written(tmp_path):
    res = CliRunner().invoke(app, ["identify", str(FLIGHTS / "log10"), "-c", "crazyflie", "--set", "vehicle.mass=-1",
                                   "-o", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert res.stderr.strip().splitlines() == ["quadctl: error: --set: vehicle.mass = -1: must be at least 0.0001 (kg)"]
    assert not (tmp_path / "o").exists()


def test_a_mass_in_grams_stops_identify_before_the_fit_as_it_stops_design(tmp_path):
    """The fit's thrust is the mass times the measured acceleration: 30 (grams typed as kg) made a thrust curve
    a thousand times too large, 154 N a rotor, written with exit 0. The config's unit-slip check runs as on every
    command that computes: its warnings, exit 1, and nothing written."""
    res = CliRunner().invoke(app, ["identify", str(FLIGHTS / "log10"), "-c", "crazyflie", "--window", "8.67:38.67",
                                   "--set", "vehicle.mass=30", "-o", str(tmp_path / "o")])
    assert res.exit_code == 1, res.output
    assert "is vehicle.mass in grams? 30 g is 0.03 kg" in res.stderr
    assert res.stderr.strip().splitlines()[-1].startswith(
        "quadctl: check failed: crazyflie.yaml with --set: vehicle.mass implausible")
    assert not (tmp_path / "o").exists()


def _at(tree: dict, keys: list):
    for key in keys:
        tree = tree[key]
    return tree


@pytest.mark.parametrize("sets", [
    ["lqr.roll.Q[1]=50", "lqr.roll.R=[4e5]"],  # two into one key: one line for both
    ["allow=[saturation]"],  # a top-level key the config leaves out
    ["simulation.plant.inertia=[1.3e-5, 1.4e-5, 2.7e-5]"],  # a section's key the config leaves out
    ["motors={layout: x, arm_length: 0.05, max_thrust: 0.16}"],  # a whole section
])
def test_the_identified_config_holds_the_set_values_as_the_fit_took_them(sets):
    """identified.yaml is the config with --set put in (as overrides.load makes it), then the identified values."""
    from quadctl.config import locate, overrides, parse
    from quadctl.identify.config_edits import identified_config

    source = locate("crazyflie")
    ident = _delay_identification(500.0)
    got = parse(identified_config(source.text, ident, "x", sets), "x").model_dump()
    want = parse(identified_config(source.text, ident, "x"), "x").model_dump()
    fit = overrides.load(source, sets).model_dump()
    for text in sets:
        top, _, rest = text.partition("=")[0].partition(".")
        key = rest.split(".")[0].split("[")[0] or None
        at = [top] if key is None else [top, key]
        if at != ["motors"]:  # (the identified values go into the section: below)
            assert _at(got, at) == _at(fit, at), text
        assert _at(got, at) != _at(want, at), text
    if sets[0].startswith("motors="):  # identified values go over the section --set gave
        assert got["motors"]["arm_length"] == 0.05 and got["motors"]["time_constant"] == 0.056


def test_a_set_value_over_two_lines_keeps_the_identified_config_loadable():
    """A comment ends at the line's end: the --set that gave a value spanning lines is shown escaped."""
    from quadctl.config import locate, parse
    from quadctl.identify.config_edits import identified_config

    text = identified_config(locate("crazyflie").text, _delay_identification(500.0), "x",
                             ["simulation.reference={setpoints: [{t: 1,\n yaw: 0.5}]}"])
    assert "--set simulation.reference={setpoints: [{t: 1,\\n yaw: 0.5}]})" in text
    assert parse(text, "x").simulation.reference.setpoints[0].yaw == 0.5


@pytest.mark.parametrize("rms, explains", [(1.004, "0 %"), (0.0, "100 %"), (0.5468, "45 %")])
def test_the_share_of_the_thrust_error_the_lag_explains_reads_0_not_minus_0(rms, explains):
    """The lag held at its floor (two samples) may fit a hair worse than no lag (the sample ULog: -0.4 %):
    that share is 0 % of the error, not -0 %."""
    from quadctl.identify.results import payload
    from quadctl.present.identify import sentences

    ident = _delay_identification(500.0)
    ident.fits["thrust"].rms = rms  # rms_without_lag: 1.0
    said = sentences(payload(ident, "crazyflie.yaml"))
    assert any(s.startswith("Thrust fit: ") and s.endswith(f"(the lag explains {explains} of the error).")
               for s in said), said


def test_a_lag_that_fits_worse_than_none_is_said_to_explain_none_of_the_thrust_error_not_a_negative_share():
    """A log whose rotors do not lag (a simulator's) fitted 69 % worse with the lag held at its floor: the
    sentence said "the lag explains -69 % of the error"."""
    from quadctl.identify.results import payload
    from quadctl.present.identify import sentences

    ident = _delay_identification(500.0)
    ident.fits["thrust"].rms = 1.69  # rms_without_lag: 1.0
    said = sentences(payload(ident, "crazyflie.yaml"))
    assert any(s.startswith("Thrust fit: ") and s.endswith("(the lag explains none of the error: it is 69 % larger "
                                                           "with it).") for s in said), said


def test_a_window_reads_back_as_it_was_typed(tmp_path):
    """log15's window from its README, 15.755:50.755, showed as 15.76-50.76 in the table and the
    identified.yaml comment: typed back, another window. Times are shown to the millisecond."""
    out = tmp_path / "o"
    res = CliRunner().invoke(app, ["identify", str(FLIGHTS / "log15"), "-c", "crazyflie", "--window", "15.755:50.755",
                                   "-o", str(out)], env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    assert "15.755-50.755" in res.output and "15.76" not in res.output
    assert "identified from log15 t 15.755:50.755 s" in (out / "identified.yaml").read_text()


def test_identify_with_a_delay_writes_it_in_controller_samples(tmp_path):
    """`--delay` ended in "internal error TypeError: Object of type bool is not JSON serializable": the
    delay's rule (not negative) judged a NumPy float, and numpy.bool went into identified.json. On log10's
    window the page's numbers: about 9.5 ms beside T_m about 0.056 s, written as 5 samples at 500 Hz."""
    out = tmp_path / "o"
    res = CliRunner().invoke(app, ["identify", str(FLIGHTS / "log10"), "-c", "crazyflie", "--window", "8.67:38.67",
                                   "--delay", "-o", str(out)])
    assert res.exit_code == 0, res.output
    thrust = json.loads((out / "identified.json").read_text())["stages"]["thrust"]["parameters"]
    assert thrust["delay"]["passes_rule"] is True and thrust["delay"]["value"] == pytest.approx(0.0095, abs=1e-3)
    assert thrust["T_m"]["value"] == pytest.approx(0.056, abs=2e-3)
    assert "delay: {samples: 5}" in (out / "identified.yaml").read_text()
