import warnings

from quadctl.cli.errors import FailedChecks
from quadctl.cli.options import AllowSaturationOpt, ConfigOpt, FreshOpt, JsonOpt, OutOpt, SetOpt
from quadctl.errors import CheckFailed, QuadctlNotice

NAME = "report"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, fresh: FreshOpt = False,
            json: JsonOpt = False, allow_saturation: AllowSaturationOpt = False) -> None:
    """Every stage and the margins in one HTML page (figures inline, nothing fetched) and a Markdown twin.

    Writes DIR/report/report.html, report.md and its figures. Exits 1 when a check fails, as `run`
    does, after writing the report of what was computed (it says where it stopped); on refused input
    (exit 2) too, unless DIR held another config's run, which is then put back as it was.
    """
    from quadctl import artifacts, report, stages
    from quadctl.cli import render
    from quadctl.cli.options import load_source, remembered
    from quadctl.cli.progress import simulation_progress
    from quadctl.workspace import Workspace

    cfg, source = load_source(config, sets)
    ws = remembered(Workspace(cfg, out, fresh=fresh, source_text=source.text))
    artifacts.check_folder(ws.out / report.FOLDER)  # a link there: refused now, not after the stages
    with simulation_progress(quiet=json) as ws.progress:
        outcome = stages.run_stages(ws, allow_saturation=allow_saturation)
    if outcome.error is not None and not isinstance(outcome.error, CheckFailed) and ws.replaced:
        # refused, in a folder that held another config's run: that run is put back whole (as every command
        # puts the folder back on exit 2), and with it goes the report that would have replaced it
        warnings.warn(QuadctlNotice(f"{ws.out}: no report written: the folder holds another config's run, put back "
                                    "as it was; report into another --out folder to keep the refused run's"),
                      stacklevel=1)
        raise outcome.error
    doc = report.build(ws, outcome, command_line=_command_line(config, out, fresh, sets, allow_saturation),
                       label=source.label)
    paths = report.write(doc, ws.out / report.FOLDER, store=ws)  # a failed write (a full disk): all put back
    ws.keep()  # the report says what ran and why it stopped: it and the artifacts it shows stay together
    if json:
        render.emit_json({"report": str(paths[-1]), "markdown": str(paths[-2]), "figures": [str(p) for p in paths[:-2]],
                          "failed": outcome.failed, "error": str(outcome.error) if outcome.error else None})
    else:
        render.out.print(f"report -> {paths[-1]} (and {paths[-2].name}, {len(paths) - 2} figures)")
    if outcome.error is not None:
        raise outcome.error
    if outcome.failed is not None:
        raise FailedChecks(outcome.failed)


def _command_line(config, out, fresh: bool, sets=None, allow_saturation: bool = False) -> str:
    """This command with the options it was given (shown in the report)."""
    import shlex

    words = ["quadctl", NAME] + (["--config", config] if config else []) + (["--out", str(out)] if out else [])
    words += [word for assignment in sets or () for word in ("--set", assignment)]
    return shlex.join(words + (["--fresh"] if fresh else []) + (["--allow-saturation"] if allow_saturation else []))
