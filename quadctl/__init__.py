"""quadctl: trim, linearize, decouple, check, design and simulate LQR controllers for quadcopters.

``import quadctl as qc`` is the public face, python-control-like; each name in :data:`__all__` is
documented with an example:

- a config and the problem it makes: :func:`load_config` (:class:`Config`), :func:`setup_of`
  (:class:`Setup`)
- the stages of a setup, each computed once: :class:`Stages` (``trim``, ``linear``, ``decoupled``,
  ``design``, ``loop``)
- the steps on any system: :func:`trim` (:class:`Trim` of a :class:`Vehicle`), :func:`linearize`
  (:class:`LinearModel`), :func:`lqr`, :func:`dlqr`, :func:`lqrd` (:class:`LqrResult`, MATLAB
  conventions), :func:`margins` (:class:`LoopMargins` of a :class:`Design`), :func:`simulate`
  (:class:`SimResult` of a :class:`ClosedLoop`)
- the errors: :class:`QuadctlError`, and the :class:`ConfigError`, :class:`TrimError`,
  :class:`DesignError`, :class:`ArgumentError` (a ``ValueError``) and :class:`ArgumentTypeError`
  (a ``TypeError``) it divides into

>>> import quadctl as qc
>>> K, S, E = qc.lqr([[0.0]], [[1.0]], [[4.0]], [[1.0]])  # x' = u: S = sqrt(Q R), K = sqrt(Q / R)
>>> round(float(S[0, 0]), 12), round(float(K[0, 0]), 12), round(float(E[0].real), 12)
(2.0, 2.0, -2.0)

Each name loads its module on first use, so ``import quadctl`` (and ``quadctl --help``) pays for
none of numpy, SciPy or CasADi. The command line (:mod:`quadctl.cli`) is a thin layer over this
library, which never imports it; the package's floors are drawn in ``docs/architecture.md``.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from quadctl.version import __version__ as __version__

_PUBLIC = {
    "load_config": ("quadctl.config.loading", "load"),
    "Config": ("quadctl.config.schema", "Config"),
    "setup_of": ("quadctl.setup", "setup_of"),
    "Setup": ("quadctl.setup", "Setup"),
    "Stages": ("quadctl.pipeline", "Stages"),
    "Vehicle": ("quadctl.physics.model", "Vehicle"),
    "trim": ("quadctl.linear.trim", "solve_trim"),
    "Trim": ("quadctl.linear.trim", "Trim"),
    "linearize": ("quadctl.linear.linearize", "linearize"),
    "LinearModel": ("quadctl.linear.linearize", "LinearModel"),
    "lqr": ("quadctl.design.decoupled", "lqr"),
    "dlqr": ("quadctl.design.discrete", "dlqr"),
    "lqrd": ("quadctl.design.discrete", "lqrd"),
    "LqrResult": ("quadctl.design.riccati", "LqrResult"),
    "Design": ("quadctl.design.decoupled", "Design"),
    "margins": ("quadctl.design.margin_findings", "all_margins"),
    "LoopMargins": ("quadctl.design.margins", "LoopMargins"),
    "simulate": ("quadctl.sim.run", "simulate"),
    "ClosedLoop": ("quadctl.sim.loop", "ClosedLoop"),
    "SimResult": ("quadctl.sim.run", "SimResult"),
    "QuadctlError": ("quadctl.errors", "QuadctlError"),
    "ConfigError": ("quadctl.errors", "ConfigError"),
    "TrimError": ("quadctl.errors", "TrimError"),
    "DesignError": ("quadctl.errors", "DesignError"),
    "ArgumentError": ("quadctl.errors", "ArgumentError"),
    "ArgumentTypeError": ("quadctl.errors", "ArgumentTypeError"),
}
"""Public name -> (the module that defines it, its name there): loaded on first use."""

__all__ = [
    "load_config", "Config", "setup_of", "Setup", "Stages", "Vehicle", "trim", "Trim", "linearize", "LinearModel",
    "lqr", "dlqr", "lqrd", "LqrResult", "Design", "margins", "LoopMargins", "simulate", "ClosedLoop", "SimResult",
    "QuadctlError", "ConfigError", "TrimError", "DesignError", "ArgumentError", "ArgumentTypeError",
]
"""The public face: the names of :data:`_PUBLIC` (a test keeps the two equal)."""


def __getattr__(name: str):
    """A public name, its module imported on first use (then kept as an attribute)."""
    try:
        module, attr = _PUBLIC[name]
    except KeyError:
        raise AttributeError(f"module 'quadctl' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The public face and the module's dunders (``__version__``): not the names this file imports for itself
    (``importlib``, ``TYPE_CHECKING``, ``annotations``) nor the submodules loaded so far."""
    return sorted({n for n in globals() if n.startswith("__") and n.endswith("__")} | set(__all__))


if TYPE_CHECKING:  # what type checkers and editors see: the same names, imported at once
    from quadctl.config.loading import load as load_config
    from quadctl.config.schema import Config
    from quadctl.design.decoupled import Design, lqr
    from quadctl.design.discrete import dlqr, lqrd
    from quadctl.design.margin_findings import all_margins as margins
    from quadctl.design.margins import LoopMargins
    from quadctl.design.riccati import LqrResult
    from quadctl.errors import ArgumentError, ArgumentTypeError, ConfigError, DesignError, QuadctlError, TrimError
    from quadctl.linear.linearize import LinearModel, linearize
    from quadctl.linear.trim import Trim
    from quadctl.linear.trim import solve_trim as trim
    from quadctl.physics.model import Vehicle
    from quadctl.pipeline import Stages
    from quadctl.setup import Setup, setup_of
    from quadctl.sim.loop import ClosedLoop
    from quadctl.sim.run import SimResult, simulate
