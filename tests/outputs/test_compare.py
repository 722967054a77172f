"""``quadctl compare``: the LQR design and the stacks' PID cascades flown through one disturbance realization."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from quadctl import metrics
from quadctl.cli.app import app

pytestmark = pytest.mark.compiler


@pytest.fixture(scope="module", params=["wind", "wind+noise"])
def gusty_crazyflie(request):
    """The bundled crazyflie config with a gust and turbulence (and sensor and process noise, whose
    period then sets the clock; without noise the clock is the LQR controller's)."""
    import quadctl as qc
    from quadctl.config import Config

    data = qc.load_config("crazyflie").model_dump(mode="json")
    if request.param == "wind+noise":
        data["simulation"]["noise"] = {"seed": 7, "force": [0.002, 0.002, 0.002],
                                       "sensor": {"pD": 0.005, "phi": 0.002, "p": 0.01}}
    data["simulation"].update(
        duration=2.0, wind={"gusts": [{"start": 0.5, "length": 0.5, "amplitude": [1.0, 0.5, 0.0]}],
                            "turbulence": {"intensity": "light", "seed": 3}})
    return qc.Stages(qc.setup_of(Config(**data)))


def test_compare_feeds_every_law_the_same_noise_and_wind(gusty_crazyflie):
    from quadctl.compare import compare

    result = compare(gusty_crazyflie, ["pid:crazyflie", "pid:px4"])
    assert [law.name for law in result.laws] == ["lqr", "pid:crazyflie", "pid:px4"]
    assert result.identical_disturbances
    # the wind each plant felt, at the instants all three runs recorded (500, 500 and 400 Hz loops)
    times = [np.round(law.run.t, 9) for law in result.laws]
    common = sorted(set(times[0]).intersection(*map(set, times[1:])))
    assert len(common) > 50
    felt = [law.run.wind[np.searchsorted(t, common)] for law, t in zip(result.laws, times)]
    assert np.abs(felt[0]).max() > 0.5  # the gust is in there
    for other in felt[1:]:
        np.testing.assert_array_equal(other, felt[0])


def test_on_the_mambo_both_laws_fly_the_same_noise_and_gusts():
    """mambo-200hz (its own sensor and process noise, a gust added): the 200 Hz LQR design and the 500 Hz
    cascade read the same rows (one digest) and their plants felt the same wind at the instants both recorded."""
    import quadctl as qc
    from quadctl.compare import compare
    from quadctl.config import Config

    data = qc.load_config("mambo-200hz").model_dump(mode="json")
    gust = {"start": 0.2, "length": 0.4, "amplitude": [1.0, 0.5, 0.0]}
    data["simulation"].update(duration=1.0, wind={"gusts": [gust], "turbulence": {"intensity": "light", "seed": 5}})
    result = compare(qc.Stages(qc.setup_of(Config(**data))), ["pid:crazyflie"])
    assert result.identical_disturbances and result.noise_seed is not None
    assert [law.rate for law in result.laws] == [200.0, 500.0]
    times = [np.round(law.run.t, 9) for law in result.laws]
    common = sorted(set(times[0]) & set(times[1]))
    assert len(common) > 50
    felt = [law.run.wind[np.searchsorted(t, common)] for law, t in zip(result.laws, times)]
    assert np.abs(felt[0]).max() > 0.5
    np.testing.assert_array_equal(felt[1], felt[0])


def test_without_one_clock_the_wind_rows_of_loops_of_different_rates_differ(gusty_crazyflie):
    """What the shared clock prevents: a 400 Hz loop on its own clock reads other turbulence rows."""
    from quadctl.compare import disturbance_digest

    setup = gusty_crazyflie.setup
    own = disturbance_digest(None, setup.wind, 400.0, 1 / 400.0, 2.0)
    shared = disturbance_digest(None, setup.wind, 400.0, 1 / 500.0, 2.0)
    assert own != shared


def test_compare_command_writes_the_table_and_json_with_units_and_the_report_shows_them(tmp_path):
    res = CliRunner().invoke(app, ["compare", "-c", "crazyflie", "--set", "simulation.duration=1", "-o", str(tmp_path),
                                   "--json", "--plot"],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["identical_disturbances"] is True
    assert [law["name"] for law in data["laws"]] == ["lqr", "pid:crazyflie"]
    assert data["units"]["position_rms"] == "m" and data["units"]["saturated"] == "s"
    assert json.loads((tmp_path / "compare.json").read_text())["laws"][1]["rate"] == 500.0
    # margins: the LQR design's loops on the coupled model, the cascade's lifted; the row the least of each law's
    assert data["units"]["gain_margin"] == "dB" and data["units"]["phase_margin"] == "deg"
    lqr, pid = data["laws"]
    assert {m["model"] for m in lqr["margins"]} == {"coupled"}
    assert [(m["model"], m["input"]) for m in pid["margins"]] == [("cascade", s) for s in "TAER"]
    for law in data["laws"]:
        least = min(min(float(m["gain_margin_upper_db"]), -float(m["gain_margin_lower_db"])) for m in law["margins"])
        assert law["gain_margin"] == pytest.approx(least)
        assert law["phase_margin"] == pytest.approx(min(float(m["phase_margin_deg"]) for m in law["margins"]))
    # the report of the same config in the same folder shows the table and the figures; of another, says so
    from quadctl.cli.options import open_workspace
    from quadctl.report import content

    section = content.comparison(open_workspace("crazyflie", tmp_path, sets=["simulation.duration=1"]))
    assert section.blocks[0].columns == ("metric", "lqr", "pid:crazyflie")
    assert sorted(b.name for b in section.blocks if hasattr(b, "png")) == [
        "compare-altitude", "compare-attitude-error", "compare-position-error", "compare-rotor-use"]
    stale = content.comparison(open_workspace("crazyflie", tmp_path, sets=["simulation.duration=2"]))
    assert "made from another config" in stale.blocks[0].text


def test_compare_refuses_an_unknown_law_in_one_line(tmp_path):
    res = CliRunner().invoke(app, ["compare", "-c", "crazyflie", "--law", "pid:betaflight", "-o", str(tmp_path)])
    assert res.exit_code == 2
    assert "pid:<preset>" in res.output and "Traceback" not in res.output


def test_compare_refuses_a_cascade_without_rotors_in_one_line_before_any_run(tmp_path):
    """hover has no motors: the default law (the Crazyflie's cascade) has no rotors to command: the line
    controller.flies=pid gives, with compare's own way out, before the trim, the design or a run."""
    import quadctl as qc
    from quadctl.compare import compare
    from quadctl.config.pid import NEEDS_ROTORS
    from quadctl.errors import ConfigError

    stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    with pytest.raises(ConfigError, match=r"law pid:px4: a PID cascade commands the rotors: add motors: .*--law lqr"):
        compare(stages, ["pid:px4"])
    assert not {"trim", "linear", "design", "lqr_loop"} & set(vars(stages))  # nothing computed
    res = CliRunner().invoke(app, ["compare", "-c", "hover", "-o", str(tmp_path)])
    assert res.exit_code == 2, res.output
    assert res.output.count("\n") == 1 and "Traceback" not in res.output
    assert f"law pid:crazyflie: {NEEDS_ROTORS}, or compare the LQR design alone (--law lqr)" in res.output
    assert not (tmp_path / "compare.json").exists()
    flies = CliRunner().invoke(app, ["simulate", "-c", "hover", "--set", "controller.flies=pid", "-o", str(tmp_path)])
    assert flies.exit_code == 2 and f"{NEEDS_ROTORS}, or fly lqr" in flies.output


def test_a_refused_compare_leaves_no_empty_run_folder_behind(tmp_path):
    """compare took its run folder before it refused a cascade without rotors: runs/x stayed, empty."""
    res = CliRunner().invoke(app, ["compare", "-c", "hover", "--law", "pid:crazyflie", "-o", str(tmp_path / "x" / "y")])
    assert res.exit_code == 2, res.output
    assert not (tmp_path / "x").exists()


def test_compare_of_the_lqr_design_alone_flies_without_rotors_and_says_nothing_of_cascades(tmp_path):
    """hover (no motors:, a continuous design) with --law lqr: the rotors' metrics '-' (None in compare.json),
    no rotor-use figure, the infinite gain margin shown as such, no word of a PID cascade."""
    res = CliRunner().invoke(app, ["compare", "-c", "hover", "--law", "lqr", "--set", "simulation.duration=0.5",
                                   "-o", str(tmp_path), "--plot"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    (law,) = json.loads((tmp_path / "compare.json").read_text())["laws"]
    assert law["name"] == "lqr" and law["rotor_peak"] is law["rotor_rms"] is law["saturated"] is None
    assert law["gain_margin"] == "inf" and law["position_rms"] > 0
    rows = {line.split("│")[1].strip(): line.split("│")[2].strip() for line in res.output.splitlines()
            if line.count("│") == 3}
    assert rows["rotor peak"] == rows["saturated [s]"] == "-" and rows["gain margin [dB]"] == "inf"
    out = " ".join(res.output.split())
    assert "leaves pN and pE free" in out and "PID" not in out and "cascade" not in out
    assert "One law flew, through no random disturbances" in out and "Every law" not in out
    assert sorted(p.name for p in (tmp_path / "plots").glob("compare-*.png")) == [
        "compare-altitude.png", "compare-attitude-error.png", "compare-position-error.png"]


@pytest.mark.parametrize(("laws", "said"), [
    (["lqr"], "its position error stays or drifts."),
    (["lqr", "pid:px4"], "where the PID cascade's position loop removes its own."),
    (["lqr", "pid:crazyflie", "pid:px4"], "where the PID cascades' position loops remove theirs."),
])
def test_the_free_position_note_speaks_of_cascades_only_when_they_are_compared(laws, said):
    from quadctl.present.compare import free_position_sentence

    sentence = free_position_sentence(("pD", "phi", "theta", "psi"), laws)
    assert sentence.endswith(said) and ("PID" in sentence) == (len(laws) > 1)
    assert free_position_sentence(("pN", "pE", "pD"), laws) is None


def test_the_table_title_keeps_the_duration_and_its_unit_on_one_line():
    """rich wraps a title longer than its table at any space, a non-breaking one too: at every config name
    length the title's duration stays beside its unit (without the non-breaking space, some break as `10` / `s`)."""
    import io

    from rich.console import Console

    from quadctl.cli import render
    from quadctl.compare import METRICS
    from quadctl.present import compare as words

    law = {"name": "lqr", "rate": 500.0, "status": "ok", "disturbances": "0" * 64} | {m: 0.5 for m, _, _ in METRICS}
    for n in range(1, 40):
        data = {"config": "c" * n, "duration": 10.0, "laws": [law]}
        console = Console(width=200, file=io.StringIO())
        console.print(render.table(words.table(data)))
        lines = [line.rstrip() for line in console.file.getvalue().splitlines()]
        assert "10 s" in " ".join(lines[:3]) and not any(line.endswith("10") for line in lines), lines[:3]


def test_an_unstable_law_has_no_margins_in_the_table_or_compare_json(tmp_path):
    """PX4's defaults on the Crazyflie: the cascade's closed loop is unstable, so it has no margin: `unstable`
    in the table (not 0 dB, which reads as a loop at the edge), null in compare.json beside
    "closed_loop_stable": false and each loop's "stable": false; the LQR design's stay numbers."""
    res = CliRunner().invoke(app, ["compare", "-c", "crazyflie", "--law", "pid:px4", "--set", "simulation.duration=0.1",
                                   "-o", str(tmp_path), "--json"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    lqr, px4 = json.loads((tmp_path / "compare.json").read_text())["laws"]
    assert px4["closed_loop_stable"] is False and px4["gain_margin"] is None and px4["phase_margin"] is None
    assert all(m["stable"] is False and m["gain_margin_upper_db"] is None and m["phase_margin_deg"] is None
               for m in px4["margins"])
    assert lqr["closed_loop_stable"] is True and lqr["gain_margin"] > 6.0 and lqr["phase_margin"] > 30.0
    from quadctl.cli import render
    from quadctl.present import compare as words

    table = words.table(json.loads((tmp_path / "compare.json").read_text()))
    rows = {row[0]: row[1:] for row in table.rows}
    assert rows["gain margin [dB]"][1] == rows["phase margin [deg]"][1] == "unstable"
    assert rows["gain margin [dB]"][0] == f"{lqr['gain_margin']:.4g}"
    assert "unstable: the law's closed loop is unstable, so it has no margin" in table.caption
    assert render.table(table) is not None


def test_a_noisy_runs_late_settling_is_noise_limited_and_a_drift_is_never():
    """The position error of a law decaying to a noise floor inside its 2 % band crosses the band in the run's
    last tenth: with noise it has no settling time and is named noise-limited (the table says `noise`); the
    same run without noise keeps the time; a position the law leaves free drifts and never settles, which
    is no noise."""
    from types import SimpleNamespace

    from quadctl.compare import metrics_of
    from quadctl.layout import N_STATES
    from quadctl.present import compare as words

    t = np.linspace(0.0, 10.0, 2001)
    rng = np.random.default_rng(0)
    x = np.zeros((len(t), N_STATES))
    x[:, 0] = np.exp(-2.0 * t) + 0.03 * rng.standard_normal(len(t))  # the noise crosses the 0.02 m band to the end
    run = SimpleNamespace(t=t, x=x, x_ref=np.zeros_like(x), u=np.zeros((len(t), 4)), status="ok")
    loop = SimpleNamespace(u_trim=np.zeros(4), actuators=None)
    Q, R = np.eye(N_STATES), np.eye(4)
    noisy = metrics_of(run, loop, Q, R, noisy=True)
    assert noisy["settling"] is None and noisy["settling_noise_limited"] is True
    quiet = metrics_of(run, loop, Q, R)
    assert quiet["settling"] > 9.0 and quiet["settling_noise_limited"] is False
    drift = SimpleNamespace(**{**vars(run), "x": np.column_stack([0.1 * t, x[:, 1:]])})
    never = metrics_of(drift, loop, Q, R, noisy=True)
    assert never["settling"] is None and never["settling_noise_limited"] is False
    # under turbulence the run is read against its twin, the law's run without it: noise-limited when the
    # twin settles (the decay alone), never settled when the twin does not (a slow decay still outside its band)
    gusts = metrics.Disturbance.GUSTS
    calm = SimpleNamespace(**{**vars(run), "x": np.column_stack([np.exp(-2.0 * t), x[:, 1:] * 0])})
    slow = SimpleNamespace(**{**vars(calm), "x": np.column_stack([np.exp(-0.2 * t), x[:, 1:] * 0])})
    assert metrics_of(run, loop, Q, R, noisy=gusts, twin=calm)["settling_noise_limited"] is True
    unsettled = metrics_of(run, loop, Q, R, noisy=gusts, twin=slow)
    assert unsettled["settling"] is None and unsettled["settling_noise_limited"] is False
    law = {"name": "lqr", "rate": 500.0, "status": "ok", **noisy}
    rows = dict((row[0], row[1]) for row in words.table({"config": "c", "duration": 10.0, "laws": [law]}).rows)
    assert rows["settling [s]"] == "noise"


def test_compare_says_when_the_cascade_reads_filtered_rates_and_the_lqr_design_raw_ones(tmp_path):
    """The Crazyflie's cascade flies behind its sensor driver's 80 Hz gyro low-pass, which the firmware runs for
    every controller; crazyflie's LQR design has no controller.filters, so its margins read better than the
    vehicle gives them beside the cascade's. compare.json says what each law reads its rates through, and the
    table is followed by the warning with the --set that compares them behind the same filter."""
    res = CliRunner().invoke(app, ["compare", "-c", "crazyflie", "-o", str(tmp_path / "raw")])
    assert res.exit_code == 0, res.output
    data = json.loads((tmp_path / "raw" / "compare.json").read_text())
    assert [law["gyro_filter"] for law in data["laws"]] == [None, "second-order low-pass at 80 Hz"]
    assert [law["gyro_lowpass_hz"] for law in data["laws"]] == [None, 80.0]  # the --set the warning names
    text = " ".join(res.output.split())
    assert ("Not like for like: the PID cascade reads the body rates behind its flight stack's gyro low-pass "
            "(pid:crazyflie: second-order low-pass at 80 Hz)") in text
    assert "--set controller.filters.gyro.cutoff=80, to compare them behind the same one." in text
    res = CliRunner().invoke(app, ["compare", "-c", "crazyflie", "-o", str(tmp_path / "same"),
                                   "--set", "controller.filters.gyro.cutoff=80"])
    assert res.exit_code == 0, res.output
    same = json.loads((tmp_path / "same" / "compare.json").read_text())
    assert [law["gyro_filter"] for law in same["laws"]] == ["second-order low-pass at 80 Hz"] * 2
    assert "Not like for like" not in res.output
    # behind the filter the LQR design's least gain margin is what the vehicle has: lower than on raw rates
    assert same["laws"][0]["gain_margin"] < data["laws"][0]["gain_margin"]
    # a compare.json written before gyro_lowpass_hz (its filter in words only): the report, which reads the file
    # the run folder keeps, still warns, naming the key to set (it stopped with an internal KeyError)
    for law in data["laws"]:
        del law["gyro_lowpass_hz"]
    (tmp_path / "raw" / "compare.json").write_text(json.dumps(data))
    res = CliRunner().invoke(app, ["report", "-c", "crazyflie", "-o", str(tmp_path / "raw")])
    assert res.exit_code == 0, res.output
    page = " ".join((tmp_path / "raw" / "report" / "report.md").read_text().split())
    assert ("(pid:crazyflie: second-order low-pass at 80 Hz)" in page
            and "Give the LQR design the stack's filter, controller.filters.gyro, to compare them" in page)


def test_compare_exits_1_when_the_lqr_design_fails_and_keeps_what_it_wrote(tmp_path):
    """crazyflie flown on a 0.1 s rotor lag its design ignores: the LQR design turns over (diverged) and its
    closed loop is unstable, as simulate and margins would say (exit 1, one line each); compare.json is kept."""
    res = CliRunner().invoke(app, ["compare", "-c", "crazyflie", "--set", "motors.time_constant=0.1",
                                   "--set", "simulation.duration=3", "-o", str(tmp_path)])
    assert res.exit_code == 1, res.output
    failed = [line for line in res.output.splitlines() if line.startswith("quadctl: check failed:")]
    assert len(failed) == 2 and "lqr: diverged at t = " in failed[0] and "turned over" in failed[0]
    assert "saved" not in failed[0]  # compare keeps the run's metrics, not its steps
    assert failed[1] == "quadctl: check failed: lqr: the closed loop is unstable (no margins)"
    lqr, pid = json.loads((tmp_path / "compare.json").read_text())["laws"]
    assert (lqr["status"], lqr["closed_loop_stable"]) == ("diverged", False)
    assert (pid["status"], pid["closed_loop_stable"]) == ("ok", True)


def test_a_cascade_that_fails_is_the_finding_and_compare_exits_0(tmp_path):
    """A sample of delay leaves the firmware's cascade unstable on the bundled crazyflie (its rate loop crosses
    over near 90 Hz) and the LQR design stable: the cascade's column says so, the exit code does not."""
    res = CliRunner().invoke(app, ["compare", "-c", "crazyflie", "--set", "controller.delay.samples=1",
                                   "--set", "simulation.duration=2", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.output
    lqr, pid = json.loads((tmp_path / "compare.json").read_text())["laws"]
    assert lqr["closed_loop_stable"] is True and pid["closed_loop_stable"] is False
    assert "check failed" not in res.output


def test_design_failures_name_the_lqr_designs_run_and_loop_and_never_a_cascades():
    """The rule behind compare's exit code, on stand-in laws: the LQR design's stopped run and unstable loop,
    one line each; a failed cascade's, nothing."""
    from types import SimpleNamespace as NS

    from quadctl.compare import Comparison

    def law(name, status, *stable):
        return NS(name=name, run=NS(status=status, message=f"{status} at t = 1 s; saved 50 steps"),
                  margins=tuple(NS(stable=s) for s in stable))

    def failures(*laws):
        return Comparison("x", 1.0, 0.01, laws, None, None).design_failures

    assert failures(law("lqr", "ok", True, True), law("pid:crazyflie", "diverged", False)) == []
    assert failures(law("lqr", "diverged", True, False), law("pid:px4", "ok", True)) == [
        "lqr: diverged at t = 1 s", "lqr: the closed loop is unstable (no margins)"]
    assert failures(law("lqr", "left_valid_range")) == ["lqr: left_valid_range at t = 1 s"]
    assert failures(law("pid:crazyflie", "diverged", False)) == []


@pytest.mark.parametrize("law, near", [("pid:crazyfly", "pid:crazyflie"), ("PID:px4", "pid:px4"), ("LQR", "lqr"),
                                       ("pid:betaflight", None)])
def test_a_mistyped_law_gets_the_nearest_one(law, near):
    """--law pid:crazyfly listed the presets but named none of them: the other choices of the command line
    (--to, --from, --mode) say `did you mean`; a law far from all (betaflight) gets the list alone."""
    from quadctl.compare import parse_law
    from quadctl.errors import ArgumentError

    message = str(pytest.raises(ArgumentError, parse_law, law).value)
    assert message.startswith(f"law {law!r}: use lqr or pid:<preset> with a preset of crazyflie, px4")
    assert message.endswith(f"; did you mean `{near}`?" if near else "px4")
