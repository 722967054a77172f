from typing import Annotated

import typer

from quadctl.cli.errors import EXIT_CHECK_FAILED
from quadctl.cli.options import ConfigOpt, FreshOpt, JsonOpt, OutOpt, SetOpt, open_workspace

NAME = "margins"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, json: JsonOpt = False,
            fresh: FreshOpt = False,
            plot: Annotated[bool, typer.Option(
                "--plot", help="Also write a Bode and Nyquist figure per loop to DIR/plots/margins-*.png.")] = False,
            coupled: Annotated[bool, typer.Option(
                "--coupled/--design-only",
                help="Also break each loop on the coupled 12-state model (other loops closed).")] = True,
            ) -> None:
    """Gain, phase and disk margins of every regulated loop, broken at its plant input; write margins.json.

    Compares each loop with the continuous LQR guarantee (gain margin -6 dB to infinity, phase
    margin 60 deg) and explains shortfalls (coupling, sampling, saturation). With a controller
    rate the loops are the sampled ones the flight computer closes. Exits 1 when a loop is unstable.
    """
    from quadctl.cli import render, render_loop

    ws = open_workspace(config, out, fresh, sets)
    margins = [m for m in ws.margins if coupled or m.model == "design"]
    paths = _save_figures(ws, margins) if plot else []
    if json:
        render.emit_json(ws.payloads["margins.json"])
    else:
        for table in render_loop.margins_table(margins, ws.setup.timing.rate):
            render.out.print(table)
        for line in render_loop.margin_notes(margins):
            render.out.print(f"  {line}", markup=False)
        render.out.print(render_loop.closed_loop_line(ws.payloads["margins.json"]), markup=False)
        render.out.print(f"-> {ws.path('margins.json')}")
        for path in paths:
            render.out.print(f"figure -> {path}")
    unstable = [m for m in margins if not m.stable]
    if unstable:
        names = ", ".join(f"{m.loop} ({m.model})" for m in unstable)
        render.err.print(f"quadctl: check failed: unstable loop(s): {names}")
        raise typer.Exit(EXIT_CHECK_FAILED)


def _save_figures(ws, margins):
    import io

    from quadctl import artifacts, plots

    paths = []
    for m in margins:
        fig = plots.margins_figure(m, title=ws.setup.name)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=90)
        paths.append(artifacts.write_bytes(artifacts.plot_path(ws.out, f"margins-{m.loop}-{m.model}"),
                                           buf.getvalue()))
    return paths
