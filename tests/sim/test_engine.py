"""The simulation engine: one closed-loop definition, every runner agreeing with every other.

For each loop feature (rate and hold, motors and box saturation, integrators with conditional
integration, noise, rotor lag, delay): the compiled one-case loop against CasADi's virtual machine, and the SIMD
lanes against the one-case loop, to 1e-12 (of each quantity's size for the lanes: _solve.LANE_RTOL). Then the
machine: a missing or failing compiler, the compile cache, threads.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from _solve import LANE_RTOL, cfg_dict, lane_gap, lanes_and_one_case_runs, solve

from quadctl import pipeline
from quadctl.native import compile as compile_mod
from quadctl.sim import engine
from quadctl.sim.run import simulate


def _features():
    """(label, config dict, duration s): one loop per feature the builder has."""
    box = cfg_dict("hover", limits={"T": [0.0, 1.5], "A": [-0.05, 0.05]})  # A clips, T does not
    box["lqr"]["altitude"] = {"Q": [50.0, 1.0, 20.0], "R": [1.0], "integral": ["pD"]}
    box["simulation"]["initial_offset"] = {"pD": 0.05, "phi": 0.1}
    box["simulation"]["noise"] = {"seed": 4, "force": [0.01, 0.01, 0.01], "sensor": {"phi": 0.01}}
    held = cfg_dict("mambo-200hz")
    held["simulation"]["initial_offset"] = {"pD": 0.5, "phi": 0.4, "theta": 0.1}  # the rotors saturate
    emulated = cfg_dict("forward", controller={"rate": 2000.0, "design": "continuous"})
    lagged = cfg_dict("mambo-200hz")
    lagged["simulation"]["initial_offset"] = {"pD": 0.5, "phi": 0.4, "theta": 0.1}
    lagged["motors"]["time_constant"] = 0.03
    delayed = cfg_dict("mambo-200hz", controller={"rate": 200.0, "delay": {"samples": 2}})
    delayed["simulation"]["initial_offset"] = {"pD": 0.5, "phi": 0.4, "theta": 0.1}
    delayed["motors"]["time_constant"] = 0.03
    lagged_continuous = cfg_dict("hover", motors={"time_constant": 0.02})
    lagged_continuous["simulation"]["initial_offset"] = {"phi": 0.02}
    included = cfg_dict("mambo-200hz", controller={"rate": 200.0, "rotor_lag": "include"})
    included["simulation"]["initial_offset"] = {"pD": 0.5, "phi": 0.4, "theta": 0.1}
    included["motors"]["time_constant"] = 0.03
    included_continuous = cfg_dict("hover", motors={"time_constant": 0.02}, controller={"rotor_lag": "include"})
    included_continuous["simulation"]["initial_offset"] = {"phi": 0.02}
    included_delayed = cfg_dict("mambo-200hz", controller={"rate": 200.0, "rotor_lag": "include",
                                                            "delay": {"samples": 1}})
    included_delayed["simulation"]["initial_offset"] = {"pD": 0.2, "phi": 0.2}
    included_delayed["motors"]["time_constant"] = 0.03
    return [("continuous", cfg_dict("forward"), 0.02),
            ("continuous, box limits, LQI, noise", box, 0.02),
            ("held, rotors, LQI, noise", held, 0.5),
            ("held, emulated continuous design", emulated, 0.05),
            ("held, rotors with lag, LQI, noise", lagged, 0.5),
            ("continuous, rotors with lag", lagged_continuous, 0.02),
            ("held, delay, rotors with lag, LQI, noise", delayed, 0.5),
            ("held, rotors with lag included in the design, LQI, noise", included, 0.5),
            ("continuous, rotor lag included in the design", included_continuous, 0.02),
            ("held, rotor lag included, one sample of delay, LQI, noise", included_delayed, 0.5)]


FEATURES = _features()
COVERED = ("held, rotors with lag, LQI, noise", "held, rotors with lag included in the design, LQI, noise",
           "continuous, rotors with lag")
"""Features whose loops the default run flies inside another feature's (with a delay, or with the lag
in the design too): their compiled and lane runs repeat with the slow tests."""
RUNS = [pytest.param(*f, id=f[0], marks=[pytest.mark.slow] if f[0] in COVERED else []) for f in FEATURES]


def _loop(data):
    setup, trim, linear, _, des = solve(data)
    return setup, pipeline.loop_of(setup, linear, des)


@pytest.mark.parametrize("label, data, duration", FEATURES, ids=[f[0] for f in FEATURES])
def test_a_loops_gains_written_into_another_loops_constants_give_its_constants(label, data, duration):
    """A sweep builds each case's constants from its structure's (fill_constants of the case's
    gain_constants): the gains must be all that differs between two loops of one structure."""
    from dataclasses import replace

    from quadctl.sim.loop_layout import fill_constants, fill_constants_stack

    _, loop = _loop(data)
    rng = np.random.default_rng(7)
    other = replace(loop, K=rng.standard_normal(loop.K.shape),
                    Ki=None if loop.Ki is None else rng.standard_normal(np.shape(loop.Ki)),
                    Kv=None if loop.Kv is None else rng.standard_normal(loop.Kv.shape))
    Ts = 1.0 / loop.rate if loop.rate else None
    got = fill_constants(loop.constants(Ts).copy(), *other.constant_layout, **other.gain_constants())
    assert not np.array_equal(loop.constants(Ts), other.constants(Ts))
    assert np.array_equal(got, other.constants(Ts))
    # a chunk's cases at once (fill_constants_stack): each row is that case's constants
    others = [other, *(replace(loop, K=rng.standard_normal(loop.K.shape),
                               Ki=None if loop.Ki is None else rng.standard_normal(np.shape(loop.Ki)),
                               Kv=None if loop.Kv is None else rng.standard_normal(loop.Kv.shape)) for _ in range(2))]
    gains = [o.gain_constants() for o in others]
    stacked = fill_constants_stack(np.repeat(loop.constants(Ts)[None], 3, axis=0), *loop.constant_layout,
                                   **{name: np.stack([g[name] for g in gains]) for name in gains[0]})
    for row, o in zip(stacked, others):
        assert np.array_equal(row, o.constants(Ts))


def _clear():
    engine.runner.cache_clear()


@pytest.mark.compiler
@pytest.mark.parametrize("label, data, duration", RUNS)
def test_compiled_and_interpreted_loops_agree(label, data, duration, monkeypatch):
    setup, loop = _loop(data)
    x0 = setup.initial_state(loop.x_trim)
    compiled = simulate(loop, x0, duration, setup.dt, noise=setup.noise)
    monkeypatch.setenv("QUADCTL_NO_COMPILE", "1")
    _clear()
    try:
        with pytest.warns(engine.CompilerNotice, match="no C compiler found"):
            interpreted = simulate(loop, x0, duration, setup.dt, noise=setup.noise)
    finally:
        _clear()
    assert compiled.backend == "compiled" and interpreted.backend == "casadi"
    diff = max(np.abs(compiled.x - interpreted.x).max(), np.abs(compiled.u - interpreted.u).max(),
               np.abs(compiled.z - interpreted.z).max() if compiled.z.size else 0.0,
               np.abs(compiled.rotor_thrust - interpreted.rotor_thrust).max() if compiled.rotor_thrust.size else 0.0,
               np.abs(compiled.lag_model - interpreted.lag_model).max() if compiled.lag_model.size else 0.0)
    assert diff < 1e-12, f"Max diff is {diff:.4E}"
    assert compiled.steps == interpreted.steps and len(compiled.t) == len(interpreted.t)
    if "LQI" in label:
        assert compiled.z.shape[1] == 1 and np.any(compiled.z != 0)
    if "box" in label:
        assert np.abs(compiled.u[:, 1]).max() == pytest.approx(0.05)  # the box clipped A
    if "rotors" in label:
        commands = loop.actuators.commands(compiled.u)
        assert commands.max() == pytest.approx(loop.actuators.hi[0])  # a rotor at its limit
    if "delay" in label:  # the applied input is the command of n samples before (trim at first)
        n = loop.spec().delay
        assert n == (1 if "one sample" in label else 2)
        first = n * round(0.005 / compiled.dt)  # steps of the first n samples
        np.testing.assert_array_equal(compiled.u[:first], np.tile(loop.u_trim, (first, 1)))
        assert np.any(compiled.u[first] != loop.u_trim)
    if "included" in label:  # the controller's lag model moves with the commands
        assert compiled.lag_model.shape == (len(compiled.t), 4) and np.ptp(compiled.lag_model) > 1e-3
    if "lag" in label:  # the rotor states move, and stay below the command they follow
        assert compiled.rotor_thrust.shape == (len(compiled.t), 4)
        assert np.ptp(compiled.rotor_thrust) > 1e-3 and compiled.rotor_thrust.max() < loop.actuators.hi[0]


@pytest.mark.compiler
@pytest.mark.parametrize("label, data, duration", RUNS)
def test_lanes_equal_the_one_case_loop(label, data, duration):
    """Eight lanes with different gains, steps and seeds, each against its own one-case run."""
    from dataclasses import replace


    setup, loop = _loop(data)
    variants = []
    for k in range(11):  # more than one group of 8 lanes, the last group padded
        scale = 1.0 + 0.05 * k
        vk = replace(loop, K=loop.K * scale, Ki=None if loop.Ki is None else loop.Ki * scale)
        noise = None if setup.noise is None else replace(setup.noise, seed=setup.noise.seed + k)
        variants.append((vk, noise, duration * (1.0 - 0.03 * k)))
    worst = 0.0
    for (_, _, xs, us), one in lanes_and_one_case_runs(setup, loop.spec(setup.noise is not None), variants):
        kept = np.hstack([one.x, one.rotor_thrust, one.z, one.lag_model])  # [x; f; z; l], the buffer aside
        worst = max(worst, lane_gap(xs[:, :kept.shape[1]], kept), lane_gap(us, one.u))
    assert worst < LANE_RTOL, f"Max diff is {worst:.4E} of the quantity's size"


def _failing_compiler(tmp_path: Path) -> str:
    """A ``cc`` that exists and fails without a word (a macOS stub without the command line tools)."""
    cc = tmp_path / "cc"
    cc.write_text("#!/bin/sh\nexit 1\n")
    cc.chmod(0o755)
    return str(cc)


@pytest.fixture(scope="module")
def compiled_runs():
    """command -> its run folder with the compiler working (the session's compile cache), made once
    for both ways of breaking the compiler."""
    return {}


@pytest.mark.parametrize("command, broken", [
    ("simulate", "missing"),
    *[pytest.param(command, "missing", marks=pytest.mark.slow) for command in ("run", "design --full", "sweep")],
    ("simulate", "failing"),  # by default one command meets a failing compiler: all reach it through one engine
    *[pytest.param(command, "failing", marks=pytest.mark.slow) for command in ("run", "design --full", "sweep")],
])
def test_every_command_without_a_working_compiler_gives_one_notice_and_the_same_numbers(
        command, broken, tmp_path, tmp_path_factory, compiled_runs):
    import subprocess
    import sys

    cfg = "mambo-200hz"
    env = {**os.environ, "QUADCTL_CACHE": str(tmp_path / "cache")}
    sweep_file = tmp_path_factory.getbasetemp() / "no-compiler-sweep.yaml"
    sweep_file.write_text("parameters:\n  lqr.roll.R[0]: [20000, 40000]\nset:\n  simulation.duration: 1.0\n")
    args = command.split() + ["-c", cfg]
    if command == "sweep":
        args += ["-s", str(sweep_file), "--jobs", "1"]

    def quadctl(out, extra_env):
        res = subprocess.run([sys.executable, "-m", "quadctl", *args, "-o", str(out)],
                             env={**env, **extra_env}, capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, res.stderr
        return res

    if command not in compiled_runs:
        compiled_runs[command] = tmp_path_factory.mktemp("compiled")
        quadctl(compiled_runs[command], {"QUADCTL_CACHE": os.environ["QUADCTL_CACHE"]})
    good_folder = compiled_runs[command]
    bad_env = ({"QUADCTL_NO_COMPILE": "1"} if broken == "missing"
               else {"CC": _failing_compiler(tmp_path), "PATH": str(tmp_path)
                     + os.pathsep + os.environ["PATH"]})
    bad = quadctl(tmp_path / "bad", bad_env)
    notices = [line for line in bad.stderr.splitlines() if line.startswith("quadctl: note:")]
    assert len(notices) == 1, bad.stderr
    assert "CasADi's virtual machine" in notices[0] and "Traceback" not in bad.stderr
    if broken == "failing":
        assert "failed (exit 1" in notices[0]
    if command == "sweep":
        import csv

        rows = [list(csv.DictReader(open(d / "sweep.csv"))) for d in (good_folder, tmp_path / "bad")]
        for a, b in zip(*rows):
            for key in ("cost", "peak.A", "settling_time.phi"):
                assert float(a[key]) == pytest.approx(float(b[key]), rel=1e-9, abs=1e-12), key
        return
    if command == "design --full":
        import json

        good, bad_ = (json.loads((d / "design_full.json").read_text())["comparison"]
                      for d in (good_folder, tmp_path / "bad"))
        for design in ("decoupled", "full"):
            assert good["designs"][design]["cost"] == pytest.approx(bad_["designs"][design]["cost"], rel=1e-9)
        return
    good_sim, bad_sim = (np.load(d / "sim.npz") for d in (good_folder, tmp_path / "bad"))
    diff = max(np.abs(good_sim["x"] - bad_sim["x"]).max(), np.abs(good_sim["u"] - bad_sim["u"]).max())
    assert diff < 1e-9, f"Max diff is {diff:.4E}"


@pytest.mark.compiler
def test_a_cached_library_loads_without_building_casadi_functions(monkeypatch):
    """The compile cache is keyed by what the C is made from, so a hit skips code generation."""
    from quadctl.sim import builder

    setup, loop = _loop(cfg_dict("forward"))
    x0 = setup.initial_state(loop.x_trim)
    first = simulate(loop, x0, 0.01, 1e-5)  # compiled (or found) and cached
    _clear()
    builder.build.cache_clear()

    def refuse(*_):
        raise AssertionError("a cached library must not rebuild the loop functions")

    monkeypatch.setattr(builder, "build", refuse)
    try:
        again = simulate(loop, x0, 0.01, 1e-5)
    finally:
        _clear()
    assert again.backend == "compiled"
    np.testing.assert_array_equal(first.x, again.x)


def _counting_source():
    """A tiny C source, and the list that records each time it was generated."""
    made = []

    def source():
        made.append(1)
        return "double qc_answer(void) { return 42.0; }\n"

    return source, made


@pytest.mark.compiler
def test_the_compile_cache_key_follows_what_the_source_is_made_from(tmp_path, monkeypatch):
    """A hit skips generating the source; another key (variant, or generator edited) recompiles."""
    monkeypatch.setenv("QUADCTL_CACHE", str(tmp_path))
    source, made = _counting_source()
    flags = ("-O1", "-fPIC", "-shared")
    one = compile_mod.compile_cached(source, flags, "variant")
    assert compile_mod.compile_cached(source, flags, "variant") == one and len(made) == 1
    assert compile_mod.compile_cached(source, flags, "other-variant") != one
    monkeypatch.setattr(compile_mod, "FINGERPRINT", "edited generator" + "0" * 50)
    assert compile_mod.compile_cached(source, flags, "variant") != one
    assert len(made) == 3
    assert sorted(p.suffix for p in tmp_path.iterdir()) == [".so", ".so", ".so"]  # no temporaries left


@pytest.mark.parametrize("value, march, machine_only", [(None, "-march=native", False),
                                                         ("x86-64-v3", "-march=x86-64-v3", True),
                                                         ("-O0 -fno-pic", "-march=native", False)],
                         ids=["unset", "named", "not-a-name"])
def test_quadctl_march_names_the_target_of_the_native_builds(value, march, machine_only):
    """QUADCTL_MARCH replaces -march=native in the lanes' and the one-case native flags (read on import: a
    fresh process); a named target's libraries are keyed by the machine alone, not this CPU's flags; a
    value that is not a plain name is not passed to the compiler."""
    env = {k: v for k, v in os.environ.items() if k != compile_mod.MARCH_ENV}
    if value is not None:
        env[compile_mod.MARCH_ENV] = value
    code = ("import platform; from quadctl.native import compile as c; "
            "print(c.MARCH, c.SIMD_FLAGS.count(c.MARCH), c.NATIVE_FLAGS.count(c.MARCH), "
            "c.cpu_tag() == platform.machine())")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split() == [march, "1", "1", str(machine_only)]


@pytest.mark.compiler
@pytest.mark.parametrize("value, said", [("foo", "QUADCTL_MARCH: the compiler refused -march=foo"),
                                         ("x86-64 v3", "QUADCTL_MARCH='x86-64 v3' is not a target's name")],
                         ids=["refused", "not-a-name"])
def test_a_quadctl_march_not_used_as_given_is_said_once_and_the_lanes_still_run(value, said, tmp_path):
    """A target the compiler refuses: the lanes are built for any CPU, and a notice says so; a value that
    is not a name: built for this CPU, and a notice says so. Once a process, however many runners."""
    code = ("import json, warnings; from quadctl import config, pipeline; from quadctl.setup import setup_of\n"
            "from quadctl.sim import engine\n"
            "setup = setup_of(config.load('hover'))\n"
            "stages = pipeline.Stages(setup)\n"
            "with warnings.catch_warnings(record=True) as caught:\n"
            "    warnings.simplefilter('always')\n"
            "    specs = (stages.loop.spec(), stages.loop.spec(True))\n"
            "    runners = [engine.runner(spec, engine.LANES) for spec in specs]\n"
            "print(json.dumps(sorted({r.backend for r in runners})))\n"
            "print(json.dumps([str(w.message) for w in caught if isinstance(w.message, engine.CompilerNotice)]))\n")
    env = {**os.environ, "QUADCTL_MARCH": value, "QUADCTL_CACHE": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    backends, notices = out.splitlines()
    assert json.loads(backends) == (["compiled"] if value == "foo" else ["compiled-simd"])
    notices = json.loads(notices)
    assert len(notices) == 1 and notices[0].startswith(said), notices


def test_with_no_compiler_a_named_quadctl_march_is_not_said_refused(monkeypatch):
    """No compiler to refuse the target: only the notice that the loop runs in CasADi's virtual machine."""
    import warnings

    from quadctl import config, pipeline
    from quadctl.setup import setup_of

    monkeypatch.setenv("QUADCTL_NO_COMPILE", "1")
    monkeypatch.setattr(engine, "MARCH", "-march=foo")
    engine._march_notice.cache_clear()
    spec = pipeline.Stages(setup_of(config.load("hover"))).loop.spec()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        got = engine.runner.__wrapped__(spec, engine.LANES)
    said = [str(w.message) for w in caught if isinstance(w.message, engine.CompilerNotice)]
    assert got.backend == "casadi"
    assert len(said) == 1 and "CasADi's virtual machine" in said[0] and "QUADCTL_MARCH" not in said[0], said


