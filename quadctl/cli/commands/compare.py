from typing import Annotated, Optional

import typer

from quadctl.cli.errors import FailedChecks
from quadctl.cli.options import ConfigOpt, JsonOpt, OutOpt, SetOpt, open_workspace

NAME = "compare"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, json: JsonOpt = False,
            law: Annotated[Optional[list[str]], typer.Option(
                "--law", metavar="LAW", help="A law to fly beside the LQR design: pid:crazyflie or pid:px4 (the "
                "flight stacks' published defaults; controller.pid's values apply to its own preset; a cascade needs "
                "motors: in the config). Repeat for more; default pid:crazyflie; lqr alone: the LQR design by "
                "itself.")] = None,
            plot: Annotated[bool, typer.Option(
                "--plot", help="Also write one figure per quantity, the laws overlaid, to DIR/plots/compare-*.png.")]
            = False) -> None:
    """Fly the config's LQR design and flight stacks' PID cascades side by side; write compare.json.

    Every law flies the same plant from the same initial offset, along the same reference, through the
    same wind and noise (one realization, read by all). The table shows tracking error, settling,
    overshoot, rotor use, time at a rotor limit, the cost on the config's LQR weights and each law's least
    gain and phase margins (its loops broken at the plant inputs). quadctl report shows it when
    compare.json is in the run folder.

    Exits 1 when the LQR design fails, as simulate and margins would: its run stops (diverged, or out of
    the model's valid range) or its closed loop is unstable. A cascade that fails is shown in its column
    and does not change the exit code: it is the finding, not the design under test.
    """
    import json as jsonlib

    from quadctl import artifacts
    from quadctl.cli import render
    from quadctl.compare import DEFAULT_LAWS, compare, parse_law, payload
    from quadctl.errors import ConfigError

    laws = law or DEFAULT_LAWS
    for text in laws:
        try:
            parse_law(text)
        except ValueError as exc:
            raise ConfigError(f"--law: {exc}") from None
    ws = open_workspace(config, out, False, sets)
    result = compare(ws, laws)
    # the provenance at the top, as every artifact carries it: the run folder's reader (the report) checks it
    data = {**artifacts.metadata(ws.cfg, "compare"), **payload(result)}
    data = artifacts.jsonable(data)  # NumPy's scalars as JSON's, infinities spelled out: the file and --json alike
    text = jsonlib.dumps(data, indent=1, sort_keys=True) + "\n"
    path = ws.write_bytes(ws.path("compare.json"), text.encode())
    names = [law.name for law in result.laws]
    figures = []
    if plot:
        from quadctl import plots
        from quadctl.plots.compare import comparison_figures
        from quadctl.present.compare import free_position_sentence

        notes = {"position-error": free_position_sentence(ws.setup.regulated, names) or ""}
        for stem, fig in comparison_figures(result.laws, title=ws.setup.name, notes=notes).items():
            figures.append(ws.write_bytes(artifacts.plot_path(ws.out, f"compare-{stem}"), plots.png_bytes(fig, 90)))
    if json:
        render.emit_json(data)
        if result.design_failures:
            raise FailedChecks(*result.design_failures)
        return
    from quadctl.present import compare as words

    render.show(words.table(data), words.disturbance_sentence(data), words.gyro_filter_sentence(data),
                words.free_position_sentence(ws.setup.regulated, names))
    render.out.print(f"-> {path}")
    for fig_path in figures:
        render.out.print(f"figure -> {fig_path}")
    if result.design_failures:  # a verdict after every output is written and shown
        raise FailedChecks(*result.design_failures)

