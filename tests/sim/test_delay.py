"""Delay (``controller.delay``): the delay margin against closed forms, the margins with the delay
included against simulation, and the config's rules.

The engine's agreement with a delay (compiled, interpreted, lanes) is in tests/sim/test_engine.py; the
sweep's lanes in tests/sweep/test_sweep.py.
"""

from __future__ import annotations

import json
import math
import shlex

import numpy as np
import pytest
import yaml
from _paths import ROOT
from _solve import cfg_dict, run, solve
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app
from quadctl.design import broken_loops, linear_loop, margin_findings, margin_search
from quadctl.errors import ConfigError
from quadctl.layout import STATE_INDEX

CLOSED_FORM = 1e-9
"""Relative: the crossover is found by root finding to ~1e-14; the margin is a ratio of two such numbers."""


@pytest.mark.parametrize("wc", [0.5, 3.0, 40.0])
def test_the_delay_margin_of_an_integrator_loop_is_pi_over_2_wc(wc):
    """``L = wc / s`` crosses ``|L| = 1`` at ``wc`` with phase -90 deg: it tolerates ``pi / 2 / wc`` s."""
    m = margin_search.loop_margins(broken_loops.BrokenLoop(np.zeros((1, 1)), np.ones(1), np.array([wc])))
    assert m.phase_margin_deg == pytest.approx(90.0, rel=CLOSED_FORM)
    assert m.delay_margin == pytest.approx(math.pi / 2 / wc, rel=CLOSED_FORM)
    assert m.delay_margin_samples is None  # continuous: no samples


@pytest.mark.parametrize("samples", [0, 1, 3])
@pytest.mark.parametrize("k", [5.0, 40.0, 150.0])
def test_a_sampled_integrator_with_n_samples_of_delay_has_the_closed_form_margins(k, samples):
    """``x <- x + Ts u``, ``u = -k x`` delayed ``n`` samples: ``L(z) = k Ts / ((z - 1) z^n)``. On
    ``z = e^(j w Ts)``, ``|L| = k Ts / (2 sin(w Ts / 2))`` and ``arg L = -pi/2 - w Ts / 2 - n w Ts``, so
    ``w_c = (2 / Ts) asin(k Ts / 2)``, ``PM = pi/2 - (n + 1/2) w_c Ts``, the delay margin ``PM / w_c``, and
    the phase reaches -pi at ``w_180 = pi / (2 (n + 1/2) Ts)``, where the upper gain margin is ``1 / |L|``.
    At k = 150, n = 3 the phase margin is negative: the loop is unstable and has none."""
    Ts = 0.005
    A, B, K = linear_loop.delayed(np.eye(1), np.array([[Ts]]), np.array([[k]]), samples)
    m = margin_search.loop_margins(broken_loops.BrokenLoop(A, B[:, 0], K[0], Ts))
    wc = 2 / Ts * math.asin(k * Ts / 2)
    pm = math.pi / 2 - (samples + 0.5) * wc * Ts
    if pm < 0:
        assert not m.stable and m.phase_margin_deg is None
        return
    w180 = math.pi / (2 * (samples + 0.5) * Ts)
    assert m.gain_crossover_freq == pytest.approx(wc, rel=CLOSED_FORM)
    assert m.phase_margin_deg == pytest.approx(math.degrees(pm), rel=CLOSED_FORM)
    assert m.delay_margin == pytest.approx(pm / wc, rel=CLOSED_FORM)
    assert m.delay_margin_samples == pytest.approx(pm / wc / Ts, rel=CLOSED_FORM)
    upper = 20 * math.log10(2 * math.sin(w180 * Ts / 2) / (k * Ts))
    assert m.gain_margin_db[1] == pytest.approx(upper, rel=CLOSED_FORM)


