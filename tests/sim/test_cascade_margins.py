"""Margins of the PID cascade's loops against what they must equal.

The lifted loop (:mod:`quadctl.sim.cascade_margins`) must have the poles of the loop the simulation
flies: the eigenvalues of the Jacobian of one frame of the compiled law and RK4 plant, as sets. A
single-rate P loop on an integrator has phase and gain margins in closed form; the same loop
written as a frame of three identical samples must keep them (the lifting and its fundamental
harmonic are exact for a loop at one rate).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadctl.design.margins import loop_margins
from quadctl.sim.cascade_margins import Lifted, exact_gain_margins

J, KP, TS = 1.4e-5, 0.004, 0.002  # kg m^2 (a Crazyflie's roll inertia), N m s/rad, s (500 Hz): kp Ts / J = 0.57


def p_rate_loop(frame: int) -> Lifted:
    """``J w' = u``, ``u = -kp w`` sampled with a ZOH, written as ``frame`` identical samples."""
    plant = (np.array([[1.0]]), np.array([[TS / J, 0.0, 0.0, 0.0]]))
    law_state = [np.eye(1)] * frame
    command = np.zeros((4, 1))
    command[0, 0] = -KP
    return Lifted(plant=plant, law_state=law_state, law_command=[command] * frame, sample_time=TS)


@pytest.mark.parametrize("frame", [1, 3])
def test_a_sampled_p_rate_loop_has_its_closed_form_margins(frame):
    # L(z) = a / (z - 1), a = kp Ts / J: |L| = 1 where 2 sin(w Ts / 2) = a, and there angle L = -(90 + w Ts / 2)
    # deg, so PM = 90 - asin(a / 2) (deg); L(-1) = -a / 2: upper gain margin 2 / a, no lower one.
    a = KP * TS / J
    loop = p_rate_loop(frame).broken(0)
    m = loop_margins(loop, grid=loop.grid(200))
    assert m.stable
    assert m.phase_margin_deg == pytest.approx(90 - math.degrees(math.asin(a / 2)), abs=1e-7)
    assert m.gain_crossover_freq == pytest.approx(2 * math.asin(a / 2) / TS, rel=1e-9)
    assert m.gain_margin_db[1] == pytest.approx(20 * math.log10(2 / a), abs=1e-7)
    lower, upper = exact_gain_margins(loop)  # from the lifted loop's poles: bisected to ~1e-12 in the gain
    assert upper == pytest.approx(20 * math.log10(2 / a), abs=1e-6) and lower == -math.inf


@pytest.fixture(scope="module")
def crazyflie_cascade():
    import quadctl as qc
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim.cascade_margins import lifted

    stages = qc.Stages(qc.setup_of(qc.load_config("crazyflie")))
    loop = pid_loop_of(stages.setup, stages.linear)
    return loop, lifted(loop)


def simulated_frame_jacobian(loop, lift: Lifted, substeps: int = 8) -> np.ndarray:
    """d(X after one frame)/dX of the compiled loop's law and RK4 plant, at the lift's equilibrium."""
    import casadi as ca

    from quadctl.sim.builder import build

    spec = loop.spec()
    funcs = build(spec)
    c, e = loop.constants(lift.sample_time), np.zeros(spec.n_exo)
    X = ca.MX.sym("X", spec.nx)
    Y = X
    for _ in range(lift.frame):
        u, Y = funcs.law(Y, 0.0, c, e)
        for _ in range(substeps):
            Y = funcs.plant(Y, u, lift.sample_time / substeps, c, e)
    return np.asarray(ca.Function("frame", [X], [ca.jacobian(Y, X)])(lift.equilibrium))


def test_the_lifted_cascade_has_the_poles_of_the_simulated_multirate_loop(crazyflie_cascade):
    loop, lift = crazyflie_cascade
    assert lift.frame == loop.law.ratios[1] > 1  # a multi-rate loop: the outer loops held over the frame
    keep = lift.states
    J_sim = simulated_frame_jacobian(loop, lift)[np.ix_(keep, keep)]
    Phi = lift.frame_map
    # first-order perturbation theory: each eigenvalue moves at most its condition number 1/|y^H x| times the
    # size of the difference of the two maps (RK4 against expm: ~1e-11 here, the maps ~6e4); twice that, as sets
    got, right = np.linalg.eig(Phi)
    left = np.linalg.inv(right).conj().T
    kappa = np.linalg.norm(left, axis=0) * np.linalg.norm(right, axis=0) / np.abs(np.sum(left.conj() * right, axis=0))
    gap = np.linalg.norm(J_sim - Phi, 2)
    assert gap < 1e-6 * np.linalg.norm(Phi, 2)  # the maps themselves agree: the lifting is the simulated loop's
    want = np.linalg.eigvals(J_sim)
    for g, k in zip(got, kappa):
        i = int(np.argmin(np.abs(want - g)))
        diff = abs(want[i] - g)
        assert diff <= 2 * k * gap + 1e-12, f"pole {g} vs {want[i]}: diff {diff:.4E}, bound {2 * k * gap:.4E}"
        want = np.delete(want, i)
    assert max(abs(got)) < 1  # and the cascade holds hover


def test_cascade_margins_are_one_loop_per_input_with_exact_gain_margins(crazyflie_cascade):
    from quadctl.sim.cascade_margins import cascade_margins

    loop, lift = crazyflie_cascade
    margins = cascade_margins(loop)
    assert [m.input for m in margins] == ["T", "A", "E", "R"]
    for j, m in enumerate(margins):
        assert m.stable and m.model == "cascade"
        lower, upper = m.gain_margin_db
        broken = lift.broken(j)
        if math.isfinite(upper):  # just inside the margin stable, just outside not
            assert broken.is_stable(10 ** (upper / 20) * (1 - 1e-6))
            assert not broken.is_stable(10 ** (upper / 20) * (1 + 1e-6))


def test_margins_command_shows_the_cascade_that_flies_and_fails_its_thin_roll_loop(tmp_path):
    """controller.flies: pid: margins.json holds the cascade's four loops; the stock Crazyflie cascade's roll
    and pitch loops have less than 6 dB (MIL-F-9490D), which fails the check, naming the cascade's values."""
    import json

    from typer.testing import CliRunner

    from quadctl.cli.app import app

    res = CliRunner().invoke(app, ["margins", "-c", "crazyflie", "--set", "controller.flies=pid", "-o", str(tmp_path)])
    assert res.exit_code == 1, res.output
    assert "lifted to its 10 ms frame" in res.output and "controller.pid.values" in res.output
    data = json.loads((tmp_path / "margins.json").read_text())
    assert data["law"] == "pid" and data["closed_loop"]["stable"] is True
    assert [loop["input"] for loop in data["loops"]] == ["T", "A", "E", "R"]


def test_the_report_of_a_config_flying_the_cascade_shows_its_loops(tmp_path):
    from quadctl.cli.options import open_workspace
    from quadctl.report import content

    section = content.margins(open_workspace("crazyflie", tmp_path, sets=["controller.flies=pid"]))
    texts = [b.text for b in section.blocks if hasattr(b, "text")]
    assert any("lifted to its 10 ms frame" in t for t in texts)
    assert [b.name for b in section.blocks if hasattr(b, "png")] == [f"margins-crazyflie-{s}" for s in "TAER"]
