"""The unit of a config value named by its key path (``vehicle.mass``: kg, ``lqr.roll.Q[1]``: 1/rad^2), from
the places the config's units are declared, once each: :data:`~quadctl.config.unit_limits.UNIT_KEYS` for the
positions, velocities, headings and times, the schema's descriptions (each starts with its key's unit: ``kg``,
``N/(rad/s)^2, ...``), and the layout's states and inputs (:mod:`quadctl.layout`) for the LQR weights and the
values given per state or input. A sweep's ``sweep.json`` gives each parameter column its unit from here.
"""

from __future__ import annotations

import re
from typing import Any

from quadctl.config.schema import Config
from quadctl.config.schema_paths import first_model
from quadctl.config.unit_limits import SCHEDULE_UNITS, UNIT_KEYS
from quadctl.layout import INPUT_UNITS, STATE_UNITS, unit_of
from quadctl.text.messages import parse_key_path

_UNIT_WORD = re.compile(r"(?:kg|rad|Hz|deg|[msN]|[0-9/()^])+")
"""A word of a unit as the schema writes them (``kg``, ``m^2``, ``N/(rad/s)^2``, ``1/(m/s)``)."""
_NAMED_UNITS = ("state units", "input units")
"""What a description of a mapping keyed by state or input names says when each value is in its key's unit
(``simulation.initial_offset``, the noise's ``sensor``, ``limits``)."""


def key_unit(cfg: Config, path: str | tuple) -> str | None:
    """The unit of the value at a key path of ``cfg``, or None where it has none (a seed, a count, a name, a share,
    a choice) or where it depends on more than the config says (a PID value, in its flight stack's units).

    - ``lqr.<name>.Q[i]`` is 1/(unit of the i-th weighted quantity)^2 (``Q[i][j]``: 1/(unit i unit j)): the
      subsystem's states (:meth:`~quadctl.config.schema.Config.partition`), then the integrals of ``integral``
      in its order, as the design stacks them; ``R[i]`` is 1/(unit of the i-th input)^2; ``bryson.errors[i]``
      is in the unit of the i-th weighted quantity. The integral of a quantity in ``u`` is in ``u s``
      (``rad/s`` integrates to ``rad``).
    - a key of :data:`~quadctl.config.unit_limits.UNIT_KEYS` has its unit there (a heading along a path is in
      rad; a schedule's values in the unit of its variable, :data:`~quadctl.config.unit_limits.SCHEDULE_UNITS`);
    - a value given per state or input (``simulation.initial_offset.phi``, ``limits.T[0]``) is in that state's
      or input's unit (:func:`quadctl.layout.unit_of`) where the schema says so;
    - any other key: the unit its schema description begins with, if it begins with one.

    Parameters
    ----------
    cfg : Config
        A validated config: its partition and integrals place the LQR weights, its schedule's variable
        gives the values' unit.
    path : str or tuple
        The key path as written (``"lqr.roll.Q[1]"``) or parsed (``("lqr", "roll", "Q", 1)``).

    Returns
    -------
    str or None

    Examples
    --------
    >>> from quadctl import config
    >>> cfg = config.load("mambo-200hz")
    >>> [key_unit(cfg, k) for k in ("vehicle.mass", "lqr.roll.Q[1]", "lqr.altitude.Q[2]", "lqr.yaw.R[0]")]
    ['kg', '1/rad^2', '1/(m s)^2', '1/(N m)^2']
    >>> key_unit(cfg, "simulation.noise.seed") is None
    True
    """
    keys = parse_key_path(path) if isinstance(path, str) else tuple(path)
    if len(keys) >= 4 and keys[0] == "lqr" and isinstance(keys[1], str):
        return _weight_unit(cfg, keys)
    unit = _listed_unit(cfg, keys)
    if unit is not None:
        return unit
    field, name = _leaf_field(keys)
    description = (field.description or "") if field is not None else ""
    if name is not None:
        named = name in STATE_UNITS or name in INPUT_UNITS
        return unit_of(name) if named and any(s in description for s in _NAMED_UNITS) else None
    return _leading_unit(description)


