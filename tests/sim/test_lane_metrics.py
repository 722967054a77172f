"""A run's metrics summed in the SIMD lanes as they step (quadctl.sim.lane_metrics, driver.c's
qc_metric), and a sweep over a mission's speed that gates on them, checked against independent
computations: quadctl.metrics and quadctl.run_summary.tracking_of of the same lanes' records, and the
one-case ``simulate`` of each case (its settling and overshoot against the reference it flew)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadctl import config, metrics, pipeline, run_summary, sweep
from quadctl.layout import N_STATES, STATE_INDEX, STATE_NAMES
from quadctl.setup import setup_of
from quadctl.sim.engine import LANES, runner
from quadctl.sim.lane_metrics import PER_STATE, MetricSpec, _slot, case_values, row_values, summaries, tracking
from quadctl.sweep import batched, lane_jobs, prepare

pytestmark = pytest.mark.compiler

SPEEDS = (2.0, 2.5, 3.0)
"""m/s: the square mission's peak speed in the sweep (it ends within its 15 s at each)."""
NOISE = {"seed": 3, "force": [0.02, 0.02, 0.02], "torque": [1e-4, 1e-4, 5e-5],
         "sensor": {"phi": 0.002, "theta": 0.002, "psi": 0.002, "p": 0.01, "q": 0.01, "r": 0.01}}
"""The forward sweep's noise (N, N m, state units): enough to keep some errors crossing their bands."""
GATE = 5e-7
"""m: the tracking-error gate, between the middle and the fastest case's RMS (about 1.2e-7, 3.3e-7 and
7.6e-7 at 2, 2.5 and 3 m/s)."""
TRACK_ATOL = 1e-12
"""m: tracking errors of ~1e-5 m are differences of positions of ~2 m: the lanes' vector sin and cos
(libmvec, up to 4 ulp) against the one-case loop's scalar ones move them by ~1e-15 m a step, over
~400 000 steps (a relative tolerance on a difference this small would test the round-off of the
positions, not the metric)."""


def square_with(speed: float):
    data = config.load("square").model_dump(mode="json")
    return config.from_dict(sweep.assign(data, ("simulation", "reference", "speed"), speed), "square")


def lane_group(cfgs):
    """The sweep's lane jobs of ``cfgs`` (one lane group), their runner and metric spec."""
    preps = []
    for k, cfg in enumerate(cfgs):
        setup = setup_of(cfg)
        preps.append(prepare.Prepared(k, {"case": k}, setup, prepare.plant_of(setup)))
    live = list(zip(preps, batched.design_all(preps, {"designs": 0, "fallbacks": 0})))
    items = [(prep, des, job) for (prep, des), job in zip(live, lane_jobs.loops_of(live))]
    spec = items[0][2].spec
    assert all(job.spec == spec for _, _, job in items)
    ref = preps[0].setup.reference
    legs = len(ref.legs) if ref is not None else 0
    mspec = MetricSpec.of(preps[0].setup.regulated, preps[0].setup.Q_block, preps[0].setup.R_block, ref is not None,
                          legs, pipeline.noisy(preps[0].setup))
    values = np.stack([case_values(mspec, p.plant.linear.u_trim, p.setup.Q_block, p.setup.R_block,
                                   *((ref.tolerance, p.setup.reference.legs) if legs else ())) for p in preps])
    return items, runner(spec, LANES), batched._cases_of(items), mspec, values


