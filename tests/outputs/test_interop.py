"""python-control interop: named StateSpace systems that reproduce quadctl's eigenvalues and margins."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest
from _solve import cfg_dict, solve

from quadctl.design import closed_loop_matrix, lqr, margin_findings
from quadctl.export import interop
from quadctl.layout import INPUT_NAMES, STATE_NAMES

control = pytest.importorskip("control")

EIG_TOL = 1e-9
"""Closed-loop eigenvalues, python-control's against quadctl's (|z| <= 1, |s| up to 1.5e4 rad/s:
relative to max(1, |eigenvalue|)). The same matrices pass through python-control's feedback
interconnection, whose products and sums round differently."""


def _match(got, want) -> float:
    """Largest relative distance from each wanted eigenvalue to its nearest unused got one."""
    got, worst = list(np.asarray(got, dtype=complex)), 0.0
    for w in np.asarray(want, dtype=complex):
        k = int(np.argmin([abs(g - w) for g in got]))
        worst = max(worst, abs(got.pop(k) - w) / max(1.0, abs(w)))
    return worst


@pytest.mark.parametrize("name", ["mambo-200hz", "crazyflie", "forward"])
def test_the_loops_reproduce_quadctls_closed_loop_eigenvalues(name):
    """Two ways: the closed loop as one system, and python-control's own feedback interconnection
    of the plant and the controller (integrators included, sampled where the design is)."""
    _, _, linear, _, des = solve(cfg_dict(name))
    want = np.linalg.eigvals(closed_loop_matrix(linear.A, linear.B, des.K_block, des.Ki_block,
                                                des.integral_states, des.sample_time))
    loop = interop.closed_loop(linear, des)
    assert loop.dt == (des.sample_time or 0)
    assert loop.state_labels == [*STATE_NAMES, *(f"z_{s}" for s in des.integral_states)]
    assert _match(loop.poles(), want) < EIG_TOL
    plant, ctl = interop.plant(linear, sample_time=des.sample_time), interop.controller(des)
    assert plant.input_labels == list(INPUT_NAMES) and ctl.output_labels == list(INPUT_NAMES)
    assert ctl.input_labels == list(STATE_NAMES)
    fb = control.feedback(plant, ctl, sign=1)  # u = controller(x): the controller carries the minus
    assert _match(fb.poles(), want) < EIG_TOL
    if des.sample_time:
        z = des.full_eigenvalues_z
        assert _match(loop.poles(), z) < EIG_TOL


def test_one_loop_has_quadctls_margins():
    """The Crazyflie's roll loop, sampled at 500 Hz and broken at its input: python-control's
    stability_margins of K * subsystem agree with quadctl.design.margin_search (lower gain margin, phase margin
    and its crossover).

    On its frequency response (1 rad/s to Nyquist, 20001 points, crossings interpolated) it agrees
    to 1e-9; its default method, from the roots of polynomials in z, finds the phase crossover only
    to 3e-5 here (quadctl's root-refined crossing has |Im L| = 6e-14 there), so that one is held to 1e-4."""
    _, _, linear, dec, des = solve(cfg_dict("crazyflie"))
    roll, Ts = des["roll"], des.sample_time
    sub = interop.subsystem(dec["roll"], sample_time=Ts)
    assert sub.state_labels == ["v", "phi", "p"] and sub.input_labels == ["A"] and sub.dt == 0.002
    L = control.series(sub, control.ss([], [], [], roll.K, dt=Ts))
    grid = np.logspace(0, np.log10(np.pi / Ts), 20001)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # python-control evaluates near the Nyquist frequency
        gm, pm, _, w_gm, wgc, _ = control.stability_margins(control.frd(L, grid))
        gm_poly, pm_poly, *_ = control.stability_margins(L)
    ours = [m for m in margin_findings.all_margins(des, dec, linear.A, linear.B)
            if m.loop == "roll" and m.model == "design"][0]
    assert 20 * np.log10(gm) == pytest.approx(ours.gain_margin_db[0], rel=1e-9)
    assert w_gm == pytest.approx(ours.phase_crossover_freqs[0], rel=1e-9)
    assert pm == pytest.approx(ours.phase_margin_deg, rel=1e-9)
    assert wgc == pytest.approx(ours.gain_crossover_freq, rel=1e-9)
    assert 20 * np.log10(gm_poly) == pytest.approx(ours.gain_margin_db[0], rel=1e-4)
    assert pm_poly == pytest.approx(ours.phase_margin_deg, rel=1e-6)


def test_a_statespace_comes_back_as_a_plant_quadctl_designs_for():
    _, _, linear, _, des = solve(cfg_dict("forward"))
    plant = interop.from_statespace(interop.plant(linear))
    A, B = plant
    assert np.array_equal(A, linear.A) and np.array_equal(B, linear.B)
    assert plant.state_names == STATE_NAMES and plant.input_names == INPUT_NAMES and plant.dt == 0.0
    # a double integrator from python-control: MATLAB lqr's K = [sqrt(q), sqrt(2 sqrt(q))]
    sys_ = control.ss([[0, 1], [0, 0]], [[0], [1]], np.eye(2), 0, states=["x", "v"], inputs=["F"], outputs=["x", "v"])
    K, P, E = interop.from_statespace(sys_).lqr(np.diag([4.0, 0.0]), [[1.0]])
    np.testing.assert_allclose(K, [[2.0, 2.0]], rtol=1e-12)
    K_ref, _, _ = control.lqr(sys_, np.diag([4.0, 0.0]), [[1.0]])
    np.testing.assert_allclose(K, K_ref, rtol=1e-9)
    # a discrete one designs with dlqr (python-control decides by dt, and so does the plant)
    sysd = control.c2d(sys_, 0.1)
    Kd = interop.from_statespace(sysd).lqr(np.diag([4.0, 0.0]), [[1.0]]).K
    np.testing.assert_allclose(Kd, control.dlqr(sysd, np.diag([4.0, 0.0]), [[1.0]])[0], rtol=1e-9)
    K2, _, _ = lqr(linear.A[np.ix_([2, 5], [2, 5])], linear.B[[2, 5]][:, [0]], np.diag([50.0, 1.0]), [[1.0]])
    np.testing.assert_allclose(K2, des["altitude"].K, rtol=1e-9)


@pytest.mark.parametrize("dt", [0, 0.1])
def test_a_plants_lqr_takes_the_cross_weight_as_python_controls_does(dt):
    """python-control's lqr(sys, Q, R, N) and dlqr(sys, Q, R, N): Plant.lqr(Q, R, N) was a TypeError."""
    sys_ = control.ss([[0, 1], [0, 0]], [[0], [1]], np.eye(2), 0)
    sys_ = control.c2d(sys_, dt) if dt else sys_
    Q, R, N = np.diag([4.0, 1.0]), [[1.0]], [[0.5], [0.0]]
    K, P, E = interop.from_statespace(sys_).lqr(Q, R, N)
    K_ref, P_ref, E_ref = (control.dlqr if dt else control.lqr)(sys_, Q, R, N)
    np.testing.assert_allclose(K, K_ref, rtol=1e-9)
    np.testing.assert_allclose(P, P_ref, rtol=1e-9)
    assert np.abs(np.sort_complex(E) - np.sort_complex(np.asarray(E_ref, dtype=complex))).max() < 1e-9


def test_a_transfer_function_is_refused_as_the_wrong_kind():
    with pytest.raises(TypeError, match="expected a control.StateSpace, got TransferFunction"):
        interop.from_statespace(control.tf([1], [1, 1]))


@pytest.mark.parametrize("bad, message", [
    (lambda: control.ss([[0.0, 1.0], [0.0, np.inf]], [[0], [1]], np.eye(2), 0), "A has non-finite entries"),
    (lambda: control.ss([[0.0]], [[1.0]], [[1.0]], 0, True), r"timebase is unspecified \(dt = True\)"),
])
def test_a_system_quadctl_cannot_design_for_is_refused_by_name(bad, message):
    with pytest.raises(ValueError, match=message):
        interop.from_statespace(bad())


def test_without_python_control_the_error_says_how_to_install_it():
    code = ("import sys; sys.modules['control'] = None\n"
            "from quadctl.export import interop\n"
            "try:\n    interop.plant(None)\nexcept ModuleNotFoundError as exc:\n    print(exc)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == ("quadctl.export.interop needs python-control: pip install '.[control]' "
                           "(in a quadctl checkout) or pip install 'quadctl[control]'")


def test_the_docstring_examples_run():
    import doctest

    from quadctl.export import bundle

    for module in (interop, bundle):
        result = doctest.testmod(module)
        assert result.attempted and not result.failed, module.__name__


# ---------------------------------------------------------------------------------------
# LQG: the compensator of a loop through a Kalman filter

LQG_SENSORS = {"pN": 0.01, "pE": 0.01, "pD": 0.01, "phi": 0.002, "theta": 0.002, "psi": 0.005,
               "p": 0.005, "q": 0.005, "r": 0.005}


def _lqg_loop(name: str, **changes):
    """``name`` with noise, closed through a Kalman filter on imu + mocap: (linear model, design, loop)."""
    from quadctl import pipeline

    data = cfg_dict(name, **changes)
    data["simulation"]["noise"] = {"seed": 3, "force": [0.005] * 3, "torque": [2e-5] * 3,
                                   "sensor": dict(LQG_SENSORS)}
    data["estimator"] = {"measure": ["imu", "mocap"]}
    setup, _, linear, _, des = solve(data)
    return linear, des, pipeline.loop_of(setup, linear, des)


@pytest.mark.parametrize("name", ["mambo-200hz", "hover"])
def test_the_lqg_compensator_closes_to_the_regulator_and_the_estimator(name):
    """Separation: python-control's feedback of the plant (ZOH at the filter's period, or continuous)
    and the LQG compensator has the full-state loop's eigenvalues and the filter's (of Ae - L C)."""
    linear, des, loop = _lqg_loop(name)
    kal = loop.estimator
    assert kal.form == ("filter" if name == "mambo-200hz" else "kalman-bucy")
    regulator = np.linalg.eigvals(closed_loop_matrix(linear.A, linear.B, des.K_block, des.Ki_block,
                                                     des.integral_states, kal.sample_time))
    want = np.concatenate([regulator, kal.eigenvalues])
    ctl = interop.controller(loop)
    assert ctl.dt == (kal.sample_time or 0) and ctl.input_labels == list(STATE_NAMES)
    assert ctl.state_labels[:2] == ["xh_pN", "xh_pE"] and len(ctl.state_labels) == 12 + len(des.integral_states)
    unmeasured = [STATE_NAMES.index(s) for s in ("u", "v", "w")]
    assert not np.any(ctl.B[:, unmeasured]) and not np.any(ctl.D[:, unmeasured])  # velocity is not measured
    fb = control.feedback(interop.plant(linear, sample_time=kal.sample_time), ctl, sign=1)
    assert _match(fb.poles(), want) < EIG_TOL
    with pytest.raises(ValueError, match=r"closes through a Kalman filter \(estimator:\)"):
        interop.closed_loop(linear, loop)


def test_an_lqg_compensator_with_a_delay_is_refused():
    _, _, loop = _lqg_loop("mambo-200hz", controller={"rate": 200.0, "delay": {"samples": 1}})
    with pytest.raises(ValueError, match=r"command of controller\.delay samples ago"):
        interop.controller(loop)
