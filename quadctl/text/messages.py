"""The message helpers every input error is written with: key paths, values, near-miss hints.

One source for how quadctl shows what a user wrote, so a config error and a sweep-file error
read alike (``c.yaml: vehicle.mass = 68: ...``; ``did you mean `mass`?``).
"""

from __future__ import annotations

import difflib
import json
import math
import re
from typing import Any

SHOWN_CHARS = 60
"""A value shown in a message is cut to this many characters."""


KEY_PATH = re.compile(r"^[A-Za-z_][\w-]*(\[\d+\])*(\.[A-Za-z_][\w-]*(\[\d+\])*)*$")
"""A key path as written on the command line and in sweep files: ``vehicle.mass``, ``lqr.roll.Q[1]``."""


def parse_key_path(path: str) -> tuple:
    """``'lqr.roll.Q[1]'`` -> ``('lqr', 'roll', 'Q', 1)``, the inverse of :func:`key_path` (check the text
    against :data:`KEY_PATH` first).

    >>> parse_key_path('lqr.roll.Q[1]')
    ('lqr', 'roll', 'Q', 1)
    """
    keys: list = []
    for part in path.split("."):
        name, *indices = part.split("[")
        keys.append(name)
        keys.extend(int(i.rstrip("]")) for i in indices)
    return tuple(keys)


def key_path(loc) -> str:
    """``['lqr', 'roll', 'Q', 1]`` -> ``'lqr.roll.Q[1]'``.

    >>> key_path(['lqr', 'roll', 'Q', 1])
    'lqr.roll.Q[1]'
    """
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<top level>"


class KeyPathError(ValueError):
    """A key path that does not fit the tree it walks; the message is the reason, worded for the user."""


def child(node: Any, key, walked) -> Any:
    """``node[key]``: one step of a key path through a config's data (YAML's dicts and lists).

    ``walked`` is the part of the path already walked (``()`` at the top). A key a mapping lacks
    raises ``KeyError``, for the caller to decide (an error, or a section to add).

    Raises
    ------
    KeyPathError
        An index into what is not a list, past the end of a list, or a name into what is not a mapping.
    """
    here = key_path(list(walked)) if walked else "the config"
    if isinstance(key, int):
        if not isinstance(node, list):
            raise KeyPathError(f"{here} is not a list; drop the [{key}]")
        if key >= len(node):
            raise KeyPathError(f"index {key} out of range: {here} has {len(node)} values "
                               f"(indices 0 to {len(node) - 1})")
        return node[key]
    if not isinstance(node, dict):
        raise KeyPathError(f"{here} = {show(node)} has no key `{key}`; the path goes too deep")
    return node[key]


def kind_of(value: Any) -> str:
    """What a YAML document (or value) is, in a reader's words: where a mapping was due, what came instead.

    >>> kind_of(None), kind_of([1]), kind_of(42), kind_of("hover"), kind_of(True)
    ('empty', 'a list', 'a number', 'text', 'true or false')
    """
    if value is None:
        return "empty"
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "text"
    return "a list" if isinstance(value, list) else f"a {type(value).__name__}"


def show(value: Any, exact: bool = False) -> str:
    """A value as the user wrote it: whole floats without ``.0`` (unless ``exact``: where a whole
    number is due, ``1e3`` is shown as ``1000.0``), text quoted, cut to 60 characters.

    >>> show([1.0, 50.0, 0.5]), show("heavy"), show(1e300), show(1e3, exact=True)
    ('[1, 50, 0.5]', '"heavy"', '1e+300', '1000.0')
    """
    def plain(v):
        if isinstance(v, (list, tuple)):
            return [plain(x) for x in v]
        if isinstance(v, float) and v.is_integer() and abs(v) < 1e15 and not exact:
            return int(v)
        return v

    value = plain(value)
    if isinstance(value, float):
        text = repr(value)
    else:
        try:
            text = json.dumps(value, default=str)
        except (TypeError, ValueError):  # a mapping with non-text keys, say
            text = repr(value)
    return text if len(text) <= SHOWN_CHARS else text[:SHOWN_CHARS - 3] + "..."


def hint(name: str, allowed, many: bool = False, cutoff: float = 0.5) -> str:
    """``did you mean `X`?`` (same letters in another case first, then the nearest spelling, at least
    ``cutoff`` alike by :func:`difflib.get_close_matches`), else the list of what is allowed (cut to 12
    with ``many``).

    >>> hint("mas", ["mass", "gravity"]), hint("Q", ["q", "r"]), hint("zz", ["a", "b"])
    ('did you mean `mass`?', 'did you mean `q`?', 'allowed: a, b')
    """
    allowed = [str(a) for a in allowed]
    same_but_case = [a for a in allowed if a.lower() == name.lower()]
    near = same_but_case or difflib.get_close_matches(name, allowed, n=1, cutoff=cutoff)
    if near:
        return f"did you mean `{near[0]}`?"
    shown = allowed[:12] + ["..."] if many and len(allowed) > 12 else allowed
    return f"allowed: {', '.join(shown)}"


def unknown(name: str, allowed, kind: str) -> str:
    """``unknown state; did you mean `pD`?``"""
    return f"unknown {kind}; {hint(name, allowed)}"


def is_whole(value: Any) -> bool:
    """An int as YAML gives it (not a bool)."""
    return isinstance(value, int) and not isinstance(value, bool)


def whole_number(value: Any, at_least: int | None = None) -> str:
    """Why ``value`` is not a whole number (>= ``at_least``), with the fix when it is one written
    as a float (``2e4`` -> ``write 20000``)."""
    bound = f" >= {at_least}" if at_least is not None else ""
    if isinstance(value, float) and finite_number(value) and value.is_integer():
        if at_least is None or value >= at_least:
            return f"must be a whole number{bound}; write {int(value)}"
    return f"must be a whole number{bound}"


def finite_number(value: Any) -> bool:
    """A real number (int or float, not a bool), not NaN or infinite (nor an int past a float's range)."""
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # an int of more than 308 digits
        return False


def eig_text(e: complex, digits: int = 5) -> str:
    """An eigenvalue as every message and table prints it: ``-2.5`` or ``-1 + 3.2j`` (``digits``
    significant digits, no ``-0``; an imaginary part below 1e-9 is left out).

    >>> eig_text(-2.5 + 0j), eig_text(-1 - 3.21234j), eig_text(-14492.84, digits=6)
    ('-2.5', '-1 - 3.2123j', '-14492.8')
    """
    e = complex(e)
    e = complex(e.real + 0.0, e.imag + 0.0)  # no "-0"
    if abs(e.imag) < 1e-9:
        return f"{e.real:.{digits}g}"
    return f"{e.real:.{digits}g} {'+' if e.imag >= 0 else '-'} {abs(e.imag):.{digits}g}j"


def one_line(text: str) -> str:
    """A message on one line: the line breaks of a multi-line message (a library's, say) become
    spaces, so a log holds every error and warning on one line.

    >>> one_line("a\\n  b\\n")
    'a b'
    """
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())
