"""A mission's verdict: a missed waypoint or a final tracking error above the tolerance is a failed check
(exit 1) in ``simulate``, ``run`` and ``report``, named by the cause the run shows; the sweep's reason
column says the same."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from quadctl import config, run_summary, sweep
from quadctl.cli.app import app
from quadctl.config.template import config_text
from quadctl.present.mission import mission_text
from quadctl.run_summary import MissionVerdict, mission_check

runner = CliRunner()

LENGTHEN = "lengthen simulation.duration"
LOOSEN = "loosen simulation.reference.tolerance"
PARTITION = "in no regulated subsystem of the partition"
HOLD = "{waypoints: [{position: [1, 0, -1], yaw: 1.5708, hold: 8}]}"
"""The hold of the issue that drifted 2.54 m off with the error in the earth frame (a 15 s run)."""


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


def _tracking(reached, final: float = 0.0) -> dict:
    return {"position_error": {"rms": 0.01, "peak": 0.1, "final": final}, "tolerance": 0.1, "mission_end": 12.75,
            "waypoints": [{"position": [2.0, 0.0, -1.0], "reached": r} for r in reached]}


CAUSES = [  # (keywords of mission_check, the verdict, words its sentence has, words it must not have)
    ({"unregulated": ("pN", "pE"), "status": "left_valid_range", "saturates": True, "duration": 5.0},
     MissionVerdict.NOT_REGULATED, ("position pN, pE are " + PARTITION, "add pN, pE"), (LENGTHEN, LOOSEN)),
    ({"unregulated": ("pD",)}, MissionVerdict.NOT_REGULATED, ("position pD is " + PARTITION,), (LENGTHEN,)),
    ({"status": "left_valid_range", "saturates": True, "duration": 5.0}, MissionVerdict.LEFT_VALID_RANGE,
     ("left the model's valid range",), (LENGTHEN, LOOSEN)),
    ({"saturates": True, "duration": 5.0}, MissionVerdict.SATURATED, ("at their limits",), (LENGTHEN, LOOSEN)),
    ({"duration": 5.0}, MissionVerdict.RUN_ENDS_BEFORE_MISSION,
     ("the run ends at 5 s, before the mission does (12.75 s): lengthen simulation.duration to at least 12.75 s",),
     (LOOSEN,)),
    ({"duration": 15.0}, MissionVerdict.MISSED, (LOOSEN, "the whole mission was flown"), (LENGTHEN,)),
]


@pytest.mark.parametrize("kwargs, verdict, said, unsaid", CAUSES,
                         ids=[f"{c[1].value}-{i}" for i, c in enumerate(CAUSES)])
def test_a_missed_waypoint_is_named_by_the_first_cause_the_run_shows(kwargs, verdict, said, unsaid):
    tracking = _tracking([1.8, None])
    tracking.update(mission_check(tracking, **kwargs))
    assert tracking["verdict"] == verdict.value and tracking["missed"] == [1]
    text = mission_text(tracking)
    assert text.startswith("simulation.reference.waypoints[1] [2, 0, -1] was never reached within 0.1 m (1 of 2 ")
    for words in said:
        assert words in text
    for words in unsaid:
        assert words not in text


def test_a_final_error_above_the_tolerance_fails_though_every_waypoint_was_reached():
    tracking = _tracking([1.8, 5.0], final=0.25)
    tracking.update(mission_check(tracking, duration=15.0))
    assert tracking["verdict"] == "missed" and tracking["final_above_tolerance"] and not tracking["missed"]
    assert mission_text(tracking).startswith("the final tracking error 0.25 m is above simulation.reference.tolerance")


@pytest.mark.parametrize("final", [0.0, 0.1])
def test_a_mission_reached_and_ended_within_the_tolerance_passes(final):
    tracking = _tracking([1.8, 5.0], final=final)
    tracking.update(mission_check(tracking, unregulated=("pN",), status="diverged", saturates=True, duration=1.0))
    assert tracking["verdict"] == "reached" and mission_text(tracking) is None


def test_only_a_position_the_mission_moves_along_is_named():
    """The partition is blamed for the axes the waypoints leave the trim along, not for every free one."""
    from quadctl.setup import setup_of

    data = config.parse(config_text("free", flight="hover"), "free.yaml").model_dump(mode="json")
    start = data["trim"]["position_ned"]
    data["simulation"]["reference"] = {"waypoints": [{"position": [start[0] + 1.0, start[1], start[2]]}]}
    assert run_summary.unregulated_positions(setup_of(config.from_dict(data, "free.yaml"))) == ("pN",)


@pytest.mark.parametrize("setpoints, ignored", [
    ([{"t": 1.0, "position": [1.0, 0.0, -1.0]}], ("pN",)),  # a step north, pN free
    ([{"t": 1.0, "position": [0.0, 0.0, -1.5]}], ()),  # a climb: pD is the altitude loop's
    ([{"t": 0.0, "position": [0.0, 0.5, -1.0]}, {"t": 2.0, "position": [0.0, 0.5, -1.0]}], ("pE",)),
    ([{"t": 1.0, "velocity": [1.0, 0.0, 0.0]}], ()),  # a velocity: flown by the velocity loop
    ([{"t": 1.0, "velocity": [1.0, 0.0, 0.0]}, {"t": 2.0, "position": [1.0, 0.0, -1.0]}], ()),  # where it is
])
def test_setpoints_that_step_a_free_position_are_named(setpoints, ignored):
    """A setpoint's position step on an axis no regulated subsystem holds is not flown: those axes are named;
    a step on a regulated one, a velocity, and a position the reference already holds are not."""
    from quadctl.setup import setup_of

    data = config.parse(config_text("free", flight="hover"), "free.yaml").model_dump(mode="json")
    data["trim"]["position_ned"] = [0.0, 0.0, -1.0]
    data["simulation"]["reference"] = {"setpoints": setpoints}
    assert run_summary.ignored_position_steps(setup_of(config.from_dict(data, "free.yaml"))) == ignored


def test_simulate_warns_that_a_position_step_on_a_free_axis_is_not_flown(free, tmp_path):
    """``hover``'s partition leaves pN free: a setpoint 1 m north ended 1.18 m off it with exit 0 and no word."""
    res = invoke("simulate", "-c", free, "-o", tmp_path, "--set",
                 "simulation.reference={setpoints: [{t: 1, position: [1, 0, -1]}]}", "--set", "simulation.duration=2")
    assert res.exit_code == 0, res.output
    assert ("quadctl: warning: simulation.reference.setpoints step position pN, " + PARTITION) in res.stderr


