"""The loop the vehicle flies (design gains with the rotors' lag and the delay): check's verdict on it."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml
from _paths import ROOT
from _solve import cfg_dict, solve
from typer.testing import CliRunner

from quadctl import pipeline
from quadctl.cli.app import app
from quadctl.linear import stability
from quadctl.present.stages import vehicle_loop_verdict


def _lagged(rotor_lag: str = "ignore", delay: int = 0) -> dict:
    """mambo-200hz with a 30 ms rotor lag (and ``delay`` samples)."""
    data = cfg_dict("mambo-200hz", controller={"rate": 200.0, "rotor_lag": rotor_lag,
                                               **({"delay": {"samples": delay}} if delay else {})})
    data["motors"]["time_constant"] = 0.03
    data["name"] = f"lag-{rotor_lag}-{delay}"
    return data


def test_least_damping_of_a_pair_and_of_its_sampled_image():
    zeta, wn, Ts = 0.3, 20.0, 0.005
    s = -zeta * wn + 1j * wn * math.sqrt(1 - zeta ** 2)
    assert stability.least_damping([s, s.conjugate(), -50.0]) == pytest.approx(zeta, rel=1e-12)
    z = np.exp(np.array([s, s.conjugate(), -50.0]) * Ts)
    assert stability.least_damping(z, Ts) == pytest.approx(zeta, rel=1e-12)
    assert stability.least_damping([0.1 + 1j, 0.1 - 1j]) < 0  # unstable: negative damping
    assert stability.least_damping([0.0], 0.01) == math.inf  # a pure delay mode (z = 0) has none


@pytest.mark.parametrize("rotor_lag, delay, stable", [("ignore", 0, True), ("ignore", 2, False),
                                                      ("include", 2, True)])
def test_the_vehicle_loop_is_the_design_loop_with_the_rotors_and_the_delay(rotor_lag, delay, stable):
    setup, _, linear, _, des = solve(_lagged(rotor_lag, delay))
    loop = pipeline.vehicle_loop_of(setup, linear, des)
    said = vehicle_loop_verdict(loop)
    assert loop.stable is stable and (said is None) is stable
    if not stable:  # the lag is ignored by the design: the way out is to include it
        assert said == ("with the rotors' 30 ms lag (ignored by the design) and 2 samples of delay the design's "
                        "closed loop is UNSTABLE; include the lag in the design (controller.rotor_lag: include), "
                        "or lower the gains (larger R)")
    assert (loop.least_damping > 0) is stable
    # as designed: a design that ignores the lag saw the coupled loop without rotors or delay
    if rotor_lag == "ignore":
        assert loop.design_least_damping == pytest.approx(
            stability.least_damping(des.core_eigenvalues), rel=1e-9)  # core: s of the sampled poles
    # the lag costs damping; the delay costs more
    assert loop.least_damping < loop.design_least_damping
    n = 12 + 4 + 4 * delay + (4 if rotor_lag == "include" else 0)  # [x; f; b] (+ the lag model)
    assert len(loop.eigenvalues) <= n


def test_check_says_what_the_lag_costs_and_fails_when_it_destabilizes(tmp_path):
    runner = CliRunner()
    results = {}
    for rotor_lag, delay in (("ignore", 0), ("ignore", 2), ("include", 2)):
        path = tmp_path / f"{rotor_lag}-{delay}.yaml"
        path.write_text(yaml.safe_dump(_lagged(rotor_lag, delay)))
        out = tmp_path / f"run-{rotor_lag}-{delay}"
        results[rotor_lag, delay] = (runner.invoke(app, ["check", "-c", str(path), "--out", str(out)]),
                                     json.loads((out / "checks.json").read_text()))
    ok, data = results["ignore", 0]
    assert ok.exit_code == 0, ok.output
    assert "with the rotors' 30 ms lag (ignored by the design) the design's closed loop stays stable" in \
        " ".join(ok.output.split())
    assert data["closed_loop"]["stable"] and data["closed_loop"]["least_damping"] < 0.5 < \
        data["closed_loop"]["design_least_damping"]
    bad, data = results["ignore", 2]
    assert bad.exit_code == 1 and not data["closed_loop"]["stable"]
    assert ("quadctl: check failed: with the rotors' 30 ms lag (ignored by the design) and 2 samples of delay "
            "the design's closed loop is UNSTABLE; include the lag in the design (controller.rotor_lag: include)"
            ) in bad.output
    fixed, data = results["include", 2]
    assert fixed.exit_code == 0 and data["closed_loop"]["stable"], fixed.output
    assert "(included in the design) and 2 samples of delay the design's closed loop stays stable" in \
        " ".join(fixed.output.split())


def test_check_and_margins_give_the_same_vehicle_loop(tmp_path):
    path = tmp_path / "lag.yaml"
    data = _lagged("ignore", 1)
    data["allow"] = ["thin-margins"]  # the lag and the delay leave thin margins; the loop is the subject here
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "run"
    for command in ("check", "margins"):
        result = CliRunner().invoke(app, [command, "-c", str(path), "--out", str(out)])
        assert result.exit_code == 0, result.output
    checks = json.loads((out / "checks.json").read_text())["closed_loop"]
    margins = json.loads((out / "margins.json").read_text())["closed_loop"]
    assert checks["eigenvalues"] == margins["eigenvalues"] and checks["stable"] == margins["stable"]


def test_run_stops_at_check_when_the_lag_destabilizes_the_design(tmp_path):
    path = tmp_path / "lag.yaml"
    path.write_text(yaml.safe_dump(_lagged("ignore", 2)))
    result = CliRunner().invoke(app, ["run", "-c", str(path), "--out", str(tmp_path / "run")])
    assert result.exit_code == 1
    assert "check failed: check: with the rotors' 30 ms lag" in " ".join(result.output.split())
    assert not (tmp_path / "run" / "sim.npz").exists()


def test_the_guide_shows_what_check_prints_for_the_lagged_plant(tmp_path):

    root = ROOT
    result = CliRunner().invoke(app, ["check", "-c", str(root / "docs/configs/mambo-rotor-lag.yaml"),
                                      "--out", str(tmp_path / "run")])
    assert result.exit_code == 0, result.output
    line = ("with the rotors' 30 ms lag (ignored by the design) the design's closed loop stays stable: least "
            "damping 0.18 (0.721 as designed)")
    assert line in (root / "docs" / "guide" / "flying.md").read_text()
    assert line in " ".join(result.output.split())
