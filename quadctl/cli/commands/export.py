from enum import Enum
from typing import Annotated, Optional

import typer

from quadctl.cli.options import ConfigOpt, OutOpt, SetOpt, rate_option
from quadctl.text.setpoints import SETPOINT_HELP

RateOpt = rate_option(
    help="Run a continuous design (no controller.rate) at this rate, after the check "
         "`quadctl check --rate` makes.")

NAME = "export"


class Target(str, Enum):
    c = "c"
    mat = "mat"
    json = "json"
    crazyflie = "crazyflie"


class Setpoint(str, Enum):
    position = "position"
    velocity = "velocity"


class Mode(str, Enum):
    force = "force"
    force_torque = "force-torque"


def command(to: Annotated[Target, typer.Option(
                "--to", help="c: a C99 controller (quadctl_controller.h and .c, double or float); mat: the design "
                             "as a MATLAB v5 .mat; json: the same as one self-describing JSON; crazyflie: a "
                             "Crazyflie out-of-tree controller app (the C controller in float, its adapter, "
                             "build files).")],
            config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None,
            rate: RateOpt = None,
            setpoint: Annotated[Optional[Setpoint], typer.Option(
                "--setpoint", show_default=False,
                help=SETPOINT_HELP)] = None,
            mode: Annotated[Optional[Mode], typer.Option(
                "--mode", show_default="force",
                help="--to crazyflie: force (each motor's thrust, mixed and clipped as the simulation "
                     "does) or force-torque (thrust and torques, mixed by the firmware).")] = None,
            json: Annotated[bool, typer.Option(
                "--json", help="Print what was written as JSON on stdout (with --to json, the controller's "
                               "JSON itself under `controller`).")] = False) -> None:
    """Take the design to the vehicle: a C controller that applies it exactly as simulate does, or its matrices.

    Writes into the run directory: quadctl_controller.h/.c (--to c), quadctl_controller.mat or quadctl_controller.json,
    beside the config (the run of another config there is removed first). --to crazyflie compares the vehicle
    with the firmware's defaults and flies the configured run, warning when it asks a motor for a thrust the
    firmware does not give (below THRUST_MIN it stops the motor; in force mode it clips one above THRUST_MAX,
    in force-torque mode it caps one at full PWM).
    Exits 1 when the design is unstable, when the gain schedule (schedule:) fails its checks, or when a
    continuous design's loop is unstable sampled at --rate; 2 when --to c has no rate (give --rate or set
    controller.rate), or when --to crazyflie cannot serve the config (a rate that does not divide the
    firmware's 1 kHz loop, a --setpoint the partition leaves free, rotors numbered unlike the firmware's), or
    when --setpoint or --mode is given with another --to.
    """
    from quadctl import artifacts, export
    from quadctl.cli import render
    from quadctl.cli.options import load_source, open_session, override
    from quadctl.present.stages import rate_warning
    from quadctl.setup import setup_of

    app_only = [f"--{name} {choice.value}" for name, choice in (("setpoint", setpoint), ("mode", mode)) if choice]
    if app_only and to is not Target.crazyflie:
        from quadctl.errors import ConfigError

        raise ConfigError(f"{' and '.join(app_only)}: only --to crazyflie takes {'them' if len(app_only) > 1 else 'it'}"
                          f" (the app's commander and mixer), not --to {to.value}; drop it, or export --to crazyflie")
    mode = mode or Mode.force
    rate = override("--rate", rate)
    cfg, source = load_source(config, sets)
    exp = export.prepare(setup_of(cfg), rate, need_rate=to in (Target.c, Target.crazyflie),
                         config_hash=cfg.digest())
    for w in exp.rate_warnings:
        render.warning(rate_warning(w, exp.rate))
    flown = None
    if to is Target.crazyflie:
        from quadctl.export import crazyflie
        from quadctl.export.crazyflie_platform import FIRMWARE, flight_thrusts, platform_rows

        flown = setpoint.value if setpoint is not None else crazyflie.default_setpoint(exp)
    folder = out or artifacts.default_out(cfg)
    files = export.files(exp, to.value, folder, artifacts.metadata(cfg, "export"), setpoint=flown, mode=mode.value)
    session = open_session(cfg, source, folder)  # after every check: a refused export touches no folder
    paths = session.write_together(files)
    session.keep()  # the export is whole: it stays, whatever follows
    flight = None
    if to is Target.crazyflie:
        from quadctl.present.platform import flight_sentences, platform_sentences

        for line in platform_sentences(platform_rows(exp), FIRMWARE, mode.value):
            render.note(line)
        flight = flight_thrusts(exp, mode.value)
        for level, line in flight_sentences(flight, FIRMWARE) if flight is not None else ():
            (render.warning if level == "warning" else render.note)(line)
        for sentence in (crazyflie.gyro_sentence(exp), crazyflie.lag_sentence(exp, config or cfg.name, sets or ())):
            if sentence is not None:
                render.note(sentence)
    kal = exp.loop.estimator
    if json:
        written = {"config_name": cfg.name, "to": to.value, "rate": exp.rate, "design": exp.mode if exp.rate else
                   "continuous", "law": exp.law(), "integral_states": list(exp.loop.integral_states),
                   "estimator": list(kal.measured) if kal is not None else None, "reference": exp.flies_reference,
                   "schedule": exp.loop.schedule.variable if exp.loop.schedule is not None else None,
                   "files": [str(p) for p in paths]}
        if to is Target.json:
            written["controller"] = artifacts.read_json(paths[0])
        if to is Target.crazyflie:
            written["crazyflie"] = {
                "setpoint": flown, "mode": mode.value, "calls_per_sample": crazyflie.divider(exp.rate),
                "firmware": {"commit": FIRMWARE.commit, "source": FIRMWARE.source,
                             "min_thrust": FIRMWARE.min_thrust, "max_thrust": FIRMWARE.max_thrust,
                             "full_pwm_thrust": FIRMWARE.full_pwm_thrust,
                             "full_pwm_voltage": FIRMWARE.full_pwm_voltage},
                "platform": [{"quantity": q, "key": k, "value": v, "firmware": f, "unit": u}
                             for q, k, v, f, u in platform_rows(exp)],
                "flight": None if flight is None else flight.summary(FIRMWARE)}
        return render.emit_json(written)
    timing = f"{exp.rate:g} Hz, {exp.mode} design" if exp.rate else "continuous design"
    filt = f"; Kalman filter ({kal.form}) measuring {', '.join(kal.measured)}" if kal is not None else ""
    if to is Target.crazyflie:
        filt += f"; reference: the commander's {flown} setpoints; output: {mode.value} mode"
    elif exp.flies_reference:
        filt += "; reference: an input at each sample" + (" (quadctl_step_ref)" if to is Target.c else "")
    table = exp.loop.schedule
    if table is not None:
        filt += f"; gains scheduled on {table.variable} ({len(table.values)} designs, {table.interpolation})"
    render.out.print(f"{cfg.name}: {timing}; integrators: {', '.join(exp.loop.integral_states) or 'none'}{filt}",
                     markup=False)
    law = crazyflie.law(exp, flown) if to is Target.crazyflie else exp.law()
    render.out.print(f"law: {law}", markup=False)
    for path in paths:
        render.out.print(f"-> {path}", markup=False)
