"""The chain of stages, written once: what ``quadctl run`` and the run report compute, in order, and
the check each stage's result must pass.

:data:`STAGES` is the table; :func:`run_stages` runs it on a :class:`~quadctl.workspace.Workspace`
(each result cached there) and says in an :class:`Outcome` how far it went. The verdicts are the
library's; the sentences are :mod:`quadctl.present`'s.

Examples
--------
>>> [stage.name for stage in STAGES]
['trim', 'linearize', 'decouple', 'check', 'design', 'margins', 'simulate']
>>> RUN
('trim', 'linearize', 'decouple', 'check', 'design', 'simulate')
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Any

import numpy as np

from quadctl.errors import QuadctlError, SaturationFailed
from quadctl.physics.motors import require_within_limits
from quadctl.present.loops import thin_sentence
from quadctl.present.mission import mission_text
from quadctl.present.stages import UNSTABLE_DESIGN, check_verdict, unstable_cascade_text


def _passes(ws, allow_saturation: bool) -> None:
    return None


def _design(ws, allow_saturation: bool) -> str | None:
    return None if ws.design.stable else UNSTABLE_DESIGN


def _flight(ws, allow_saturation: bool) -> str | None:
    """The first of :func:`flight_failures`: what ``quadctl run`` and the report stop on."""
    reasons = flight_failures(ws, allow_saturation)
    return reasons[0] if reasons else None


def flight_failures(ws, allow_saturation: bool) -> tuple[str, ...]:
    """Why the flight fails its check, in order; empty: it passes. First one of: it did not finish, the
    PID cascade it flew is unstable about hover (:func:`cascade_instability`), it flew its actuators'
    limits most of the run (:func:`saturation_failure`); then, beside it, its mission not flown (a run
    that stopped early misses its waypoints too: both are said)."""
    flown = ws.simulation
    first = (flown.sim.message if flown.sim.status != "ok"
             else cascade_instability(ws) or saturation_failure(ws, allow_saturation))
    return tuple(why for why in (first, mission_text(flown.flight.get("reference"))) if why)


def saturation_failure(ws, allow_saturation: bool) -> str | None:
    """Why the flight fails on its actuators' limits: at a limit most of the run, unless accepted
    (``allow_saturation``, or the config's ``allow: [saturation]``); None: it does not."""
    sat = ws.simulation.flight.get("saturation")
    try:
        require_within_limits(sat["fraction"] if sat else None, sat["mode"] if sat else None,
                              allowed=allow_saturation or "saturation" in ws.cfg.allow)
    except SaturationFailed as exc:
        return str(exc)
    return None


def cascade_instability(ws) -> str | None:
    """With ``controller.flies: pid``, why the cascade that flies is unstable about hover (its lifted closed
    loop, :attr:`quadctl.pipeline.Stages.pid_lift`, has a pole on or outside the unit circle); None: it is
    stable, or the LQR design flies (its stability is the design stage's check). A run of an unstable cascade
    can end before its mode grows: the run alone does not say it."""
    if ws.setup.law != "pid":
        return None
    lift = ws.pid_lift
    if lift.stable:
        return None
    return unstable_cascade_text(ws.setup.pid.title or ws.setup.pid.preset, float(np.abs(lift.poles).max()),
                                 lift.frame_time)


def _thin(ws, allow_saturation: bool) -> str | None:
    return None if "thin-margins" in ws.cfg.allow else thin_sentence(ws.margins)


@dataclass(frozen=True)
class Stage:
    """One stage of the chain.

    Attributes
    ----------
    name : str
        As the commands and the artifacts name it.
    compute : callable
        ``ws -> result``: the result, computed once and cached on the workspace.
    verdict : callable
        ``(ws, allow_saturation) -> str | None``: why the result fails its check (None: it passes).
    after_flight : bool
        The verdict is given after the flight (a loop's thin margin fails the run, but the flight is
        still worth computing and reporting).
    """

    name: str
    compute: Callable[[Any], Any]
    verdict: Callable[[Any, bool], str | None] = _passes
    after_flight: bool = False


STAGES: tuple[Stage, ...] = (
    Stage("trim", lambda ws: ws.trim),
    Stage("linearize", lambda ws: ws.linear),
    Stage("decouple", lambda ws: ws.decoupled),
    Stage("check", lambda ws: ws.checks, lambda ws, allow: check_verdict(ws.checks)),
    Stage("design", lambda ws: ws.design, _design),
    Stage("margins", lambda ws: ws.margins, _thin, after_flight=True),
    Stage("simulate", lambda ws: ws.simulation, _flight),
)
"""The stages in order, each with its check: a regulated subsystem that is not stabilizable, a
continuous design unstable sampled at the controller's rate, or a design loop the rotors' lag and
the delay make unstable (``check``); an assembled design unstable on the coupled model (``design``);
a loop with a thin margin (:func:`quadctl.design.margins.thin_loops`) the config does not accept
(``margins``, after the flight); a simulation that does not finish, flies its limits most of the
run, or misses its mission (``simulate``)."""
NAMES = tuple(stage.name for stage in STAGES)
"""Every stage's name, in order: what the report runs."""
RUN = tuple(name for name in NAMES if name != "margins")
"""The stages ``quadctl run`` runs (``quadctl margins`` and the report add the margins)."""


def verdict(name: str, results, allow_saturation: bool = False) -> str | None:
    """Stage ``name``'s check on ``results`` (a workspace, or any object with its results, such as
    :class:`quadctl.pipeline.Stages`): why it fails, None when it passes."""
    return next(stage for stage in STAGES if stage.name == name).verdict(results, allow_saturation)


@dataclass(frozen=True)
class Outcome:
    """How far the stages went.

    Attributes
    ----------
    done : tuple of str
        The stages computed, in order (a simulation that diverged is computed).
    failed : str or None
        Why a check failed (``"check: subsystem roll is not stabilizable: mode 0 in phi, p"``): what
        ``quadctl run`` exits 1 for.
    error : QuadctlError or None
        An error a stage raised (its ``exit_code`` says what kind); the stages after it did not run.
    names : tuple of str
        The stages that were to run, in order.
    """

    done: tuple[str, ...]
    failed: str | None = None
    error: QuadctlError | None = None
    names: tuple[str, ...] = NAMES

    @property
    def stopped_at(self) -> str | None:
        """The stage that failed a check or raised; None when every stage passed."""
        if self.failed is not None:
            return self.failed.split(":", 1)[0]
        return None if self.error is None else self.names[len(self.done)]


def run_stages(ws, names: tuple[str, ...] = NAMES, *, allow_saturation: bool = False,
               computed: Callable[[str], None] | None = None,
               passed: Callable[[str], None] | None = None,
               around: Callable[[str], Any] | None = None) -> Outcome:
    """Run the stages ``names`` of :data:`STAGES` in order on ``ws`` until one fails its check or raises.

    Neither stops with an exception: both are in the returned :class:`Outcome`, so that what was
    computed can still be shown. A stage whose verdict comes after the flight is checked once the
    others have passed.

    Parameters
    ----------
    ws : Workspace
        Where the results are computed and cached.
    names : tuple of str
        Which stages (:data:`NAMES` for the report, :data:`RUN` for ``quadctl run``).
    allow_saturation : bool
        Accept a flight at its actuators' limits (``--allow-saturation``; the config's
        ``allow: [saturation]`` is read from ``ws``).
    computed, passed : callable, optional
        Called with a stage's name once it is computed (before its check), and once it passed.
    around : callable, optional
        ``name -> context manager`` entered around a stage's computation (a progress bar).
    """
    done: list[str] = []
    deferred: list[Stage] = []
    for stage in (s for s in STAGES if s.name in names):
        try:
            with (around(stage.name) if around is not None else nullcontext()):
                stage.compute(ws)
        except QuadctlError as exc:
            return Outcome(tuple(done), error=exc, names=names)
        done.append(stage.name)
        if computed is not None:
            computed(stage.name)
        if stage.after_flight:
            deferred.append(stage)
            continue
        why = stage.verdict(ws, allow_saturation)
        if why is not None:
            return Outcome(tuple(done), failed=f"{stage.name}: {why}", names=names)
        if passed is not None:
            passed(stage.name)
    for stage in deferred:
        why = stage.verdict(ws, allow_saturation)
        if why is not None:
            return Outcome(tuple(done), failed=f"{stage.name}: {why}", names=names)
        if passed is not None:
            passed(stage.name)
    return Outcome(tuple(done), names=names)