@pytest.mark.compiler
@pytest.mark.parametrize("value, said", [("foo", "QUADCTL_MARCH: the compiler refused -march=foo"),
                                         ("x86-64 v3", "QUADCTL_MARCH='x86-64 v3' is not a target's name")],
                         ids=["refused", "not-a-name"])
def test_a_sweep_on_two_workers_says_a_quadctl_march_not_used_as_given_once(value, said, tmp_path):
    """Each worker builds its own lanes; the sweep says the notice before they start, and they do not
    repeat it (it came once a worker: two lines with -j 2)."""
    (tmp_path / "s.yaml").write_text("parameters:\n  vehicle.mass: {from: 0.06, to: 0.08, num: 32}\n"
                                     "set: {simulation.duration: 0.2}\n")
    env = {**os.environ, "QUADCTL_MARCH": value, "QUADCTL_CACHE": str(tmp_path / "cache")}
    res = subprocess.run([sys.executable, "-m", "quadctl", "sweep", "-c", "hover", "-s", str(tmp_path / "s.yaml"),
                          "-o", str(tmp_path / "out"), "-j", "2", "--no-plot"],
                         env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    notes = [line for line in res.stderr.replace("\r", "\n").splitlines() if "QUADCTL_MARCH" in line]
    assert len(notes) == 1 and notes[0].startswith(f"quadctl: note: {said}"), notes
    assert json.loads((tmp_path / "out" / "sweep.json").read_text())["statuses"] == {"ok": 32}


@pytest.mark.compiler
def test_threads_compile_one_library_without_touching_the_working_directory(tmp_path, monkeypatch):
    """Dask workers run chunks in threads: one compiles, the others wait and load its library, and
    nothing changes the process's working directory (which every thread shares)."""
    from concurrent.futures import ThreadPoolExecutor

    def no_chdir(*_):
        raise AssertionError("os.chdir moves every thread of the process")

    monkeypatch.setattr(os, "chdir", no_chdir)
    monkeypatch.setenv("QUADCTL_CACHE", str(tmp_path / "cache"))
    cwd = os.getcwd()
    source, made = _counting_source()
    with ThreadPoolExecutor(4) as pool:
        paths = list(pool.map(lambda _: compile_mod.compile_cached(source, ("-O1", "-fPIC", "-shared"), "same"),
                              range(4)))
    assert len(set(paths)) == 1 and paths[0].exists() and len(made) == 1
    # a real loop library, generated by CasADi, from several threads at once
    _clear()
    specs = [_loop(cfg_dict(name))[1].spec() for name in ("forward", "hover")]
    with ThreadPoolExecutor(4) as pool:
        runners = list(pool.map(lambda k: engine.runner(specs[k % 2], 1), range(4)))
    _clear()
    assert {r.backend for r in runners} == {"compiled"} and os.getcwd() == cwd


_RACE = """
import sys, time
from pathlib import Path
from quadctl.native import compile as compile_mod
log = Path(sys.argv[1])
def source():
    with log.open("a") as fh:
        fh.write("made\\n")
    time.sleep(0.5)  # the other process asks meanwhile
    return "double qc_answer(void) { return 42.0; }\\n"
print(compile_mod.compile_cached(source, ("-O1", "-fPIC", "-shared"), "raced"))
"""


@pytest.mark.compiler
@pytest.mark.skipif(os.name != "posix", reason="the machine-wide lock is flock")
def test_processes_compile_one_library_once(tmp_path):
    """A sweep's worker processes on a cold cache: one compiles, the other waits and loads its library."""
    import subprocess
    import sys

    env = {**os.environ, "QUADCTL_CACHE": str(tmp_path / "cache")}
    log = tmp_path / "made.log"
    procs = [subprocess.Popen([sys.executable, "-c", _RACE, str(log)], env=env, stdout=subprocess.PIPE, text=True)
             for _ in range(2)]
    paths = {p.communicate(timeout=120)[0].strip() for p in procs}
    assert all(p.returncode == 0 for p in procs)
    assert len(paths) == 1 and Path(paths.pop()).exists()
    assert log.read_text().count("made") == 1
    assert sorted(p.suffix for p in (tmp_path / "cache").iterdir()) == [".so"]  # no lock or temporary left


def test_no_library_module_changes_directory_or_calls_fchmod_unguarded():
    root = Path(compile_mod.__file__).parents[1]
    for path in root.rglob("*.py"):
        text = path.read_text()
        assert "os.chdir(" not in text, path
        for line in text.splitlines():
            if "os.fchmod(" in line:
                assert "hasattr(os, \"fchmod\")" in text or "hasattr(os, 'fchmod')" in text, path


def test_fingerprint_changes_with_any_generator_source_or_casadi(tmp_path):
    sources = dict(compile_mod._SOURCES)

    def fp(casadi="casadi 3.6.0", **edits):
        return compile_mod.fingerprint({**sources, **edits}, casadi)

    base = fp()
    assert fp() == base and fp("casadi 3.7.0") != base
    for name in compile_mod.GENERATOR_SOURCES:
        assert fp(**{name: sources[name] + b"\n/* edited */\n"}) != base, name
    # this process's key is that of the files it imported
    assert compile_mod.FINGERPRINT == compile_mod.fingerprint(compile_mod._read_sources(), compile_mod.casadi_stamp())


def test_stale_libraries_of_other_fingerprints_are_evicted(tmp_path):
    ours = tmp_path / f"qc_{compile_mod.FINGERPRINT[:12]}_abc.so"
    old_other = tmp_path / "qc_0123456789ab_abc.so"
    new_other = tmp_path / "qc_0123456789ab_def.so"
    legacy = tmp_path / "qb_0123456789abcdef0123.so"
    for path in (ours, old_other, new_other, legacy):
        path.write_bytes(b"")
    old = time.time() - (compile_mod.EVICT_AFTER_DAYS + 1) * 86400
    for path in (ours, old_other, legacy):
        os.utime(path, (old, old))
    gone = compile_mod.evict_stale(tmp_path)
    assert sorted(gone) == sorted([old_other, legacy])
    assert ours.exists() and new_other.exists()


def test_the_cache_is_in_the_platforms_cache_folder(monkeypatch):
    monkeypatch.delenv("QUADCTL_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", "/x/cache")
    monkeypatch.setattr(compile_mod.sys, "platform", "linux")
    assert compile_mod.cache_dir() == Path("/x/cache/quadctl")
    monkeypatch.setattr(compile_mod.sys, "platform", "darwin")
    assert compile_mod.cache_dir() == Path.home() / "Library" / "Caches" / "quadctl"
    monkeypatch.setattr(compile_mod.sys, "platform", "win32")
    monkeypatch.setenv("LOCALAPPDATA", "C:/Users/u/AppData/Local")
    assert compile_mod.cache_dir() == Path("C:/Users/u/AppData/Local") / "quadctl"


def test_driver_sizes_come_from_the_layout():
    """The C has no size of its own: every dimension is a macro the generator emits."""
    import re

    driver = compile_mod.DRIVER_SOURCE
    code = re.sub(r"/\*.*?\*/", "", driver, flags=re.S)
    assert not re.search(r"\[(12|4|6|16|18)\]", code)
    assert not shutil.which("nonexistent-quadctl-cc")


def test_the_generated_law_branches_by_selects_only():
    """Every branch of the generated code is a select of two computed values, which GCC vectorizes in
    the lanes (built with SIMD_FLAGS' -fno-trapping-math): no fmin/fmax call (no vector form under C's
    NaN rule) and no short-circuit && or ||. A PID cascade's law, with its tilt, rate and integrator
    limits, has 156 of them; with fmin calls GCC left its lane loop scalar ("control flow in loop")."""
    from quadctl.native.emit import emit
    from quadctl.sim.builder import build
    from quadctl.sim.engine import LANES

    data = cfg_dict("crazyflie")
    data["controller"]["flies"] = "pid"
    setup, _, linear, _, _ = solve(data)
    law = build(pipeline.pid_loop_of(setup, linear).spec()).law
    source = emit(law, "qc_law", LANES)
    assert source.count(" ? ") > 100
    assert "fmin(" not in source and "fmax(" not in source and "&&" not in source and "||" not in source
    assert "-fno-trapping-math" in compile_mod.SIMD_FLAGS


@pytest.mark.parametrize("label, data, duration", [FEATURES[0], FEATURES[2]], ids=[FEATURES[0][0], FEATURES[2][0]])
def test_a_diagonal_inertia_is_baked_in_as_zeros_with_the_same_numbers(label, data, duration):
    """A vehicle with a diagonal J flies code with its products of inertia baked in as exact zeros
    (LoopSpec.diagonal_inertia): the numbers of the code that reads them from the constants, to the
    last bit, in fewer operations (189 fewer a step of the continuous loop, of 1 000)."""
    from dataclasses import replace

    from quadctl.sim.builder import build
    from quadctl.sim.stack import stack_of
    from quadctl.sim.stack_run import run_stack

    setup, loop = _loop(data)
    stack = stack_of([loop], [setup.initial_state(loop.x_trim)], duration, setup.dt, noise=setup.noise)
    assert stack.spec.diagonal_inertia
    generic = replace(stack.spec, diagonal_inertia=False)
    (_, t, xs, us), = run_stack(stack, engine.runner(stack.spec, 1))
    (_, t_g, xs_g, us_g), = run_stack(stack, engine.runner(generic, 1))
    assert np.array_equal(t, t_g) and np.array_equal(xs, xs_g) and np.array_equal(us, us_g)
    step = "plant" if stack.spec.held else "step"
    saved = getattr(build(generic), step).n_instructions() - getattr(build(stack.spec), step).n_instructions()
    assert saved >= 150


def test_a_vehicle_with_products_of_inertia_flies_the_code_that_reads_them():
    """A full tensor is not baked in as diagonal: forcing the diagonal code on it changes the flight."""
    from dataclasses import replace

    from quadctl.sim.stack import stack_of
    from quadctl.sim.stack_run import run_stack

    data = cfg_dict("hover")
    data["vehicle"]["inertia"] = [[6.9e-5, 0.9e-5, -1.2e-5], [0.9e-5, 7.75e-5, 0.6e-5], [-1.2e-5, 0.6e-5, 1.5e-4]]
    data["simulation"]["initial_offset"] = {"phi": 0.3, "psi": 0.2}
    setup, loop = _loop(data)
    stack = stack_of([loop], [setup.initial_state(loop.x_trim)], 0.3, setup.dt)
    assert not stack.spec.diagonal_inertia
    (_, _, xs, _), = run_stack(stack, engine.runner(stack.spec, 1))
    (_, _, xs_d, _), = run_stack(stack, engine.runner(replace(stack.spec, diagonal_inertia=True), 1))
    assert np.abs(xs[-1] - xs_d[-1]).max() > 1e-6


def test_a_flown_reference_adds_no_select_to_the_lanes_step():
    """The runners choose a reference row's expansions before each step
    (:func:`quadctl.physics.reference_rows.in_force`), so the generated step reads its columns with no select.
    With a select per column (about 180) GCC's jump threading turned the lanes' step into branches and
    left it scalar ("control flow in loop"): a mission sweep ran 3 times slower."""
    from dataclasses import replace

    from quadctl.native.emit import emit
    from quadctl.sim.builder import build
    from quadctl.sim.engine import LANES

    _, loop = _loop(cfg_dict("square"))
    spec = loop.spec(reference=True)
    assert spec.reference and not spec.held
    selects = [emit(build(s).step, "qc_step", LANES).count(" ? ") for s in (spec, replace(spec, reference=False))]
    assert selects[0] == selects[1]
