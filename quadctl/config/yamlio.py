"""The one YAML loader of quadctl: configs and sweep files are read, parsed and bounded here.

PyYAML's safe loader, changed so that every number and key reads as written: numbers as YAML 1.2
reads them (``1e5`` a number, ``010`` ten, ``1:30`` and dates text); duplicate keys refused, naming
both lines; size (:data:`MAX_BYTES`), depth (:data:`MAX_DEPTH`) and alias expansion
(:data:`MAX_EXPANDED`) bounded while parsing; every problem one line raised as the caller's error
class (:class:`~quadctl.errors.ConfigError`, :class:`~quadctl.errors.SweepError`). See
docs/reference/config.md ("How YAML is read").

Examples
--------
>>> load("vehicle: {mass: 68e-3, inertia: [6.9e-5, 7.75e-5, 1.5e-4]}\\nseed: 010", "c.yaml")
{'vehicle': {'mass': 0.068, 'inertia': [6.9e-05, 7.75e-05, 0.00015]}, 'seed': 10}
"""

from __future__ import annotations

import math
import os
import re
import stat
from pathlib import Path
from typing import Any

import yaml
from yaml.nodes import MappingNode, ScalarNode, SequenceNode

from quadctl.errors import ConfigError, QuadctlError
from quadctl.text.messages import key_path

MAX_BYTES = 1_000_000
"""Largest file read (bytes). The bundled configs are about 1.5 kB and a large sweep file a few
kB; a megabyte is a wrong path (a log, a data file, ``/dev/zero``), refused before it is read."""
MAX_DEPTH = 32
"""Deepest nesting of mappings and lists. A config nests 5 levels (``lqr.roll.Q[1][1]``); PyYAML
composes recursively, so 5000 levels would end in Python's RecursionError."""
MAX_EXPANDED = 2_000_000
"""Largest size of the document with its aliases expanded, counted as one per mapping, list and
value plus the characters of each value. Without aliases that is at most about the file's size
(so :data:`MAX_BYTES` bounds it); an alias (``*name``) repeats what its anchor (``&name``) marks,
so nested aliases multiply (a "billion laughs" of 1.6 kB stands for 9^9 values), and every reader
of the data (validation, hashing, JSON) would pay for the expansion."""
MAX_DIGITS = 400
"""Longest integer read (digits): past 1.8e308 no quadctl number is finite anyway, and Python
refuses to convert more than 4300 digits."""

_INT = "tag:yaml.org,2002:int"
_FLOAT = "tag:yaml.org,2002:float"
_TIMESTAMP = "tag:yaml.org,2002:timestamp"
_INT_RE = re.compile(r"""^(?:[-+]?[0-9][0-9_]*
                          |[-+]?0x[0-9a-fA-F_]+
                          |[-+]?0o[0-7_]+
                          |[-+]?0b[01_]+)$""", re.X)
