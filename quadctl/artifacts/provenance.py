"""What made an artifact: the software versions and the C compiler, read cheaply, once per process.

:func:`quadctl.artifacts.metadata` is the one place that puts these into an artifact; this module
only finds them. Versions come from the installed packages' metadata (``importlib.metadata``),
never by importing SciPy or CasADi (``quadctl simulate`` on fresh artifacts imports neither). The
compiler is asked for its version only when a stage ran a compiled loop, once per process.
"""

from __future__ import annotations

import platform
import subprocess
from functools import lru_cache

from quadctl.native.compile import find_compiler
from quadctl.version import __version__

PACKAGES = ("numpy", "scipy", "casadi")
"""Distributions whose versions every artifact records (with quadctl's and Python's)."""
NOT_USED = "not used"
"""``compiler`` of an artifact whose stage ran no closed loop."""
INTERPRETED = "none"
"""``compiler`` when the loop ran in CasADi's virtual machine (no working C compiler)."""
COMPILER_TIMEOUT = 10.0
"""s to wait for ``<compiler> --version`` (it answers in milliseconds)."""


def software() -> dict[str, str]:
    """Versions of quadctl, Python, NumPy, SciPy and CasADi (``"not installed"`` if one is missing).

    Returns
    -------
    dict
        ``{"quadctl": "0.1.0", "python": "3.11.9", "numpy": ..., "scipy": ..., "casadi": ...}``.

    Examples
    --------
    >>> sorted(software())
    ['casadi', 'numpy', 'python', 'quadctl', 'scipy']
    """
    return dict(_software())


@lru_cache(maxsize=1)
def _software() -> dict[str, str]:
    from importlib import metadata

    found = {"quadctl": __version__, "python": platform.python_version()}
    for name in PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "not installed"
    return found


def compiler(backends=()) -> dict[str, str] | str:
    """The C compiler behind the loops a stage ran.

    Parameters
    ----------
    backends : str or iterable of str
        The simulation backends the stage used (``SimResult.backend``: ``"compiled"``,
        ``"compiled-simd"``, ``"casadi"``); empty when it ran no closed loop.

    Returns
    -------
    dict or str
        ``{"path": ..., "version": ...}`` (the first line of ``<path> --version``) when a loop
        was compiled; :data:`INTERPRETED` (``"none"``) when every loop ran in CasADi's virtual
        machine; :data:`NOT_USED` when no loop ran.
    """
    backends = {backends} if isinstance(backends, str) else set(backends)
    if not backends:
        return NOT_USED
    if not any(b.startswith("compiled") for b in backends):
        return INTERPRETED

    path = find_compiler()
    if path is None:  # QUADCTL_NO_COMPILE set after the library was loaded: the loop still ran compiled
        return {"path": "unknown", "version": "unknown"}
    return {"path": path, "version": compiler_version(path)}


@lru_cache(maxsize=8)
def compiler_version(path: str) -> str:
    """First line of ``<path> --version``, asked once per process (``"unknown (...)"`` if it fails)."""
    try:
        proc = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=COMPILER_TIMEOUT)
    except (OSError, subprocess.SubprocessError) as exc:
        return f"unknown ({type(exc).__name__})"
    lines = (proc.stdout or proc.stderr or "").strip().splitlines()
    return lines[0].strip() if lines else f"unknown (exit {proc.returncode}, no output)"
