"""A design that includes the rotors' lag (``controller.rotor_lag: include``).

The lag-augmented design against its Riccati equations and a closed form, the controller's lag
model against the simulated rotors, the margins (the LQR guarantee on the augmented loop; the lag
model as a controller state on the coupled loop, against a closed form), the true closed loop's
eigenvalues, and what including the lag buys on the Mambo at 200 Hz with a 30 ms lag.
"""

from __future__ import annotations

import json
import math
import shlex
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg
from _paths import ROOT
from _solve import cfg_dict, solve
from typer.testing import CliRunner

from quadctl import config, pipeline
from quadctl.cli.app import app
from quadctl.config.notices import notices
from quadctl.design import broken_loops, discrete, integral, lag, linear_loop, margin_findings, margin_search
from quadctl.design.decoupled import solve_subsystem
from quadctl.design.riccati import riccati_residual
from quadctl.errors import ConfigError
from quadctl.sim.run import simulate

RICCATI_TOL = 1e-10
"""Relative residual of a Riccati equation at the design's P: round-off of a well-posed solve (measured
below 2e-16 for every subsystem here)."""
GAIN_RTOL = 1e-9
"""Gains against a closed form or SciPy's solver: both exact to round-off, amplified by the
conditioning of the Riccati equation (measured 1e-13)."""
MODEL_VS_ROTORS = 1e-8
"""N: the controller's lag model (its exact ZOH per sample) against the plant's rotors (RK4 at five
steps a sample, local error (dt / tau)^5 / 120 ~ 3e-10 of the step's change): measured 1.0e-9."""
TAU = 0.03
"""s: the Mambo's rotor lag used throughout (as docs/configs/mambo-rotor-lag.yaml)."""


def _mambo(rotor_lag: str, delay: int = 0) -> dict:
    data = cfg_dict("mambo-200hz")
    data["controller"]["rotor_lag"] = rotor_lag
    if delay:
        data["controller"]["delay"] = {"samples": delay}
    data["motors"]["time_constant"] = TAU
    data["simulation"]["initial_offset"] = {"pD": 0.5, "phi": 0.4, "theta": 0.1}  # the rotors saturate
    return data


def _hover(rotor_lag: str = "include") -> dict:
    """The report's hover design, continuous, with a 20 ms lag."""
    data = cfg_dict("hover", motors={"time_constant": 0.02})
    data["controller"]["rotor_lag"] = rotor_lag
    data["simulation"]["initial_offset"] = {"phi": 0.02}
    return data


@pytest.mark.parametrize("q, r, tau", [(4.0, 1.0, 1.5), (100.0, 1e-2, 0.03), (1.0, 4e4, 0.005)])
def test_a_lagged_integrator_gain_has_its_closed_form(q, r, tau):
    """``x' = v``, ``v' = (u - v) / tau``, ``Q = diag(q, 0)``: ``k_x = sqrt(q/r)``,
    ``k_v = sqrt(1 + 2 tau k_x) - 1``."""
    sub = SimpleNamespace(A=np.zeros((1, 1)), B=np.ones((1, 1)), states=("x",), inputs=("u",), name="integrator")
    K, Kv, Ki, P, eig, _, residual = solve_subsystem(sub, np.array([[q]]), np.array([[r]]), (), None, tau)
    kx, kv = lag.scalar_integrator_gain(q, r, tau)
    assert K[0, 0] == pytest.approx(kx, rel=GAIN_RTOL) and Kv[0, 0] == pytest.approx(kv, rel=GAIN_RTOL)
    assert Ki.size == 0 and residual < RICCATI_TOL
    # the closed loop s^2 + c1 s + c0 of the return-difference equation
    a = 1 / tau
    c0 = a * math.sqrt(q / r)
    np.testing.assert_allclose(np.sort_complex(eig), np.sort_complex(np.roots([1, math.sqrt(a * a + 2 * c0), c0])),
                               rtol=GAIN_RTOL)


def test_each_subsystem_of_a_continuous_included_design_solves_its_riccati_equation():
    """On ``[x; v; z]``: the lagged plant (:func:`quadctl.design.lag.lagged`) with its integrators, Q zero on ``v``."""
    setup, _, _, dec, des = solve(_hover())
    assert des.lag_time_constant == 0.02
    for sub in des.subsystems:
        dsub = dec[sub.name]
        Al, Bl = lag.lagged(dsub.A, dsub.B, 0.02)
        m = Bl.shape[1]
        C = np.hstack([integral.selector(sub.states, sub.integral), np.zeros((len(sub.integral), m))])
        Aa, Ba = integral.augment(Al, Bl, C)
        assert sub.Q.shape == Aa.shape and not np.any(sub.Q[len(sub.states):len(sub.states) + m])
        res = riccati_residual(Aa, Ba, sub.Q, sub.R, sub.P)
        assert res < RICCATI_TOL, f"{sub.name}: residual {res:.3e}"
        K = np.linalg.solve(sub.R, Ba.T @ sub.P)
        Kd = np.hstack([sub.K, sub.Kv, *([sub.Ki] if sub.Ki is not None else [])])
        np.testing.assert_allclose(Kd, K, rtol=GAIN_RTOL, atol=GAIN_RTOL * np.abs(K).max())


