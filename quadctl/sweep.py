"""Sweeps: many designs of one config, varied by key path, with metrics, gates and executors.

A sweep file names config values to vary by their key path (``lqr.roll.Q[1]``,
``vehicle.mass``), each as a list, a range or (random mode) a distribution, and gates on the
metrics of every case. Each case is the base config with those values put in, validated again
by :func:`quadctl.config.from_dict`, so every case is a valid config or a row that says why not.

Per case: trim, linearize, decouple, LQR design, the coupled closed-loop eigenvalues, a nonlinear
RK4 simulation and its metrics. Cases run in chunks, on local processes or a Dask cluster, and
a chunk computes its cases together: the small Riccati equations in one batched solve
(:func:`quadctl.batch.care`), the simulations :data:`~quadctl.batch_codegen.LANES` at a time in
SIMD code generated from the CasADi model (:mod:`quadctl.batch_codegen`). A config that uses
features the batched path does not model (anything beyond the plain continuous LQR loop) runs
each case through :mod:`quadctl.pipeline` instead: slower, the same answers.

The sweep file::

    mode: grid                  # or random (then samples and seed)
    samples: 1000               # random mode: number of cases
    seed: 1                     # random mode: the same seed gives the same cases
    parameters:                 # key path -> values
      lqr.roll.Q[1]: [10, 50, 100]                                  # a list
      lqr.altitude.R[0]: {from: 0.1, to: 10, num: 5, scale: log}   # a range (scale: linear or log)
      vehicle.mass: {distribution: normal, mean: 0.068, std: 0.003} # random mode only
    set:                        # optional: values every case gets
      simulation.duration: 5.0
    gates:                      # metric -> {min, max} (or {equals} for stable and status)
      settling_time.pD: {max: 3.0}
      peak.T: {max: 1.5}
    require_ok: true            # a case must also design, be stable and simulate to the end
    chunk_size: 32              # optional: cases per task

Distributions (random mode): ``uniform {low, high}``, ``loguniform {low, high}``,
``normal {mean, std}``, ``choice {values}``. In random mode a list is a uniform choice and a
range is sampled uniformly on ``[from, to]`` (log-uniformly with ``scale: log``).

A sweep whose only parameter is ``simulation.noise.seed`` is a Monte Carlo
(:attr:`SweepSpec.monte_carlo`): every case also keeps the deviation of its regulated states from
the reference on a common grid of :data:`MC_POINTS` times, and the run directory gets
``montecarlo.png`` and ``montecarlo.npz``, the percentile bands of those deviations against time
(:func:`montecarlo_bands`).
"""

from __future__ import annotations

import base64
import csv
import difflib
import hashlib
import io
import json
import math
import multiprocessing
import os
import re
import signal
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from quadctl import __version__
from quadctl.errors import ConfigError, DesignError, QuadctlError, StepSizeError, SweepError, TrimError
from quadctl.layout import INPUT_INDEX, INPUT_NAMES, N_INPUTS, N_STATES, STATE_INDEX, STATE_NAMES, unit_of

MODES = ("grid", "random")
DISTRIBUTIONS = {
    "uniform": ("low", "high"),
    "loguniform": ("low", "high"),
    "normal": ("mean", "std"),
    "choice": ("values",),
}
"""Distribution name -> its required keys (random mode)."""
TOP_KEYS = ("mode", "samples", "seed", "parameters", "set", "gates", "require_ok", "chunk_size",
            "description")
RANGE_KEYS = ("from", "to", "num", "scale")
GATE_KEYS = ("min", "max", "equals")
FREE_MAPPINGS = (("simulation", "initial_offset"),)
"""Config mappings whose keys are free (state names): a sweep may add a key there."""
MAX_CASES = 1_000_000
"""A grid larger than this is refused (use random mode with ``samples``)."""
MC_PARAMETER = ("simulation", "noise", "seed")
"""The key path a Monte Carlo varies, and the only one (see :attr:`SweepSpec.monte_carlo`)."""
MC_POINTS = 201
"""A Monte Carlo case keeps its regulated states at this many evenly spaced times (float32): with
the ten regulated states of ``mambo-200hz``, 8 kB a case in memory and in the journal, whatever the
duration and step (10 000 seeds: 80 MB). At 10 s, a point every 50 ms."""
MC_PERCENTILES = (5, 25, 50, 75, 95)
"""The percentiles a Monte Carlo reports at every time (the bands 5-95 and 25-75, the median)."""
PARTS = "sweep.parts"
"""Folder of the run directory holding the finished chunks (the journal ``--resume`` reads)."""
WORST_SHOWN = 10
BEST_SHOWN = 5

_PATH_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\[\d+\])*(\.[A-Za-z_][A-Za-z0-9_]*(\[\d+\])*)*$")


# ---------------------------------------------------------------------------------------
# The sweep file


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
class Gate:
    """A threshold on one metric: ``min <= value <= max``, or ``value == equals``."""

    metric: str
    min: float | None = None
    max: float | None = None
    equals: Any = None

    def passes(self, value) -> bool:
        """A missing value (never settled, no design) fails every gate."""
        if self.equals is not None:
            return value == self.equals
        if value is None or isinstance(value, (bool, str)):
            return False
        if self.min is not None and not value >= self.min:
            return False
        if self.max is not None and not value <= self.max:
            return False
        return True

    def slack(self, value) -> float:
        """How far inside the gate ``value`` is, relative to the threshold (negative: outside)."""
        if self.equals is not None:
            return 0.0 if value == self.equals else -math.inf
        if value is None or isinstance(value, (bool, str)) or not math.isfinite(value):
            return -math.inf
        slack = math.inf
        for bound, sign in ((self.max, 1.0), (self.min, -1.0)):
            if bound is not None:
                slack = min(slack, sign * (bound - value) / max(abs(bound), 1e-12))
        return slack

    def describe(self) -> str:
        if self.equals is not None:
            return f"{self.metric} == {json.dumps(self.equals)}"
        parts = ([f"{self.min:g} <="] if self.min is not None else []) + [self.metric] + \
                ([f"<= {self.max:g}"] if self.max is not None else [])
        return " ".join(parts)


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
    fixed : tuple of (path, keys, value)
        ``set:`` values every case gets.
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

    @property
    def names(self) -> list[str]:
        """The parameters' key paths (the first columns of the table)."""
        return [p.path for p in self.parameters]

    @property
    def monte_carlo(self) -> bool:
        """A Monte Carlo: the sweep varies the noise seed (``simulation.noise.seed``) and nothing
        else, so its cases differ only in the noise each run draws. ``set:`` values apply to all."""
        return all(p.keys == MC_PARAMETER for p in self.parameters)

    def count(self) -> int:
        """Number of cases."""
        if self.mode == "random":
            return int(self.samples)
        return int(np.prod([len(p.grid_values()) for p in self.parameters], dtype=object))

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


