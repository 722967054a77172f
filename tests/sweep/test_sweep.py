"""Sweeps: expansion, key paths, gates, failure rows, resume, executors, and the batched numerics
checked against their one-case references (SciPy, quadctl's own simulate and metrics)."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg
from _paths import ROOT
from _solve import max_rel_diff
from typer.testing import CliRunner

from quadctl import artifacts, config, metrics, pipeline, run_summary, sweep
from quadctl.cli.app import app
from quadctl.design import lqr, riccati_residual
from quadctl.design.riccati import care_batch
from quadctl.errors import DesignError, SweepError
from quadctl.sim.run import simulate
from quadctl.sweep.gates import Gate

SHORT = {"simulation.duration": 0.15}
"""Every sweep here simulates 0.15 s (about 4 400 RK4 steps at the report's auto step): long
enough for the fast loops, short enough to keep the suite quick."""

MATCH_RTOL = 1e-9
"""Batched and one-case paths do the same arithmetic in a different order (SIMD lanes, a
vectorized Riccati solver, summed quadratic forms): they agree to round-off amplified by the
closed loop's stiffness (|lambda| dt up to 0.5 over thousands of steps), far below 1e-9."""


@pytest.fixture(scope="module")
def cfg():
    return config.load("forward")


def spec_of(cfg, **data):
    data.setdefault("set", dict(SHORT))
    return sweep.from_dict(data, cfg, "test.yaml")


# ---------------------------------------------------------------------------------------
# Expansion


def test_grid_is_the_cartesian_product_in_file_order(cfg):
    spec = spec_of(cfg, parameters={"lqr.roll.Q[1]": [10, 50],
                                    "lqr.altitude.R[0]": {"from": 0.1, "to": 10, "num": 3, "scale": "log"}})
    cases = spec.cases()
    assert spec.count() == len(cases) == 6
    assert [c.index for c in cases] == list(range(6))
    assert [c.values for c in cases] == [(10, 0.1), (10, 1.0), (10, 10.0), (50, 0.1), (50, 1.0), (50, 10.0)]


def test_linear_range_includes_both_ends(cfg):
    spec = spec_of(cfg, parameters={"vehicle.mass": {"from": 0.06, "to": 0.08, "num": 5}})
    assert [c.values[0] for c in spec.cases()] == pytest.approx([0.06, 0.065, 0.07, 0.075, 0.08])


def test_random_mode_same_seed_same_cases_and_within_bounds(cfg):
    params = {"lqr.roll.Q[1]": {"distribution": "loguniform", "low": 10, "high": 100},
              "vehicle.mass": {"distribution": "normal", "mean": 0.068, "std": 0.003},
              "lqr.yaw.R[0]": [0.5, 1, 2],
              "lqr.pitch.Q[1]": {"from": 20, "to": 80}}
    a = spec_of(cfg, mode="random", samples=200, seed=7, parameters=params).cases()
    b = spec_of(cfg, mode="random", samples=200, seed=7, parameters=params).cases()
    c = spec_of(cfg, mode="random", samples=200, seed=8, parameters=params).cases()
    assert a == b
    assert a != c
    roll, mass, yaw, pitch = (np.array([case.values[k] for case in a]) for k in range(4))
    assert roll.min() >= 10 and roll.max() <= 100
    assert set(yaw) <= {0.5, 1, 2} and len(set(yaw)) == 3
    assert pitch.min() >= 20 and pitch.max() <= 80
    # 200 normal draws: the mean is within 4 standard errors (seeded, so this cannot flake)
    assert abs(mass.mean() - 0.068) < 4 * 0.003 / math.sqrt(200)
    assert len({case.values for case in a}) == 200  # no two alike


# ---------------------------------------------------------------------------------------
# Errors in the sweep file


@pytest.mark.parametrize("data,message", [
    ({"parameters": {"lqr.rol.Q[1]": [1, 2]}}, r"parameters\.lqr\.rol\.Q\[1\]: no such key in the config: "
                                                r"`lqr\.rol`; did you mean `roll`\?"),
    ({"parameters": {"lqr.roll.Q[3]": [1, 2]}}, r"index 3 out of range: lqr\.roll\.Q has 3 values"),
    ({"parameters": {"vehicle.mas": [1]}}, r"`vehicle\.mas`; did you mean `mass`\?"),
    ({"parameters": {"lqr.roll": [1]}}, r"is a section, not a value; name one of its keys: Q, R"),
    ({"parameters": {"vehicle.mass.x": [1]}}, r"has no key `x`; the path goes too deep"),
    ({"parameters": {"vehicle.mass[0]": [1]}}, r"vehicle\.mass is not a list; drop the \[0\]"),
    ({"parameters": {"lqr..roll": [1]}}, r"not a key path"),
    ({"parameters": {"vehicle.inertia": {"from": 1, "to": 2, "num": 2}}}, r"is a list .* index one entry"),
    ({"parameters": {"vehicle.mass": []}}, r"parameters\.vehicle\.mass: empty list; give at least one value"),
    ({"parameters": {"vehicle.mass": {"from": 0.06, "to": 0.07, "num": 0}}},
     r"vehicle\.mass\.num = 0: empty range; num must be a whole number >= 1"),
    ({"parameters": {"vehicle.mass": {"from": 0, "to": 0.07, "num": 3, "scale": "log"}}},
     r"a log range needs from and to > 0"),
    ({"parameters": {"vehicle.mass": {"distribution": "normal", "mean": 0.07, "std": 0.01}}},
     r"a distribution needs mode: random"),
    ({"mode": "random", "samples": 5, "parameters": {"vehicle.mass": {"distribution": "uniform", "low": 2,
                                                                      "high": 1}}},
     r"empty range: low 2 must be below high 1"),
    ({"mode": "random", "parameters": {"vehicle.mass": [1]}}, r"samples: random mode needs the number of cases"),
    ({"mode": "grd", "parameters": {"vehicle.mass": [1]}}, r"mode: \"grd\" is not a mode; use grid or random"),
    ({"paramters": {"vehicle.mass": [1]}}, r"paramters: unknown key; did you mean `parameters`\?"),
    ({"parameters": {}}, r"parameters: nothing to vary"),
    ({"parameters": {"vehicle.mass": [1]}, "gates": {"settling_time.pd": {"max": 1}}},
     r"gates\.settling_time\.pd: unknown metric; did you mean `settling_time\.pD`\?"),
    ({"parameters": {"vehicle.mass": [1]}, "gates": {"settling_time.pN": {"max": 1}}},
     r"pN is not regulated, so it has no settling time; regulated states: pD, u,"),
    ({"parameters": {"vehicle.mass": [1]}, "gates": {"peak.T": {"maks": 1}}},
     r"gates\.peak\.T\.maks: unknown key; did you mean `max`\?"),
    ({"parameters": {"vehicle.mass": [1]}, "gates": {"peak.T": {"min": 2, "max": 1}}},
     r"min 2 is above max 1; no case can pass"),
    ({"parameters": {"vehicle.mass": [1]}, "gates": {"status": {"equals": "okk"}}},
     r"^s\.yaml: gates\.status\.equals = \"okk\": no case has that status; did you mean `ok`\?$"),
    ({"parameters": {"vehicle.mass": [1]}, "gates": {"stable": {"equals": 1}}},
     r"^s\.yaml: gates\.stable\.equals = 1: stable is true or false$"),
])
def test_sweep_file_errors_name_the_key_and_the_fix(cfg, data, message):
    with pytest.raises(SweepError, match=message) as info:
        sweep.from_dict(data, cfg, "s.yaml")
    text = str(info.value)
    assert text.startswith("s.yaml: ") and "\n" not in text


def test_every_status_a_case_can_have_is_one_a_status_gate_takes():
    """The statuses a chunk's rows are given (one by one, batched, and the simulation's) are the ones a gate
    `status: {equals: ...}` accepts."""
    import inspect

    from quadctl.sim.run import STATUS_WORDS
    from quadctl.sweep import evaluate, lane_rows, rows
    from quadctl.sweep.gates import CASE_STATUSES

    source = "".join(inspect.getsource(module) for module in (evaluate, lane_rows, rows))
    written = set(re.findall(r'failed_row\([^,]+, "(\w+)"|\["status"\] = "(\w+)"', source))
    assert {a or b for a, b in written} | set(STATUS_WORDS) == set(CASE_STATUSES)


@pytest.mark.parametrize("data,message", [
    ({"mode": "grid", "samples": 10, "parameters": {"vehicle.mass": [0.06, 0.07]}},
     r"^s\.yaml: samples: 10: a grid runs every combination of the parameters' values and takes no samples; "
     r"remove it, or set mode: random to draw that many cases$"),
    ({"samples": 10, "parameters": {"vehicle.mass": [0.06, 0.07]}}, r"^s\.yaml: samples: 10: a grid runs every"),
    ({"seed": 3, "parameters": {"vehicle.mass": [0.06, 0.07]}},
     r"^s\.yaml: seed: 3: a grid .* takes no seed; remove it, or set mode: random to draw its cases from that seed$"),
], ids=["grid with samples", "samples, grid by default", "grid with a seed"])
def test_a_grid_refuses_samples_and_seed(cfg, data, message):
    """docs/guide/sweeps.md says a grid takes no samples, seed or distributions; samples: 10 ran silently."""
    with pytest.raises(SweepError, match=message):
        sweep.from_dict(data, cfg, "s.yaml")


@pytest.mark.parametrize("path,section", [("simulation.noise.seed", "simulation.noise"),
                                          ("simulation.wind.turbulence.seed", "simulation.wind")])
def test_a_path_into_a_section_the_config_leaves_out_says_to_add_it(path, section):
    """hover has no noise nor wind: it said "simulation.noise = null has no key `seed`; the path goes too deep"."""
    hover = config.load("hover")
    assert getattr(hover.simulation, section.split(".")[1]) is None
    with pytest.raises(SweepError, match=rf"^s\.yaml: parameters\.{re.escape(path)}: the config has no "
                                         rf"`{re.escape(section)}` section \(it is null\); add a "
                                         rf"`{re.escape(section)}:` section to the config, or give it under the "
                                         rf"sweep's `set:`, to vary its keys$"):
        sweep.from_dict({"parameters": {path: [1, 2]}}, hover, "s.yaml")


def test_missing_sweep_file_and_yaml_errors(cfg, tmp_path):
    with pytest.raises(SweepError, match=r"no such sweep file; check the path"):
        sweep.load(tmp_path / "nope.yaml", cfg)
    bad = tmp_path / "bad.yaml"
    bad.write_text("parameters:\n  vehicle.mass: [1, 2\n")
    with pytest.raises(SweepError, match=r"YAML syntax error at line \d+, column \d+"):
        sweep.load(bad, cfg)


def test_initial_offset_of_another_state_is_a_valid_key(cfg):
    spec = spec_of(cfg, parameters={"simulation.initial_offset.q": [0.0, 0.1]})
    assert spec.parameters[0].keys == ("simulation", "initial_offset", "q")


def test_assign_copies_only_the_path(cfg):
    base = cfg.model_dump(mode="json")
    new = sweep.assign(base, ("lqr", "roll", "Q", 1), 7.0)
    assert new["lqr"]["roll"]["Q"] == [1.0, 7.0, 1.0]
    assert base["lqr"]["roll"]["Q"] == [1.0, 50.0, 1.0]
    assert new["vehicle"] is base["vehicle"]


# ---------------------------------------------------------------------------------------
# Batched numerics against their one-case references


def _random_stabilizable(rng, n, m):
    while True:
        A = rng.normal(size=(n, n))
        B = rng.normal(size=(n, m))
        ctrb = np.hstack([np.linalg.matrix_power(A, k) @ B for k in range(n)])
        if np.linalg.matrix_rank(ctrb) == n:
            return A, B


@pytest.mark.parametrize("n,m", [(1, 1), (2, 1), (3, 1), (3, 2), (4, 2)])
def test_batched_riccati_agrees_with_scipy_and_solves_the_equation(n, m):
    rng = np.random.default_rng(n * 10 + m)
    N = 60
    systems = [_random_stabilizable(rng, n, m) for _ in range(N)]
    A = np.stack([s[0] for s in systems])
    B = np.stack([s[1] for s in systems])
    L = rng.normal(size=(N, n, n))
    Q = L @ L.transpose(0, 2, 1) + 1e-3 * np.eye(n)
    M = rng.normal(size=(N, m, m))
    R = M @ M.transpose(0, 2, 1) + 0.1 * np.eye(m)
    res = care_batch(A, B, Q, R)
    assert res.ok.all()
    worst = 0.0
    for k in range(N):
        P = scipy.linalg.solve_continuous_are(A[k], B[k], Q[k], R[k])
        worst = max(worst, np.abs(res.P[k] - P).max() / np.abs(P).max())
        ours = riccati_residual(A[k], B[k], Q[k], R[k], res.P[k])
        assert ours == pytest.approx(res.residual[k], rel=1e-6, abs=1e-18)
        # never worse than SciPy's own solution by more than round-off
        assert ours <= 10 * riccati_residual(A[k], B[k], Q[k], R[k], P) + 1e-14
        assert np.all(np.linalg.eigvals(A[k] - B[k] @ res.K[k]).real < 0)
    # random draws include nearly uncontrollable pairs (P ~ 1e6): both solvers then carry
    # residuals ~1e-11 and their P differ in the 9th digit; well-conditioned ones agree to 1e-13
    assert worst < 1e-7, f"Max diff is {worst:.4E}"
    assert res.residual.max() <= 1e-10


def test_batched_riccati_flags_what_has_no_stabilizing_solution():
    # an unstable mode no input reaches, and a marginal mode Q does not see
    A = np.array([[[1.0, 0.0], [0.0, -1.0]], [[0.0, 1.0], [0.0, 0.0]]])
    B = np.array([[[0.0], [1.0]], [[0.0], [1.0]]])
    Q = np.array([np.eye(2), np.zeros((2, 2))])
    R = np.ones((2, 1, 1))
    res = care_batch(A, B, Q, R)
    assert not res.ok.any()
    for k in range(2):
        with pytest.raises(DesignError):
            lqr(A[k], B[k], Q[k], R[k])


def test_summary_matches_metrics_summarize(forward):
    setup, trim, linear, _, des = forward
    loop = pipeline.loop_of(setup, linear, des)
    sim = simulate(loop, setup.initial_state(linear.x_trim), 1.0, "auto")
    regulated = setup.regulated
    ref = metrics.summarize(sim, linear.u_trim, des.Q_block, des.R_block, regulated)
    got = metrics.summarize_run(sim.t, sim.x, sim.u, sim.x_ref, linear.u_trim, des.Q_block, des.R_block,
                              regulated, sim.status)
    assert got.keys() == ref.keys()
    for key in ("settling_time", "overshoot", "peak_error", "final_error", "peak"):
        assert got[key] == ref[key], key
    assert got["cost"] == pytest.approx(ref["cost"], rel=1e-12)
    assert got["status"] == ref["status"]
    # the reference given by what makes it (x_trim + x_rate t) instead of the array
    lazy = metrics.summarize_run(sim.t, sim.x, sim.u, (loop.x_trim, loop.x_rate), linear.u_trim, des.Q_block,
                               des.R_block, regulated, sim.status)
    for key in ("settling_time", "overshoot", "peak", "status"):
        assert lazy[key] == got[key], key
    for key in ("peak_error", "final_error"):
        assert lazy[key] == pytest.approx(got[key], rel=1e-12, abs=1e-15), key


# ---------------------------------------------------------------------------------------
# Running sweeps


BATCHED_CASES = {
    "forward": ({"lqr.roll.Q[1]": [10, 200], "lqr.altitude.R[0]": [0.3, 3.0], "vehicle.mass": [0.06, 0.075]},
                SHORT),
    # discrete design at 200 Hz, rotors, LQI on altitude, noise: the seed and the weights vary
    "mambo-200hz": ({"lqr.roll.R[0]": [20000, 80000], "lqr.altitude.Q[2]": [0.5, 2.0],
                     "simulation.noise.seed": [1, 2]}, {"simulation.duration": 0.6}),
    # the continuous design run at a rate (emulation), rotors, LQI, noise
    "emulated": ({"lqr.roll.R[0]": [20000, 80000], "controller.rate": [200.0, 400.0]},
                 {"simulation.duration": 0.6, "controller.design": "continuous"}),
    # rotor dynamics: the lag is a constant of the lanes (and its RK4 step is each case's)
    "rotor lag": ({"motors.time_constant": [0.01, 0.03], "lqr.roll.R[0]": [20000, 80000]},
                  {"simulation.duration": 0.6}),
    # delay: the buffer's length is a spec field (one lane group per delay)
    "delay": ({"controller.delay": [0.0, 0.005, 0.01], "lqr.roll.R[0]": [20000, 80000]},
              {"simulation.duration": 0.6}),
    # runs that end between two controller samples, in lanes beside longer ones: the last record
    # holds the input the case applied, not the one its finished lane goes on computing
    # the rotors' saturation rule is the lanes' structure: each rule its own lanes, the rows the pipeline's
    "saturation rules": ({"motors.saturation": ["clip", "prioritize"], "motors.max_thrust": [0.2, 0.33]},
                         {"simulation.duration": 1.0,
                          "simulation.initial_offset": {"pD": 1.0, "phi": 0.4, "psi": 0.8}}),
    "ends between samples": ({"controller.rate": [200.0, 300.0], "lqr.roll.R[0]": [20000, 80000]},
                             {"simulation.duration": 0.501}),
    # the gyro filter: its order is the lanes' structure, its coefficients each case's constants
    "gyro filter": ({"controller.filters.gyro.cutoff": [20.0, 40.0], "lqr.roll.R[0]": [20000, 80000]},
                    {"simulation.duration": 0.4, "controller.filters": {"gyro": {"cutoff": 30.0}}}),
    # controller.flies: pid: each case's cascade (its values, its plant) in the lanes, at the cascade's rate
    # (500 Hz, the noise on its clock, as simulate flies it), not the LQR design
    "pid cascade": ({"controller.pid.values.rate_roll_kp": [200.0, 250.0], "vehicle.mass": [0.0578, 0.0782]},
                    {"simulation.duration": 0.6, "controller.flies": "pid",
                     "controller.pid": {"preset": "crazyflie", "values": {"rate_roll_kp": 250.0}}}),
    # the PWM's thrust curve (the firmware's, scaled to each case's max_thrust) is each lane's, whether the lanes
    # share a loop but for the gains (rate_roll_kp) or not (max_thrust)
    "pid cascade, its rotors": ({"motors.max_thrust": [0.25, 0.33],
                                 "controller.pid.values.rate_roll_kp": [200.0, 250.0]},
                                {"simulation.duration": 0.6, "controller.flies": "pid",
                                 "controller.pid": {"preset": "crazyflie", "values": {"rate_roll_kp": 250.0}}}),
}


@pytest.mark.compiler
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in ("emulated", "rotor lag", "delay")
                                  else n for n in BATCHED_CASES])  # their loops: tests/sim/test_engine.py's lanes