@pytest.mark.parametrize("which", ["forward", "square"])
def test_lane_sums_read_back_as_the_metrics_of_the_same_records(which):
    """Summed in the lanes (nothing stored) or computed by quadctl.metrics and tracking_of from the
    records the same lanes keep: the same numbers (the cost to round-off of its summation order). forward
    fills a whole group of lanes, so every record but the last takes qc_metric's path for all lanes
    recording at once, which a group with an idle (padded) lane never takes; its 1 s lets most states
    settle (6 to 8 of 10 a case), so the settling times compared are numbers, not None. It flies with
    sensor and process noise, so the lanes also sum the line through each error's last tenth, and the
    states the noise keeps crossing their bands read noise-limited the same from the lanes' sums as
    from the records."""
    if which == "forward":
        base = config.load("forward").model_dump(mode="json")
        base["simulation"]["noise"] = NOISE
        cfgs = [config.from_dict(sweep.assign(sweep.assign(base, ("lqr", "roll", "Q", 1), float(q)),
                                              ("simulation", "duration"), 1.0), "forward")
                for q in np.geomspace(10.0, 200.0, LANES)]
    else:
        cfgs = [square_with(s) for s in SPEEDS]
    items, run, cases, mspec, values = lane_group(cfgs)
    assert run.backend == "compiled-simd"
    recorded = run.run(cases)
    summed = [(done, t_end, x_end.copy(), sums.copy())
              for _, done, t_end, x_end, _, sums in run.iter_summaries(cases, mspec, values)]
    for (prep, _, job), (done, t, xs, us), (done2, t_end, x_end, sums) in zip(items, recorded, summed):
        setup, linear = prep.setup, prep.plant.linear
        assert (done2, t_end) == (done, t[-1]) and done == job.plan.n_steps
        np.testing.assert_array_equal(x_end, xs[-1])
        x = xs[:, :N_STATES]
        if setup.reference is None:
            x_ref = linear.x_trim + np.outer(t, linear.x_rate)
        else:  # the reference the rows tabulate, evaluated in Python at each record's row
            flown = setup.flown_reference
            rows = flown.rows(np.floor(t / job.exo_period + 1e-9).astype(np.int64), job.exo_period)
            x_ref = flown.flown(rows, t)[0]
        want = metrics.summarize(_Run(t, x, us, x_ref, "ok"), linear.u_trim, setup.Q_block, setup.R_block,
                                 setup.regulated)
        got = summaries(sums[None], [job.plan.dt], setup.regulated, ["ok"])[0]
        # forward flies with noise: read so, the same records give the same noise-limited states (at least
        # one in its 1 s), settling times and tails' lines, to the last bit (square flies without: its lanes
        # sum no tails)
        assert mspec.tail == (which == "forward")
        if mspec.tail:
            noisy = metrics.summarize(_Run(t, x, us, x_ref, "ok"), linear.u_trim, setup.Q_block, setup.R_block,
                                      setup.regulated, noisy=True)
            lanes_noisy = summaries(sums[None], [job.plan.dt], setup.regulated, ["ok"], [True])[0]
            assert lanes_noisy["noise_limited"] == noisy["noise_limited"] and want["noise_limited"] == []
            assert lanes_noisy["settling_time"] == noisy["settling_time"] and noisy["noise_limited"]
            # read as under turbulence, against a twin that settled every other state: the same verdicts
            twin = {name: (None if k % 2 else 0.5) for k, name in enumerate(setup.regulated)}
            gusty = metrics.summarize(_Run(t, x, us, x_ref, "ok"), linear.u_trim, setup.Q_block, setup.R_block,
                                      setup.regulated, noisy=metrics.Disturbance.GUSTS, twin=twin)
            lanes_gusty = summaries(sums[None], [job.plan.dt], setup.regulated, ["ok"], [metrics.Disturbance.GUSTS],
                                    [twin])[0]
            assert lanes_gusty["noise_limited"] == gusty["noise_limited"]
            assert lanes_gusty["settling_time"] == gusty["settling_time"]
            assert gusty["noise_limited"]
            assert set(gusty["noise_limited"]) <= {name for name, time in twin.items() if time is not None}
            per = sums[:len(PER_STATE) * N_STATES].reshape(len(PER_STATE), N_STATES)
            for i in mspec.states:
                lines = metrics.trend_of_sums(*(sums[_slot(k)] for k in ("tail_n", "tail_t", "tail_tt")),
                                              *(per[PER_STATE.index(k), i] for k in ("tail_e", "tail_te", "tail_ee")),
                                              t[-1] - (1.0 - metrics.NOISE_TAIL) * t[-1])
                assert lines == metrics.tail_trend(t, x[:, i] - x_ref[:, i]), STATE_NAMES[i]
        if which == "forward":
            assert sum(v is not None for v in want["settling_time"].values()) >= 5
        for key in ("settling_time", "overshoot", "peak"):
            assert got[key].keys() == want[key].keys()
            for name, value in want[key].items():
                assert got[key][name] == (None if value is None else pytest.approx(value, rel=1e-12, abs=1e-15)), \
                    (key, name)
        assert got["cost"] == pytest.approx(want["cost"], rel=1e-12)
        names, (flat,) = row_values(sums[None], [job.plan.dt], setup.regulated, ["ok"])
        assert dict(zip(names, flat)) == {**{f"{key}.{name}": value for key in ("settling_time", "overshoot", "peak")
                                             for name, value in got[key].items()},
                                          "cost": got["cost"], "status": "ok", "noise_limited": []}
        if setup.reference is not None:
            track = run_summary.tracking_of(setup.reference, t, x, x_ref)
            lanes = tracking(sums, len(setup.reference.legs))
            assert lanes["rms"] == pytest.approx(track["position_error"]["rms"], rel=1e-12)
            assert lanes["peak"] == track["position_error"]["peak"]
            assert lanes["reached"] == [w["reached"] for w in track["waypoints"]]


