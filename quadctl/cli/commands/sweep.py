from pathlib import Path
from typing import Annotated, Optional

import typer

from quadctl.cli.errors import FailedChecks
from quadctl.cli.options import ConfigOpt, JsonOpt, OutOpt, SetOpt, nonempty_path

NAME = "sweep"


def command(
    sweep: Annotated[Path, typer.Option("--sweep", "-s", metavar="FILE", parser=nonempty_path(
        "give the sweep file, as `quadctl sweep -s examples/ci-sweep.yaml`"),
                                        help="Sweep file: parameters to vary, mode, gates.")],
    config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None,
    jobs: Annotated[Optional[int], typer.Option(
        "--jobs", "-j", min=1, metavar="N",
        help="Local worker processes (not with --scheduler). Default: all cores.")] = None,
    scheduler: Annotated[Optional[str], typer.Option(
        "--scheduler", metavar="ADDRESS", help="Run on this Dask scheduler (tcp://host:8786) instead.")] = None,
    resume: Annotated[bool, typer.Option(
        "--resume", help="Keep the rows an interrupted run of this sweep finished; compute the rest.")] = False,
    json: JsonOpt = False,
    no_plot: Annotated[bool, typer.Option(
        "--no-plot",
        help="Write no figure (sweep.png, montecarlo.png): the tables, sweep.csv and sweep.json only.")] = False,
) -> None:
    """Design, simulate and score many variants of a config; write sweep.csv, sweep.json, sweep.png.

    They are written beside the config (the run of another config in the folder is removed first).

    Each case is the config with the sweep file's values put in at their key paths (lqr.roll.Q[1], vehicle.mass).
    Every case is trimmed, designed, simulated on the nonlinear model and scored.
    Exits 1 when a case fails a gate (or, with require_ok, fails to design, is unstable or diverges).

    A sweep whose parameters all change the simulated vehicle, never the design
    (the noise seed, simulation.plant mass and inertia errors, the initial
    offset, the wind, controller.delay, motors.time_constant while
    controller.rotor_lag is ignore) is an uncertainty study: one design flies
    every case; it also writes montecarlo.png and montecarlo.npz (bands).
    """
    # only what the worker processes need starts before them (they fork from this process): the
    # terminal's output (rich) is imported as they run
    from quadctl import sweep as sweep_mod
    from quadctl.cli.errors import remember_interrupt_hint
    from quadctl.cli.options import label_of, load_source, open_session
    from quadctl.cli.progress import sweep_progress
    from quadctl.errors import SweepError
    from quadctl.sweep.runner import check_scheduler_address

    if jobs is not None and scheduler:
        raise SweepError("--jobs and --scheduler: give one; on a cluster its workers do the work")
    if scheduler is not None:
        check_scheduler_address(scheduler)  # before anything is loaded: a typo, or nothing, fails at once
    cfg, source = load_source(config, sets)
    spec = sweep_mod.load(sweep, cfg)
    session = open_session(cfg, source, out)  # after the sweep file: a refused one touches no folder
    remember_interrupt_hint(f"the chunks it finished are kept in {session.out / sweep_mod.PARTS}: the same "
                            "command with --resume computes only the rest")
    with sweep_progress(quiet=json, meanwhile=None if no_plot else _import_plots) as progress:
        outcome = sweep_mod.execute(cfg, spec, session, label=label_of(source, sets), jobs=jobs,
                                    scheduler=scheduler, resume=resume, progress=progress, plot=not no_plot)
    session.keep()  # the sweep's outputs are whole: they stay, whatever follows (a failed gate, exit 1)
    from quadctl.cli import render, render_sweep

    result, summary = outcome.result, outcome.summary
    if scheduler and "casadi" in result.stats["backend"]:  # locally, the engine's own notice said so
        from quadctl.sim.engine import VM_COST

        render.note(f"the Dask workers found no working C compiler: they simulated in CasADi's virtual machine "
                    f"({VM_COST})")
    if json:
        render.emit_json({**summary, "performance": render_sweep.sweep_performance(outcome)})
    else:
        render.out.print(render_sweep.sweep_tables(result, spec))
        method = sweep_mod.sweep_file.fixed_value(spec.fixed, "simulation.method", cfg.simulation.method)
        render.out.print(render_sweep.sweep_line(outcome, method))
        for path in outcome.files:
            render.out.print(f"-> {path}")
    if summary.get("montecarlo", {}).get("cases") == 0:
        render.warning("no montecarlo.png or montecarlo.npz: no case of this Monte Carlo simulated to the end, "
                       "so there are no bands to draw; each case's reason is in sweep.csv")
    if result.failed:
        if not json:
            for line in render_sweep.worst_lines(result):
                render.out.print(line, markup=False)
        raise FailedChecks(f"{len(result.failed)} of {len(result.rows)} cases fail: "
                           + render_sweep.sweep_failures(summary))


def _import_plots() -> None:
    """matplotlib for the figures (~0.3 s), imported while the workers compute rather than after them
    (the forward sweep of 1000 cases with its figure: 0.97 -> 0.89 s)."""
    import quadctl.plots  # noqa: F401
