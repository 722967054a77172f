"""The presenter: one eigenvalue format, the damp rows against closed forms, and how the margins
of a continuous and of a discrete design are worded."""

from __future__ import annotations

import ast
import cmath
import math

import numpy as np
import pytest
from _solve import cfg_dict, solve

import quadctl
from quadctl import present
from quadctl.design import margin_findings
from quadctl.linear import stability
from quadctl.present import cells, loops
from quadctl.present import design as shown
from quadctl.present import flight as shown_flight
from quadctl.text.messages import eig_text

PACKAGE = quadctl.__file__.rsplit("/", 1)[0]


@pytest.mark.parametrize("value, digits, text", [
    (-2.5, 5, "-2.5"),
    (-1 - 3.212345j, 5, "-1 - 3.2123j"),
    (complex(-0.0, 1e-12), 5, "0"),            # no "-0", round-off imaginary part left out
    (-0.0 + 2j, 5, "0 + 2j"),
    (-14492.84, 5, "-14493"),
    (-14492.84, 6, "-14492.8"),
    (0.9999999999 + 0j, 10, "0.9999999999"),
])
def test_an_eigenvalue_is_written_one_way(value, digits, text):
    assert eig_text(value, digits) == text
    if digits == 5:
        assert present.eig(value) == text == cells.num(complex(value))


@pytest.mark.parametrize("value, text", [(18.43, "+18.4"), (-26.49, "-26.5"), (0.0, "0"), (math.inf, "+inf"),
                                         (-math.inf, "-inf"), (None, "-")])
def test_a_margin_in_db(value, text):
    assert cells.db(value) == text


@pytest.mark.parametrize("lower, upper, text", [
    (-13.43, 13.43, "±13.4"),
    (0.0, 0.0, "0"),                 # an unstable loop: no margin, written as the classical margins are
    (-6.0206, math.inf, "-6.02 / +inf"),
    (-3.1, 5.2, "-3.1 / +5.2"),
])
def test_a_disk_gain_range(lower, upper, text):
    assert cells.gain_range_db(lower, upper) == text


def test_numbers_and_vectors_as_the_commands_print_them():
    assert cells.num(0.00077912) == "0.0007791" and cells.num(-0.0) == "0" and cells.num(None) == "-"
    assert cells.num(math.inf) == "inf" and cells.num(np.float64(2.0)) == "2"
    assert cells.vector(np.array([[0.21669, 7.4213, 1.0006]])) == "[0.2167, 7.421, 1.001]"
    assert cells.weights(np.diag([50.0, 1.0])) == "diag(50, 1)" and cells.weights([[2.0]]) == "2"
    assert cells.percent(0.02854) == "2.85 %" and cells.percent(None) == "-"
    mark = cells.Mark("met", "ok")
    assert mark == "met" and mark.kind == "ok" and mark.upper() == "MET"


def test_eigenvalues_are_formatted_only_by_messages_eig_text():
    """No module writes an eigenvalue's imaginary part with its own format (four did)."""
    offenders = []
    for path in sorted(__import__("pathlib").Path(PACKAGE).rglob("*.py")):
        if path.name == "messages.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.FormattedValue) and node.format_spec is not None
                    and isinstance(node.value, ast.Attribute) and node.value.attr == "imag"):
                offenders.append(f"{path.name}:{node.lineno}")
    assert offenders == []


def test_headroom_used_is_a_share_from_0_to_100_percent_each_way():
    """R at trim 0 in a box [-1e-7, 1e-7] N m, held at the lower limit the whole run: it used none of its room
    up and all of its room down. A (trim 0, box [-2, 2]) went to -0.5 and 1.5: 75 % up, 25 % down."""
    inf = math.inf
    sat = {"mode": "box", "actuators": ["T", "A", "E", "R"], "flag_above": 0.01,
           "fraction": {"T": 0.0, "A": 0.0, "E": 0.0, "R": 1.0},
           "low": [-inf, -2.0, -inf, -1e-7], "high": [inf, 2.0, inf, 1e-7],
           "peak_command": {"T": 0.7, "A": 1.5, "E": 0.0, "R": -1e-7},
           "min_command": {"T": 0.6, "A": -0.5, "E": 0.0, "R": -1e-7}}
    table = shown_flight.headroom_table({"saturation": sat}, [0.65, 0.0, 0.0, 0.0])
    used = {row[0]: row[4] for row in table.rows}
    assert used == {"T": "- / -", "A": "75 % / 25 %", "E": "- / -", "R": "0 % / 100 %"}


