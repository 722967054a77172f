"""A flight of the PID cascade (``controller.flies: pid``) is judged by the cascade's lifted closed loop, not by
its run alone: an unstable mode can grow too slowly for a run to show it
(:func:`quadctl.stages.cascade_instability`)."""

from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from quadctl.cli.app import app
from quadctl.present.stages import unstable_cascade_text

pytestmark = pytest.mark.compiler


def test_the_doubling_time_is_that_of_the_radius_per_frame():
    """A radius of 2 ** (frame / T) doubles a mode every T s."""
    for frame_s, T in ((0.01, 1.77), (0.002, 0.25), (0.05, 30.0)):
        text = unstable_cascade_text("x", 2 ** (frame_s / T), frame_s)
        assert f"doubles every {T:.3g} s" in text and f"{frame_s * 1e3:.3g} ms frame" in text
    assert "does not decay" in unstable_cascade_text("x", 1.0, 0.01)


def test_a_cascade_one_sample_of_delay_destabilizes_fails_simulate_and_run_though_its_run_ends(tmp_path):
    """The stock cascade on the bundled crazyflie keeps 0.75 dB; one sample of delay leaves it unstable
    (quadctl margins says so). A 1 s run still ends: simulate and run exit 1 with the lifted loop's verdict,
    and the flight's artifacts are kept; the same cascade without the delay passes."""
    common = ["-c", "crazyflie", "--set", "controller.flies=pid", "--set", "simulation.duration=1"]
    delayed = ["--set", "controller.delay.samples=1"]
    res = CliRunner().invoke(app, ["simulate", *common, *delayed, "-o", str(tmp_path / "a")])
    assert res.exit_code == 1, res.output
    assert "ok: completed 1000 steps" in " ".join(res.output.split())
    (line,) = [x for x in res.output.splitlines() if x.startswith("quadctl: check failed:")]
    assert "the PID cascade (Crazyflie controller_pid) is unstable about hover" in line
    radius = float(line.split("spectral radius ")[1].split(" ")[0])
    CliRunner().invoke(app, ["margins", *common, "--set", "controller.delay.samples=1", "-o", str(tmp_path / "m")])
    closed = json.loads((tmp_path / "m" / "margins.json").read_text())["closed_loop"]
    assert not closed["stable"] and math.isclose(radius, closed["spectral_radius"], rel_tol=1e-4)
    assert (tmp_path / "a" / "sim.npz").exists()
    run = CliRunner().invoke(app, ["run", *common, "--set", "controller.delay.samples=1", "-o", str(tmp_path / "r")])
    assert run.exit_code == 1 and "check failed: simulate: the PID cascade" in " ".join(run.output.split())
    fine = CliRunner().invoke(app, ["simulate", *common, "-o", str(tmp_path / "b")])
    assert fine.exit_code == 0, fine.output
    assert "controller: the Crazyflie controller_pid cascade at 500 Hz (controller.flies: pid)" in fine.output
    ctl = json.loads((tmp_path / "b" / "sim.json").read_text())["controller"]
    assert (ctl["flies"], ctl["cascade"], ctl["sample_time"]) == ("pid", "Crazyflie controller_pid", 0.002)


def test_the_controller_line_names_the_law_that_flies():
    """A sampled design's line names the design; with controller.flies: pid, the cascade and its own rate
    (1 / its sample time), not the design's."""
    from types import SimpleNamespace as NS

    from quadctl.present.flight import controller_text

    sim = NS(plan=NS(method="rk4", schedule=()), dt=0.001)
    design = {"rate": 200.0, "design": "discrete", "hold_steps": 5, "sample_time": 0.005, "flies": "lqr",
              "cascade": None}
    assert controller_text({"controller": design}, sim).startswith("controller: discrete design at 200 Hz")
    cascade = design | {"flies": "pid", "cascade": "Crazyflie controller_pid", "sample_time": 0.002, "hold_steps": 2}
    assert controller_text({"controller": cascade}, sim) == (
        "controller: the Crazyflie controller_pid cascade at 500 Hz (controller.flies: pid), zero-order hold: one "
        "sample every 2 RK4 steps of 0.001 s")


def test_the_lqr_design_that_flies_is_not_judged_by_its_cascade():
    """Without controller.flies: pid the cascade neither flies nor is checked: the LQR design flies the delay."""
    import quadctl as qc
    from quadctl import stages

    data = qc.load_config("crazyflie").model_dump(mode="json")
    data["controller"]["delay"] = {"samples": 1}
    ws = qc.Stages(qc.setup_of(qc.Config(**data)))
    assert stages.cascade_instability(ws) is None
    assert "pid_lift" not in vars(ws)  # not even lifted
