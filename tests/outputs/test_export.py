"""quadctl export: the exported C closes the loop exactly as simulate does; the .mat and JSON carry the design.

The proof: the exported C, compiled with the system compiler (``-std=c99 -Wall -Wextra -pedantic
-Werror``, both precisions), is loaded with ctypes and closes the loop around quadctl's own plant
(the engine's ``plant`` function: RK4 under the held input, evaluated by CasADi), sample by sample;
the trajectory must be ``simulate``'s.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import json
import math
import re
import shlex
import shutil
import subprocess

import numpy as np
import pytest
from _paths import ROOT
from _solve import cfg_dict
from typer.testing import CliRunner

from quadctl import config, export
from quadctl.cli.app import app
from quadctl.errors import ArgumentError, CheckFailed
from quadctl.export import c as cexport
from quadctl.export import data
from quadctl.layout import N_INPUTS, N_STATES, STATE_INDEX
from quadctl.physics import motors
from quadctl.setup import setup_of
from quadctl.sim.run import simulate

runner = CliRunner()
STRICT = ("-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror")
"""The flags the exported C must compile cleanly with."""
DOUBLE_TOL = 1e-12
"""The double build runs the same emitted operations as the engine's compiled loop (and the plant
is the engine's): any difference is a bug, not round-off."""
FLOAT_STATE_TOL = 1e-4
"""(m, m/s, rad, rad/s). A float controller's input is off by about an ulp of its size (6e-8 N at
the Mambo's 0.65 N trim thrust); the stable loop turns that into state errors of the same order,
and the positions nothing regulates (pN, pE) integrate it: up to 1.2e-6 in these runs. 1e-4 is
80 times that, and what a motion-capture system resolves (0.1 mm)."""
FLOAT_INPUT_RTOL = 1e-5
"""Of the size of the terms each input is summed from, ``|u_trim| + |K| (|x| + |x_ref|) + |Ki| |z|``
(largest over the run). A float sum of n terms errs by at most about n unit roundoffs (2^-24) of
that size (Higham, "Accuracy and Stability of Numerical Algorithms", 3.1): 14 terms, mixing there
and back 8 more, 22 u = 1.3e-6; the float loop's own state difference adds K dx. Seen: up to
1.7e-6 (the Crazyflie's yaw torque); 1e-5 is 168 u."""


def _mambo_saturating():
    """mambo-200hz from 2 m low and tilted: the rotors clip, the altitude integrator freezes."""
    data = cfg_dict("mambo-200hz")
    data["simulation"] = {**data["simulation"], "duration": 6.0,
                          "initial_offset": {"pD": 2.0, "phi": 0.3, "theta": -0.3, "psi": 0.5}}
    return data, None


def _mambo_box():
    """mambo-200hz without rotors, with box limits on T and A only (E, R unlimited: +-inf)."""
    data = cfg_dict("mambo-200hz", motors=None, limits={"T": [0.3, 0.9], "A": [-0.004, 0.004]})
    data["simulation"] = {**data["simulation"], "duration": 4.0, "initial_offset": {"pD": 1.0, "phi": 0.3}}
    return data, None


def _mambo_emulated():
    """mambo-200hz designed continuous and exported at --rate 200 (emulation)."""
    return cfg_dict("mambo-200hz", controller={"rate": None, "design": "discrete"}), 200.0


def _mambo_lagged(rotor_lag: str, delay: int = 0):
    """mambo-200hz with a 30 ms rotor lag (designed with it, or not), and ``delay`` samples of delay."""
    data = cfg_dict("mambo-200hz")
    data["motors"]["time_constant"] = 0.03
    data["controller"]["rotor_lag"] = rotor_lag
    if delay:
        data["controller"]["delay"] = {"samples": delay}
    data["simulation"] = {**data["simulation"], "duration": 3.0,
                          "initial_offset": {"pD": 0.5, "phi": 0.4, "theta": 0.1}}  # the rotors clip
    return data, None


def _mambo_gyro_filtered():
    """mambo-200hz with the rotors' 30 ms lag included, one sample of delay, and the gyro filtered (second-order
    low-pass at 40 Hz, a notch at 70 Hz), tilted so the rotors clip."""
    data, _ = _mambo_lagged("include", 1)
    data["controller"]["filters"] = {"gyro": {"cutoff": 40.0, "order": 2}, "notch": {"center": 70.0, "bandwidth": 30.0}}
    data["simulation"]["duration"] = 2.0
    return data, None


CASES = {
    "mambo-200hz": lambda: (cfg_dict("mambo-200hz"), None),  # LQI on altitude, rotors, 200 Hz
    "crazyflie": lambda: (cfg_dict("crazyflie"), None),       # no integrator, 500 Hz
    "mambo-saturating": _mambo_saturating,
    "mambo-box": _mambo_box,
    "mambo-emulated": _mambo_emulated,
    "mambo-lag-ignored": lambda: _mambo_lagged("ignore"),
    "mambo-lag-included": lambda: _mambo_lagged("include"),
    "mambo-lag-included-delayed": lambda: _mambo_lagged("include", 2),
    "mambo-lag-ignored-delayed": lambda: _mambo_lagged("ignore", 1),
    "mambo-gyro-filtered": _mambo_gyro_filtered,
}


def cc() -> str:
    from quadctl.native.compile import find_compiler

    compiler = find_compiler()
    if compiler is None:
        pytest.skip("no C compiler (looked for $CC, cc, gcc, clang): the exported C cannot be built here")
    return compiler


def prepared(case: str):
    cfg_data, rate = CASES[case]()
    cfg = config.from_dict(cfg_data, f"{case}.yaml")
    return export.prepare(setup_of(cfg), rate, config_hash=cfg.digest())


