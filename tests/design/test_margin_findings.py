"""What a loop's margins say (quadctl.design.margin_findings): the findings against numbers got another
way, a discrete design's loops not held to the continuous LQR guarantee, and every kind worded."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from _solve import cfg_dict, solve
from typer.testing import CliRunner

from quadctl.cli.app import app
from quadctl.design import margin_findings
from quadctl.present.loops import loop_notes


def test_a_discrete_designs_loops_are_not_held_to_the_continuous_guarantee():
    """Sampling does not keep the continuous LQR guarantee: a discrete design's loop has a finite
    upper gain margin and its notes say what the hold takes (phase w_c Ts / 2 at the crossover),
    never that it falls short; continuous gains run at a rate are still compared with it."""
    _, _, linear, dec, des = solve(cfg_dict("mambo-200hz"))
    result = margin_findings.all_margins(des, dec, linear.A, linear.B)
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
    emulated = margin_findings.all_margins(des_e, dec, linear.A, linear.B, emulated_rate=200.0)
    roll_e = next(m for m in emulated if m.loop == "roll" and m.model == "design")
    said = loop_notes(roll_e)
    assert roll_e.stable and said[0].startswith("short of the continuous LQR guarantee: upper gain margin")
    assert said[1].startswith("cause: continuous gains run at 200 Hz (sample and hold)")
    # the continuous report design run at 200 Hz: unstable sampled loops
    _, _, linear, dec, des_c = solve(cfg_dict("forward"))
    emulated = margin_findings.all_margins(des_c, dec, linear.A, linear.B, emulated_rate=200.0)
    assert not next(m for m in emulated if m.loop == "roll").stable


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
    found = margin_findings.all_margins(des, dec, linear.A, linear.B, actuators=setup.actuators, u_trim=linear.u_trim,
                                        initial_demand={k: v for k, v in demand.items() if v is not None})
    room = headroom(setup.actuators, linear.u_trim)
    for m in (m for m in found if m.model == "design"):
        hold, sat = m.findings[0], next(f for f in m.findings if isinstance(f, margin_findings.SaturationCover))
        assert isinstance(hold, margin_findings.HoldPhase) and hold.crossover_rad_s == m.gain_crossover_freq
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
    for m in (m for m in margin_findings.all_margins(des_e, dec, linear.A, linear.B, emulated_rate=200.0) if m.stable):
        short, cause = m.findings[:2]
        lower, upper = m.gain_margin_db
        assert isinstance(short, margin_findings.GuaranteeShort) and isinstance(cause, margin_findings.EmulatedHold)
        assert short.upper_gain_margin_db == (upper if math.isfinite(upper) else None)
        assert short.lower_gain_margin_db == (lower if lower > -6.0206 else None)
        assert short.phase_margin_deg == (m.phase_margin_deg if m.phase_margin_deg < 60 else None)
        assert cause.rate_hz == 200.0
        assert cause.hold_phase_deg == pytest.approx(math.degrees(m.gain_crossover_freq / 200.0 / 2), rel=1e-12)


def test_a_loop_unstable_with_a_rotor_lag_its_design_ignores_names_the_lag():
    """crazyflie flown with the 72.5 ms lag identified from log10 (docs/guide/identify.md): its roll and
    pitch loops are unstable, and the note blamed the gains "at this rate" alone; it names the lag the design
    leaves out. With the lag in the design (controller.rotor_lag: include) no loop is unstable for it."""
    _, _, linear, dec, des = solve(cfg_dict("crazyflie"))
    found = margin_findings.all_margins(des, dec, linear.A, linear.B, rotor_time_constant=0.0725)
    unstable = [m for m in found if not m.stable]
    assert {m.loop for m in unstable} >= {"roll", "pitch"}
    for m in unstable:
        (f,) = m.findings
        assert f.ignored_rotor_lag_s == 0.0725 and "the design leaves out the rotors' 72.5 ms lag" in loop_notes(m)[0]
    assert all(f.ignored_rotor_lag_s is None for m in margin_findings.all_margins(des, dec, linear.A, linear.B)
               if not m.stable for f in m.findings)
    lagged = cfg_dict("crazyflie")
    lagged["motors"]["time_constant"] = 0.0725
    lagged["controller"]["rotor_lag"] = "include"
    _, _, linear, dec, des_lag = solve(lagged)
    assert des_lag.lag_time_constant == 0.0725
    assert all(m.stable for m in margin_findings.all_margins(des_lag, dec, linear.A, linear.B,
                                                             rotor_time_constant=0.0725))


def test_every_kind_of_finding_has_its_words():
    """Each kind (every :class:`~quadctl.design.margin_findings.Finding` subclass) is worded by the presenter,
    with its numbers in the sentence."""
    from quadctl.present import loops

    F = margin_findings
    cases = [
        (F.UnstableLoop(True, 2), "the closed loop is UNSTABLE: no margin; the gains are too high for this loop at "
                                  "this rate with 2 samples of delay"),
        (F.UnstableLoop(True, 0, 0.0725), "the closed loop is UNSTABLE: no margin; the design leaves out the "
                                          "rotors' 72.5 ms lag this loop has (controller.rotor_lag: include designs "
                                          "with it), or the gains are too high for this loop at this rate"),
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


def test_margins_name_what_they_take_when_given_something_else():
    """The decoupled model where the design goes (an AttributeError from inside), a config, or a plant
    of the wrong shape (NumPy's 'negative dimensions are not allowed'): each is one qc error saying what
    to pass."""
    import quadctl as qc

    stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    A, B = stages.linear.A, stages.linear.B
    with pytest.raises(qc.ArgumentTypeError, match=r"^margins takes the design and the decoupled model, .*; "
                                                   r"design is Decoupled$"):
        qc.margins(stages.decoupled, stages.design, A, B)
    with pytest.raises(qc.ArgumentTypeError, match=r"; decoupled is Config$"):
        qc.margins(stages.design, qc.load_config("hover"), A, B)
    with pytest.raises(qc.ArgumentError, match=r"^margins: A has shape \(3, 3\), expected 12 x 12$"):
        qc.margins(stages.design, stages.decoupled, np.eye(3), B)
    with pytest.raises(qc.ArgumentError, match=r"^margins: B has shape \(12, 3\), expected 12 x 4$"):
        qc.margins(stages.design, stages.decoupled, A, B[:, :3])
    with pytest.raises(qc.ArgumentError, match=r"^margins: A is complex"):
        qc.margins(stages.design, stages.decoupled, A + 0j, B)
    assert len(qc.margins(stages.design, stages.decoupled, A.tolist(), B.tolist())) == 8  # lists are matrices


@pytest.mark.parametrize("kwargs, error, match", [
    ({"emulated_rate": -100.0}, "ArgumentError", r"emulated_rate = -100\.0: must be a positive number \(Hz\) or None"),
    ({"emulated_rate": "200"}, "ArgumentError", r"emulated_rate = '200': must be a positive number"),
    ({"emulated_rate": 200.0, "delay_samples": -1}, "ArgumentError", r"delay_samples = -1: must be a whole number"),
    ({"emulated_rate": 200.0, "delay_samples": 1.5}, "ArgumentError", r"delay_samples = 1\.5: must be a whole"),
    ({"rotor_time_constant": -0.01}, "ArgumentError", r"rotor_time_constant = -0\.01: must be a positive number"),
    ({"estimator": "kalman"}, "ArgumentTypeError", r"estimator must be Kalman or None, got str"),
    ({"rate_filter": "80 Hz"}, "ArgumentTypeError", r"rate_filter must be RateFilter or None, got str"),
    ({"actuators": {"max_thrust": 1.0}}, "ArgumentTypeError", r"actuators must be Actuators or None, got dict"),
])
def test_margins_refuse_options_that_are_not_what_they_take(kwargs, error, match):
    """A negative rotor time constant gave every loop unstable, a negative delay NumPy's broadcast error,
    a text rate Python's TypeError, an estimator of another kind an AttributeError from inside."""
    import quadctl as qc

    stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    with pytest.raises(getattr(qc, error), match=rf"^margins: {match}"):
        qc.margins(stages.design, stages.decoupled, stages.linear.A, stages.linear.B, **kwargs)
