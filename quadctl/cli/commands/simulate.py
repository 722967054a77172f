import typer

from quadctl.cli.errors import EXIT_CHECK_FAILED
from quadctl.cli.options import ConfigOpt, FreshOpt, JsonOpt, OutOpt, PlotOpt, open_workspace

NAME = "simulate"


def command(config: ConfigOpt = None, out: OutOpt = None, plot: PlotOpt = False,
            json: JsonOpt = False, fresh: FreshOpt = False) -> None:
    """Fixed-step RK4 of the full nonlinear closed loop; write sim.npz and sim.json.

    Exits 1 when the run diverges or leaves the model's valid range (what was computed is saved).
    """
    from quadctl.cli import render
    from quadctl.cli.figures import save_figures

    ws = open_workspace(config, out, fresh)
    sim = ws.simulation
    if sim.backend != "compiled":
        render.notice("no C compiler found: simulating in CasADi's interpreter (correct, slower)")
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
        render.out.print(render.metrics_table(ws.metrics))
        render.out.print(render.peaks_table(ws.metrics, ws.linear.u_trim))
        render.out.print(f"{sim.status}: {sim.message} -> {ws.path('sim.npz')}")
        for path in figures:
            render.out.print(f"figure -> {path}")
    if sim.status != "ok":
        render.err.print(f"quadctl: check failed: {sim.message}")
        raise typer.Exit(EXIT_CHECK_FAILED)