class Controller:
    """The exported C loaded with ctypes (``quadctl_init``, ``quadctl_step``, ``quadctl_mix``), compiled with
    ``STRICT -O2`` and ``flags``."""

    def __init__(self, exp, folder, single: bool, flags: tuple[str, ...] = ()):
        folder.mkdir(parents=True, exist_ok=True)
        for name, text in cexport.sources(exp).items():
            (folder / name).write_text(text)
        lib = folder / f"controller_{'float' if single else 'double'}{''.join(flags)}.so"
        res = subprocess.run([cc(), *STRICT, "-O2", *flags, "-fPIC", "-shared",
                              *(["-DQUADCTL_FLOAT"] if single else []), str(folder / cexport.SOURCE), "-o", str(lib),
                              "-lm"], capture_output=True, text=True)
        assert res.returncode == 0, res.stderr
        self.lib = ctypes.CDLL(str(lib))
        self.real = ctypes.c_float if single else ctypes.c_double
        nz, nl = len(exp.loop.integral_states), exp.loop.spec().n_lag
        ny = len(exp.loop.measured)
        nb = N_INPUTS * exp.loop.delay_samples if ny else 0  # a filter remembers the delayed commands
        ng = exp.loop.spec().n_filter

        class State(ctypes.Structure):  # quadctl_controller of the header (l[]: a design with the rotors' lag;
            _fields_ = [("z", self.real * max(nz, 1)),  # b[], xh[]: a Kalman filter, with and without delay;
                        *([("l", self.real * nl)] if nl else []), *([("b", self.real * nb)] if nb else []),
                        *([("g", self.real * ng)] if ng else []),  # g[]: the gyro filter)
                        *([("xh", self.real * exp.loop.spec().n_estimate)] if ny else []), ("k", ctypes.c_ulong)]

        self.state = State()
        self.lib.quadctl_init(ctypes.byref(self.state))

    def step(self, x) -> np.ndarray:
        """``u`` from the state ``x`` (12), or from the measurements ``y`` of a Kalman filter."""
        xa, ua = (self.real * len(x))(*x), (self.real * N_INPUTS)()
        self.lib.quadctl_step(ctypes.byref(self.state), xa, ua)
        return np.array(ua[:], dtype=float)

    def step_ref(self, x, x_ref, u_ref) -> np.ndarray:
        """``u`` from ``x`` (or ``y``) and the reference at the sample (``quadctl_step_ref``)."""
        class Reference(ctypes.Structure):  # quadctl_reference of the header
            _fields_ = [("x", self.real * N_STATES), ("u", self.real * N_INPUTS)]

        xa, ua = (self.real * len(x))(*x), (self.real * N_INPUTS)()
        ref = Reference((self.real * N_STATES)(*x_ref), (self.real * N_INPUTS)(*u_ref))
        self.lib.quadctl_step_ref(ctypes.byref(self.state), xa, ctypes.byref(ref), ua)
        return np.array(ua[:], dtype=float)

    def reference_trim(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, u) of ``quadctl_reference_trim``."""
        class Reference(ctypes.Structure):
            _fields_ = [("x", self.real * N_STATES), ("u", self.real * N_INPUTS)]

        ref = Reference()
        self.lib.quadctl_reference_trim(ctypes.byref(ref))
        return np.array(ref.x[:], dtype=float), np.array(ref.u[:], dtype=float)

    def mix(self, u) -> np.ndarray:
        ua, fa = (self.real * N_INPUTS)(*u), (self.real * N_INPUTS)()
        self.lib.quadctl_mix(ua, fa)
        return np.array(fa[:], dtype=float)


def fly(exp, ctl: Controller, x0, plan):
    """The closed loop of the C controller around the engine's plant: ``quadctl_step`` at every
    controller sample, ``hold`` RK4 steps of the plant under the held input in between. The rotors'
    lag is the plant's (its rotor states); the configured delay is the vehicle's: each command
    reaches the plant ``n`` samples after ``quadctl_step`` returns it (the trim input before).

    Returns (xs, us, commands): the state before each step and the input applied during it (N + 1
    rows; the last input is the one held at the end), and what ``quadctl_step`` returned at each
    sample."""
    import casadi as ca

    from quadctl.sim.builder import build

    loop = exp.loop
    plant = build(loop.spec(noise=False)).plant
    c, e = ca.DM(loop.constants(plan.sample_time)), ca.DM.zeros(0, 1)
    X = loop.initial_loop_state(x0)  # the plant passes the simulation's controller states through untouched
    pending = [np.asarray(loop.u_trim, dtype=float)] * loop.delay_samples
    xs, us, commands = np.empty((plan.n_steps + 1, N_STATES)), np.empty((plan.n_steps + 1, N_INPUTS)), []
    for k in range(plan.n_steps):
        if k % plan.hold == 0:
            commands.append(ctl.step(X[:N_STATES]))
            pending.append(commands[-1])
            u = pending.pop(0)
        xs[k], us[k] = X[:N_STATES], u
        X = np.asarray(plant(X, u, plan.dt, c, e)).ravel()
    xs[-1], us[-1] = X[:N_STATES], u
    return xs, us, np.array(commands)


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow)  # each flown with a delay by default
                                  if c in ("mambo-lag-ignored", "mambo-lag-included") else c for c in CASES])
def test_the_exported_c_flies_the_loop_simulate_flies(case, tmp_path):
    exp = prepared(case)
    setup, loop = exp.setup, exp.loop
    x0 = setup.initial_state(loop.x_trim)
    plan = loop.plan(setup.duration, setup.dt)
    ref = simulate(loop, x0, setup.duration, setup.dt, noise=None, max_samples=plan.n_steps + 1)
    assert ref.status == "ok" and ref.stride == 1 and len(ref.t) == plan.n_steps + 1
    terms = np.abs(loop.u_trim) + (np.abs(ref.x) + np.abs(ref.x_ref)) @ np.abs(loop.K).T
    if loop.integral_states:
        terms = terms + np.abs(ref.z) @ np.abs(loop.Ki).T
    if loop.Kv is not None:
        terms = terms + np.abs(ref.lag_model) @ np.abs(loop.Kv).T
    scale = terms.max(axis=0)
    for single in (False, True):
        xs, us, commands = fly(exp, Controller(exp, tmp_path / case, single), x0, plan)
        if loop.delay_samples:  # the law's command at sample k is what the simulation applies at k + n
            n, samples = loop.delay_samples, ref.u[::plan.hold]
            shifted = np.abs(commands[:len(samples) - n] - samples[n:]).max()
            assert shifted <= (DOUBLE_TOL if not single else FLOAT_INPUT_RTOL * scale.max()), \
                f"max |command - simulated input n samples later| = {shifted:.4e}"
            np.testing.assert_array_equal(samples[:n], np.tile(loop.u_trim, (n, 1)))
        dx, du = np.abs(xs - ref.x).max(), np.abs(us[:-1] - ref.u[:-1]).max()
        if single:
            worst = (np.abs(us[:-1] - ref.u[:-1]) / scale).max()
            assert dx <= FLOAT_STATE_TOL and worst <= FLOAT_INPUT_RTOL, \
                f"float: max |dx| = {dx:.3e}, max |du| = {du:.3e} ({worst:.3e} of the terms' size)"
        else:
            assert dx <= DOUBLE_TOL and du <= DOUBLE_TOL, f"double: max |dx| = {dx:.4e}, max |du| = {du:.4e}"


# ---------------------------------------------------------------------------------------
# LQG: the Kalman filter in the exported C

LQG_CONFIG = str(ROOT / "docs" / "configs" / "mambo-lqg.yaml")
"""The export page's LQG config (mambo-200hz measured by an IMU and motion capture)."""
LQG_SENSORS = {"pN": 0.01, "pE": 0.01, "pD": 0.01, "phi": 0.002, "theta": 0.002, "psi": 0.005,
               "p": 0.005, "q": 0.005, "r": 0.005}
"""Sensor noise (state units) of what the filter measures (IMU and motion capture), as
tests/design/test_estimator.py."""


def _mambo_lqg(delayed: bool = False):
    """mambo-200hz (LQI on altitude, rotors) from 2 m low and tilted (the rotors clip), with process and
    sensor noise, closed through a Kalman filter on imu + mocap; ``delayed``: 30 ms rotor lag included in
    the design (the lag model) and 2 samples of delay."""
    data = cfg_dict("mambo-200hz")
    if delayed:
        data["motors"]["time_constant"] = 0.03
        data["controller"] = {**data["controller"], "rotor_lag": "include", "delay": {"samples": 2}}
    data["simulation"] = {**data["simulation"], "duration": 2.0,
                          "initial_offset": {"pD": 2.0, "phi": 0.3, "theta": -0.3, "psi": 0.5},
                          "noise": {"seed": 3, "force": [0.005] * 3, "torque": [2e-5] * 3,
                                    "sensor": dict(LQG_SENSORS)}}
    data["estimator"] = {"measure": ["imu", "mocap"]}
    return data, None


def _mambo_lqg_emulated():
    """The LQG config designed continuous and exported at --rate 200: the filter is the discrete one at 200 Hz."""
    data, _ = _mambo_lqg()
    data["controller"] = {**data["controller"], "rate": None}
    return data, 200.0


def _mambo_lqg_gyro_filtered():
    """The LQG config with the gyro filtered (second-order low-pass at 30 Hz, a notch at 70 Hz): the Kalman
    filter's model includes the filter, measures the filtered rates, and estimates the filter's states."""
    data, _ = _mambo_lqg()
    data["controller"] = {**data["controller"], "filters": {"gyro": {"cutoff": 30.0, "order": 2},
                                                            "notch": {"center": 70.0, "bandwidth": 30.0}}}
    data["simulation"]["duration"] = 1.0  # the rotors clip in its first half second
    return data, None


CASES["mambo-lqg"] = _mambo_lqg
CASES["mambo-lqg-lag-delayed"] = lambda: _mambo_lqg(delayed=True)
CASES["mambo-lqg-emulated"] = _mambo_lqg_emulated
CASES["mambo-lqg-gyro-filtered"] = _mambo_lqg_gyro_filtered
LQG_CASES = ("mambo-lqg", "mambo-lqg-lag-delayed", "mambo-lqg-emulated", "mambo-lqg-gyro-filtered")


def test_a_gyro_filter_left_to_the_flight_stack_is_refused_beside_a_kalman_filter():
    """The Kalman filter's model holds the gyro filter's states: the C cannot leave that filter to the flight
    stack (``gyro_filtered_by``, the Crazyflie app's). A wrong argument, refused as one (it was a bare ValueError)."""
    exp = prepared("mambo-lqg-gyro-filtered")
    with pytest.raises(ArgumentError, match=r"^sources: gyro_filtered_by with a Kalman filter \(estimator:\): .*; "
                                            r"leave out gyro_filtered_by, or export the design without the estimator$"):
        cexport.sources(exp, gyro_filtered_by="the flight stack's")


