from quadctl.cli.errors import FailedChecks
from quadctl.cli.options import ConfigOpt, FreshOpt, JsonOpt, OutOpt, PlotOpt, SetOpt, open_workspace
from quadctl.errors import ScheduleError

NAME = "schedule"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, json: JsonOpt = False,
            fresh: FreshOpt = False, plot: PlotOpt = False) -> None:
    """Trim and design at each value of the config's schedule (schedule: variable, values); write
    schedule.json and schedule.npz.

    The variable is speed (m/s along the trim heading), climb (m/s, up positive) or yaw (rad). The
    designs are made together (batched), their gains tabled and interpolated (schedule.interpolation:
    nearest, linear or cubic; outside the values the end point's gain holds), and each interpolated
    gain is closed on the model trimmed at its value on a grid schedule.check times finer. A value
    with no trim says why in its row, and the command then exits 2 (narrow schedule.values to the
    envelope); --plot draws the envelope (DIR/plots/schedule.png). Exits 1 when a design or a
    frozen-point check is unstable.
    """
    from quadctl.cli import render
    from quadctl.present import schedule as shown

    ws = open_workspace(config, out, fresh, sets)
    sched = ws.schedule
    path = None
    if plot:
        from quadctl import artifacts, plots

        fig = plots.schedule_figure(sched, ws.setup.actuators, title=ws.setup.name)
        path = ws.write_bytes(artifacts.plot_path(ws.out, "schedule"), plots.png_bytes(fig, plots.DPI))
    if json:
        render.emit_json(ws.payloads["schedule.json"])
    else:
        render.show(shown.points_table(sched), shown.envelope_sentence(sched), shown.failures_table(sched),
                    shown.checks_sentence(sched))
        render.out.print(f"-> {ws.path('schedule.json')}, {ws.path('schedule.npz')}")
        if path is not None:
            render.out.print(f"figure -> {path}")
    missing = shown.missing(sched)
    if missing:  # bad input, refused once the points, their reasons and the envelope are written and shown
        ws.keep()
        raise ScheduleError(missing)
    verdict = shown.verdict(sched)
    if verdict:
        raise FailedChecks(verdict)
