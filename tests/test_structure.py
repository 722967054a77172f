"""Architecture rules that keep the tool quick and the core reusable."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import quadctl

PACKAGE = Path(quadctl.__file__).parent


def test_help_imports_no_heavy_library():
    """`quadctl --help` must not pay for numpy, scipy, casadi or matplotlib."""
    code = ("import sys, quadctl.cli.app; "
            "print(sorted(m for m in ('numpy', 'scipy', 'casadi', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


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
