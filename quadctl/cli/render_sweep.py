"""Terminal output of ``quadctl sweep``: the progress bar, the best/worst table, the summary line."""

from __future__ import annotations

import math

from rich.console import Group
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TextColumn,
    TimeElapsedColumn,
)
from rich.table import Table
from rich.text import Text

from quadctl.cli.render import err, num, out

SHOWN = 5
"""Rows of the best and of the worst cases in the table."""


class _RateColumn(ProgressColumn):
    """Cases per second since the start (chunks land in bursts: a moving estimate would jump)."""

    def render(self, task) -> Text:
        rate = _rate(task)
        return Text(f"{rate:,.0f} cases/s" if rate else "", style="progress.data.speed")


class _EtaColumn(ProgressColumn):
    """Time left at the average rate so far."""

    def render(self, task) -> Text:
        rate = _rate(task)
        if task.finished or not rate or task.total is None:
            return Text("ETA -:--:--" if not task.finished else "", style="progress.remaining")
        left = int((task.total - task.completed) / rate)
        return Text(f"ETA {left // 3600}:{left // 60 % 60:02d}:{left % 60:02d}", style="progress.remaining")


def _rate(task) -> float | None:
    done = task.completed - (task.fields.get("resumed") or 0)
    elapsed = task.elapsed
    return done / elapsed if elapsed and done > 0 else None


def sweep_bar() -> Progress:
    """The sweep's progress bar on stderr (cases done, rate and ETA), not started; no refresh thread
    (:func:`quadctl.cli.progress.sweep_progress` redraws it as chunks land)."""
    return Progress(TextColumn("sweep"), BarColumn(), MofNCompleteColumn(), _RateColumn(),
                    TimeElapsedColumn(), _EtaColumn(), console=err, auto_refresh=False)


def _shown_metrics(result, spec) -> list[str]:
    """The table's metric columns: the gated ones, tightest first (the least slack among the worst cases, so
    the gate that ranks them is on screen), then a settling time, the peak thrust and the cost, three in
    all. A mission's table shows no settling time it does not gate: a mission is judged on its waypoints and
    tracking error, and its settling times (of the error to a moving reference) measure nothing it asks."""
    from quadctl.sweep.gates import WAYPOINTS_REACHED

    worst = result.ranked()[:SHOWN]
    tightest = sorted(spec.gates, key=lambda g: min((g.slack(r.get(g.metric)) for r in worst), default=math.inf))
    gated = list(dict.fromkeys(g.metric for g in tightest))  # a stable sort: the file's order among equals
    mission = WAYPOINTS_REACHED in result.columns
    extra = [m for m in ("settling_time.pD", "peak.T", "cost") if m in result.columns and m not in gated
             and not (mission and m.startswith("settling_time."))]
    return (gated + extra)[:3]


RANKED_BY = {True: ("most slack at their tightest gate, relative to its bound",
                    "least slack at their tightest gate, relative to its bound"),
             False: ("lowest LQR cost", "highest LQR cost")}
"""What the best and the worst tables rank by, with gates and without: a case's slack is that of the gate
it comes nearest to failing (:func:`quadctl.sweep.gates.margin`)."""


def sweep_tables(result, spec) -> Group:
    """Two tables: the best and the worst cases (by their slack to the gates; by cost without gates)."""
    metrics = _shown_metrics(result, spec)
    ranked = result.ranked()
    worst = ranked[:SHOWN]
    best = [r for r in reversed(ranked[-SHOWN:]) if r not in worst]
    of = f"of {len(result.rows)} cases"
    tables = []
    for title, rows in ((f"Best {of} ({RANKED_BY[bool(spec.gates)][0]})", best),
                        (f"Worst {of} ({RANKED_BY[bool(spec.gates)][1]})", worst)):
        if not rows:
            continue
        table = Table(title=title, title_justify="left", expand=not out.is_wide)  # a pipe: as wide as its rows
        table.add_column("case", justify="right")
        table.add_column("parameters", overflow="fold", ratio=3)
        for name in metrics:
            table.add_column(_header(name), justify="right", ratio=1)
        table.add_column("result")
        for row in rows:
            params = ", ".join(f"{_short(n)}={_fmt(row.get(n))}" for n in spec.names)
            status = row.get("status")
            verdict = ("[green]pass[/green]" if row["pass"] else
                       "[red]fail[/red]" + ("" if status == "ok" else f" ({status})"))
            table.add_row(str(row["case"]), params, *[_cell(row, m) for m in metrics], verdict)
        tables.append(table)
    return Group(*tables)