def replay(ctl: Controller, y) -> tuple[np.ndarray, np.ndarray]:
    """``quadctl_step`` on each row of ``y``: (the commands, the estimate ``xh`` after each step)."""
    commands, estimates = [], []
    for row in y:
        commands.append(ctl.step(row))
        estimates.append(np.array(ctl.state.xh[:], dtype=float))
    return np.array(commands), np.array(estimates)


@pytest.mark.compiler
@pytest.mark.parametrize("case", LQG_CASES)
def test_the_exported_kalman_filter_gives_the_simulated_commands_and_estimates(case, tmp_path):
    """Fed, at each sample, the measured states plus the sensor noise the simulation drew (what its
    controller saw), the exported C returns the commands simulate computed and keeps its estimates:
    the filter's update, the law on the updated estimate, the prediction with the applied (clipped,
    delayed) command."""
    from quadctl.physics.noise import realize

    exp = prepared(case)
    setup, loop = exp.setup, exp.loop
    assert loop.estimator is not None and loop.estimator.form == "filter"
    plan = loop.plan(setup.duration, setup.dt)
    ref = simulate(loop, setup.initial_state(loop.x_trim), setup.duration, setup.dt, noise=setup.noise,
                   max_samples=plan.n_steps + 1)
    assert ref.status == "ok" and ref.stride == 1
    _, sensor = realize(setup.noise, plan.n_steps, plan.dt)
    samples = np.arange(0, plan.n_steps, plan.hold)
    measured = [STATE_INDEX[s] for s in loop.measured]
    y = (ref.x[samples] + sensor[samples])[:, measured]
    n = loop.delay_samples
    applied = ref.u[samples]  # the input held over each sample: the command of n samples before
    prior = (ref.x_hat - ref.x_ref)[samples[1:]]  # the a priori estimate each next sample starts from
    assert max(motors.saturation_fraction(loop.actuators, ref.u).values()) > 0.01  # clipped commands predict
    terms = (np.abs(loop.u_trim) + np.abs(ref.x_hat - ref.x_ref) @ np.abs(loop.K).T
             + np.abs(ref.z) @ np.abs(loop.Ki).T
             + (np.abs(ref.lag_model) @ np.abs(loop.Kv).T if loop.Kv is not None else 0.0)).max()
    for single in (False, True):
        commands, estimates = replay(Controller(exp, tmp_path / case, single), y)
        du = np.abs(commands[:len(samples) - n] - applied[n:]).max()
        dxh = np.abs(estimates[:-1, :N_STATES] - prior).max()  # (the gyro filter's estimates after x's)
        if single:
            print(f"{case} float: max |du| = {du:.3e} ({du / terms:.3e} of {terms:.3g}), max |dxh| = {dxh:.3e}")
            assert du <= FLOAT_INPUT_RTOL * terms and dxh <= FLOAT_STATE_TOL, \
                f"float: max |du| = {du:.3e} ({du / terms:.3e} of the terms' size), max |dxh| = {dxh:.3e}"
        else:
            print(f"{case} double: max |du| = {du:.3e}, max |dxh| = {dxh:.3e}")
            assert du <= DOUBLE_TOL and dxh <= DOUBLE_TOL, f"double: max |du| = {du:.4e}, max |dxh| = {dxh:.4e}"
    if n:
        np.testing.assert_array_equal(applied[:n], np.tile(loop.u_trim, (n, 1)))
    # the noise matters: without it the same controller computes other commands
    clean, _ = replay(Controller(exp, tmp_path / "clean", False), ref.x[samples][:, measured])
    assert np.abs(clean[:len(samples) - n] - applied[n:]).max() > 1e3 * DOUBLE_TOL


# ---------------------------------------------------------------------------------------
# A reference: the exported C takes x_ref(t) and u_ref(t) at each sample


def _square(lqg: bool = False):
    """The bundled square mission designed at 200 Hz (lqrd; its continuous design is far too fast to
    sample at any rate a flight computer runs). ``lqg``: on the Mambo's rotors, with LQI on altitude,
    1 m low and rolled (the rotors clip, the integrator freezes), 6 s of the mission under process and
    sensor noise drawn every 2 ms (so most samples fall inside a reference row: the law's ``x_ref(t)``
    is the row's expansion, not its tabulated value), closed through a Kalman filter on imu + mocap."""
    data = cfg_dict("square", controller={"rate": 200, "design": "discrete"})
    if lqg:
        data["motors"] = cfg_dict("mambo-200hz")["motors"]
        data["lqr"]["altitude"] = {"Q": [50, 1, 10], "R": [1], "integral": ["pD"]}
        data["simulation"] = {**data["simulation"], "duration": 6.0, "initial_offset": {"pD": 1.0, "phi": 0.3},
                              "noise": {"seed": 3, "period": 0.002, "force": [0.005] * 3, "torque": [2e-5] * 3,
                                        "sensor": dict(LQG_SENSORS)}}
        data["estimator"] = {"measure": ["imu", "mocap"]}
    return data, None


CASES["square"] = _square
CASES["square-lqg"] = lambda: _square(lqg=True)


def _assert_fed_commands(exp, folder, label: str, fed, applied, terms: float) -> None:
    """The export in double and in float, fed each sample's ``fed`` = (measured state, x_ref, u_ref),
    returns the inputs the simulation applied: within DOUBLE_TOL in double, within FLOAT_INPUT_RTOL of
    the law's terms' size ``terms`` in float."""
    for single in (False, True):
        ctl = Controller(exp, folder, single)
        commands = np.array([ctl.step_ref(*row) for row in zip(*fed)])
        du = np.abs(commands - applied).max()
        if single:
            print(f"{label} float: max |du| = {du:.3e} ({du / terms:.3e} of {terms:.3g})")
            assert du <= FLOAT_INPUT_RTOL * terms, f"float: max |du| = {du:.3e} ({du / terms:.3e} of the terms' size)"
        else:
            print(f"{label} double: max |du| = {du:.3e}")
            assert du <= DOUBLE_TOL, f"double: max |du| = {du:.4e}"


@pytest.mark.compiler
@pytest.mark.parametrize("case", ["square", "square-lqg"])
def test_the_exported_c_fed_the_reference_gives_the_simulated_commands(case, tmp_path):
    """``quadctl_step_ref`` fed, at each sample, what the simulation's law was fed (the measured
    state, or the measurements with the sensor noise drawn; the reference ``x_ref(t)``, ``u_ref(t)``
    the run recorded) returns the inputs the simulation applied: to round-off in double, to the float
    sums' round-off in float."""
    from quadctl.physics.noise import realize
    from quadctl.pipeline import simulation_of

    exp = prepared(case)
    setup, loop = exp.setup, exp.loop
    assert exp.flies_reference and loop.delay_samples == 0
    plan = loop.plan(setup.duration, setup.dt)
    ref = simulation_of(setup, loop)
    assert ref.status == "ok" and ref.stride == 1 and len(ref.t) == plan.n_steps + 1
    samples = np.arange(0, plan.n_steps, plan.hold)
    x = ref.x[samples]
    if loop.estimator is not None:
        _, sensor = realize(setup.noise, plan.n_steps, plan.dt)
        x = (x + sensor[samples])[:, [STATE_INDEX[s] for s in loop.measured]]
        assert max(motors.saturation_fraction(loop.actuators, ref.u).values()) > 0.01  # clipped: frozen, predicted
    x_ref, u_ref, applied = ref.x_ref[samples], ref.u_ref[samples], ref.u[samples]
    assert np.ptp(x_ref[:, STATE_INDEX["pN"]]) > 1.0 and np.ptp(u_ref[:, 1:], axis=0).min() > 0  # a path, its torques
    # samples flown a quarter turn from the trim's heading: the law's heading frame, in C too
    assert np.count_nonzero(np.abs(x_ref[:, STATE_INDEX["psi"]] - loop.x_trim[STATE_INDEX["psi"]]) > 1.5) > 100
    dev = (ref.x_hat - ref.x_ref)[samples] if loop.estimator is not None else x_ref - ref.x[samples]
    terms = (np.abs(u_ref) + np.abs(dev) @ np.abs(loop.K).T
             + (np.abs(ref.z[samples]) @ np.abs(loop.Ki).T if loop.integral_states else 0.0)).max()
    _assert_fed_commands(exp, tmp_path / case, case, (x, x_ref, u_ref), applied, terms)
    # the reference matters: fed the trim instead, the same controller computes other commands
    trim_x, trim_u = Controller(exp, tmp_path / "trim", False).reference_trim()
    np.testing.assert_array_equal(trim_x, loop.x_trim)
    np.testing.assert_array_equal(trim_u, loop.u_trim)
    held = Controller(exp, tmp_path / "held", False)
    still = np.array([held.step_ref(row, trim_x, trim_u) for row in x])
    assert np.abs(still - applied).max() > 1e3 * DOUBLE_TOL


