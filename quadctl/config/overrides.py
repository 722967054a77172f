"""``--set KEY=VALUE``: a value put into a config's YAML at a key path, then validated with the file.

A variation of a config without an edited copy (``--set simulation.duration=30``). The value is read
as YAML (:func:`quadctl.config.yamlio.load`: ``30`` is a number, ``[0.02, 0.02, 0.04]`` a list, ``discrete``
text), put into the file's data at its key path (a section the file leaves out is added), and the
whole is validated by the one schema (:func:`quadctl.config.from_dict`): a bad key or value is refused
as it would be in the file, naming ``--set``.

Examples
--------
>>> cfg = load(config.bundled("hover"), ["simulation.duration=30", "vehicle.inertia=[0.02, 0.02, 0.04]"])
>>> cfg.simulation.duration, cfg.vehicle.inertia
(30.0, [0.02, 0.02, 0.04])
>>> load(config.bundled("hover"), ["simulation.duration=-30"])
Traceback (most recent call last):
...
quadctl.errors.ConfigError: --set: simulation.duration = -30: must be greater than 0.0 (s)
"""

from __future__ import annotations

import copy
from typing import Any, NamedTuple

from quadctl import config
from quadctl.config import Config, Source, yamlio
from quadctl.errors import ConfigError
from quadctl.text.messages import KEY_PATH, KeyPathError, child, hint, key_path, parse_key_path, show

OPTION = "--set"
EXAMPLE = "`--set simulation.duration=30`"


class Assignment(NamedTuple):
    """One ``--set``: the key path as written, its parts (``('lqr', 'roll', 'Q', 1)``) and the value."""

    path: str
    keys: tuple
    value: Any


def parse(text: str) -> Assignment:
    """``'lqr.roll.Q[1]=50'`` -> ``Assignment('lqr.roll.Q[1]', ('lqr', 'roll', 'Q', 1), 50)``.

    Raises
    ------
    ConfigError
        No ``=``, a key that is not a key path, or a value that is not YAML.
    """
    path, eq, value = text.partition("=")
    path = path.strip()
    if not eq:
        raise ConfigError(f"{OPTION} {text}: give KEY=VALUE, as {EXAMPLE}")
    if not KEY_PATH.match(path):
        raise ConfigError(f"{OPTION} {text}: {path or 'the key'} is not a key path; write it as "
                          "`simulation.duration` or `lqr.roll.Q[1]`")
    return Assignment(path, parse_key_path(path), yamlio.load(value, f"{OPTION} {path}", ConfigError))


def apply(data: Any, assignments) -> dict:
    """A copy of the config's data (as YAML gives it) with each assignment put in, in order, those
    under ``simulation.plant`` last: a plant the file leaves out stands for the design vehicle, so an
    index into it starts from the vehicle as every other assignment leaves it, whatever their order.

    Raises
    ------
    ConfigError
        A key path that goes through a value (``vehicle.mass.x``) or past the end of a list.
    """
    out = copy.deepcopy(data) if isinstance(data, dict) else {}
    for a in sorted(assignments, key=lambda a: list(a.keys[:2]) == ["simulation", "plant"]):  # stable
        node: Any = out
        *parents, last = a.keys
        try:
            for k, key in enumerate(parents):
                if isinstance(node, dict) and node.get(key) is None:  # a section or list the file leaves out
                    node[key] = _absent(out, a, k)
                node = child(node, key, a.keys[:k])
            if isinstance(last, int) or not isinstance(node, dict):
                child(node, last, parents)  # the list and its index exist, or the path goes too deep
        except KeyPathError as exc:
            raise ConfigError(f"{OPTION} {a.path}: {exc}") from None
        node[last] = a.value
    return out


def _absent(data: dict, a: Assignment, k: int):
    """What ``a`` walks into at its ``k``-th key, which ``data`` leaves out: a new section, or the list
    the config holds there when it is left out (:func:`quadctl.config.default_at`: the design vehicle's
    ``simulation.plant.inertia``, the schema's ``[0, 0, 0]`` of ``simulation.noise.force``).

    Raises
    ------
    ConfigError
        An index into a list the config does not hold (no default): the whole list is to be given.
    """
    if not isinstance(a.keys[k + 1], int):
        return {}
    default = config.default_at(data, a.keys[:k + 1])
    index = a.keys[k + 1]
    if isinstance(default, list) and index < len(default):
        return default
    here = key_path(list(a.keys[:k + 1]))
    why = (f"its default {show(default)} has no [{index}]" if isinstance(default, list)
           else "it has no default list")
    raise ConfigError(f"{OPTION} {a.path} = {show(a.value)}: the config leaves `{here}` out and {why}; "
                      f"set the whole list: {OPTION} {here}=[...]")


def load(source: Source, sets=()) -> Config:
    """The config of ``source`` with the ``--set`` values ``sets`` (``KEY=VALUE`` texts) put in.

    Errors of the file's own keys name the file; an error that only the assignments cause names
    ``--set`` (``--set: simulation.duration = -1: must be greater than 0 ...``).
    """
    if not sets:
        return config.parse(source.text, source.label)
    assignments = [parse(text) for text in sets]
    data = yamlio.load(source.text, source.label, ConfigError)
    merged = apply(data, assignments)
    try:
        return config.from_dict(merged, source.label)
    except ConfigError as exc:
        tree = config.from_dict(data, source.label).model_dump(mode="json")  # the file's own error names the file
        if "unknown key" not in str(exc):  # a name the schema takes (lqr.rol) but no part of the config has
            created = [(a, c) for a in assignments if (c := _created(tree, a.keys)) is not None]
            named = {key_path(c[0]) for _, c in created}
            if exc.key not in named:  # (else the checks name that key themselves, with the names allowed
                # there: `unknown state; allowed: ...`, whatever other keys the --set values add)
                for a, (path, siblings) in created:
                    if _refused(data, a, source.label):  # the key this one adds is the one refused
                        raise ConfigError(f"{OPTION} {a.path}: no such key in the config: `{key_path(path)}`; "
                                          + hint(str(path[-1]), siblings)) from None
        return config.from_dict(merged, OPTION)  # else the values given here caused it: raises naming --set


def _refused(data: Any, a: Assignment, label: str) -> bool:
    """Whether the config's data with ``a`` alone put in fails validation."""
    try:
        config.from_dict(apply(data, [a]), label)
    except ConfigError:
        return True
    return False


def _created(tree: Any, keys: tuple):
    """(the key path up to the first key ``keys`` adds to a mapping of the config ``tree``, the keys there)
    or None when every key exists (or goes into a section the config leaves out, null)."""
    node = tree
    for k, key in enumerate(keys):
        try:
            node = child(node, key, keys[:k])
        except KeyPathError:
            return None
        except KeyError:
            return keys[:k + 1], [str(x) for x in node]
    return None

def recorded(text: str, sets) -> str:
    """The config's text with the ``--set`` values after it as comments (``config.yaml``: what made the run).

    A value that spans lines is commented on each of them (split where YAML, or Python, breaks a line:
    ``\\r`` and the Unicode line separators too), so the file still reads as the config alone.

    >>> print(recorded("name: x\\n", ["description=a\\nb"]), end="")
    name: x
    # run with these values put in (config.resolved.yaml holds the result):
    #   --set description=a
    #     b
    """
    if not sets:
        return text
    lines = "".join(f"#   {OPTION} " + "\n#     ".join(s.splitlines() or [""]) + "\n" for s in sets)
    return (text if text.endswith("\n") else text + "\n") + (
        f"# run with these values put in (config.resolved.yaml holds the result):\n{lines}")