def load(path: str | Path, cfg) -> SweepSpec:
    """Read and validate a sweep file against the config it varies.

    Raises
    ------
    SweepError
        One line naming the file, the key and the fix.
    """
    path = Path(path)
    if path.is_dir():
        raise SweepError(f"{path}: is a folder, not a sweep file; give a .yaml file")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SweepError(f"{path}: no such sweep file; check the path") from None
    except (OSError, UnicodeDecodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise SweepError(f"{path}: cannot read the sweep file ({reason}); check the file") from None
    return parse(text, cfg, str(path))


def parse(text: str, cfg, label: str = "<sweep>") -> SweepSpec:
    """Validate YAML text as a sweep file; ``label`` names it in errors."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise SweepError(f"{label}: YAML syntax error{where}: {problem}; fix the YAML") from None
    return from_dict(data, cfg, label)


def from_dict(data: Any, cfg, label: str = "<sweep>") -> SweepSpec:
    """Validate a mapping (as YAML gives it) as a sweep of ``cfg``."""

    def fail(where: str, why: str) -> SweepError:
        return SweepError(f"{label}: {where}: {why}")

    if not isinstance(data, dict):
        kind = "empty" if data is None else f"a {type(data).__name__}"
        raise SweepError(f"{label}: the sweep file is {kind}, not a mapping; "
                         "give at least `parameters:` (see examples/ci-sweep.yaml)")
    for key in data:
        if key not in TOP_KEYS:
            raise fail(str(key), "unknown key; " + _hint(str(key), TOP_KEYS))
    mode = data.get("mode", "grid")
    if mode not in MODES:
        raise fail("mode", f"{_show(mode)} is not a mode; use grid or random")
    samples = data.get("samples")
    if mode == "random":
        if samples is None:
            raise fail("samples", "random mode needs the number of cases; add `samples: 100`, say")
    if samples is not None and (not _is_int(samples) or samples < 1):
        raise fail("samples", f"{_show(samples)}: must be a whole number >= 1")
    seed = data.get("seed", 0)
    if not _is_int(seed) or seed < 0:
        raise fail("seed", f"{_show(seed)}: must be a whole number >= 0")
    chunk = data.get("chunk_size")
    if chunk is not None and (not _is_int(chunk) or chunk < 1):
        raise fail("chunk_size", f"{_show(chunk)}: must be a whole number >= 1")
    require_ok = data.get("require_ok", True)
    if not isinstance(require_ok, bool):
        raise fail("require_ok", f"{_show(require_ok)}: must be true or false")

    base = cfg.model_dump(mode="json")
    params = data.get("parameters")
    if not isinstance(params, dict) or not params:
        raise fail("parameters", "nothing to vary; add at least one key path, "
                   "such as `lqr.roll.Q[1]: [10, 50, 100]`")
    parameters = []
    for path, spec in params.items():
        keys = check_path(base, str(path), label, "parameters")
        kind = _check_values(spec, str(path), mode, label)
        leaf = _lookup(base, keys)
        if isinstance(leaf, list) and kind != "values":
            raise fail(f"parameters.{path}", f"is a list ({_show(leaf)}) here, a range gives numbers; "
                       f"index one entry, as `{path}[0]`")
        parameters.append(Parameter(str(path), keys, kind, spec))
    fixed = []
    sets = data.get("set") or {}
    if not isinstance(sets, dict):
        raise fail("set", "must be a mapping of key path -> value")
    for path, value in sets.items():
        keys = check_path(base, str(path), label, "set")
        if str(path) in params:
            raise fail(f"set.{path}", "is also a parameter; keep it in one place")
        fixed.append((str(path), keys, value))
    if data.get("gates") is not None and not isinstance(data.get("gates"), dict):
        raise fail("gates", "must be a mapping of metric -> {min, max}")
    gates = tuple(_check_gate(metric, spec, cfg, label) for metric, spec in (data.get("gates") or {}).items())
    spec = SweepSpec(label=label, mode=mode, samples=int(samples) if samples is not None else None,
                     seed=int(seed), parameters=tuple(parameters), fixed=tuple(fixed), gates=gates,
                     require_ok=require_ok, chunk_size=int(chunk) if chunk is not None else None,
                     canonical=json.loads(json.dumps({k: v for k, v in data.items() if k != "description"},
                                                     default=str)))
    if mode == "grid":
        count = spec.count()
        if count > MAX_CASES:
            raise fail("parameters", f"the grid has {count} cases, more than {MAX_CASES}; "
                       "use mode: random with samples")
    return spec


def _check_values(spec, path: str, mode: str, label: str) -> str:
    where = f"{label}: parameters.{path}"
    if isinstance(spec, list):
        if not spec:
            raise SweepError(f"{where}: empty list; give at least one value")
        return "values"
    if not isinstance(spec, dict):
        raise SweepError(f"{where} = {_show(spec)}: give a list of values, a range "
                         "{from, to, num} or, in random mode, a {distribution: ...}")
    if "distribution" in spec:
        if mode != "random":
            raise SweepError(f"{where}: a distribution needs mode: random (a grid takes lists and ranges)")
        kind = spec["distribution"]
        if kind not in DISTRIBUTIONS:
            raise SweepError(f"{where}: unknown distribution {_show(kind)}; "
                             f"use one of {', '.join(DISTRIBUTIONS)}")
        need = DISTRIBUTIONS[kind]
        for key in spec:
            if key != "distribution" and key not in need:
                raise SweepError(f"{where}.{key}: unknown key for {kind}; it takes {', '.join(need)}")
        for key in need:
            if key not in spec:
                raise SweepError(f"{where}: {kind} needs `{key}`; give {', '.join(need)}")
        if kind == "choice":
            if not isinstance(spec["values"], list) or not spec["values"]:
                raise SweepError(f"{where}.values: empty; give a non-empty list")
            return "distribution"
        for key in need:
            _finite(spec[key], f"{where}.{key}")
        if kind == "normal" and spec["std"] < 0:
            raise SweepError(f"{where}.std = {_show(spec['std'])}: must be >= 0")
        if kind in ("uniform", "loguniform") and not spec["low"] < spec["high"]:
            raise SweepError(f"{where}: empty range: low {_show(spec['low'])} must be below "
                             f"high {_show(spec['high'])}")
        if kind == "loguniform" and spec["low"] <= 0:
            raise SweepError(f"{where}.low = {_show(spec['low'])}: loguniform needs low > 0")
        return "distribution"
    for key in spec:
        if key not in RANGE_KEYS:
            raise SweepError(f"{where}.{key}: unknown key; a range takes from, to, num, scale "
                             "(and a distribution needs `distribution:`)")
    need = ("from", "to") if mode == "random" else ("from", "to", "num")
    for key in need:
        if key not in spec:
            raise SweepError(f"{where}: a range needs `{key}`; give {{from, to, num}}")
    _finite(spec["from"], f"{where}.from")
    _finite(spec["to"], f"{where}.to")
    if "num" in spec:
        num = spec["num"]
        if not _is_int(num) or num < 1:
            raise SweepError(f"{where}.num = {_show(num)}: empty range; num must be a whole number >= 1")
    scale = spec.get("scale", "linear")
    if scale not in ("linear", "log"):
        raise SweepError(f"{where}.scale = {_show(scale)}: use linear or log")
    if scale == "log" and (spec["from"] <= 0 or spec["to"] <= 0):
        raise SweepError(f"{where}: a log range needs from and to > 0")
    if mode == "random" and spec["from"] == spec["to"]:
        raise SweepError(f"{where}: empty range: from equals to; give a list for one value")
    return "range"


def check_path(tree: dict, path: str, label: str, section: str) -> tuple:
    """Parse ``path`` and check that it names a value of the config ``tree``.

    Raises SweepError naming the first part that does not exist, and the nearest valid key.
    """
    where = f"{label}: {section}.{path}"
    if not _PATH_RE.match(path):
        raise SweepError(f"{where}: not a key path; write it as `lqr.roll.Q[1]` or `vehicle.mass`")
    keys = parse_path(path)
    node = tree
    walked: list = []
    for k, key in enumerate(keys):
        here = _path_text(walked) or "the config"
        if isinstance(key, int):
            if not isinstance(node, list):
                raise SweepError(f"{where}: {here} is not a list; drop the [{key}]")
            if key >= len(node):
                raise SweepError(f"{where}: index {key} out of range: {here} has {len(node)} values "
                                 f"(indices 0 to {len(node) - 1})")
            node = node[key]
        else:
            if not isinstance(node, dict):
                raise SweepError(f"{where}: {here} = {_show(node)} has no key `{key}`; "
                                 "the path goes too deep")
            if key not in node:
                if tuple(walked) in FREE_MAPPINGS and k == len(keys) - 1:
                    if key not in STATE_NAMES:  # a new key of a free mapping: another state's offset
                        raise SweepError(f"{where}: `{key}` is not a state; " + _hint(key, STATE_NAMES))
                    return keys
                raise SweepError(f"{where}: no such key in the config: `{_path_text([*walked, key])}`; "
                                 + _hint(key, [str(x) for x in node]))
            node = node[key]
        walked.append(key)
    if isinstance(node, dict):
        raise SweepError(f"{where}: is a section, not a value; name one of its keys: "
                         f"{', '.join(map(str, node))}")
    return keys


def parse_path(path: str) -> tuple:
    """``'lqr.roll.Q[1]'`` -> ``('lqr', 'roll', 'Q', 1)``."""
    keys: list = []
    for part in path.split("."):
        name, *indices = re.split(r"\[", part)
        keys.append(name)
        keys.extend(int(i.rstrip("]")) for i in indices)
    return tuple(keys)


def _path_text(keys) -> str:
    from quadctl.config import key_path

    return key_path(list(keys)) if keys else ""


def _check_gate(metric, spec, cfg, label: str) -> Gate:
    metric = str(metric)
    where = f"{label}: gates.{metric}"
    known = metric_columns(cfg)
    gateable = [m for m in known if m not in ("dt", "steps")] + ["steps"]
    if metric not in gateable:
        family, _, name = metric.partition(".")
        if family in ("settling_time", "overshoot") and name in STATE_NAMES:
            regulated = [m.partition(".")[2] for m in known if m.startswith(family + ".")]
            raise SweepError(f"{where}: {name} is not regulated, so it has no {family.replace('_', ' ')}; "
                             f"regulated states: {', '.join(regulated)}")
        raise SweepError(f"{where}: unknown metric; " + _hint(metric, gateable, many=True))
    if not isinstance(spec, dict) or not spec:
        raise SweepError(f"{where}: give a threshold, as {{max: 3.0}} or {{min: 0}}")
    for key in spec:
        if key not in GATE_KEYS:
            raise SweepError(f"{where}.{key}: unknown key; " + _hint(str(key), GATE_KEYS))
    if metric in ("stable", "status"):
        if set(spec) != {"equals"}:
            raise SweepError(f"{where}: {metric} takes {{equals: {'true' if metric == 'stable' else 'ok'}}}")
        return Gate(metric, equals=spec["equals"])
    if "equals" in spec:
        raise SweepError(f"{where}: a number takes min and max, not equals")
    for key in ("min", "max"):
        if key in spec:
            _finite(spec[key], f"{where}.{key}")
    if "min" in spec and "max" in spec and spec["min"] > spec["max"]:
        raise SweepError(f"{where}: min {spec['min']} is above max {spec['max']}; no case can pass")
    return Gate(metric, min=_num(spec.get("min")), max=_num(spec.get("max")))


def metric_columns(cfg) -> list[str]:
    """The metric columns of a sweep of ``cfg``, in table order.

    ``stable`` (coupled linear closed loop), ``eig.fastest`` / ``eig.slowest`` (most negative and
    largest real part of its eigenvalues, marginal position modes left out; rad/s), then per
    regulated state ``settling_time.<state>`` (s, 2 % band) and ``overshoot.<state>`` (%), per
    input ``peak.<input>`` (max |u|: N or N m), ``cost`` (the LQR cost integral), ``status``
    (the simulation's: ok, diverged, left_valid_range; or why the case has no simulation),
    ``dt`` (s) and ``steps``.
    """
    states = regulated_states(cfg)
    return (["stable", "eig.fastest", "eig.slowest"] + [f"settling_time.{s}" for s in states]
            + [f"overshoot.{s}" for s in states] + [f"peak.{i}" for i in INPUT_NAMES]
            + ["cost", "status", "dt", "steps"])


def regulated_states(cfg) -> list[str]:
    """The states of the config's regulated subsystems, in state order."""
    regulated = {s for sub in cfg.partition().values() if sub.regulate for s in sub.states}
    return [s for s in STATE_NAMES if s in regulated]


def _lookup(tree, keys):
    for key in keys:
        try:
            tree = tree[key]
        except (KeyError, IndexError, TypeError):
            return None
    return tree


def assign(tree: Any, keys: tuple, value) -> Any:
    """A copy of ``tree`` with the value at ``keys`` replaced (only the path is copied)."""
    if not keys:
        return value
    head, rest = keys[0], keys[1:]
    if isinstance(tree, dict):
        out = dict(tree)
        out[head] = assign(tree.get(head), rest, value) if rest else _like(tree.get(head), value)
        return out
    out = list(tree)
    out[head] = assign(tree[head], rest, value) if rest else _like(tree[head], value)
    return out


def _like(old, value):
    """A whole float where the config holds an integer (a seed from a range): the integer."""
    if _is_int(old) and isinstance(value, float) and value.is_integer():
        return int(value)
    return value


def _hint(name: str, allowed, many: bool = False) -> str:
    by_case = {str(a).lower(): a for a in allowed}
    if name.lower() in by_case:
        return f"did you mean `{by_case[name.lower()]}`?"
    near = difflib.get_close_matches(name, list(allowed), n=1, cutoff=0.5)
    if near:
        return f"did you mean `{near[0]}`?"
    shown = list(allowed)
    if many and len(shown) > 12:
        shown = shown[:12] + ["..."]
    return f"allowed: {', '.join(shown)}"


def _is_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _finite(value, where: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SweepError(f"{where} = {_show(value)}: must be a finite number")


def _num(value):
    return None if value is None else float(value)


def _show(value) -> str:
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


# ---------------------------------------------------------------------------------------
# Evaluating cases


@dataclass(frozen=True)
class ChunkTask:
    """Everything a worker needs for a chunk of cases (plain data: it travels by pickle).

    Attributes
    ----------
    base : dict
        The base config as a mapping, with the sweep's ``set:`` values already in.
    label : str
        Names the config in the message of a case that fails validation.
    keys : tuple of tuple
        The parameters' parsed key paths.
    names : tuple of str
        The parameters' key paths as written (row keys).
    cases : tuple of (int, tuple)
        Case number and parameter values.
    gates : tuple of Gate
    require_ok : bool
    fast : bool
        Use the batched path for configs it models (False: every case through the pipeline).
    trace : tuple of str
        A Monte Carlo: the states whose trajectories each case keeps (empty: none).
    """

    base: dict
    label: str
    keys: tuple
    names: tuple
    cases: tuple
    gates: tuple
    require_ok: bool
    fast: bool = True
    trace: tuple = ()


@dataclass
class ChunkResult:
    """Rows of a chunk, what computing them took and, in a Monte Carlo, each case's trajectory:
    case number -> (MC_POINTS, len(trace)) float32 array (see :func:`resample_deviation`); a case
    that did not simulate to the end has none."""

    rows: list
    stats: dict
    traces: dict = field(default_factory=dict)


def evaluate_chunk(task: ChunkTask) -> ChunkResult:
    """Evaluate a chunk of cases: one row per case, never an exception for a bad case.

    The top-level function executors run (a local process or a Dask worker).
    """
    from quadctl import config as config_mod
    from quadctl import pipeline

    start = time.perf_counter()
    stats = {"cases": len(task.cases), "designs": 0, "design_time": 0.0, "design_cpu": 0.0, "simulate_time": 0.0,
             "steps": 0, "fallbacks": 0, "backend": set()}
    rows: dict[int, dict] = {}
    traces: dict[int, np.ndarray] = {}
    ready = []
    plant_cache: dict[str, Any] = {}
    for index, values in task.cases:
        data = task.base
        for keys, value in zip(task.keys, values):
            data = assign(data, keys, _plain(value))
        head = {"case": index, **dict(zip(task.names, values))}
        try:
            cfg = config_mod.from_dict(data, f"{task.label} case {index}")
        except ConfigError as exc:
            rows[index] = _failed(head, "invalid_config", str(exc))
            continue
        key = json.dumps(cfg.model_dump(mode="json", include={"vehicle", "trim", "subsystems"}),
                         sort_keys=True)
        if key not in plant_cache:
            try:
                trim = pipeline.trim_of(cfg)
                linear = pipeline.linear_of(cfg, trim)
                plant_cache[key] = (trim, linear, pipeline.decoupled_of(cfg, linear),
                                    pipeline.reference_rate(trim))
            except TrimError as exc:
                plant_cache[key] = exc
        plant = plant_cache[key]
        if isinstance(plant, TrimError):
            rows[index] = _failed(head, "no_trim", str(plant))
            continue
        ready.append(_Prepared(index, head, cfg, *plant))
    # the batched path for plain configs; a case is as plain as the base when the sweep only
    # touches keys the batched path models, so the full check runs once per chunk, not per case.
    # A Monte Carlo (noise: never plain) keeps trajectories, which only the pipeline path gives.
    batched = task.fast and not task.trace
    shortcut = ready and batched and all(_plain_key(keys) for keys in task.keys) and is_plain(ready[0].cfg)
    plain = [bool(shortcut) or (batched and is_plain(p.cfg)) for p in ready]
    fast = [p for p, ok in zip(ready, plain) if ok]
    slow = [p for p, ok in zip(ready, plain) if not ok]
    if fast:
        rows.update(_evaluate_batched(fast, stats))
    for prep in slow:
        try:
            rows[prep.index], trace = _evaluate_one(prep, stats, task.trace)
            if trace is not None:
                traces[prep.index] = trace
        except QuadctlError as exc:  # whatever else a feature of the config refuses: a row, not a crash
            rows[prep.index] = _failed(prep.head, "failed", str(exc))
    out = []
    for index, _ in task.cases:
        row = rows[index]
        passed, failed = judge(row, task.gates, task.require_ok)
        row["pass"] = passed
        row["failed_gates"] = "; ".join(failed)
        out.append(row)
    stats["backend"] = sorted(stats["backend"])
    stats["wall_time"] = time.perf_counter() - start
    return ChunkResult(rows=out, stats=stats, traces=traces)


@dataclass
class _Prepared:
    index: int
    head: dict
    cfg: Any
    trim: Any
    linear: Any
    decoupled: Any
    rate: np.ndarray


_PLAIN = {
    "": {"name", "description", "vehicle", "trim", "subsystems", "lqr", "simulation"},
    "vehicle": {"mass", "gravity", "inertia", "drag"},
    "trim": {"velocity_ned", "position_ned", "yaw"},
    "simulation": {"duration", "dt", "initial_offset"},
    "lqr.*": {"Q", "R"},
    "subsystems.*": {"states", "inputs", "regulate", "outputs"},
}
"""The config keys the batched path models. A config that sets any other key away from its
default (a controller rate, motors, noise, integral action...) is evaluated case by case through
the pipeline."""


def is_plain(cfg) -> bool:
    """True when ``cfg`` is the plain continuous LQR loop the batched path simulates: every key
    outside :data:`_PLAIN` holds its schema default."""

    def at_default(section, key: str) -> bool:
        default = _default_of(type(section), key)
        return default is not _REQUIRED and _dumped(getattr(section, key)) == default

    def plain(section, allowed) -> bool:
        return all(key in allowed or at_default(section, key) for key in type(section).model_fields)

    if not plain(cfg, _PLAIN[""]):
        return False
    for name in ("vehicle", "trim", "simulation"):
        if not plain(getattr(cfg, name), _PLAIN[name]):
            return False
    blocks = [(w, _PLAIN["lqr.*"]) for w in cfg.lqr.values()]
    blocks += [(s, _PLAIN["subsystems.*"]) for s in (cfg.subsystems or {}).values()]
    return all(plain(section, allowed) for section, allowed in blocks)


def _plain_key(keys: tuple) -> bool:
    """Whether a key path stays inside what the batched path models (:data:`_PLAIN`)."""
    if not keys or keys[0] not in _PLAIN[""]:
        return False
    if keys[0] in ("lqr", "subsystems"):
        return len(keys) > 2 and keys[2] in _PLAIN[f"{keys[0]}.*"]
    if keys[0] in _PLAIN:
        return len(keys) > 1 and keys[1] in _PLAIN[keys[0]]
    return True


def _dumped(value):
    return value.model_dump(mode="json") if hasattr(value, "model_dump") else value


_REQUIRED = object()


@lru_cache(maxsize=256)
def _default_of(model: type, key: str):
    """A schema field's default, dumped (``_REQUIRED`` if it has none); pydantic's lookup is slow."""
    field_info = model.model_fields[key]
    if field_info.is_required():
        return _REQUIRED
    return _dumped(field_info.get_default(call_default_factory=True))


def _plain(value):
    """numpy scalars as Python numbers (the strict config schema takes float, not float64)."""
    if isinstance(value, np.generic):
        return value.item()
    return value


def _failed(head: dict, status: str, reason: str) -> dict:
    row = dict(head)
    row.update({"stable": None, "eig.fastest": None, "eig.slowest": None, "status": status,
                "dt": None, "steps": 0, "reason": reason})
    return row


def _row(head: dict, stable: bool, core_eigs, plan, summary: dict | None, steps: int, reason: str = "") -> dict:
    row = dict(head)
    row["stable"] = bool(stable)
    row["eig.fastest"] = float(np.min(core_eigs.real)) if len(core_eigs) else None
    row["eig.slowest"] = float(np.max(core_eigs.real)) if len(core_eigs) else None
    if summary is not None:
        for state, value in summary["settling_time"].items():
            row[f"settling_time.{state}"] = value
        for state, value in summary["overshoot"].items():
            row[f"overshoot.{state}"] = value
        for name, value in summary["peak"].items():
            row[f"peak.{name}"] = value
        row["cost"] = summary["cost"]
        row["status"] = summary["status"]
    row["dt"] = plan.dt if plan is not None else None
    row["steps"] = int(steps)
    row["reason"] = reason
    return row


def _weights_block(cfg) -> tuple[np.ndarray, np.ndarray, list[str], dict]:
    """(Q_block (12, 12), R_block (4, 4), regulated states, {subsystem: (Q, R)}) from the config."""
    from quadctl import pipeline

    regulated = [s for states in (v[2] for v in _block_index(cfg).values()) for s in states]
    Q, R = pipeline.weights_block(cfg)
    return Q, R, regulated, pipeline.weights_of(cfg)


def _block_index(cfg) -> dict:
    """Regulated subsystem -> (state indices, input indices, state names); cached per partition."""
    return _block_index_cached(_partition_key(cfg))


def _partition_key(cfg) -> tuple:
    return tuple((name, tuple(sub.states), tuple(sub.inputs))
                 for name, sub in cfg.partition().items() if sub.regulate)


@lru_cache(maxsize=64)
def _block_index_cached(key) -> dict:
    return {name: (np.array([STATE_INDEX[s] for s in states]), np.array([INPUT_INDEX[i] for i in inputs]),
                   list(states)) for name, states, inputs in key}


@lru_cache(maxsize=64)
def _pattern_cached(key) -> tuple[bool, ...]:
    mask = np.zeros((N_INPUTS, N_STATES), dtype=bool)
    for si, ii, _ in _block_index_cached(key).values():
        mask[np.ix_(ii, si)] = True
    return tuple(bool(v) for v in mask.ravel(order="F"))


def _core_eigenvalues(A_cl, K) -> tuple[np.ndarray, bool]:
    """Eigenvalues of the coupled closed loop without its marginal position modes, and stability.

    As :func:`quadctl.lqr.closed_loop_stability` decides it.
    """
    from quadctl.analysis import is_stable
    from quadctl.lqr import closed_loop_stability

    _, marginal, stable = closed_loop_stability(A_cl, K)
    keep = [i for i, s in enumerate(STATE_NAMES) if s not in marginal]
    core = np.linalg.eigvals(np.asarray(A_cl)[np.ix_(keep, keep)])
    return core, bool(stable and all(is_stable(e) for e in core))


def _evaluate_one(prep: _Prepared, stats: dict, trace: tuple = ()) -> tuple[dict, np.ndarray | None]:
    """One case through the pipeline, as ``quadctl simulate`` runs it (the reference path).

    Returns the row and, when ``trace`` names states and the run reached its end, their
    deviations resampled by :func:`resample_deviation` (else None).
    """
    from quadctl import metrics, pipeline

    cfg, linear = prep.cfg, prep.linear
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        des = pipeline.design_of(cfg, prep.decoupled, linear)
        stats["design_time"] += time.perf_counter() - t0
        stats["design_cpu"] += time.process_time() - c0
        stats["designs"] += len(prep.decoupled.regulated)
    except DesignError as exc:
        return _failed(prep.head, "design_failed", str(exc)), None
    A_cl = linear.A - linear.B @ des.K_block
    core, stable = _core_eigenvalues(A_cl, des.K_block)
    loop = pipeline.loop_of(cfg, linear, des, prep.rate)  # the integrators of an LQI design too
    try:
        t0 = time.perf_counter()
        sim = pipeline.simulation_of(cfg, loop)
        stats["simulate_time"] += time.perf_counter() - t0
    except StepSizeError as exc:
        row = _row(prep.head, stable, core, None, None, 0, str(exc))
        row["status"] = "step_refused"
        return row, None
    stats["backend"].add(sim.backend)
    stats["steps"] += sim.steps
    Q, R, regulated, _ = _weights_block(cfg)
    summary = metrics.summarize(sim, linear.u_trim, Q, R, regulated)
    row = _row(prep.head, stable, core, sim.plan, summary, sim.steps,
               "" if sim.status == "ok" else sim.message)
    kept = None
    if trace and sim.status == "ok":
        kept = resample_deviation(sim.t, sim.x, sim.x_ref, trace, cfg.simulation.duration)
    return row, kept


def mc_grid(duration: float) -> np.ndarray:
    """The Monte Carlo time grid: (MC_POINTS,) evenly spaced times from 0 to ``duration`` s."""
    return np.linspace(0.0, float(duration), MC_POINTS)


def resample_deviation(t, x, x_ref, states, duration: float) -> np.ndarray:
    """Deviation of ``states`` from the reference, linearly interpolated onto :func:`mc_grid`.

    Parameters
    ----------
    t : (N,) array_like
        s, increasing (a simulation's records).
    x, x_ref : (N, 12) array_like
        State and reference (state units: m, m/s, rad, rad/s).
    states : sequence of str
    duration : float
        s, the end of the grid.

    Returns
    -------
    (MC_POINTS, len(states)) float32 ndarray
        ``x - x_ref`` at the grid's times. float32 keeps seven digits, far below the noise a Monte
        Carlo measures, at half the memory.
    """
    grid = mc_grid(duration)
    index = [STATE_INDEX[s] for s in states]
    dev = np.asarray(x)[:, index] - np.asarray(x_ref)[:, index]
    return np.stack([np.interp(grid, t, dev[:, j]) for j in range(len(index))], axis=1).astype(np.float32)


def _evaluate_batched(preps: list[_Prepared], stats: dict) -> dict[int, dict]:
    """Cases of plain configs, designed and simulated together."""
    from quadctl import batch, batch_codegen, pipeline
    from quadctl.lqr import lqr
    from quadctl.simulate import RUNAWAY, VALID_PITCH, _verdict, max_stable_steps, plan_step

    rows: dict[int, dict] = {}
    # 1. LQR of every regulated subsystem of every case, batched by shape
    weights = [_weights_block(prep.cfg) for prep in preps]
    # the design stage: stacking, batched solves, one-by-one fallbacks (wall and CPU time)
    t0, c0 = time.perf_counter(), time.process_time()
    problems = []  # (case position, subsystem, Q, R)
    for k, prep in enumerate(preps):
        for sub in prep.decoupled.regulated:
            problems.append((k, sub, *weights[k][3][sub.name]))
    gains: dict[tuple[int, str], np.ndarray] = {}
    failed: dict[int, str] = {}
    by_shape: dict[tuple[int, int], list] = {}
    for item in problems:
        by_shape.setdefault(item[1].B.shape, []).append(item)
    for group in by_shape.values():
        res = batch.care(np.stack([g[1].A for g in group]), np.stack([g[1].B for g in group]),
                         np.stack([g[2] for g in group]), np.stack([g[3] for g in group]))
        for j, (k, sub, Q, R) in enumerate(group):
            if res.ok[j]:
                gains[(k, sub.name)] = res.K[j]
                continue
            stats["fallbacks"] += 1  # the one-case solver decides, and says why
            try:
                gains[(k, sub.name)] = lqr(sub.A, sub.B, Q, R, name=f"subsystem {sub.name}",
                                           state_names=sub.states).K
            except DesignError as exc:
                failed.setdefault(k, str(exc))
    stats["designs"] += len(problems)
    stats["design_time"] += time.perf_counter() - t0
    stats["design_cpu"] += time.process_time() - c0
    # 2. block gains, coupled eigenvalues, step plans
    live = []
    for k, prep in enumerate(preps):
        if k in failed:
            rows[prep.index] = _failed(prep.head, "design_failed", failed[k])
            continue
        K = np.zeros((N_INPUTS, N_STATES))
        index = _block_index(prep.cfg)
        for sub in prep.decoupled.regulated:
            si, ii, _ = index[sub.name]
            K.flat[(ii[:, None] * N_STATES + si).ravel()] = gains[(k, sub.name)].ravel()
        live.append((k, prep, K))
    if not live:
        return rows
    A_cl = np.stack([prep.linear.A - prep.linear.B @ K for _, prep, K in live])
    eigs, vecs = np.linalg.eig(A_cl)
    limits = max_stable_steps(eigs)
    cores, stables = batch.coupled_stability(A_cl, np.stack([K for _, _, K in live]))
    largest = np.argmax(np.abs(vecs), axis=1).tolist()  # each mode's largest state (eigen_owners)
    jobs = []
    for j, (k, prep, K) in enumerate(live):
        cfg = prep.cfg
        owner_of = pipeline.state_owner(cfg)
        owners = [owner_of.get(STATE_NAMES[i], "unassigned") for i in largest[j]]
        core, stable = cores[j], bool(stables[j])
        sim_cfg = cfg.simulation
        try:
            plan = plan_step(eigs[j], owners, sim_cfg.duration, sim_cfg.dt, limits=limits[j])
        except StepSizeError as exc:
            row = _row(prep.head, stable, core, None, None, 0, str(exc))
            row["status"] = "step_refused"
            rows[prep.index] = row
            continue
        x_trim, rate = prep.linear.x_trim, prep.rate
        bound = np.array([RUNAWAY[s] for s in STATE_NAMES])
        lo, hi = x_trim - bound, x_trim + bound
        theta = STATE_INDEX["theta"]
        lo[theta], hi[theta] = -VALID_PITCH, VALID_PITCH
        drift = np.abs(rate) * sim_cfg.duration
        lo, hi = lo - drift, hi + drift
        c = batch_codegen.pack_lane_constants(x_trim, rate, prep.linear.u_trim, K,
                                              pipeline.vehicle_of(cfg).vector())
        pattern = _pattern_of(cfg)
        jobs.append((pattern, prep, k, core, stable, plan, pipeline.initial_state(cfg, x_trim), c, lo, hi,
                     max(1, math.ceil(plan.n_steps / sim_cfg.max_samples))))
    # 3. simulations, LANES at a time per gain pattern, metrics as each group lands
    by_pattern: dict[tuple, list] = {}
    for job in jobs:
        by_pattern.setdefault(job[0], []).append(job)
    for pattern, group in by_pattern.items():
        runner = batch_codegen.get_lanes(pattern)
        stats["backend"].add(runner.backend)
        t0 = time.perf_counter()
        results = runner.iter_run(np.stack([g[6] for g in group]), np.array([g[5].dt for g in group]),
                                  np.array([g[5].n_steps for g in group]), np.stack([g[7] for g in group]),
                                  np.array([g[10] for g in group]), np.stack([g[8] for g in group]),
                                  np.stack([g[9] for g in group]))
        for j, done, ks, xs, us in results:
            _, prep, k, core, stable, plan, _, _, lo, hi, _ = group[j]
            t = plan.dt * ks
            status, message = _verdict(xs, t, done, plan.n_steps, lo, hi)
            Qb, Rb, regulated, _ = weights[k]
            summary = batch.summarize_run(t, xs, us, (prep.linear.x_trim, prep.rate), prep.linear.u_trim,
                                          Qb, Rb, regulated, status)
            stats["steps"] += done
            rows[prep.index] = _row(prep.head, stable, core, plan, summary, done,
                                    "" if status == "ok" else message)
        stats["simulate_time"] += time.perf_counter() - t0
    return rows


def _pattern_of(cfg) -> tuple[bool, ...]:
    """:func:`structural_pattern` of a config's partition (cached per partition)."""
    return _pattern_cached(_partition_key(cfg))


def structural_pattern(decoupled) -> tuple[bool, ...]:
    """The block gain's sparsity (48 bools, column-major): regulated inputs x their subsystem's states."""
    mask = np.zeros((N_INPUTS, N_STATES), dtype=bool)
    for sub in decoupled.regulated:
        mask[np.ix_([INPUT_INDEX[i] for i in sub.inputs], sub.state_index)] = True
    return tuple(bool(v) for v in mask.ravel(order="F"))


# ---------------------------------------------------------------------------------------
# Gates


def judge(row: dict, gates, require_ok: bool) -> tuple[bool, list[str]]:
    """Whether a row passes, and what it fails (gate descriptions, or why it has no result)."""
    failed = []
    if require_ok:
        if row.get("status") != "ok":
            failed.append(f"status {row.get('status')}")
        elif row.get("stable") is False:
            failed.append("unstable on the coupled model")
    for gate in gates:
        if not gate.passes(row.get(gate.metric)):
            value = row.get(gate.metric)
            shown = "none" if value is None else (f"{value:.4g}" if isinstance(value, float) else str(value))
            failed.append(f"{gate.describe()} (got {shown})")
    return not failed, failed


def margin(row: dict, gates, require_ok: bool) -> float:
    """How well a row passes: the smallest relative slack over its gates (-inf: no result).

    Without gates, the negative LQR cost (lower cost ranks better).
    """
    if require_ok and (row.get("status") != "ok" or row.get("stable") is False):
        return -math.inf
    if not gates:
        cost = row.get("cost")
        return -cost if isinstance(cost, (int, float)) and math.isfinite(cost) else -math.inf
    return min(g.slack(row.get(g.metric)) for g in gates)


# ---------------------------------------------------------------------------------------
# Running a sweep


@dataclass
class SweepResult:
    """A finished (or resumed) sweep.

    Attributes
    ----------
    rows : list of dict
        One per case, by case number: ``case``, the parameters, the metrics, ``pass``,
        ``failed_gates``, ``reason``.
    columns : list of str
        The table's columns, in order.
    computed : int
        Cases computed in this call (the rest came from ``done``).
    wall_time : float
        s, for the cases computed here.
    stats : dict
        Totals over the chunks: ``designs`` (subsystem LQR solves), ``design_time`` and
        ``design_cpu`` (s of wall and of CPU time in the design stage, summed over workers: CPU
        time is what a design costs, wall time also counts what other processes took),
        ``steps`` (RK4 steps simulated), ``fallbacks`` (batched solves redone one by one),
        ``backend``, ``executor``, ``workers``.
    traces : dict
        A Monte Carlo: case number -> (MC_POINTS, regulated states) float32 deviations from the
        reference, for the cases computed here that simulated to the end (a resumed sweep's
        earlier cases are in its journal: :class:`SweepStore`).
    """

    rows: list
    columns: list
    computed: int
    wall_time: float
    stats: dict
    gates: tuple = ()
    require_ok: bool = True
    traces: dict = field(default_factory=dict)

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if not r["pass"]]

    def ranked(self) -> list[dict]:
        """Rows from the worst to the best (see :func:`margin`)."""
        return sorted(self.rows, key=lambda r: (margin(r, self.gates, self.require_ok), -r["case"]))

    @property
    def steps_per_second(self) -> float:
        return self.stats["steps"] / self.wall_time if self.wall_time > 0 else math.inf


def default_jobs() -> int:
    """All the cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def default_chunk(n_cases: int, workers: int) -> int:
    """Cases per task: about four tasks per worker (so a stop loses little and the load balances),
    a multiple of the SIMD lanes, 8 to 256 cases (the batched solves pay off with more)."""
    from quadctl.batch_codegen import LANES

    size = max(LANES, min(256, math.ceil(n_cases / (4 * max(1, workers)))))
    return math.ceil(size / LANES) * LANES


def tasks_for(cfg, spec: SweepSpec, cases: Iterable[Case], label: str, size: int,
              fast: bool = True) -> list[ChunkTask]:
    """The chunks of ``cases`` (in case order, ``size`` each), ready for any executor.

    A case's row does not depend on the chunk it is in, so the chunk size is free to follow the
    executor (the resume test checks this: a resumed sweep, chunked anew, writes the same table).
    """
    cases = list(cases)
    base = base_of(cfg, spec)
    keys = tuple(p.keys for p in spec.parameters)
    trace = tuple(regulated_states(cfg)) if spec.monte_carlo else ()
    return [ChunkTask(base=base, label=label, keys=keys, names=tuple(spec.names),
                      cases=tuple((c.index, c.values) for c in cases[i:i + size]), gates=spec.gates,
                      require_ok=spec.require_ok, fast=fast, trace=trace)
            for i in range(0, len(cases), size)]


def base_of(cfg, spec: SweepSpec) -> dict:
    """The config every case starts from, as a mapping: ``cfg`` with the ``set:`` values in."""
    base = cfg.model_dump(mode="json")
    for _, keys, value in spec.fixed:
        base = assign(base, keys, value)
    return base


def run(cfg, spec: SweepSpec, *, label: str | None = None, jobs: int | None = None,
        scheduler: str | None = None, done: dict[int, dict] | None = None,
        on_chunk: Callable[[list, dict], None] | None = None,
        progress: Callable[[int, int], None] | None = None, fast: bool = True) -> SweepResult:
    """Run a sweep: every case of ``spec`` not already in ``done``.

    Parameters
    ----------
    cfg : Config
        The base config.
    spec : SweepSpec
    label : str, optional
        Names the config in case messages (default its name).
    jobs : int, optional
        Local worker processes (default all cores; 1 runs in this process).
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:8786``): run the chunks there.
    done : dict, optional
        Rows already computed, by case number (a resumed sweep): not recomputed.
    on_chunk : callable, optional
        ``on_chunk(rows, traces)`` for each finished chunk, in completion order (to save them);
        ``traces`` as :attr:`ChunkResult.traces` (empty unless a Monte Carlo).
    progress : callable, optional
        ``progress(cases_done, cases_total)`` after each chunk.
    fast : bool
        Use the batched path where it applies (False: every case through the pipeline).

    Returns
    -------
    SweepResult

    Raises
    ------
    SweepError
        ``jobs`` below 1, or the scheduler cannot be reached.
    """
    label = label or cfg.name
    done = dict(done or {})
    cases = spec.cases()
    todo = [c for c in cases if c.index not in done]
    stats = {"designs": 0, "design_time": 0.0, "design_cpu": 0.0, "simulate_time": 0.0, "steps": 0, "fallbacks": 0,
             "backend": set()}
    if jobs is not None and jobs < 1:
        raise SweepError(f"--jobs {jobs}: must be at least 1")
    client = _dask_client(scheduler) if scheduler else None
    try:
        if client is not None:
            workers = max(1, sum(client.nthreads().values()))
            stats["executor"] = f"dask {scheduler} ({workers} threads)"
        else:
            workers = max(1, min(jobs or default_jobs(), len(todo)))
            stats["executor"] = "local" if workers == 1 else f"local processes ({workers})"
        stats["workers"] = workers
        tasks = tasks_for(cfg, spec, todo, label, spec.chunk_size or default_chunk(len(todo), workers), fast)
        if client is None and tasks and fast:
            _warm_up(tasks[0])
        results = _dask_results(client, tasks) if client is not None else _local_results(tasks, workers)
        rows = dict(done)
        traces: dict[int, np.ndarray] = {}
        total = len(cases)
        start = time.perf_counter()
        if progress:
            progress(len(rows), total)
        for result in results:
            for row in result.rows:
                rows[row["case"]] = row
            traces.update(result.traces)
            for key in ("designs", "design_time", "design_cpu", "simulate_time", "steps", "fallbacks"):
                stats[key] += result.stats[key]
            stats["backend"].update(result.stats["backend"])
            if on_chunk:
                on_chunk(result.rows, result.traces)
            if progress:
                progress(len(rows), total)
        wall = time.perf_counter() - start
    finally:
        if client is not None:
            client.close()
    stats["backend"] = sorted(stats["backend"])
    ordered = [rows[c.index] for c in cases]
    return SweepResult(rows=ordered, columns=columns_of(cfg, spec), computed=len(todo), wall_time=wall,
                       stats=stats, gates=spec.gates, require_ok=spec.require_ok,
                       traces={c.index: traces[c.index] for c in cases if c.index in traces})


def columns_of(cfg, spec: SweepSpec) -> list[str]:
    """Table columns: ``case``, the parameters, the metrics, ``pass``, ``failed_gates``, ``reason``."""
    return ["case", *spec.names, *metric_columns(cfg), "pass", "failed_gates", "reason"]


def _warm_up(task: ChunkTask) -> None:
    """Build (and compile, once per machine) the lane code before the workers fork from us."""
    from quadctl import config as config_mod
    from quadctl import pipeline
    from quadctl.batch_codegen import get_lanes

    try:
        cfg = config_mod.from_dict(task.base, task.label)
        if is_plain(cfg):
            dec = pipeline.decoupled_of(cfg, pipeline.linear_of(cfg, pipeline.trim_of(cfg)))
            get_lanes(structural_pattern(dec))
    except QuadctlError:
        pass  # the cases will say what is wrong, row by row


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and stops the pool


def _local_results(tasks: list[ChunkTask], jobs: int) -> Iterator[ChunkResult]:
    if jobs == 1:
        for task in tasks:
            yield evaluate_chunk(task)
        return
    # fork on Linux: workers start at once with everything imported and the lane library loaded
    # (the progress bar runs no thread, so nothing is forked mid-lock); spawn elsewhere (macOS's
    # system libraries are not fork-safe)
    ctx = multiprocessing.get_context("fork" if sys.platform.startswith("linux") else "spawn")
    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_ignore_sigint)
    pending = set()
    try:
        queue = list(tasks)
        # keep two tasks per worker in flight: a stop (Ctrl-C) leaves little half-done work
        while queue or pending:
            while queue and len(pending) < 2 * jobs:
                pending.add(pool.submit(evaluate_chunk, queue.pop(0)))
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                try:
                    result = fut.result()
                except BrokenProcessPool:
                    raise RuntimeError("a sweep worker process died (killed, or out of memory); the chunks "
                                       "finished before are kept: rerun with --resume (--jobs 1 shows "
                                       "any error in this process)") from None
                yield result
    finally:
        for fut in pending:
            fut.cancel()
        pool.shutdown(wait=True, cancel_futures=True)


SCHEDULER_TIMEOUT = "10s"
"""How long to try to reach a Dask scheduler before saying it cannot be reached."""


def _dask_client(address: str):
    try:
        from distributed import Client
    except ImportError:
        raise SweepError("--scheduler needs the `distributed` package; "
                         "install it with pip install 'quadctl[cluster]'") from None
    try:
        return Client(address, timeout=SCHEDULER_TIMEOUT, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SweepError(f"--scheduler {address}: cannot reach the Dask scheduler ({reason}); "
                         "check the address, or start one with `dask scheduler`") from None


def _dask_results(client, tasks: list[ChunkTask]) -> Iterator[ChunkResult]:
    from distributed import as_completed

    futures = client.map(evaluate_chunk, tasks, pure=False)
    try:
        for fut in as_completed(futures, loop=client.loop):
            yield fut.result()
    finally:
        client.cancel(futures)


# ---------------------------------------------------------------------------------------
# The run directory: journal, resume, outputs


class SweepStore:
    """The sweep's files in a run directory.

    Finished chunks go to ``DIR/sweep.parts/`` one file each, atomically, as they land; a
    stopped sweep keeps them and ``--resume`` reads them back instead of recomputing. At the
    end: ``sweep.csv`` (one row per case), ``sweep.json`` (summary, gates, worst and best cases,
    config hash) and ``sweep.png`` (the trade-off plot). A Monte Carlo's chunks also hold their
    cases' trajectories (float32, base64), so a resumed one has the bands of every case, and it
    ends with ``montecarlo.png`` and ``montecarlo.npz`` (:func:`montecarlo_bands`).

    Parameters
    ----------
    out : path
        The run directory.
    cfg : Config
    spec : SweepSpec
    """

    def __init__(self, out: Path | str, cfg, spec: SweepSpec):
        self.out = Path(out)
        self.cfg = cfg
        self.spec = spec
        self.parts = self.out / PARTS
        self.digest = spec.digest(cfg)
        self.trace = tuple(regulated_states(cfg)) if spec.monte_carlo else ()
        self.traces: dict[int, np.ndarray] = {}
        """Monte Carlo trajectories journaled so far (read back on resume, added per chunk)."""

    def start(self, resume: bool) -> dict[int, dict]:
        """Rows of finished chunks when resuming (checked to be of this very sweep), else none:
        a fresh sweep first clears the journal of an earlier one."""
        from quadctl import artifacts

        artifacts.remove_stale_temporaries(self.out)  # what a killed run was writing
        files = sorted(self.parts.glob("chunk-*.json")) if self.parts.is_dir() else []
        if not resume:
            for path in files:
                path.unlink()
            return {}
        done: dict[int, dict] = {}
        for path in files:
            data = artifacts.read_json(path)
            if data.get("sweep_digest") != self.digest:
                raise SweepError(
                    f"{path}: rows of another sweep (the config, the sweep file or quadctl changed "
                    "since); run without --resume to start over, or use another -o folder")
            for row in data["rows"]:
                done[int(row["case"])] = row
            if self.trace:
                self.traces.update(self._decode(path, data.get("traces")))
        return done

    def save_chunk(self, rows: list[dict], traces: dict | None = None) -> Path:
        """Write a finished chunk atomically (``chunk-<first case>.json``), with its cases'
        trajectories in a Monte Carlo."""
        from quadctl import artifacts

        first = min(int(r["case"]) for r in rows)
        payload = {**artifacts.metadata(self.cfg, "sweep-chunk"), "sweep_digest": self.digest,
                   "cases": [r["case"] for r in rows], "rows": rows}
        if self.trace:
            traces = traces or {}
            self.traces.update(traces)
            payload["traces"] = {"states": list(self.trace), "points": MC_POINTS, "dtype": "<f4",
                                 "cases": {str(k): base64.b64encode(np.ascontiguousarray(v, "<f4").tobytes())
                                           .decode("ascii") for k, v in traces.items()}}
        return artifacts.write_json(self.parts / f"chunk-{first:07d}.json", payload)

    def _decode(self, path: Path, block) -> dict[int, np.ndarray]:
        """A chunk's trajectories, checked to have this sweep's layout."""
        if not isinstance(block, dict) or block.get("states") != list(self.trace) \
                or block.get("points") != MC_POINTS or block.get("dtype") != "<f4":
            raise SweepError(f"{path}: a Monte Carlo chunk without trajectories of this layout "
                             f"({MC_POINTS} times of {', '.join(self.trace)}); run without --resume "
                             "to start over")
        shape = (MC_POINTS, len(self.trace))
        return {int(k): np.frombuffer(base64.b64decode(v), dtype="<f4").reshape(shape)
                for k, v in block["cases"].items()}

    def finish(self, result: SweepResult) -> dict:
        """Write sweep.csv, sweep.json and sweep.png (and a Monte Carlo's files); return the
        summary (sweep.json's content)."""
        from quadctl import artifacts

        csv_path = artifacts.write_bytes(self.out / "sweep.csv", to_csv(result).encode())
        summary = summarize(result, self.cfg, self.spec)
        summary["files"] = {"table": csv_path.name, "plot": "sweep.png", "chunks": PARTS}
        bands = self.finish_montecarlo(result)
        if self.trace:
            summary["montecarlo"] = {
                "cases": 0 if bands is None else len(bands.cases), "points": MC_POINTS,
                "percentiles": list(MC_PERCENTILES), "states": list(self.trace),
                "left_out": [r["case"] for r in result.rows] if bands is None else list(bands.left_out)}
        if bands is not None:
            summary["files"]["montecarlo"] = list(MC_FILES)
        payload = artifacts.jsonable({**artifacts.metadata(self.cfg, "sweep"), **summary,
                                      "sweep_digest": self.digest})
        artifacts.write_json(self.out / "sweep.json", payload)
        artifacts.write_bytes(self.out / "sweep.png", tradeoff_png(result, self.cfg))
        return payload

    def finish_montecarlo(self, result: SweepResult) -> MonteCarloBands | None:
        """A Monte Carlo: write montecarlo.npz and montecarlo.png from every trajectory (journaled
        and computed now). None if the sweep is no Monte Carlo or no case simulated to the end:
        then those files of an earlier run in this folder go, so none is mistaken for this one's."""
        from quadctl import artifacts

        traces = {**self.traces, **result.traces} if self.trace else {}
        if not traces:
            for name in MC_FILES:
                (self.out / name).unlink(missing_ok=True)
            return None
        duration = _lookup(base_of(self.cfg, self.spec), ("simulation", "duration"))
        bands = montecarlo_bands(traces, self.trace, duration, [r["case"] for r in result.rows])
        meta = {**artifacts.metadata(self.cfg, "montecarlo"), "sweep_digest": self.digest,
                "quantity": "deviation from the reference, x - x_ref, in state units (m, m/s, rad, rad/s)",
                "units": {s: unit_of(s) for s in bands.states}, "left_out": list(bands.left_out)}
        artifacts.write_npz(self.out / "montecarlo.npz",
                            {"t": bands.t, "percentiles": np.asarray(bands.percentiles, dtype=float),
                             "bands": bands.bands, "states": np.array(bands.states), "cases": bands.cases,
                             "traces": bands.traces}, meta)
        artifacts.write_bytes(self.out / "montecarlo.png", montecarlo_png(bands, self.cfg))
        return bands


MC_FILES = ("montecarlo.png", "montecarlo.npz")


@dataclass(frozen=True)
class MonteCarloBands:
    """Percentile bands of a Monte Carlo's trajectories against time.

    Attributes
    ----------
    t : (P,) ndarray
        s, the grid (:func:`mc_grid`).
    percentiles : tuple of float
        The levels, :data:`MC_PERCENTILES`.
    bands : (len(percentiles), P, S) ndarray
        At each level, time and state: the deviation from the reference in state units (m, m/s,
        rad, rad/s), over the cases at that time (numpy's linear interpolation between cases).
    states : tuple of str
        The S states, in state order.
    cases : (N,) int ndarray
        The cases the bands are over, in order.
    traces : (N, P, S) float32 ndarray
        Their trajectories.
    left_out : tuple of int
        Cases of the sweep without a trajectory (they did not simulate to the end).
    """

    t: np.ndarray
    percentiles: tuple
    bands: np.ndarray
    states: tuple
    cases: np.ndarray
    traces: np.ndarray
    left_out: tuple = ()


def montecarlo_bands(traces: dict, states, duration: float, cases: Iterable[int] = ()) -> MonteCarloBands:
    """The percentile bands of trajectories on the Monte Carlo grid.

    Parameters
    ----------
    traces : dict
        Case number -> (MC_POINTS, len(states)) deviations (:func:`resample_deviation`).
    states : sequence of str
    duration : float
        s, the run's length (the grid's end).
    cases : iterable of int, optional
        Every case of the sweep: those without a trajectory are listed as left out.

    Raises
    ------
    SweepError
        No trajectory at all, or one of another shape.

    Examples
    --------
    >>> b = montecarlo_bands({0: np.zeros((MC_POINTS, 1)), 1: np.ones((MC_POINTS, 1))}, ["pD"], 1.0)
    >>> float(b.bands[2, 0, 0])  # the median of 0 and 1
    0.5
    """
    shape = (MC_POINTS, len(states))
    if not traces:
        raise SweepError("no case of the Monte Carlo simulated to the end, so there are no bands; "
                         "see the reasons in sweep.csv")
    for case, trace in traces.items():
        if np.shape(trace) != shape:
            raise SweepError(f"case {case}: trajectory of shape {np.shape(trace)}, expected {shape} "
                             f"({MC_POINTS} times of {', '.join(states)})")
    order = sorted(traces)
    stack = np.stack([np.asarray(traces[k], dtype=np.float32) for k in order])
    bands = np.percentile(stack.astype(np.float64), MC_PERCENTILES, axis=0)
    return MonteCarloBands(t=mc_grid(duration), percentiles=tuple(float(p) for p in MC_PERCENTILES),
                           bands=bands, states=tuple(states), cases=np.array(order, dtype=np.int64),
                           traces=stack, left_out=tuple(int(c) for c in cases if c not in traces))


def montecarlo_png(bands: MonteCarloBands, cfg) -> bytes:
    """The Monte Carlo figure (:func:`quadctl.plots.montecarlo_figure`) as PNG bytes."""
    from quadctl import plots

    groups = {name: [s for s in sub.states if s in bands.states]
              for name, sub in cfg.partition().items() if sub.regulate}
    fig = plots.montecarlo_figure(bands, groups, title=cfg.name)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return buf.getvalue()


def to_csv(result: SweepResult) -> str:
    """The table as CSV: empty cells for missing values, ``true``/``false`` for flags."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(result.columns)
    for row in result.rows:
        writer.writerow([_cell(row.get(c)) for c in result.columns])
    return buf.getvalue()


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ""
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return str(value)


def summarize(result: SweepResult, cfg, spec: SweepSpec) -> dict:
    """The summary of a sweep: counts, each gate's failures, the worst and best cases.

    Deterministic (no timings), so the same sweep gives the same sweep.json apart from ``created``.
    """
    rows = result.rows
    statuses: dict[str, int] = {}
    for row in rows:
        statuses[row["status"]] = statuses.get(row["status"], 0) + 1
    gates = {}
    for gate in spec.gates:
        values = [r.get(gate.metric) for r in rows]
        numbers = [v for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]
        gates[gate.metric] = {
            "min": gate.min, "max": gate.max, "equals": gate.equals, "rule": gate.describe(),
            "failed": sum(not gate.passes(v) for v in values),
            "observed_min": min(numbers) if numbers else None,
            "observed_max": max(numbers) if numbers else None,
        }
    ranked = result.ranked()
    return {
        "sweep": {"file": spec.label, "mode": spec.mode, "samples": spec.samples, "seed": spec.seed,
                  "parameters": {p.path: p.spec for p in spec.parameters},
                  "set": {path: value for path, _, value in spec.fixed}, "require_ok": spec.require_ok},
        "cases": len(rows),
        "passed": sum(r["pass"] for r in rows),
        "failed": sum(not r["pass"] for r in rows),
        "statuses": statuses,
        "unstable": sum(r.get("stable") is False for r in rows),
        "gates": gates,
        "worst": [r for r in ranked[:WORST_SHOWN] if not r["pass"]] or ranked[:min(WORST_SHOWN, len(ranked))],
        "best": list(reversed(ranked[-BEST_SHOWN:])),
        "columns": result.columns,
        "ok": all(r["pass"] for r in rows),
    }


def tradeoff_axes(result: SweepResult) -> tuple[str, str]:
    """The plot's (x, y) metrics: a peak input against a settling time, the gated ones first."""
    gated = [g.metric for g in result.gates]
    xs = [m for m in gated if m.startswith("peak.")] + ["peak.T"]
    ys = [m for m in gated if m.startswith("settling_time.")] + \
         [c for c in result.columns if c.startswith("settling_time.")]
    return xs[0], (ys[0] if ys else "cost")


def tradeoff_png(result: SweepResult, cfg) -> bytes:
    """The trade-off figure as PNG bytes."""
    from quadctl import plots

    x, y = tradeoff_axes(result)
    fig = plots.sweep_tradeoff_figure(result.rows, x, y, result.gates, title=cfg.name)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return buf.getvalue()


@dataclass
class SweepOutcome:
    """What :func:`execute` did: the result, the summary written, the files, and what was reused."""

    result: SweepResult
    summary: dict
    out: Path
    reused: int = 0
    files: list = field(default_factory=list)


def execute(cfg, spec: SweepSpec, out: Path | str, *, label: str | None = None, jobs: int | None = None,
            scheduler: str | None = None, resume: bool = False,
            progress: Callable[[int, int], None] | None = None) -> SweepOutcome:
    """Run a sweep into a run directory: journal each chunk, resume, write the outputs.

    Parameters
    ----------
    cfg : Config
    spec : SweepSpec
    out : path
        Run directory (``sweep.csv``, ``sweep.json``, ``sweep.png``, ``sweep.parts/``; a Monte
        Carlo also ``montecarlo.png`` and ``montecarlo.npz``).
    label, jobs, scheduler, progress
        As :func:`run`.
    resume : bool
        Keep the rows of an earlier, interrupted run of this same sweep and compute only the rest.

    Returns
    -------
    SweepOutcome

    Raises
    ------
    SweepError
        ``resume`` finds rows of a different sweep, or the scheduler cannot be reached.
    """
    store = SweepStore(out, cfg, spec)
    done = store.start(resume)
    result = run(cfg, spec, label=label, jobs=jobs, scheduler=scheduler, done=done,
                 on_chunk=store.save_chunk, progress=progress)
    summary = store.finish(result)
    files = [store.out / "sweep.csv", store.out / "sweep.json", store.out / "sweep.png"]
    files += [store.out / name for name in summary["files"].get("montecarlo", [])]
    return SweepOutcome(result=result, summary=summary, out=store.out, reused=len(done), files=files)