def test_each_subsystem_of_a_discrete_included_design_is_scipys_dare_on_the_zoh_of_the_lagged_plant():
    """lqrd on ``[x; v]`` (the ZOH of the lag is exact: ``v <- a v + (1 - a) u``), then the LQI accumulator."""
    setup, _, _, dec, des = solve(_mambo("include"))
    Ts = des.sample_time
    for sub in des.subsystems:
        dsub = dec[sub.name]
        n = len(sub.states)
        Al, Bl = lag.lagged(dsub.A, dsub.B, TAU)
        nl = Bl.shape[1]
        Ad, Bd = discrete.c2d(Al, Bl, Ts)
        np.testing.assert_allclose(Ad[n:, n:], lag.model_pole(TAU, Ts) * np.eye(nl), rtol=1e-13)
        keep = [*range(n), *range(n + nl, sub.Q.shape[0])]
        Q = sub.Q[np.ix_(keep, keep)]  # the config's weights of [x; z]
        Qfull = np.zeros_like(sub.Q)
        Qfull[np.ix_(keep, keep)] = Q
        Ad, Bd, Qd, Rd, Nd = discrete.lqrd_weights(Al, Bl, Qfull[:n + nl, :n + nl], sub.R, Ts)
        C = np.hstack([integral.selector(sub.states, sub.integral), np.zeros((len(sub.integral), nl))])
        Aa, Ba = integral.augment_discrete(Ad, Bd, C, Ts)
        Qa, Na = integral.discrete_weights(Qd, Nd, Qfull, Ts)
        P = scipy.linalg.solve_discrete_are(Aa, Ba, Qa, Rd, s=Na)
        K = np.linalg.solve(Rd + Ba.T @ P @ Ba, Ba.T @ P @ Aa + Na.T)
        Kd = np.hstack([sub.K, sub.Kv, *([sub.Ki] if sub.Ki is not None else [])])
        np.testing.assert_allclose(Kd, K, rtol=1e-7, atol=1e-7 * np.abs(K).max())
        assert sub.residual < RICCATI_TOL


@pytest.mark.parametrize("which", ["held", "continuous"])
def test_the_controllers_lag_model_is_the_simulated_rotors(which):
    """With the model right (the plant's tau, no delay) ``l = mix_inv f - u_trim``, saturation included:
    at every sample of a held loop (its exact ZOH against RK4), at every step of a continuous one
    (the same ODE under the same RK4)."""
    data = _mambo("include") if which == "held" else _hover()
    setup, _, linear, _, des = solve(data)
    loop = pipeline.loop_of(setup, linear, des)
    sim = simulate(loop, setup.initial_state(loop.x_trim), 1.0 if which == "held" else 0.3, max_samples=10 ** 6)
    assert sim.status == "ok" and sim.stride == 1
    v = sim.rotor_thrust @ loop.actuators.mix_inv.T - loop.u_trim
    every = round(1 / (loop.rate * sim.dt)) if which == "held" else 1
    worst = np.abs(v - sim.lag_model)[::every].max()
    assert worst < (MODEL_VS_ROTORS if which == "held" else 1e-14), f"Max diff is {worst:.4E}"
    assert np.abs(v).max() > 1e-3  # the rotors did move
    if which == "held":
        assert np.any(loop.actuators.commands(sim.u) >= loop.actuators.hi - 1e-12)  # and saturated


def test_the_true_closed_loop_is_the_design_and_the_lag_models_error_modes():
    """``[x; v; z; l]`` under ``u = -K x - Ki z - Kv l``: the error ``v - l`` obeys ``e' = -e / tau``, so the
    eigenvalues are the design's (of ``[x; v; z]``) and four at ``-1/tau`` (``exp(-Ts/tau)`` sampled)."""
    for data, Ts in ((_hover(), None), (_mambo("include"), 0.005)):
        setup, _, linear, _, des = solve(data)
        tau = des.lag_time_constant
        A, B, K = linear_loop.vehicle(des, linear.A, linear.B, Ts, 0, tau)
        got = np.linalg.eigvals(A - B @ K)
        model = np.full(4, lag.model_pole(tau, Ts))
        core = des.full_eigenvalues_z if Ts else des.full_eigenvalues
        keep = [e for e in core if abs(e - (1.0 if Ts else 0.0)) > 1e-12]  # the free positions are left out
        want = np.concatenate([keep, model])
        assert len(got) == len(want)
        for w in want:
            assert np.min(np.abs(got - w)) < 1e-9 * max(1.0, abs(w)), w


