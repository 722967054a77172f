"""Stability margins against loops with known answers, and against the LQR guarantee."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.optimize
from _paths import ROOT
from _solve import cfg_dict, solve
from typer.testing import CliRunner

from quadctl.cli.app import app
from quadctl.design import discrete, margins
from quadctl.design.margins import BrokenLoop, loop_margins
from quadctl.present.loops import loop_notes


def integrator_with_lag(k: float, tau: float) -> BrokenLoop:
    """``L(s) = k / (s (tau s + 1))`` as state feedback: x1' = x2, x2' = (u - x2) / tau, u = -k x1."""
    A = np.array([[0.0, 1.0], [0.0, -1.0 / tau]])
    b = np.array([0.0, 1.0 / tau])
    return BrokenLoop(A, b, np.array([k, 0.0]))


@pytest.mark.parametrize("k, tau", [(math.sqrt(2), 1.0), (5.0, 0.1), (0.3, 2.0)])
def test_integrator_with_first_order_lag(k, tau):
    """|L(jw)| = 1 at k = w sqrt(1 + w^2 tau^2); PM = 90 - atan(w tau); the phase never reaches
    -180 deg, so both gain margins are infinite."""
    wc = math.sqrt((math.sqrt(1 + 4 * k**2 * tau**2) - 1) / (2 * tau**2))
    m = loop_margins(integrator_with_lag(k, tau))
    assert m.stable
    assert m.gain_crossover_freq == pytest.approx(wc, rel=1e-9)
    assert m.phase_margin_deg == pytest.approx(90 - math.degrees(math.atan(wc * tau)), abs=1e-7)
    assert m.gain_margin_db == (-math.inf, math.inf)


def test_integrator_with_lag_of_k_sqrt2_has_45_degrees():
    m = loop_margins(integrator_with_lag(math.sqrt(2), 1.0))
    assert m.phase_margin_deg == pytest.approx(45.0, abs=1e-8)
    assert m.gain_crossover_freq == pytest.approx(1.0, rel=1e-10)


def test_three_lags_gain_margin_is_six():
    """L = 1 / (s (s + 1) (s + 2)): phase -180 deg at w = sqrt(2), |L| = 1/6 there: GM = 6 (15.56 dB)."""
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -2.0, -3.0]])
    m = loop_margins(BrokenLoop(A, np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])))
    assert m.gain_margin_db[1] == pytest.approx(20 * math.log10(6.0), abs=1e-9)
    assert m.phase_crossover_freqs[1] == pytest.approx(math.sqrt(2), rel=1e-10)
    assert m.gain_margin_db[0] == -math.inf
    wc = scipy.optimize.brentq(lambda w: w**2 * (w**2 + 1) * (w**2 + 4) - 1, 0.1, 1.0)
    pm = 90 - math.degrees(math.atan(wc) + math.atan(wc / 2))
    assert m.phase_margin_deg == pytest.approx(pm, abs=1e-8)


def test_pure_integrator_disk_margin_is_two():
    """L = k / s: |S - T| = 1 at every frequency, so alpha = 2, gains [0, inf), disk phase 90 deg."""
    m = loop_margins(BrokenLoop(np.array([[0.0]]), np.array([1.0]), np.array([3.0])))
    assert m.disk_alpha == pytest.approx(2.0, rel=1e-9)
    assert m.disk_phase_deg == pytest.approx(90.0, rel=1e-9)
    # |1 + k/(jw)| = |jw + k| / w > 1, tending to 1 beyond the grid's last frequency
    assert 1.0 <= m.min_return_difference < 1.0 + 1e-4


def test_unstable_loop_is_reported_unstable():
    m = loop_margins(BrokenLoop(np.array([[0.0]]), np.array([1.0]), np.array([-1.0])))
    assert not m.stable and not m.meets_lqr_guarantee


def test_an_unstable_loop_has_no_margin():
    """x' = 2 x + u with u = -x: L = 1 / (s - 2), closed loop s = 1. The disk formula alone,
    ``1 / max |S - 1/2|`` with ``S - 1/2 = (s - 3) / (2 (s - 1))``, gives 2/3 (at s = 0): a
    margin the loop does not have. It is unstable, so every margin is zero."""
    loop = BrokenLoop(np.array([[2.0]]), np.array([1.0]), np.array([1.0]))
    assert loop.closed_loop_eigenvalues()[0] == pytest.approx(1.0)
    w = np.logspace(-3, 3, 601)
    assert 1.0 / np.abs(1 / (1 + loop(w)) - 0.5).max() == pytest.approx(2 / 3, rel=1e-5)
    m = loop_margins(loop)
    assert not m.stable
    assert m.gain_margin_db == (0.0, 0.0) and m.phase_crossover_freqs == (None, None)
    assert m.phase_margin_deg == 0.0 and m.gain_crossover_freq is None
    assert (m.disk_alpha, m.disk_gain_db, m.disk_phase_deg, m.disk_freq) == (0.0, (0.0, 0.0), 0.0, None)
    d = m.as_dict()
    assert d["disk_margin_alpha"] == 0.0 and d["disk_margin_freq"] is None and not d["meets_lqr_guarantee"]


@pytest.mark.filterwarnings("ignore:__call__. evaluation above Nyquist")
def test_agrees_with_python_control_continuous_and_sampled():
    control = pytest.importorskip("control")
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -2.0, -3.0]])
    B, C = np.array([[0.0], [0.0], [1.0]]), np.array([[1.5, 0.2, 0.0]])
    sys = control.ss(A, B, C, 0)
    for ts in (None, 0.1):
        if ts:
            sysd = control.c2d(sys, ts)
            loop = BrokenLoop(sysd.A, sysd.B.ravel(), sysd.C.ravel(), ts)
            grid = np.logspace(-3, math.log10(math.pi / ts), 20001)
            ref = sysd
        else:
            loop = BrokenLoop(A, B.ravel(), C.ravel())
            grid = np.logspace(-3, 3, 20001)
            ref = sys
        m = loop_margins(loop)
        gm, pm, _, wpc, wgc, _ = control.stability_margins(ref, method="frd" if ts else "best")
        assert 10 ** (m.gain_margin_db[1] / 20) == pytest.approx(gm, rel=1e-6)
        assert m.phase_margin_deg == pytest.approx(pm, rel=1e-6)
        assert m.gain_crossover_freq == pytest.approx(wgc, rel=1e-6)
        alpha = control.disk_margins(ref, grid)[0]
        assert m.disk_alpha == pytest.approx(float(np.min(alpha)), rel=1e-5)


def test_continuous_lqr_loops_meet_the_guarantee():
    """Every report loop on its design model: |1 + L| >= 1, GM from -6 dB to inf, PM >= 60 deg."""
    _, _, linear, dec, des = solve(cfg_dict("forward"))
    result = margins.all_margins(des, dec, linear.A, linear.B)
    design_loops = [m for m in result if m.model == "design"]
    assert {m.loop for m in design_loops} == {"altitude", "roll", "pitch", "yaw"}
    for m in design_loops:
        assert m.meets_lqr_guarantee, m.loop
        assert np.abs(1 + m.response).min() >= 1 - 1e-9
        assert "meets the continuous LQR guarantee" in loop_notes(m)[0]


def test_a_discrete_designs_loops_are_not_held_to_the_continuous_guarantee():
    """Sampling does not keep the continuous LQR guarantee: a discrete design's loop has a finite
    upper gain margin and its notes say what the hold takes (phase w_c Ts / 2 at the crossover),
    never that it falls short; continuous gains run at a rate are still compared with it."""
    _, _, linear, dec, des = solve(cfg_dict("mambo-200hz"))
    result = margins.all_margins(des, dec, linear.A, linear.B)
    roll = next(m for m in result if m.loop == "roll" and m.model == "design")
    assert roll.sample_time == pytest.approx(0.005) and roll.stable
    assert math.isfinite(roll.gain_margin_db[1])  # a sampled loop has a finite upper gain margin
    assert not roll.meets_lqr_guarantee  # the field keeps its meaning
    hold = math.degrees(roll.gain_crossover_freq * 0.005 / 2)
    assert loop_notes(roll)[0] == (f"sampled loop: the hold's half-sample delay is {hold:.3g} deg of phase at the "
                                   f"{roll.gain_crossover_freq:.4g} rad/s crossover")
    assert not any("short" in n or "guarantee" in n for m in result for n in loop_notes(m))
    # the continuous design of mambo-200hz run at 200 Hz: short of the guarantee, and why
    cont = cfg_dict("mambo-200hz")
    cont["controller"]["design"] = "continuous"
    _, _, linear, dec, des_e = solve(cont)
    emulated = margins.all_margins(des_e, dec, linear.A, linear.B, emulated_rate=200.0)
    roll_e = next(m for m in emulated if m.loop == "roll" and m.model == "design")
    said = loop_notes(roll_e)
    assert roll_e.stable and said[0].startswith("short of the continuous LQR guarantee: upper gain margin")
    assert said[1].startswith("cause: continuous gains run at 200 Hz (sample and hold)")
    # the continuous report design run at 200 Hz: unstable sampled loops
    _, _, linear, dec, des_c = solve(cfg_dict("forward"))
    emulated = margins.all_margins(des_c, dec, linear.A, linear.B, emulated_rate=200.0)
    assert not next(m for m in emulated if m.loop == "roll").stable


def test_the_grid_of_a_sampled_loop_ends_at_nyquist():
    Ad, Bd = discrete.c2d([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], 0.01)
    loop = BrokenLoop(Ad, Bd.ravel(), np.array([1.0, 1.0]), 0.01)
    assert margins.frequency_grid(loop)[-1] == pytest.approx(math.pi / 0.01, rel=1e-15)


REPORT_AT_200HZ = ROOT / "docs" / "configs" / "report-at-200hz.yaml"


def test_margins_json_gives_an_unstable_loop_no_margin_and_spells_infinity(tmp_path):
    """The report's gains at 200 Hz: roll, pitch and yaw are unstable sampled loops, so their
    margins are zero (not the 1.89 / +-31 dB / 86.8 deg the disk formula gives); altitude is
    stable with no lower critical gain: "-inf", distinct from null (not applicable)."""
    res = CliRunner().invoke(app, ["margins", "-c", str(REPORT_AT_200HZ), "-o", str(tmp_path), "--design-only"])
    assert res.exit_code == 1, res.output
    assert "31.2" not in res.output and "1.89" not in res.output
    data = json.loads((tmp_path / "margins.json").read_text())
    loops = {(m["loop"], m["model"]): m for m in data["loops"]}
    for name in ("roll", "pitch", "yaw"):
        m = loops[name, "design"]
        assert m["stable"] is False, name
        assert (m["disk_margin_alpha"], m["disk_gain_margin_db"], m["disk_phase_margin_deg"]) == (0.0, [0.0, 0.0], 0.0)
        assert (m["gain_margin_lower_db"], m["gain_margin_upper_db"], m["phase_margin_deg"]) == (0.0, 0.0, 0.0)
        assert m["disk_margin_freq"] is None and m["gain_crossover_freq"] is None
        assert m["gain_margin_lower_freq"] is None and m["gain_margin_upper_freq"] is None
    altitude = loops["altitude", "design"]
    assert altitude["stable"] is True and altitude["gain_margin_lower_db"] == "-inf"
    assert altitude["gain_margin_lower_freq"] is None  # no crossover: not applicable
    assert 20.0 < altitude["gain_margin_upper_db"] < 30.0 and 0.5 < altitude["disk_margin_alpha"] < 2.0


def test_an_infinite_margin_is_a_string_in_margins_json(tmp_path):
    """A continuous LQR loop: upper gain margin +inf, disk gain range up to +inf (alpha 2)."""
    res = CliRunner().invoke(app, ["margins", "-c", "hover", "-o", str(tmp_path), "--design-only", "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    assert data == json.loads((tmp_path / "margins.json").read_text())
    for m in data["loops"]:
        assert m["stable"] and m["meets_lqr_guarantee"], m["loop"]
        assert m["gain_margin_upper_db"] == "inf" and m["gain_margin_upper_freq"] is None


def test_the_saturation_note_reads_the_disk_margin_as_a_sector_in_the_inputs_units(tmp_path):
    """The circle criterion: a loop with disk gain margin [g_min, ...] stays stable while the rotors
    deliver at least g_min of the command, i.e. for commands up to headroom / g_min (N or N m)."""
    import re

    from quadctl.physics.motors import headroom

    res = CliRunner().invoke(app, ["margins", "-c", "mambo-200hz", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.output
    data = json.loads((tmp_path / "margins.json").read_text())
    setup, _, linear, _, _ = solve(cfg_dict("mambo-200hz"))
    room = headroom(setup.actuators, linear.u_trim)
    for loop in (l for l in data["loops"] if l["model"] == "design"):
        (note,) = [n for n in loop["notes"] if n.startswith("saturation:")]
        unit = "N" if loop["input"] == "T" else "N m"
        g_min = 10 ** (loop["disk_gain_margin_db"][0] / 20)
        down, up = room[loop["input"]]
        found = re.search(rf"has (\S+) {unit} of headroom .* above (\S+), i\.e\. for commands up to (\S+) {unit}; "
                          rf"the initial offset asks for \S+ {unit}, within it", note)
        assert found, note
        assert float(found[1]) == pytest.approx(min(down, up), rel=1e-2)
        assert float(found[2]) == pytest.approx(g_min, rel=1e-2)
        assert float(found[3]) == pytest.approx(min(down, up) / g_min, rel=1e-2)


def test_the_findings_are_the_numbers_the_loop_has():
    """A discrete design's findings against numbers got another way: the hold's half-sample phase is
    ``-arg(exp(-j w_c Ts / 2))``; the saturation the disk covers is the headroom over the disk's least
    gain ``(2 - alpha) / (2 + alpha)``, and the initial demand is ``|K dx0|`` of the input."""
    from quadctl.physics.motors import headroom

    setup, _, linear, dec, des = solve(cfg_dict("mambo-200hz"))
    demand = {"T": 0.0, "A": 1e-3, "E": 1e9, "R": None}
    found = margins.all_margins(des, dec, linear.A, linear.B, actuators=setup.actuators, u_trim=linear.u_trim,
                                initial_demand={k: v for k, v in demand.items() if v is not None})
    room = headroom(setup.actuators, linear.u_trim)
    for m in (m for m in found if m.model == "design"):
        hold, sat = m.findings[0], next(f for f in m.findings if isinstance(f, margins.SaturationCover))
        assert isinstance(hold, margins.HoldPhase) and hold.crossover_rad_s == m.gain_crossover_freq
        phase = -math.degrees(np.angle(np.exp(-0.5j * m.gain_crossover_freq * 0.005)))
        assert hold.hold_phase_deg == pytest.approx(phase, rel=1e-12) and hold.sample_time_s == 0.005
        g_min = (2 - m.disk_alpha) / (2 + m.disk_alpha)
        assert sat.headroom == min(room[m.input]) and sat.disk_gain_min == pytest.approx(g_min, rel=1e-12)
        assert sat.covered_command == pytest.approx(min(room[m.input]) / g_min, rel=1e-12)
        assert sat.initial_demand == demand[m.input] and sat.within is (None if demand[m.input] is None else
                                                                         demand[m.input] <= sat.covered_command)
        assert sat.as_dict()["kind"] == "saturation" and sat.as_dict()["initial_demand_within"] is sat.within
        assert m.as_dict()["findings"] == [f.as_dict() for f in m.findings]
    # a continuous design emulated at 200 Hz: short of the guarantee by exactly the margins it misses
    cont = cfg_dict("mambo-200hz")
    cont["controller"]["design"] = "continuous"
    _, _, linear, dec, des_e = solve(cont)
    for m in (m for m in margins.all_margins(des_e, dec, linear.A, linear.B, emulated_rate=200.0) if m.stable):
        short, cause = m.findings[:2]
        lower, upper = m.gain_margin_db
        assert isinstance(short, margins.GuaranteeShort) and isinstance(cause, margins.EmulatedHold)
        assert short.upper_gain_margin_db == (upper if math.isfinite(upper) else None)
        assert short.lower_gain_margin_db == (lower if lower > -6.0206 else None)
        assert short.phase_margin_deg == (m.phase_margin_deg if m.phase_margin_deg < 60 else None)
        assert cause.rate_hz == 200.0
        assert cause.hold_phase_deg == pytest.approx(math.degrees(m.gain_crossover_freq / 200.0 / 2), rel=1e-12)


def test_every_kind_of_finding_has_its_words():
    """Each kind (every :class:`~quadctl.design.margins.Finding` subclass) is worded by the presenter,
    with its numbers in the sentence."""
    from quadctl.present import loops

    F = margins
    cases = [
        (F.UnstableLoop(True, 2), "the closed loop is UNSTABLE: no margin; the gains are too high for this loop at "
                                  "this rate with 2 samples of delay"),
        (F.HoldPhase(12.5, 0.005, 1.79), "sampled loop: the hold's half-sample delay is 1.79 deg of phase at the 12.5 "
                                         "rad/s crossover"),
        (F.GuaranteeMet(), "meets the continuous LQR guarantee (gain margin -6 dB to inf, phase margin >= 60 deg)"),
        (F.GuaranteeShort(18.2, None, 41.5), "short of the continuous LQR guarantee: upper gain margin 18.2 dB "
                                             "(guarantee: inf); phase margin 41.5 deg (guarantee: >= 60 deg)"),
        (F.EmulatedHold(200.0, 30.0, 4.3), "cause: continuous gains run at 200 Hz (sample and hold); the guarantee "
                                           "assumes instantaneous continuous feedback; the hold's half-sample delay "
                                           "alone costs 4.3 deg at the 30 rad/s crossover"),
        (F.CouplingCause(), "cause: couplings the decoupled design ignores (the guarantee holds on the subsystem it "
                            "was designed on)"),
        (F.GyroFilterLag("first-order low-pass at 80 Hz", 40.0, 4.55),
         "gyro filter (first-order low-pass at 80 Hz): 4.55 deg of phase lag at the 40 rad/s crossover"),
        (F.SaturationCover("A", "N m", 0.02, 0.5, 0.04, 0.05),
         "saturation: A has 0.02 N m of headroom from trim (other inputs at trim); the disk margin keeps the loop "
         "stable (circle criterion) while the effective gain stays above 0.5, i.e. for commands up to 0.04 N m; the "
         "initial offset asks for 0.05 N m, BEYOND it: the margins no longer guarantee stability during that "
         "saturation"),
        (F.LqgUnstable(("pD", "phi")), "LQG (Kalman filter on pD phi): the closed loop is UNSTABLE: no margin"),
        (F.LqgEstimator(("pD", "phi"), "discrete", None, True),
         "LQG: the LQR guarantee (gain margin -6 dB to inf, phase margin >= 60 deg) does not hold with an estimator "
         "in the loop (Doyle 1978); Kalman filter (discrete) on pD phi; meets it anyway"),
        (F.LqgAgainstFullState(50.0, 70.0, (-5.0, 12.0), (-7.0, math.inf), 0.8, 1.2),
         "against full-state feedback: phase margin 50 deg (full state 70), gain margin -5 / 12 dB (full state -7 / "
         "inf), disk alpha 0.8 (full state 1.2)"),
        (F.LqgLeftOut(True, 1), "not in this loop: the rotors' lag and 1 samples of delay (the full-state loops "
                                "include them)"),
    ]
    assert {type(f) for f, _ in cases} == set(F.Finding.__subclasses__())
    for f, words in cases:
        assert loops.note(f) == words, f.kind
