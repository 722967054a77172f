"""The warnings and the gate on a stage's result that every command running the stage gives alike
(``simulate``, ``check`` and ``run``): the verdicts are the library's, this only prints them."""

from __future__ import annotations


def warn_of_the_flight(ws, flown, allow_saturation: bool) -> None:
    """The warnings on a flight (``simulate`` and ``run`` alike): inputs at a limit for a part of the
    run the gate lets through, the gain schedule's (what fails the flight is a failed check:
    :func:`quadctl.stages.flight_failures`)."""
    from quadctl.cli import render
    from quadctl.present.flight import saturation_text

    saturates = saturation_text(flown.flight)
    if saturates:
        from quadctl.stages import saturation_failure

        if saturation_failure(ws, allow_saturation) is None:  # else the failed check says it
            render.warning(saturates)
    warn_of_ignored_steps(ws)
    warn_of_the_schedule(ws)


def warn_of_ignored_steps(ws) -> None:
    """Setpoints that step a position no regulated subsystem holds: the vehicle does not follow them."""
    from quadctl.present.mission import ignored_steps_text
    from quadctl.run_summary import ignored_position_steps

    text = ignored_steps_text(ignored_position_steps(ws.setup))
    if text:
        from quadctl.cli import render

        render.warning(text)


def mission_failure(flown) -> str | None:
    """Why the flight's mission failed (a waypoint never reached, a final error above the tolerance), in
    a sentence; None: it did not (or there is no mission)."""
    from quadctl.present.mission import mission_text

    return mission_text(flown.flight.get("reference"))


def warn_of_the_schedule(ws) -> None:
    """With ``schedule:``, the warnings on the gains flown: values with no trim, checks that fail."""
    if ws.setup.schedule is not None:
        from quadctl.cli import render
        from quadctl.present.schedule import flight_warnings

        for line in flight_warnings(ws.schedule):
            render.warning(line)


def warn_of_the_rate(rate: float, warnings) -> None:
    """A continuous design's loops that ``rate`` (Hz) cannot realize, a warning each (``check`` and ``run``)."""
    from quadctl.cli import render
    from quadctl.present.stages import rate_warning

    for w in warnings:
        render.warning(rate_warning(w, rate))
