"""What the package ships beside its modules: the typing marker and the package data it reads."""

from __future__ import annotations

import re
import sys
from importlib import resources
from pathlib import Path

import pytest
from _paths import ROOT


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


def test_the_bundled_configs_live_once_at_the_top_of_the_repository():
    """configs/ holds them; the package folder does not (the wheel's build step copies them in)."""
    from quadctl import config

    names = sorted(p.stem for p in (ROOT / "configs").glob("*.yaml"))
    assert names and names == config.bundled_names()
    assert not (ROOT / "quadctl" / "configs").exists()


def _built_wheel(tmp_path: Path) -> Path:
    """A wheel of the checkout, built from a copy of its sources (the checkout gets no build/ folder)."""
    import shutil
    import subprocess

    source = tmp_path / "source"
    source.mkdir()
    for name in ("pyproject.toml", "setup.py", "MANIFEST.in", "LICENSE", "README.md"):
        shutil.copy(ROOT / name, source / name)
    for name in ("quadctl", "configs"):
        shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    res = subprocess.run([sys.executable, "-m", "pip", "wheel", str(source), "--no-deps",
                          "-q", "-w", str(tmp_path / "wheel")], capture_output=True, text=True, timeout=300)
    if res.returncode != 0 and re.search(r"No matching distribution|Could not find a version|NewConnectionError",
                                         res.stderr):  # the build's isolated setuptools comes from the index
        pytest.skip(f"cannot build a wheel here (no package index): {res.stderr.strip().splitlines()[-1]}")
    assert res.returncode == 0, res.stderr
    return next((tmp_path / "wheel").glob("quadctl-*.whl"))


@pytest.mark.slow
def test_a_wheel_carries_and_runs_every_bundled_config(tmp_path):
    """Installed from a wheel (its files unpacked on the path, away from any checkout), quadctl lists
    the bundled configs, each as the repository's configs/ holds it, and trims each by name."""
    import subprocess
    import zipfile

    from quadctl import config

    wheel = _built_wheel(tmp_path)
    site = tmp_path / "site"
    with zipfile.ZipFile(wheel) as z:
        z.extractall(site)
    for path in (ROOT / "configs").glob("*.yaml"):
        assert (site / "quadctl" / "configs" / path.name).read_bytes() == path.read_bytes(), path.name
    env = {**__import__("os").environ, "PYTHONPATH": str(site), "COLUMNS": "200"}
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()

    def quadctl(*args):
        return subprocess.run([sys.executable, "-m", "quadctl", *args], cwd=elsewhere, env=env, capture_output=True,
                              text=True, timeout=300)

    where = quadctl("--version")  # the unpacked wheel's package, not the checkout's
    assert where.returncode == 0
    listed = quadctl("configs")
    assert listed.returncode == 0, listed.stderr
    for name in config.bundled_names():
        assert name in listed.stdout
        ran = quadctl("trim", "-c", name, "-o", str(tmp_path / "runs" / name))
        assert ran.returncode == 0, f"{name}: {ran.stdout}{ran.stderr}"
    import_path = subprocess.run([sys.executable, "-c", "import quadctl; print(quadctl.__file__)"], cwd=elsewhere,
                                 env=env, capture_output=True, text=True).stdout
    assert import_path.startswith(str(site)), import_path
