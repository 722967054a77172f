"""A validated sweep as data: its parameters (:class:`Parameter`), its cases (:class:`Case`) and the
whole sweep (:class:`SweepSpec`: mode, values, ``set:``, gates), which lists its cases and hashes itself.

:mod:`quadctl.sweep.sweep_file` makes one from a sweep file.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from quadctl.sweep.gates import Gate
from quadctl.version import __version__


@dataclass(frozen=True)
class Parameter:
    """One varied config value.

    Attributes
    ----------
    path : str
        The key path as written (``lqr.roll.Q[1]``).
    keys : tuple
        The path parsed: names (str) and list indices (int).
    kind : {"values", "range", "distribution"}
    spec : list or dict
        The values, the range or the distribution as given.
    """

    path: str
    keys: tuple
    kind: str
    spec: Any

    def size(self) -> int:
        """How many values a grid takes from this parameter (without listing them)."""
        return len(self.spec) if self.kind == "values" else int(self.spec["num"])

    def grid_values(self) -> list:
        """The values a grid takes (lists as given, ranges expanded)."""
        if self.kind == "values":
            return list(self.spec)
        lo, hi, num = self.spec["from"], self.spec["to"], int(self.spec["num"])
        if self.spec.get("scale", "linear") == "log":
            values = np.geomspace(lo, hi, num)
        else:
            values = np.linspace(lo, hi, num)
        return [float(v) for v in values]

    def sample(self, rng: np.random.Generator, n: int) -> list:
        """``n`` random values (random mode)."""
        spec = self.spec
        if self.kind == "values":
            return [spec[i] for i in rng.integers(0, len(spec), n)]
        if self.kind == "range":
            lo, hi = float(spec["from"]), float(spec["to"])
            if spec.get("scale", "linear") == "log":
                return [float(v) for v in np.exp(rng.uniform(math.log(lo), math.log(hi), n))]
            return [float(v) for v in rng.uniform(lo, hi, n)]
        kind = spec["distribution"]
        if kind == "uniform":
            values = rng.uniform(spec["low"], spec["high"], n)
        elif kind == "loguniform":
            values = np.exp(rng.uniform(math.log(spec["low"]), math.log(spec["high"]), n))
        elif kind == "normal":
            values = rng.normal(spec["mean"], spec["std"], n)
        else:  # choice
            return [spec["values"][i] for i in rng.integers(0, len(spec["values"]), n)]
        return [float(v) for v in values]


@dataclass(frozen=True)
class Case:
    """One case: its number and the value of each parameter (in the sweep file's order)."""

    index: int
    values: tuple


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep file.

    Attributes
    ----------
    label : str
        The file, for messages.
    mode : {"grid", "random"}
    samples : int or None
    seed : int
    parameters : tuple of Parameter
    fixed : tuple
        ``set:`` values every case gets, each ``(path, keys, value)``.
    gates : tuple of Gate
    require_ok : bool
        A case that fails to design, is unstable on the coupled model or does not simulate to
        the end fails the sweep even without gates.
    chunk_size : int or None
    canonical : dict
        The file's content, normalized (what the sweep digest hashes).
    """

    label: str
    mode: str
    samples: int | None
    seed: int
    parameters: tuple[Parameter, ...]
    fixed: tuple[tuple[str, tuple, Any], ...]
    gates: tuple[Gate, ...]
    require_ok: bool
    chunk_size: int | None
    canonical: dict
    uncertainty: bool = False
    """Every parameter is :func:`~quadctl.sweep.uncertainty.plant_side`: one design, many vehicles (see
    :attr:`monte_carlo`)."""
    metrics: tuple[str, ...] = ()
    """The metric columns (:func:`quadctl.sweep.gates.metric_columns`) of the config the cases start
    from (:func:`quadctl.sweep.sweep_file.configured`): a mission that ``set:`` gives adds its tracking columns."""
    parameter_units: tuple[tuple[str, str], ...] = ()
    """``(key path, unit)`` of each parameter that has a unit (:func:`quadctl.config.key_units.key_unit` on the
    config the cases start from), in file order; a seed, a count or a share has none."""

    @property
    def names(self) -> list[str]:
        """The parameters' key paths (the first columns of the table)."""
        return [p.path for p in self.parameters]

    @property
    def monte_carlo(self) -> bool:
        """An uncertainty study: every parameter is :func:`~quadctl.sweep.uncertainty.plant_side` (the
        noise seed, mass and inertia errors of the simulated vehicle, the rotor lag it ignores, the delay, ...), so its
        cases share one design and differ only in the vehicle they fly; each keeps its trajectory
        for the bands (``montecarlo.npz``). ``set:`` values apply to all."""
        return self.uncertainty

    def count(self) -> int:
        """Number of cases."""
        if self.mode == "random":
            return int(self.samples)
        return math.prod(p.size() for p in self.parameters)

    def cases(self) -> list[Case]:
        """Every case, numbered from 0: the grid in file order (first key slowest), or ``samples``
        random draws (one stream per parameter, in file order, from ``seed``)."""
        if self.mode == "grid":
            grids = [p.grid_values() for p in self.parameters]
            mesh = np.stack(np.meshgrid(*[np.arange(len(g)) for g in grids], indexing="ij"), -1)
            flat = mesh.reshape(-1, len(grids))
            return [Case(i, tuple(g[j] for g, j in zip(grids, row))) for i, row in enumerate(flat.tolist())]
        rng = np.random.default_rng(self.seed)
        columns = [p.sample(rng, int(self.samples)) for p in self.parameters]
        return [Case(i, tuple(col[i] for col in columns)) for i in range(int(self.samples))]

    def digest(self, cfg) -> str:
        """sha256 of the config, the sweep and the quadctl version: what a resumed sweep must match."""
        text = json.dumps({"config": cfg.digest(), "sweep": self.canonical, "quadctl": __version__},
                          sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()