def test_batched_path_matches_the_pipeline(name):
    """Every config simulate accepts runs in the lanes, and its rows are the one-by-one path's."""
    cfg = config.load(name if name in ("forward", "mambo-200hz") else "mambo-200hz")
    parameters, fixed = BATCHED_CASES[name]
    spec = spec_of(cfg, parameters=parameters, set=fixed, gates={"peak.T": {"max": 3.0}})
    fast = sweep.run(cfg, spec, jobs=1)
    slow = sweep.run(cfg, spec, jobs=1, fast=False)
    assert fast.stats["backend"] == ["compiled-simd"] and slow.stats["backend"] == ["compiled"]
    assert {r["path"] for r in fast.rows} == {"batched"} and {r["path"] for r in slow.rows} == {"one-by-one"}
    worst, where = max_rel_diff(fast.rows, slow.rows)
    assert worst < MATCH_RTOL, f"Max diff is {worst:.4E} at {where}"
    assert {r["status"] for r in fast.rows} == {"ok"}


def test_failed_cases_are_rows_with_their_reason(cfg):
    spec = spec_of(cfg, parameters={"lqr.yaw.Q[0]": [0.0, 50.0], "vehicle.mass": [-0.01, 0.068]},
                   set={**SHORT, "lqr.yaw.Q[1]": 0.0})
    result = sweep.run(cfg, spec, jobs=1)
    by_values = {r["case"]: r for r in result.rows}
    # Q = 0 on yaw: its double integrator is invisible to the cost, no stabilizing solution
    assert by_values[1]["status"] == "design_failed"
    assert "subsystem yaw" in by_values[1]["reason"]
    # a negative mass is not a valid config: the case says which key and why
    assert by_values[0]["status"] == "invalid_config"
    assert "case 0: vehicle.mass = -0.01" in by_values[0]["reason"]
    assert by_values[3]["status"] == "ok" and by_values[3]["pass"]
    assert [r["pass"] for r in result.rows] == [False, False, False, True]
    assert result.stats["fallbacks"] == 1


