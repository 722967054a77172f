"""Architecture rules that keep the tool quick and the core reusable."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest
from _paths import ROOT

import quadctl

PACKAGE = Path(quadctl.__file__).parent


def test_help_imports_no_heavy_library():
    """`quadctl --help` must not pay for numpy, scipy, casadi or matplotlib."""
    code = ("import sys, quadctl.cli.app; "
            "print(sorted(m for m in ('numpy', 'scipy', 'casadi', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"



def test_what_draws_nothing_loads_no_figures_and_no_worker_processes():
    """The run folder, the stages, the export and the gain schedule load neither matplotlib (the figures
    load it when they are drawn) nor the process pools of a sweep's runner (its design borrows the
    sweep's batched solves only when a schedule is designed)."""
    code = ("import sys, quadctl.workspace, quadctl.stages, quadctl.export, quadctl.schedule.envelope; "
            "print(sorted(m for m in ('matplotlib', 'multiprocessing', 'concurrent.futures') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    code = "import sys, quadctl.sweep; print('matplotlib' in sys.modules)"  # a sweep draws when asked to
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"

def test_library_never_imports_the_cli():
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        if "cli" in path.relative_to(PACKAGE).parts or path.name == "__main__.py":  # the entry point
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            offenders += [f"{path.name}: {n}" for n in names if n.startswith("quadctl.cli")]
    assert offenders == []


def test_dynamics_live_only_in_model():
    """No second copy of the equations: only model.py builds cross products and Euler kinematics."""
    for path in PACKAGE.rglob("*.py"):
        if path.name == "model.py":
            continue
        text = path.read_text()
        assert "ca.cross(" not in text and "tan(theta)" not in text, path.name


def _quadctl_imports(module: str) -> set[str]:
    """Paths (relative to the package) of the quadctl modules ``module`` imports, directly or not."""
    seen, todo = set(), [module]
    while todo:
        name = todo.pop()
        path = PACKAGE / (name.split(".", 1)[1].replace(".", "/") + ".py")
        if not path.exists():
            path = path.with_suffix("") / "__init__.py"
        rel = path.relative_to(PACKAGE).as_posix()
        if rel in seen:
            continue
        seen.add(rel)
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("quadctl"):
                todo += [node.module] if node.module != "quadctl" else [f"quadctl.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                todo += [a.name for a in node.names if a.name.startswith("quadctl.")]
    return seen


def test_compile_cache_key_covers_everything_the_generators_import():
    """A cached library is found by a hash of the generator's sources, not of the generated C: a
    module the generators import but the hash leaves out could change the C and load a stale library."""
    from quadctl.native.compile import GENERATOR_SOURCES

    used = _quadctl_imports("quadctl.sim.native") | {"sim/driver.c"}  # native.library_source writes the C
    used -= {"sim/__init__.py", "native/__init__.py"}  # the package maps: no code
    assert used <= set(GENERATOR_SOURCES), sorted(used - set(GENERATOR_SOURCES))
    assert all((PACKAGE / name).exists() for name in GENERATOR_SOURCES)


@pytest.mark.compiler  # the interpreted fallback is CasADi itself
def test_simulate_on_fresh_artifacts_imports_neither_casadi_nor_scipy(tmp_path):
    """The warm path (artifacts and compiled loop cached) is numpy and the compiled loop only:
    CasADi and SciPy would cost more than integrating a million steps (docs/performance.md)."""
    cfg = ROOT / "configs" / "hover.yaml"
    env = {**__import__("os").environ, "QUADCTL_CACHE": str(tmp_path / "cache")}
    run = [sys.executable, "-m", "quadctl", "simulate", "-c", str(cfg), "-o", str(tmp_path / "run")]
    subprocess.run(run, capture_output=True, check=True, env=env)  # designs, compiles, caches
    code = ("import sys\nfrom quadctl.cli.app import main\n"
            f"sys.argv = {['quadctl', *run[3:]]!r}\n"
            "try:\n    main()\nexcept SystemExit as exc:\n    assert not exc.code, exc.code\n"
            "heavy = ('casadi.casadi', 'scipy.linalg', 'scipy.optimize', 'matplotlib')\n"
            "print(sorted(m for m in heavy if m in sys.modules), file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    assert out.stderr.strip().splitlines()[-1] == "[]"


def test_lazy_module_loads_once_under_concurrent_first_use(tmp_path, monkeypatch):
    """Dask workers run chunks in threads: all of them must see the whole module (importlib's
    LazyLoader on Python 3.11 let 3 of 4 threads see it half-loaded)."""
    import threading

    from quadctl._lazy import lazy_import

    (tmp_path / "slow_module_for_quadctl.py").write_text(
        "import time\nLOADS = [1]\ntime.sleep(0.2)\nVALUE = 42\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    mod = lazy_import("slow_module_for_quadctl")
    assert "slow_module_for_quadctl" not in sys.modules  # nothing ran yet
    seen, start = [], threading.Barrier(4)

    def use():
        start.wait()
        seen.append(mod.VALUE)

    threads = [threading.Thread(target=use) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert seen == [42] * 4 and mod.LOADS == [1]
    assert lazy_import("slow_module_for_quadctl") is sys.modules["slow_module_for_quadctl"]
    sys.modules.pop("slow_module_for_quadctl")


def test_lazy_import_of_a_missing_module_fails_at_once():
    import pytest

    from quadctl._lazy import lazy_import

    with pytest.raises(ModuleNotFoundError, match="no_such_module_for_quadctl"):
        lazy_import("no_such_module_for_quadctl")


def _import_graph() -> dict[str, set[str]]:
    """Module -> the quadctl modules it imports, at the top or inside a function (``from pkg import
    sub`` counts as importing ``pkg.sub``; a name from a package counts as importing the package)."""
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path

    def owner(name: str) -> str:
        while name not in modules:
            name = name.rpartition(".")[0]
        return name

    graph = {}
    for name, path in modules.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("quadctl"):
                deps |= {f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in modules else owner(node.module)
                         for a in node.names}
            elif isinstance(node, ast.Import):
                deps |= {owner(a.name) for a in node.names if a.name.startswith("quadctl.")}
        graph[name] = deps - {name, "quadctl"}
    return graph


def test_no_import_cycles_not_even_inside_functions():
    """Imports go one way: no module reaches itself again through what it imports, counting the
    imports deferred into functions (a cycle hidden there is still a cycle)."""
    graph, cycles = _import_graph(), []

    def visit(name, trail):
        if name in trail:
            cycles.append(" -> ".join(trail[trail.index(name):] + [name]))
            return
        if name in done:
            return
        for dep in sorted(graph.get(name, ())):
            visit(dep, trail + [name])
        done.add(name)

    done: set[str] = set()
    for name in sorted(graph):
        visit(name, [])
    assert cycles == []
# ---------------------------------------------------------------------------------------------
# One home for the linear closed loop (quadctl/design/linear_loop.py) and for the stability test
# (quadctl/linear/stability.py): the source is scanned for a second copy.

LOOP_HOME = {"design/linear_loop.py"}
SOLVER_LOOPS = "design/riccati/"
"""The Riccati solvers close ``A - B K`` inside their Newton steps and residuals: part of solving for
the gain, below :mod:`quadctl.design.linear_loop` in the import graph (which depends on them through
:mod:`quadctl.design.discrete`)."""
STABILITY_HOME = {"linear/stability.py"}


def _is_gain(node) -> bool:
    """A gain: a name (or attribute, or item of one) that starts with ``K`` (``K``, ``Ka``, ``Kf``,
    ``design.K_block``, ``K[others, :]``)."""
    while isinstance(node, ast.Subscript):
        node = node.value
    name = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""
    return name.startswith("K")


def closed_loops_built(tree) -> list[int]:
    """Lines that build a closed loop: ``M - X @ K`` with ``M`` a matrix (not a sum, as in a cost's
    cross term ``Q + K'RK - N K``) and ``K`` a gain."""
    out = []
    for node in ast.walk(tree):
        if (isinstance(node, ast.BinOp) and isinstance(node.op, ast.Sub) and not isinstance(node.left, ast.BinOp)
                and isinstance(node.right, ast.BinOp) and isinstance(node.right.op, ast.MatMult)
                and _is_gain(node.right.right)):
            out.append(node.lineno)
    return out


def _is_one_minus(node) -> bool:
    return (isinstance(node, ast.BinOp) and isinstance(node.op, ast.Sub) and isinstance(node.left, ast.Constant)
            and node.left.value == 1)


def _is_abs(node) -> bool:
    return isinstance(node, ast.Call) and (
        (isinstance(node.func, ast.Name) and node.func.id == "abs")
        or (isinstance(node.func, ast.Attribute) and node.func.attr in ("abs", "absolute")))


def _root_name(node) -> str:
    while isinstance(node, (ast.Subscript, ast.Attribute, ast.Call)):
        node = node.func if isinstance(node, ast.Call) else node.value
    return node.id if isinstance(node, ast.Name) else ""


def _is_real_part(node) -> bool:
    """``x.real`` of anything but a loop's frequency response ``L`` (whose sign finds phase crossovers)."""
    return isinstance(node, ast.Attribute) and node.attr == "real" and not _root_name(node.value).startswith("L")


def stability_tests_made(tree) -> list[int]:
    """Lines that test stability themselves: a comparison of a real part (``e.real < 0``), a comparison
    with ``1 - margin`` or of a magnitude with 1 (``abs(z) < 1``), or a use of the stability margins."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            if any(map(_is_real_part, sides)) or any(map(_is_one_minus, sides)):
                out.append(node.lineno)
            elif any(map(_is_abs, sides)) and any(isinstance(s, ast.Constant) and s.value == 1 for s in sides):
                out.append(node.lineno)
        elif isinstance(node, (ast.Name, ast.Attribute, ast.alias)):
            name = getattr(node, "id", None) or getattr(node, "attr", None) or getattr(node, "name", None)
            if name in ("STABILITY_MARGIN", "UNIT_CIRCLE_MARGIN"):
                out.append(node.lineno)
    return out


def _offenders(find, homes, skip: tuple[str, ...] = ()) -> list[str]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE)
        if rel.as_posix() in homes or rel.as_posix().startswith(skip):
            continue
        out += [f"{rel}:{line}" for line in find(ast.parse(path.read_text()))]
    return out


def test_closed_loops_are_built_only_in_linear_loop():
    """Every ``A - B K`` outside the Riccati solvers is :mod:`quadctl.design.linear_loop`'s (``close``,
    ``matrix``, ``vehicle``, ...)."""
    assert _offenders(closed_loops_built, LOOP_HOME, skip=(SOLVER_LOOPS,)) == []


def test_stability_is_decided_only_in_the_stability_module():
    """Every stability comparison and both margins live in :mod:`quadctl.linear.stability`."""
    assert _offenders(stability_tests_made, STABILITY_HOME) == []


@pytest.mark.parametrize("source, loops, tests", [
    ("A_cl = A - B @ K", 1, 0),
    ("Acl = Aa - Ba @ Ka_r", 1, 0),
    ("A_o = A - B[:, others] @ K[others, :]", 1, 0),
    ("x = Ae - Be @ design.K_block - G @ C", 1, 0),
    ("ok = e.real < -1e-9 * max(1.0, abs(e))", 0, 1),
    ("ok = np.all(np.abs(E) < 1 - 1e-9)", 0, 1),
    ("ok = abs(z) < 1", 0, 1),
    ("ok = radius >= 1.0 - UNIT_CIRCLE_MARGIN", 0, 1 + 1),  # the comparison and the margin
    ("from quadctl.linear.analysis import STABILITY_MARGIN", 0, 1),
    # not loops, not stability tests: an observer, a cost's cross term, a zero test, an imaginary part
    ("Ao = A - L @ C", 0, 0),
    ("stage = Q + K.T @ R @ K - N @ K", 0, 0),
    ("zero = abs(e) < 1e-9", 0, 0),
    ("real = e.imag >= 0", 0, 0),
    ("crossing = Lc.real < 0", 0, 0),
    ("ok = np.linalg.eigvals(A)[0].real < 0", 0, 1),
])
def test_the_scans_find_a_second_copy(source, loops, tests):
    """The two scans above flag what they must and nothing else (so a copy put back fails them)."""
    tree = ast.parse(source)
    assert len(closed_loops_built(tree)) == loops
    assert len(stability_tests_made(tree)) == tests
