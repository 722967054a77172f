"""quadctl benchmarks: one table, measured in one run, against the obvious alternatives.

    python benchmarks/bench.py            # everything (about a minute)
    python benchmarks/bench.py --skip-slow  # without the two RK45 runs (about 7 s each)
    python benchmarks/bench.py --cli-python VENV/bin/python  # the CLI rows with another install
    python benchmarks/bench.py --only sweep flying-sweep  # some sections (see --help)

1. One closed-loop simulation of the bundled forward config (the report's case), RK4 at
   dt = 1e-5 s for 10 s = 1 000 000 steps: quadctl's compiled loop (library call, after the one-time
   compilation), the same through the command line end to end (a fresh process: interpreter
   start, imports, the simulation, metrics, artifacts; with and without --fresh), and SciPy's solve_ivp (RK45 and LSODA)
   and python-control's input_output_response on the same closed loop (the CasADi model called
   from Python), at tolerances that reach the same final-state accuracy.
   Also the same loop without a C compiler (CasADi's virtual machine, the fallback).
1b. The same loop at dt: auto (the stiff case: rate poles near -14 500 rad/s): ETDRK4's graded
   schedule at tolerance 1e-8 against RK4 at its stability-held step and LSODA at rtol 1e-10, CPU
   time of whole library calls, best of several; and a sweep of the 1000 random designs of
   benchmarks/random-1000.yaml for 10 s at dt: auto, ETDRK4 against RK4 (steps per case, cases/s);
   and ETDRK4 across the steps of a reference (velocity setpoints on the forward loop) and across a
   gain schedule (the bundled schedule config flown from hover to 10 m/s), against RK4 at a small
   step that divides the reference's rows.
2. A sweep of 1000 random designs (benchmarks/random-1000.yaml, no two alike) x 10 000 RK4 steps:
   on both cores, on one, through the command line, and the one-case-at-a-time pipeline, against
   the machine's ceiling (a hand-written structure-of-arrays C RK4 of the same loop, 64 cases a chunk,
   OpenMP over both cores, compiled at bench time from CEILING_SOURCE); and a
   sweep of 1000 random designs of mambo-200hz (benchmarks/mambo-1000.yaml: 200 Hz discrete
   design, rotors, LQI, noise; 2 000 steps each), the configs that fly, at the same lane speed; and a
   sweep of the bundled square mission over its speed (benchmarks/square-speed.yaml: 48 cases, each
   its own reference, a tracking-error gate), at the same lane speed; and the PID cascade in the lanes:
   64 masses of the crazyflie config (benchmarks/crazyflie-mass.yaml) flown by the Crazyflie firmware's
   cascade (controller.flies: pid) and by the config's LQR design, alternated, for their ratio.
3. The LQR designs of that sweep (4000 small subsystems): quadctl's batched solver against a
   Python loop over scipy.linalg.solve_continuous_are.
4. quadctl.design.lqr on one larger random system (n = 10, 50, 100, 200) against
   scipy.linalg.solve_continuous_are on the same problem.
5. Discrete designs of 1000 3-state subsystems (the report's roll and pitch loops at 200 Hz, random
   weights): the batched lqrd (lqrd_weights_batch, dare_batch) against a Python loop over
   scipy.linalg.solve_discrete_are.
6. Figures: `quadctl run --plot` on the forward config, a fresh process end to end, with the run
   folder's stage artifacts there (they are reused) and --fresh; the same without --plot; the six
   figures drawn in the library; the sweep's trade-off figure of the 1000 random designs.
7. A 50-point gain schedule (the bundled schedule config at 50 speeds from 0 to 10 m/s, and
   mambo-200hz's discrete LQI design at the same speeds): trims, batched designs and the frozen-point
   checks on a 4x finer grid (197 loops), in the library and through the command line; against
   the same done point by point through the one-case pipeline.
8. Identification from real Crazyflie flights (tests/data/crazyflie-flights): log10, 50 s at about
   1 kHz, read and identified (thrust curve, motor lag, intervals; the window from the excitation), in
   the library and through the command line; log10 and log15 together (the thrust stage, then Ixx
   and Iyy); log10 with a pure delay as well.

Not a test: it asserts nothing, it prints what it measured and the machine's load while it ran
(other processes on a 2-core machine change every number here). Each quadctl timing is the best of
a few runs; the alternatives, which take seconds, run once.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SWEEP_FILE = HERE / "random-1000.yaml"
FLYING_SWEEP_FILE = HERE / "mambo-1000.yaml"
PID_SWEEP_FILE = HERE / "crazyflie-mass.yaml"
MISSION_SWEEP_FILE = HERE / "square-speed.yaml"
DURATION = 10.0       # s
DT = 1e-5             # s: 1 000 000 RK4 steps
REPEAT = 5
"""Timed runs of each sweep: the best is reported (the others lost time to other processes)."""
ALTERNATED = 8
"""Runs of each sweep, the plain and the flying one alternated, for their ratio on both cores."""
LIBRARY_IMPORTS = "import typer._adapters, numpy, pydantic, rich.console, rich.table, yaml"
"""What any quadctl command imports before it does any work (typer imports pydantic to parse)."""
LSODA_IMPORTS = "import numpy, scipy.integrate"
"""What a script that runs LSODA imports before it integrates (its right-hand side aside)."""
TOLERANCES = {"RK45": (1e-8, 1e-10), "LSODA": (1e-10, 1e-12)}
"""(rtol, atol) per solve_ivp method: the loosest that reach the final-state error of quadctl's RK4
at dt = 1e-5 s (about 1e-9 in state units, against the reference) on this problem."""


def timed(fn, repeat: int = 1):
    """(best wall time in s, last result)."""
    best, out = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def table(title: str, header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    line = "| " + " | ".join(h.ljust(w) for h, w in zip(header, widths)) + " |"
    rule = "|" + "|".join("-" * (w + 2) for w in widths) + "|"
    body = ["| " + " | ".join(str(c).rjust(w) if k else str(c).ljust(w) for k, (c, w) in
                              enumerate(zip(r, widths))) + " |" for r in rows]
    return "\n".join([f"\n{title}\n", line, rule, *body])


# ---------------------------------------------------------------------------------------
# 1. One simulation


def one_simulation(skip_slow: bool, cli_python: str) -> str:
    from scipy.integrate import solve_ivp

    from quadctl import config, pipeline
    from quadctl.setup import setup_of
    from quadctl.sim import engine
    from quadctl.sim.run import simulate

    cfg = config.load("forward")
    setup = setup_of(cfg)
    linear = pipeline.linear_of(setup, pipeline.trim_of(setup))
    des = pipeline.design_of(setup, pipeline.decoupled_of(setup, linear), linear)
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(linear.x_trim)
    simulate(loop, x0, 0.01, DT)  # compile (or load the cached library) before timing

    rhs = closed_loop_rhs(loop)  # the closed loop as one CasADi function, called by the ODE solvers

    # reference: an independent method at a far tighter tolerance
    ref = solve_ivp(rhs, (0, DURATION), x0, method="LSODA", rtol=1e-12, atol=1e-14).y[:, -1]

    def error(x_end):
        return float(np.max(np.abs(np.asarray(x_end) - ref)))

    runs = []
    sims = [simulate(loop, x0, DURATION, DT) for _ in range(3)]
    best = min(sims, key=lambda s: s.wall_time)
    ours = best.wall_time
    runs.append(("quadctl compiled RK4 (library)", ours, f"{best.steps:,} steps", error(best.x[-1])))
    # no C compiler: the same loop in CasADi's virtual machine (a tenth of the run, scaled)
    os.environ["QUADCTL_NO_COMPILE"] = "1"
    engine.runner.cache_clear()
    try:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            simulate(loop, x0, 0.01, DT)  # builds the CasADi blocks before timing
            vm = min((simulate(loop, x0, DURATION / 10, DT) for _ in range(2)), key=lambda s: s.wall_time)
    finally:
        del os.environ["QUADCTL_NO_COMPILE"]
        engine.runner.cache_clear()
    runs.append(("quadctl without a C compiler (CasADi VM), x10", vm.wall_time * 10,
                 f"{vm.steps * 10:,} steps", float("nan")))

    with tempfile.TemporaryDirectory() as tmp:
        import yaml

        data = cfg.model_dump(mode="json")
        data["name"] = "forward-1M"
        data["simulation"]["dt"] = DT
        path = Path(tmp) / "forward-1M.yaml"
        path.write_text(yaml.safe_dump(data, sort_keys=False))
        cmd = [cli_python, "-m", "quadctl", "simulate", "-c", str(path), "-o", str(Path(tmp) / "run")]
        subprocess.run(cmd, check=True, capture_output=True)  # designs once, warms the OS file cache
        cli, _ = timed(lambda: subprocess.run(cmd, check=True, capture_output=True), repeat=REPEAT)
        with np.load(Path(tmp) / "run" / "sim.npz") as npz:
            cli_err = error(npz["x"][-1])
        fresh, _ = timed(lambda: subprocess.run([*cmd, "--fresh"], check=True, capture_output=True), repeat=3)
        floor, _ = timed(lambda: subprocess.run([cli_python, "-c", LIBRARY_IMPORTS], check=True), repeat=REPEAT)
    runs.append(("quadctl simulate, CLI end to end", cli, f"{best.steps:,} steps", cli_err))
    runs.append(("quadctl simulate --fresh, CLI end to end", fresh, "+ trim, design", cli_err))

    for method in ("RK45", "LSODA"):
        if skip_slow and method == "RK45":
            continue
        rtol, atol = TOLERANCES[method]
        wall, sol = timed(lambda m=method, r=rtol, a=atol: solve_ivp(rhs, (0, DURATION), x0, method=m,
                                                                      rtol=r, atol=a))
        runs.append((f"scipy solve_ivp {method} (rtol {rtol:g})", wall, f"{sol.nfev:,} RHS calls",
                     error(sol.y[:, -1])))

    import control

    sys_ct = control.nlsys(lambda tt, xx, uu, params: rhs(tt, xx), None, states=12, inputs=0,
                           outputs=12, name="quad")
    for method in ("RK45", "LSODA"):
        if skip_slow and method == "RK45":
            continue
        rtol, atol = TOLERANCES[method]
        wall, resp = timed(lambda m=method, r=rtol, a=atol: control.input_output_response(
            sys_ct, [0.0, DURATION], 0.0, x0, solve_ivp_method=m, solve_ivp_kwargs={"rtol": r, "atol": a}))
        runs.append((f"python-control input_output_response, {method}", wall, "(solve_ivp inside)",
                     error(resp.states[:, -1])))

    rows = []
    for name, wall, work, err in runs:
        rows.append([name, f"{wall:.3f}", work, f"{1e6 / wall / 1e6:.2f} M", "-" if err != err else f"{err:.1e}",
                     "1" if wall == ours else f"{wall / ours:.2f}"])
    return table(f"One simulation: forward config, RK4 dt = {DT:g} s over {DURATION:g} s = 1,000,000 steps",
                 ["method", "wall (s)", "work", "RK4 steps/s equiv.", "final error", "wall / quadctl"],
                 rows) + ("\n\n'RK4 steps/s equiv.' is 1,000,000 / wall: the rate at which each method "
                          "covers the same 10 s simulation. 'final error' is the largest final-state "
                          "difference (state units) from LSODA at rtol 1e-12. The CLI rows are fresh "
                          "processes; the first reuses the trim and design artifacts of an earlier run "
                          "(`quadctl simulate` after `quadctl design`), --fresh recomputes them. Of the "
                          f"CLI's {cli:.3f} s, {floor:.3f} s is Python starting and importing typer, numpy, "
                          "pydantic, rich and yaml (`python -c '...'`): the floor of any command on "
                          f"these dependencies, with that interpreter ({cli_python}).")


# ---------------------------------------------------------------------------------------
# 1b. The stiff loop at dt: auto: ETDRK4 against RK4 and LSODA


def closed_loop_rhs(loop):
    """The forward loop's right-hand side ``rhs(t, x)`` for solve_ivp: one CasADi function of the
    model (:func:`quadctl.physics.model.build_model`, the one copy of the equations) under the loop's law
    ``u = u_trim - K (x - x_ref(t))``, called from Python."""
    import casadi as ca

    from quadctl.physics.model import build_model

    x, t = ca.SX.sym("x", 12), ca.SX.sym("t")
    u = loop.u_trim - ca.DM(loop.K) @ (x - (loop.x_trim + loop.x_rate * t))
    rhs_fn = ca.Function("closed_loop", [t, x], [build_model().f(x, u, loop.params)])

    def rhs(tt, xx):
        return rhs_fn(tt, xx).full().ravel()

    return rhs


def lean_closed_loop_rhs(loop):
    """The same closed loop as :func:`closed_loop_rhs`, written as a careful user writes it for
    LSODA: one scalar Python function, the model's equations through :mod:`math`, every sine,
    cosine and product computed once, the gain as nested tuples. The strongest Python right-hand
    side, so the ETDRK4 row is measured against it; checked against the CasADi model before timing.
    Diagonal inertia and still air (the ``forward`` config)."""
    from math import cos, sin

    m, g, jxx, jyy, jzz, kx, ky, kz, *products = (float(v) for v in loop.params)
    if any(products):
        raise ValueError("the lean right-hand side is written for a diagonal inertia")
    K = tuple(tuple(float(v) for v in row) for row in np.asarray(loop.K))
    u0 = tuple(float(v) for v in np.asarray(loop.u_trim).ravel())
    x0 = tuple(float(v) for v in np.asarray(loop.x_trim).ravel())
    xr = tuple(float(v) for v in np.asarray(loop.x_rate).ravel())
    k0, k1, k2, k3 = K
    iy_z, iz_x, ix_y = (jyy - jzz) / jxx, (jzz - jxx) / jyy, (jxx - jyy) / jzz

    def rhs(t, x):
        e = [x[i] - x0[i] - xr[i] * t for i in range(12)]
        thrust = u0[0] - sum(k * v for k, v in zip(k0, e))
        roll = u0[1] - sum(k * v for k, v in zip(k1, e))
        pitch = u0[2] - sum(k * v for k, v in zip(k2, e))
        yaw = u0[3] - sum(k * v for k, v in zip(k3, e))
        _, _, _, vu, vv, vw, phi, theta, psi, p, q, r = x
        cph, sph, cth, sth, cps, sps = cos(phi), sin(phi), cos(theta), sin(theta), cos(psi), sin(psi)
        # R_E^b rows (3-2-1); position rate is its transpose times the body velocity
        r00, r01, r02 = cth * cps, cth * sps, -sth
        r10, r11, r12 = sph * sth * cps - cph * sps, sph * sth * sps + cph * cps, sph * cth
        r20, r21, r22 = cph * sth * cps + sph * sps, cph * sth * sps - sph * cps, cph * cth
        tm = thrust / m
        yp = (q * sph + r * cph) / cth
        return [r00 * vu + r10 * vv + r20 * vw, r01 * vu + r11 * vv + r21 * vw, r02 * vu + r12 * vv + r22 * vw,
                -tm * kx * vu + g * r02 - (q * vw - r * vv),
                -tm * ky * vv + g * r12 - (r * vu - p * vw),
                -tm - tm * kz * vw + g * r22 - (p * vv - q * vu),
                p + yp * sth, q * cph - r * sph, yp,
                roll / jxx + iy_z * q * r, pitch / jyy + iz_x * r * p, yaw / jzz + ix_y * p * q]

    reference = closed_loop_rhs(loop)
    rng = np.random.default_rng(0)
    for _ in range(20):  # the same function as the model's, or the comparison means nothing
        x = np.asarray(loop.x_trim).ravel() + rng.normal(scale=0.3, size=12)
        t = float(rng.uniform(0, DURATION))
        want, got = reference(t, x), np.asarray(rhs(t, x))
        if not np.allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max()):
            raise AssertionError(f"lean right-hand side differs from the model by {np.abs(got - want).max():.2e}")
    return rhs


def cpu_best(fn, repeat: int):
    """(best process CPU time in s, last result): CPU time, so other processes on the machine do not count."""
    best, out = np.inf, None
    for _ in range(repeat):
        start = time.process_time()
        out = fn()
        best = min(best, time.process_time() - start)
    return best, out


def child_cpu_best(fn, repeat: int) -> float:
    """Best CPU time (s, user + system) of the child processes ``fn`` runs."""
    best = np.inf
    for _ in range(repeat):
        before = os.times()
        fn()
        after = os.times()
        best = min(best, (after.children_user - before.children_user)
                   + (after.children_system - before.children_system))
    return best


def stiff_simulation(cli_python: str) -> str:
    """The report's 10 s forward loop at dt: auto: ETDRK4's graded schedule (tolerance 1e-8) against
    RK4 at its stability-held step and SciPy's LSODA at rtol 1e-10 (on a lean scalar Python right-hand
    side, and on the CasADi model's), each a whole library call (ETDRK4: the public call after a
    warm-up, and a loop's first run with its linear part, φ-functions and schedule), CPU time, best
    of several."""
    import dataclasses

    from scipy.integrate import solve_ivp

    from quadctl import config, pipeline
    from quadctl.setup import setup_of
    from quadctl.sim.run import simulate

    setup = setup_of(config.load("forward"))
    linear = pipeline.linear_of(setup, pipeline.trim_of(setup))
    des = pipeline.design_of(setup, pipeline.decoupled_of(setup, linear), linear)
    loop = pipeline.loop_of(setup, linear, des)
    x0 = setup.initial_state(linear.x_trim)
    rhs = closed_loop_rhs(loop)
    lean = lean_closed_loop_rhs(loop)
    ref = solve_ivp(rhs, (0, DURATION), x0, method="LSODA", rtol=1e-12, atol=1e-14).y[:, -1]

    def error(x_end):
        return float(np.max(np.abs(np.asarray(x_end) - ref)))

    simulate(loop, x0, 0.01, "auto", method="etdrk4")  # compile (or load) both loops before timing
    simulate(loop, x0, 0.01, "auto")
    public = dataclasses.replace(setup, method="etdrk4", tolerance=1e-8)
    pipeline.simulation_of(public, loop)  # the warm-up: the loop keeps its plan, φ-functions and constants
    etd_cpu, etd = cpu_best(lambda: pipeline.simulation_of(public, loop), 20)
    first_cpu, _ = cpu_best(lambda: pipeline.simulation_of(public, dataclasses.replace(loop)), 10)  # a fresh loop
    rk4_cpu, rk4 = cpu_best(lambda: simulate(loop, x0, DURATION, "auto"), 5)
    lsoda_cpu, sol = cpu_best(lambda: solve_ivp(rhs, (0, DURATION), x0, method="LSODA", rtol=1e-10,
                                                atol=1e-12), 5)
    lean_cpu, lean_sol = cpu_best(lambda: solve_ivp(lean, (0, DURATION), x0, method="LSODA", rtol=1e-10,
                                                    atol=1e-12), 5)
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [cli_python, "-m", "quadctl", "simulate", "-c", "forward", "--set", "simulation.method=etdrk4",
               "-o", str(Path(tmp) / "run")]
        subprocess.run(cmd, check=True, capture_output=True)  # designs once, warms the OS file cache
        cli_cpu = child_cpu_best(lambda: subprocess.run(cmd, check=True, capture_output=True), REPEAT)
        with np.load(Path(tmp) / "run" / "sim.npz") as npz:
            cli_err = error(npz["x"][-1])
        floor_cpu = child_cpu_best(lambda: subprocess.run([cli_python, "-c", LIBRARY_IMPORTS], check=True), REPEAT)
        scipy_cpu = child_cpu_best(lambda: subprocess.run([cli_python, "-c", LSODA_IMPORTS], check=True), REPEAT)
    segs = etd.plan.schedule
    rows = [["quadctl ETDRK4, dt: auto, tolerance 1e-8 (pipeline.simulation_of)", f"{etd_cpu * 1e3:.2f}",
             f"{etd.steps:,} steps, {len(segs)} segments, {segs[0].dt:.2g} .. {segs[-1].dt:.2g} s",
             f"{error(etd.x[-1]):.1e}", "1"],
            ["the same, a loop's first run (its plan, φ-functions, constants)", f"{first_cpu * 1e3:.2f}",
             "the row above and its setup", f"{error(etd.x[-1]):.1e}", f"{first_cpu / etd_cpu:.1f}"],
            ["quadctl RK4, dt: auto (library)", f"{rk4_cpu * 1e3:.2f}", f"{rk4.steps:,} steps of {rk4.dt:.3g} s",
             f"{error(rk4.x[-1]):.1e}", f"{rk4_cpu / etd_cpu:.1f}"],
            ["scipy solve_ivp LSODA (rtol 1e-10), lean scalar Python RHS", f"{lean_cpu * 1e3:.2f}",
             f"{lean_sol.nfev:,} RHS calls", f"{error(lean_sol.y[:, -1]):.1e}", f"{lean_cpu / etd_cpu:.1f}"],
            ["scipy solve_ivp LSODA (rtol 1e-10), CasADi-function RHS", f"{lsoda_cpu * 1e3:.2f}",
             f"{sol.nfev:,} RHS calls", f"{error(sol.y[:, -1]):.1e}", f"{lsoda_cpu / etd_cpu:.1f}"],
            ["quadctl simulate --set simulation.method=etdrk4, CLI end to end", f"{cli_cpu * 1e3:.2f}",
             "a fresh process", f"{cli_err:.1e}", f"{cli_cpu / etd_cpu:.1f}"],
            ["Python's import floor + lean LSODA (rtol 1e-10)", f"{(floor_cpu + lean_cpu) * 1e3:.2f}",
             "`python -c '...'` + the lean LSODA row", "-", f"{(floor_cpu + lean_cpu) / etd_cpu:.1f}"],
            ["LSODA's script: Python, numpy + scipy.integrate + lean LSODA", f"{(scipy_cpu + lean_cpu) * 1e3:.2f}",
             f"`python -c '{LSODA_IMPORTS}'` + lean LSODA", "-", f"{(scipy_cpu + lean_cpu) / etd_cpu:.1f}"]]
    return table(f"The stiff loop: forward config, {DURATION:g} s at dt: auto (fastest pole "
                 f"{abs(rk4.plan.fastest_eigenvalue):,.0f} rad/s)",
                 ["method", "CPU (ms)", "work", "final error", "CPU / ETDRK4"], rows) + (
        "\n\nCPU time of the calling process (best of 20 for ETDRK4, of 5 for the others; of the child "
        "process for the CLI rows), so the other work on a loaded machine does not count; ETDRK4's is the "
        "public call after a warm-up, which leaves the loop its plan, φ-functions and constants (the second "
        "row computes them, on a fresh copy of the loop each run). The CLI row reuses the trim and design "
        "of an earlier run. 'final error': largest final-state difference (state units) from LSODA at rtol 1e-12.")


STIFF_SWEEP_DURATION = 10.0
"""s: the stiff sweep runs the report's whole 10 s per case (RK4 at its stability-held step)."""


