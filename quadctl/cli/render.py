"""Rich renderings of stage results for the terminal (stdout), and the notice line (stderr)."""

from __future__ import annotations

import json
import math

import numpy as np
from rich.console import Console
from rich.table import Table

from quadctl import stability
from quadctl.layout import INPUT_NAMES, STATE_NAMES, unit_of
from quadctl.messages import eig_text, one_line

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


def num(value: float, digits: int = 4) -> str:
    if value is None:
        return "-"
    if isinstance(value, complex) or isinstance(value, np.complexfloating):
        return eig(value)
    if not math.isfinite(value):
        return str(value)
    return f"{value:.{digits}g}"


eig = eig_text


def yes(flag: bool) -> str:
    return "[green]yes[/green]" if flag else "[red]no[/red]"


def matrix(title: str, mat, rows, cols) -> Table:
    table = Table(title=title, title_justify="left", show_edge=False, pad_edge=False)
    table.add_column("")
    for c in cols:
        table.add_column(c, justify="right")
    for i, r in enumerate(rows):
        table.add_row(r, *[("·" if mat[i, j] == 0 else f"{mat[i, j]:.4g}") for j in range(len(cols))])
    return table


def trim_table(trim) -> Table:
    table = Table(title="Trim", title_justify="left")
    for col in ("quantity", "value", "unit"):
        table.add_column(col, justify="right" if col == "value" else "left")
    for i, name in enumerate(STATE_NAMES):
        table.add_row(name, f"{trim.x[i]:.6g}", unit_of(name))
    for j, name in enumerate(INPUT_NAMES):
        table.add_row(f"[bold]{name}[/bold]", f"{trim.u[j]:.6g}", unit_of(name))
    return table


def linear_tables(linear) -> list[Table]:
    return [matrix("A = df/dx at the trim (· is an exact zero)", linear.A, STATE_NAMES, STATE_NAMES),
            matrix("B = df/du at the trim", linear.B, STATE_NAMES, INPUT_NAMES)]


def subsystems_table(dec) -> Table:
    table = Table(title="Subsystems (diagonal blocks of A, matching columns of B)", title_justify="left")
    for col in ("subsystem", "states", "inputs", "regulated", "open-loop eigenvalues"):
        table.add_column(col)
    for s in dec.subsystems:
        eigs = ", ".join(eig(e) for e in np.linalg.eigvals(s.A))
        src = "" if s.regulated else " (from A)"
        table.add_row(s.name, " ".join(s.states), " ".join(s.inputs) + src, yes(s.regulated), eigs)
    return table


def dropped_table(dec, top: int = 8) -> Table:
    table = Table(title=f"Largest coupling terms the partition drops (top {top} of A and of B; "
                        f"{len(dec.dropped)} in all)", title_justify="left")
    for col in ("term", "matrix", "value", "unit", "|value| / max|matrix|"):
        table.add_column(col, justify="right" if col in ("value", "|value| / max|matrix|") else "left")
    for kind in ("A", "B"):
        for d in [d for d in dec.dropped if d.matrix == kind][:top]:
            table.add_row(d.name, d.matrix, f"{d.value:.4g}", d.unit, f"{d.relative:.2e}")
    return table


def checks_table(checks: dict, regulated: set[str]) -> Table:
    table = Table(title="Controllability and observability", title_justify="left", caption=(
        "ctrb/obsv: Kalman matrix rank by SVD, counting singular values > tol = max(shape) * eps * "
        f"sigma_max (eps = {np.finfo(float).eps:.3g}); verdicts by PBH at each eigenvalue; "
        "stable means Re < 0; * analysed only"), caption_justify="left")
    for col, right in (("system", False), ("ctrb", True), ("obsv", True), ("tol", True),
                       ("controllable", False), ("observable", False), ("stabilizable", False),
                       ("detectable", False)):
        table.add_column(col, justify="right" if right else "left")
    for name, c in checks.items():
        label = name if name == "full" or name in regulated else f"{name}*"
        table.add_row(label, f"{c.ctrb.rank}/{c.n}", f"{c.obsv.rank}/{c.n}", f"{c.ctrb.tolerance:.0e}",
                      yes(c.controllable), yes(c.observable), yes(c.stabilizable), yes(c.detectable))
    return table


def design_tables(des) -> list:
    table = Table(title="LQR per subsystem (u = -K x, K = R^-1 B' P)", title_justify="left")
    lagged = des.lag_time_constant is not None
    for col in ("subsystem", "states", "input", "K", *(["Kv (lag)"] if lagged else []), "closed-loop eigenvalues",
                "Riccati residual"):
        table.add_column(col)
    for s in des.subsystems:
        kv = ["[" + ", ".join(f"{k:.4g}" for k in s.Kv.ravel()) + "]"] if lagged else []
        table.add_row(s.name, " ".join(s.states), " ".join(s.inputs),
                      "[" + ", ".join(f"{k:.4g}" for k in s.K.ravel()) + "]", *kv,
                      ", ".join(eig(e) for e in s.eigenvalues), f"{s.residual:.1e}")
    title = ("Coupled closed loop with the rotors' lag, [x; v]: A - B [K_block, Kv_block]" if lagged else
             "Coupled 12-state closed loop A - B K_block")
    full = Table(title=title, title_justify="left")
    full.add_column("eigenvalue (rad/s)", justify="right")
    full.add_column("verdict")
    for e in sorted(des.full_eigenvalues, key=lambda z: (z.real, z.imag)):
        zero = abs(e) < 1e-9
        verdict = ("marginal: unregulated position" if zero and des.marginal_states else
                   ("stable" if stability.is_stable(e) else "[red]unstable[/red]"))
        full.add_row(eig(e), verdict)
    return [table, matrix("K_block, transposed: a row per state, a column per input (· is zero)",
                          des.K_block.T, STATE_NAMES, INPUT_NAMES), full]


def metrics_table(metrics: dict) -> Table:
    table = Table(title="Closed-loop response (error from the reference)", title_justify="left",
                  caption="settling: within 2 % of the state's largest error; '-' never settled or n/a",
                  caption_justify="left")
    for col in ("state", "unit", "settling (s)", "overshoot (%)", "peak |error|", "final error"):
        table.add_column(col, justify="left" if col in ("state", "unit") else "right")
    for name in STATE_NAMES:
        table.add_row(name, unit_of(name), num(metrics["settling_time"].get(name)),
                      num(metrics["overshoot"].get(name), 3), num(metrics["peak_error"][name]),
                      num(metrics["final_error"][name]))
    return table


def peaks_table(metrics: dict, u_trim) -> Table:
    table = Table(title="Inputs", title_justify="left")
    for col in ("input", "unit", "trim", "peak magnitude"):
        table.add_column(col, justify="left" if col in ("input", "unit") else "right")
    for j, name in enumerate(INPUT_NAMES):
        table.add_row(name, unit_of(name), num(u_trim[j]), num(metrics["peak"][name]))
    return table
