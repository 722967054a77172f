"""What the package ships beside its modules: the typing marker and the package data it reads."""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _package_data() -> list[str]:
    if sys.version_info < (3, 11):
        pytest.skip("tomllib is Python 3.11+")
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["quadctl"]


def test_the_package_is_marked_typed():
    assert (resources.files("quadctl") / "py.typed").is_file()
    assert "py.typed" in _package_data()


def test_package_data_covers_every_data_file_the_package_reads():
    package = ROOT / "quadctl"
    data = {p.relative_to(package).as_posix() for p in package.rglob("*")
            if p.is_file() and p.suffix not in (".py", ".pyc") and "__pycache__" not in p.parts}
    patterns = _package_data()
    uncovered = sorted(f for f in data if not any(Path(f).match(pattern) for pattern in patterns))
    assert uncovered == []