def stiff_references() -> str:
    """ETDRK4 (dt: auto, tolerance 1e-8) where the reference steps: the forward loop with velocity
    setpoints at 0.5 and 1 s (1.5 s), graded again after each (and, for comparison, from t = 0 only);
    the schedule config flown from hover to 10 m/s in 2 m/s setpoints (6 s), each stretch on the loop
    closed at the nearest schedule value (and on the trim's loop only). Errors against RK4 at 1/256 of
    the rows' period (a step that divides it); RK4 at its stable step beside."""
    import dataclasses
    from unittest import mock

    from quadctl import config, pipeline
    from quadctl.physics.trajectory import Reference
    from quadctl.schedule.envelope import schedule_of
    from quadctl.setup import setup_of
    from quadctl.sim.run import simulate

    def flight(name: str, speeds, start: float, duration: float):
        data = config.load(name).model_dump(exclude_none=True)
        data["simulation"].update(duration=duration, reference={"setpoints": [
            {"t": start + 0.5 * i if name == "forward" else start + i, "velocity": [v, 0.0, 0.0]}
            for i, v in enumerate(speeds)]})
        setup = setup_of(config.from_dict(data))
        stages = pipeline.Stages(setup)
        loop = stages.loop
        if setup.schedule is not None:
            sched = schedule_of(setup)
            loop = sched.flown_by(loop)
        return loop, setup.initial_state(loop.x_trim), setup.flown_reference, duration

    rows = []
    flights = [("forward, velocity setpoints at 0.5 and 1 s (1.5 s)", flight("forward", (2.0, 3.0), 0.5, 1.5),
                "graded from t = 0 only"),
               ("schedule config, 0 to 10 m/s in 2 m/s setpoints (6 s)",
                flight("schedule", (2.0, 4.0, 6.0, 8.0, 10.0), 1.0, 6.0), "on the trim's loop only")]
    for label, (loop, x0, ref, T), other in flights:
        truth = simulate(loop, x0, T, 0.005 / 256, reference=ref)

        def err(run, truth=truth):
            return f"{np.max(np.abs(run.x[-1] - truth.x[-1])):.1e}"

        def etd(lp=loop, x0=x0, ref=ref, T=T):
            return simulate(lp, x0, T, "auto", method="etdrk4", tolerance=1e-8, reference=ref)

        etd()  # compiled before timing
        cpu, run = cpu_best(etd, 5)
        rows.append([label, "ETDRK4, dt: auto, tolerance 1e-8", f"{run.steps:,}", f"{cpu * 1e3:.1f}", err(run)])
        if loop.schedule is None:  # the steps of the reference not graded for
            with mock.patch.object(Reference, "jumps", ()):
                cpu_o, alt = cpu_best(etd, 5)
        else:
            trim_only = dataclasses.replace(loop, schedule_jacobians=None)
            cpu_o, alt = cpu_best(lambda lp=trim_only: etd(lp), 5)
        rows.append(["", f"ETDRK4, {other}", f"{alt.steps:,}", f"{cpu_o * 1e3:.1f}", err(alt)])
        cpu_r, rk4 = cpu_best(lambda lp=loop, x0=x0, ref=ref, T=T: simulate(lp, x0, T, "auto", reference=ref), 3)
        rows.append(["", "RK4, dt: auto (its stable step)", f"{rk4.steps:,}", f"{cpu_r * 1e3:.1f}", err(rk4)])
    return table("ETDRK4 across the steps of a reference and a gain schedule",
                 ["flight", "method", "steps", "CPU (ms)", "final error"], rows) + (
        "\n\nCPU time of whole library calls, best of 5 (RK4: of 3). 'final error': largest final-state "
        "difference (state units) from RK4 at 1/256 of the reference rows' 5 ms period. RK4 at its stable "
        "step straddles the rows, so a setpoint acts at the next step's start.")