def _weight_unit(cfg: Config, keys: tuple) -> str | None:
    """The unit of an entry of ``lqr.<name>``'s Q, R or ``bryson.errors``."""
    subsystem = cfg.partition().get(keys[1])
    weights = cfg.lqr.get(keys[1])
    if subsystem is None or weights is None:
        return None
    weighted = [unit_of(s) for s in subsystem.states] + [_integral(unit_of(s)) for s in weights.integral]
    inputs = [unit_of(i) for i in subsystem.inputs]
    kind, index = keys[2], keys[3:]
    if kind == "bryson" and len(index) == 2 and index[0] == "errors":
        return _item(weighted, index[1])
    units = {"Q": weighted, "R": inputs}.get(kind)
    if units is None or not all(isinstance(i, int) for i in index):
        return None
    given = getattr(weights, kind)
    full = bool(given) and isinstance(given[0], list)
    if len(index) == 1 and not full:
        index = (index[0], index[0])  # an entry of a diagonal
    if len(index) != 2 or _item(units, index[0]) is None or _item(units, index[1]) is None:
        return None
    a, b = units[index[0]], units[index[1]]
    if a == b:
        return f"1/{a}^2" if re.fullmatch(r"\w+", a) else f"1/({a})^2"
    return f"1/({_factor(a)} {_factor(b)})"


def _integral(unit: str) -> str:
    """The unit of the time integral of a quantity in ``unit``: ``m`` -> ``m s``, ``rad/s`` -> ``rad``."""
    return unit[:-2] if unit.endswith("/s") else f"{unit} s"


def _factor(unit: str) -> str:
    """``unit`` as a factor of a product: a quotient in parentheses."""
    return f"({unit})" if "/" in unit else unit


def _item(units: list[str], i: Any) -> str | None:
    return units[i] if isinstance(i, int) and 0 <= i < len(units) else None


def _listed_unit(cfg: Config, keys: tuple) -> str | None:
    """The unit of a key of :data:`UNIT_KEYS` (its first word: ``rad along a path`` is in rad)."""
    for pattern, unit in UNIT_KEYS:
        parts = tuple("*" if p == "*" else p for p in parse_key_path(pattern.replace("[*]", ".*")))
        if len(parts) == len(keys) and all(p == k or (p == "*" and isinstance(k, int)) for p, k in zip(parts, keys)):
            if unit == "schedule.variable":
                if cfg.schedule is None:
                    return None
                unit = SCHEDULE_UNITS[cfg.schedule.variable]
            return unit.split(" ")[0]
    return None


def _leaf_field(keys: tuple):
    """The schema field that holds the value at ``keys`` (list indices skipped), and the name it is
    keyed by when that field maps names to values (``initial_offset.phi``: ``"phi"``); (None, None) for a
    path that is not the schema's."""
    model: Any = Config
    field = name = section = None  # section: the model of a mapping of names to sections (lqr), its name next
    for key in keys:
        if isinstance(key, int):
            continue
        if section is not None:  # the name of a section (lqr.roll)
            model, section = section, None
            continue
        if model is None:  # inside a field's value: the name of a mapping of values, once
            if field is None or name is not None or not _mapping(field):
                return None, None
            name = key
            continue
        field = model.model_fields.get(key)
        if field is None:
            return None, None
        model = first_model(field.annotation)
        if model is not None and _mapping(field):
            model, section = None, model
    return (None, None) if section is not None else (field, name)


def _mapping(field) -> bool:
    """Whether a schema field is a mapping of names (``dict[str, ...]``)."""
    return "dict[" in str(field.annotation)


def _leading_unit(description: str) -> str | None:
    """The unit a schema description begins with (``"m/s, earth frame"``: ``m/s``; ``"kg m^2: ..."``:
    ``kg m^2``; ``"N per rotor"``: ``N``), or None (``"random seed"``)."""
    words = []
    for word in description.split(" "):
        bare = word.rstrip(",;:")
        if not (_UNIT_WORD.fullmatch(bare) and re.search(r"[A-Za-z]", bare)):
            break
        words.append(bare)
        if bare != word:
            break
    return " ".join(words) or None
