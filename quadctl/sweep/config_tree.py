"""A config as a mapping (a config tree, as YAML gives it or as dumped): a value read and put in by
key path, the way a sweep's ``set:`` values and each case's values go into the config they vary."""

from __future__ import annotations

from typing import Any

from quadctl.config.schema_paths import PLANT, default_at
from quadctl.text.messages import is_whole


def value_at(tree, keys):
    """The value at key path ``keys`` (names and list indices) of a config tree; None where the path ends."""
    for key in keys:
        try:
            tree = tree[key]
        except (KeyError, IndexError, TypeError):
            return None
    return tree


def with_sections(base: dict, paths) -> dict:
    """``base`` with ``simulation.plant`` spelled out (the design vehicle's values) when a path goes
    into it and the config has none: then ``simulation.plant.mass`` is a mass error to sweep, the
    other values staying the design model's (the same vehicle as no section at all)."""
    if base.get("simulation", {}).get("plant") is not None or not any(
            str(p).startswith("simulation.plant.") for p in paths):
        return base
    return assign(base, PLANT, default_at(base, PLANT))


def with_set(base: dict, fixed) -> dict:
    """The config mapping ``base`` with the sweep's ``set:`` values
    (:attr:`quadctl.sweep.spec.SweepSpec.fixed`) in, in order: a section given whole replaces the
    config's, and one the config leaves out is made."""
    for _, keys, value in fixed:
        base = assign(base, keys, value)
    return base


def assign(tree: Any, keys: tuple, value) -> Any:
    """A copy of ``tree`` with the value at ``keys`` replaced (only the path is copied); a section on
    the way that ``tree`` leaves out (absent or null) is made."""
    if not keys:
        return value
    head, rest = keys[0], keys[1:]
    if tree is None and isinstance(head, str):
        tree = {}
    if isinstance(tree, dict):
        out = dict(tree)
        out[head] = assign(tree.get(head), rest, value) if rest else typed_like(tree.get(head), value)
        return out
    out = list(tree)
    out[head] = assign(tree[head], rest, value) if rest else typed_like(tree[head], value)
    return out


def typed_like(old, value):
    """A whole float where the config holds an integer (a seed from a range): the integer."""
    if is_whole(old) and isinstance(value, float) and value.is_integer():
        return int(value)
    return value
