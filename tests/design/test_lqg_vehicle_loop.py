"""The closed-loop verdict of a loop with a Kalman filter (margins.json ``closed_loop``, check's vehicle loop):
the loop that flies, plant and filter together, against the separation principle.

Independent reference: SciPy's ZOH plant closed by the design's gains (LQI, free positions left out) and
the filter's own error dynamics ``Ad - Ad M C`` with ``M`` from SciPy's DARE on the filter's noise model
(``A - L C``, ``L`` from SciPy's CARE, for a continuous Kalman-Bucy filter); their union, as sets, within
each eigenvalue's conditioning.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg
import yaml
from _solve import cfg_dict, solve
from scipy import signal
from test_lqg_gyro_filter import LQG_CONFIG, as_sets_close, eigen_tolerance

from quadctl import pipeline
from quadctl.config import loading
from quadctl.design import linear_loop, lqg_loop
from quadctl.layout import STATE_INDEX
from quadctl.linear import stability
from quadctl.present.loops import closed_loop_sentence
from quadctl.present.stages import vehicle_loop_verdict

NOISE = {"seed": 3, "force": [0.005] * 3, "torque": [2e-5] * 3,
         "sensor": dict.fromkeys(("pN", "pE", "pD", "phi", "theta", "psi", "p", "q", "r"), 0.01)}


def _config(name: str) -> dict:
    """``mambo-lqg`` (200 Hz, discrete filter), or ``hover`` with the same sensors and a continuous
    (Kalman-Bucy) filter."""
    if name == "mambo-lqg":
        return yaml.safe_load(loading.locate(LQG_CONFIG).text)
    data = cfg_dict("hover")
    data["simulation"]["noise"] = NOISE
    data["estimator"] = {"measure": ["imu", "mocap"]}
    return data


def _reference(setup, linear, des, kal) -> np.ndarray:
    """The separation principle's eigenvalues, from SciPy: the full-state LQI loop (free positions, whose
    columns are unit vectors, left out) and the filter's error dynamics, its gain solved again."""
    A, B, K, ints = linear.A, linear.B, des.K_block, des.integral_states
    Ts, C, Qn, Rn = kal.sample_time, kal.C, kal.Qn, kal.Rn
    nz = len(ints)
    S = np.zeros((nz, 12))
    for i, s in enumerate(ints):
        S[i, STATE_INDEX[s]] = 1.0
    Ki = np.asarray(des.Ki_block).reshape(4, nz)
    if Ts is None:
        loop = np.block([[A - B @ K, -B @ Ki], [-S, np.zeros((nz, nz))]])
        P = scipy.linalg.solve_continuous_are(A.T, C.T, kal.G @ Qn @ kal.G.T, Rn)
        filt = A - P @ C.T @ np.linalg.solve(Rn, C)
    else:  # the filter's noise model as given (kal.G is its held Gd); its gain solved again
        Ad, Bd, *_ = signal.cont2discrete((A, B, np.eye(12), np.zeros((12, 4))), Ts, method="zoh")
        loop = np.block([[Ad - Bd @ K, -Bd @ Ki], [-Ts * S, np.eye(nz)]])
        P = scipy.linalg.solve_discrete_are(Ad.T, C.T, kal.G @ Qn @ kal.G.T, Rn)
        M = P @ C.T @ np.linalg.inv(C @ P @ C.T + Rn)
        filt = Ad - Ad @ M @ C
    free = [STATE_INDEX[s] for s in ("pN", "pE")]
    one = 0.0 if Ts is None else 1.0
    for i in free:  # nothing reads them: a unit column, its eigenvalue the plant's own
        column = loop[:, i].copy()
        column[i] -= one
        assert not column.any()
    keep = [i for i in range(len(loop)) if i not in free]
    return np.concatenate([np.linalg.eigvals(loop[np.ix_(keep, keep)]), np.linalg.eigvals(filt)])


