"""The public face: ``import quadctl as qc`` and the names of ``qc.__all__``, each importable, each
documented with an example, each the one implementation in its module; and ``qc.lqr``, ``qc.dlqr``,
``qc.lqrd`` against the closed forms of a scalar integrator."""

from __future__ import annotations

import importlib
import inspect
import math
import pkgutil
import re
import subprocess
import sys

import pytest
from _paths import ROOT

import quadctl as qc


def _sections(doc: str) -> set[str]:
    """numpydoc section titles of a docstring (a line underlined with dashes)."""
    return set(re.findall(r"^(\w[\w ]*)\n-{3,}$", doc, re.M))


def missing_docs(obj) -> list[str]:
    """What a public object's docstring lacks: a summary, an example (``Examples`` with ``>>>``) and,
    for a function, its ``Parameters`` and ``Returns``."""
    doc = inspect.cleandoc(obj.__doc__ or "")  # its own: not one inherited from a base class
    sections = _sections(doc)
    out = [] if doc.split("\n", 1)[0].strip() else ["a docstring"]
    if "Examples" not in sections or ">>>" not in doc.split("Examples", 1)[1]:
        out.append("an example")
    if inspect.isfunction(obj):
        out += [s for s in ("Parameters", "Returns") if s not in sections]
    return out


def test_all_is_the_table_the_names_load_from():
    assert len(set(qc.__all__)) == len(qc.__all__)
    assert set(qc.__all__) == set(qc._PUBLIC)


def test_no_public_name_is_also_a_submodule():
    """``import quadctl.x`` sets the package's attribute ``x`` to the module: a public function named
    like a submodule would become that module as soon as anything imported it."""
    submodules = {m.name for m in pkgutil.iter_modules(qc.__path__)}
    assert set(qc.__all__) & submodules == set()


@pytest.mark.parametrize("name", qc.__all__)
def test_each_public_name_imports_and_is_documented_with_an_example(name):
    obj = getattr(qc, name)
    module, attr = qc._PUBLIC[name]
    assert obj is getattr(importlib.import_module(module), attr)  # the one implementation, not a copy
    assert missing_docs(obj) == [], f"qc.{name}'s docstring lacks {', '.join(missing_docs(obj))}"


def _bare(x):
    """Summary only."""


def _no_example(x):
    """Summary.

    Parameters
    ----------
    x : int

    Returns
    -------
    int
    """


class _Undocumented:
    pass


@pytest.mark.parametrize("obj, missing", [
    (_bare, ["an example", "Parameters", "Returns"]),
    (_no_example, ["an example"]),
    (_Undocumented, ["a docstring", "an example"]),
    (qc._PUBLIC.get, ["an example"]),  # a builtin: not a Python function, so no sections asked
])
def test_the_docstring_check_finds_what_is_missing(obj, missing):
    assert missing_docs(obj) == missing


def test_dir_lists_the_public_face_and_no_helper_of_the_package():
    """Tab completion shows ``qc.lqr``, not the ``importlib`` or ``TYPE_CHECKING`` the package imports for
    itself, nor a submodule some earlier import bound as an attribute."""
    importlib.import_module("quadctl.version")
    shown = {n for n in dir(qc) if not n.startswith("__")}
    assert shown == set(qc.__all__)
    assert "__version__" in dir(qc)


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match=r"^module 'quadctl' has no attribute 'lqrr'$"):
        qc.lqrr  # noqa: B018


