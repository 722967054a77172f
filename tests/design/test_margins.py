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
from quadctl.design import discrete, margin_findings, margin_search, margins
from quadctl.design.broken_loops import BrokenLoop
from quadctl.design.margin_search import loop_margins
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



@pytest.mark.parametrize("k, sample_time", [(15.0, None), (25.0, None), (15.0, 0.01)])
def test_an_open_loop_unstable_plant_loses_stability_below_the_gain_where_its_dc_crossing_reaches_minus_one(
        k, sample_time):
    """L = k (s + 1) / ((s - 1) (s + 10)): its Nyquist curve leaves the negative real axis at w = 0, from
    L(0) = -k / 10. Closed with a gain g, s^2 + (9 + g k) s + (g k - 10) is stable only for g > 10 / k: a
    lower gain margin of 20 log10(10 / k) dB, at w = 0 (python-control's stability_margins finds it there);
    none above. At k = 15 that is -3.5 dB, short of LQR's -6 dB, whatever the phase margin (122 deg).
    Sampled (ZOH at 100 Hz) the curve starts on the axis too, at z = 1, where L(1) = L(0) of the plant."""
    A, b, gain = np.array([[0.0, 1.0], [10.0, -9.0]]), np.array([0.0, 1.0]), np.array([k, k])
    if sample_time:
        A, B = discrete.c2d(A, b[:, None], sample_time)
        b = B[:, 0]
    m = loop_margins(BrokenLoop(A, b, gain, sample_time))
    critical = 10.0 / k
    assert m.stable and (m.gain_margin_db[1] == math.inf or sample_time)  # sampled, a high gain fails too
    assert m.gain_margin_db[0] == pytest.approx(20 * math.log10(critical), abs=1e-9)
    assert m.phase_crossover_freqs[0] == 0.0
    loop = BrokenLoop(A, b, gain, sample_time)
    assert loop.is_stable(critical * 1.01) and not loop.is_stable(critical * 0.99)
    if not sample_time:
        assert m.meets_lqr_guarantee == (20 * math.log10(critical) <= margins.LQR_GAIN_MARGIN_DB[0])


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
    margin the loop does not have. It is unstable, so it has none: every margin None, not 0 (at the edge)."""
    loop = BrokenLoop(np.array([[2.0]]), np.array([1.0]), np.array([1.0]))
    assert loop.closed_loop_eigenvalues()[0] == pytest.approx(1.0)
    w = np.logspace(-3, 3, 601)
    assert 1.0 / np.abs(1 / (1 + loop(w)) - 0.5).max() == pytest.approx(2 / 3, rel=1e-5)
    m = loop_margins(loop)
    assert not m.stable
    assert m.gain_margin_db == (None, None) and m.phase_crossover_freqs == (None, None)
    assert m.phase_margin_deg is None and m.gain_crossover_freq is None and m.delay_margin is None
    assert (m.disk_alpha, m.disk_gain_db, m.disk_phase_deg, m.disk_freq) == (None, (None, None), None, None)
    assert margins.least_margins([m]) == (None, None) and m.thin == ()
    d = m.as_dict()
    assert d["stable"] is False and not d["meets_lqr_guarantee"]
    assert d["disk_margin_alpha"] is None and d["disk_margin_freq"] is None and d["phase_margin_deg"] is None
    assert d["gain_margin_lower_db"] is d["gain_margin_upper_db"] is None


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
    result = margin_findings.all_margins(des, dec, linear.A, linear.B)
    design_loops = [m for m in result if m.model == "design"]
    assert {m.loop for m in design_loops} == {"altitude", "roll", "pitch", "yaw"}
    for m in design_loops:
        assert m.meets_lqr_guarantee, m.loop
        assert np.abs(1 + m.response).min() >= 1 - 1e-9
        assert "meets the continuous LQR guarantee" in loop_notes(m)[0]



def test_the_grid_of_a_sampled_loop_ends_at_nyquist():
    Ad, Bd = discrete.c2d([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], 0.01)
    loop = BrokenLoop(Ad, Bd.ravel(), np.array([1.0, 1.0]), 0.01)
    assert margin_search.frequency_grid(loop)[-1] == pytest.approx(math.pi / 0.01, rel=1e-15)


REPORT_AT_200HZ = ROOT / "docs" / "configs" / "report-at-200hz.yaml"


def test_margins_json_gives_an_unstable_loop_no_margin_and_spells_infinity(tmp_path):
    """The report's gains at 200 Hz: roll, pitch and yaw are unstable sampled loops, so they have no
    margins (not the 1.89 / +-31 dB / 86.8 deg the disk formula gives, nor 0): null beside "stable": false,
    "unstable" in the tables; altitude is stable with no lower critical gain: "-inf", distinct from null."""
    res = CliRunner().invoke(app, ["margins", "-c", str(REPORT_AT_200HZ), "-o", str(tmp_path), "--design-only"])
    assert res.exit_code == 1, res.output
    assert "31.2" not in res.output and "1.89" not in res.output
    data = json.loads((tmp_path / "margins.json").read_text())
    loops = {(m["loop"], m["model"]): m for m in data["loops"]}
    for name in ("roll", "pitch", "yaw"):
        m = loops[name, "design"]
        assert m["stable"] is False, name
        assert (m["disk_margin_alpha"], m["disk_gain_margin_db"], m["disk_phase_margin_deg"]) == (None, [None, None],
                                                                                                  None)
        assert (m["gain_margin_lower_db"], m["gain_margin_upper_db"], m["phase_margin_deg"]) == (None, None, None)
        assert m["delay_margin"] == {"s": None, "samples": None}
        assert m["disk_margin_freq"] is None and m["gain_crossover_freq"] is None
        assert m["gain_margin_lower_freq"] is None and m["gain_margin_upper_freq"] is None
    tables = [{}, {}, {}]  # each loop's row in the classical table, the disk table, the delay table
    for line in res.output.splitlines():
        cells = [c.strip() for c in line.split("│")[1:-1]]
        if len(cells) > 2 and cells[1] == "design":
            next(t for t in tables if cells[0] not in t)[cells[0]] = cells
    classical, disk, delay = tables
    for label in ("roll (A)", "pitch (E)", "yaw (R)"):
        assert classical[label][2] == classical[label][4] == "unstable", classical[label]  # GM dB, PM deg
        assert disk[label][2:5] == ["unstable"] * 3 and disk[label][-1] == "unstable", disk[label]
        assert delay[label][3:] == ["unstable"] * 2, delay[label]  # delay margin ms, samples
    assert float(delay["altitude (T)"][3]) > 0  # a stable loop's delay margin
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
    assert {m["model"] for m in data["loops"]} == {"design", "coupled"}  # as the help says
    for m in data["loops"]:
        assert m["stable"] and m["meets_lqr_guarantee"], m["loop"]
        assert m["gain_margin_upper_db"] == "inf" and m["gain_margin_upper_freq"] is None


def test_design_only_hides_the_coupled_loops_and_its_help_says_margins_json_keeps_them():
    """The help said --coupled/--design-only decides whether the coupled loops are broken at all; they always
    are: --design-only leaves them out of the tables and the verdict, and margins.json (and --json) holds them."""
    shown = CliRunner().invoke(app, ["margins", "--help"], env={"COLUMNS": "200"}).output
    text = " ".join(shown.replace("│", "").split())
    assert "--design-only shows the design's loops alone. margins.json, and --json, hold both." in text


def test_the_figure_of_an_unstable_loop_says_it_has_no_margin():
    """L = 1 / (s - 2) closed by u = -x is unstable: no margin marked, the title says so; the stable
    integrator with a lag (phase never -180 deg: infinite gain margin) draws as before."""
    from quadctl.plots.frequency import margins_figure

    bad = loop_margins(BrokenLoop(np.array([[2.0]]), np.array([1.0]), np.array([1.0])))
    title = margins_figure(bad, title="t").get_suptitle()
    assert title.endswith("closed loop unstable, no margins"), title
    A = np.array([[0.0, 1.0], [0.0, -1.0]])
    good = loop_margins(BrokenLoop(A, np.array([0.0, 1.0]), np.array([2 ** 0.5, 0.0])))
    assert good.gain_margin_db == (-math.inf, math.inf)
    assert margins.least_margins([good]) == (math.inf, pytest.approx(45.0, abs=1e-6))
    assert "unstable" not in margins_figure(good).get_suptitle()