@pytest.mark.compiler
def test_the_exported_gain_schedule_gives_the_simulated_commands(tmp_path):
    """The bundled crazyflie-speed-schedule (hover to 20 m/s and back on velocity setpoints, the gains
    scheduled on the commanded speed, linear between designs at 0, 4, ..., 20 m/s): its export, fed at
    each sample the measured state and the reference the simulation's law used, returns the inputs
    simulate applied, across every piece of the table; the constant gain of the trim's design, fed the
    same, does not."""
    from dataclasses import replace

    from quadctl.design.gain_table import scheduling_value
    from quadctl.sim.loop_layout import constant_layout

    cfg = config.load("crazyflie-speed-schedule")
    exp = export.prepare(setup_of(cfg), config_hash=cfg.digest())
    setup, loop = exp.setup, exp.loop
    table = loop.schedule
    assert table is not None and exp.flies_reference
    duration = 11.0  # s: the climb to 20 m/s (reached at 10 s), every piece of the table
    plan = loop.plan(duration, setup.dt)
    ref = simulate(loop, setup.initial_state(loop.x_trim), duration, setup.dt, noise=None,
                   reference=setup.flown_reference, max_samples=plan.n_steps + 1)
    assert ref.status == "ok" and ref.stride == 1
    samples = np.arange(0, plan.n_steps, plan.hold)
    x, x_ref, u_ref, applied = ref.x[samples], ref.x_ref[samples], ref.u_ref[samples], ref.u[samples]
    speed = np.array([scheduling_value("speed", row, loop.schedule_heading) for row in x_ref])  # commanded
    assert speed.min() == 0 and speed.max() == pytest.approx(20.0)  # every piece of the table is flown
    source = cexport.sources(exp)[cexport.SOURCE]
    start = sum(int(np.prod(shape)) for name, shape in constant_layout(*loop.constant_layout)
                if name not in ("schedule_heading", "schedule_breaks", "schedule_coefficients"))
    assert f"#define QC_SCHEDULE_HEADING {start}  /* schedule_heading 1 */" in source
    terms = (np.abs(u_ref) + np.abs(x - x_ref) @ np.abs(table.gains).max(axis=0).T).max()
    _assert_fed_commands(exp, tmp_path / "schedule", "schedule", (x, x_ref, u_ref), applied, terms)
    header = " ".join(cexport.sources(exp)[cexport.HEADER].replace(" * ", " ").split())
    for text in ("K = G(v), the gain schedule on speed v (m/s) of x_ref(t): the designs at v = 0, 4, 8, 12, 16, 20, "
                 "linear between them, held outside them", "v is the horizontal velocity of x_ref(t) along the "
                 "heading 0 rad (m/s), turned with the reference's yaw (its yaw less the trim's added), x_ref(t) "
                 "being ref->x, the reference given", "5 pieces"):
        assert text in header, text
    (field,) = [f for f in data.fields(exp) if f.name == "schedule"]  # the .mat and the JSON carry the table
    np.testing.assert_array_equal(field.value["coefficients"], table.coefficients)
    assert field.value["variable"] == "speed" and "schedule" not in {f.name for f in data.fields(prepared("square"))}
    fixed = Controller(replace(exp, loop=replace(loop, schedule=None)), tmp_path / "fixed", False)
    unscheduled = np.array([fixed.step_ref(*row) for row in zip(x, x_ref, u_ref)])
    assert np.abs(unscheduled - applied).max() > 1e3 * DOUBLE_TOL


def test_a_schedule_that_fails_its_checks_is_not_exported(monkeypatch):
    """What fails `quadctl schedule` does not leave quadctl (exit 1, the schedule's own verdict)."""
    from dataclasses import replace

    from quadctl.schedule import envelope

    real = envelope.schedule_of

    def failing(setup):
        sched = real(setup)
        return replace(sched, checks=replace(sched.checks, stable=np.zeros_like(sched.checks.stable)))

    monkeypatch.setattr(envelope, "schedule_of", failing)
    with pytest.raises(CheckFailed, match=r"^not exported: the gain schedule fails its checks: .* frozen-point "
                                          r"checks fail: .*\(`quadctl schedule` shows them\)$"):
        export.prepare(setup_of(config.load("crazyflie-speed-schedule")))


def test_the_reference_header_documents_the_reference_input():
    """A config with simulation.reference exports quadctl_step_ref and quadctl_reference (x_ref, u_ref
    in the order and units of x and u), says so in the law, and has no quadctl_step; one without keeps
    quadctl_step and knows nothing of a reference."""
    files = cexport.sources(prepared("square"))
    header, source = files[cexport.HEADER], files[cexport.SOURCE]
    for line in ("void quadctl_step_ref(quadctl_controller *c, const quadctl_real x[QUADCTL_NX], "
                 "const quadctl_reference *ref, quadctl_real u[QUADCTL_NU]);",
                 "void quadctl_reference_trim(quadctl_reference *ref);",
                 "quadctl_real x[QUADCTL_NX];  /* x_ref(t): the commanded state (order and units of x: QUADCTL_X_*) */",
                 "quadctl_real u[QUADCTL_NU];  /* u_ref(t): the feedforward input (order and units of u: "
                 "QUADCTL_U_*) */",
                 "read x; quadctl_step_ref(&c, x, &ref, u); apply u", "u = u_ref(t) - K (x - x_ref(t))"):
        assert line in header, line
    assert "void quadctl_step(" not in header and "THE REFERENCE" in header
    assert "#define QC_E_REF_U 37  /* ref_u (4) */" in source and "#define QC_NE 90" in source
    lqg = cexport.sources(prepared("square-lqg"))[cexport.HEADER]
    assert "const quadctl_real y[QUADCTL_NY], const quadctl_reference *ref" in lqg
    assert "xh <- Ae xc + Be (u_applied - u_ref(t))    predict" in lqg
    plain = cexport.sources(prepared("crazyflie"))
    assert "quadctl_reference" not in plain[cexport.HEADER] + plain[cexport.SOURCE]
    assert "qc_law(X, &t, qc_c, NULL, u, X_sampled);" in plain[cexport.SOURCE]


def test_the_lqg_header_documents_the_measurements_and_the_filter(tmp_path):
    """quadctl_step takes y, the measured states in the header's order; the struct holds the a priori
    estimate; the delay's commands are kept for the filter only; the constants are the filter's."""
    res = runner.invoke(app, ["export", "--to", "c", "-c", LQG_CONFIG, "-o", str(tmp_path)])
    assert res.exit_code == 0, res.stderr
    header = (tmp_path / cexport.HEADER).read_text()
    for line in ("void quadctl_step(quadctl_controller *c, const quadctl_real y[QUADCTL_NY], "
                 "quadctl_real u[QUADCTL_NU]);", "#define QUADCTL_NY 9", "#define QUADCTL_NB 0",
                 "#define QUADCTL_Y_PN 0  /* pN (m), x[0] */", "#define QUADCTL_Y_PHI 3  /* phi (rad), x[6] */",
                 "#define QUADCTL_Y_R 8  /* r (rad/s), x[11] */", "quadctl_real xh[QUADCTL_NE];",
                 "#define QUADCTL_NE 12",
                 "MATLAB dlqe's filter form", "xc = xh + M (y - C x_ref(t) - C xh)",
                 "xh <- Ae xc + Be (u_applied - u_trim)"):
        assert line in header, line
    source = (tmp_path / cexport.SOURCE).read_text()
    assert "static const int qc_measured[QUADCTL_NY] = {0, 1, 2, 6, 7, 8, 9, 10, 11};" in source
    assert "#define QC_LE 328  /* Le 12x9 */" in source
    delayed = cexport.sources(prepared("mambo-lqg-lag-delayed"))
    assert "#define QUADCTL_NB 8" in delayed[cexport.HEADER] and "quadctl_real b[8];" in delayed[cexport.HEADER]
    assert "remembers the commands of the last 2 samples (b[], starting at" in _flat(
        delayed[cexport.HEADER].replace(" * ", " "))
    plain = cexport.sources(prepared("mambo-200hz"))
    assert "#define QUADCTL_NY 0" in plain[cexport.HEADER] and "xh[" not in plain[cexport.SOURCE]


