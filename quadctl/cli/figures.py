"""Save the simulation figures of a workspace, atomically."""

from __future__ import annotations

from pathlib import Path


def save_figures(ws, sim) -> list[Path]:
    """Render every figure of ``sim`` to ``ws.out/plots/*.png``; return the paths."""
    from quadctl import artifacts, plots

    paths = []
    for name, fig in plots.simulation_figures(sim, ws.setup.partition, ws.linear.u_trim,
                                              title=ws.setup.name, actuators=ws.setup.actuators).items():
        paths.append(artifacts.write_bytes(artifacts.plot_path(ws.out, name), plots.png_bytes(fig, plots.DPI)))
    return paths
