from typing import Annotated

import typer

from quadctl.cli.errors import FailedChecks
from quadctl.cli.options import ConfigOpt, FreshOpt, JsonOpt, OutOpt, SetOpt, open_workspace

NAME = "design"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, json: JsonOpt = False,
            fresh: FreshOpt = False,
            full: Annotated[bool, typer.Option(
                "--full", help="Also solve one 12-state LQR on the coupled model with the same cost, simulate "
                               "both on the nonlinear model and say which does better; write design_full.json.")
                            ] = False) -> None:
    """LQR per regulated subsystem, assembled and checked on the coupled model; write design.json.

    With a controller rate (controller.rate, controller.design: discrete) the design is the
    discrete LQR at that rate (MATLAB lqrd). Exits 1 when the design, stable per subsystem, is
    unstable on the coupled 12-state model.
    """
    from quadctl.cli import render

    ws = open_workspace(config, out, fresh, sets)
    des = ws.design
    comparison = ws.full if full else None
    if json:
        payload = ws.payloads["design.json"]
        render.emit_json({**payload, "full": ws.payloads["design_full.json"]} if full else payload)
    else:
        from quadctl import pipeline
        from quadctl.present import design as shown

        lag_or_delay = ws.setup.rotor_time_constant is not None or ws.setup.timing.delay_samples
        render.show(shown.discrete_sentence(des), shown.plant_and_timing(ws.setup) if lag_or_delay else None,
                    shown.gains_table(des), shown.gain_matrix_table(des), shown.damp_table(des))
        kal = pipeline.estimator_of(ws.setup, ws.linear)
        if kal is not None:
            render.show(*shown.estimator_blocks(ws.setup, kal))
        render.out.print(f"-> {ws.path('design.json')}")
        if comparison is not None:
            from quadctl.cli import render_loop

            for item in render_loop.full_tables(*comparison):
                render.out.print(item)
            render.out.print(f"-> {ws.path('design_full.json')}")
    if not des.stable:
        raise FailedChecks("every subsystem is stable alone, but the assembled gain is UNSTABLE on the "
                           "coupled 12-state model (the dropped couplings matter)")
    if not json:
        from quadctl.present import design as shown

        render.show(shown.stability_sentence(des))