def test_the_header_says_what_the_law_does_with_the_rotor_lag_and_the_delay():
    """The lag model is the controller's (state in the struct); the delay is the vehicle's (no buffer)."""
    lagged = cexport.sources(prepared("mambo-lag-included-delayed"))
    header = lagged[cexport.HEADER]
    assert "#define QUADCTL_NL 4" in header and "quadctl_real l[4];" in header
    assert "controller.delay, 2 samples (0.01 s) from measurement to actuation" in header
    assert "Do not add a buffer here" in header and "a = exp(-Ts/tau) = 0.846481725" in header
    assert "u = sat(u_trim - K (x - x_ref(t)) - Ki z - Kv l)" in " ".join(header.replace(" *  ", "").split())
    plain = cexport.sources(prepared("mambo-200hz"))[cexport.HEADER]
    assert "#define QUADCTL_NL 0" in plain and "quadctl_real l[" not in plain
    assert "No delay was configured" in plain and "The design ignores the rotors' lag" in plain


def test_the_proof_cases_clip_and_freeze_the_integrator():
    """The saturating cases exercise what the C must get right beyond the gains: rotor clipping,
    box clipping with unlimited (infinite) inputs, and conditional integration."""
    exp = prepared("mambo-saturating")
    setup, loop = exp.setup, exp.loop
    sim = simulate(loop, setup.initial_state(loop.x_trim), setup.duration, setup.dt, noise=None, max_samples=10**6)
    fractions = motors.saturation_fraction(loop.actuators, sim.u)
    assert max(fractions.values()) > 0.01, fractions
    hold = sim.plan.hold
    samples = np.arange(0, len(sim.t) - hold, hold)
    error = sim.x[samples, STATE_INDEX["pD"]] - sim.x_ref[samples, STATE_INDEX["pD"]]
    frozen = (sim.z[samples + hold, 0] == sim.z[samples, 0]) & (np.abs(error) > 1e-3)
    assert frozen.sum() >= 10  # the integrator held still while the thrust was clipped
    box = prepared("mambo-box")
    assert box.loop.actuators.mode == "box" and np.isinf(box.loop.actuators.hi[2])
    sim = simulate(box.loop, box.setup.initial_state(box.loop.x_trim), box.setup.duration, "auto", noise=None)
    assert max(motors.saturation_fraction(box.loop.actuators, sim.u).values()) > 0.01


def test_the_header_documents_the_interface_from_the_layout(tmp_path):
    exp = prepared("crazyflie")
    header = cexport.sources(exp)[cexport.HEADER]
    for line in ("void quadctl_init(quadctl_controller *c);",
                 "void quadctl_step(quadctl_controller *c, const quadctl_real x[QUADCTL_NX], "
                 "quadctl_real u[QUADCTL_NU]);",
                 "void quadctl_mix(const quadctl_real u[QUADCTL_NU], quadctl_real thrust[QUADCTL_N_ROTORS]);",
                 "#define QUADCTL_NX 12", "#define QUADCTL_NU 4", "#define QUADCTL_NZ 0",
                 "#define QUADCTL_SAMPLE_TIME 0.002", "#define QUADCTL_X_THETA 7  /* theta (rad) */",
                 " *   x[ 2] pD     m      trim -1", " *   u[ 0] T      N      trim +0.26487",
                 "typedef double quadctl_real;", "typedef float quadctl_real;"):
        assert line in header, line
    assert exp.law() in " ".join(line.lstrip(" *") for line in header.splitlines())
    # a loop without rotors has no mixer
    box = cexport.sources(prepared("mambo-box"))
    assert "#define QUADCTL_N_ROTORS" in header and "#define QUADCTL_N_ROTORS" not in box[cexport.HEADER]
    assert "INFINITY" in box[cexport.SOURCE]


def test_the_mixer_gives_the_rotor_thrusts_of_the_applied_input(tmp_path):
    exp = prepared("crazyflie")
    act = exp.loop.actuators
    ctl = Controller(exp, tmp_path, single=False)
    x0 = exp.setup.initial_state(exp.loop.x_trim)
    u = ctl.step(x0)
    np.testing.assert_allclose(ctl.mix(u), np.clip(act.commands(u), act.lo, act.hi), rtol=0, atol=1e-15)
    np.testing.assert_allclose(ctl.mix(exp.loop.u_trim), [0.027 * 9.81 / 4] * 4, rtol=1e-12)
    np.testing.assert_array_equal(ctl.mix([5.0, 0, 0, 0]), [act.hi[0]] * 4)  # clipped to the rotors' limit


def test_float_clip_tolerance_covers_the_mixing_round_off():
    act = prepared("crazyflie").loop.actuators
    tol = cexport.float_tolerance(act)
    assert tol == pytest.approx(cexport.FLOAT_ROUNDOFF_ULPS * 2.0 ** -23 * 4 * 0.159166, rel=0.05)
    rng = np.random.default_rng(0)  # float32 mix and unmix of commands inside the limits
    f = rng.uniform(act.lo, act.hi, size=(1000, 4)).astype(np.float32)
    u = f @ act.mix_inv.T.astype(np.float32)
    back = (u @ act.mix.T.astype(np.float32)) @ act.mix_inv.T.astype(np.float32)
    assert np.abs(back - u).max() < tol / 8


# ---------------------------------------------------------------------------------------
# The command


