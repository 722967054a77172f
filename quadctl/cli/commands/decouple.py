from quadctl.cli.options import ConfigOpt, FreshOpt, JsonOpt, OutOpt, SetOpt, open_workspace

NAME = "decouple"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, json: JsonOpt = False,
            fresh: FreshOpt = False) -> None:
    """Split the linear model into subsystems and list the coupling terms dropped; write subsystems.json."""
    from quadctl.cli import render

    ws = open_workspace(config, out, fresh, sets)
    dec = ws.decoupled
    if json:
        return render.emit_json(ws.payloads["subsystems.json"])
    from quadctl.present import stages

    render.show(stages.subsystems_table(dec), stages.dropped_table(dec))
    render.out.print(f"-> {ws.path('subsystems.json')}")
