
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
from quadctl.cli.stage_warnings import (
    mission_failure,
    require_within_limits,
    warn_of_the_flight,
    warn_of_the_rate,
)

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
    stages = {}

    def done(stage: str, detail: str) -> None:
        stages[stage] = detail
        if not json:
            render.out.print(f"[green]✓[/green] {stage:<10} {detail}", soft_wrap=True)  # a pipe gets whole lines

    from quadctl.errors import SaturationFailed
    from quadctl.present import design as shown_design
    from quadctl.present import flight as shown_flight
    from quadctl.present import stages as shown

    done("trim", shown.trim_summary(ws.trim))
    done("linearize", f"A {ws.linear.A.shape}, B {ws.linear.B.shape}")
    done("decouple", shown.decouple_summary(ws.decoupled))
    why = ws.checks.verdict()
    if why:
        raise _stop(json, stages, f"check: {why}")
    done("check", shown.CHECKS_PASSED)
    warn_of_the_rate(ws.checks.rate, ws.checks.rate_warnings)
    if not ws.design.stable:
        raise _stop(json, stages, f"design: {shown.UNSTABLE_DESIGN}")
    done("design", shown_design.summary(ws.design))
    with simulation_progress(quiet=json) as ws.progress:
        flown = ws.simulation
    sim = flown.sim
    warn_of_the_flight(ws, flown, allow_saturation)
    if sim.status != "ok":
        raise _stop(json, stages, f"simulate: {sim.message}")
    try:
        require_within_limits(ws, flown, allow_saturation)
    except SaturationFailed as exc:
        raise _stop(json, stages, f"simulate: {exc}", exc) from None
    mission = mission_failure(flown)
    if mission:
        raise _stop(json, stages, f"simulate: {mission}")
    done("simulate", f"{sim.steps} {shown_flight.integrator_name(sim)} steps, {shown_flight.step_span(sim)}, "
                     f"{sim.steps_per_second / 1e6:.2f} M steps/s")
    if plot:
        for path in save_figures(ws, sim, flown.flight.get("reference")):
            if not json:
                render.out.print(f"figure -> {path}")
    if json:
        render.emit_json({"stages": stages, "ok": True, "out": str(ws.out)})
    else:
        render.out.print(f"artifacts in {ws.out}/")


def _stop(json: bool, stages: dict, why: str, error: Exception | None = None) -> Exception:
    """The error ``run`` stops with at a failed stage (``error``, else a failed check), its JSON first."""
    from quadctl.cli import render

    if json:
        render.emit_json({"stages": stages, "ok": False, "failed": why})
    return error if error is not None else FailedChecks(why)