def test_the_augmented_loop_meets_the_lqr_guarantee_and_the_model_in_the_controller_has_its_closed_form():
    """Continuous: on the design model (the lag states fed back as the design assumes) every loop has
    ``|1 + L| >= 1``. With the lag model in the controller, broken at the rotors' command, a lagged
    integrator's loop is ``k_x / (s (tau s + 1 + k_v))``: phase margin ``90 - atan(w_c tau / (1 + k_v))``."""
    setup, _, linear, dec, des = solve(_hover())
    loops = margin_findings.all_margins(des, dec, linear.A, linear.B, rotor_time_constant=0.02)
    design_loops = [m for m in loops if m.model == "design"]
    assert design_loops and all(m.meets_lqr_guarantee for m in design_loops), \
        [(m.loop, m.phase_margin_deg, m.gain_margin_db) for m in design_loops]
    q, r, tau = 100.0, 1.0, 0.05
    kx, kv = lag.scalar_integrator_gain(q, r, tau)
    Al, Bl = lag.lagged(np.zeros((1, 1)), np.ones((1, 1)), tau)
    A, B, K = linear_loop.with_lag_model(Al, Bl, np.array([[kx, 0.0]]), np.array([[kv]]), tau)
    m = margin_search.loop_margins(broken_loops.BrokenLoop(A, B[:, 0], K[0]))
    b = (1 + kv) ** 2  # tau^2 w^4 + (1 + kv)^2 w^2 - kx^2 = 0 at the crossover
    wc = math.sqrt((-b + math.sqrt(b * b + 4 * tau ** 2 * kx ** 2)) / (2 * tau ** 2))
    assert m.gain_crossover_freq == pytest.approx(wc, rel=1e-9)
    assert m.phase_margin_deg == pytest.approx(90 - math.degrees(math.atan(wc * tau / (1 + kv))), rel=1e-9)


def test_including_a_30ms_lag_at_200hz_restores_the_roll_and_pitch_phase_margins():
    """mambo-200hz with a 30 ms lag, coupled loops at the rotors' command: roll 17.4 deg (ignore)
    against 46.2 deg (include, the lag model in the controller); the augmented design loop 61.6 deg."""
    out = {}
    for mode in ("ignore", "include"):
        setup, _, linear, dec, des = solve(_mambo(mode))
        loops = margin_findings.all_margins(des, dec, linear.A, linear.B, rotor_time_constant=TAU)
        out[mode] = {(m.loop, m.model): m for m in loops}
    for axis in ("roll", "pitch"):
        ignore, include = out["ignore"][(axis, "coupled")], out["include"][(axis, "coupled")]
        assert ignore.phase_margin_deg < 20 and include.phase_margin_deg > 45, (ignore.phase_margin_deg,
                                                                                include.phase_margin_deg)
        assert include.delay_margin > 2 * ignore.delay_margin
        assert out["include"][(axis, "design")].phase_margin_deg > 60


def test_include_runs_the_flight_with_less_overshoot_and_the_same_cost_of_settling():
    """The whole flight (noise off), mambo-200hz, 30 ms lag: the roll overshoot with include is below ignore's."""
    peaks = {}
    for mode in ("ignore", "include"):
        setup, _, linear, _, des = solve(_mambo(mode))
        loop = pipeline.loop_of(setup, linear, des)
        sim = simulate(loop, setup.initial_state(loop.x_trim), 3.0)
        assert sim.status == "ok"
        phi = sim.x[:, 6] - sim.x_ref[:, 6]
        peaks[mode] = -phi.min() / phi[0]  # the undershoot past zero, as a fraction of the 0.4 rad offset
    assert peaks["include"] < peaks["ignore"], peaks


def test_include_without_a_time_constant_is_refused():
    data = cfg_dict("mambo-200hz")
    data["controller"]["rotor_lag"] = "include"
    with pytest.raises(ConfigError, match=r"controller.rotor_lag = \"include\": needs the rotors' lag to include: set "
                                          r"motors.time_constant \(s\), or use rotor_lag: ignore"):
        config.from_dict(data)


@pytest.mark.parametrize("given, noted", [(None, True), ("ignore", False), ("include", False)])
def test_a_time_constant_without_rotor_lag_says_which_the_design_took(given, noted):
    data = cfg_dict("mambo-200hz")
    data["motors"]["time_constant"] = TAU
    data["controller"].pop("rotor_lag", None)
    if given is not None:
        data["controller"]["rotor_lag"] = given
    found = [n for n in notices(config.from_dict(data, "c.yaml"), "c.yaml") if n.key == "controller.rotor_lag"]
    assert bool(found) == noted
    if noted:
        assert "the design ignores the lag (rotor_lag: ignore, the default)" in found[0].message


