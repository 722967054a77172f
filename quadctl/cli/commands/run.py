
from quadctl.cli.errors import FailedChecks
from quadctl.cli.options import (
    AllowSaturationOpt,
    ConfigOpt,
    FreshOpt,
    JsonOpt,
    OutOpt,
    PlotOpt,
    SetOpt,
    open_workspace,
)
from quadctl.cli.stage_warnings import warn_of_the_flight, warn_of_the_rate

NAME = "run"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, plot: PlotOpt = False,
            json: JsonOpt = False, fresh: FreshOpt = False,
            allow_saturation: AllowSaturationOpt = False) -> None:
    """Every stage in order: trim, linearize, decouple, check, design, simulate.

    With a schedule: section, simulate flies the gain schedule (as quadctl schedule writes it). Stops
    with exit 1 at the first failed check; artifacts of earlier stages stay whole.
    """
    from quadctl.cli import render
    from quadctl.cli.figures import save_figures
    from quadctl.cli.progress import simulation_progress

    ws = open_workspace(config, out, fresh, sets)
    done_lines = {}

    from quadctl import stages
    from quadctl.present.stages import stage_summary

    def computed(stage: str) -> None:  # the warnings on a result, before its check
        if stage == "simulate":
            warn_of_the_flight(ws, ws.simulation, allow_saturation)

    def passed(stage: str) -> None:
        done_lines[stage] = stage_summary(ws, stage)
        if not json:
            render.out.print(f"[green]✓[/green] {stage:<10} {done_lines[stage]}", soft_wrap=True)  # whole lines
        if stage == "check":
            warn_of_the_rate(ws.checks.rate, ws.checks.rate_warnings)

    with simulation_progress(quiet=json) as ws.progress:
        outcome = stages.run_stages(ws, stages.RUN, allow_saturation=allow_saturation, computed=computed,
                                    passed=passed)
    if outcome.error is not None:
        raise outcome.error
    if outcome.failed is not None:
        raise _stop(json, done_lines, outcome.failed)
    sim = ws.simulation.sim
    if plot:
        for path in save_figures(ws, sim, ws.simulation.flight.get("reference")):
            if not json:
                render.out.print(f"figure -> {path}")
    if json:
        render.emit_json({"stages": done_lines, "ok": True, "out": str(ws.out)})
    else:
        render.out.print(f"artifacts in {ws.out}/")


def _stop(json: bool, done: dict, why: str) -> Exception:
    """The error ``run`` stops with at a failed check, its JSON first."""
    from quadctl.cli import render

    if json:
        render.emit_json({"stages": done, "ok": False, "failed": why})
    return FailedChecks(why)
