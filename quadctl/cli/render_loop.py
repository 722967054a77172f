"""Rich rendering of ``design --full``'s comparison, which only the terminal shows (the report does not run it)."""

from __future__ import annotations

import math

from rich.table import Table

from quadctl.cli.render import eig, num
from quadctl.layout import INPUT_NAMES, STATE_NAMES, unit_of


def full_tables(fd, comparison: dict) -> list:
    table = Table(title="Full 12-state LQR on the coupled model (same Q, R)", title_justify="left",
                  caption=("left out: " + ", ".join(fd.left_out) + " (no weight, no dynamics); " if fd.left_out
                           else "") + "weighted positions are regulated about the moving reference",
                  caption_justify="left")
    table.add_column("input")
    for s in fd.states:
        table.add_column(s, justify="right")
    for s in fd.integral_states:
        table.add_column(f"int {s}", justify="right")
    for j, name in enumerate(INPUT_NAMES):
        row = [f"{fd.K[j, STATE_NAMES.index(s)]:.4g}" for s in fd.states]
        row += [f"{fd.Ki[j, i]:.4g}" for i in range(len(fd.integral_states))]
        table.add_row(name, *row)
    eigs = ", ".join(eig(e) for e in sorted(fd.core_eigenvalues, key=lambda z: (z.real, z.imag)))
    comp = Table(title="Decoupled vs full design on the nonlinear model (same initial offset, no noise)",
                 title_justify="left",
                 caption="settling: the slowest regulated state; peak: max |u - u_trim|; cost: "
                         "integral of e'Qe + du'R du on the run; linear cost: dx0' P dx0 on the coupled "
                         "linear model", caption_justify="left")
    for col in ("criterion", "decoupled", "full", "better", "by (worse / better - 1)"):
        comp.add_column(col, justify="left" if col in ("criterion", "better") else "right")
    designs = comparison["designs"]
    rows = [("settling (s)", "settling", lambda r: r["settling"]), ("cost", "cost", lambda r: r["cost"]),
            ("linear cost", "linear_cost", lambda r: r["linear_cost"])]
    rows += [(f"peak |d{n}| ({unit_of(n)})", f"peak_{n}", lambda r, n=n: r["peak_input"][n]) for n in INPUT_NAMES]
    for label, key, get in rows:
        better = comparison["better"][key]
        ratio = better["ratio"]
        by = "-" if ratio is None else ("inf" if not math.isfinite(ratio) else f"{(ratio - 1) * 100:.3g} %")
        comp.add_row(label, num(get(designs["decoupled"])), num(get(designs["full"])),
                     better["winner"] or "tie", by)
    return [table, f"full closed-loop eigenvalues (rad/s): {eigs}", comp]
