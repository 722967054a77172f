"""Margins a user can act on: a stable loop below 6 dB of gain margin or 30 deg of phase margin (the
classical requirement, MIL-F-9490D) is flagged, and fails the check unless the config accepts it."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from quadctl import config, stages
from quadctl.cli.app import app
from quadctl.design import broken_loops, margin_search, margins
from quadctl.present.loops import thin_sentence

runner = CliRunner()
LAGGED = "docs/configs/mambo-rotor-lag.yaml"  # mambo-200hz's design on rotors that lag 30 ms: 17.4 deg (roll)


def _third_order(k: float) -> margins.LoopMargins:
    """``L(s) = k / (s + 1)^3`` broken from its state-space form (companion of ``s^3 + 3 s^2 + 3 s + 1``)."""
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -3.0, -3.0]])
    B = np.array([[0.0], [0.0], [1.0]])
    return margin_search.loop_margins(broken_loops.broken_loop(A, B, np.array([[k, 0.0, 0.0]]), 0))


def _closed_form(k: float) -> tuple[float, float]:
    """(upper gain margin dB, phase margin deg) of ``k / (s + 1)^3``: the phase crosses -180 deg at
    ``w = sqrt 3`` where ``|L| = k / 8``; ``|L| = 1`` at ``w = sqrt(k^(2/3) - 1)``, phase ``-3 atan w``."""
    w = math.sqrt(k ** (2.0 / 3.0) - 1.0)
    return 20 * math.log10(8.0 / k), 180.0 - 3 * math.degrees(math.atan(w))


@pytest.mark.parametrize(("k", "thin"), [(2.0, ()), (3.5, ()), (3.8, ("phase",)), (4.5, ("gain", "phase"))])
def test_a_loop_is_thin_where_its_closed_form_margins_are_below_the_requirement(k, thin):
    m = _third_order(k)
    gm, pm = _closed_form(k)
    assert m.gain_margin_db[1] == pytest.approx(gm, abs=1e-6) and m.phase_margin_deg == pytest.approx(pm, abs=1e-6)
    assert m.thin == thin
    assert (gm < margins.THIN_GAIN_MARGIN_DB) == ("gain" in thin)
    assert (pm < margins.THIN_PHASE_MARGIN_DEG) == ("phase" in thin)
    assert m.as_dict()["thin"] == list(thin)


def test_a_lower_gain_margin_inside_6_db_is_thin_and_an_unstable_loop_is_not_called_thin():
    base = _third_order(2.0)
    fragile = margins.LoopMargins(**{**base.__dict__, "gain_margin_db": (-4.0, math.inf)})
    assert fragile.thin == ("gain",)
    assert _third_order(9.0).stable is False and _third_order(9.0).thin == ()  # k > 8: unstable, no margin


def _lagged(tmp_path, allow=()):
    data = config.load(LAGGED).model_dump(mode="json")
    data["allow"] = list(allow)
    path = tmp_path / "lagged.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_margins_fails_the_check_on_thin_margins_and_says_what_to_do(tmp_path):
    res = runner.invoke(app, ["margins", "-c", _lagged(tmp_path), "-o", str(tmp_path / "run")])
    assert res.exit_code == 1, res.output
    said = " ".join(res.output.split())
    assert "check failed: thin margins, below 6 dB of gain margin or 30 deg of phase margin (MIL-F-9490D): " in said
    assert "roll (design): phase margin 17.4 deg" in said and "pitch (coupled): phase margin 18.7 deg" in said
    assert "yaw" not in said.split("check failed")[1] and "altitude" not in said.split("check failed")[1]
    assert "allow: [thin-margins] in the config accepts it" in said


def test_allow_thin_margins_accepts_them_with_a_warning(tmp_path):
    res = runner.invoke(app, ["margins", "-c", _lagged(tmp_path, ["thin-margins"]), "-o", str(tmp_path / "run")])
    assert res.exit_code == 0, res.output
    assert "(accepted: allow: [thin-margins])" in " ".join(res.output.split())


def test_the_report_fails_on_thin_margins_after_the_flight(tmp_path):
    from quadctl.workspace import Workspace

    ws = Workspace(config.load(_lagged(tmp_path)), tmp_path / "run")
    outcome = stages.run_stages(ws)
    assert outcome.done[-1] == "simulate" and outcome.failed.startswith("margins: thin margins")
    assert thin_sentence(ws.margins, accepted=True).endswith("(accepted: allow: [thin-margins])")
