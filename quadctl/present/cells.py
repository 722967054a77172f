"""The pieces every presented result is made of: a table, a verdict cell, the number formats.

Numbers are written as the stage commands print them: the trim with 6 significant digits, gains
and metrics with 4, margins with 3, eigenvalues with 5 (:func:`eig`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl.text.messages import eig_text

NBSP = "\u00a0"
"""A space no line is broken at: between a number and its unit (``10 s``); the terminal and the report keep it."""


class Mark(str):
    """A cell or a sentence that carries a verdict: ``kind`` is ``ok``, ``warning`` or ``fail``.

    It is its text everywhere a ``str`` is (the report escapes it like any cell); a renderer
    that colours reads ``kind``.

    >>> m = Mark("yes", "ok")
    >>> m == "yes", m.kind
    (True, 'ok')
    """

    kind: str

    def __new__(cls, text: str, kind: str = ""):
        obj = super().__new__(cls, text)
        obj.kind = kind
        return obj


@dataclass(frozen=True)
class Table:
    """A table of text cells under a title.

    ``align``: a letter per column, ``l`` left, ``r`` right (numbers), ``w`` left and wrapping
    (long text); default the first left, the rest right. ``id`` names the table (in the HTML).
    """

    id: str
    title: str
    columns: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    caption: str = ""
    align: str = ""

    def alignment(self) -> str:
        return self.align or "l" + "r" * (len(self.columns) - 1)

    def column(self, name: str) -> tuple[str, ...]:
        """The cells of the column headed ``name``."""
        i = self.columns.index(name)
        return tuple(row[i] for row in self.rows)


eig = eig_text
"""An eigenvalue: ``-2.5`` or ``-1 + 3.2j`` (5 significant digits, no ``-0``):
:func:`quadctl.text.messages.eig_text`."""


UNSTABLE = "unstable"
"""A margin's cell for an unstable loop, which has none (:func:`quadctl.design.margins.no_margin`): a word, not
a number (0 would read as a loop at the edge of stability)."""


def eigs(values) -> str:
    """Eigenvalues separated by commas, as given."""
    return ", ".join(eig(e) for e in values)


def num(value, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; ``-`` for None, ``inf``/``nan`` as such, no ``-0``.

    >>> num(0.123456), num(None), num(-0.0), num(float("inf")), num(2.5 + 1j)
    ('0.1235', '-', '0', 'inf', '2.5 + 1j')
    """
    if value is None:
        return "-"
    if isinstance(value, (complex, np.complexfloating)):
        return eig(value)
    if not math.isfinite(value):
        return str(float(value))
    return f"{value + 0.0:.{digits}g}"


def apart(a: float, b: float, digits: int = 4) -> tuple[str, str]:
    """Two numbers that differ, each written with ``digits`` significant digits, or with more where those read
    alike (up to 17, which tell any two floats apart): a value beside the limit it passes.

    >>> apart(0.3406, 0.2787), apart(0.2786932, 0.2786929)
    (('0.3406', '0.2787'), ('0.2786932', '0.2786929'))
    """
    for d in range(digits, 18):
        x, y = f"{a:.{d}g}", f"{b:.{d}g}"
        if x != y:
            break
    return x, y


def db(value) -> str:
    """A margin in dB, signed, 3 digits: ``+18.4``, ``-inf``; exactly ``0`` (no margin) as ``0``; None ``-``.

    >>> db(18.43), db(float("-inf")), db(0.0), db(None)
    ('+18.4', '-inf', '0', '-')
    """
    if value is None:
        return "-"
    if value == 0:
        return "0"
    return f"{value:+.3g}" if math.isfinite(value) else ("+inf" if value > 0 else "-inf")


def gain_range_db(lower, upper) -> str:
    """A (lower, upper) gain range in dB: ``±13.4`` when symmetric, ``0`` for none, else ``lower / upper``.

    >>> gain_range_db(-13.43, 13.43), gain_range_db(0.0, 0.0), gain_range_db(-6.02, float("inf"))
    ('±13.4', '0', '-6.02 / +inf')
    """
    if upper == 0 and (lower is None or lower == 0):
        return "0"
    if lower is not None and upper is not None and abs(lower + upper) < 1e-6 * max(1.0, abs(upper)):
        return f"±{abs(upper):.3g}"
    return f"{db(lower)} / {db(upper)}"


def vector(values, digits: int = 4) -> str:
    """``[0.2167, 7.421, 1.001]``: the entries of an array, flattened."""
    return "[" + ", ".join(num(float(v), digits) for v in np.ravel(values)) + "]"


def weights(mat) -> str:
    """A weight matrix: ``diag(50, 1)`` when diagonal, else its rows."""
    mat = np.atleast_2d(np.asarray(mat, dtype=float))
    if np.count_nonzero(mat - np.diag(np.diag(mat))) == 0:
        d = np.diag(mat)
        return num(d[0]) if d.size == 1 else "diag(" + ", ".join(num(v) for v in d) + ")"
    return "[" + "; ".join(", ".join(num(v) for v in row) for row in mat) + "]"


def percent(share, digits: int = 3, places: int | None = None) -> str:
    """A share as a percentage: ``2.85 %`` (``digits`` significant digits, or ``places`` decimals); None ``-``.
    One that shows as zero has no sign: ``0 %``, not ``-0 %`` (a negative zero, or a tiny negative share
    rounded to ``places``).

    >>> percent(0.02851), percent(-0.0), percent(-0.004, places=0), percent(0.4532, places=0), percent(None)
    ('2.85 %', '0 %', '0 %', '45 %', '-')
    """
    if share is None:
        return "-"
    text = f"{share * 100:.{digits}g}" if places is None else f"{share * 100:.{places}f}"
    return f"{text.lstrip('-') if float(text) == 0 else text} %"


def yes(flag: bool) -> Mark:
    return Mark("yes", "ok") if flag else Mark("no", "fail")


def sentence(text: str) -> str:
    """A fragment as a sentence: capital first letter, a full stop."""
    return text[:1].upper() + text[1:] + ("" if text.endswith(".") else ".")
