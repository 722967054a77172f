import typer

from quadctl.cli.errors import EXIT_CHECK_FAILED
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

NAME = "simulate"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, plot: PlotOpt = False,
            json: JsonOpt = False, fresh: FreshOpt = False,
            allow_saturation: AllowSaturationOpt = False) -> None:
    """Fixed-step RK4 of the full nonlinear closed loop; write sim.npz and sim.json.

    Exits 1 when the run diverges or leaves the model's valid range (what was computed is saved).
    """
    from quadctl.cli import render
    from quadctl.cli.figures import save_figures
    from quadctl.cli.progress import simulation_progress

    ws = open_workspace(config, out, fresh, sets)
    with simulation_progress(quiet=json) as ws.progress:
        flown = ws.simulation
    sim = flown.sim
    figures = save_figures(ws, sim) if plot else []
    if json:
        render.emit_json(ws.payloads["sim.json"])
    else:
        plan = sim.plan
        how = "auto" if plan.auto else "given"
        render.out.print(f"RK4 dt = {sim.dt:.4g} s ({how}; stable up to {plan.max_stable_dt:.4g} s, "
                         f"fastest eigenvalue {render.eig(plan.fastest_eigenvalue)} rad/s in "
                         f"{plan.fastest_owner}), {sim.steps} steps in {sim.wall_time * 1e3:.1f} ms: "
                         f"[bold]{sim.steps_per_second / 1e6:.2f} M steps/s[/bold] ({sim.backend})")
        _print_flight(render, flown, before=True)
        render.out.print(render.metrics_table(flown.metrics))
        render.out.print(render.peaks_table(flown.metrics, ws.linear.u_trim))
        _print_flight(render, flown, before=False)
        render.out.print(f"{sim.status}: {sim.message} -> {ws.path('sim.npz')}")
        for path in figures:
            render.out.print(f"figure -> {path}")
    sat = flown.flight.get("saturation")
    if sat and sat["saturates"] and not _fails_on_saturation(ws, flown, allow_saturation):  # else the error says it
        worst = max(sat["fraction"], key=sat["fraction"].get)
        render.err.print(f"quadctl: warning: the design saturates: {worst} is at a limit "
                         f"{sat['fraction'][worst] * 100:.3g} % of the run (flag above "
                         f"{sat['flag_above'] * 100:g} %); lower the gains (larger R) or the initial offset",
                         markup=False)
    if sim.status != "ok":
        render.err.print(f"quadctl: check failed: {sim.message}")
        raise typer.Exit(EXIT_CHECK_FAILED)
    _require_within_limits(ws, flown, allow_saturation)


def _require_within_limits(ws, flown, allow_saturation: bool) -> None:
    """Exit 1 (a check failed) when the design saturates most of the run and nobody accepted it."""
    from quadctl import motors

    sat = flown.flight.get("saturation")
    motors.require_within_limits(sat["fraction"] if sat else None,
                                 allowed=allow_saturation or "saturation" in ws.cfg.allow)


def _fails_on_saturation(ws, flown, allow_saturation: bool) -> bool:
    from quadctl.errors import SaturationFailed

    try:
        _require_within_limits(ws, flown, allow_saturation)
    except SaturationFailed:
        return True
    return False


def _print_flight(render, flown, *, before: bool) -> None:
    """Controller rate, saturation, noise RMS and integrator lines, when they apply."""
    from quadctl.cli import render_loop

    flight, sim = flown.flight, flown.sim
    if before:
        line = render_loop.controller_line(flight, sim)
        if line:
            render.out.print(line)
        return
    table = render_loop.saturation_table(flight)
    if table is not None:
        render.out.print(table)
    if flight.get("noise") or flight.get("wind"):
        render.out.print(render_loop.rms_table(flight))
    table = render_loop.estimation_table(flight)
    if table is not None:
        render.out.print(table)
    if flight.get("wind"):
        render.out.print(render_loop.wind_line(flight), markup=False)
        render.out.print(render_loop.wind_table(flight))
    line = render_loop.integral_line(flight)
    if line:
        render.out.print(line)