def test_a_case_whose_values_look_like_a_unit_slip_is_a_failed_row_as_the_config_alone_is_refused(cfg):
    spec = spec_of(cfg, parameters={"vehicle.mass": [68.0, 0.068]})  # 68 g written as 68 kg, then right
    slip, right = sweep.run(cfg, spec, jobs=1).rows
    assert slip["status"] == "invalid_config" and not slip["pass"]
    assert "case 0: vehicle.mass = 68 kg" in slip["reason"] and "is vehicle.mass in grams?" in slip["reason"]
    assert right["status"] == "ok" and right["pass"]
    allowed = spec_of(cfg, parameters={"vehicle.mass": [68.0]}, set={**SHORT, "allow": ["implausible"]})
    assert sweep.run(cfg, allowed, jobs=1).rows[0]["status"] == "ok"
    weights = spec_of(cfg, parameters={"lqr.roll.Q[1]": [50.0]}, set={**SHORT, "vehicle.mass": 68.0})
    assert sweep.run(cfg, weights, jobs=1).rows[0]["status"] == "invalid_config"  # the slip in set:


def test_a_step_rk4_cannot_hold_is_a_row(cfg):
    spec = spec_of(cfg, parameters={"lqr.roll.R[0]": [1.0]}, set={**SHORT, "simulation.dt": 0.001})
    row = sweep.run(cfg, spec, jobs=1).rows[0]
    assert row["status"] == "step_refused" and "is unstable for RK4" in row["reason"] and not row["pass"]


def test_gates_and_ranking(cfg):
    spec = spec_of(cfg, parameters={"lqr.altitude.R[0]": [0.2, 1.0, 5.0]},
                   gates={"peak.T": {"max": 3.0}, "stable": {"equals": True}})
    result = sweep.run(cfg, spec, jobs=1)
    peaks = [r["peak.T"] for r in result.rows]
    assert peaks[0] > peaks[1] > peaks[2]            # cheaper thrust, gentler thrust
    assert [r["pass"] for r in result.rows] == [p <= 3.0 for p in peaks]
    assert result.ranked()[0]["case"] == 0           # the worst: the largest peak
    assert "peak.T <= 3 (got" in result.rows[0]["failed_gates"]


@pytest.mark.parametrize("bounds", [{"min": 0.5}, {"max": 0.8}, {"min": 0.5, "max": 0.8}, {"min": -2.0, "max": -2.0}])
def test_a_gates_bounds_are_inclusive_and_a_value_past_one_by_an_ulp_fails(bounds):
    """``min <= value <= max``: a value on a bound passes with slack 0 (a CI gate at a sweep's own best
    value holds), one a unit in the last place outside fails; no value, a flag, a word and NaN fail."""
    from quadctl.sweep.gates import Gate

    gate = Gate("peak.T", **bounds)
    for bound, outward in ((bounds.get("min"), -np.inf), (bounds.get("max"), np.inf)):
        if bound is None:
            continue
        assert gate.passes(bound) and gate.slack(bound) == 0.0
        past = float(np.nextafter(bound, outward))
        assert not gate.passes(past) and gate.slack(past) < 0.0
    for value in (None, True, "0.6", float("nan")):
        assert not gate.passes(value)


@pytest.mark.parametrize("gates, slacks, worst", [
    # hand-computed relative slacks: (value - min) / |min| and (max - value) / |max|, the smallest of a row's
    ({"eig.slowest": {"min": -4.0}}, [(-1.0 + 4.0) / 4.0, (-3.0 + 4.0) / 4.0], 1),
    ({"peak.T": {"min": 0.5}}, [(0.7 - 0.5) / 0.5, (0.9 - 0.5) / 0.5], 0),
    ({"peak.T": {"min": 0.5, "max": 0.8}}, [min(0.4, (0.8 - 0.7) / 0.8), min(0.8, (0.8 - 0.9) / 0.8)], 1),
])
def test_rows_rank_by_their_hand_computed_slack_on_min_and_max_bounds(gates, slacks, worst):
    """Two rows inside (or outside) a ``min`` bound: the one nearer the bound ranks worse. The rows'
    ``eig.slowest`` are -1 and -3 rad/s, their ``peak.T`` 0.7 and 0.9 N."""
    from quadctl.sweep.gates import Gate, margin
    from quadctl.sweep.runner import SweepResult

    rows = [{"case": 0, "status": "ok", "stable": True, "eig.slowest": -1.0, "peak.T": 0.7},
            {"case": 1, "status": "ok", "stable": True, "eig.slowest": -3.0, "peak.T": 0.9}]
    parsed = tuple(Gate(metric=m, **bounds) for m, bounds in gates.items())
    for row, want in zip(rows, slacks):
        assert margin(row, parsed, True) == pytest.approx(want, rel=1e-12)
        assert parsed[0].passes(row[parsed[0].metric]) == (want >= 0)
    result = SweepResult(rows=rows, columns=[], computed=2, wall_time=0.0, stats={}, gates=parsed)
    assert [r["case"] for r in result.ranked()] == [worst, 1 - worst]


def test_local_processes_give_the_same_rows(cfg):
    spec = spec_of(cfg, mode="random", samples=20, seed=3, chunk_size=8,
                   parameters={"lqr.pitch.Q[1]": {"distribution": "loguniform", "low": 5, "high": 500}})
    one = sweep.run(cfg, spec, jobs=1)
    two = sweep.run(cfg, spec, jobs=2)
    assert two.stats["executor"] == "local processes (2)"
    assert one.rows == two.rows


def test_a_sweep_of_one_task_runs_in_this_process_whatever_the_jobs(cfg, monkeypatch):
    """Three cases are one task (one group of the lanes): no pool is started for it at --jobs 2, and the rows
    are those of --jobs 1."""
    from quadctl.sweep import runner

    spec = spec_of(cfg, mode="random", samples=3, seed=3,
                   parameters={"lqr.pitch.Q[1]": {"distribution": "loguniform", "low": 5, "high": 500}})
    one = sweep.run(cfg, spec, jobs=1)

    def no_pool(*args, **kwargs):
        raise AssertionError("a process pool for one task")

    monkeypatch.setattr(runner, "ProcessPoolExecutor", no_pool)
    two = sweep.run(cfg, spec, jobs=2)
    assert (two.stats["executor"], two.stats["workers"]) == ("local", 1)
    assert one.rows == two.rows


def test_dask_local_cluster_gives_the_same_rows(cfg):
    distributed = pytest.importorskip("distributed")
    spec = spec_of(cfg, mode="random", samples=12, seed=5, chunk_size=8,
                   parameters={"lqr.roll.Q[1]": {"distribution": "loguniform", "low": 5, "high": 500}})
    local = sweep.run(cfg, spec, jobs=1)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        remote = sweep.run(cfg, spec, scheduler=cluster.scheduler_address)
    assert remote.stats["executor"].startswith("dask tcp://127.0.0.1:")
    assert remote.rows == local.rows


# ---------------------------------------------------------------------------------------
# The run directory and resume


class _Stop(KeyboardInterrupt):
    pass


def test_resume_keeps_finished_rows_and_computes_only_the_rest(cfg, tmp_path, monkeypatch):
    spec = spec_of(cfg, mode="random", samples=24, seed=11, chunk_size=8,
                   parameters={"lqr.roll.Q[1]": {"distribution": "loguniform", "low": 5, "high": 500},
                               "vehicle.mass": {"distribution": "uniform", "low": 0.06, "high": 0.075}},
                   gates={"settling_time.phi": {"max": 0.1}})
    sweep.execute(cfg, spec, tmp_path / "full", jobs=1)

    def stop_after_first(done, total):
        if done >= 8:
            raise _Stop()

    with pytest.raises(_Stop):
        sweep.execute(cfg, spec, tmp_path / "cut", jobs=1, progress=stop_after_first)
    parts = sorted((tmp_path / "cut" / sweep.PARTS).glob("chunk-*.json"))
    assert [p.name for p in parts] == ["chunk-0000000.json"]
    assert not (tmp_path / "cut" / "sweep.csv").exists()

    computed = []
    real = sweep.evaluate_chunk
    monkeypatch.setattr(sweep.runner, "evaluate_chunk", lambda task: computed.extend(i for i, _ in task.cases)
                        or real(task))
    resumed = sweep.execute(cfg, spec, tmp_path / "cut", jobs=1, resume=True)
    assert sorted(computed) == list(range(8, 24))
    assert resumed.reused == 8 and resumed.result.computed == 16
    assert (tmp_path / "cut" / "sweep.csv").read_text() == (tmp_path / "full" / "sweep.csv").read_text()

    computed.clear()
    again = sweep.execute(cfg, spec, tmp_path / "cut", jobs=1, resume=True)
    assert computed == [] and again.reused == 24

    changed = dataclasses.replace(spec, seed=12, canonical={**spec.canonical, "seed": 12})
    with pytest.raises(SweepError, match=r"rows of another sweep .* run without --resume"):
        sweep.execute(cfg, changed, tmp_path / "cut", jobs=1, resume=True)