def stiff_sweep() -> str:
    """1000 random designs of the forward loops (benchmarks/random-1000.yaml) at dt: auto for the
    report's 10 s: ETDRK4 (each case on its own graded schedule, tolerance 1e-8) against RK4 (each at
    its stability-held step), the library on both cores, measured in the same run (one timed run
    each, after a warm-up that compiles both lane libraries)."""
    import dataclasses

    import yaml

    from quadctl import config, sweep

    cfg = config.load("forward")
    data = yaml.safe_load(SWEEP_FILE.read_text())
    rows = []
    for method in ("etdrk4", "rk4"):
        data["set"] = {"simulation.dt": "auto", "simulation.duration": STIFF_SWEEP_DURATION,
                       "simulation.method": method}
        spec = sweep.from_dict(data, cfg, SWEEP_FILE.name)
        sweep.run(cfg, dataclasses.replace(spec, samples=16), jobs=2)  # warm: imports, lane library
        wall, result = timed(lambda s=spec: sweep.run(cfg, s, jobs=2))
        steps = np.array([r["steps"] for r in result.rows])
        ok = sum(r["status"] == "ok" for r in result.rows)
        rows.append([f"quadctl sweep {method.upper()}, dt: auto, library, --jobs 2", f"{wall:.2f}",
                     f"{len(result.rows) / wall:,.0f}", f"{steps.mean():,.0f} ({steps.min():,} .. {steps.max():,})",
                     f"{result.stats['steps'] / wall / 1e6:.2f} M", f"{ok}"])
    speedup = float(rows[1][1]) / float(rows[0][1])
    return table(f"Stiff sweep: 1000 random designs of the forward loops, {STIFF_SWEEP_DURATION:g} s each at dt: auto "
                 "(benchmarks/random-1000.yaml's weights)",
                 ["run", "wall (s)", "cases/s", "steps per case (min .. max)", "steps/s", "ok"], rows) + (
        f"\n\nETDRK4 {speedup:.1f}x the cases/s of RK4 in the same run: each case on its own graded schedule "
        "(tolerance 1e-8), the φ-functions of the cases' linear parts computed together; RK4 at each case's "
        "stability-held step.")


