"""Save the simulation figures of a workspace, atomically."""

from __future__ import annotations

import os
from pathlib import Path

from quadctl.threads import die_with_parent


def save_figures(ws, sim, tracking: dict | None = None) -> list[Path]:
    """Render every figure of ``sim`` to ``ws.out/plots/*.png``; return the paths (in figure order).
    ``tracking``: the run's reference summary (``sim.json``'s ``reference``), whose waypoints the path marks.

    With more than one core (and ``os.fork``), a child process draws about half of them (by
    :func:`_cost`) while this one draws the rest; should the child fail, this process draws its
    share too, so a figure is never missing and an error is this process's own.
    """
    from quadctl import artifacts, plots

    makers = plots.simulation_figure_makers(sim, ws.setup.partition, ws.linear.u_trim,
                                            title=ws.setup.name, actuators=ws.setup.actuators,
                                            tracking=tracking)
    paths = {name: artifacts.plot_path(ws.out, name) for name in makers}  # every name checked first
    ws.remember(*paths.values())  # before the child draws its share: a roll-back puts every figure back

    def draw(names) -> None:
        for name in names:
            artifacts.write_bytes(paths[name], ws.stamp(plots.png_bytes(makers[name](), plots.DPI)))

    theirs = _share(makers, ws) if _can_fork() else []
    child = _fork(draw, theirs) if theirs else None
    if child is None:
        theirs = []
    try:
        draw([name for name in makers if name not in theirs])
    finally:  # the child is done before this returns or raises: no figure is written after
        drawn = child is None or _succeeded(child)
    if not drawn:
        draw(theirs)
    ws.record_written(*paths.values())  # every figure this run's: none of another config's is missing
    return list(paths.values())


def _cost(name: str, ws) -> float:
    """Rough drawing cost of figure ``name`` in panel-equivalents: a subsystem's panels; the inputs'
    linear and log-time panels (a log axis's many minor ticks cost about twice a linear one)."""
    if name in ws.setup.partition:
        return len(ws.setup.partition[name].states)
    if name == "inputs":
        return 3.0 * (4 + (ws.setup.actuators is not None and ws.setup.actuators.mode == "motors"))
    return {"path": 3.0}.get(name, 2.0)


def _share(makers: dict, ws) -> list[str]:
    """The figures a child draws: a greedy half of the total :func:`_cost` (the costliest first)."""
    mine, theirs, load = [], [], [0.0, 0.0]
    for name in sorted(makers, key=lambda n: -_cost(n, ws)):
        side = 0 if load[0] <= load[1] else 1
        (mine, theirs)[side].append(name)
        load[side] += _cost(name, ws)
    return theirs if mine else []


def _can_fork() -> bool:
    """A second core to draw on, and ``os.fork`` to start a drawer that needs no new imports."""
    if not hasattr(os, "fork"):
        return False
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return cores > 1


def _fork(draw, names) -> int | None:
    """A child process that draws ``names`` and exits (0 if it wrote them all); its pid, or None if
    none could start."""
    try:
        pid = os.fork()
    except OSError:
        return None
    if pid == 0:  # the child: never returns, never runs the parent's exit handlers or flushes its buffers
        code = 1
        try:
            die_with_parent()  # a parent killed hard leaves no drawer writing into its folder unlocked
            draw(names)
            code = 0
        finally:
            os._exit(code)
    return pid


def _succeeded(pid: int) -> bool:
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status) == 0