class _Run:
    """The fields of a SimResult that metrics.summarize reads."""

    def __init__(self, t, x, u, x_ref, status):
        self.t, self.x, self.u, self.x_ref, self.status = t, x, u, x_ref, status


@pytest.fixture(scope="module")
def speed_sweep():
    cfg = config.load("square")
    spec = sweep.from_dict({"parameters": {"simulation.reference.speed": list(SPEEDS)},
                            "gates": {"tracking.rms": {"max": GATE}}}, cfg, "square-speed.yaml")
    assert not spec.monte_carlo  # a reference is the run's command: no trajectories kept
    result = sweep.run(cfg, spec, jobs=1)
    ones = []
    for speed in SPEEDS:  # each case alone, as `quadctl simulate` runs it
        setup = setup_of(square_with(speed))
        stages = pipeline.Stages(setup)
        sim = pipeline.simulation_of(setup, stages.loop)
        ones.append((setup, stages, sim))
    return result, ones


def test_a_sweep_over_a_missions_speed_gates_on_the_one_case_tracking_error(speed_sweep):
    result, ones = speed_sweep
    assert {r["path"] for r in result.rows} == {"batched"} and result.stats["backend"] == ["compiled-simd"]
    for row, (setup, _, sim) in zip(result.rows, ones):
        track = run_summary.tracking_summary(setup, sim)
        assert row["tracking.rms"] == pytest.approx(track["position_error"]["rms"], rel=1e-9, abs=TRACK_ATOL)
        assert row["tracking.peak"] == pytest.approx(track["position_error"]["peak"], rel=1e-9, abs=TRACK_ATOL)
        assert row["waypoints.reached"] == sum(w["reached"] is not None for w in track["waypoints"]) == 4
        assert row["pass"] == (track["position_error"]["rms"] <= GATE)
        assert row["status"] == sim.status == "ok" and row["steps"] == sim.steps
    assert [r["pass"] for r in result.rows] == [True, True, False]  # the gate splits the cases
    assert "tracking.rms <= 5e-07" in result.rows[-1]["failed_gates"]


