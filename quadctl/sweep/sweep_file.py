"""The sweep file: parameters by key path, values, distributions and gates, read, parsed and checked
against the config they vary into a :class:`~quadctl.sweep.spec.SweepSpec`.
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from quadctl import config
from quadctl.config import yamlio
from quadctl.config.key_units import key_unit
from quadctl.config.kinds import misplaced
from quadctl.config.schema import Config
from quadctl.config.schema_paths import default_at, section_model
from quadctl.errors import ArgumentTypeError, ConfigError, SweepError
from quadctl.layout import STATE_NAMES
from quadctl.sweep.config_tree import assign, value_at, with_sections, with_set
from quadctl.sweep.gates import CASE_STATUSES, MARGIN_COLUMNS, Gate, gated_margins, metric_columns
from quadctl.sweep.spec import Parameter, SweepSpec
from quadctl.sweep.uncertainty import plant_side
from quadctl.text.messages import (
    KEY_PATH,
    KeyPathError,
    child,
    finite_number,
    hint,
    is_whole,
    key_path,
    kind_of,
    parse_key_path,
    show,
    whole_number,
)

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
"""Most cases a sweep runs (a grid, or ``samples`` in random mode), checked before any is listed.
Every case is listed up front and its row (about 60 columns) stays in memory until sweep.csv is
written, so a million is what a workstation holds comfortably, and at the thousand cases a
second two cores manage it is already a 20-minute run; ``samples: 1000000000`` would exhaust the
memory before the first case ran."""


def load(path: str | Path, cfg) -> SweepSpec:
    """Read and validate a sweep file against the config it varies.

    Raises
    ------
    SweepError
        One line naming the file, the key and the fix.
    """
    text = yamlio.read_text(path, str(path), "sweep file", SweepError)
    return parse(text, cfg, str(path))


def parse(text: str, cfg, label: str = "<sweep>") -> SweepSpec:
    """Validate YAML text as a sweep file; ``label`` names it in errors.

    The text is read by :func:`quadctl.config.yamlio.load`, the loader configs are read with, so a
    number reads the same in both (``68e-3``, ``5e0``) and the same bounds hold."""
    return from_dict(yamlio.load(text, label, SweepError), cfg, label)


def from_dict(data: Any, cfg, label: str = "<sweep>") -> SweepSpec:
    """Validate a mapping (as YAML gives it) as a sweep of ``cfg``.

    Parameters
    ----------
    data : dict
        The sweep file's mapping: ``parameters`` (key path -> values, a range or a distribution) and
        optionally ``mode``, ``samples``, ``seed``, ``set``, ``gates``, ``require_ok``, ``chunk_size``.
    cfg : Config
        The config it varies (:func:`quadctl.config.loading.load`): each key path is checked against it.
    label : str
        Names the sweep in errors.

    Returns
    -------
    SweepSpec

    Raises
    ------
    SweepError
        One line naming the key and the fix (a ``ValueError``).
    ArgumentTypeError
        ``cfg`` is not a :class:`~quadctl.config.schema.Config` (a ``TypeError``).

    Examples
    --------
    >>> import quadctl as qc
    >>> from quadctl import sweep
    >>> spec = sweep.from_dict({"parameters": {"lqr.pitch.Q[1]": [25, 50, 100]}}, qc.load_config("hover"))
    >>> spec.mode, len(spec.cases())
    ('grid', 3)
    """

    def fail(where: str, why: str) -> SweepError:
        return SweepError(f"{label}: {where}: {why}")

    if not isinstance(cfg, Config):
        raise ArgumentTypeError(f"a sweep varies a validated Config, sweep.from_dict(data, qc.load_config('hover')); "
                                f"got {type(cfg).__name__}")
    if not isinstance(data, dict):
        raise SweepError(f"{label}: the sweep file is {kind_of(data)}, not a mapping; "
                         "give at least `parameters:` (see examples/ci-sweep.yaml)")
    for key in data:
        if key not in TOP_KEYS:
            raise SweepError(misplaced(data, label, "sweep") or f"{label}: {key}: unknown key; "
                             + hint(str(key), TOP_KEYS))
    mode = data.get("mode", "grid")
    if mode not in MODES:
        raise fail("mode", f"{show(mode)} is not a mode; use grid or random")
    samples = data.get("samples")
    if mode == "random":
        if samples is None:
            raise fail("samples", "random mode needs the number of cases; add `samples: 100`, say")
    else:  # a grid runs every combination of the values given: nothing is drawn
        for key, drawn in (("samples", "that many cases"), ("seed", "its cases from that seed")):
            if key in data:
                raise fail(key, f"{show(data[key])}: a grid runs every combination of the parameters' values "
                           f"and takes no {key}; remove it, or set mode: random to draw {drawn}")
    if samples is not None and (not is_whole(samples) or samples < 1):
        raise fail("samples", f"{show(samples, exact=True)}: {whole_number(samples, 1)}")
    if samples is not None and samples > MAX_CASES:
        raise fail("samples", f"{show(samples)}: more than {MAX_CASES:,} cases, the most a sweep runs; "
                   "run fewer samples, or split the sweep into several files")
    seed = data.get("seed", 0)
    if not is_whole(seed) or seed < 0:
        raise fail("seed", f"{show(seed, exact=True)}: {whole_number(seed, 0)}")
    chunk = data.get("chunk_size")
    if chunk is not None and (not is_whole(chunk) or chunk < 1):
        raise fail("chunk_size", f"{show(chunk, exact=True)}: {whole_number(chunk, 1)}")
    require_ok = data.get("require_ok", True)
    if not isinstance(require_ok, bool):
        raise fail("require_ok", f"{show(require_ok)}: must be true or false")

    params = data.get("parameters")
    if not isinstance(params, dict) or not params:
        raise fail("parameters", "nothing to vary; add at least one key path, "
                   "such as `lqr.roll.Q[1]: [10, 50, 100]`")
    sets = data.get("set") or {}
    if not isinstance(sets, dict):
        raise fail("set", "must be a mapping of key path -> value")
    base = with_sections(cfg.model_dump(mode="json"), [str(p) for p in params] + [str(p) for p in sets])
    fixed = []
    for path, value in sets.items():
        keys = check_path(base, str(path), label, "set")
        if str(path) in params:
            raise fail(f"set.{path}", "is also a parameter; keep it in one place")
        fixed.append((str(path), keys, value))
    base = with_set(base, fixed)  # the parameters vary the config as set: leaves it (a section it made)
    parameters = []
    for path, spec in params.items():
        keys = check_path(base, str(path), label, "parameters")
        kind = _check_values(spec, str(path), mode, label)
        leaf = value_at(base, keys)
        if isinstance(leaf, list) and kind != "values":
            raise fail(f"parameters.{path}", f"is a list ({show(leaf)}) here, a range gives numbers; "
                       f"index one entry, as `{path}[0]`")
        parameters.append(Parameter(str(path), keys, kind, spec))
    _check_nesting(fixed, parameters, fail)
    start = configured(cfg, fixed, label, [(p.keys, _representative(p)) for p in parameters])
    if data.get("gates") is not None and not isinstance(data.get("gates"), dict):
        raise fail("gates", "must be a mapping of metric -> {min, max}")
    gates = tuple(_check_gate(metric, spec, start, label) for metric, spec in (data.get("gates") or {}).items())
    if any(p.path == "simulation.method" for p in parameters):
        raise SweepError(f"{label}: parameters.simulation.method: a sweep runs one integrator in its lanes; "
                         "set it under `set:` (or in the config), and sweep the methods as two sweeps")
    rotor_lag = fixed_value(fixed, "controller.rotor_lag", cfg.controller.rotor_lag)
    trim_wind = fixed_value(fixed, "trim.wind", cfg.trim.wind)
    estimator = cfg.estimator
    if any(p == "estimator" or p.startswith("estimator.") for p, _, _ in fixed):
        estimator = SimpleNamespace(force=None, torque=None, sensor={})  # set: may add one: a filter that
                                                                         # takes every noise value
    spec = SweepSpec(label=label, mode=mode, samples=int(samples) if samples is not None else None,
                     seed=int(seed), parameters=tuple(parameters), fixed=tuple(fixed), gates=gates,
                     require_ok=require_ok, chunk_size=int(chunk) if chunk is not None else None,
                     canonical=json.loads(json.dumps({k: v for k, v in data.items() if k != "description"},
                                                     default=str)),
                     uncertainty=all(plant_side(p.keys, rotor_lag, bool(trim_wind), estimator) for p in parameters),
                     metrics=tuple(metric_columns(start)) + (MARGIN_COLUMNS if gated_margins(gates) else ()),
                     parameter_units=tuple((p.path, unit) for p in parameters
                                           if (unit := key_unit(start, p.keys)) is not None))
    if mode == "grid":
        count = spec.count()
        if count > MAX_CASES:
            sizes = " x ".join(str(p.size()) for p in parameters)
            raise fail("parameters", f"the grid has {sizes} = {count:,} cases, more than {MAX_CASES:,} "
                       "(the most a sweep runs); use fewer values, or mode: random with samples")
    return spec


def _check_values(spec, path: str, mode: str, label: str) -> str:
    where = f"{label}: parameters.{path}"
    if isinstance(spec, list):
        if not spec:
            raise SweepError(f"{where}: empty list; give at least one value")
        return "values"
    if not isinstance(spec, dict):
        raise SweepError(f"{where} = {show(spec)}: give a list of values, a range "
                         "{from, to, num} or, in random mode, a {distribution: ...}")
    if "distribution" in spec:
        if mode != "random":
            raise SweepError(f"{where}: a distribution needs mode: random (a grid takes lists and ranges)")
        kind = spec["distribution"]
        if kind not in DISTRIBUTIONS:
            raise SweepError(f"{where}: unknown distribution {show(kind)}; "
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
            raise SweepError(f"{where}.std = {show(spec['std'])}: must be >= 0")
        if kind in ("uniform", "loguniform") and not spec["low"] < spec["high"]:
            raise SweepError(f"{where}: empty range: low {show(spec['low'])} must be below "
                             f"high {show(spec['high'])}")
        if kind == "loguniform" and spec["low"] <= 0:
            raise SweepError(f"{where}.low = {show(spec['low'])}: loguniform needs low > 0")
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
        if not is_whole(num) or num < 1:
            why = "empty range; num " if finite_number(num) and num < 1 else "num "
            raise SweepError(f"{where}.num = {show(num, exact=True)}: {why}{whole_number(num, 1)}")
        if num > MAX_CASES:
            raise SweepError(f"{where}.num = {show(num)}: more than {MAX_CASES:,} values, the most cases a "
                             "sweep runs; use fewer")
    scale = spec.get("scale", "linear")
    if scale not in ("linear", "log"):
        raise SweepError(f"{where}.scale = {show(scale)}: use linear or log")
    if scale == "log" and (spec["from"] <= 0 or spec["to"] <= 0):
        raise SweepError(f"{where}: a log range needs from and to > 0")
    if mode == "random" and spec["from"] == spec["to"]:
        raise SweepError(f"{where}: empty range: from equals to; give a list for one value")
    return "range"


def _inside(keys: tuple, outer: tuple) -> bool:
    """Whether the key path ``keys`` lies inside ``outer`` (``vehicle.inertia[0]`` inside ``vehicle.inertia``)."""
    return len(keys) > len(outer) and keys[:len(outer)] == outer


def _check_nesting(fixed, parameters, fail) -> None:
    """Refuse a key path the sweep would write over with a later value of a path around it: a ``set:`` value
    inside a later ``set:`` section or inside a parameter, and a parameter inside another parameter (each case
    takes one of the two; the results' column would show values no case flew). A parameter inside a ``set:``
    section varies what ``set:`` made, as documented."""
    for i, (path, keys, _) in enumerate(fixed):
        later = next((p for p, k, _ in fixed[i + 1:] if _inside(keys, k)), None)
        if later is not None:
            raise fail(f"set.{path}", f"lies inside set.{later}, which follows and gives it whole; put set.{path} "
                                      f"after it, or its value inside it")
        around = next((p.path for p in parameters if _inside(keys, p.keys)), None)
        if around is not None:
            raise fail(f"set.{path}", f"lies inside parameters.{around}, whose values replace it in every case; "
                                      f"give the value in those")
    for p in parameters:
        around = next((q.path for q in parameters if _inside(p.keys, q.keys)), None)
        if around is not None:
            raise fail(f"parameters.{p.path}", f"lies inside parameters.{around}: a case would fly one of the two "
                                               "values; vary one of them")


def fixed_value(fixed, path: str, default):
    """The value the sweep's ``set:`` gives the key ``path`` (``fixed``: :attr:`SweepSpec.fixed`), else ``default``."""
    return next((v for p, _, v in fixed if p == path), default)


def check_path(tree: dict, path: str, label: str, section: str) -> tuple:
    """Parse ``path`` and check that it names a value of the config ``tree`` (``section``
    ``parameters``) or a value or a whole section (``set``, which may also make a section the config
    leaves out). A key the schema takes that a section given by ``set:`` leaves out is its default.

    Raises SweepError naming the first part that does not exist, and the nearest valid key.
    """
    where = f"{label}: {section}.{path}"
    if not KEY_PATH.match(path):
        raise SweepError(f"{where}: not a key path; write it as `lqr.roll.Q[1]` or `vehicle.mass`")
    keys = parse_key_path(path)
    node = tree
    for k, key in enumerate(keys):
        walked = keys[:k]
        if node is None and walked:  # an optional section the config leaves out (null)
            here = _path_text(walked)
            if section != "set" or section_model(list(walked)) is None:
                raise SweepError(f"{where}: the config has no `{here}` section (it is null); add a `{here}:` "
                                 f"section to the config, or give it under the sweep's `set:`, to vary its keys")
            node = {}  # set: makes it
        try:
            node = child(node, key, walked)
        except KeyPathError as exc:
            raise SweepError(f"{where}: {exc}") from None
        except KeyError:
            if tuple(walked) in FREE_MAPPINGS and k == len(keys) - 1:
                if key not in STATE_NAMES:  # a new key of a free mapping: another state's offset
                    raise SweepError(f"{where}: `{key}` is not a state; " + hint(key, STATE_NAMES)) from None
                return keys
            model = section_model(list(walked))
            known = [str(x) for x in node] + [f for f in (model.model_fields if model else ()) if f not in node]
            if model is None or key not in model.model_fields:
                raise SweepError(f"{where}: no such key in the config: `{_path_text([*walked, key])}`; "
                                 + hint(key, known)) from None
            node = default_at(tree, keys[:k + 1])  # a key a section given by set: leaves out
    if isinstance(node, dict) and section != "set":
        raise SweepError(f"{where}: is a section, not a value; name one of its keys: "
                         f"{', '.join(map(str, node))}, or set it whole under the sweep's `set:`")
    return keys


def _path_text(keys) -> str:
    return key_path(list(keys)) if keys else ""


def _check_gate(metric, spec, cfg, label: str) -> Gate:
    metric = str(metric)
    where = f"{label}: gates.{metric}"
    known = metric_columns(cfg)
    gateable = [m for m in known if m not in ("dt", "steps")] + ["steps", *MARGIN_COLUMNS]
    if metric not in gateable:
        family, _, name = metric.partition(".")
        if family in ("settling_time", "overshoot") and name in STATE_NAMES:
            regulated = [m.partition(".")[2] for m in known if m.startswith(family + ".")]
            raise SweepError(f"{where}: {name} is not regulated, so it has no {family.replace('_', ' ')}; "
                             f"regulated states: {', '.join(regulated)}")
        raise SweepError(f"{where}: unknown metric; " + hint(metric, gateable, many=True))
    if not isinstance(spec, dict) or not spec:
        raise SweepError(f"{where}: give a threshold, as {{max: 3.0}} or {{min: 0}}")
    for key in spec:
        if key not in GATE_KEYS:
            raise SweepError(f"{where}.{key}: unknown key; " + hint(str(key), GATE_KEYS))
    if metric in ("stable", "status"):
        if set(spec) != {"equals"}:
            raise SweepError(f"{where}: {metric} takes {{equals: {'true' if metric == 'stable' else 'ok'}}}")
        value = spec["equals"]
        if metric == "stable" and not isinstance(value, bool):  # a case is stable or not: no other value passes
            raise SweepError(f"{where}.equals = {json.dumps(value)}: stable is true or false")
        if metric == "status" and value not in CASE_STATUSES:  # a value no case has: every case would fail
            raise SweepError(f"{where}.equals = {json.dumps(value)}: no case has that status; "
                             + hint(str(value), CASE_STATUSES))
        return Gate(metric, equals=value)
    if "equals" in spec:
        raise SweepError(f"{where}: a number takes min and max, not equals")
    for key in ("min", "max"):
        if key in spec:
            _finite(spec[key], f"{where}.{key}")
    if "min" in spec and "max" in spec and spec["min"] > spec["max"]:
        raise SweepError(f"{where}: min {spec['min']} is above max {spec['max']}; no case can pass")
    return Gate(metric, min=_num(spec.get("min")), max=_num(spec.get("max")))


def configured(cfg, fixed, label: str = "<sweep>", varied=()):
    """The config the cases start from: ``cfg`` with the ``set:`` values ``fixed`` in, validated.

    Where they do not make a valid config on their own, the same with the values ``varied``
    (``(keys, value)`` pairs: one value of each parameter, :func:`_representative`) in too, as a
    case's values may make it valid; else ``cfg`` itself (each case is validated when it runs). A
    key no config takes is refused at once.

    Raises
    ------
    SweepError
        A ``set:`` value holds a key the config does not take (``set.simulation.reference.sped``), or a
        value its key refuses whatever the rest of the config holds (``set.simulation.duration = -1``).
    """

    if not fixed:
        return cfg
    data = with_set(with_sections(cfg.model_dump(mode="json"), [p for p, _, _ in fixed]), fixed)
    try:
        return config.from_dict(data, f"{label}: set")
    except ConfigError as exc:
        if "unknown key" in str(exc):  # no parameter makes an unknown key known: the set: value's slip
            raise SweepError(str(exc)) from None
    for keys, value in varied:
        data = assign(data, keys, value)
    try:
        return config.from_dict(data, label)
    except ConfigError:
        for path, _, value in fixed:  # a value its own key refuses: no case's values make it valid
            why = config.refusal(path, value)
            if why is not None:
                raise SweepError(f"{label}: set.{path} = {show(value)}: {why}") from None
        return cfg


def _representative(p: Parameter):
    """One value of the parameter ``p``, without drawing: its first value, a range's ``from``, a
    distribution's ``low``, ``mean`` or first choice."""
    spec = p.spec
    if p.kind == "values":
        return spec[0]
    if p.kind == "range":
        return spec["from"]
    return {"uniform": spec.get("low"), "loguniform": spec.get("low"), "normal": spec.get("mean"),
            "choice": (spec.get("values") or [None])[0]}[spec["distribution"]]


MAX_MAGNITUDE = 1e300
"""Largest magnitude of a number in a range, a distribution or a gate: the width of a range
(``to - from``) and a normal draw must stay finite. The values go on to the config, which has
its own, tighter bounds."""


def _finite(value, where: str) -> None:
    if not finite_number(value):
        raise SweepError(f"{where} = {show(value)}: must be a finite number")
    if abs(value) > MAX_MAGNITUDE:
        raise SweepError(f"{where} = {show(value)}: must be at most {MAX_MAGNITUDE:g} in magnitude")


def _num(value):
    return None if value is None else float(value)
