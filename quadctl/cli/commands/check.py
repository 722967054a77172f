import typer

from quadctl.cli.errors import EXIT_CHECK_FAILED
from quadctl.cli.options import ConfigOpt, FreshOpt, JsonOpt, OutOpt, open_workspace

NAME = "check"


def command(config: ConfigOpt = None, out: OutOpt = None, json: JsonOpt = False,
            fresh: FreshOpt = False) -> None:
    """Controllability, observability, PBH, stabilizability of every subsystem and the full model.

    Exits 1 when a regulated subsystem is not stabilizable.
    """
    from quadctl.cli import render

    ws = open_workspace(config, out, fresh)
    checks = ws.checks
    regulated = {s.name for s in ws.decoupled.regulated}
    failed = [n for n in regulated if not checks[n].stabilizable]
    if json:
        render.emit_json(ws.payloads["checks.json"])
    else:
        render.out.print(render.checks_table(checks, regulated))
        render.out.print(f"-> {ws.path('checks.json')}")
    for name in failed:
        mode = checks[name].unstabilizable_modes[0]
        render.err.print(f"quadctl: check failed: subsystem {name} is not stabilizable: mode "
                         f"{render.eig(mode.eigenvalue)} in {', '.join(mode.states)}")
    if failed:
        raise typer.Exit(EXIT_CHECK_FAILED)