def _short(path: str) -> str:
    """A parameter's key path without its section (``lqr.roll.Q[1]`` -> ``roll.Q[1]``)."""
    head, _, rest = path.partition(".")
    return rest or head


def _header(metric: str) -> str:
    """``settling_time.pD`` -> ``settle pD (s)``: short enough for an 80-column terminal."""
    from quadctl.layout import unit_of

    family, _, name = metric.partition(".")
    if family == "settling_time":
        return f"settle {name} (s)"
    if family == "overshoot":
        return f"overshoot {name} (%)"
    if family == "peak":
        return f"peak {name} ({unit_of(name)})"
    if family == "eig":
        return f"eig {name} (rad/s)"
    return metric


def worst_lines(result, limit: int = SHOWN) -> list[str]:
    """One line per failing case, worst first: what it fails."""
    return [f"case {row['case']}: {row['failed_gates']}" + (f" ({row['reason']})" if row.get("reason") else "")
            for row in result.ranked()[:limit] if not row["pass"]]


def _cell(row: dict, metric: str) -> str:
    """A row's ``metric`` as the table shows it: a noise-limited settling time as ``noise``, as
    ``quadctl simulate`` shows it (:func:`quadctl.metrics.noise_limited`)."""
    kind, _, state = metric.partition(".")
    if kind == "settling_time" and row.get(metric) is None and state in row.get("noise_limited", ()):
        return "noise"
    return _fmt(row.get(metric))


def _fmt(value) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return num(value)
    return "-" if value is None else str(value)


def sweep_performance(outcome) -> dict:
    """Timing of the cases computed in this run (not in sweep.json, which stays deterministic)."""
    result = outcome.result
    stats = result.stats
    wall = result.wall_time
    return {
        "cases": len(result.rows), "computed": result.computed, "resumed": outcome.reused,
        "wall_time_s": wall, "simulated_steps": stats["steps"],
        "steps_per_second": stats["steps"] / wall if wall > 0 else None,
        "designs_per_second": result.computed / wall if wall > 0 else None,
        "subsystem_designs": stats["designs"],
        "us_per_subsystem_design": 1e6 * stats["design_cpu"] / stats["designs"] if stats["designs"] else None,
        "us_per_subsystem_design_wall": 1e6 * stats["design_time"] / stats["designs"] if stats["designs"] else None,
        "batched_solves_redone_by_scipy": stats["fallbacks"],
        "backend": stats["backend"], "executor": stats["executor"],
    }


def sweep_line(outcome, method: str = "rk4") -> str:
    """One line: what ran, how fast (steps of ``method``, the integrator the lanes ran), and the verdict."""
    perf = sweep_performance(outcome)
    result = outcome.result
    resumed = f", {perf['resumed']} resumed" if perf["resumed"] else ""
    speed = ""
    if perf["steps_per_second"]:
        speed = (f": [bold]{perf['steps_per_second'] / 1e6:.3g} M {method.upper()} steps/s[/bold], "
                 f"{perf['designs_per_second']:.0f} designs/s")
    if perf["us_per_subsystem_design"] is not None:
        speed += f", {perf['us_per_subsystem_design']:.1f} µs CPU per subsystem LQR"
    backend = ", ".join(perf["backend"]) or "no case simulated"
    # every case read back from the journal: nothing ran anywhere
    where = f" on {perf['executor']} ({backend})" if perf["computed"] else ""
    failed = len(result.failed)
    verdict = "[green]all pass[/green]" if not failed else f"[red]{failed} fail[/red]"
    return (f"{perf['cases']} cases ({perf['computed']} computed{resumed}) in {perf['wall_time_s']:.2f} s"
            f"{where}{speed}; {verdict}")


def sweep_failures(summary: dict) -> str:
    """What the failing cases fail, with counts, and the worst case numbers."""
    parts = [f"{metric} ({gate['failed']})" for metric, gate in summary["gates"].items() if gate["failed"]]
    bad = {k: v for k, v in summary["statuses"].items() if k != "ok"}
    parts += [f"status {k} ({v})" for k, v in bad.items()]
    if summary.get("unstable"):
        parts.append(f"unstable ({summary['unstable']})")
    worst = ", ".join(str(r["case"]) for r in summary["worst"][:5] if not r["pass"])
    text = "; ".join(parts) if parts else "see sweep.csv"
    return f"{text}; worst cases: {worst}" if worst else text