# ---------------------------------------------------------------------------------------
# 2 and 3. The sweep and its designs


def the_flying_sweep(plain: list | None = None) -> str:
    """Sweep 2: 1000 random mambo-200hz designs, the configs that fly, in the same lanes, at two case
    lengths: 2 s (the file's, 2 000 steps) and the config's own 10 s (10 000 steps, as many as a plain
    case's). ``plain`` the plain sweep's ``[cfg, spec]`` (or None): each length is then also run
    alternately with it on both cores, and their ratio is of those runs (a slower spell of the machine
    then slows both, not one)."""
    import dataclasses

    from quadctl import config, sweep

    cfg = config.load("mambo-200hz")
    short = sweep.load(FLYING_SWEEP_FILE, cfg)
    cases = short.cases()
    assert len({c.values for c in cases}) == len(cases)  # no two alike
    # the same draws without the file's ``set: simulation.duration``: the config's own 10 s
    whole = dataclasses.replace(short, fixed=tuple(f for f in short.fixed if f[0] != "simulation.duration"))
    sweep.run(cfg, dataclasses.replace(short, samples=16), jobs=1)  # warm: imports, lane library
    rows, notes = [], []
    for spec in (short, whole):
        steps = None
        for jobs in (2, 1):
            wall, result = timed(lambda j=jobs, s=spec: sweep.run(cfg, s, jobs=j), repeat=REPEAT)
            st = result.stats
            steps = max(r["steps"] for r in result.rows)
            rows.append([f"quadctl sweep, library, --jobs {jobs}", f"{steps:,}", f"{wall:.2f}",
                         f"{st['steps'] / wall / 1e6:.2f} M", f"{len(result.rows) / wall:,.0f}",
                         f"{1e6 * st['design_cpu'] / st['designs']:.1f}", f"{st['fallbacks']}"])
            paths = {r["path"] for r in result.rows}
            notes.append(f"{steps:,} steps a case, --jobs {jobs}: rows by path {sorted(paths)}, "
                         f"backends {st['backend']}")
        if plain:
            notes.append(f"{steps:,} steps a case: " + against_plain(plain, (cfg, spec), ALTERNATED))
    subset = dataclasses.replace(short, samples=100)
    wall, slow = timed(lambda: sweep.run(cfg, subset, jobs=1, fast=False))
    st = slow.stats
    rows.append(["one case at a time (pipeline), --jobs 1, 100 cases", f"{st['steps'] // 100:,}", f"{wall:.2f}",
                 f"{st['steps'] / wall / 1e6:.2f} M", f"{100 / wall:,.0f}",
                 f"{1e6 * st['design_cpu'] / st['designs']:.1f}", "-"])
    return table(f"Sweep: 1000 random mambo-200hz designs, 2 s (2,000 RK4 steps) and 10 s (10,000) each "
                 f"(benchmarks/mambo-1000.yaml, and the same draws at the config's own duration: 200 Hz "
                 f"discrete design, rotors, LQI, noise; best of {REPEAT})",
                 ["run", "steps per case", "wall (s)", "simulated steps/s", "designs/s",
                  "µs CPU per subsystem design", "designs redone one by one"], rows) + "\n\n" + ";\n\n".join(notes)


def against_plain(plain: list, other: tuple, runs: int) -> str:
    """The note of ``other``'s (``(cfg, spec)``) simulated steps/s against the plain sweep's
    (``plain``) on both cores and on one, the best of ``runs`` runs of each, alternated so both see
    the same machine. On one core the ratio is of the cases' own costs; on two it also carries the
    worker processes' fixed cost (forking them, their first chunk's copied pages, ~30 ms a run),
    which weighs more on a shorter sweep."""
    from quadctl import sweep

    notes = []
    for jobs in (2, 1):
        best = [0.0, 0.0]
        for _ in range(runs):
            for k, (c, s) in enumerate((plain, other)):
                wall, result = timed(lambda c=c, s=s, j=jobs: sweep.run(c, s, jobs=j))
                best[k] = max(best[k], result.stats["steps"] / wall)
        where = "both cores" if jobs == 2 else "one core (--jobs 1)"
        notes.append(f"on {where}: {best[1] / 1e6:.2f} M / {best[0] / 1e6:.2f} M = {best[1] / best[0]:.2f}")
    return (f"simulated steps/s against the plain (forward) sweep's, best of {runs} runs of each, alternated, "
            + "; ".join(notes))