def test_resume_without_a_journal_says_so_and_computes_every_case(cfg, tmp_path):
    from quadctl.errors import QuadctlNotice

    spec = spec_of(cfg, parameters={"lqr.roll.Q[1]": [10, 50]})
    with pytest.warns(QuadctlNotice, match=r"--resume: no finished chunks in .*sweep\.parts.*all 2 cases"):
        outcome = sweep.execute(cfg, spec, tmp_path / "new", jobs=1, resume=True)
    assert outcome.reused == 0 and outcome.result.computed == 2


def test_a_killed_sweep_resumes_from_its_journal(tmp_path):
    """kill -9 a real `quadctl sweep` once it has journaled a chunk; --resume finishes the rest."""
    import os
    import signal
    import subprocess
    import sys
    import time

    sweep_file = _write(tmp_path / "s.yaml", {
        "mode": "random", "samples": 160, "seed": 1, "chunk_size": 8,
        "parameters": {"lqr.roll.Q[1]": {"distribution": "loguniform", "low": 5, "high": 500}},
        "set": {"simulation.duration": 1.0}})
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "quadctl", "sweep", "-s", str(sweep_file), "-o", str(out),
                             "-j", "1"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, "QUADCTL_CACHE": os.environ["QUADCTL_CACHE"]})
    deadline = time.monotonic() + 60
    while not list((out / sweep.PARTS).glob("chunk-*.json")) and time.monotonic() < deadline:
        time.sleep(0.005)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    kept = list((out / sweep.PARTS).glob("chunk-*.json"))
    assert 1 <= len(kept) < 20, "the sweep must be stopped part-way for this test to mean anything"
    assert not (out / "sweep.csv").exists()
    res = runner.invoke(app, ["sweep", "-s", str(sweep_file), "-o", str(out), "-j", "1", "--resume", "--json"])
    assert res.exit_code == 0, res.output
    perf = json.loads(res.stdout)["performance"]
    assert perf["resumed"] == 8 * len(kept) and perf["computed"] == 160 - 8 * len(kept)
    full = runner.invoke(app, ["sweep", "-s", str(sweep_file), "-o", str(tmp_path / "full"), "-j", "1"])
    assert full.exit_code == 0
    assert (out / "sweep.csv").read_text() == (tmp_path / "full" / "sweep.csv").read_text()


def test_outputs_table_summary_and_plot(cfg, tmp_path):
    spec = spec_of(cfg, parameters={"lqr.altitude.R[0]": [0.2, 5.0]}, gates={"peak.T": {"max": 3.0}})
    outcome = sweep.execute(cfg, spec, tmp_path, jobs=1)
    with open(tmp_path / "sweep.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    header = list(table[0])
    assert header[:2] == ["case", "lqr.altitude.R[0]"]
    assert header[-4:] == ["pass", "failed_gates", "reason", "path"]
    assert header.index("stable") < header.index("peak.T") < header.index("pass")
    assert [row["pass"] for row in table] == ["false", "true"]
    summary = json.loads((tmp_path / "sweep.json").read_text())
    assert summary["config_hash"] == cfg.digest()
    assert summary["cases"] == 2 and summary["failed"] == 1 and not summary["ok"]
    assert summary["gates"]["peak.T"]["failed"] == 1
    assert summary["worst"][0]["case"] == 0
    assert summary["sweep_digest"] == spec.digest(cfg)
    units = summary["units"]  # every numeric column of the CSV has its unit, the parameter's too; case, flags none
    assert units["peak.T"] == "N" and units["peak.A"] == "N m" and units["eig.fastest"] == "rad/s"
    assert units["settling_time.pD"] == "s" and units["overshoot.pD"] == "%" and units["dt"] == "s"
    assert units["lqr.altitude.R[0]"] == "1/N^2"  # R weighs the thrust, in N
    assert set(units) == set(header) - {"case", "stable", "status", "pass", "failed_gates", "reason", "path"}
    assert (tmp_path / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert outcome.summary["ok"] is False
    assert not spec.monte_carlo and not (tmp_path / "montecarlo.png").exists()


def test_sweep_json_gives_each_parameter_column_with_a_unit_its_unit(tmp_path):
    """The parameters' units in sweep.json, from the config the cases start from: a Q entry on the integral
    of pD (m s) is 1/(m s)^2, a torque's R 1/(N m)^2, a mass kg, the rotors' lag s; the noise
    seed has none. The metric columns keep theirs."""
    cfg = config.load("mambo-200hz")
    spec = spec_of(cfg, parameters={"lqr.altitude.Q[2]": [1.0], "lqr.roll.R[0]": [40000.0],
                                    "simulation.noise.seed": [1, 2], "vehicle.mass": [0.068],
                                    "motors.time_constant": [0.02]},
                   set=dict(SHORT))
    sweep.execute(cfg, spec, tmp_path, jobs=1)
    summary = json.loads((tmp_path / "sweep.json").read_text())
    assert summary["cases"] == 2
    units = summary["units"]
    assert {c: units.get(c) for c in summary["columns"][1:6]} == {
        "lqr.altitude.Q[2]": "1/(m s)^2", "lqr.roll.R[0]": "1/(N m)^2", "simulation.noise.seed": None,
        "vehicle.mass": "kg", "motors.time_constant": "s"}
    assert units["peak.T"] == "N" and units["settling_time.pD"] == "s"


def test_the_sweeps_page_gives_each_metric_column_the_unit_sweep_json_gives_it():
    """docs/guide/sweeps.md's table of columns, its unit cells against :data:`quadctl.sweep.gates.METRIC_UNITS`
    (the one place they are declared): each row's columns (``<state>``, ``<input>`` every one) have exactly the
    units its cell lists, and every metric with a unit is in the table."""
    from quadctl.layout import INPUT_NAMES, STATE_NAMES
    from quadctl.sweep.gates import METRIC_UNITS, column_units

    page = (ROOT / "docs" / "guide" / "sweeps.md").read_text()
    table = page[page.index("| column | unit | meaning |"):].split("\n\n")[0].splitlines()[2:]
    documented = set()
    for line in table:
        names, unit = (c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))[:2])
        columns = [c.replace("<state>", s).replace("<input>", i) for c in re.findall(r"`([^`]+)`", names)
                   for s in STATE_NAMES for i in INPUT_NAMES]
        assert set(column_units(columns).values()) == (set(unit.split(", ")) if unit else set()), line
        documented |= {c for c in columns if c in column_units(columns)}
    assert {k for k in METRIC_UNITS if not k.endswith(".")} <= documented
    assert all(any(c.startswith(k) for c in documented) for k in METRIC_UNITS if k.endswith("."))


def test_the_sweeps_page_names_every_column_sweep_csv_ends_with():
    """``path`` (batched, or one-by-one and why) is a column of every sweep.csv, but the page's table of
    columns stopped at ``reason``: each of the fixed columns after the metrics is in the table."""
    from quadctl.sweep.runner import columns_of

    page = (ROOT / "docs" / "guide" / "sweeps.md").read_text()
    table = page[page.index("| column | unit | meaning |"):].split("\n\n")[0]
    named = set(re.findall(r"^\| ([^|]+)\|", table, re.M))
    named = {c for cell in named for c in re.findall(r"`([^`]+)`", cell)}
    spec = SimpleNamespace(names=(), metrics=())
    assert set(columns_of(spec)) - {"case"} <= named, set(columns_of(spec)) - {"case"} - named


# ---------------------------------------------------------------------------------------
# The command


runner = CliRunner()


def _write(path: Path, data: dict) -> Path:
    path.write_text(json.dumps(data))  # JSON is YAML
    return path


def test_cli_gate_pass_exits_0(tmp_path):
    sweep_file = _write(tmp_path / "s.yaml", {"parameters": {"lqr.roll.Q[1]": [25, 50]}, "set": SHORT,
                                              "gates": {"peak.T": {"max": 10.0}}})
    res = runner.invoke(app, ["sweep", "-s", str(sweep_file), "-o", str(tmp_path / "out"), "-j", "1"])
    assert res.exit_code == 0, res.output
    assert "all pass" in res.output and "M RK4 steps/s" in res.output
    assert (tmp_path / "out" / "sweep.csv").exists()


def test_cli_line_names_the_integrator_the_lanes_ran(tmp_path):
    sweep_file = _write(tmp_path / "s.yaml", {"parameters": {"lqr.roll.Q[1]": [25, 50]},
                                              "set": {**SHORT, "simulation.method": "etdrk4"}})
    res = runner.invoke(app, ["sweep", "-s", str(sweep_file), "-o", str(tmp_path / "out"), "-j", "1", "--no-plot"])
    assert res.exit_code == 0, res.output
    assert "M ETDRK4 steps/s" in res.output and "RK4 steps/s" not in res.output.replace("ETDRK4", "")