def test_each_sample_of_delay_takes_one_sample_of_margin():
    """The shift states are ``z^-n`` exactly: the crossover stays, the margin drops by ``n Ts``."""
    data = cfg_dict("mambo-200hz")
    _, _, linear, dec, des = solve(data)
    base = margin_findings.all_margins(des, dec, linear.A, linear.B)
    for n in (1, 3):
        with_delay = margin_findings.all_margins(des, dec, linear.A, linear.B, delay_samples=n)
        for b, d in zip(base, with_delay):
            if b.model != "design":  # the coupled loops' other channels are delayed too
                continue
            assert d.delay_samples == n and d.gain_crossover_freq == pytest.approx(b.gain_crossover_freq, rel=1e-9)
            assert d.delay_margin_samples == pytest.approx(b.delay_margin_samples - n, rel=1e-9)


def test_with_a_30ms_rotor_lag_one_sample_of_delay_leaves_0_73_and_two_are_unstable():
    """docs/guide/flying.md, 9: the lag's margin (1.73 samples) less the delay; both in the loop at once."""
    found = {}
    for n in (1, 2):
        data = cfg_dict("mambo-200hz", controller={"rate": 200.0, "delay": {"samples": n}})
        data["motors"]["time_constant"] = 0.03
        _, _, linear, dec, des = solve(data)
        found[n] = [m for m in margin_findings.all_margins(des, dec, linear.A, linear.B, delay_samples=n,
                                                           rotor_time_constant=0.03) if m.loop == "roll"]
    assert all(m.stable and round(m.delay_margin_samples, 2) == 0.73 for m in found[1])
    assert not any(m.stable for m in found[2])


def _roll_case(samples: int) -> dict:
    """mambo-200hz without rotor limits or noise (saturation would bound the growth), a small roll."""
    data = cfg_dict("mambo-200hz", motors=None)
    data["controller"]["delay"] = {"samples": samples}
    data["simulation"]["noise"] = None
    data["simulation"]["initial_offset"] = {"phi": 0.01}
    return data


