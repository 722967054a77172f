from quadctl.cli.options import ConfigOpt, FreshOpt, JsonOpt, OutOpt, SetOpt, open_workspace

NAME = "linearize"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, json: JsonOpt = False,
            fresh: FreshOpt = False) -> None:
    """Jacobians A (12 x 12) and B (12 x 4) at the trim, from CasADi; write linear.npz."""
    from quadctl.cli import render

    ws = open_workspace(config, out, fresh, sets)
    linear = ws.linear
    if json:
        from quadctl import artifacts

        arrays, meta = artifacts.read_npz(ws.path("linear.npz"))
        return render.emit_json(artifacts.jsonable({**meta, **arrays}))
    for table in render.linear_tables(linear):
        render.out.print(table)
    render.out.print(f"-> {ws.path('linear.npz')}")
