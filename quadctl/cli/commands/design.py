import typer

from quadctl.cli.errors import EXIT_CHECK_FAILED
from quadctl.cli.options import ConfigOpt, FreshOpt, JsonOpt, OutOpt, open_workspace

NAME = "design"


def command(config: ConfigOpt = None, out: OutOpt = None, json: JsonOpt = False,
            fresh: FreshOpt = False) -> None:
    """LQR per regulated subsystem, assembled and checked on the coupled model; write design.json.

    Exits 1 when the design, stable per subsystem, is unstable on the coupled 12-state model.
    """
    from quadctl.cli import render

    ws = open_workspace(config, out, fresh)
    des = ws.design
    if json:
        render.emit_json(ws.payloads["design.json"])
    else:
        for table in render.design_tables(des):
            render.out.print(table)
        render.out.print(f"-> {ws.path('design.json')}")
    if not des.stable:
        render.err.print("quadctl: check failed: every subsystem is stable alone, but the assembled "
                         "gain is UNSTABLE on the coupled 12-state model (the dropped couplings matter)")
        raise typer.Exit(EXIT_CHECK_FAILED)
    if not json:
        marg = f" (marginal by design: {', '.join(des.marginal_states)})" if des.marginal_states else ""
        render.out.print(f"[green]stable[/green] on the coupled 12-state linear model{marg}")
