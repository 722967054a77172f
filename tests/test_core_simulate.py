"""RK4 simulation: step choice, refusal of unstable steps, compiled vs interpreted, convergence."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from quadctl import codegen, pipeline
from quadctl.errors import StepSizeError
from quadctl.layout import STATE_INDEX
from quadctl.simulate import (
    ACCURACY_STEP,
    ClosedLoop,
    max_stable_step,
    max_stable_steps,
    plan_step,
    record_stride,
    rk4_amplification,
    simulate,
)


@pytest.fixture(scope="module")
def loop(forward):
    cfg, trim, linear, _, des = forward
    return cfg, pipeline.closed_loop_of(cfg, linear, des.K_block, pipeline.reference_rate(trim))


def test_rk4_real_axis_limit():
    """RK4 is stable on the negative real axis up to h lambda = -2.785293563 (a known constant)."""
    assert max_stable_step(-1.0) == pytest.approx(2.785293563, rel=1e-8)
    assert max_stable_step(-100.0) == pytest.approx(0.02785293563, rel=1e-8)
    assert max_stable_step(0.0) == math.inf
    h = max_stable_step(-3 + 4j)
    assert rk4_amplification(h * (-3 + 4j)) == pytest.approx(1.0, abs=1e-9)
    assert rk4_amplification(1.01 * h * (-3 + 4j)) > 1.0


def test_auto_step_is_stable_and_accurate(loop):
    _, cl = loop
    plan = plan_step(cl.eigenvalues, cl.owners, 10.0, "auto")
    assert plan.auto and plan.dt * abs(plan.fastest_eigenvalue) <= ACCURACY_STEP + 1e-12
    assert plan.dt < plan.max_stable_dt
    assert plan.n_steps * plan.dt == pytest.approx(10.0)
    assert plan.fastest_owner == "roll"  # 1/Jxx is the largest input gain


def test_unstable_user_step_is_refused_with_eigenvalue_subsystem_and_limit(loop):
    _, cl = loop
    with pytest.raises(StepSizeError, match=r"simulation.dt = 0.001 s is unstable for RK4: the closed-loop "
                       r"eigenvalue -14492.8 rad/s \(subsystem roll\) needs dt <= 0.000192\d* s"):
        plan_step(cl.eigenvalues, cl.owners, 10.0, 1e-3)
    ok = plan_step(cl.eigenvalues, cl.owners, 1.0, 1.9e-4)
    assert ok.dt == 1.9e-4 and not ok.auto


def test_closed_loop_returns_to_trim(loop):
    cfg, cl = loop
    sim = pipeline.simulation_of(cfg, cl)
    assert sim.status == "ok" and sim.t[-1] == pytest.approx(cfg.simulation.duration)
    err = sim.x[-1] - sim.x_ref[-1]
    regulated = [STATE_INDEX[s] for s in ("pD", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r")]
    assert np.abs(err[regulated]).max() < 1e-4
    # the unregulated north position keeps moving at the flight speed
    assert sim.x[-1, 0] == pytest.approx(cfg.simulation.duration * 1.0, abs=0.5)


@pytest.mark.compiler
def test_compiled_and_interpreted_loops_agree(loop, monkeypatch):
    cfg, cl = loop
    x0 = pipeline.initial_state(cfg, cl.x_trim)
    compiled = simulate(cl, x0, 0.02, 2e-5)
    monkeypatch.setenv("QUADCTL_NO_COMPILE", "1")
    codegen.get_loop.cache_clear()
    try:
        interpreted = simulate(cl, x0, 0.02, 2e-5)
    finally:
        codegen.get_loop.cache_clear()
    assert compiled.backend == "compiled" and interpreted.backend == "casadi"
    diff = np.abs(compiled.x - interpreted.x).max()
    assert diff < 1e-12, f"Max diff is {diff:.4E}"
    np.testing.assert_allclose(compiled.u, interpreted.u, atol=1e-12)


def test_rk4_is_fourth_order(loop):
    """Halving dt divides the global error by ~16 (reference: dt / 8)."""
    cfg, cl = loop
    x0 = pipeline.initial_state(cfg, cl.x_trim)
    runs = [simulate(cl, x0, 0.01, h).x[-1] for h in (4e-5, 2e-5, 2.5e-6)]
    e1, e2 = np.abs(runs[0] - runs[2]).max(), np.abs(runs[1] - runs[2]).max()
    assert 12 < e1 / e2 < 24  # order 3 would give 8, order 5 would give 32


def test_divergence_stops_and_keeps_what_was_computed(loop):
    cfg, cl = loop
    bad = ClosedLoop(**{**cl.__dict__, "K": -cl.K})  # positive feedback
    sim = simulate(bad, pipeline.initial_state(cfg, cl.x_trim), 5.0, 1e-4)
    assert sim.status in ("diverged", "left_valid_range")
    assert sim.steps < 50000 and len(sim.t) >= 2 and np.all(np.isfinite(sim.x[:-1]))
    assert "saved" in sim.message


def test_leaving_the_euler_range_is_reported(loop):
    cfg, cl = loop
    free = ClosedLoop(**{**cl.__dict__, "K": np.zeros((4, 12)), "eigenvalues": np.zeros(12)})
    x0 = cl.x_trim.copy()
    x0[STATE_INDEX["q"]] = 3.0  # pitch up at 3 rad/s with no control
    sim = simulate(free, x0, 2.0, 1e-3)
    assert sim.status == "left_valid_range"
    assert "pitch" in sim.message and "Euler" in sim.message
    assert abs(sim.x[-2, STATE_INDEX["theta"]]) <= math.radians(85)


def test_chunked_runs_equal_one_long_call(loop, monkeypatch):
    """Chunk boundaries (for Ctrl-C) change nothing but round-off in t = t0 + k dt."""
    import quadctl.simulate as sim_mod

    cfg, cl = loop
    x0 = pipeline.initial_state(cfg, cl.x_trim)
    whole = simulate(cl, x0, 0.05, 1e-5)
    monkeypatch.setattr(sim_mod, "CHUNK_STEPS", 777)
    chunked = simulate(cl, x0, 0.05, 1e-5)
    np.testing.assert_array_equal(whole.t, chunked.t)
    diff = np.abs(whole.x - chunked.x).max()
    assert diff < 1e-13, f"Max diff is {diff:.4E}"
    np.testing.assert_allclose(whole.u, chunked.u, atol=1e-12)
    assert whole.steps == chunked.steps == 5000


def test_max_samples_sets_the_record_stride_and_keeps_the_last_step(loop):
    cfg, cl = loop
    x0 = pipeline.initial_state(cfg, cl.x_trim)
    every = simulate(cl, x0, 0.01, 1e-5)  # 1000 steps, all kept
    few = simulate(cl, x0, 0.01, 1e-5, max_samples=70)
    assert every.stride == 1 and len(every.t) == 1001
    assert few.stride == 15 and len(few.t) == 1000 // 15 + 2 <= 70 and few.t[-1] == every.t[-1]
    np.testing.assert_array_equal(few.x[:-1], every.x[:-1:15])
    np.testing.assert_array_equal(few.x[-1], every.x[-1])
    for n in (1, 2, 3, 999, 1000, 1001, 289_856, 1_000_000):
        for cap in (2, 3, 69, 70, 1001, 20_000):
            stride = record_stride(n, cap)
            assert codegen.record_rows(n, stride) <= cap, (n, cap)
            assert stride == 1 or codegen.record_rows(n, stride - 1) > cap, (n, cap)  # the smallest


@pytest.mark.compiler
def test_a_cached_library_loads_without_building_casadi_functions(loop, monkeypatch):
    """The compile cache is keyed by what the C is made from, so a hit skips code generation."""
    cfg, cl = loop
    x0 = pipeline.initial_state(cfg, cl.x_trim)
    first = simulate(cl, x0, 0.01, 1e-5)  # compiled (or found) and cached

    def refuse(*_):
        raise AssertionError("a cached library must not rebuild the step functions")

    codegen.get_loop.cache_clear()
    monkeypatch.setattr(codegen, "build_step_functions", refuse)
    try:
        again = simulate(cl, x0, 0.01, 1e-5)
    finally:
        codegen.get_loop.cache_clear()
    assert again.backend == "compiled"
    np.testing.assert_array_equal(first.x, again.x)


def _counting_source():
    """A tiny C source, and the list that records each time it was generated."""
    made = []

    def source():
        made.append(1)
        return "double qc_answer(void) { return 42.0; }\n"

    return source, made


def test_the_compile_cache_key_follows_what_the_source_is_made_from(tmp_path, monkeypatch):
    """A hit skips generating the source; another key (variant, or generator edited) recompiles."""
    compiler = codegen.find_compiler()
    if compiler is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("QUADCTL_CACHE", str(tmp_path))
    source, made = _counting_source()
    flags = ("-O1", "-fPIC", "-shared")
    one = codegen.compile_cached(source, flags, compiler, "t", "fingerprint variant")
    assert codegen.compile_cached(source, flags, compiler, "t", "fingerprint variant") == one and len(made) == 1
    assert codegen.compile_cached(source, flags, compiler, "t", "fingerprint other-variant") != one
    assert codegen.compile_cached(source, flags, compiler, "t", "edited-model variant") != one
    assert len(made) == 3
    assert sorted(p.suffix for p in tmp_path.iterdir()) == [".so", ".so", ".so"]  # no temporaries left


def test_threads_compiling_the_same_library_all_get_it(tmp_path, monkeypatch):
    """Dask workers run chunks in threads: one compiles, the others wait and load its library."""
    from concurrent.futures import ThreadPoolExecutor

    compiler = codegen.find_compiler()
    if compiler is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("QUADCTL_CACHE", str(tmp_path))
    source, made = _counting_source()
    with ThreadPoolExecutor(4) as pool:
        paths = list(pool.map(lambda _: codegen.compile_cached(source, ("-O1", "-fPIC", "-shared"), compiler,
                                                               "t", "same"), range(4)))
    assert len(set(paths)) == 1 and paths[0].exists() and len(made) == 1


def test_fingerprint_changes_with_any_generator_source_or_casadi(tmp_path):
    import shutil

    for name in codegen.SCALAR_SOURCES:
        shutil.copy(Path(codegen.__file__).parent / name, tmp_path / name)

    def fp(casadi="casadi 3.6.0"):
        return codegen.fingerprint(codegen.read_sources(tmp_path, codegen.SCALAR_SOURCES), casadi)

    base = fp()
    assert fp() == base and fp("casadi 3.7.0") != base
    for name in ("model.py", "_driver.c"):
        original = (tmp_path / name).read_bytes()
        (tmp_path / name).write_bytes(original + b"\n# edited\n")
        assert fp() != base, name
        (tmp_path / name).write_bytes(original)
    assert fp() == base
    # this process's key is that of the files it imported
    assert codegen.FINGERPRINT == codegen.fingerprint(
        codegen.read_sources(Path(codegen.__file__).parent, codegen.SCALAR_SOURCES), codegen.casadi_stamp())


def test_vectorized_step_limits_agree_with_the_scan():
    rng = np.random.default_rng(3)
    eig = np.concatenate([rng.normal(size=300) * 10 ** rng.uniform(-2, 4, 300)
                          + 1j * rng.normal(size=300) * 10 ** rng.uniform(-2, 4, 300),
                          [-1.0, -14493.0, 0.0, 2.0, 1j, -1e-12 + 5j]])
    fast = max_stable_steps(eig)
    slow = np.array([max_stable_step(e) for e in eig])
    finite = np.isfinite(slow) & (slow > 0)
    assert np.array_equal(fast[~finite], slow[~finite])
    worst = np.max(np.abs(fast[finite] - slow[finite]) / slow[finite])
    assert worst < 1e-12, f"Max diff is {worst:.4E}"
    with pytest.raises(StepSizeError, match="is unstable for RK4"):  # limits given by a batch
        plan_step(eig[:3], ["x"] * 3, 2.0, 10.0, limits=fast[:3])


def test_the_config_default_of_max_samples_is_the_library_default():
    from quadctl.config import SimulationConfig
    from quadctl.simulate import MAX_SAMPLES

    assert SimulationConfig().max_samples == MAX_SAMPLES