def test_cli_gate_failure_exits_1_and_lists_the_worst(tmp_path):
    sweep_file = _write(tmp_path / "s.yaml", {"parameters": {"lqr.altitude.R[0]": [0.2, 1.0, 5.0]},
                                              "set": SHORT, "gates": {"peak.T": {"max": 3.0}}})
    res = runner.invoke(app, ["sweep", "-s", str(sweep_file), "-o", str(tmp_path / "out"), "-j", "1"])
    assert res.exit_code == 1
    assert "quadctl: check failed: 2 of 3 cases fail: peak.T (2); worst cases: 0, 1" in res.output
    assert "case 0: peak.T <= 3 (got" in res.output


def test_cli_json_output_is_parseable_and_no_plot_draws_no_figure(tmp_path):
    sweep_file = _write(tmp_path / "s.yaml", {"parameters": {"lqr.roll.Q[1]": [50]}, "set": SHORT})
    out = tmp_path / "out"
    out.mkdir()
    (out / "sweep.png").write_bytes(b"an earlier run's figure")
    (out / artifacts.MARK_NAME).write_text("")  # the earlier run's folder, quadctl's
    res = runner.invoke(app, ["sweep", "-s", str(sweep_file), "-o", str(out), "-j", "1", "--json", "--no-plot"])
    assert res.exit_code == 0
    payload = json.loads(res.stdout)
    assert payload["cases"] == 1 and payload["performance"]["simulated_steps"] > 0
    assert "plot" not in payload["files"] and not (out / "sweep.png").exists()  # not mistaken for this run's
    assert (out / "sweep.csv").exists() and json.loads((out / "sweep.json").read_text())["cases"] == 1


@pytest.mark.parametrize("data,code,message", [
    ({"parameters": {"lqr.roll.Q[7]": [1]}}, 2, "index 7 out of range"),
    ({"parameters": {"vehicle.mass": [0.07]}, "gates": {"peak.X": {"max": 1}}}, 2, "unknown metric"),
])
def test_cli_bad_sweep_file_exits_2_with_one_line(tmp_path, data, code, message):
    sweep_file = _write(tmp_path / "s.yaml", data)
    res = runner.invoke(app, ["sweep", "-s", str(sweep_file), "-o", str(tmp_path / "out")])
    assert res.exit_code == code
    assert message in res.output and "Traceback" not in res.output


def test_cli_jobs_and_scheduler_together_is_bad_input(tmp_path):
    sweep_file = _write(tmp_path / "s.yaml", {"parameters": {"vehicle.mass": [0.07]}})
    res = runner.invoke(app, ["sweep", "-s", str(sweep_file), "-j", "2", "--scheduler", "tcp://127.0.0.1:1"])
    assert res.exit_code == 2
    assert "--jobs and --scheduler: give one" in res.output


def test_ci_example_passes_on_the_bundled_design(tmp_path):
    cfg = config.load("forward")
    spec = sweep.load(ROOT / "examples" / "ci-sweep.yaml", cfg)
    result = sweep.run(cfg, spec, jobs=1)
    assert len(result.rows) == 27
    assert all(r["pass"] for r in result.rows), [r["failed_gates"] for r in result.rows if not r["pass"]]


def test_a_range_of_seeds_gives_whole_numbers_where_the_config_holds_one():
    """Ranges are floats; an integer config key (a noise seed) gets the integer."""
    from quadctl.sweep import assign

    tree = {"simulation": {"noise": {"seed": 1}, "duration": 2.0}}
    assert assign(tree, ("simulation", "noise", "seed"), 4.0)["simulation"]["noise"]["seed"] == 4
    assert type(assign(tree, ("simulation", "noise", "seed"), 4.0)["simulation"]["noise"]["seed"]) is int
    assert assign(tree, ("simulation", "duration"), 3.0)["simulation"]["duration"] == 3.0
    assert assign(tree, ("simulation", "noise", "seed"), 4.5)["simulation"]["noise"]["seed"] == 4.5  # refused later


# ---------------------------------------------------------------------------------------
# Monte Carlo over noise seeds


MC_SWEEP = {"parameters": {"simulation.noise.seed": [1, 2, 3, 4]}, "set": {"simulation.duration": 0.5},
            "chunk_size": 2}
"""Four seeds of mambo-200hz, 0.5 s each (the roll and pitch transients and a hundred noise draws)."""


@pytest.fixture(scope="module")
def mambo():
    return config.load("mambo-200hz")


def test_only_a_sweep_of_the_noise_seed_is_a_monte_carlo(mambo):
    assert sweep.from_dict(MC_SWEEP, mambo, "mc.yaml").monte_carlo
    mixed = {**MC_SWEEP, "parameters": {**MC_SWEEP["parameters"], "vehicle.mass": [0.068]}}
    assert not sweep.from_dict(mixed, mambo, "mc.yaml").monte_carlo


