"""`quadctl check`'s verdict: exit 1 when a regulated loop cannot work, at the config's rate or a what-if one."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _paths import ROOT
from typer.testing import CliRunner

from quadctl import config, pipeline
from quadctl.cli.app import app
from quadctl.design import discrete
from quadctl.setup import setup_of

REPORT_AT_200HZ = ROOT / "docs" / "configs" / "report-at-200hz.yaml"
UNSTABLE_AT_200HZ = "sampled at 200 Hz the continuous design's loop(s) roll, pitch, yaw, coupled are UNSTABLE"


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


def flat(text: str) -> str:
    return " ".join(text.split())


def test_the_report_gains_really_are_unstable_at_200hz():
    """The verdict's physics: the roll loop's continuous gain on the 200 Hz ZOH plant has an
    eigenvalue outside the unit circle (independently of check's own code path)."""
    setup = setup_of(config.load("forward"))
    linear = pipeline.linear_of(setup, pipeline.trim_of(setup))
    dec = pipeline.decoupled_of(setup, linear)
    des = pipeline.design_of(setup, dec, linear)
    roll = next(s for s in des.subsystems if s.name == "roll")
    Ad, Bd = discrete.c2d(dec["roll"].A, dec["roll"].B, 1 / 200)
    assert np.abs(np.linalg.eigvals(Ad - Bd @ roll.K)).max() > 1.0


@pytest.mark.parametrize("args", [("-c", "forward", "--rate", 200), ("-c", REPORT_AT_200HZ)],
                         ids=["what-if --rate", "the config's own rate"])
def test_check_exits_1_when_a_sampled_loop_is_unstable(tmp_path, args):
    res = invoke("check", *args, "-o", tmp_path)
    assert res.exit_code == 1, res.output
    out = flat(res.output)
    assert f"quadctl: check failed: {UNSTABLE_AT_200HZ}; design for the rate (controller.rate: 200 with " \
           "controller.design: discrete) or use smaller gains (larger R)" in out
    assert (tmp_path / "checks.json").exists()  # the verdict comes after the artifact


def test_check_json_still_parses_when_the_check_fails(tmp_path):
    res = CliRunner().invoke(app, ["check", "-c", "forward", "--rate", "200", "-o", str(tmp_path),
                                                   "--json"])
    assert res.exit_code == 1
    data = json.loads(res.stdout)
    assert data["what_if_rate"]["rate"] == 200 and len(data["what_if_rate"]["warnings"]) == 4
    assert UNSTABLE_AT_200HZ in flat(res.stderr)


@pytest.mark.parametrize("args", [("-c", "forward"), ("-c", "forward", "--rate", 100_000), ("-c", "mambo-200hz")],
                         ids=["no rate", "a rate fast enough", "a discrete design"])
def test_check_passes_loops_that_work(tmp_path, args):
    res = invoke("check", *args, "-o", tmp_path)
    assert res.exit_code == 0, res.output
    assert "check failed" not in res.output


def test_run_stops_at_check_with_the_same_verdict(tmp_path):
    res = invoke("run", "-c", REPORT_AT_200HZ, "-o", tmp_path)
    assert res.exit_code == 1, res.output
    assert f"quadctl: check failed: check: {UNSTABLE_AT_200HZ}" in flat(res.output)
    assert "✓ check" not in res.output and not (tmp_path / "sim.npz").exists()


def test_the_slowest_rate_check_takes_is_a_verdict_not_a_crash(tmp_path):
    """At --rate's lower bound (1e-9 Hz: a sample every 30 years) the sampled loops overflow: that
    is an unstable loop (spectral radius inf), said in one line, exit 1."""
    res = invoke("check", "-c", "hover", "--rate", "1e-9", "-o", tmp_path)
    assert res.exit_code == 1
    assert "quadctl: check failed: sampled at 1e-09 Hz the continuous design's loop(s)" in flat(res.output)
    assert "spectral radius inf" in flat(res.output) and "Traceback" not in res.output


@pytest.mark.parametrize("command", [("check",), ("export", "--to", "c")])
def test_a_rate_beside_the_configs_own_is_refused_alike_by_check_and_export(tmp_path, command):
    """check used to ignore --rate on a discrete design (mambo-200hz: 200 Hz) while export refused it."""
    res = invoke(*command, "-c", "mambo-200hz", "--rate", 100, "-o", tmp_path)
    assert res.exit_code == 2, res.output
    assert res.stderr.strip() == ("quadctl: error: mambo-200hz.yaml: --rate 100: the config sets controller.rate "
                                  "= 200 Hz; drop --rate, or remove controller.rate to run the continuous design at "
                                  "another rate")
    assert not (tmp_path / "checks.json").exists()


def test_a_rate_equal_to_a_discrete_configs_own_checks_the_discrete_design(tmp_path):
    """forward designed discrete at 200 Hz passes check; --rate 200 made check test the *continuous* design at
    200 Hz instead (unstable: exit 1, "use a discrete design") though the config is one."""
    text = config.locate("forward").text.replace("name: forward\n",
                                                  "name: forward\ncontroller: {rate: 200, design: discrete}\n")
    (tmp_path / "c.yaml").write_text(text)
    plain = invoke("check", "-c", tmp_path / "c.yaml", "-o", tmp_path / "a")
    again = invoke("check", "-c", tmp_path / "c.yaml", "--rate", 200, "-o", tmp_path / "b")
    assert plain.exit_code == again.exit_code == 0, again.output
    assert "UNSTABLE" not in again.stderr


def test_check_judges_the_loop_a_kalman_filter_flies(tmp_path):
    """With only an estimator beside the design, check's closed loop is the plant and the filter together
    (the margins' verdict: tests/design/test_lqg_vehicle_loop.py checks its eigenvalues), not null."""
    res = invoke("check", "-c", ROOT / "docs" / "configs" / "mambo-lqg.yaml", "-o", tmp_path)
    assert res.exit_code == 0, res.output
    assert "with the Kalman filter included (plant and estimator) the design's closed loop stays stable" in flat(
        res.output)
    loop = json.loads((tmp_path / "checks.json").read_text())["closed_loop"]
    assert loop["stable"] and loop["estimator"] and len(loop["eigenvalues"]) == 23


def test_a_measured_set_that_cannot_estimate_the_state_is_check_s_verdict_beside_a_delay(tmp_path):
    """With a delay the flown loop is judged; a filter that cannot be built (pN, pE, pD unobservable from the
    IMU) leaves the full-state loop judged and the verdict says why (exit 1), checks.json written."""
    res = invoke("check", "-c", ROOT / "docs" / "configs" / "mambo-lqg.yaml", "-o", tmp_path,
                 "--set", "controller.delay=0.005", "--set", "estimator.measure=[imu]")
    assert res.exit_code == 1, res.output
    assert "pN, pE, pD not observable" in flat(res.output)
    loop = json.loads((tmp_path / "checks.json").read_text())["closed_loop"]
    assert loop["estimator"] is None and loop["delay_samples"] == 1
