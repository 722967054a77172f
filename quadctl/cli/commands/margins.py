from typing import Annotated

import typer

from quadctl.cli.errors import FailedChecks
from quadctl.cli.options import ConfigOpt, FreshOpt, JsonOpt, OutOpt, SetOpt, open_workspace

NAME = "margins"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, json: JsonOpt = False,
            fresh: FreshOpt = False,
            plot: Annotated[bool, typer.Option(
                "--plot", help="Also write a Bode and Nyquist figure per loop to DIR/plots/margins-*.png.")] = False,
            coupled: Annotated[bool, typer.Option(
                "--coupled/--design-only",
                help="Also show each loop broken on the coupled 12-state model (other loops closed), and exit 1 "
                     "on its verdict; --design-only shows the design's loops alone. margins.json, and --json, hold "
                     "both.")] = True,
            ) -> None:
    """Gain, phase and disk margins of every regulated loop, broken at its plant input; write margins.json.

    A continuous design's loops are compared with the continuous LQR guarantee (gain margin -6 dB
    to infinity, phase margin 60 deg), shortfalls explained (coupling, sampling, saturation). A
    discrete design's loops are the sampled ones the flight computer closes: sampling does not keep
    that guarantee, so their own margins are shown without it. With controller.flies: pid, the PID
    cascade's loops: each input broken at the plant with the whole multi-rate cascade closed around it,
    lifted to its frame (every hold exact). Exits 1 when a loop is unstable, or
    has less than 6 dB of gain margin or 30 deg of phase margin (MIL-F-9490D) unless the config
    lists thin-margins under allow.
    """
    from quadctl.cli import render

    ws = open_workspace(config, out, fresh, sets)
    cascade = ws.setup.law == "pid"
    margins = [m for m in ws.margins if coupled or m.model in ("design", "cascade")]
    paths = _save_figures(ws, margins) if plot else []
    if json:
        render.emit_json(ws.payloads["margins.json"])
    else:
        from quadctl.present import loops

        if cascade:
            payload = ws.payloads["margins.json"]
            render.show(loops.classical_table(margins, payload["rate"]), loops.disk_table(margins, True),
                        loops.delay_table(margins), loops.cascade_sentence(payload))
        else:
            discrete = ws.design.rate is not None
            render.show(loops.classical_table(margins, ws.setup.timing.rate), loops.disk_table(margins, discrete),
                        loops.delay_table(margins), loops.guarantee_sentence(margins, discrete))
            for line in loops.notes(margins):
                render.out.print(f"  {line}", markup=False)
            render.show(loops.closed_loop_sentence(ws.payloads["margins.json"]))
        render.out.print(f"-> {ws.path('margins.json')}")
        for path in paths:
            render.out.print(f"figure -> {path}")
    from quadctl.present.loops import loop_name, thin_sentence

    unstable = [m for m in margins if not m.stable]
    thin = thin_sentence(margins, accepted="thin-margins" in ws.cfg.allow)
    if thin and "thin-margins" in ws.cfg.allow:
        render.warning(thin)
        thin = None
    if unstable or thin:
        names = ", ".join(loop_name(m) for m in unstable)
        raise FailedChecks(*([f"unstable loop(s): {names}"] if unstable else []), *([thin] if thin else []))


def _save_figures(ws, margins):
    from quadctl import artifacts, plots

    paths = []
    for m in margins:
        fig = plots.margins_figure(m, title=ws.setup.name)
        paths.append(ws.write_bytes(artifacts.plot_path(ws.out, plots.margins_figure_name(m)),
                                    plots.png_bytes(fig, 90)))
    return paths