def test_export_c_writes_the_two_files(tmp_path):
    res = runner.invoke(app, ["export", "--to", "c", "-c", "crazyflie", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.stderr
    assert res.stdout.splitlines()[0] == "crazyflie: 500 Hz, discrete design; integrators: none"
    assert (tmp_path / "quadctl_controller.h").exists() and (tmp_path / "quadctl_controller.c").exists()


def test_a_continuous_design_needs_a_rate(tmp_path):
    res = runner.invoke(app, ["export", "--to", "c", "-c", "hover", "-o", str(tmp_path)])
    assert res.exit_code == 2
    assert res.stderr.strip() == (
        "quadctl: error: hover.yaml: the design is continuous (no controller.rate) and a flight computer samples: give "
        "--rate HZ to run it at that rate, or set controller.rate (with controller.design: discrete to design "
        "for it)")


def test_a_rate_that_makes_the_loop_unstable_is_refused_with_the_reason(tmp_path):
    res = runner.invoke(app, ["export", "--to", "c", "-c", "hover", "--rate", "200", "-o", str(tmp_path)])
    assert res.exit_code == 1
    assert res.stderr.startswith("quadctl: check failed: not exported: roll: closed-loop pole -14493 rad/s is 115x "
                                 "faster "
                                 "than 200 Hz realizes")
    assert "sampled at 200 Hz this loop is UNSTABLE" in res.stderr
    assert not (tmp_path / "quadctl_controller.c").exists()


@pytest.mark.parametrize("to", ["c", "crazyflie", "json", "mat"])
def test_a_config_that_flies_the_pid_cascade_is_refused_in_one_line_and_nothing_is_written(tmp_path, to):
    """The export carries the LQR design: the C of a config that flies the cascade (controller.flies: pid)
    read the cascade's 41 law states uninitialized (the firmware build failed on -Werror=uninitialized),
    and its JSON or .mat would give the LQR gains of a vehicle that flies the PID."""
    from quadctl.export import PID_NOT_EXPORTED

    res = runner.invoke(app, ["export", "--to", to, "-c", "crazyflie", "--set", "controller.flies=pid",
                              "-o", str(tmp_path / "out")])
    assert res.exit_code == 2, res.output
    assert res.stderr == f"quadctl: error: {PID_NOT_EXPORTED}\n"
    assert not (tmp_path / "out").exists()


def test_a_rate_for_a_config_that_has_one_is_refused(tmp_path):
    res = runner.invoke(app, ["export", "--to", "c", "-c", "crazyflie", "--rate", "200", "-o", str(tmp_path)])
    assert res.exit_code == 2
    assert "--rate 200: the config sets controller.rate = 500 Hz" in res.stderr


# ---------------------------------------------------------------------------------------
# .mat and JSON


def _plain(value):
    """A value as loadmat(simplify_cells=True) gives it back: squeezed arrays, cells as lists."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [str(v) for v in value]
    if isinstance(value, np.ndarray):
        return np.squeeze(value)
    return value


def _loaded(value):
    if isinstance(value, dict):
        return {k: _loaded(v) for k, v in value.items()}
    if isinstance(value, np.ndarray) and value.dtype == object:
        return [str(v) for v in value.ravel()]
    if isinstance(value, np.ndarray) and value.dtype.kind == "U":  # an empty char array
        return "".join(value.ravel())
    return np.squeeze(value) if isinstance(value, np.ndarray) else value


def _assert_same(name, expected, got):
    if isinstance(expected, dict):
        assert set(got) == set(expected), name
        for k in expected:
            _assert_same(f"{name}.{k}", expected[k], got[k])
    elif isinstance(expected, list):
        got = [got] if isinstance(got, str) else got  # a one-element cell comes back as its element
        assert list(got) == expected, name
    elif isinstance(expected, np.ndarray):
        got = np.asarray(got)
        assert got.size == expected.size and np.array_equal(got.ravel(), expected.ravel()), name
    else:
        assert got == expected, name


@pytest.mark.parametrize("name", ["mambo-200hz", "forward"])
def test_the_mat_file_round_trips_through_loadmat(name, tmp_path):
    from scipy.io import loadmat

    res = runner.invoke(app, ["export", "--to", "mat", "-c", name, "-o", str(tmp_path)])
    assert res.exit_code == 0, res.stderr
    got = loadmat(str(tmp_path / data.MAT_FILE), simplify_cells=True)
    cfg = config.load(name)
    exp = export.prepare(setup_of(cfg), need_rate=False, config_hash=cfg.digest())
    fields = data.fields(exp)
    assert {f.name for f in fields} | {"units", "descriptions"} == {k for k in got if not k.startswith("__")}
    for f in fields:
        _assert_same(f.name, _plain(f.value), _loaded(got[f.name]))
    assert got["units"]["K"] == "input unit per state unit"
    assert got["Ts"] == (0.005 if name == "mambo-200hz" else 0.0)
    assert got["K"].shape == (4, 12) and got["x_trim"].shape == (12,)
    # every number is a double: MATLAB's int64 * double is int64, so an integer delay_samples * Ts was 0
    raw = loadmat(str(tmp_path / data.MAT_FILE))
    numeric = {k: v for k, v in raw.items() if isinstance(v, np.ndarray) and v.dtype.kind in "iuf"}
    assert "delay_samples" in numeric and all(v.dtype == np.float64 for v in numeric.values()), {
        k: v.dtype for k, v in numeric.items() if v.dtype != np.float64}


def test_the_mat_file_loads_in_octave(tmp_path):
    octave = shutil.which("octave-cli") or shutil.which("octave")
    if octave is None:
        pytest.skip("GNU Octave is not on PATH")
    assert runner.invoke(app, ["export", "--to", "mat", "-c", "mambo-200hz", "-o", str(tmp_path)]).exit_code == 0
    script = ("d = load('quadctl_controller.mat'); assert(isequal(size(d.K), [4 12]));"
              "assert(isequal(size(d.x_trim), [12 1]));"
              "assert(strcmp(d.state_names{3}, 'pD')); assert(abs(d.Ts - 0.005) < 1e-15);"
              "assert(isequal(size(d.subsystems.altitude.Q), [3 3])); disp('ok')")
    res = subprocess.run([octave, "--quiet", "--no-window-system", "--eval", script], cwd=tmp_path,
                         capture_output=True, text=True)
    assert res.returncode == 0 and res.stdout.strip().endswith("ok"), res.stderr


def test_the_json_holds_the_same_fields_with_units_and_shapes(tmp_path):
    res = runner.invoke(app, ["export", "--to", "json", "-c", "mambo-200hz", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.stderr
    doc = json.loads((tmp_path / data.JSON_FILE).read_text())
    cfg = config.load("mambo-200hz")
    assert doc["format"] == "quadctl-controller" and doc["config_hash"] == cfg.digest()
    exp = export.prepare(setup_of(cfg), config_hash=cfg.digest())
    assert doc["law"] == exp.law()
    for f in data.fields(exp):
        entry = doc["fields"][f.name]
        array = isinstance(f.value, np.ndarray)  # the keys the export page names: shape and complex for arrays only
        assert set(entry) == {"value", "unit", "description"} | ({"shape", "complex"} if array else set()), f.name
        if array:
            assert entry["shape"] == list(f.value.shape), f.name
            value = np.array(entry["value"], dtype=float)
            if entry["complex"]:
                value = value[..., 0] + 1j * value[..., 1]
            np.testing.assert_array_equal(value.reshape(f.value.shape), f.value, err_msg=f.name)
    eig = doc["fields"]["eig_cl"]
    assert eig["unit"] == "z" and eig["shape"] == [13] and eig["complex"] is True
    assert doc["fields"]["K"]["complex"] is False and doc["fields"]["K"]["shape"] == [4, 12]
    assert doc["fields"]["K"]["unit"] == "input unit per state unit"
    assert doc["fields"]["subsystems"]["value"]["altitude"]["integral"] == ["pD"]


def test_the_mat_file_carries_the_kalman_filter_that_gives_the_simulated_estimates(tmp_path):
    """The ``estimator`` struct of an LQG export, read back with loadmat, is the loop's filter; its
    fields alone (Ae, Be, gain M, measured_index, x_trim, x_rate, u_trim, Ts) rerun the filter on the
    measurements simulate's controller saw and give simulate's a priori estimates."""
    from scipy.io import loadmat

    from quadctl.physics.noise import realize

    exp = prepared("mambo-lqg")
    buf = io.BytesIO()
    data.write_mat(buf, exp)
    buf.seek(0)
    d = loadmat(buf, simplify_cells=True)
    e, kal = d["estimator"], exp.loop.estimator
    assert e["form"] == "filter" and list(e["measured"]) == list(kal.measured) == [
        "pN", "pE", "pD", "phi", "theta", "psi", "p", "q", "r"]
    np.testing.assert_array_equal(e["gain"], kal.gain)
    np.testing.assert_allclose(e["predictor_gain"], e["Ae"] @ e["gain"], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(e["C"], np.eye(N_STATES)[e["measured_index"].astype(int) - 1])
    setup, loop = exp.setup, exp.loop
    plan = loop.plan(setup.duration, setup.dt)
    ref = simulate(loop, setup.initial_state(loop.x_trim), setup.duration, setup.dt, noise=setup.noise,
                   max_samples=plan.n_steps + 1)
    _, sensor = realize(setup.noise, plan.n_steps, plan.dt)
    samples = np.arange(0, plan.n_steps, plan.hold)
    xh, worst = np.zeros(N_STATES), 0.0
    for k, i in enumerate(samples):
        worst = max(worst, np.abs(xh - (ref.x_hat[i] - ref.x_ref[i])).max())
        x_ref = d["x_trim"] + d["x_rate"] * k * d["Ts"]
        y = e["C"] @ (ref.x[i] + sensor[i])
        xc = xh + e["gain"] @ (y - e["C"] @ x_ref - e["C"] @ xh)
        xh = e["Ae"] @ xc + e["Be"] @ (ref.u[i] - d["u_trim"])
    print(f"max |x_hat(mat) - x_hat(simulate)| = {worst:.3e}")
    assert worst < 1e-12, f"max |x_hat(mat) - x_hat(simulate)| = {worst:.3e}"
    assert np.ptp(ref.x_hat[:, STATE_INDEX["w"]]) > 0.1  # the unmeasured climb rate is estimated, and moves


def test_the_mat_file_of_a_filtered_lqg_loop_reruns_the_gyro_filter_and_the_kalman_filter():
    """With the gyro filter in the Kalman filter's model, the ``.mat`` file's fields alone (``gyro_filter``'s
    A, b, c, d on the raw rates; ``estimator``'s Ae, Be, C, gain over ``states``, the 12 and the filter's)
    rerun both on the measurements simulate's controller saw and give simulate's a priori estimates."""
    from scipy.io import loadmat

    from quadctl.physics.noise import realize

    exp = prepared("mambo-lqg-gyro-filtered")
    buf = io.BytesIO()
    data.write_mat(buf, exp)
    buf.seek(0)
    d = loadmat(buf, simplify_cells=True)
    e, f, kal = d["estimator"], d["gyro_filter"], exp.loop.estimator
    ne = N_STATES + 3 * len(f["b"])
    assert e["Ae"].shape == (ne, ne) and e["C"].shape == (9, ne) and len(e["states"]) == ne == kal.n_estimate
    np.testing.assert_array_equal(e["Ae"], kal.A)
    setup, loop = exp.setup, exp.loop
    plan = loop.plan(setup.duration, setup.dt)
    ref = simulate(loop, setup.initial_state(loop.x_trim), setup.duration, setup.dt, noise=setup.noise,
                   max_samples=plan.n_steps + 1)
    _, sensor = realize(setup.noise, plan.n_steps, plan.dt)
    rows = e["measured_index"].astype(int) - 1
    rates = [STATE_INDEX[r] for r in ("p", "q", "r")]
    m = len(f["b"])
    g, xh, worst = np.zeros((3, m)), np.zeros(ne), 0.0
    for k, i in enumerate(np.arange(0, plan.n_steps, plan.hold)):
        worst = max(worst, np.abs(xh[:N_STATES] - (ref.x_hat[i] - ref.x_ref[i])).max())
        x_m = ref.x[i] + sensor[i]
        raw = x_m[rates].copy()
        x_m[rates] = g @ f["c"] + f["d"] * raw  # the law's filtered rates
        g = g @ f["A"].T + np.outer(raw, f["b"])
        y = (x_m - (d["x_trim"] + d["x_rate"] * k * d["Ts"]))[rows]
        xc = xh + e["gain"] @ (y - e["C"] @ xh)
        xh = e["Ae"] @ xc + e["Be"] @ (ref.u[i] - d["u_trim"])
    print(f"max |x_hat(mat) - x_hat(simulate)| = {worst:.3e}")
    assert worst < 1e-12, f"max |x_hat(mat) - x_hat(simulate)| = {worst:.3e}"


def test_a_continuous_lqg_export_carries_the_kalman_bucy_filter():
    data_, _ = _mambo_lqg()
    data_["controller"] = {**data_["controller"], "rate": None}
    cfg = config.from_dict(data_, "lqg.yaml")
    exp = export.prepare(setup_of(cfg), need_rate=False)
    (field,) = [f for f in data.fields(exp) if f.name == "estimator"]
    e = field.value
    assert e["form"] == "kalman-bucy" and e["sample_time"] == 0.0 and "intensities" in field.unit
    np.testing.assert_array_equal(e["gain"], e["predictor_gain"])
    np.testing.assert_array_equal(e["Ae"], exp.linear.A)
    assert "Kalman-Bucy filter's estimate" in exp.law()
    assert "estimator" not in {f.name for f in data.fields(prepared("mambo-200hz"))}


def test_exported_eigenvalues_are_the_designs():
    cfg = config.load("mambo-200hz")
    exp = export.prepare(setup_of(cfg))
    got = np.sort_complex(exp.closed_loop_eigenvalues())
    want = np.sort_complex(exp.design.full_eigenvalues_z)
    assert np.abs(got - want).max() < 1e-12
    marginal = np.abs(got) >= 1  # pN, pE: nothing regulates them (marginal by design)
    assert marginal.sum() == len(exp.design.marginal_states) == 2 and np.allclose(got[marginal], 1.0)


# ---------------------------------------------------------------------------------------
# The Crazyflie config


def test_the_crazyflie_flies_within_its_motors():
    """Bryson weights sized for the rotors: from the configured offset no rotor reaches a limit,
    and the most loaded stays inside the firmware's 0.12 N thrust cap too."""
    exp = prepared("crazyflie")
    setup, loop = exp.setup, exp.loop
    sim = simulate(loop, setup.initial_state(loop.x_trim), setup.duration, setup.dt, noise=None)
    assert sim.status == "ok"
    thrust = loop.actuators.commands(sim.u)
    assert 0.06 < thrust.min() and thrust.max() < 0.12
    assert not motors.saturates(motors.saturation_fraction(loop.actuators, sim.u))
    final = np.abs(sim.x[-1] - sim.x_ref[-1])
    assert final[STATE_INDEX["pD"]] < 1e-3 and final[STATE_INDEX["phi"]] < 1e-5


def test_the_crazyflie_parameters_are_the_cited_ones():
    cfg = config.load("crazyflie")
    assert cfg.vehicle.mass == 0.027 and cfg.vehicle.inertia == [16.571710e-6, 16.655602e-6, 29.261652e-6]
    rpm = math.pi / 30  # rad/s per rpm
    assert cfg.motors.thrust_coefficient == pytest.approx(3.1582e-10 / rpm ** 2, rel=1e-4)
    assert cfg.motors.max_thrust == pytest.approx(0.091492681 + 0.067673604, rel=2e-6)
    # Förster's rotor drag at hover: K_aero * (sum of rotor speeds) = T * Kc
    T = cfg.vehicle.mass * cfg.vehicle.gravity
    speeds = 4 * math.sqrt(T / 4 / cfg.motors.thrust_coefficient)
    assert cfg.vehicle.drag[0] * T == pytest.approx(10.2506e-7 * speeds, rel=1e-4)
    assert cfg.vehicle.drag[2] * T == pytest.approx(7.5533e-7 * speeds, rel=1e-4)


def test_simulate_crazyflie_reports_no_saturation(tmp_path):
    res = runner.invoke(app, ["simulate", "-c", "crazyflie", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.stderr
    assert "saturates" not in res.stderr
    assert "ok: completed 10000 steps" in res.stdout


# ---------------------------------------------------------------------------------------
# docs/guide/export.md ("Take it to the vehicle"): every command and code block runs, and prints what it shows

PAGE = ROOT / "docs" / "guide" / "export.md"
INLINE_COMMANDS = ("quadctl simulate -c crazyflie", "quadctl margins -c crazyflie")
"""Commands the section names in its text (not in a console block)."""


def _flight_loop_main(read: str) -> str:
    """A main.c for the export page's flight loop: ``read`` (the sensor read it calls), a rotor write that
    keeps what it was sent, and one tick whose commands it prints."""
    return (r"""
#include <stdio.h>
#include "quadctl_controller.h"

void control_tick(quadctl_controller *c);

static quadctl_real sent[QUADCTL_N_ROTORS];
""" + read + r"""
void set_rotor_thrusts(const quadctl_real thrust[QUADCTL_N_ROTORS]) {
  int i;
  for (i = 0; i < QUADCTL_N_ROTORS; ++i) sent[i] = thrust[i];
}

int main(void) {
  quadctl_controller c;
  quadctl_init(&c);
  control_tick(&c);
  printf("%.17g %.17g %.17g %.17g\n", (double)sent[0], (double)sent[1], (double)sent[2], (double)sent[3]);
  return 0;
}
""")


FLIGHT_LOOP_MAIN = _flight_loop_main(r"""
void read_state(quadctl_real x[QUADCTL_NX]) {  /* hover trim, 0.5 m low */
  int i;
  for (i = 0; i < QUADCTL_NX; ++i) x[i] = 0;
  x[QUADCTL_X_PD] = -0.5;
}
""")


def _section() -> str:
    return PAGE.read_text(encoding="utf-8")


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", _section(), re.S)


def _console_runs() -> list[tuple[str, list[str]]]:
    """(command, the output lines shown under it) of every console block."""
    runs = []
    for block in _blocks("console"):
        for line in block.splitlines():
            if line.startswith("$ "):
                runs.append((line[2:].split("  #")[0].strip(), []))
            elif line.strip() and line.strip() != "...":
                runs[-1][1].append(line)
    return runs


def _flat(text: str) -> str:
    return " ".join(text.split())


def test_the_page_comes_after_the_flight_page():
    """The export page builds on the designs of the flight page: the guide's order reads that one first."""
    order = re.findall(r"^guide/(\S+)$", (ROOT / "docs" / "index.md").read_text(encoding="utf-8"), re.M)
    assert order.index("export") > order.index("flying")


def test_the_page_commands_print_what_it_shows_and_its_code_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "docs").symlink_to(ROOT / "docs")  # the section's LQG config
    runs = _console_runs()
    assert len(runs) == 12
    for command, shown in runs:
        res = runner.invoke(app, shlex.split(command)[1:])
        failed = any(line.startswith(("quadctl: error:", "quadctl: check failed:")) for line in shown)
        assert (res.exit_code != 0) == failed, (command, res.exit_code, res.stderr)
        # a shown note or warning is on stderr, the rest on stdout
        printed = _flat(res.stderr if failed else f"{res.stdout}\n{res.stderr}")
        for line in shown:
            assert _flat(line) in printed, (command, line)
    for command in INLINE_COMMANDS:
        assert command in _flat(_section())
        res = runner.invoke(app, [*shlex.split(command)[1:], "-o", str(tmp_path / "inline")])
        assert res.exit_code == 0, (command, res.stderr)
    for block in _blocks("python"):  # a `print(...)  # text` line prints exactly that text
        expected = [line.split("  # ", 1)[1] for line in block.splitlines()
                    if line.startswith("print(") and "  # " in line]
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            exec(compile(block, str(PAGE), "exec"), {})
        assert out.getvalue().splitlines() == expected


@pytest.mark.parametrize("single", [False, True], ids=["double", "float"])
def test_the_flight_loop_compiles_and_flies(single, tmp_path):
    """The export page's C snippet, with stub sensors and motors, against the crazyflie export: one tick
    from 0.5 m low asks every rotor for the same thrust, the library's, clipped."""
    snippet = _blocks("c")[0]
    compiler = cc()
    res = runner.invoke(app, ["export", "--to", "c", "-c", "crazyflie", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.stderr
    (tmp_path / "flight.c").write_text(snippet)
    (tmp_path / "main.c").write_text(FLIGHT_LOOP_MAIN)
    exe = tmp_path / "flight"
    build = subprocess.run([compiler, *STRICT, *(["-DQUADCTL_FLOAT"] if single else []), "flight.c", "main.c",
                            cexport.SOURCE, "-o", str(exe), "-lm"], cwd=tmp_path, capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    thrust = np.array(subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split(), float)
    loop = prepared("crazyflie").loop
    x = np.zeros(N_STATES)
    x[STATE_INDEX["pD"]] = -0.5
    act = loop.actuators
    want = np.clip(act.commands(loop.u_trim - loop.K @ (x - loop.x_trim)), act.lo, act.hi)
    np.testing.assert_allclose(thrust, want, rtol=1e-6 if single else 1e-14)
    assert np.all(thrust > 0.027 * 9.81 / 4)  # climbing


LQG_FLIGHT_LOOP_MAIN = _flight_loop_main(r"""
void read_sensors(quadctl_real y[QUADCTL_NY]) {  /* 0.5 m low (pD = -0.5 m), rolled 0.1 rad */
  int i;
  for (i = 0; i < QUADCTL_NY; ++i) y[i] = 0;
  y[QUADCTL_Y_PD] = -0.5;
  y[QUADCTL_Y_PHI] = 0.1;
}
""")


@pytest.mark.compiler
@pytest.mark.parametrize("single", [False, True], ids=["double", "float"])
def test_the_readme_lqg_flight_loop_compiles_and_its_first_tick_is_the_filters(single, tmp_path):
    """The export page's LQG snippet against the mambo-lqg export: the first tick is the filter's update from
    the trim, xc = M (y - C x_trim), and the law on it, u = sat(u_trim - K xc), mixed to the rotors."""
    snippet = _blocks("c")[1]
    assert "quadctl_step(c, y, u)" in snippet
    res = runner.invoke(app, ["export", "--to", "c", "-c", LQG_CONFIG, "-o", str(tmp_path)])
    assert res.exit_code == 0, res.stderr
    (tmp_path / "flight.c").write_text(snippet)
    (tmp_path / "main.c").write_text(LQG_FLIGHT_LOOP_MAIN)
    exe = tmp_path / "flight"
    build = subprocess.run([cc(), *STRICT, *(["-DQUADCTL_FLOAT"] if single else []), "flight.c", "main.c",
                            cexport.SOURCE, "-o", str(exe), "-lm"], cwd=tmp_path, capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    thrust = np.array(subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split(), float)
    cfg = config.load(LQG_CONFIG)
    loop = export.prepare(setup_of(cfg)).loop
    kal, act = loop.estimator, loop.actuators
    y = np.zeros(len(kal.measured))
    y[kal.measured.index("pD")], y[kal.measured.index("phi")] = -0.5, 0.1
    xc = kal.gain @ (y - kal.C @ loop.x_trim)
    want = np.clip(act.commands(loop.u_trim - loop.K @ xc), act.lo, act.hi)
    np.testing.assert_allclose(thrust, want, rtol=1e-6 if single else 1e-14)
    assert thrust[0] != thrust[1]  # the roll measurement moved the estimate: the rotors differ


REFERENCE_FLIGHT_LOOP_MAIN = r"""
#include <stdio.h>
#include "quadctl_controller.h"

void control_tick(quadctl_controller *c, double t);

static quadctl_real applied[QUADCTL_NU];

void read_state(quadctl_real x[QUADCTL_NX]) {  /* the trim, 0.2 m east and 0.3 m low */
  quadctl_reference trim;
  int i;
  quadctl_reference_trim(&trim);
  for (i = 0; i < QUADCTL_NX; ++i) x[i] = trim.x[i];
  x[QUADCTL_X_PE] += 0.2;
  x[QUADCTL_X_PD] += 0.3;
}

void path_at(double t, quadctl_reference *ref) {  /* the trim moving north at 1 m/s, pitching 0.05 rad */
  quadctl_reference_trim(ref);
  ref->x[QUADCTL_X_PN] += (quadctl_real)t;
  ref->x[QUADCTL_X_U] = 1;
  ref->x[QUADCTL_X_THETA] = -0.05;
  ref->u[QUADCTL_U_E] = 0.001;
}

void apply_inputs(const quadctl_real u[QUADCTL_NU]) {
  int i;
  for (i = 0; i < QUADCTL_NU; ++i) applied[i] = u[i];
}

int main(void) {
  quadctl_controller c;
  quadctl_init(&c);
  control_tick(&c, 0.5);
  printf("%.17g %.17g %.17g %.17g\n", (double)applied[0], (double)applied[1], (double)applied[2], (double)applied[3]);
  return 0;
}
"""


@pytest.mark.compiler
@pytest.mark.parametrize("single", [False, True], ids=["double", "float"])
def test_the_readme_reference_flight_loop_compiles_and_regulates_to_the_reference(single, tmp_path):
    """The export page's reference snippet against the square's export at 200 Hz: one tick is
    u = u_ref - K (x - x_ref) with the reference the path gave (no limits in this config)."""
    snippet = _blocks("c")[2]
    assert "quadctl_step_ref(c, x, &ref, u)" in snippet
    res = runner.invoke(app, ["export", "--to", "c", "-c", "square", "--set", "controller.rate=200",
                              "--set", "controller.design=discrete", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.stderr
    (tmp_path / "flight.c").write_text(snippet)
    (tmp_path / "main.c").write_text(REFERENCE_FLIGHT_LOOP_MAIN)
    exe = tmp_path / "flight"
    build = subprocess.run([cc(), *STRICT, *(["-DQUADCTL_FLOAT"] if single else []), "flight.c", "main.c",
                            cexport.SOURCE, "-o", str(exe), "-lm"], cwd=tmp_path, capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    u = np.array(subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split(), float)
    loop = prepared("square").loop
    x, x_ref, u_ref = loop.x_trim.copy(), loop.x_trim.copy(), loop.u_trim.copy()
    x[STATE_INDEX["pE"]] += 0.2
    x[STATE_INDEX["pD"]] += 0.3
    x_ref[STATE_INDEX["pN"]] += 0.5
    x_ref[STATE_INDEX["u"]], x_ref[STATE_INDEX["theta"]], u_ref[2] = 1.0, -0.05, 0.001
    want = u_ref - loop.K @ (x - x_ref)
    np.testing.assert_allclose(u, want, rtol=1e-6 if single else 1e-14, atol=1e-7 if single else 1e-15)
    assert u[0] > loop.u_trim[0] and u[1] != 0 and u[2] != 0  # 0.3 m low: it climbs; it rolls and pitches


def test_the_readme_matlab_runs_in_octave(tmp_path):
    octave = shutil.which("octave-cli") or shutil.which("octave")
    if octave is None:
        pytest.skip("GNU Octave is not on PATH")
    (block,) = _blocks("matlab")
    out = tmp_path / "runs" / "mambo-200hz"
    assert runner.invoke(app, ["export", "--to", "mat", "-c", "mambo-200hz", "-o", str(out)]).exit_code == 0
    script = block + "\nassert(max(abs(u - d.u_trim)) == 0); disp('ok')"
    res = subprocess.run([octave, "--quiet", "--no-window-system", "--eval", script], cwd=tmp_path,
                         capture_output=True, text=True)
    assert res.returncode == 0 and res.stdout.strip().endswith("ok"), res.stderr
