from typing import Annotated

import typer

from quadctl.cli.errors import EXIT_CHECK_FAILED
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
        if des.rate:
            render.out.print(f"discrete design at {des.rate:g} Hz (lqrd: ZOH plant, cost integrated over "
                             f"{1e3 / des.rate:.4g} ms); eigenvalues shown as ln(z)/Ts in rad/s")
        tau = ws.setup.rotor_time_constant
        if tau is not None and des.lag_time_constant is None:
            render.out.print(f"rotor lag {tau * 1e3:.4g} ms: ignored by the design (controller.rotor_lag: "
                             f"{ws.setup.rotor_lag}); simulated in the plant")
        elif tau is not None:
            render.out.print(f"rotor lag {tau * 1e3:.4g} ms: included in the design (controller.rotor_lag: include; "
                             "each subsystem's inputs lag, Kv feeds back the controller's lag model)")
        for table in render.design_tables(des):
            render.out.print(table)
        est = ws.payloads["design.json"].get("estimator")
        if est:
            render.out.print(_estimator_line(est, render))
        render.out.print(f"-> {ws.path('design.json')}")
        if comparison is not None:
            from quadctl.cli import render_loop

            for item in render_loop.full_tables(*comparison):
                render.out.print(item)
            render.out.print(f"-> {ws.path('design_full.json')}")
    if not des.stable:
        render.err.print("quadctl: check failed: every subsystem is stable alone, but the assembled "
                         "gain is UNSTABLE on the coupled 12-state model (the dropped couplings matter)")
        raise typer.Exit(EXIT_CHECK_FAILED)
    if not json:
        marg = f" (marginal by design: {', '.join(des.marginal_states)})" if des.marginal_states else ""
        render.out.print(f"[green]stable[/green] on the coupled 12-state linear model{marg}")


def _estimator_line(est: dict, render) -> str:
    """One line on the Kalman filter design.json holds: its form, what it measures, its slowest pole."""
    eig = [complex(re, im) for re, im in est["eigenvalues"]]
    if est["form"] == "filter":
        slowest = max(eig, key=abs)
        how = (f"discrete filter at {1 / est['sample_time']:g} Hz, gain M (measurement update; predictor "
               f"L = Ad M), slowest pole |z| = {abs(slowest):.4g}")
    else:
        slowest = max(eig, key=lambda e: e.real)
        how = f"Kalman-Bucy filter, gain L, slowest pole {render.eig(slowest)} rad/s"
    return f"estimator (LQG) on {' '.join(est['measured'])}: {how}"