def test_a_mission_sweeps_settling_and_overshoot_are_against_the_reference(speed_sweep):
    """The settling and overshoot columns measure the state against the reference it flew (the
    one-case run's ``x - x_ref``), not against the trim it started from."""
    result, ones = speed_sweep
    for row, (setup, stages, sim) in zip(result.rows, ones):
        against_trim = 0
        for name in setup.regulated:
            i = STATE_INDEX[name]
            want = metrics.settling_time(sim.t, sim.x[:, i] - sim.x_ref[:, i])
            assert row[f"settling_time.{name}"] == (None if want is None else pytest.approx(want, rel=1e-9)), name
            over = metrics.overshoot(sim.x[:, i] - sim.x_ref[:, i])
            assert row[f"overshoot.{name}"] == (None if over is None else pytest.approx(over, rel=1e-6, abs=1e-6))
            trim = metrics.settling_time(sim.t, sim.x[:, i] - stages.linear.x_trim[i])
            got = row[f"settling_time.{name}"]
            against_trim += (trim is None) != (got is None) or (got is not None and not math.isclose(trim, got,
                                                                                                    rel_tol=1e-9))
        assert against_trim >= 3  # the positions (and more) settle elsewhere measured from the trim


def test_case_values_of_stacks_are_each_case_s_values():
    """Given the stacked trims and weights of a group, case_values gives each case's own row: u_trim,
    the weights at the spec's pairs (read by hand from Q and R) and the tolerance."""
    rng = np.random.default_rng(3)
    Q = np.zeros((5, N_STATES, N_STATES))
    Q[:, [0, 6, 7], [0, 6, 7]] = rng.uniform(1, 9, (5, 3))
    R = np.zeros((5, 4, 4))
    R[:, [1, 3], [1, 3]] = rng.uniform(1, 9, (5, 2))
    u = rng.uniform(0, 1, (5, 4))
    mspec = MetricSpec.of(("phi", "theta"), Q[0], R[0])
    stacked = case_values(mspec, u, Q, R)
    assert stacked.shape == (5, mspec.n_values)
    for k in range(5):
        expected = [*u[k], Q[k, 0, 0], Q[k, 6, 6], Q[k, 7, 7], R[k, 1, 1], R[k, 3, 3], 0.0]
        assert stacked[k].tolist() == expected
        assert case_values(mspec, u[k], Q[k], R[k]).tolist() == expected


def test_row_values_are_the_summaries_flattened_for_every_settling_and_status():
    """row_values (the sweep's row columns) against summaries of the same sums, in the row's column
    order, with every settling marker (never left the band, never settled, a step) and a run that did
    not finish (no settling times), and an undefined overshoot (no initial error)."""
    rng = np.random.default_rng(5)
    mspec = MetricSpec.of(("phi", "p", "v"), np.eye(N_STATES), np.eye(4))
    sums = rng.uniform(-1, 1, (4, mspec.n_sums))
    settle = slice(5 * N_STATES, 6 * N_STATES)  # PER_STATE's "settle"
    sums[:, settle] = rng.choice([-2.0, -1.0, 17.0, 250.0], (4, N_STATES))
    sums[1, STATE_INDEX["phi"]] = 0.0  # e0: no initial error, no overshoot
    status = ["ok", "ok", "diverged", "ok"]
    dt = [1e-3, 2e-3, 1e-3, 5e-4]
    want = summaries(sums, dt, ("phi", "p", "v"), status)
    names, values = row_values(sums, dt, ("phi", "p", "v"), status)
    assert names == ("settling_time.v", "settling_time.phi", "settling_time.p", "overshoot.v", "overshoot.phi",
                     "overshoot.p", "peak.T", "peak.A", "peak.E", "peak.R", "cost", "status", "noise_limited")
    for w, got in zip(want, values):
        flat = {f"{key}.{name}": value for key in ("settling_time", "overshoot", "peak")
                for name, value in w[key].items()}
        assert dict(zip(names, got)) == {**flat, "cost": w["cost"], "status": w["status"], "noise_limited": []}
    assert values[2][:3] == [None, None, None]  # diverged: no settling time
    assert values[1][4] is None  # phi started at its reference
