

from quadctl.cli.errors import FailedChecks
from quadctl.cli.options import ConfigOpt, FreshOpt, JsonOpt, OutOpt, SetOpt, open_workspace, override, rate_option
from quadctl.cli.stage_warnings import warn_of_the_rate

RateOpt = rate_option(
    help="Also check the continuous design against this controller rate (a what-if for a config "
         "without controller.rate; one that sets it is checked at its own rate).")

NAME = "check"


def command(config: ConfigOpt = None, out: OutOpt = None, sets: SetOpt = None, json: JsonOpt = False,
            fresh: FreshOpt = False,
            rate: RateOpt = None,
            ) -> None:
    """Controllability, observability (PBH and the staircase), stabilizability of every subsystem and the full model.

    Warns when a continuous design has closed-loop poles faster than the controller rate can
    realize (which loop, by how much, and whether the sampled loop is still stable).
    With an 'estimator:' section, the measured set on the coupled model too (row 'estimator').
    With rotor lag (motors.time_constant) or delay (controller.delay), whether the design's loop
    stays stable with them, and how much damping they take.

    Exits 1 when a regulated subsystem is not stabilizable, the measured set leaves a mode that is
    not stable unobservable, a loop sampled at the config's controller.rate (continuous design) or
    at --rate is unstable, or the lag and delay make the design's loop unstable.
    """
    from quadctl.cli import render
    from quadctl.present import stages

    rate = override("--rate", rate)
    ws = open_workspace(config, out, fresh, sets)
    ws.setup.timing.refuse_other_rate(rate)
    if ws.setup.timing.rate is not None:  # --rate is the config's own: checked as the config's (no what-if of
        rate = None                       # the continuous design, which a discrete config does not fly)
    checks = ws.checks
    regulated = set(checks.regulated)
    rated = [(checks.rate, checks.rate_warnings)] if checks.rate_warnings else []
    what_if = None
    if rate is not None and all(checks[n].stabilizable for n in regulated):
        from quadctl import pipeline

        what_if = pipeline.rate_warnings_of(ws.setup, ws.decoupled, ws.linear, rate)
        rated = [(hz, found) for hz, found in rated if hz != rate] + [(rate, what_if)]
    if json:
        payload = ws.payloads["checks.json"]
        if rate is not None:
            payload = {**payload, "what_if_rate": {"rate": rate, "warnings": [
                stages.rate_warning(w, rate) for hz, found in rated if hz == rate for w in found]}}
        render.emit_json(payload)
    else:
        render.show(stages.checks_table(checks.checks, regulated))
        if checks.vehicle_loop is not None:
            render.out.print(stages.vehicle_loop_summary(checks.vehicle_loop), markup=False)
        render.out.print(f"-> {ws.path('checks.json')}")
    for hz, warnings in rated:
        warn_of_the_rate(hz, warnings)
    failures = stages.check_failures(checks)
    at_rate = stages.sampled_unstable(what_if, rate) if what_if is not None else None  # --rate's own verdict
    if at_rate and at_rate not in failures:
        failures.append(at_rate)
    if failures:
        raise FailedChecks(*failures)