def test_monte_carlo_bands_are_ordered_percentiles_of_the_kept_trajectories(mambo, tmp_path):
    from quadctl import artifacts

    spec = sweep.from_dict(MC_SWEEP, mambo, "mc.yaml")
    outcome = sweep.execute(mambo, spec, tmp_path, jobs=2)  # the trajectories come back from workers
    assert sorted(outcome.result.traces) == [0, 1, 2, 3]
    arrays, meta = artifacts.read_npz(tmp_path / "montecarlo.npz")
    bands, traces, states = arrays["bands"], arrays["traces"], list(arrays["states"])
    assert list(arrays["percentiles"]) == [5, 25, 50, 75, 95]
    assert bands.shape == (5, sweep.MC_POINTS, len(states)) == (5, *traces.shape[1:])
    assert states == sweep.regulated_states(mambo) and meta["left_out"] == []
    assert np.all(np.diff(bands, axis=0) >= 0), "p5 <= p25 <= p50 <= p75 <= p95 at every time and state"
    np.testing.assert_allclose(bands[2], np.median(traces.astype(np.float64), axis=0), rtol=0, atol=1e-15)
    # physics: every seed starts at the configured offset, and the noise makes the seeds differ
    offset = mambo.simulation.initial_offset
    for name, value in offset.items():
        assert traces[:, 0, states.index(name)] == pytest.approx(value, rel=1e-6)
    assert np.ptp(traces[:, -1, :], axis=0).min() > 0
    assert (tmp_path / "montecarlo.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert outcome.summary["montecarlo"]["cases"] == 4
    assert outcome.summary["files"]["montecarlo"] == ["montecarlo.png", "montecarlo.npz"]


def test_a_resumed_monte_carlo_reads_the_trajectories_from_its_journal(mambo, tmp_path):
    spec = sweep.from_dict(MC_SWEEP, mambo, "mc.yaml")
    sweep.execute(mambo, spec, tmp_path / "full", jobs=1)

    def stop_after_first(done, total):
        if done >= 2:
            raise _Stop()

    with pytest.raises(_Stop):
        sweep.execute(mambo, spec, tmp_path / "cut", jobs=1, progress=stop_after_first)
    resumed = sweep.execute(mambo, spec, tmp_path / "cut", jobs=1, resume=True)
    assert resumed.reused == 2 and sorted(resumed.result.traces) == [2, 3]
    assert (tmp_path / "cut" / "montecarlo.npz").read_bytes() == (tmp_path / "full" / "montecarlo.npz").read_bytes()


def test_every_field_of_a_loop_but_its_gains_is_part_of_its_lane_structure():
    """A sweep gives cases of one lane structure (lane_jobs._structure) the constants and initial
    state of the first, with only the gains rewritten: so a change in any other field of the loop must
    give another structure. Each field of ClosedLoop but the gains and the spectrum, changed alone."""
    from dataclasses import fields, replace
    from types import SimpleNamespace

    from _solve import cfg_dict, solve

    from quadctl.config.pid import resolve
    from quadctl.design.gain_table import GainTable
    from quadctl.linear.filters import rate_filter_of
    from quadctl.sweep import lane_jobs

    data = cfg_dict("mambo-200hz", controller={"rate": 200.0, "rotor_lag": "include", "delay": {"samples": 1}})
    data["motors"]["time_constant"] = 0.03
    data["estimator"] = {"measure": ["imu", "mocap"]}
    measured = ("pN", "pE", "pD", "phi", "theta", "psi", "p", "q", "r")
    data["simulation"]["noise"] = {"seed": 1, "force": [0.01] * 3, "torque": [1e-5] * 3,
                                   "sensor": {s: 0.01 for s in measured}}
    setup, _, linear, _, des = solve(data)
    loop = pipeline.loop_of(setup, linear, des)
    assert loop.Kv is not None and loop.estimator is not None and loop.integral_states and loop.delay_samples

    def key(lp):
        return lane_jobs._structure(lp, (True, False, 1.0), lane_jobs._Seen())[0]

    changed = {"params": loop.params * 1.01, "x_trim": loop.x_trim + 1e-3, "u_trim": loop.u_trim * 1.01,
               "x_rate": loop.x_rate + 1e-3, "rate": 400.0, "integral_states": ("pN",),
               "actuators": replace(loop.actuators), "open_loop_eigenvalues": loop.open_loop_eigenvalues * 2,
               "delay_samples": 2, "lag_model_time_constant": 0.05, "estimator": replace(loop.estimator),
               "schedule": GainTable.of("speed", [0.0, 1.0], np.stack([loop.K, loop.K])),
               "schedule_heading": 0.5, "schedule_eigenvalues": np.array([-1.0 + 0j]),
               "schedule_jacobians": (np.zeros((2, 12, 12)), np.zeros((2, 12, 4))),
               "law": resolve("crazyflie"),
               "rate_filter": rate_filter_of(SimpleNamespace(gyro=SimpleNamespace(cutoff=30.0, order=2),
                                                             notch=None))}
    structural = {f.name for f in fields(loop)} - set(lane_jobs.PER_CASE)
    assert structural == set(changed), "a new ClosedLoop field: add a change of it here"
    for name, value in changed.items():
        assert key(replace(loop, **{name: value})) != key(loop), name
    same = replace(loop, K=loop.K * 2, Ki=loop.Ki * 2, Kv=loop.Kv * 2, eigenvalues=loop.eigenvalues * 2, owners=[])
    assert key(same) == key(loop)


def test_a_sweep_into_a_pipe_draws_no_progress_bar(tmp_path):
    """stderr not a terminal (a CI log, `2> file`): the summary line on stdout only, no bar frames."""
    import subprocess
    import sys

    sweep_file = _write(tmp_path / "s.yaml", {"parameters": {"lqr.roll.Q[1]": [25, 50]}, "set": SHORT})
    proc = subprocess.run([sys.executable, "-m", "quadctl", "sweep", "-s", str(sweep_file), "-o", str(tmp_path / "o"),
                           "-j", "1", "--no-plot"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "all pass" in proc.stdout
    assert proc.stderr == ""


@pytest.mark.compiler
def test_a_chunk_mixing_designs_with_and_without_the_rotor_lag_designs_each_as_the_pipeline():
    """Cases whose design includes the rotors' lag (designed one by one) between cases batched in one
    chunk, each with its own weights: the batched ones still solve their own problems (path
    ``batched``), and every row is the one-by-one path's."""
    cfg = config.load("mambo-200hz")
    spec = spec_of(cfg, mode="random", samples=8, seed=3, chunk_size=8,
                   parameters={"controller.rotor_lag": {"distribution": "choice", "values": ["include", "ignore"]},
                               "lqr.roll.R[0]": {"distribution": "loguniform", "low": 20000, "high": 80000}},
                   set={"simulation.duration": 0.3, "motors.time_constant": 0.02})
    lags = [c.values[0] for c in spec.cases()]
    assert lags.index("include") < len(lags) - 1 - lags[::-1].index("ignore")  # a lag case before a batched one
    fast = sweep.run(cfg, spec, jobs=1)
    slow = sweep.run(cfg, spec, jobs=1, fast=False)
    for row, lag in zip(fast.rows, lags):
        assert row["path"] == ("batched" if lag == "ignore" else "one-by-one: the design includes the rotors' lag")
    worst, where = max_rel_diff(fast.rows, slow.rows)
    assert worst < MATCH_RTOL, f"Max diff is {worst:.4E} at {where}"


# ---------------------------------------------------------------------------------------
# set: makes the section its parameters vary, and sets a section whole

MISSION = {"waypoints": [{"position": [0.3, 0.0, -1.0]}], "tolerance": 0.05}


@pytest.fixture(scope="module")
def square_without_mission():
    from quadctl.config import overrides

    return overrides.load(config.bundled("square"), ["simulation.reference=null"])


def test_set_makes_the_section_its_parameters_vary(square_without_mission):
    """The config has no mission: set: gives one, the parameters vary its speed (a key set: leaves to
    its default), a gate reads its waypoints; each row is the one-case run of the same config."""
    from quadctl.config import overrides
    from quadctl.setup import setup_of

    cfg = square_without_mission
    spec = sweep.from_dict({"set": {"simulation.reference": MISSION, "simulation.duration": 2.0},
                            "parameters": {"simulation.reference.speed": [0.5, 1.0]},
                            "gates": {"waypoints.reached": {"min": 1}}}, cfg, "s.yaml")
    result = sweep.run(cfg, spec, jobs=1)
    assert {"tracking.rms", "tracking.peak", "waypoints.reached"} <= set(result.columns)
    for row in result.rows:
        assert row["status"] == "ok" and row["pass"] and row["waypoints.reached"] == 1, row
        one = overrides.load(config.bundled("square"), [f"simulation.reference={json.dumps(MISSION)}",
                                                        "simulation.duration=2",
                                                        f"simulation.reference.speed={row['simulation.reference.speed']}"])
        setup = setup_of(one)
        track = run_summary.tracking_summary(setup, pipeline.simulation_of(setup, pipeline.Stages(setup).loop))
        for column, key in (("tracking.rms", "rms"), ("tracking.peak", "peak")):
            assert row[column] == pytest.approx(track["position_error"][key], rel=MATCH_RTOL, abs=1e-15)
    assert result.rows[0]["tracking.rms"] < result.rows[1]["tracking.rms"]  # slower flies closer


def test_a_case_whose_mission_is_refused_is_its_own_row_and_the_others_fly_as_without_it(square_without_mission):
    """A chunk tabulates its cases' references together: a speed no attitude flies is that case's row,
    with the reason simulate gives it, and the other cases' rows are those they have without it."""
    from quadctl.config import overrides
    from quadctl.errors import TrimError
    from quadctl.setup import setup_of
    from quadctl.sim.exogenous import ExoStream

    def rows(speeds):
        spec = sweep.from_dict({"set": {"simulation.reference": MISSION, "simulation.duration": 1.0},
                                "parameters": {"simulation.reference.speed": speeds}},
                               square_without_mission, "s.yaml")
        return [{k: v for k, v in row.items() if k not in ("case", "wall_time")}
                for row in sweep.run(square_without_mission, spec, jobs=1).rows]

    alone, together = rows([0.5, 1.0]), rows([0.5, 40.0, 1.0])
    refused = together.pop(1)
    setup = setup_of(overrides.load(config.bundled("square"), [f"simulation.reference={json.dumps(MISSION)}",
                                                               "simulation.duration=1",
                                                               "simulation.reference.speed=40"]))
    loop = pipeline.Stages(setup).loop
    plan = loop.plan(setup.duration, setup.dt)
    with pytest.raises(TrimError) as simulated:  # the rows simulate draws (through the final step's)
        ExoStream(None, None, loop.rate or setup.timing.rate, setup.flown_reference).rows(0, plan.n_steps + 1,
                                                                                            plan.dt)
    assert refused["status"] == "failed" and refused["reason"] == str(simulated.value), refused
    assert together == alone


def test_a_mission_set_gives_brings_its_columns_where_only_the_cases_make_it_valid(square_without_mission):
    """A waypoint 200 m out is past what the config's own 15 s can reach (MAX_REACH), not the cases'
    30 and 60 s: the mission's columns and gates still come with it."""
    far = {"waypoints": [{"position": [200.0, 0.0, -1.0]}], "speed": 1.0}
    data = {"set": {"simulation.reference": far}, "parameters": {"simulation.duration": [30.0, 60.0]},
            "gates": {"waypoints.reached": {"min": 1}, "tracking.rms": {"max": 1.0}}}
    spec = sweep.from_dict(data, square_without_mission, "s.yaml")
    assert {"tracking.rms", "tracking.peak", "waypoints.reached"} <= set(spec.metrics)
    assert [g.metric for g in spec.gates] == ["waypoints.reached", "tracking.rms"]
    assert not {"tracking.rms", "waypoints.reached"} & set(sweep.from_dict(
        {"parameters": {"simulation.duration": [30.0]}}, square_without_mission, "s.yaml").metrics)


@pytest.mark.parametrize("fixed,section,expected", [
    pytest.param({"simulation.initial_offset": {"pN": 0.5}}, ("simulation", "initial_offset"), {"pN": 0.5},
                 id="a section replaced whole, not merged"),
    pytest.param({"simulation.initial_offset": {}}, ("simulation", "initial_offset"), {}, id="emptied"),
    pytest.param({"simulation.wind": {"steady": [1.0, 0.0, 0.0]}}, ("simulation", "wind", "steady"), [1.0, 0.0, 0.0],
                 id="a section the config leaves out, given whole"),
    pytest.param({"simulation.wind.steady": [0.0, 2.0, 0.0]}, ("simulation", "wind", "steady"), [0.0, 2.0, 0.0],
                 id="a section the config leaves out, made by one of its keys"),
])
def test_set_may_set_a_section_whole_or_make_it(cfg, fixed, section, expected):
    from quadctl.sweep.runner import base_of

    spec = spec_of(cfg, parameters={"lqr.roll.Q[1]": [10, 50]}, set={**SHORT, **fixed})
    case = config.from_dict(base_of(cfg, spec), "case")
    node = case.model_dump(mode="json")
    for key in section:
        node = node[key]
    assert node == expected
    assert cfg.simulation.initial_offset != {"pN": 0.5} and cfg.simulation.wind is None  # the config had others


def test_a_parameter_may_vary_a_key_of_a_section_set_makes(cfg):
    from quadctl.sweep.runner import base_of

    spec = spec_of(cfg, parameters={"simulation.wind.steady[1]": [1.0, 2.0]},
                   set={**SHORT, "simulation.wind": {"steady": [3.0, 0.0, 0.0]}})
    assert spec.parameters[0].keys == ("simulation", "wind", "steady", 1)
    assert base_of(cfg, spec)["simulation"]["wind"] == {"steady": [3.0, 0.0, 0.0]}


@pytest.mark.parametrize("data,message", [
    ({"parameters": {"simulation.reference.speed": [1, 2]}},
     r"^s\.yaml: parameters\.simulation\.reference\.speed: the config has no `simulation\.reference` section \(it is "
     r"null\); add a `simulation\.reference:` section to the config, or give it under the sweep's `set:`, to vary its "
     r"keys$"),
    ({"set": {"simulation.reference": {"waypoints": [{"position": [1, 0, -1]}], "sped": 2}},
      "parameters": {"lqr.roll.Q[0]": [1]}},
     r"^s\.yaml: set: simulation\.reference\.sped: unknown key; did you mean `speed`\?$"),
    ({"set": {"simulation.reference.sped": 2}, "parameters": {"lqr.roll.Q[0]": [1]}},
     r"^s\.yaml: set\.simulation\.reference\.sped: no such key in the config: `simulation\.reference\.sped`; did you "
     r"mean `speed`\?$"),
    ({"set": {"simulation.reference": {"waypoints": [{"position": [1, 0, -1]}]}},
      "parameters": {"simulation.reference.waypoints[0].hod": [1]}},
     r"^s\.yaml: parameters\.simulation\.reference\.waypoints\[0\]\.hod: no such key in the config: "
     r"`simulation\.reference\.waypoints\[0\]\.hod`; did you mean `hold`\?$"),
    ({"set": {"simulation.reference": {"waypoints": [{"position": [1, 0, -1]}]}},
      "parameters": {"simulation.reference.waypoints[1].hold": [1]}},
     r"^s\.yaml: parameters\.simulation\.reference\.waypoints\[1\]\.hold: index 1 out of range"),
    ({"parameters": {"simulation.initial_offset": [{"pN": 1}]}},
     r"^s\.yaml: parameters\.simulation\.initial_offset: is a section, not a value; name one of its keys: pD, phi, "
     r"theta, psi, or set it whole under the sweep's `set:`$"),
    ({"set": {"simulation.reference": {"waypoints": [{"position": [1, 0, -1]}]}},
      "parameters": {"simulation.reference.waypoints[0]": [1]}},
     r"^s\.yaml: parameters\.simulation\.reference\.waypoints\[0\]: is a section, not a value; name one of its keys: "
     r"position, or set it whole under the sweep's `set:`$"),
    ({"parameters": {"vehicle.inertia[0]": [7e-5, 8e-5], "vehicle.inertia": [[6.9e-5, 7.75e-5, 1.5e-4]]}},  # one
     r"^s\.yaml: parameters\.vehicle\.inertia\[0\]: lies inside parameters\.vehicle\.inertia: a case would fly one "
     r"of the two values; vary one of them$"),                       # inertia flew every case, the column said two
    ({"parameters": {"vehicle.inertia": [[6.9e-5, 7.75e-5, 1.5e-4]], "vehicle.inertia[0]": [7e-5, 8e-5]}},
     r"^s\.yaml: parameters\.vehicle\.inertia\[0\]: lies inside parameters\.vehicle\.inertia:"),
    ({"set": {"vehicle.inertia[0]": 8e-5}, "parameters": {"vehicle.inertia": [[6.9e-5, 7.75e-5, 1.5e-4]]}},
     r"^s\.yaml: set\.vehicle\.inertia\[0\]: lies inside parameters\.vehicle\.inertia, whose values replace it in "
     r"every case; give the value in those$"),
    ({"set": {"vehicle.mass": 0.07, "vehicle": {"mass": 0.068, "inertia": [6.9e-5, 7.75e-5, 1.5e-4]}},
      "parameters": {"lqr.roll.Q[0]": [1]}},
     r"^s\.yaml: set\.vehicle\.mass: lies inside set\.vehicle, which follows and gives it whole; put "
     r"set\.vehicle\.mass after it, or its value inside it$"),
    ({"set": {"simulation.duration": -1}, "parameters": {"vehicle.mass": [0.5]}},  # each case ran and failed
     r"^s\.yaml: set\.simulation\.duration = -1: must be greater than 0\.0 \(s\)$"),
    ({"set": {"controller.rate": "fast"}, "parameters": {"lqr.roll.Q[0]": [1]}},
     r"^s\.yaml: set\.controller\.rate = \"fast\": must be a number"),
])
def test_set_and_its_sections_errors_name_the_key_and_the_fix(data, message):
    with pytest.raises(SweepError, match=message):
        sweep.from_dict(data, config.load("hover"), "s.yaml")


def test_margin_columns_are_the_margins_command_s_and_gate_thin_loops():
    """A gate on margin.gain_db / margin.phase_deg adds the columns: the least margins over the loops that
    ``quadctl margins`` reports (the rotors' lag in them); the 30 ms lag's thin roll loop fails."""
    from quadctl.design.margins import THIN_GAIN_MARGIN_DB, THIN_PHASE_MARGIN_DEG
    from quadctl.setup import setup_of

    cfg = config.load("mambo-200hz")
    spec = spec_of(cfg, parameters={"motors.time_constant": [0.01, 0.03]}, set={"simulation.duration": 0.3},
                   gates={"margin.gain_db": {"min": THIN_GAIN_MARGIN_DB},
                          "margin.phase_deg": {"min": THIN_PHASE_MARGIN_DEG}})
    assert "margin.phase_deg" in spec.metrics
    rows = sweep.run(cfg, spec, jobs=1).rows
    for row, tau in zip(rows, (0.01, 0.03)):
        data = cfg.model_dump(mode="json")
        data["motors"]["time_constant"] = tau
        st = pipeline.Stages(setup_of(config.from_dict(data)))
        found = pipeline.margins_of(st.setup, st.linear, st.decoupled, st.design)
        assert row["margin.phase_deg"] == min(m.phase_margin_deg for m in found)
        assert row["margin.gain_db"] == min(min(-m.gain_margin_db[0], m.gain_margin_db[1]) for m in found)
    assert [r["pass"] for r in rows] == [True, False]
    assert "margin.phase_deg" in rows[1]["failed_gates"]
    plain = spec_of(cfg, parameters={"motors.time_constant": [0.01]}, set={"simulation.duration": 0.3})
    assert "margin.phase_deg" not in plain.metrics  # computed only when gated


def test_a_sweep_that_flies_the_cascade_gates_the_cascades_margins_not_the_lqr_designs(monkeypatch):
    """controller.flies: pid: the margin columns are the cascade's, as quadctl margins reports them for that
    config (the stock Crazyflie cascade keeps 0.75 dB where the LQR design keeps 24 dB): a gate at 6 dB fails.
    The case's cascade is lifted once, for its stability and its margins."""
    from quadctl.setup import setup_of

    lifts = []
    real = pipeline.lifted
    monkeypatch.setattr(pipeline, "lifted", lambda loop: lifts.append(1) or real(loop))
    cfg = config.load("crazyflie")
    spec = spec_of(cfg, parameters={"vehicle.mass": [0.027]}, set={"simulation.duration": 0.3,
                                                                    "controller.flies": "pid"},
                   gates={"margin.gain_db": {"min": 6}})
    (row,) = sweep.run(cfg, spec, jobs=1).rows
    assert len(lifts) == 1
    monkeypatch.undo()
    data = cfg.model_dump(mode="json")
    data["controller"]["flies"] = "pid"
    st = pipeline.Stages(setup_of(config.from_dict(data)))
    found = st.margins  # the law that flies: the cascade's loops
    assert {m.model for m in found} == {"cascade"}
    assert row["margin.gain_db"] == min(min(-m.gain_margin_db[0], m.gain_margin_db[1]) for m in found)
    assert row["margin.gain_db"] < 1 and not row["pass"]


def test_a_margin_gate_on_an_unstable_loop_says_the_loop_is_unstable():
    """80 ms of rotor lag loses one of mambo-200hz's loops: its margin cells are empty and the gate fails
    with why, 'got none: a loop is unstable', where it read 'got none' as a run that stopped does."""
    cfg = config.load("mambo-200hz")
    spec = spec_of(cfg, parameters={"motors.time_constant": [0.08]}, set={"simulation.duration": 0.3},
                   gates={"margin.gain_db": {"min": 6}, "margin.phase_deg": {"min": 30}})
    (row,) = sweep.run(cfg, spec, jobs=1).rows
    assert row["margin.gain_db"] is None and row["margin.phase_deg"] is None and not row["pass"]
    assert row["failed_gates"] == ("6 <= margin.gain_db (got none: a loop is unstable); "
                                   "30 <= margin.phase_deg (got none: a loop is unstable)")


@pytest.mark.parametrize("n, workers", [(48, 2), (1000, 2), (64, 2), (17, 2), (3000, 2), (1, 1), (200, 3), (9, 4)])
def test_default_chunks_are_whole_lane_groups_the_workers_finish_together(n, workers):
    """Cases cost alike, so tasks taken by the next free worker (largest first) leave each worker within
    one lane group of the others; every task but the last is whole groups of the lanes, at most
    MAX_CHUNK cases; all cases are in, once."""
    from quadctl.sim.engine import LANES
    from quadctl.sweep.runner import MAX_CHUNK, default_chunks

    sizes = default_chunks(n, workers)
    assert sum(sizes) == n and all(0 < s <= MAX_CHUNK for s in sizes)
    assert all(s % LANES == 0 for s in sizes[:-1]) and sizes == sorted(sizes, reverse=True)
    load = [0] * workers
    for s in sizes:
        load[load.index(min(load))] += s
    assert max(load) - min(load) <= LANES or len(sizes) < workers
    assert len(sizes) >= min(2 * workers, math.ceil(n / LANES))  # about two tasks a worker, where there are cases


def test_distinct_rows_number_each_value_from_its_first_row():
    """The design stage's dedup: each distinct row once, numbered in order of first appearance, the
    first row of each; every row maps back to its own value (ints as well as floats)."""
    from quadctl.sweep.batched import _distinct_rows

    rng = np.random.default_rng(3)
    values = rng.normal(size=(5, 7))
    order = rng.integers(0, 5, size=40)
    M = values[order]
    first, inverse = _distinct_rows(M)
    assert np.array_equal(M[first][inverse], M)
    assert np.array_equal(first, [int(np.flatnonzero(order == v)[0]) for v in dict.fromkeys(order.tolist())])
    assert np.array_equal(inverse, [list(dict.fromkeys(order.tolist())).index(v) for v in order.tolist()])
    slots = np.array([[0, 1], [2, 1], [0, 1], [0, 0]])
    first, inverse = _distinct_rows(slots)
    assert first.tolist() == [0, 1, 3] and inverse.tolist() == [0, 1, 0, 2]


@pytest.mark.parametrize("gates, columns, want", [
    ((), ["settling_time.pD", "settling_time.phi", "peak.T"], ("peak.T", "settling_time.pD")),
    ((Gate("peak.A", max=0.01), Gate("settling_time.phi", max=2.0)), ["settling_time.pD", "settling_time.phi"],
     ("peak.A", "settling_time.phi")),
    # a mission's sweep: the error it gates on, not a settling time the mission never asked for
    ((Gate("waypoints.reached", min=4), Gate("tracking.peak", max=1e-3)),
     ["settling_time.pD", "tracking.rms", "tracking.peak", "waypoints.reached"], ("peak.T", "tracking.peak")),
    ((), ["settling_time.pD", "tracking.rms", "tracking.peak"], ("peak.T", "tracking.rms")),
    # gated on its margins alone: the margin it judges, not a settling time a short run may never reach
    ((Gate("margin.gain_db", min=6), Gate("margin.phase_deg", min=30)),
     ["settling_time.pD", "margin.gain_db", "margin.phase_deg"], ("peak.T", "margin.gain_db")),
    ((Gate("margin.phase_deg", min=30), Gate("settling_time.phi", max=2.0)),
     ["settling_time.pD", "settling_time.phi", "margin.phase_deg"], ("peak.T", "settling_time.phi")),
])
def test_the_trade_off_figure_plots_what_the_sweep_judges(gates, columns, want):
    from quadctl.sweep.outputs import tradeoff_axes
    from quadctl.sweep.runner import SweepResult

    result = SweepResult(rows=[], columns=["case", *columns, "pass"], computed=0, wall_time=0.0, stats={},
                         gates=gates)
    assert tradeoff_axes(result) == want


@pytest.mark.compiler
def test_a_noisy_sweep_s_lanes_give_the_one_case_rows_with_their_noise_limited_settling(mambo):
    """mambo-200hz's 10 s with noise, two seeds: the lanes' rows are the one-by-one path's, the rate
    states' settling times blank and noise-limited (named in the row and its reason), and a gate on
    one fails saying so rather than reading 'none'."""
    spec = sweep.from_dict({"parameters": {"simulation.noise.seed": [1, 2]},
                            "gates": {"settling_time.p": {"max": 1.0}, "settling_time.phi": {"max": 1.0}}},
                           mambo, "noisy.yaml")
    fast = sweep.run(mambo, spec, jobs=1)
    slow = sweep.run(mambo, spec, jobs=1, fast=False)
    assert {r["path"] for r in fast.rows} == {"batched"} and {r["path"] for r in slow.rows} == {"one-by-one"}
    worst, where = max_rel_diff(fast.rows, slow.rows)
    assert worst < MATCH_RTOL, f"Max diff is {worst:.4E} at {where}"
    for row in fast.rows:
        assert {"p", "q"} <= set(row["noise_limited"]) and "phi" not in row["noise_limited"]
        assert row["settling_time.p"] is None and row["settling_time.q"] is None
        assert 0.3 < row["settling_time.phi"] < 1.0  # the attitude settles within the noise: a number
        assert row["reason"].startswith("settling noise-limited: ") and " p, q" in row["reason"]
        assert not row["pass"]
        assert row["failed_gates"] == "settling_time.p <= 1 (got noise-limited)"
    assert "noise_limited" not in fast.columns  # sweep.csv keeps its columns


@pytest.mark.compiler
def test_a_turbulent_sweep_reads_each_case_against_its_twin_in_the_lanes_as_one_by_one():
    """crazyflie-wind's turbulence, 5 s from 0.3 m below, a fast altitude loop and one so slow its run
    without turbulence (its twin) is still outside pD's band at the end, two turbulence seeds: the lanes'
    rows are the one-by-one path's; each case's noise-limited states are the late ones its twin settled
    (pD: the fast loop's, never the slow one's), the same with either seed; the cases of one loop share
    one twin (the lanes step four cases' and two twins' runs)."""
    from quadctl.config import overrides

    cfg = overrides.load(config.bundled("crazyflie-wind"), ["simulation.duration=5",
                                                            "simulation.initial_offset={pD: 0.3}"])
    spec = sweep.from_dict({"parameters": {"lqr.altitude.R[0]": [1.0, 1.0e6],
                                           "simulation.wind.turbulence.seed": [1, 2]},
                            "set": {"lqr.altitude.Q": [100.0, 1.0]}}, cfg, "turbulent.yaml")
    fast = sweep.run(cfg, spec, jobs=1)
    slow = sweep.run(cfg, spec, jobs=1, fast=False)
    assert {r["path"] for r in fast.rows} == {"batched"} and {r["status"] for r in fast.rows} == {"ok"}
    worst, where = max_rel_diff(fast.rows, slow.rows)
    assert worst < MATCH_RTOL, f"Max diff is {worst:.4E} at {where}"
    steps = fast.rows[0]["steps"]
    assert fast.stats["steps"] == (4 + 2) * steps and slow.stats["steps"] == (4 + 4) * steps
    by_loop = {}
    for row in fast.rows:
        by_loop.setdefault(row["lqr.altitude.R[0]"], []).append(row["noise_limited"])
        assert row["settling_time.pD"] is None
    assert by_loop[1.0][0] == by_loop[1.0][1] and "pD" in by_loop[1.0][0]
    assert by_loop[1.0e6][0] == by_loop[1.0e6][1] and "pD" not in by_loop[1.0e6][0]


def test_sweep_run_names_what_it_takes_when_given_something_else():
    """A name where the config goes, or the sweep's mapping where its spec goes: one TypeError saying what to
    pass, not an AttributeError from inside."""
    from quadctl import sweep

    cfg = config.load("forward")
    data = {"parameters": {"lqr.roll.Q[1]": [25, 50]}}
    with pytest.raises(TypeError, match=r"^sweep.run takes a validated Config, .*; got str$"):
        sweep.run("forward", sweep.from_dict(data, cfg), jobs=1)
    with pytest.raises(TypeError, match=r"^sweep.run takes a SweepSpec, sweep.from_dict\(data, cfg\) .*; got dict$"):
        sweep.run(cfg, data, jobs=1)


def test_a_sweep_spec_names_the_config_it_varies_when_given_something_else():
    """A config's name where the config goes failed with 'str' object has no attribute 'model_dump'
    (sweep.from_dict, and sweep.parse and sweep.load through it)."""
    data = {"parameters": {"lqr.roll.Q[1]": [25, 50]}}
    for call in (lambda: sweep.from_dict(data, "forward"),
                 lambda: sweep.parse('parameters: {"lqr.roll.Q[1]": [1]}', {})):
        with pytest.raises(TypeError, match=r"^a sweep varies a validated Config, .*; got (str|dict)$"):
            call()


@pytest.mark.parametrize("jobs", [0, 1.5, "2", True])
def test_sweep_run_refuses_jobs_that_are_not_a_whole_number_of_at_least_one(jobs):
    """1.5 and '2' failed inside with a TypeError of Python's ('float' object cannot be interpreted as an
    integer), and True ran as one worker."""
    cfg = config.load("forward")
    spec = sweep.from_dict({"parameters": {"lqr.roll.Q[1]": [25, 50]}}, cfg)
    with pytest.raises(SweepError, match=rf"^--jobs {re.escape(repr(jobs))}: must be a whole number of at least 1$"):
        sweep.run(cfg, spec, jobs=jobs)


def test_execute_refuses_a_session_of_another_config_and_writes_nothing(cfg, tmp_path):
    """A session writes its own config beside the files, stamps the figures with it and removes the runs of
    any other: given one of another config, the folder would say one config and hold another's sweep."""
    spec = spec_of(cfg, parameters={"lqr.roll.Q[1]": [25, 50]})
    other = config.from_dict(sweep.assign(cfg.model_dump(mode="json"), ("vehicle", "mass"), 0.07), "other")
    said = (rf"^the session of .* is of config {other.name!r} \({other.digest()[:12]}\), the sweep of {cfg.name!r} "
            r".*: give the run folder's path")
    with artifacts.Session(other, tmp_path) as session, pytest.raises(ValueError, match=said):
        sweep.execute(cfg, spec, session, jobs=1, plot=False)
    assert not (tmp_path / "sweep.csv").exists() and not (tmp_path / "config.yaml").exists()


def test_a_sweep_that_flies_the_cascade_judges_the_cascades_stability_not_the_lqr_designs():
    """controller.flies: pid: one sample of delay leaves the stock Crazyflie cascade unstable about hover (as
    simulate's check and quadctl margins find) while the LQR design stays stable, and a 0.3 s run still ends.
    The row is unstable, with the lifted loop's radius, and fails require_ok; without the delay it is stable.
    eig.slowest is ln(radius) / frame."""
    from quadctl.setup import setup_of

    cfg = config.load("crazyflie")
    spec = spec_of(cfg, parameters={"controller.delay.samples": [0, 1]},
                   set={"simulation.duration": 0.3, "controller.flies": "pid", "controller.delay": {"samples": 0}},
                   require_ok=True)
    fine, delayed = sweep.run(cfg, spec, jobs=1).rows
    assert (fine["status"], delayed["status"]) == ("ok", "ok")
    assert fine["stable"] and fine["pass"] and fine["eig.fastest"] is None
    assert delayed["stable"] is False and not delayed["pass"]
    data = cfg.model_dump(mode="json")
    data["controller"].update(flies="pid", delay={"samples": 1})
    st = pipeline.Stages(setup_of(config.from_dict(data)))
    assert st.design.stable  # the LQR design, which does not fly, is stable
    lift = st.pid_lift
    radius = float(np.abs(lift.poles).max())
    assert math.isclose(delayed["eig.slowest"], math.log(radius) / (lift.frame * lift.sample_time), rel_tol=1e-9)
    assert delayed["eig.slowest"] > 0 > fine["eig.slowest"]
    assert delayed["failed_gates"] == f"the PID cascade is unstable about hover (spectral radius {radius:.5g} " \
                                      f"per {lift.frame * lift.sample_time * 1e3:.3g} ms frame)"