def _lag_section() -> str:
    text = (ROOT / "docs" / "guide" / "flying.md").read_text(encoding="utf-8")
    return text[text.index("**10. Designing with the rotors' lag"):text.index("## Flight config keys")]


def test_the_rotor_lag_table_is_what_the_commands_write(tmp_path, monkeypatch):
    """docs/guide/flying.md, 10: the table's numbers are those of margins.json (roll: design and coupled) and sim.json
    of the ignore and include configs."""
    root = ROOT
    monkeypatch.chdir(root)
    section = _lag_section()
    found = {}
    for name in ("mambo-rotor-lag", "mambo-rotor-lag-include"):
        out = tmp_path / name
        for command in ("margins", "simulate"):
            res = CliRunner().invoke(app, [command, "-c", f"docs/configs/{name}.yaml", "-o", str(out)])
            thin = command == "margins" and name == "mambo-rotor-lag"  # 17.4 deg: below 30, a failed check
            assert res.exit_code == (1 if thin else 0), res.output
        loops = json.loads((out / "margins.json").read_text())["loops"]
        roll = {m["model"]: m for m in loops if m["loop"] == "roll"}
        metrics = json.loads((out / "sim.json").read_text())["metrics"]
        c = roll["coupled"]
        found[name] = [
            *(f"{roll[k]['phase_margin_deg']:.3g} deg at {roll[k]['gain_crossover_freq']:.3g} rad/s"
              for k in ("design", "coupled")),
            f"{c['delay_margin']['s'] * 1e3:.3g} ms ({c['delay_margin']['samples']:.3g} samples)",
            f"±{c['disk_gain_margin_db'][1]:.3g} dB, {c['disk_phase_margin_deg']:.3g} deg",
            *(f"{metrics['settling_time'][s]:.3g} s, {metrics['overshoot'][s]:.3g} %" for s in ("phi", "theta"))]
    rows = [line for line in section.splitlines() if line.startswith("| ") and "---" not in line][1:]
    columns = list(zip(*[[cell.strip() for cell in row.strip("|").split("|")[1:]] for row in rows]))
    assert [list(col) for col in columns] == [found["mambo-rotor-lag"], found["mambo-rotor-lag-include"]]
    commands = [shlex.split(line[2:].split("  #")[0]) for line in section.splitlines() if line.startswith("$ quadctl")]
    assert ["quadctl", "margins", "-c", "docs/configs/mambo-rotor-lag-include.yaml"] in commands


@pytest.mark.parametrize("rotor_lag, stable", [("ignore", False), ("include", True)])
def test_two_samples_of_delay_with_the_lag_are_unstable_unless_the_design_includes_it(rotor_lag, stable, tmp_path):
    """margins.json's closed loop (lag, lag model, delay) against the margins: with a 30 ms lag the ignore
    design tolerates 1.73 samples of delay, the include design 5.59; two samples split them."""
    import yaml

    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(_mambo(rotor_lag, delay=2)))
    res = CliRunner().invoke(app, ["margins", "-c", str(path), "-o", str(tmp_path / "out")])
    thin = any(m["thin"] for m in json.loads((tmp_path / "out" / "margins.json").read_text())["loops"])
    assert res.exit_code == (0 if stable and not thin else 1), res.output  # thin margins fail the check too
    closed = json.loads((tmp_path / "out" / "margins.json").read_text())["closed_loop"]
    radius = max(math.hypot(*e) for e in closed["eigenvalues"])
    assert closed["stable"] is stable and closed["domain"] == "z"
    assert (radius < 1) is stable and radius == pytest.approx(closed["spectral_radius"], rel=1e-12)
    assert ("closed loop with a 30 ms rotor lag (" + rotor_lag + "d by the design) and 2 samples of delay: "
            + ("stable" if stable else "UNSTABLE")) in " ".join(res.output.split())


def test_python_control_interop_refuses_a_design_whose_controller_has_lag_states():
    pytest.importorskip("control")
    from quadctl.export import interop

    setup, _, linear, _, des = solve(_mambo("include"))
    with pytest.raises(ValueError, match=r"the design includes the rotors' lag \(controller.rotor_lag: include\)"):
        interop.closed_loop(linear, des)
    with pytest.raises(ValueError, match="lag-model states"):
        interop.controller(pipeline.loop_of(setup, linear, des))


def test_design_full_refuses_an_included_lag_with_the_key_and_the_way_out(tmp_path):
    path = ROOT / "docs/configs/mambo-rotor-lag-include.yaml"
    res = CliRunner().invoke(app, ["design", "--full", "-c", str(path), "-o", str(tmp_path)])
    assert res.exit_code == 2
    assert "controller.rotor_lag = include: design --full (one coupled LQR) is built for designs without the " \
           "rotors' lag only" in " ".join(res.output.split())
