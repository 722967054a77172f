"""Sampled, saturating and noisy loops through the CLI: margins, check --rate, design --full, saturation."""

from __future__ import annotations

import json

import pytest
import yaml
from _paths import ROOT
from _solve import cfg_dict
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app
from quadctl.errors import ConfigError

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


def flat(text: str) -> str:
    """Output with rich's line wrapping undone."""
    return " ".join(text.split())


def write(tmp_path, data: dict):
    path = tmp_path / f"{data['name']}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_margins_command_writes_the_table_json_and_figures(tmp_path):
    res = invoke("margins", "-c", "mambo-200hz", "-o", tmp_path, "--plot")
    assert res.exit_code == 0, res.output
    data = json.loads((tmp_path / "margins.json").read_text())
    assert data["rate"] == 200 and data["design"] == "discrete"
    assert {(m["loop"], m["model"]) for m in data["loops"]} == {
        (s, k) for s in ("altitude", "roll", "pitch", "yaw") for k in ("design", "coupled")}
    pngs = sorted((tmp_path / "plots").glob("margins-*.png"))
    assert len(pngs) == 8 and all(p.stat().st_size < 150_000 for p in pngs)
    out = flat(res.output)
    assert ("The continuous LQR guarantee (gain margin [1/2, inf), i.e. -6.02 dB to +inf, phase margin >= 60 deg) "
            "is a property of continuous state feedback that sampling does not keep") in out
    assert "short" not in out and "Disk margins of the sampled loops" in out
    least = min(data["loops"], key=lambda m: m["phase_margin_deg"])
    assert f"least phase margin {least['phase_margin_deg']:.3g} deg ({least['loop']}, {least['model']})" in out


def test_margins_of_the_report_gains_run_at_200hz_fail(tmp_path):
    data = cfg_dict("forward", name="report-at-200hz", controller={"rate": 200.0, "design": "continuous"})
    res = invoke("margins", "-c", write(tmp_path, data), "-o", tmp_path, "--design-only")
    assert res.exit_code == 1
    assert "unstable loop(s): roll (design), pitch (design), yaw (design)" in flat(res.output)


def test_check_warns_when_the_rate_cannot_realize_the_continuous_design(tmp_path):
    res = invoke("check", "-c", "forward", "-o", tmp_path, "--rate", 200)
    assert res.exit_code == 1  # unstable sampled loops: tests/cli/test_check_command.py
    out = flat(res.output)
    assert "quadctl: warning: roll: closed-loop pole -14493 rad/s is 115x faster than 200 Hz realizes" in out
    assert "sampled at 200 Hz this loop is UNSTABLE (spectral radius 72.8)" in out
    assert "warning: altitude" not in out
    data = cfg_dict("forward", name="emulated", controller={"rate": 200.0, "design": "continuous"})
    res = invoke("check", "-c", write(tmp_path, data), "-o", tmp_path / "e")
    checks = json.loads((tmp_path / "e" / "checks.json").read_text())
    assert {w["loop"] for w in checks["rate"]["warnings"]} == {"roll", "pitch", "yaw", "coupled"}


def test_simulate_flags_a_design_that_saturates(tmp_path):
    data = cfg_dict("forward", name="report-on-mambo", controller={"rate": 200.0}, motors={})
    res = invoke("simulate", "-c", write(tmp_path, data), "-o", tmp_path)
    assert res.exit_code == 0, res.output
    assert "quadctl: warning: the design saturates: rotor" in flat(res.output)
    sim = json.loads((tmp_path / "sim.json").read_text())
    assert sim["saturation"]["saturates"] and sim["controller"]["hold_steps"] == 5


def test_simulate_reports_rms_and_integrators_of_mambo(tmp_path):
    res = invoke("simulate", "-c", "mambo-200hz", "-o", tmp_path)
    assert res.exit_code == 0, res.output
    out = flat(res.output)
    assert "RMS deviation from the reference, noise seed 1" in out and "integral of pD" in out
    sim = json.loads((tmp_path / "sim.json").read_text())
    assert not sim["saturation"]["saturates"] and sim["noise"]["seed"] == 1
    assert set(sim["rms_error"]) >= {"pD", "phi", "r"}


def test_design_full_compares_the_two_designs(tmp_path):
    res = invoke("design", "-c", "mambo-200hz", "-o", tmp_path, "--full", "--json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    assert data["rate"] == 200 and data["integral_states"] == ["pD"]
    comparison = data["full"]["comparison"]
    assert set(comparison["designs"]) == {"decoupled", "full"}
    assert data["full"]["left_out"] == ["pN", "pE"]


@pytest.mark.parametrize("change, message", [
    ({"lqr": {"altitude": {"Q": [50, 1, 10], "R": [1], "integral": ["u"]}}},
     r"lqr.altitude.integral\[0\] = \"u\": not a state of subsystem `altitude`; integrate one of pD, w"),
    ({"lqr": {"altitude": {"Q": [50, 1], "R": [1], "integral": ["pD"]}}},
     r"lqr.altitude.Q = \[50, 1\]: expected 3 values \(one per pD, w, integral of pD\)"),
    ({"motors": {}, "limits": {"T": [0, 1]}}, r"limits = .*give either motors: .* or limits:, not both"),
    ({"limits": {"X": [0, 1]}}, r"limits.X = \[0, 1\]: unknown input; allowed: T, A, E, R"),
    ({"limits": {"T": [1, 0]}}, r"limits.T = \[1, 0\]: must be \[low, high\] with low < high"),
    ({"motors": {"min_thrust": 0.4}}, r"motors.min_thrust = 0.4: must be below motors.max_thrust = 0.33 N"),
    ({"controller": {"rate": -5}}, r"controller.rate = -5"),
    ({"simulation": {"noise": {"sensor": {"ph": 0.1}}}}, r"simulation.noise.sensor.ph = 0.1: unknown state; "
                                                         r"did you mean `phi`\?"),
])
def test_controller_motor_and_noise_config_errors_name_the_key(change, message):
    data = cfg_dict("forward")
    for key, value in change.items():
        if key == "lqr":
            data["lqr"].update(value)
        else:
            data[key] = value
    with pytest.raises(ConfigError, match=message):
        config.from_dict(data)


def test_every_bundled_config_with_a_rate_or_motors_loads():
    cfg = config.load("mambo-200hz")
    assert cfg.controller.rate == 200 and cfg.motors.max_thrust == 0.33
    assert cfg.lqr["altitude"].integral == ["pD"]
    cfg = config.load("crazyflie")
    assert cfg.controller.rate == 500 and cfg.motors.max_thrust == 0.159166 and cfg.vehicle.mass == 0.027


def test_the_readme_walkthrough_configs_load():

    folder = ROOT / "docs" / "configs"
    loaded = {p.stem: config.load(p) for p in folder.glob("*.yaml")}
    assert loaded["report-at-200hz"].controller.design == "continuous"
    assert loaded["report-on-mambo"].motors is not None and loaded["report-on-mambo"].controller.rate == 200