def test_damp_of_a_second_order_pair_and_a_real_pole():
    """``wn = |s|``, ``zeta = -Re(s)/|s|``, ``tau = -1/Re(s)``: a pair with wn = 5, zeta = 0.6 is -3 +- 4j."""
    wn, zeta = 5.0, 0.6
    pair = -zeta * wn + np.array([1j, -1j]) * wn * math.sqrt(1 - zeta ** 2)
    d = stability.damp([-10.0, *pair, 0.0])
    assert d.wn == pytest.approx([0.0, wn, wn, 10.0])  # lowest natural frequency first
    assert np.isnan(d.zeta[0]) and d.zeta[1:] == pytest.approx([zeta, zeta, 1.0])
    assert d.tau == pytest.approx([math.inf, 1 / (zeta * wn), 1 / (zeta * wn), 0.1])
    assert d.s[1].imag < 0 < d.s[2].imag and d.z is None


def test_damp_of_a_discrete_loop_reads_z_as_ln_z_over_ts():
    """z = exp(s Ts) gives back s (MATLAB's damp of a discrete system); z = 0 is infinitely fast, deadbeat."""
    Ts = 0.005
    s = np.array([-2.0 + 3.0j, -2.0 - 3.0j, -50.0, 0.0])
    d = stability.damp(np.append(np.exp(s * Ts), 0.0), Ts)
    assert d.s[:4] == pytest.approx(np.array([0.0, -2 - 3j, -2 + 3j, -50.0]))
    assert d.wn[:4] == pytest.approx([0.0, math.sqrt(13), math.sqrt(13), 50.0])
    assert d.zeta[1:4] == pytest.approx([2 / math.sqrt(13), 2 / math.sqrt(13), 1.0])
    assert d.tau[1:4] == pytest.approx([0.5, 0.5, 0.02])
    assert d.wn[4] == math.inf and d.zeta[4] == 1.0 and d.tau[4] == 0.0 and d.z[4] == 0


@pytest.mark.parametrize("name", ["hover", "mambo-200hz"])
def test_the_damp_table_of_a_design(name):
    """Every pole of the coupled loop once, with its closed-form wn, zeta and tau; a discrete design
    shows z and reads it as ln(z)/Ts; the free positions are marginal, every other pole stable."""
    _, _, _, _, des = solve(cfg_dict(name))
    table = shown.damp_table(des)
    discrete = des.full_eigenvalues_z is not None
    assert table.columns == (*(["pole z"] if discrete else []), "pole (rad/s)", "wn (rad/s)", "zeta", "tau (s)",
                             "verdict")
    poles = des.full_eigenvalues_z if discrete else des.full_eigenvalues
    assert len(table.rows) == len(poles)
    if discrete:
        assert sorted(table.column("pole z")) == sorted(eig_text(z) for z in poles)
    by_text = {eig_text(p): complex(p) for p in poles}
    for row in table.rows:
        pole = by_text[row[0]]
        s = cmath.log(pole) / des.sample_time if discrete else pole  # MATLAB damp: s = ln(z) / Ts
        assert row[-5] == eig_text(s)
        assert float(row[-4]) == pytest.approx(abs(s), rel=1e-4, abs=1e-12)
        if abs(s) < 1e-9:
            assert row[-3] == "-" and row[-2] == "inf" and row[-1] == "marginal: unregulated position"
            continue
        assert float(row[-3]) == pytest.approx(-s.real / abs(s), rel=2e-3)
        assert float(row[-2]) == pytest.approx(-1 / s.real, rel=1e-3)
        assert row[-1] == "stable" and row[-1].kind == "ok"
    assert [row[-1] for row in table.rows].count("marginal: unregulated position") == len(des.marginal_states)