def the_mission_sweep(plain: list | None = None) -> str:
    """Sweep 2b: the square mission over its speed in the lanes (each case its own reference and
    feedforward, the tracking error summed in the lanes); with ``plain`` (the plain sweep's ``[cfg,
    spec]``) also alternated with it on both cores, for their ratio."""
    import dataclasses

    from quadctl import config, sweep

    cfg = config.load("square")
    spec = sweep.load(MISSION_SWEEP_FILE, cfg)
    sweep.run(cfg, dataclasses.replace(spec, samples=2), jobs=1)  # warm: imports, lane and map libraries
    rows, notes = [], []
    for jobs in (2, 1):
        wall, result = timed(lambda j=jobs: sweep.run(cfg, spec, jobs=j), repeat=3)
        st = result.stats
        passed = sum(r["pass"] for r in result.rows)
        rows.append([f"quadctl sweep, library, --jobs {jobs}", f"{wall:.2f}", f"{st['steps'] / wall / 1e6:.2f} M",
                     f"{len(result.rows) / wall:,.1f}", f"{st['steps'] / len(result.rows):,.0f}",
                     f"{passed} of {len(result.rows)}"])
    if plain:
        notes.append(against_plain(plain, (cfg, spec), ALTERNATED // 2))
    return table(f"Sweep: the square mission at {spec.count()} random speeds (benchmarks/square-speed.yaml: a "
                 "reference and its feedforward per case, gated on the tracking error; best of 3)",
                 ["run", "wall (s)", "simulated steps/s", "cases/s", "steps per case", "pass the gates"],
                 rows) + ("\n\n" + "; ".join(notes) if notes else "")


PID_REPEAT = 5
"""Runs of each law's sweep in :func:`the_pid_sweep`, alternated."""


def the_pid_sweep() -> str:
    """Sweep 2c: one grid of masses of the crazyflie config flown by the Crazyflie firmware's PID cascade
    (``controller.flies: pid``) and by the config's LQR design in the lanes, the two alternated ``PID_REPEAT``
    times on each core count, the best of each; their ratio of simulated steps/s. Each PID case also lifts its
    cascade about hover for its ``stable`` column, as ``simulate`` checks it, where an LQR case is designed."""
    from quadctl import sweep
    from quadctl.config import overrides
    from quadctl.config.loading import bundled

    source = bundled("crazyflie")
    laws = {"LQR": overrides.load(source), "PID": overrides.load(source, ["controller.flies=pid"])}
    specs = {name: sweep.load(PID_SWEEP_FILE, cfg) for name, cfg in laws.items()}
    for name, cfg in laws.items():  # warm: imports, each law's lane library
        sweep.run(cfg, specs[name], jobs=1)
    rows, ratios = [], []
    for jobs in (2, 1):
        best, last = {}, {}
        for _ in range(PID_REPEAT):
            for name, cfg in laws.items():
                wall, result = timed(lambda c=cfg, s=specs[name], j=jobs: sweep.run(c, s, jobs=j))
                rate = result.stats["steps"] / wall
                if rate > best.get(name, (0.0,))[0]:
                    best[name] = (rate, wall)
                last[name] = result
        for name in laws:
            st, (rate, wall) = last[name].stats, best[name]
            passed = sum(r["status"] == "ok" for r in last[name].rows)
            rows.append([f"{name}: quadctl sweep, library, --jobs {jobs}", f"{wall:.3f}", f"{rate / 1e6:.2f} M",
                         f"{len(last[name].rows) / wall:,.0f}", f"{st['steps'] / len(last[name].rows):,.0f}",
                         f"{passed} of {len(last[name].rows)}", ", ".join(st["backend"])])
        ratios.append(f"--jobs {jobs}: {best['PID'][0] / 1e6:.2f} M / {best['LQR'][0] / 1e6:.2f} M = "
                      f"{best['PID'][0] / best['LQR'][0]:.2f}")
    lift = _lift_cpu(laws["PID"])
    return table(f"Sweep: {specs['LQR'].count()} masses of the crazyflie config (benchmarks/crazyflie-mass.yaml), "
                 "the firmware's PID cascade (controller.flies: pid) against the LQR design, alternated, best of "
                 f"{PID_REPEAT}",
                 ["run", "wall (s)", "simulated steps/s", "cases/s", "steps per case", "status ok", "backend"],
                 rows) + ("\n\nThe PID sweep's simulated steps/s against the LQR sweep's (a PID case lifts its "
                          "cascade about hover for its stable column, an LQR case is designed): " + "; ".join(ratios)
                          + "\n\nThe cascade's lift, one case of the crazyflie config (quadctl.sim.cascade_lift."
                          f"lifted and its poles): {lift * 1e3:.2f} ms of CPU, best of {LIFT_REPEAT}")


LIFT_REPEAT = 20
"""Lifts timed in :func:`_lift_cpu`."""


def _lift_cpu(cfg) -> float:
    """s of CPU, best of :data:`LIFT_REPEAT`: the PID cascade of ``cfg`` linearized about hover and lifted to its
    frame, its poles computed (what a PID sweep case adds to judge its stability)."""
    from quadctl import pipeline
    from quadctl.setup import setup_of
    from quadctl.sim.cascade_lift import lifted

    loop = pipeline.Stages(setup_of(cfg)).pid_loop
    times = []
    for _ in range(LIFT_REPEAT + 1):  # the first warms: the law's Jacobians, built once per loop
        start = time.process_time()
        _ = lifted(loop).poles
        times.append(time.process_time() - start)
    return min(times[1:])


CEILING_CHUNK = 64
"""Cases a chunk of the hand-written C loop (:data:`CEILING_SOURCE`): 64 lanes, structure of arrays."""
CEILING_SOURCE = r"""
#include <math.h>
#define W 64
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
double sin(double) __attribute__((simd("notinbranch"), const, nothrow));
double cos(double) __attribute__((simd("notinbranch"), const, nothrow));
#endif
/* the forward closed loop, RK4, W cases a chunk (structure of arrays: state i of case l at x[i][l]),
   u = u0 - K (x - x0 - xr t); the model's equations written out (diagonal inertia, rotor drag).
   GAIN_TERMS (-D...): which K[j][i] the law reads, as X(j, i) in row-major order: every entry (the
   dense gain) or the loop's nonzeros only (the generated lanes' gain: a decoupled design's zeros
   are structural, quadctl.sim.builder masks them out) */
static void rhs(double x[12][W], const double K[4][12][W], const double* p, const double* u0,
                const double* xr0, const double* xr, double t, double f[12][W]) {
  const double m = p[0], g = p[1], jxx = p[2], jyy = p[3], jzz = p[4], kx = p[5], ky = p[6], kz = p[7];
  const double iyz = (jyy - jzz) / jxx, izx = (jzz - jxx) / jyy, ixy = (jxx - jyy) / jzz;
#pragma omp simd
  for (int l = 0; l < W; ++l) {
    double e[12], u[4];
    for (int i = 0; i < 12; ++i) e[i] = x[i][l] - xr0[i] - xr[i] * t;
    for (int j = 0; j < 4; ++j) u[j] = u0[j];
#define X(j, i) u[j] -= K[j][i][l] * e[i];
    GAIN_TERMS
#undef X
    double vu = x[3][l], vv = x[4][l], vw = x[5][l], ph = x[6][l], th = x[7][l], ps = x[8][l];
    double P = x[9][l], Q = x[10][l], R = x[11][l];
    double cph = cos(ph), sph = sin(ph), cth = cos(th), sth = sin(th), cps = cos(ps), sps = sin(ps);
    double r00 = cth * cps, r01 = cth * sps, r02 = -sth;
    double r10 = sph * sth * cps - cph * sps, r11 = sph * sth * sps + cph * cps, r12 = sph * cth;
    double r20 = cph * sth * cps + sph * sps, r21 = cph * sth * sps - sph * cps, r22 = cph * cth;
    double tm = u[0] / m, yp = (Q * sph + R * cph) / cth;
    f[0][l] = r00 * vu + r10 * vv + r20 * vw;
    f[1][l] = r01 * vu + r11 * vv + r21 * vw;
    f[2][l] = r02 * vu + r12 * vv + r22 * vw;
    f[3][l] = -tm * kx * vu + g * r02 - (Q * vw - R * vv);
    f[4][l] = -tm * ky * vv + g * r12 - (R * vu - P * vw);
    f[5][l] = -tm - tm * kz * vw + g * r22 - (P * vv - Q * vu);
    f[6][l] = P + yp * sth;
    f[7][l] = Q * cph - R * sph;
    f[8][l] = yp;
    f[9][l] = u[1] / jxx + iyz * Q * R;
    f[10][l] = u[2] / jyy + izx * R * P;
    f[11][l] = u[3] / jzz + ixy * P * Q;
  }
}

/* n cases (a multiple of W): K [n/W][4][12][W], x [n/W][12][W] (advanced in place) */
void ceiling(long n, const double* K, double* x, const double* p, const double* u0, const double* xr0,
             const double* xr, double dt, long steps) {
#pragma omp parallel for schedule(static)
  for (long c = 0; c < n / W; ++c) {
    double (*X)[W] = (double (*)[W])(x + c * 12 * W);
    const double (*KK)[12][W] = (const double (*)[12][W])(K + c * 48 * W);
    double k1[12][W], k2[12][W], k3[12][W], k4[12][W], y[12][W];
    for (long s = 0; s < steps; ++s) {
      double t = dt * (double)s;
      rhs(X, KK, p, u0, xr0, xr, t, k1);
      for (int i = 0; i < 12; ++i)
        for (int l = 0; l < W; ++l) y[i][l] = X[i][l] + 0.5 * dt * k1[i][l];
      rhs(y, KK, p, u0, xr0, xr, t + 0.5 * dt, k2);
      for (int i = 0; i < 12; ++i)
        for (int l = 0; l < W; ++l) y[i][l] = X[i][l] + 0.5 * dt * k2[i][l];
      rhs(y, KK, p, u0, xr0, xr, t + 0.5 * dt, k3);
      for (int i = 0; i < 12; ++i)
        for (int l = 0; l < W; ++l) y[i][l] = X[i][l] + dt * k3[i][l];
      rhs(y, KK, p, u0, xr0, xr, t + dt, k4);
      for (int i = 0; i < 12; ++i)
        for (int l = 0; l < W; ++l) X[i][l] += dt / 6.0 * (k1[i][l] + 2.0 * k2[i][l] + 2.0 * k3[i][l] + k4[i][l]);
    }
  }
}
"""
"""The machine's ceiling for the plain sweep (:func:`the_ceiling`): a hand-written structure-of-arrays
RK4 of the same 12-state closed loop, :data:`CEILING_CHUNK` cases a chunk (the lane loop vectorized,
sin and cos by glibc's vector math), OpenMP over the chunks. The benchmark's yardstick, compiled here
from this string: not quadctl's code (which generates its loops from the CasADi model)."""


def the_ceiling(cfg, spec, dense: bool = False) -> tuple:
    """(run, steps, what ran): ``run()`` runs :data:`CEILING_SOURCE` on the plain sweep's work (its
    cases' count rounded up to whole chunks, each its own gains: the forward design's scaled by up to
    +-10 %, its step and step count from benchmarks/random-1000.yaml) on both cores, ``steps`` in
    all; checked against quadctl's RK4 of the unscaled loop first (the same loop, or the ratio means
    nothing). The law reads the gain's structural nonzeros, as the lanes' generated code does
    (``dense``: all 48 entries, the 38 zeros of the decoupled design included: 25-40 % slower on
    the same work). Compiled with ``-ffp-contract=off`` as the lanes are (no fused multiply-add:
    the same roundings; it changes the ceiling's speed by about 1 %)."""
    import ctypes

    import yaml

    from quadctl import pipeline
    from quadctl.native.compile import MARCH  # the lanes' target: the same instructions on both sides
    from quadctl.setup import setup_of
    from quadctl.sim.run import simulate

    setup = setup_of(cfg)
    linear = pipeline.linear_of(setup, pipeline.trim_of(setup))
    loop = pipeline.loop_of(setup, linear, pipeline.design_of(setup, pipeline.decoupled_of(setup, linear), linear))
    fixed = yaml.safe_load(SWEEP_FILE.read_text())["set"]
    dt = float(fixed["simulation.dt"])
    steps = round(float(fixed["simulation.duration"]) / dt)
    n = -(-spec.count() // CEILING_CHUNK) * CEILING_CHUNK
    with tempfile.TemporaryDirectory() as tmp:
        src, lib = Path(tmp) / "ceiling.c", Path(tmp) / "ceiling.so"
        src.write_text(CEILING_SOURCE)
        pattern = np.ones((4, 12), dtype=bool) if dense else \
            np.reshape(np.asarray(loop.spec().pattern, dtype=bool), (4, 12), order="F")
        terms = " ".join(f"X({j}, {i})" for j, i in zip(*np.nonzero(pattern)))
        base = ["cc", "-O3", MARCH, "-ffp-contract=off", "-fno-math-errno", "-fno-builtin-sin",
                "-fno-builtin-cos", f"-DGAIN_TERMS={terms}", "-fPIC", "-shared", str(src), "-o", str(lib), "-lm"]
        threads = "OpenMP, 2 threads"
        if subprocess.run([*base[:1], "-fopenmp", *base[1:]], capture_output=True).returncode != 0:
            subprocess.run([*base[:1], "-fopenmp-simd", *base[1:]], check=True, capture_output=True)
            threads = "one thread (no OpenMP)"
        os.environ.setdefault("OMP_NUM_THREADS", "2")  # read when OpenMP loads: both cores
        ceiling = ctypes.CDLL(str(lib)).ceiling
    ptr = ctypes.c_void_p
    ceiling.argtypes = [ctypes.c_long, ptr, ptr, ptr, ptr, ptr, ptr, ctypes.c_double, ctypes.c_long]
    ceiling.restype = None
    rng = np.random.default_rng(1)
    scale = 1.0 + 0.1 * rng.uniform(-1, 1, size=n)
    scale[0] = 1.0
    K = np.asarray(loop.K)[None] * scale[:, None, None]
    K = np.ascontiguousarray(K.reshape(n // CEILING_CHUNK, CEILING_CHUNK, 4, 12).transpose(0, 2, 3, 1))
    x0 = setup.initial_state(loop.x_trim)
    consts = [np.ascontiguousarray(np.asarray(v, dtype=float).ravel()) for v in
              (loop.params, loop.u_trim, loop.x_trim, loop.x_rate)]

    def run(m=steps):
        x = np.ascontiguousarray(np.broadcast_to(x0[None, :, None], (n // CEILING_CHUNK, 12, CEILING_CHUNK)))
        ceiling(n, K.ctypes.data, x.ctypes.data, *(c.ctypes.data for c in consts), dt, m)
        return x

    check = simulate(loop, x0, dt * 2000, dt).x[-1]
    err = float(np.abs(run(2000)[0, :, 0] - check).max())
    if err > 1e-8:
        raise AssertionError(f"the C ceiling's loop differs from quadctl's by {err:.2e} after 2000 steps")
    gain = "dense gain" if dense else f"the gain's {int(pattern.sum())} nonzeros"
    return run, n * steps, f"{n} cases x {steps:,} steps, {CEILING_CHUNK} a chunk, {gain}, {threads}"


def against_ceiling(cfg, spec, runs: int) -> tuple[list, float]:
    """([(a ceiling's steps/s, its steps, what it ran)] for the ceiling and its dense-gain variant, the
    library sweep's steps/s on both cores): each the best of ``runs``, alternated so all see the same
    machine."""
    from quadctl import sweep

    ceilings = [the_ceiling(cfg, spec), the_ceiling(cfg, spec, dense=True)]
    best = [0.0] * (len(ceilings) + 1)
    for _ in range(runs):
        for k, (run_ceiling, ceiling_steps, _) in enumerate(ceilings):
            best[k] = max(best[k], ceiling_steps / timed(run_ceiling)[0])
        wall, result = timed(lambda: sweep.run(cfg, spec, jobs=2))
        best[-1] = max(best[-1], result.stats["steps"] / wall)
    return [(rate, steps, what) for rate, (_, steps, what) in zip(best, ceilings)], best[-1]


def the_sweep() -> tuple[str, list]:
    """Sweep 1: 1000 random designs of the forward config; (text, [cfg, spec])."""
    import dataclasses

    from quadctl import config, sweep
    from quadctl.native.compile import MARCH

    cfg = config.load("forward")
    spec = sweep.load(SWEEP_FILE, cfg)
    cases = spec.cases()
    assert len({c.values for c in cases}) == len(cases)  # no two alike
    sweep.run(cfg, dataclasses.replace(spec, samples=16), jobs=1)  # warm: imports, lane library
    rows = []
    results = {}
    for jobs in (2, 1):
        wall, result = timed(lambda j=jobs: sweep.run(cfg, spec, jobs=j), repeat=REPEAT)
        results[jobs] = result
        steps = result.stats["steps"]
        rows.append([f"quadctl sweep, library, --jobs {jobs}", f"{wall:.2f}", f"{steps / wall / 1e6:.2f} M",
                     f"{len(result.rows) / wall:,.0f}", f"{result.stats['steps'] / len(result.rows):,.0f}"])
    steps = results[2].stats["steps"]
    ceilings, library = against_ceiling(cfg, spec, ALTERNATED // 2)
    for k, (rate, ceiling_steps, what) in enumerate(ceilings):
        rows.append([f"hand-written C RK4 of the same loop ({what})" + (": the machine's ceiling" if k == 0 else ""),
                     f"{ceiling_steps / rate:.2f}", f"{rate / 1e6:.2f} M", "-", "10,000"])
    ceiling, dense = ceilings[0][0], ceilings[1][0]
    # the CLI from a fresh process: --no-plot (the tables, sweep.csv and sweep.json: what CI runs), and
    # as it runs by default, with the trade-off figure (sweep.png, matplotlib)
    for label, extra in (("--no-plot", ["--no-plot"]), ("with its figure", [])):
        with tempfile.TemporaryDirectory() as tmp:
            cmd = [sys.executable, "-m", "quadctl", "sweep", "-c", "forward", "-s", str(SWEEP_FILE), "-o", tmp,
                   "-j", "2", *extra]
            wall, proc = timed(lambda c=cmd: subprocess.run(c, capture_output=True, text=True), repeat=REPEAT)
            if proc.returncode not in (0, 1):
                raise RuntimeError(proc.stderr)
        rows.append([f"quadctl sweep {label}, CLI end to end, -j 2", f"{wall:.2f}", f"{steps / wall / 1e6:.2f} M",
                     f"{1000 / wall:,.0f}", "(same cases)"])
    # the obvious alternative: each case through the pipeline, one at a time (trim, linearization,
    # quadctl.design per subsystem, the compiled scalar loop, metrics.summarize), on the first 100 cases
    subset = dataclasses.replace(spec, samples=100)
    wall, slow = timed(lambda: sweep.run(cfg, subset, jobs=1, fast=False))
    rows.append(["one case at a time (pipeline), --jobs 1, 100 cases", f"{wall:.2f}",
                 f"{slow.stats['steps'] / wall / 1e6:.2f} M", f"{100 / wall:,.0f}", "10,000"])
    text = table(f"Sweep: 1000 random designs x 10,000 RK4 steps (benchmarks/random-1000.yaml; best of {REPEAT})",
                 ["run", "wall (s)", "simulated steps/s", "designs/s", "steps per case"], rows)
    text += (f"\n\nThe library sweep on both cores at {library / 1e6:.2f} M / {ceiling / 1e6:.2f} M = "
             f"{library / ceiling:.2f} of the hand-written C ceiling's simulated steps/s ({library / dense:.2f} of "
             f"the dense-gain variant's {dense / 1e6:.2f} M), best of "
             f"{ALTERNATED // 2} runs of each, alternated (benchmarks/bench.py CEILING_SOURCE: the same loop's "
             f"RK4 and nothing else, no design, metrics or records; compiled here with -O3 {MARCH} "
             "-ffp-contract=off and OpenMP).")
    for jobs, result in results.items():
        st = result.stats
        text += (f"\n\n--jobs {jobs}: the design stage (stacking, batched Riccati solves, fallbacks) took "
                 f"{1e6 * st['design_cpu'] / st['designs']:.1f} µs of CPU time per subsystem design "
                 f"({1e6 * st['design_time'] / st['designs']:.1f} µs of wall time in its worker; "
                 f"{st['designs']} designs, {st['fallbacks']} redone one by one).")
    return text, [cfg, spec]


def the_designs(cfg, spec) -> str:
    import scipy.linalg

    from quadctl import pipeline, sweep
    from quadctl.design.riccati import care_batch
    from quadctl.setup import setup_of

    # the 4000 subsystem problems of the sweep: the report's plant, each case's weights
    base = cfg.model_dump(mode="json")
    problems: dict[tuple, list] = {}
    setup = setup_of(cfg)
    linear = pipeline.linear_of(setup, pipeline.trim_of(setup))
    dec = pipeline.decoupled_of(setup, linear)
    for case in spec.cases():
        data = base
        for p, value in zip(spec.parameters, case.values):
            data = sweep.assign(data, p.keys, value)
        for name, (Q, R) in setup_of(config_from(data)).weights.items():
            sub = dec[name]
            problems.setdefault(sub.B.shape, []).append((sub.A, sub.B, np.atleast_2d(Q), np.atleast_2d(R)))
    n = sum(len(v) for v in problems.values())
    stacks = {shape: [np.stack([p[k] for p in group]) for k in range(4)] for shape, group in problems.items()}

    def batched():
        return [care_batch(*stack) for stack in stacks.values()]

    def loop():
        out = []
        for group in problems.values():
            for A, B, Q, R in group:
                P = scipy.linalg.solve_continuous_are(A, B, Q, R)
                out.append(np.linalg.solve(R, B.T @ P))
        return out

    fast, results = timed(batched, repeat=3)
    assert all(r.ok.all() for r in results)
    slow, _ = timed(loop)
    rows = [["quadctl care_batch (batched, residual-checked)", f"{1e6 * fast / n:.1f}", f"{n / fast:,.0f}", "1"],
            ["Python loop over scipy solve_continuous_are", f"{1e6 * slow / n:.1f}", f"{n / slow:,.0f}",
             f"{slow / fast:.0f}"]]
    return table(f"LQR designs: the sweep's {n} subsystem problems (2- and 3-state, one input)",
                 ["solver", "µs per design", "designs/s", "time / quadctl"], rows)


# ---------------------------------------------------------------------------------------
# 4 and 5. The Riccati solvers alone

LQR_SIZES = (10, 50, 100, 200)
"""States of the random problems of :func:`lqr_sizes` (inputs: n / 5)."""
LQR_SEED = 2024


def lqr_sizes() -> str:
    import scipy.linalg

    from quadctl.design import lqr, riccati_residual

    rng = np.random.default_rng(LQR_SEED)
    rows = []
    for n in LQR_SIZES:
        m = max(1, n // 5)
        # random A (spectral radius ~1, about half its modes unstable), B: stabilizable almost surely
        A, B, Q, R = rng.normal(size=(n, n)) / np.sqrt(n), rng.normal(size=(n, m)), np.eye(n), np.eye(m)
        repeat = 20 if n <= 50 else 5
        problem = (A, B, Q, R)
        lqr(*problem)  # loads SciPy (above 7 states lqr uses its Schur decomposition)
        ours, res = timed(lambda p=problem: lqr(*p), repeat=repeat)
        theirs, P = timed(lambda p=problem: scipy.linalg.solve_continuous_are(*p), repeat=repeat)
        rows.append([f"{n} x {m}", f"{1e3 * ours:.2f}", f"{1e3 * theirs:.2f}", f"{theirs / ours:.2f}",
                     f"{res.residual:.0e}", f"{riccati_residual(A, B, Q, R, P):.0e}"])
    return table(f"quadctl.design.lqr against scipy.linalg.solve_continuous_are (random problems, seed {LQR_SEED}; "
                 "best wall time of 5-20)",
                 ["n x m", "lqr (ms)", "SciPy (ms)", "SciPy / lqr", "lqr residual", "SciPy residual"], rows) + (
        "\n\nlqr's time includes what SciPy's does not do: the weight checks, the gain, the closed-loop "
        "eigenvalues and the residual that certifies the answer. Both call multi-threaded BLAS: on a shared "
        "2-core machine run these rows with OPENBLAS_NUM_THREADS=1, or threads contending with other "
        "processes spread them 3-10x from run to run.")


def discrete_designs(count: int = 1000, rate: float = 200.0) -> str:
    import scipy.linalg

    from quadctl import config, pipeline
    from quadctl.design import discrete
    from quadctl.design.riccati import dare_batch
    from quadctl.setup import setup_of

    setup = setup_of(config.load("forward"))
    dec = pipeline.decoupled_of(setup, pipeline.linear_of(setup, pipeline.trim_of(setup)))
    rng = np.random.default_rng(LQR_SEED)
    subs = [dec["roll"], dec["pitch"]]
    A = np.stack([subs[k % 2].A for k in range(count)])
    B = np.stack([subs[k % 2].B for k in range(count)])
    Q = np.stack([np.diag(10 ** rng.uniform(-1, 2, 3)) for _ in range(count)])
    R = 10 ** rng.uniform(-1, 1, (count, 1, 1))
    Ts = 1 / rate

    def cpu(fn, repeat):
        best, out = np.inf, None
        for _ in range(repeat):
            start = time.process_time()
            out = fn()
            best = min(best, time.process_time() - start)
        return best, out

    def batched():
        Ad, Bd, Qd, Rd, Nd = discrete.lqrd_weights_batch(A, B, Q, R, Ts)
        return dare_batch(Ad, Bd, Qd, Rd, Nd)

    weights_time, (Ad, Bd, Qd, Rd, Nd) = cpu(lambda: discrete.lqrd_weights_batch(A, B, Q, R, Ts), 5)
    dare_time, _ = cpu(lambda: dare_batch(Ad, Bd, Qd, Rd, Nd), 5)
    design_time, res = cpu(batched, 5)
    assert res.ok.all()

    def scipy_loop():
        for k in range(count):
            P = scipy.linalg.solve_discrete_are(Ad[k], Bd[k], Qd[k], Rd[k], s=Nd[k])
            np.linalg.solve(Rd[k] + Bd[k].T @ P @ Bd[k], Bd[k].T @ P @ Ad[k] + Nd[k].T)

    loop_time, _ = cpu(scipy_loop, 1)
    one_time, _ = cpu(lambda: [discrete.lqrd(A[k], B[k], Q[k], R[k], Ts) for k in range(100)], 1)
    rows = [["lqrd_weights_batch + dare_batch (the whole design)", f"{1e6 * design_time / count:.1f}", "1"],
            ["  of which lqrd_weights_batch (Van Loan, batched expm)", f"{1e6 * weights_time / count:.1f}", ""],
            ["  of which dare_batch (doubling, Newton-Hewer, checks)", f"{1e6 * dare_time / count:.1f}", ""],
            ["loop over scipy solve_discrete_are (+ gain), same weights", f"{1e6 * loop_time / count:.1f}",
             f"{loop_time / design_time:.0f}"],
            ["loop over quadctl.design.discrete.lqrd (one case, first 100)", f"{1e6 * one_time / 100:.1f}",
             f"{one_time / 100 * count / design_time:.0f}"]]
    return table(f"Discrete LQR designs: {count} 3-state subsystems (roll and pitch of the forward config, random "
                 f"weights) at {rate:g} Hz; CPU time, best of 5 (loops: one run)",
                 ["solver", "µs CPU per design", "time / batched"], rows)


SECTIONS = ("simulation", "stiff", "sweep", "flying-sweep", "mission-sweep", "pid-sweep", "designs", "lqr",
            "discrete", "figures", "schedule", "identify")
"""What ``--only`` may name: the numbered sections of the module docstring (the designs are the
plain sweep's)."""


# ---------------------------------------------------------------------------------------
# 6. Figures


def figures(cli_python: str) -> str:
    """`quadctl run --plot` end to end against `quadctl run`, the figures in the library, the sweep's figure."""
    from quadctl import config, plots, sweep
    from quadctl.sweep.outputs import tradeoff_png
    from quadctl.workspace import Workspace

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        run = [cli_python, "-m", "quadctl", "run", "-c", "forward", "-o", str(Path(tmp) / "run")]
        subprocess.run([*run, "--plot"], check=True, capture_output=True)  # the stages' artifacts, warm caches
        for name, cmd, repeat in (("quadctl run --plot, CLI end to end (stage artifacts reused)", [*run, "--plot"],
                                   REPEAT),
                                  ("quadctl run, CLI end to end (stage artifacts reused)", run, REPEAT),  # no figure
                                  ("quadctl run --plot --fresh, CLI end to end", [*run, "--plot", "--fresh"], 3),
                                  ("quadctl run --fresh, CLI end to end", [*run, "--fresh"], 3)):
            wall, _ = timed(lambda c=cmd: subprocess.run(c, check=True, capture_output=True), repeat=repeat)
            rows.append([name, f"{wall:.3f}", f"best of {repeat}"])
        with Workspace(config.load("forward"), Path(tmp) / "run") as ws:
            sim, setup, u_trim = ws.simulation.sim, ws.setup, ws.linear.u_trim

        def draw():
            return [plots.png_bytes(fig) for fig in plots.simulation_figures(
                sim, setup.partition, u_trim, title=setup.name, actuators=setup.actuators).values()]

        wall, pngs = timed(draw, repeat=REPEAT)
        rows.append([f"the {len(pngs)} figures of that run, drawn to PNG, library",
                     f"{wall:.3f}", f"best of {REPEAT}"])
    cfg = config.load("forward")
    result = sweep.run(cfg, sweep.load(SWEEP_FILE, cfg), jobs=2)
    wall, _ = timed(lambda: tradeoff_png(result, cfg), repeat=REPEAT)
    rows.append([f"the sweep's figure (sweep.png), {len(result.rows)} cases, library", f"{wall:.3f}",
                 f"best of {REPEAT}"])
    return table(f"Figures: the forward config ({len(sim.t):,} samples a time series)",
                 ["run", "wall (s)", "runs"], rows)


# ---------------------------------------------------------------------------------------
# 7. A gain schedule


SCHEDULE_POINTS = 50
SCHEDULE_TOP = 10.0  # m/s


def the_schedule(cli_python: str) -> str:
    """A 50-point schedule: the library, the command line end to end, and point by point."""
    from quadctl import config, pipeline
    from quadctl.design import linear_loop
    from quadctl.errors import TrimError
    from quadctl.schedule.envelope import fine_values, point_setup, schedule_of
    from quadctl.setup import setup_of

    values = np.linspace(0.0, SCHEDULE_TOP, SCHEDULE_POINTS).round(6).tolist()
    rows = []
    for name in ("schedule", "mambo-200hz"):
        data = config.load(name).model_dump()
        data["schedule"] = {"variable": "speed", "values": values, "interpolation": "linear", "check": 4}
        setup = setup_of(config.from_dict(data, name))
        wall, sched = timed(lambda s=setup: schedule_of(s), repeat=REPEAT)
        kind = "discrete 200 Hz, LQI" if sched.sample_time else "continuous"
        rows.append([f"{name} ({kind}): schedule_of, library", f"{wall:.3f}", f"best of {REPEAT}",
                     f"{len(sched.checks.values)} loops, passed {sched.passed}"])

        def one_by_one(s=setup, sched=sched):  # the pipeline a point at a time, the checks' loops one by one
            for v in values:
                _ = pipeline.Stages(point_setup(s, v)).design
            Ts = sched.sample_time
            for v, G in zip(sched.checks.values, sched.table.at(sched.checks.values)):
                try:
                    stages = pipeline.Stages(point_setup(s, v))
                    A = linear_loop.matrix(stages.linear.A, stages.linear.B, G[:, :12], G[:, 12:],
                                           sched.integral_states, Ts)
                    np.linalg.eigvals(A)
                except TrimError:
                    pass

        from threadpoolctl import threadpool_limits

        with threadpool_limits(1):  # as schedule_of runs (BLAS threads cost far more on these small matrices)
            loop_wall, _ = timed(one_by_one)
        rows.append([f"  the same point by point (pipeline.Stages, {len(fine_values(values, 4))} trims, one thread)",
                     f"{loop_wall:.3f}", "one run", f"{loop_wall / wall:.0f}x the library"])
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [cli_python, "-m", "quadctl", "schedule", "-c", "schedule", "-o", str(Path(tmp) / "run"),
               "--set", f"schedule.values={values}"]
        wall, _ = timed(lambda: subprocess.run(cmd, check=True, capture_output=True), repeat=3)
        rows.append(["quadctl schedule -c schedule (50 values), CLI end to end", f"{wall:.3f}", "best of 3", ""])
        wall, _ = timed(lambda: subprocess.run([*cmd, "--plot"], check=True, capture_output=True), repeat=3)
        rows.append(["  the same with --plot (the envelope figure)", f"{wall:.3f}", "best of 3", ""])
    return table(f"A {SCHEDULE_POINTS}-point gain schedule over speed 0-{SCHEDULE_TOP:g} m/s, frozen-point checks on a "
                 "4x finer grid", ["run", "wall (s)", "runs", "note"], rows)


def identification(cli_python: str) -> str:
    """Section 8: ``quadctl identify`` on the real logs, CPU time of whole library calls, best of 3."""
    from quadctl import config
    from quadctl.identify import readers, results

    flights = HERE.parent / "tests" / "data" / "crazyflie-flights"
    cfg = config.load("crazyflie")
    rows = []
    for label, names, delay in (("log10 (50 s at 1 kHz): read and identified", ["log10"], False),
                                ("log10 with a pure delay", ["log10"], True),
                                ("log10 and log15 (112 s): thrust, then Ixx and Iyy", ["log10", "log15"], False)):
        def run(names=names, delay=delay):
            logs = [readers.read_log(flights / n) for n in names]
            return results.identify(logs, cfg, delay=delay)

        cpu, ident = cpu_best(run, 3)
        tm = ident.fits["thrust"].value("T_m")
        rows.append([label, f"{cpu:.2f}", ", ".join(ident.fits), f"{tm * 1e3:.1f}"])
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [cli_python, "-m", "quadctl", "identify", str(flights / "log10"), "-c", "crazyflie", "-o", tmp]
        cpu = child_cpu_best(lambda: subprocess.run(cmd, check=True, capture_output=True), 3)
        rows.append(["quadctl identify log10 -c crazyflie, CLI end to end (figure included)", f"{cpu:.2f}",
                     "thrust", ""])
    return table("Identification from real Crazyflie flights (CPU time, best of 3)",
                 ["run", "CPU (s)", "stages", "T_m (ms)"], rows)


def config_from(data):
    from quadctl import config

    return config.from_dict(data, "bench")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-slow", action="store_true", help="skip the RK45 runs (about 7 s each)")
    parser.add_argument("--cli-python", default=sys.executable, metavar="PYTHON",
                        help="interpreter for the command-line runs (default: this one), e.g. a venv's python "
                             "with quadctl installed the way users install it (not editable)")
    parser.add_argument("--only", nargs="+", choices=SECTIONS, metavar="SECTION",
                        help=f"run only these sections: {', '.join(SECTIONS)} (default: all)")
    args = parser.parse_args()
    only = set(args.only or SECTIONS)
    import casadi

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"quadctl benchmarks on {cpu_name()}, {os.cpu_count()} cores; Python {platform.python_version()}, "
          f"numpy {np.__version__}, casadi {casadi.__version__}; load average {load:.2f} at start")
    if os.environ.pop("PYTHONDONTWRITEBYTECODE", None) is not None:
        # an installed quadctl runs from compiled modules (pip compiles them at install); without them
        # each command-line run would compile every module it imports again (~0.3 s)
        print("PYTHONDONTWRITEBYTECODE is unset for the command-line runs: they run from compiled modules, "
              "as an installed quadctl does")
    if "simulation" in only:
        print(one_simulation(args.skip_slow, args.cli_python))
    if "stiff" in only:
        print(stiff_simulation(args.cli_python))
        print(stiff_references())
        print(stiff_sweep())
    cfg_spec = None
    if "sweep" in only:
        text, cfg_spec = the_sweep()
        print(text)
    if "flying-sweep" in only:
        print(the_flying_sweep(cfg_spec))
    if "mission-sweep" in only:
        print(the_mission_sweep(cfg_spec))
    if "pid-sweep" in only:
        print(the_pid_sweep())
    if "designs" in only:
        if cfg_spec is None:
            from quadctl import config, sweep

            cfg = config.load("forward")
            cfg_spec = [cfg, sweep.load(SWEEP_FILE, cfg)]
        print(the_designs(*cfg_spec))
    if "lqr" in only:
        print(lqr_sizes())
    if "discrete" in only:
        print(discrete_designs())
    if "figures" in only:
        print(figures(args.cli_python))
    if "schedule" in only:
        print(the_schedule(args.cli_python))
    if "identify" in only:
        print(identification(args.cli_python))
    end = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"\nload average {end:.2f} at the end (2 cores: above ~0.3, other work shared the machine)")


if __name__ == "__main__":
    main()
