from quadctl.cli.options import ConfigOpt, FreshOpt, JsonOpt, OutOpt, SetOpt, open_workspace

NAME = "trim"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, json: JsonOpt = False,
            fresh: FreshOpt = False) -> None:
    """Solve the equilibrium for the config's flight condition; write trim.json."""
    from quadctl.cli import render

    ws = open_workspace(config, out, fresh, sets)
    trim = ws.trim
    if json:
        return render.emit_json(ws.payloads["trim.json"])
    from quadctl.present import stages

    render.show(*stages.trim_tables(trim), stages.trim_sentence(trim, ws.setup.velocity_ned))
    render.out.print(f"-> {ws.path('trim.json')}")