_FLOAT_RE = re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                            |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                            |[-+]?\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                            |[-+]?\.(?:inf|Inf|INF)
                            |\.(?:nan|NaN|NAN))$""", re.X)


class _Bounded(Exception):
    """A bound or a duplicate key found while composing: the message without the file name."""


class Loader(yaml.SafeLoader):
    """PyYAML's safe loader with YAML 1.2 numbers, duplicate keys refused and resource bounds.

    Use :func:`load`; the loader raises :class:`_Bounded` for what it refuses itself.
    """

    # int, float and timestamp resolvers replaced: a fresh table, not the parent's
    yaml_implicit_resolvers = {
        first: [(tag, regexp) for tag, regexp in resolvers if tag not in (_INT, _FLOAT, _TIMESTAMP)]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()}

    def __init__(self, stream):
        super().__init__(stream)
        self._path: list = []
        self._depth = 0
        self._sizes: dict[int, int] = {}

    def compose_node(self, parent, index):
        if parent is None:
            part = None
        elif isinstance(parent, SequenceNode):
            part = index
        elif isinstance(index, ScalarNode):
            part = index.value
        else:  # a mapping's key itself
            part = None
        if part is not None:
            self._path.append(part)
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                mark = self.peek_event().start_mark
                raise _Bounded(f"{self._where(3)}nested more than {MAX_DEPTH} levels deep at line "
                               f"{mark.line + 1}; a config nests about 5: check the brackets")
            alias = self.check_event(yaml.AliasEvent)
            mark = self.peek_event().start_mark if alias else None
            node = super().compose_node(parent, index)
            if alias:
                if id(node) not in self._sizes:  # the anchor is still open: the alias is inside it
                    raise _Bounded(f"{self._where()}the alias at line {mark.line + 1} refers to a mapping "
                                   "or list that contains it (a recursive alias); write the values out")
            else:
                self._sizes[id(node)] = self._size_of(node)
            if self._sizes[id(node)] > MAX_EXPANDED:
                line = (mark or node.start_mark).line + 1
                raise _Bounded(f"{self._where()}at line {line} the aliases (*name) expand the document past "
                               f"{MAX_EXPANDED:,} values and characters: a YAML alias bomb? "
                               "write the values out")
            return node
        finally:
            self._depth -= 1
            if part is not None:
                self._path.pop()

    def compose_mapping_node(self, anchor):
        node = super().compose_mapping_node(anchor)
        seen: dict[tuple, Any] = {}
        for key, _ in node.value:
            if not isinstance(key, ScalarNode):
                continue
            ident = (key.tag, key.value)
            if ident in seen:
                first = seen[ident].start_mark.line + 1
                path = key_path([*self._path, key.value])
                raise _Bounded(f"{path}: duplicate key at lines {first} and {key.start_mark.line + 1}; "
                               "keep one (YAML would silently take the last)")
            seen[ident] = key
        return node

    def _size_of(self, node) -> int:
        if isinstance(node, ScalarNode):
            return 1 + len(node.value)
        if isinstance(node, SequenceNode):
            return 1 + sum(self._sizes[id(child)] for child in node.value)
        if isinstance(node, MappingNode):
            return 1 + sum(self._sizes[id(k)] + self._sizes[id(v)] for k, v in node.value)
        return 1

    def _where(self, parts: int | None = None) -> str:
        """The key path being read, as a message prefix (its first ``parts`` keys, then ...)."""
        if not self._path:
            return ""
        cut = parts is not None and len(self._path) > parts
        return f"{key_path(self._path[:parts] if cut else self._path)}{'...' if cut else ''}: "

    def construct_yaml_int(self, node):
        text = self.construct_scalar(node).replace("_", "")
        sign = -1 if text[0] == "-" else 1
        text = text.lstrip("+-")
        if len(text) > MAX_DIGITS:
            raise _Bounded(f"line {node.start_mark.line + 1}: a whole number of {len(text)} digits (quadctl "
                           f"reads at most {MAX_DIGITS}); quadctl's numbers end at about 1.8e308")
        base = {"0x": 16, "0o": 8, "0b": 2}.get(text[:2].lower(), 10)
        return sign * int(text[2:] if base != 10 else text, base)


Loader.add_constructor(_INT, Loader.construct_yaml_int)
Loader.add_implicit_resolver(_INT, _INT_RE, list("-+0123456789"))
Loader.add_implicit_resolver(_FLOAT, _FLOAT_RE, list("-+0123456789."))


class Dumper(yaml.SafeDumper):
    """PyYAML's safe dumper quoting what :class:`Loader` would read as another type (a text ``1e5``
    or ``010`` is a number to quadctl, so it is written ``'1e5'``) and writing a number as short as
    it reads back, with a point (``4.0``, ``1.0e-05``, ``1.11e+08``). Use :func:`dump` or :func:`flow`."""

    yaml_implicit_resolvers = {first: list(resolvers) for first, resolvers in Loader.yaml_implicit_resolvers.items()}

    def represent_float(self, data):
        """Six significant digits where they read back as ``data``, with a point in the mantissa so that
        any YAML reader (PyYAML's ``safe_load`` too) reads a float (``4.0``, ``1.0e-05``, ``1.11e+08``);
        PyYAML's own spelling otherwise (every digit, ``.inf``, ``.nan``, ``-0.0``)."""
        short = f"{data:.6g}"
        if not math.isfinite(data) or float(short) != data or short == "-0":
            return super().represent_float(data)
        mantissa, e, exponent = short.partition("e")
        return self.represent_scalar(_FLOAT, mantissa + ("" if "." in mantissa else ".0") + e + exponent)


Dumper.add_representer(float, Dumper.represent_float)


def dump(data: Any) -> str:
    """``data`` as a YAML document for people to read, quadctl's one way to write YAML: keys in their
    order, text as written (``Förster``, not ``F\\xF6rster``; only characters YAML cannot hold are
    escaped), numbers as short as they read back, with a point (``4.0``, ``1.0e-05``), and no line folded,
    however long (an editor or terminal wraps them for the reader).

    Examples
    --------
    >>> print(dump({"description": "rotor limits (Förster 2015)", "inertia": [6.9e-5, 7.75e-5], "id": "1e5"}), end="")
    description: rotor limits (Förster 2015)
    inertia:
    - 6.9e-05
    - 7.75e-05
    id: '1e5'
    """
    return yaml.dump(data, Dumper=Dumper, sort_keys=False, allow_unicode=True, width=float("inf"))


def flow(value: Any) -> str:
    """``value`` as one line of YAML to follow ``key: `` (lists and mappings in brackets), written as
    :func:`dump` writes.

    Examples
    --------
    >>> flow("Förster, identified from log.csv"), flow([1e-05, 0.068]), flow({"a": "yes"})
    ('Förster, identified from log.csv', '[1.0e-05, 0.068]', "{a: 'yes'}")
    """
    text = yaml.dump(value, Dumper=Dumper, default_flow_style=True, sort_keys=False, allow_unicode=True,
                     width=float("inf"))
    return text.removesuffix("...\n").strip("\n")


def load(text: str, label: str, error: type[QuadctlError] = ConfigError) -> Any:
    """Parse one YAML document as quadctl reads every file.

    Parameters
    ----------
    text : str
        The YAML text (at most :data:`MAX_BYTES` characters).
    label : str
        The file, named in every error.
    error : QuadctlError subclass
        What to raise (ConfigError, SweepError).

    Returns
    -------
    The data: dicts, lists, str, int, float, bool and None.

    Raises
    ------
    error
        One line: a syntax error with its line and column, a duplicate key with both lines, or
        a bound (size, depth, alias expansion) with its name and value.
    """
    if len(text) > MAX_BYTES:
        raise error(f"{label}: {len(text):,} characters, more than the {MAX_BYTES:,} quadctl reads; "
                    "a config or sweep file is a few kB: check the file")
    loader = None
    try:
        loader = Loader(text)  # the reader checks the characters here
        return loader.get_single_data()
    except _Bounded as exc:
        raise error(f"{label}: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        kind = "syntax error" if isinstance(exc, (yaml.scanner.ScannerError, yaml.parser.ParserError,
                                                  yaml.reader.ReaderError)) else "error"
        start = _start_mark(exc)
        if start is not None and (start.line, start.column) != (mark.line, mark.column):
            where = f" at line {start.line + 1}, column {start.column + 1}"
            problem = f"{exc.context}, {problem} (reading stopped at line {mark.line + 1}, column {mark.column + 1})"
        else:
            where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise error(f"{label}: YAML {kind}{where}: {_in_plain_words(text, mark, problem)}") from None
    except RecursionError:  # MAX_DEPTH keeps the composer shallow; this is the last line of defence
        raise error(f"{label}: nested too deeply to read; check the brackets") from None
    finally:
        if loader is not None:
            loader.dispose()