def test_the_report_s_reference_section_warns_that_a_position_step_on_a_free_axis_is_not_flown(free, tmp_path):
    res = invoke("report", "-c", free, "-o", tmp_path, "--set",
                 "simulation.reference={setpoints: [{t: 1, position: [1, 0, -1]}]}", "--set", "simulation.duration=2")
    assert res.exit_code == 0, res.output
    page = (tmp_path / "report" / "report.md").read_text()
    section = page[page.index("## Reference"):]
    assert "⚠ simulation.reference.setpoints step position pN, " + PARTITION in section


# ---------------------------------------------------------------------------------------------
# the commands


@pytest.fixture(scope="module")
def free(tmp_path_factory):
    """``quadctl init --flight hover``'s config (pN, pE analysed only) told to fly to a waypoint 1 m north."""
    folder = tmp_path_factory.mktemp("free")
    path = folder / "free.yaml"
    path.write_text(config_text("free", flight="hover"))
    return path


@pytest.mark.parametrize("command", ["simulate", pytest.param("run", marks=pytest.mark.slow), "report"])
def test_a_free_position_design_told_to_reach_a_waypoint_fails_naming_the_partition(free, command, tmp_path):
    res = invoke(command, "-c", free, "-o", tmp_path, "--set",
                 "simulation.reference={waypoints: [{position: [1, 0, -1]}]}")
    assert res.exit_code == 1, res.output
    assert "quadctl: check failed: " in res.stderr and "waypoints[0] [1, 0, -1] was never reached" in res.stderr
    assert "position pN is " + PARTITION in res.stderr and LENGTHEN not in res.stderr


@pytest.mark.parametrize("command", ["simulate", "run"])
def test_a_run_shorter_than_the_mission_fails_and_says_to_lengthen_it(command, tmp_path):
    res = invoke(command, "-c", "square", "-o", tmp_path, "--set", "simulation.duration=5")
    assert res.exit_code == 1, res.output
    assert "the run ends at 5 s, before the mission does (12.75 s): lengthen simulation.duration to at least " \
           "12.75 s" in res.stderr
    if command == "simulate":  # its last line: the run completed, its mission did not
        assert "mission not flown: completed" in res.stdout and "ok: completed" not in res.stdout


def test_a_fixed_design_holds_a_waypoint_a_quarter_turn_from_its_trim(tmp_path):
    """The issue's hold: 2.54 m off and drifting with exit 0 before; now reached, and exit 0 says so."""
    res = invoke("simulate", "-c", "square", "-o", tmp_path, "--set", f"simulation.reference={HOLD}")
    assert res.exit_code == 0, res.stderr
    assert "waypoints: 1 of 1 reached within 0.1 m" in res.output and "check failed" not in res.stderr


# ---------------------------------------------------------------------------------------------
# the sweep's reason


@pytest.mark.compiler
@pytest.mark.parametrize("fast", [True, False])
def test_the_sweeps_reason_names_a_mission_that_outlasts_the_run(fast):
    cfg = config.load("square")
    spec = sweep.from_dict({"parameters": {"simulation.duration": [5.0, 13.0]}}, cfg, "durations.yaml")
    rows = sweep.run(cfg, spec, jobs=1, fast=fast).rows
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert rows[0]["reason"].startswith("simulation.reference.waypoints[1] [2, 2, -1.5] was never reached")
    assert LENGTHEN + " to at least 12.75 s" in rows[0]["reason"]
    assert rows[1]["reason"] == "" and rows[1]["waypoints.reached"] == 4
