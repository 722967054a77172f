"""The terminal: presented tables and sentences (:mod:`quadctl.present`) in rich, and the notice line (stderr).

Styling only: every number and word comes from :mod:`quadctl.present`, as in the report.
"""

from __future__ import annotations

import json
import textwrap

from rich.console import Console
from rich.table import Table
from rich.text import Text

from quadctl import present
from quadctl.layout import INPUT_NAMES, STATE_NAMES
from quadctl.present.cells import NBSP
from quadctl.text.messages import one_line

WIDE = 10_000
"""Columns of stdout when it is not a terminal and ``COLUMNS`` is unset (a pipe, a CI log, a file):
so wide that no table is cut (``control…``) and no line is broken; rich's own default is 80."""


class _Stdout(Console):
    """stdout: the terminal's width on a terminal; ``COLUMNS`` or :data:`WIDE` elsewhere; ``--width``
    (:func:`set_width`) over both. A reader that leaves (``quadctl design | head -1``) ends the output,
    not the run: the rest goes to the null device and the command exits with its own code."""

    fixed_width: int | None = None

    @property
    def size(self):
        dims = Console.size.fget(self)
        if self.fixed_width is not None:
            return dims._replace(width=self.fixed_width)
        if self.is_terminal or (self._environ.get("COLUMNS") or "").isdigit():
            return dims
        return dims._replace(width=WIDE)

    @size.setter
    def size(self, new_size) -> None:
        Console.size.fset(self, new_size)

    @property
    def is_wide(self) -> bool:
        """The width is :data:`WIDE` (no screen's): a table that fills the width would fill that."""
        return self.size.width == WIDE and self.fixed_width is None

    def on_broken_pipe(self) -> None:
        self.quiet = True
        reader_left()


def reader_left() -> None:
    """stdout's reader closed the pipe: send what stdout still gets to the null device (no second
    ``BrokenPipeError`` when Python flushes it at exit), so the command finishes its work quietly."""
    import os
    import sys

    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout is not a file (a test's captured stream)
        pass
    finally:
        os.close(devnull)
    out.quiet = True


def set_width(columns: int | None) -> None:
    """``--width``: stdout's tables and lines this many columns wide, terminal or not (None: the default)."""
    out.fixed_width = columns


out = _Stdout(highlight=False)
err = Console(stderr=True, highlight=False, soft_wrap=True)
"""stderr: errors, warnings, notes and the progress bar. ``soft_wrap``: a line is never broken at
the console width (rich takes 80 columns when stderr is not a terminal, and a CI log would get
``worst cases: 20, 11, 2,`` and ``19, 10`` on two lines); the terminal wraps it for the eye."""


def note(text: str) -> None:
    """``quadctl: note: ...``: a default taken, a name resolved one of two ways."""
    err.print(f"quadctl: note: {one_line(text)}", markup=False)


def warning(text: str) -> None:
    """``quadctl: warning: ...``: valid input that is likely not what was meant."""
    err.print(f"quadctl: warning: {one_line(text)}", markup=False)


def emit_json(payload) -> None:
    """Machine-readable result on stdout (nothing else goes there in ``--json`` mode)."""
    try:
        print(json.dumps(payload, indent=1, sort_keys=True), flush=True)
    except BrokenPipeError:
        reader_left()


num = present.num
eig = present.eig
STYLE = {"ok": "green", "warning": "yellow", "fail": "red"}
"""How a verdict (:class:`quadctl.present.Mark`) is coloured on the terminal."""


def cell(text: str) -> Text:
    """A presented cell or sentence as rich text: never parsed as markup, a verdict coloured, never broken at a
    non-breaking space (:data:`quadctl.present.cells.NBSP`)."""
    kind = Unbroken if NBSP in text else Text
    return kind(str(text), style=STYLE.get(getattr(text, "kind", ""), ""))


class Unbroken(Text):
    """Text whose lines break at its ordinary spaces only. rich breaks at any Unicode space, the non-breaking
    one too (``over 10`` / ``s``): this breaks the lines first, each within the width, where rich then has
    nothing left to break, and prints the non-breaking spaces as spaces."""

    def wrap(self, console, width, **kwargs):
        lines = []
        for line in self.plain.split("\n"):
            lines += textwrap.wrap(line, max(width, 1), break_on_hyphens=False) or [""]
        flat = Text("\n".join(lines).replace(NBSP, " "), style=self.style, justify=self.justify,
                    overflow=self.overflow, no_wrap=self.no_wrap, end=self.end)
        return flat.wrap(console, width, **kwargs)


def table(t: present.Table) -> Table:
    """A presented table on the terminal: the same title, headers, cells and caption as the report."""
    out_table = Table(title=cell(t.title), title_justify="left", caption=cell(t.caption) if t.caption else None,
                      caption_justify="left")
    for name, align in zip(t.columns, t.alignment()):
        out_table.add_column(Text(name), justify="right" if align == "r" else "left")
    for row in t.rows:
        out_table.add_row(*(cell(c) for c in row))
    return out_table


def show(*blocks) -> None:
    """Print presented blocks in order: tables, sentences (a verdict coloured); None is skipped."""
    for block in blocks:
        if block is None:
            continue
        out.print(table(block) if isinstance(block, present.Table) else cell(block))


def matrix(title: str, mat, rows, cols) -> Table:
    table = Table(title=title, title_justify="left", show_edge=False, pad_edge=False)
    table.add_column("")
    for c in cols:
        table.add_column(c, justify="right")
    for i, r in enumerate(rows):
        table.add_row(r, *[("·" if mat[i, j] == 0 else f"{mat[i, j]:.4g}") for j in range(len(cols))])
    return table


def linear_tables(linear) -> list[Table]:
    return [matrix("A = df/dx at the trim (· is an exact zero)", linear.A, STATE_NAMES, STATE_NAMES),
            matrix("B = df/du at the trim", linear.B, STATE_NAMES, INPUT_NAMES)]
