
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
from quadctl.cli.stage_warnings import mission_failure, warn_of_the_flight

NAME = "simulate"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, plot: PlotOpt = False,
            json: JsonOpt = False, fresh: FreshOpt = False,
            allow_saturation: AllowSaturationOpt = False) -> None:
    """Simulate the full nonlinear closed loop (RK4, or ETDRK4: simulation.method); write sim.npz and sim.json.

    The loop flies simulation.reference (setpoints or a mission) when the config gives one, and the
    gain schedule when it has a schedule: section (schedule.json and schedule.npz written beside).
    Exits 1 when the run diverges or leaves the model's valid range, the PID cascade it flies
    (controller.flies: pid) is unstable about hover, it flies its actuators' limits most of the run
    (unless accepted), or its mission misses a waypoint or ends farther than the tolerance from it
    (what was computed is saved).
    """
    from quadctl.cli import render
    from quadctl.cli.figures import save_figures
    from quadctl.cli.progress import simulation_progress

    ws = open_workspace(config, out, fresh, sets)
    with simulation_progress(quiet=json) as ws.progress:
        flown = ws.simulation
    sim = flown.sim
    figures = save_figures(ws, sim, flown.flight.get("reference")) if plot else []
    if json:
        render.emit_json(ws.payloads["sim.json"])
    else:
        from quadctl.present import flight as shown
        from quadctl.present import mission
        from quadctl.present.schedule import schedule_line

        fl = flown.flight
        render.out.print(f"{shown.integrator_name(sim)} {shown.step_text(sim)}, {sim.steps} steps in "
                         f"{sim.wall_time * 1e3:.1f} ms: "
                         f"[bold]{sim.steps_per_second / 1e6:.2f} M steps/s[/bold] ({sim.backend})")
        render.show(shown.controller_text(fl, sim), shown.metrics_table(flown.metrics),
                    shown.inputs_table(flown.metrics, ws.linear.u_trim, fl["peak_delta"]),
                    shown.headroom_table(fl, ws.linear.u_trim),
                    shown.rms_table(fl) if fl.get("noise") or fl.get("wind") else None,
                    shown.estimation_table(fl), shown.wind_line(fl["wind"]) if fl.get("wind") else None,
                    schedule_line(fl["gain_schedule"]) if fl.get("gain_schedule") else None,
                    shown.speeds_table(fl) if fl.get("wind") else None, shown.integral_text(fl),
                    *((mission.waypoints_table(fl["reference"]), *mission.tracking_lines(fl["reference"]))
                      if fl.get("reference") else ()))
        render.out.print(f"{mission.run_line(sim.status, sim.message, mission_failure(flown) is not None)} -> "
                         f"{ws.path('sim.npz')}")
        for path in figures:
            render.out.print(f"figure -> {path}")
    warn_of_the_flight(ws, flown, allow_saturation)
    from quadctl.stages import flight_failures

    reasons = flight_failures(ws, allow_saturation)
    if reasons:
        raise FailedChecks(*reasons)
