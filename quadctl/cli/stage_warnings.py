"""The warnings and the gate on a stage's result that every command running the stage gives alike
(``simulate``, ``check`` and ``run``): the verdicts are the library's, this only prints them."""

from __future__ import annotations


def warn_of_the_flight(ws, flown, allow_saturation: bool) -> None:
    """The warnings on a flight (``simulate`` and ``run`` alike): inputs at a limit for a part of the
    run the gate lets through, the gain schedule's (a mission that fails is a failed check:
    :func:`mission_failure`)."""
    from quadctl.cli import render
    from quadctl.present.flight import saturation_text

    saturates = saturation_text(flown.flight)
    if saturates and not _fails_on_saturation(ws, flown, allow_saturation):  # else the error says it
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


def require_within_limits(ws, flown, allow_saturation: bool) -> None:
    """Exit 1 (a check failed) when the design saturates most of the run and nobody accepted it."""
    from quadctl.physics import motors

    sat = flown.flight.get("saturation")
    fractions, mode = (sat["fraction"], sat["mode"]) if sat else (None, None)
    motors.require_within_limits(fractions, mode,
                                 allowed=allow_saturation or "saturation" in ws.cfg.allow)


def _fails_on_saturation(ws, flown, allow_saturation: bool) -> bool:
    from quadctl.errors import SaturationFailed

    try:
        require_within_limits(ws, flown, allow_saturation)
    except SaturationFailed:
        return True
    return False


def warn_of_the_rate(rate: float, warnings) -> None:
    """A continuous design's loops that ``rate`` (Hz) cannot realize, a warning each (``check`` and ``run``)."""
    from quadctl.cli import render
    from quadctl.present.stages import rate_warning

    for w in warnings:
        render.warning(rate_warning(w, rate))