@pytest.mark.parametrize("name", ["mambo-lqg", "hover+LQG continuous"])
def test_the_verdict_has_the_regulators_and_the_filters_eigenvalues(name):
    setup, _, linear, _, des = solve(_config(name))
    kal = pipeline.estimator_of(setup, linear)
    loop = pipeline.vehicle_loop_of(setup, linear, des)
    M = lqg_loop.lqg_vehicle(des, linear.A, linear.B, kal)
    got, tol = eigen_tolerance(M)
    want = _reference(setup, linear, des, kal)
    worst = as_sets_close(got, want, [tol[int(np.argmin(np.abs(got - w)))] for w in want])
    as_sets_close(loop.eigenvalues, want, [tol[int(np.argmin(np.abs(got - w)))] for w in want])  # the verdict's, too
    # nothing but the filter between design and flight: the loop flies as designed, filter included
    as_sets_close(loop.design_eigenvalues, want, [tol[int(np.argmin(np.abs(got - w)))] for w in want])
    # the full-state verdict's loop, and the filter's states on top of it
    full = linear_loop.vehicle_matrix(des, linear.A, linear.B, kal.sample_time)
    assert len(loop.eigenvalues) == len(full) + kal.n_estimate and loop.estimated == kal.measured
    assert loop.stable
    print(f"{name}: {len(want)} eigenvalues, worst {worst:.2e} (tolerances {min(tol):.1e} to {max(tol):.1e})")


def test_as_designed_is_the_regulator_and_the_filter_without_the_delay():
    """With two samples of delay the loop that flies has the delay's buffer too; the design, which does
    not see the delay, promised the separation principle's eigenvalues (the reference) and its least
    damping, the filter's modes included: that is what "as designed" compares the flown loop with."""
    data = _config("mambo-lqg")
    data.setdefault("controller", {})["delay"] = {"samples": 2}
    setup, _, linear, _, des = solve(data)
    kal = pipeline.estimator_of(setup, linear)
    loop = pipeline.vehicle_loop_of(setup, linear, des)
    got, tol = eigen_tolerance(lqg_loop.lqg_vehicle(des, linear.A, linear.B, kal))
    want = _reference(setup, linear, des, kal)
    as_sets_close(loop.design_eigenvalues, want, [tol[int(np.argmin(np.abs(got - w)))] for w in want])
    assert loop.design_least_damping == pytest.approx(stability.least_damping(want, kal.sample_time), rel=1e-9)
    assert len(loop.eigenvalues) == len(want) + 2 * 4  # the delay's buffer: two samples of the four inputs
    full = np.linalg.eigvals(linear_loop.vehicle_matrix(des, linear.A, linear.B, kal.sample_time))
    assert loop.design_least_damping < stability.least_damping(full, kal.sample_time)  # a filter mode is the least


@pytest.fixture(scope="module")
def mambo_lqg():
    return solve(_config("mambo-lqg"))


def test_the_margins_line_says_the_filter_is_in_the_loop(mambo_lqg):
    """margins' last line counts the filter's states (23 = mambo-200hz's 11 and the 12 estimates) and says so."""
    from quadctl import payloads

    setup, _, linear, _, des = mambo_lqg
    loop = pipeline.vehicle_loop_of(setup, linear, des)
    payload = payloads.margins(setup, des, [], loop)
    assert payload["closed_loop"]["estimator"] == list(setup.estimator.measured)
    radius = f"{np.abs(loop.eigenvalues).max():.6g}"
    assert closed_loop_sentence(payload) == ("closed loop with the Kalman filter included (plant and estimator): "
                                                  f"stable (23 eigenvalues, spectral radius {radius})")


def test_an_unstable_filter_fails_the_verdict(mambo_lqg):
    """The same regulator through a filter that overcorrects, ``M = 2.2 C'`` (each measured state's update
    ``1 - 2.2 = -1.2``: its error dynamics ``Ad - Ad M C`` leave the unit circle, the reference): the
    full-state loop is stable, the loop that flies is not, and both the margins line and check's verdict
    say so."""
    from quadctl import payloads

    setup, _, linear, _, des = mambo_lqg
    kal = pipeline.estimator_of(setup, linear)
    bad = replace(kal, gain=2.2 * kal.C.T)
    radius = np.abs(np.linalg.eigvals(kal.A - kal.A @ bad.gain @ kal.C)).max()
    assert radius > 1.0
    full = stability.is_stable(np.linalg.eigvals(linear_loop.vehicle_matrix(des, linear.A, linear.B, kal.sample_time)),
                               discrete=True)
    assert np.all(full)
    loop = pipeline.vehicle_loop_of(setup, linear, des, estimator=bad)
    assert not loop.stable
    assert np.abs(loop.eigenvalues).max() == pytest.approx(radius, rel=1e-9)  # the filter's mode is the worst
    line = closed_loop_sentence(payloads.margins(setup, des, [], loop))
    assert line.kind == "fail" and line.startswith(
        "closed loop with the Kalman filter included (plant and estimator): UNSTABLE (23 eigenvalues")
    assert vehicle_loop_verdict(loop) == ("with the Kalman filter included (plant and estimator) the design's closed "
                                          "loop is UNSTABLE; measure more states (estimator.measure) or lower the "
                                          "gains (larger R)")