def test_the_delay_the_margin_refuses_diverges_in_simulation_and_one_inside_settles():
    """Measured: roll's delay margin is 4.75 samples at 200 Hz (49.8 rad/s crossover, 67.8 deg)."""
    _, _, linear, dec, des = solve(_roll_case(0))
    margin = min(m.delay_margin_samples for m in margin_findings.all_margins(des, dec, linear.A, linear.B))
    inside, outside = math.floor(margin), math.floor(margin) + 1
    assert (inside, outside) == (4, 5)
    phi = STATE_INDEX["phi"]
    results = {}
    for n in (inside, outside):
        data = _roll_case(n)
        _, _, linear, dec, des = solve(data)
        stable = all(m.stable for m in margin_findings.all_margins(des, dec, linear.A, linear.B, delay_samples=n))
        sim = run(data)[3]
        results[n] = (stable, sim.status, np.abs(sim.x[-len(sim.t) // 10:, phi]).max())
    assert results[inside][0] and results[inside][1] == "ok" and results[inside][2] < 1e-9, results
    assert not results[outside][0] and results[outside][1] != "ok", results


def test_margins_json_reports_the_delay_margin(tmp_path):
    data = cfg_dict("mambo-200hz", name="delayed")
    data["controller"]["delay"] = 0.005
    path = tmp_path / "delayed.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    res = CliRunner().invoke(app, ["margins", "-c", str(path), "-o", str(tmp_path)], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    out = json.loads((tmp_path / "margins.json").read_text())
    assert out["delay_samples"] == 1
    roll = next(m for m in out["loops"] if m["loop"] == "roll" and m["model"] == "design")
    assert roll["delay_samples"] == 1
    assert roll["delay_margin"]["samples"] == pytest.approx(roll["delay_margin"]["s"] * 200.0, rel=1e-12)
    expected = math.radians(roll["phase_margin_deg"]) / roll["gain_crossover_freq"]
    assert roll["delay_margin"]["s"] == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("controller, message", [
    ({"rate": 200.0, "delay": 0.007}, r"controller.delay = 0.007: is 1.4 samples at 200 Hz; the simulated delay is "
                                      r"a whole number of samples: use 0.005 s \({samples: 1}\) or 0.01 s "
                                      r"\({samples: 2}\)"),
    ({"rate": 200.0, "delay": 5}, r"^<config>: controller\.delay = 5: is 1000 samples at 200 Hz, more than "
                                  r"the 100 samples \(0\.5 s\) quadctl simulates; controller\.delay is in seconds "
                                  r"\(5 ms is 0\.005\): shorten it$"),
    ({"delay": 0.005}, r"controller.delay = 0.005: a delay is counted in controller samples: set controller.rate"),
    ({"rate": 200.0, "delay": {"samples": 101}}, r"controller.delay.samples = 101: must be at most 100"),
])
def test_a_delay_the_simulation_cannot_hold_exactly_is_refused(controller, message):
    data = cfg_dict("hover", controller=controller)
    with pytest.raises(ConfigError, match=message):
        config.from_dict(data)


def test_a_delay_in_seconds_and_in_samples_are_the_same_loop():
    a = run(cfg_dict("mambo-200hz", controller={"rate": 200.0, "delay": 0.01}))
    b = run(cfg_dict("mambo-200hz", controller={"rate": 200.0, "delay": {"samples": 2}}))
    assert a[2].delay_samples == b[2].delay_samples == 2
    np.testing.assert_array_equal(a[3].x, b[3].x)


def _plant_section() -> str:
    text = (ROOT / "docs" / "guide" / "flying.md").read_text(encoding="utf-8")
    return text[text.index("**9. The plant a vehicle really is"):text.index("**10. Designing with the rotors' lag")]


def test_the_plant_section_commands_run_and_print_its_numbers(tmp_path, monkeypatch):
    """docs/guide/flying.md ("A design that flies"), 9: every command runs, and the table's
    numbers are those of its margins.json (roll, design model) and sim.json."""
    monkeypatch.chdir(ROOT)  # the configs' paths are the repository's
    section = _plant_section()
    commands = [line[2:].split("  #")[0].strip() for line in section.splitlines()
                if line.startswith(("$ quadctl margins", "$ quadctl simulate"))]  # check's line: test_vehicle_loop
    assert len(commands) == 6
    found = {}
    for k, command in enumerate(commands):
        out = tmp_path / str(k)
        res = CliRunner().invoke(app, [*shlex.split(command)[1:], "-o", str(out)])
        thin = command.startswith("quadctl margins") and any(
            m["thin"] for m in json.loads((out / "margins.json").read_text())["loops"])
        assert res.exit_code == (1 if thin else 0), (command, res.output)  # thin margins: a failed check
        assert ("check failed: thin margins" in " ".join(res.output.split())) == thin
        config_name = command.split("-c ")[1]
        if command.startswith("quadctl margins"):
            data = json.loads((out / "margins.json").read_text())
            roll = next(m for m in data["loops"] if m["loop"] == "roll" and m["model"] == "design")
            found.setdefault(config_name, []).extend([
                f"{roll['phase_margin_deg']:.3g} deg at {roll['gain_crossover_freq']:.3g} rad/s",
                f"{roll['delay_margin']['s'] * 1e3:.3g} ms ({roll['delay_margin']['samples']:.3g} samples)",
                f"±{roll['disk_gain_margin_db'][1]:.3g} dB, {roll['disk_phase_margin_deg']:.3g} deg"])
        else:
            metrics = json.loads((out / "sim.json").read_text())["metrics"]
            found.setdefault(config_name, []).extend(
                f"{metrics['settling_time'][s]:.3g} s, {metrics['overshoot'][s]:.3g} %" for s in ("phi", "theta"))
    rows = [line for line in section.splitlines() if line.startswith("| ") and "---" not in line][1:]
    columns = list(zip(*[[cell.strip() for cell in row.strip("|").split("|")[1:]] for row in rows]))
    assert [list(col) for col in columns] == [found[name] for name in
                                              ("mambo-200hz", "docs/configs/mambo-rotor-lag.yaml",
                                               "docs/configs/mambo-delay.yaml")]
