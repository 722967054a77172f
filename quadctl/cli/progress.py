"""Progress bars on stderr, only on a terminal: the simulation's (only for a run that takes a while)
and the sweep's. Both import rich on first use, and each says only when its bar appears: one helper
(:func:`_shown_when`) starts, advances and stops either."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable

IMPORTS_CUT_SHORT: list[str] = []
"""The imports a Ctrl-C cut short in this process (the figure's, which a sweep makes while its workers
compute: :func:`sweep_progress`). What such an import left half made can kill the interpreter as it
exits: after its one line, a sweep so interrupted ended by a fatal error (exit -6) or by the signal
(-2) 2 to 4 times in 30 on a machine loaded to 6. The command still cleans up (its workers stopped,
its run folder closed, its files written); then :func:`quadctl.cli.entry.main` leaves without the
interpreter's exit (``os._exit``), its output flushed."""
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

    def make(done: int, total: int):
        now = time.perf_counter()
        if not first:  # the first chunk: the rate is measured from here (compiling is over)
            first.extend((now, done))
            return None
        rate = (done - first[1]) / (now - first[0]) if now > first[0] else 0.0
        if done >= total or rate <= 0 or (total - first[1]) / rate < SHOWN_FROM:
            return None
        return _bar(err), "simulate", {}

    with _shown_when(make) as update:
        yield update


@contextlib.contextmanager
def _shown_when(make: Callable[[int, int], tuple | None]):
    """Yield ``progress(done, total)`` that draws a bar once ``make`` gives one: the one place a bar is
    started, advanced and stopped.

    Until a bar is shown, each call asks ``make(done, total)`` for one: a rich ``Progress`` not yet
    started, its task's description and the task's fields, or None (not now). Once shown, each call
    advances it to ``done`` of ``total`` and redraws it; it is stopped (cleared) when the block ends.
    """
    shown: dict = {}

    def update(done: int, total: int) -> None:
        if not shown:
            made = make(done, total)
            if made is None:
                return
            bar, description, fields = made
            bar.start()
            shown.update(bar=bar, task=bar.add_task(description, total=total, **fields))
        shown["bar"].update(shown["task"], completed=done, total=total, refresh=True)

    try:
        yield update
    finally:
        if shown:
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
    asked: list = []

    def make(done: int, total: int):
        if asked:  # asked once, at the first call: no bar then, none later
            return None
        asked.append(True)
        if meanwhile is not None:
            try:
                meanwhile()
            except KeyboardInterrupt:  # what it imported may be half made: the process leaves at once
                IMPORTS_CUT_SHORT.append(getattr(meanwhile, "__name__", "meanwhile"))
                raise
        from quadctl.cli.render import err

        if quiet or not err.is_terminal:  # a pipe or a CI log gets the summary line only
            return None
        from quadctl.cli.render_sweep import sweep_bar

        return sweep_bar(), "sweep", {"resumed": done}

    with _shown_when(make) as update:
        yield update