def test_the_gains_table_shows_ki_beside_k_for_an_lqi_design():
    _, _, _, _, des = solve(cfg_dict("mambo-200hz"))
    table = shown.gains_table(des)
    assert table.columns[3:5] == ("K", "Ki") and "- Ki z" in table.title
    altitude = des["altitude"]
    assert table.column("Ki")[0] == "[" + ", ".join(f"{v:.4g}" for v in altitude.Ki.ravel()) + "]"
    assert table.column("Ki")[1:] == ("-", "-", "-")
    K = shown.gain_matrix_table(des)
    (int_row,) = [r for r in K.rows if r[0] == "int pD"]
    assert int_row[1] == f"{des.Ki_block[0, 0]:.4g}" and set(int_row[2:]) == {"·"}
    _, _, _, _, plain = solve(cfg_dict("forward"))
    assert "Ki" not in shown.gains_table(plain).columns


def _margins(name, **emulated):
    _, _, linear, dec, des = solve(cfg_dict(name))
    return des, margin_findings.all_margins(des, dec, linear.A, linear.B, **emulated)


def test_a_continuous_design_is_checked_against_the_lqr_guarantee():
    des, found = _margins("hover")
    assert des.rate is None
    disk = loops.disk_table(found, discrete=False)
    assert disk.columns[-1] == "guarantee" and set(disk.column("guarantee")) == {"met"}
    assert loops.guarantee_sentence(found, discrete=False) == (
        f"{len(found)} of {len(found)} loops meet the continuous LQR guarantee (gain margin [1/2, inf), i.e. "
        "-6.02 dB to +inf, phase margin >= 60 deg).")
    assert loops.summary(found, discrete=False) == (
        f"{len(found)} of {len(found)} loops meet the continuous LQR guarantee")
    # continuous gains run at a rate are still the continuous design: short of the guarantee, said so
    _, emulated = _margins("mambo-200hz", emulated_rate=200.0)
    short = [m for m in emulated if m.stable and not m.meets_lqr_guarantee]
    assert short and all(v in ("met", "short") for v in loops.disk_table(emulated, False).column("guarantee"))
    assert loops.guarantee_verdict(short[0]) == "short" and loops.guarantee_verdict(short[0]).kind == "warning"


def test_a_discrete_design_shows_the_margins_its_sampled_loops_have():
    """Said once, neutrally: the guarantee is continuous state feedback's; no loop is called short."""
    des, found = _margins("mambo-200hz")
    assert des.rate == 200 and not any(m.meets_lqr_guarantee for m in found)
    disk = loops.disk_table(found, discrete=True)
    assert "guarantee" not in disk.columns and set(disk.column("closed loop")) == {"stable"}
    text = loops.guarantee_sentence(found, discrete=True)
    assert text.startswith("The continuous LQR guarantee (gain margin [1/2, inf), i.e. -6.02 dB to +inf, phase "
                           "margin >= 60 deg) is a property of continuous state feedback that sampling does not keep")
    pm = min(found, key=lambda m: m.phase_margin_deg)
    disk_min = min(found, key=lambda m: m.disk_alpha)
    lo, hi = disk_min.disk_gain_db
    assert (f"least phase margin {pm.phase_margin_deg:.3g} deg ({pm.loop}, {pm.model}), least disk margin "
            f"±{hi:.3g} dB, {disk_min.disk_phase_deg:.3g} deg ({disk_min.loop}, {disk_min.model})") in text
    assert lo == pytest.approx(-hi)
    summary = loops.summary(found, discrete=True)
    assert summary.startswith(f"{len(found)} of {len(found)} sampled loops stable; least phase margin")
    every = " ".join([text, summary, *loops.notes(found), *disk.column("closed loop")])
    assert "short" not in every and "meet" not in every


def test_the_least_margins_of_a_discrete_design_with_unstable_loops_are_said_to_be_the_stable_loops():
    """With roll and pitch unstable (crazyflie flown with a 72.5 ms rotor lag its design ignores) the sentence
    named the yaw loop's 41 deg as the "least phase margin" of the sampled loops, with no word of the two
    that have none."""
    import dataclasses

    _, found = _margins("mambo-200hz")
    assert "unstable" not in loops.guarantee_sentence(found, discrete=True)
    broken = [dataclasses.replace(m, stable=False) if m.loop == "roll" else m for m in found]
    n = sum(m.loop == "roll" for m in found)
    text = loops.guarantee_sentence(broken, discrete=True)
    assert n == 2 and text.endswith(") (of the stable loops; 2 unstable, with no margin).")
    assert "(roll, " not in text  # the least margins are the stable loops'
