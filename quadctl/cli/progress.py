"""Progress bars on stderr, only on a terminal: the simulation's (only for a run that takes a while)
and the sweep's. Both import rich on first use."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable

SHOWN_FROM = 2.0
"""s of wall time a run is projected to take (from its first chunks) before a bar is drawn: a
shorter run ends before a bar would tell anything."""


@contextlib.contextmanager
def simulation_progress(quiet: bool = False):
    """Yield ``progress(done, total)`` (RK4 steps) for :func:`quadctl.sim.run.simulate`, or None.

    The bar (percentage, elapsed time, ETA) goes to stderr, and only when stderr is a terminal and
    not ``quiet`` (``--json``); it appears once the run, at the rate of its chunks so far, is projected
    to last :data:`SHOWN_FROM` s or more, and is cleared when the run ends.
    """
    from quadctl.cli.render import err

    if quiet or not err.is_terminal:
        yield None
        return
    first: list = []
    shown: dict = {}

    def update(done: int, total: int) -> None:
        if not shown:
            now = time.perf_counter()
            if not first:  # the first chunk: the rate is measured from here (compiling is over)
                first.extend((now, done))
                return
            rate = (done - first[1]) / (now - first[0]) if now > first[0] else 0.0
            if done >= total or rate <= 0 or (total - first[1]) / rate < SHOWN_FROM:
                return
            shown["bar"] = bar = _bar(err)
            bar.start()
            shown["task"] = bar.add_task("simulate", total=total)
        shown["bar"].update(shown["task"], completed=done, total=total, refresh=True)

    try:
        yield update
    finally:
        if "bar" in shown:
            shown["bar"].stop()


def _bar(console):
    from rich.progress import (
        BarColumn,
        Progress,
        TaskProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return Progress(TextColumn("simulate"), BarColumn(), TaskProgressColumn(), TimeElapsedColumn(),
                    TextColumn("ETA"), TimeRemainingColumn(), console=console, transient=True, auto_refresh=False)


@contextlib.contextmanager
def sweep_progress(quiet: bool = False, meanwhile: Callable[[], object] | None = None):
    """Yield ``progress(done, total)`` (cases) for :func:`quadctl.sweep.execute`; None when ``quiet``
    (``--json``) and there is nothing to do ``meanwhile``.

    The first call comes once the sweep's worker processes run (they fork from a process without
    rich). It calls ``meanwhile()``, work this process needs after the sweep (the figure's imports),
    and makes the bar (:func:`quadctl.cli.render_sweep.sweep_bar`, on a terminal unless ``quiet``), so both overlap
    the workers' computing. That call's ``done`` are the rows kept from an interrupted run
    (``--resume``): the rate counts the others.
    """
    if quiet and meanwhile is None:
        yield None
        return
    shown: dict = {}

    def update(done: int, total: int) -> None:
        if not shown:
            shown["started"] = True
            if meanwhile is not None:
                meanwhile()
            from quadctl.cli.render import err

            if not quiet and err.is_terminal:  # a pipe or a CI log gets the summary line only
                from quadctl.cli.render_sweep import sweep_bar

                shown["bar"] = sweep_bar()
                shown["bar"].start()
                shown["task"] = shown["bar"].add_task("sweep", total=total, resumed=done)
        if "bar" in shown:
            shown["bar"].update(shown["task"], completed=done, total=total, refresh=True)

    try:
        yield update
    finally:
        if "bar" in shown:
            shown["bar"].stop()