def _start_mark(exc: yaml.YAMLError):
    """Where the problem starts, when PyYAML says so apart from where it stopped reading: the key, quoted
    text, anchor, tag or block scalar it was scanning, or the ``[`` or ``{`` left open (its context mark).
    None otherwise, and for a block mapping or list, whose context mark is where the enclosing block
    begins (often line 1): farther from the problem than where reading stopped."""
    context, start, mark = (getattr(exc, name, None) for name in ("context", "context_mark", "problem_mark"))
    if start is None or mark is None or not isinstance(context, str):
        return None
    return start if context.startswith(("while scanning", "while parsing a flow")) else None


_KEY_WITHOUT_SPACE = re.compile(r"^\s*(?:-\s+)?[A-Za-z_][\w-]*:[^\s:/]\S*")
"""A line that starts ``key:value`` (no space after the colon): YAML reads it as one word, not a key."""


def _in_plain_words(text: str, mark, problem: str) -> str:
    """The parser's ``problem`` with the fix of its common causes in plain words: a tab where YAML
    wants spaces, or a ``key:value`` line (the nearest at or above the error) missing its space."""
    lines = text.splitlines()
    if mark is None or mark.line >= len(lines):
        return f"{problem}; fix the YAML"
    if lines[mark.line][mark.column:mark.column + 1] == "\t":
        return "a tab character; YAML indents with spaces, not tabs: replace the tab with spaces"
    for number in range(mark.line, -1, -1):
        found = _KEY_WITHOUT_SPACE.match(lines[number])
        if found:
            return (f"{problem}; line {number + 1} has `{found.group().strip()}`, one word to YAML: write "
                    "`key: value` with a space after the colon")
    return f"{problem}; fix the YAML"


def read_text(path: str | Path, label: str, what: str, error: type[QuadctlError] = ConfigError) -> str:
    """The UTF-8 text of a file, read with a size cap.

    A regular file larger than :data:`MAX_BYTES` is refused from its size, without reading; any
    other file (a pipe, ``/dev/stdin``, a device such as ``/dev/zero``) is read up to the cap.

    Parameters
    ----------
    path : path
    label : str
        How to name the file in errors.
    what : str
        ``"config file"`` or ``"sweep file"``.
    error : QuadctlError subclass

    Raises
    ------
    error
        The file does not exist, is a folder, is too large, cannot be read or is not UTF-8.
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise error(f"{label}: no such {what}; check the path") from None
    except OSError as exc:
        raise error(f"{label}: cannot read the {what} ({_reason(exc)}); check the file") from None
    if stat.S_ISDIR(info.st_mode):
        raise error(f"{label}: is a folder, not a {what}; give a .yaml file")
    too_big = (f"{label}: more than {MAX_BYTES:,} bytes, the most quadctl reads for a {what}; "
               f"a {what} is a few kB: check the path")
    if stat.S_ISREG(info.st_mode) and info.st_size > MAX_BYTES:
        raise error(too_big)
    try:
        with open(path, "rb") as stream:
            data = stream.read(MAX_BYTES + 1)
    except OSError as exc:
        raise error(f"{label}: cannot read the {what} ({_reason(exc)}); check the file") from None
    if len(data) > MAX_BYTES:
        raise error(too_big)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{label}: cannot read the {what} (not UTF-8 text: {exc.reason} at byte {exc.start}); "
                    "save it as UTF-8") from None


def _reason(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__
