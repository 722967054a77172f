from pathlib import Path
from typing import Annotated, Optional

import typer

from quadctl.cli.options import JsonOpt, force_option, label_of, noticed, out_folder, set_option

NAME = "identify"

VehicleConfigOpt = Annotated[Optional[str], typer.Option(
    "--config", "-c", metavar="PATH|NAME", show_default=False,
    help="Required: the config of the vehicle flown (its mass, rotor positions and numbering), a file or the name "
         "of a bundled config (see `quadctl configs`), e.g. -c crazyflie.")]


def command(logs: Annotated[list[str], typer.Argument(
                metavar="LOG", show_default=False,
                help="Flight logs: Crazyflie microSD binary, PX4 ULog (pyulog) or CSV; one or more.")],
            config: VehicleConfigOpt = None,
            out: Annotated[Optional[Path], typer.Option(
                "--out", "-o", metavar="DIR", parser=out_folder,
                help="Folder for the results. Default: runs/<config name>-identified.")] = None,
            window: Annotated[Optional[list[str]], typer.Option(
                "--window", metavar="T0:T1", help="The stretch of a log to fit, s from the log's first sample, as "
                "the output shows times (t0:t1, or t0:t1,t2:t3 that do not overlap); once per LOG, in order. Default: "
                "chosen from the excitation.")] = None,
            columns: Annotated[Optional[list[str]], typer.Option(
                "--columns", metavar="NAME=COLUMN", help="A CSV's column names (t=time_s,cmd_1=m1).")] = None,
            delay: Annotated[bool, typer.Option(
                "--delay", help="Fit a pure delay of the commands beside the motor lag.")] = False,
            sets: set_option("the fit takes the config with them, and identified.yaml carries them.") = None,
            force: force_option("an identified.yaml edited since quadctl wrote it (the edits are lost)") = False,
            json: JsonOpt = False) -> None:
    """Identify the rotors' thrust curve and lag, Ixx and Iyy, and the torque coefficient from flight logs.

    The config gives what a log cannot (mass, rotor positions and numbering). Writes identified.json
    (values, 95 % intervals, windows, residuals, the logs' sha256), identified.yaml (the config with
    the identified values, each line saying where it came from) and identify.png. A value that is not
    physically possible (a time constant, an inertia or a torque coefficient whose 95 % interval reaches
    zero, a full-command thrust whose interval reaches a rotor's share of the weight) is not written into
    identified.yaml (the config's stays) and is flagged in identified.json: exit 1 after writing. An
    identified.yaml edited since quadctl wrote it is not written over (exit 2, nothing changed) unless --force.
    """
    import json as _json

    from quadctl import artifacts
    from quadctl.artifacts.writing import write_together
    from quadctl.cli import render
    from quadctl.config import locate, overrides
    from quadctl.errors import CheckFailed, ConfigError
    from quadctl.identify import config_edits, csv_log, readers, results
    from quadctl.plots.identify import fit_figure
    from quadctl.present import identify as shown

    if config is None:  # no default: the fit depends on the vehicle's mass and geometry
        raise ConfigError(shown.config_needed())
    source = locate(config)
    cfg = overrides.load(source, sets or ())
    # the fit takes the config's mass (and its rotor positions): a unit slip there (grams, mm) is a thrust curve
    # and an inertia off by as much, so it stops identify as it stops every command that computes
    noticed(cfg, label_of(source, sets))
    folder = out or Path("runs") / f"{cfg.name}-identified"
    results.require_unedited(folder, force)  # before the fit, and before the folder is touched
    read = [readers.read_log(p, csv_log.parse_columns(columns)) for p in logs]
    ident = results.identify(read, cfg, results.windows_per_log(window, len(logs)), delay=delay)
    text = config_edits.identified_config(source.text, ident, f"{cfg.name}-identified", sets or ())
    payload = results.payload(ident, source.label, cfg, written=text, sets=sets or ())
    # the folder's lock only, not a session of it (quadctl.artifacts.Session, as sweep and export take): what
    # identify writes is made from flight logs and is no config's run (quadctl.artifacts.run_folder.NOT_THE_RUNS),
    # and its folder is where the identified config runs (run -c DIR/identified.yaml -o DIR). A session of the
    # vehicle's config would write that config over the identified one's and remove its run at every new fit.
    with artifacts.locked(folder):  # a folder of quadctl's (claimed), one quadctl at a time
        results.require_unedited(folder, force)  # (edited while the fit ran)
        write_together({folder / "identified.json": _json.dumps(payload, indent=1).encode(),
                        folder / "identified.yaml": text.encode(), folder / "identify.png": fit_figure(ident)})
    if json:
        render.emit_json(payload)
    else:
        render.show(*shown.log_sentences(payload), shown.values_table(payload), *shown.sentences(payload))
        for name in ("identified.json", "identified.yaml", "identify.png"):
            render.out.print(f"-> {folder / name}")
    if payload["implausible"]:
        raise CheckFailed(shown.implausible(payload, folder))