def test_import_quadctl_loads_no_heavy_library_until_a_name_is_used():
    code = ("import sys, quadctl as qc\n"
            "heavy = ('numpy', 'scipy', 'casadi', 'matplotlib', 'pydantic')\n"
            "print(sorted(m for m in heavy if m in sys.modules))\n"
            "qc.lqr\n"
            "print(sorted(m for m in ('numpy', 'casadi') if m in sys.modules), 'lqr' in vars(qc))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.splitlines() == ["[]", "['numpy'] True"]


# ---------------------------------------------------------------------------------------
# The scalar integrator, in closed form


@pytest.mark.parametrize("q, r", [(1.0, 1.0), (4.0, 1.0), (1e-2, 25.0), (300.0, 1e-3)])
def test_lqr_of_the_scalar_integrator_is_its_closed_form(q, r):
    """``x' = u``: the CARE ``q - S^2 / r = 0`` gives ``S = sqrt(q r)``, ``K = S / r = sqrt(q / r)``
    and the closed-loop pole ``-K``."""
    K, S, E = qc.lqr([[0.0]], [[1.0]], [[q]], [[r]])
    assert S[0, 0] == pytest.approx(math.sqrt(q * r), rel=1e-12)
    assert K[0, 0] == pytest.approx(math.sqrt(q / r), rel=1e-12)
    assert E[0] == pytest.approx(-math.sqrt(q / r), rel=1e-12)


@pytest.mark.parametrize("q, r", [(1.0, 1.0), (4.0, 1.0), (1e-2, 25.0), (300.0, 1e-3)])
def test_dlqr_of_the_scalar_sum_is_its_closed_form(q, r):
    """``x+ = x + u``: the DARE ``S = q + S - S^2 / (r + S)`` is ``S^2 - q S - q r = 0``, so
    ``S = (q + sqrt(q^2 + 4 q r)) / 2``, ``K = S / (r + S)`` and the pole ``z = 1 - K``."""
    S_exact = (q + math.sqrt(q * q + 4 * q * r)) / 2
    K, S, E = qc.dlqr([[1.0]], [[1.0]], [[q]], [[r]])
    assert S[0, 0] == pytest.approx(S_exact, rel=1e-12)
    assert K[0, 0] == pytest.approx(S_exact / (r + S_exact), rel=1e-12)
    assert E[0] == pytest.approx(1 - S_exact / (r + S_exact), rel=1e-12)


@pytest.mark.parametrize("q, r, Ts", [(1.0, 1.0, 0.1), (4.0, 1.0, 0.01), (300.0, 1e-3, 0.005), (1.0, 1.0, 2.0)])
def test_lqrd_of_the_scalar_integrator_is_its_closed_form(q, r, Ts):
    """``x' = u`` held for ``Ts``: ``Ad = 1``, ``Bd = Ts`` and the continuous cost over a sample,
    ``Qd = q Ts``, ``Rd = r Ts + q Ts^3 / 3``, ``Nd = q Ts^2 / 2``. The DARE's linear term then
    vanishes: ``Ts^2 S^2 = Qd Rd - Nd^2``, so ``S = sqrt(q r + q^2 Ts^2 / 12)`` (``sqrt(q r)`` as
    ``Ts -> 0``) and ``K = (S + q Ts / 2) / (r + q Ts^2 / 3 + Ts S)``."""
    S_exact = math.sqrt(q * r + q * q * Ts * Ts / 12)
    K_exact = (S_exact + q * Ts / 2) / (r + q * Ts * Ts / 3 + Ts * S_exact)
    K, S, E = qc.lqrd([[0.0]], [[1.0]], [[q]], [[r]], Ts)
    assert S[0, 0] == pytest.approx(S_exact, rel=1e-10)
    assert K[0, 0] == pytest.approx(K_exact, rel=1e-10)
    assert E[0] == pytest.approx(1 - Ts * K_exact, rel=1e-10)


# ---------------------------------------------------------------------------------------
# The README's Python section


def _readme_python_section() -> list[str]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = re.split(r"\n#+ ", re.split(r"\n#+ From Python\n", text, maxsplit=1)[1], maxsplit=1)[0]
    return re.findall(r"```python\n(.*?)```", section, re.S)


def test_the_readmes_python_section_runs(tmp_path, monkeypatch, capsys):
    """Its block runs as written, on the public face, and prints what its comments say."""
    blocks = _readme_python_section()
    assert blocks and blocks[0].startswith("import quadctl as qc\n")
    monkeypatch.chdir(tmp_path)
    names: dict = {}
    for code in blocks:
        exec(compile(code, "README.md (From Python)", "exec"), names)
    assert names["K"].round(2).tolist() == [[7.07, 3.89]]  # "[[7.07 3.89]]"
    assert names["stages"].design.K_block.shape == (4, 12)  # "the (4, 12) gain, discrete at 5 ms"
    assert names["stages"].design.sample_time == pytest.approx(0.005)
    assert names["run"].status == "ok" and names["run"].x.shape[1] == 12
    assert "[[7.07 3.89]]" in capsys.readouterr().out


# ---------------------------------------------------------------------------------------
# What a refused call raises is in its docstring's Raises


def _raises_section(obj) -> str:
    doc = inspect.cleandoc(obj.__doc__ or "")
    found = re.search(r"^Raises\n-{3,}\n(.*?)(?:\n\n\w[\w ]*\n-{3,}\n|\Z)", doc, re.M | re.S)
    return found.group(1) if found else ""


@pytest.mark.parametrize("name, call", [
    ("lqr", lambda: qc.lqr([[0.0]], [[1.0, 0.0]], [[1.0]], [[1.0]])),           # B of two inputs, R of one
    ("lqr", lambda: qc.lqr([[0.0]], [[1.0]], [[1.0]], [[1j]])),
    ("dlqr", lambda: qc.dlqr([[1.0]], [[1.0]], [[1.0, 0.0]], [[1.0]])),
    ("dlqr", lambda: qc.dlqr([[2.0]], [[0.0]], [[1.0]], [[1.0]])),              # no input reaches z = 2
    ("lqrd", lambda: qc.lqrd([[0.0]], [[1.0]], [[1.0]], [[1.0]], -0.1)),
    ("lqrd", lambda: qc.lqrd([[0.0]], [[1.0]], "Q", [[1.0]], 0.1)),
    ("trim", lambda: qc.trim([1.0, 0.0], 0.0, [0, 0, 0], qc.Vehicle())),
    ("linearize", lambda: qc.linearize([0.0] * 11, [0.6, 0, 0, 0], qc.Vehicle())),
])
def test_a_refused_call_raises_what_its_docstring_lists(name, call):
    """qc.lqr and qc.dlqr listed only DesignError, and lqrd an ArgumentError only for Ts, while a matrix
    of the wrong shape or kind raises qc.ArgumentError."""
    with pytest.raises(qc.QuadctlError) as info:
        call()
    assert type(info.value).__name__ in _raises_section(getattr(qc, name)), (name, type(info.value).__name__)


def test_results_of_arrays_compare_by_identity_and_can_be_keys():
    """Two results solved alike are two results: ``==`` says whether they are the same one (NumPy's
    element-wise ``==`` of their arrays made it raise), and each can key a dict."""
    import numpy as np

    A, B = [[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]]
    a, b = (qc.lqr(A, B, np.eye(2), [[1.0]]) for _ in range(2))
    assert a == a and a != b and not (a == b)
    assert len({a: 1, b: 2}) == 2
    stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    for result in (stages.trim, stages.linear, stages.design, stages.decoupled, stages.loop, stages.setup,
                   *stages.margins):
        assert result == result and {result: 0}[result] == 0
