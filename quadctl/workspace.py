"""Artifact-backed stages: run a stage, write its artifact, reuse upstream artifacts.

:class:`Workspace` is :class:`quadctl.pipeline.Stages` with a run folder; what each artifact holds
is :mod:`quadctl.payloads`.

A :class:`Workspace` couples a config to a run directory. Each stage writes its artifact
atomically; an upstream artifact is reused only when its ``config_hash`` and quadctl
version match, otherwise it is recomputed and rewritten (never a stale result). It writes through a
session of the folder (:class:`quadctl.artifacts.Session`): its first write also writes the config beside
the artifacts and removes every artifact another config made there, with a notice naming them, and every
write can be undone (:meth:`Workspace.roll_back`): a command that refuses its input after some stages ran
puts the folder back as it found it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from quadctl import artifacts, compare, payloads, pipeline, run_summary
from quadctl.artifacts.places import (
    CHECKS,
    DESIGN,
    DESIGN_FULL,
    LINEAR,
    MARGINS,
    SCHEDULE_JSON,
    SCHEDULE_NPZ,
    SIM_JSON,
    SIM_NPZ,
    SUBSYSTEMS,
    TRIM,
)
from quadctl.artifacts.session import Session
from quadctl.config import Config
from quadctl.design import Design
from quadctl.design.discrete import RateWarning
from quadctl.design.kalman import require_detectable, selector
from quadctl.errors import DesignError
from quadctl.layout import N_INPUTS, STATE_NAMES
from quadctl.linear.analysis import Checks, check
from quadctl.linear.decouple import Decoupled
from quadctl.linear.linearize import LinearModel
from quadctl.linear.trim import Trim
from quadctl.metrics import summarize
from quadctl.payloads import ESTIMATOR_CHECK
from quadctl.present.loops import loop_notes
from quadctl.present.schedule import verdict
from quadctl.present.stages import rate_warning
from quadctl.schedule.envelope import schedule_of
from quadctl.setup import setup_of
from quadctl.sim.loop import ClosedLoop
from quadctl.sim.run import SimResult


@dataclass(frozen=True)
class CheckReport:
    """``check``'s result: the rank checks per subsystem (and ``"full"``, and ``"estimator"`` for the
    measured set); for a continuous design run at a rate, the loops that rate cannot realize; with
    rotor lag or delay, the loop the vehicle flies."""

    checks: dict[str, Checks]
    regulated: tuple[str, ...]
    """The regulated subsystems (those whose stabilizability the verdict needs)."""
    rate: float | None
    rate_warnings: tuple[RateWarning, ...]
    vehicle_loop: pipeline.VehicleLoop | None = None
    """With rotor lag, a delay, a gyro filter or a Kalman filter: the design's loop flown with them (else None)."""
    undetectable: str | None = None
    """Why the estimator's measured set cannot estimate the state (else None)."""

    def __getitem__(self, name: str) -> Checks:
        return self.checks[name]

    @property
    def unstabilizable(self) -> tuple[str, ...]:
        """The regulated subsystems that are not stabilizable, sorted."""
        return tuple(sorted(n for n in self.regulated if not self.checks[n].stabilizable))

    @property
    def passed(self) -> bool:
        """No regulated subsystem unstabilizable, the state detectable from the measured set, no loop
        unstable sampled at the controller rate, the vehicle's loop stable. Why not, in words:
        :func:`quadctl.present.stages.check_failures`."""
        return (not self.unstabilizable and self.undetectable is None
                and all(w.sampled_stable for w in self.rate_warnings)
                and (self.vehicle_loop is None or self.vehicle_loop.stable))


@dataclass(frozen=True)
class Flight:
    """``simulate``'s result: the run, the loop it flew, its metrics and flight numbers."""

    sim: SimResult
    loop: ClosedLoop
    metrics: dict
    flight: dict


def _with_messages(payload: dict, warnings, rate) -> dict:
    """checks.json with each rate warning also in words (``message``: :func:`quadctl.present.stages.rate_warning`)."""
    if payload["rate"] is None:
        return payload

    said = [{**d, "message": rate_warning(w, rate)} for d, w in zip(payload["rate"]["warnings"], warnings)]
    return {**payload, "rate": {**payload["rate"], "warnings": said}}


def _with_verdict(payload: dict, sched) -> dict:
    """schedule.json with the schedule's verdict in words (``verdict``: :func:`quadctl.present.schedule.verdict`;
    None when it passes)."""

    return {**payload, "verdict": verdict(sched)}


def _with_notes(payload: dict, margins) -> dict:
    """margins.json with each loop's findings also in words (``notes``: :func:`quadctl.present.loops.loop_notes`),
    for a reader of the file; the payload below the presenter holds the findings as values."""

    return {**payload, "loops": [{**d, "notes": list(loop_notes(m))} for d, m in zip(payload["loops"], margins)]}


class Workspace(Session, pipeline.Stages):
    """Stages of one config in one run directory: :class:`quadctl.pipeline.Stages` that reuses
    each stage's fresh artifact and writes the ones it computes, through a
    :class:`~quadctl.artifacts.Session` of the folder (the config beside them, another config's run
    removed, every write undoable).

    Parameters
    ----------
    cfg : Config
    out : path, optional
        Run directory (default ``runs/<config name>``).
    fresh : bool
        Recompute every stage, ignoring existing artifacts.
    source_text : str, optional
        The YAML the config was read from (the file's text, or a bundled config's), kept as
        ``config.yaml``. Without it (a config built in Python) ``config.yaml`` is the validated
        config under a comment that says so.
    progress : callable, optional
        ``progress(done, total)`` in RK4 steps while the simulation stage runs (see
        :func:`quadctl.sim.run.simulate`).
    """

    def __init__(self, cfg: Config, out: Path | str | None = None, *, fresh: bool = False,
                 source_text: str | None = None, progress=None):
        pipeline.Stages.__init__(self, setup_of(cfg))
        self.progress = progress
        self.fresh = fresh
        self.reused: list[Path] = []
        self.payloads: dict[str, dict] = {}
        """JSON artifacts written or reused in this session, by file name (what ``--json`` prints);
        a reused artifact is parsed once, here."""
        Session.__init__(self, cfg, out, source_text=source_text)

    def _reusable(self, name: str) -> bool:
        if self.fresh:
            return False
        if name in self.payloads:
            return True
        ok = artifacts.is_fresh(self.path(name), self.cfg)
        if ok:
            self.reused.append(self.path(name))
            if name.endswith(".json"):  # --json prints the artifact, reused or new
                self.payloads[name] = artifacts.read_json(self.path(name))
        return ok

    def _meta(self, kind: str, backends=()) -> dict:
        return artifacts.metadata(self.cfg, kind, backends)

    def roll_back(self) -> bool:
        """:meth:`Session.roll_back`; what the session read of the folder is forgotten too (the folder's
        files are the earlier ones again: read afresh if reused)."""
        if self._undo is not None:
            self.reused.clear()
            self.payloads.clear()
        return super().roll_back()

    def _write_json(self, name: str, kind: str, payload: dict, backends=()) -> None:
        full = artifacts.jsonable({**self._meta(kind, backends), **payload})
        self.write_json(self.path(name), full)
        self.payloads[name] = full

    def _write_npz(self, name: str, arrays: dict, meta: dict) -> None:
        self.write_npz(self.path(name), arrays, meta)

    # -- stages ---------------------------------------------------------------------------

    @cached_property
    def trim(self) -> Trim:
        if self._reusable(TRIM):
            data = self.payloads[TRIM]
            return Trim(x=np.array(data["x"]), u=np.array(data["u"]), xdot=np.array(data["xdot"]),
                        residual=float(data["residual"]), iterations=int(data["iterations"]))
        trim = super().trim
        self._write_json(TRIM, "trim", payloads.trim(self.setup, trim))
        return trim

    @cached_property
    def linear(self) -> LinearModel:
        if self._reusable(LINEAR):
            arrays, _ = artifacts.read_npz(self.path(LINEAR))
            return LinearModel(A=arrays["A"], B=arrays["B"], x_trim=arrays["x_trim"],
                               u_trim=arrays["u_trim"], x_rate=arrays["x_rate"])
        linear = super().linear
        self._write_npz(LINEAR, payloads.linear(linear), self._meta("linear"))
        return linear

    @cached_property
    def decoupled(self) -> Decoupled:
        dec = super().decoupled
        self._write_json(SUBSYSTEMS, "subsystems", payloads.subsystems(dec))
        return dec

    @cached_property
    def checks(self) -> CheckReport:
        """Rank checks; for a continuous design run at ``controller.rate``, the rate warnings."""
        checks = pipeline.checks_of(self.decoupled, self.linear)
        est = self.setup.estimator
        if est is not None:  # the measured set on the coupled 12-state model (what the Kalman filter sees)

            checks[ESTIMATOR_CHECK] = check(self.linear.A, self.linear.B, selector(est.measured), STATE_NAMES)
        regulated = {s.name for s in self.decoupled.regulated}
        timing = self.setup.timing
        warnings: list[RateWarning] = []
        vehicle = None
        if all(checks[n].stabilizable for n in regulated):
            warnings = list(self.rate_warnings)
            filtered = est is not None and checks[ESTIMATOR_CHECK].detectable  # (else no filter: said below)
            if (self.setup.rotor_time_constant is not None or timing.delay_samples or self.setup.rate_filter is not None
                    or filtered):  # the loop flown is not the design's
                des = self.__dict__.get("design") or pipeline.design_of(self.setup, self.decoupled, self.linear)
                vehicle = pipeline.vehicle_loop_of(self.setup, self.linear, des, with_filter=filtered)
        self._write_json(CHECKS, "checks", _with_messages(payloads.checks(self.setup, checks, regulated, warnings,
                                                                          vehicle), warnings, timing.rate))
        undetectable = None
        if est is not None and not checks[ESTIMATOR_CHECK].detectable:

            try:
                require_detectable(self.linear.A, selector(est.measured), est.measured)
            except DesignError as exc:
                undetectable = str(exc)
        return CheckReport(checks=checks, regulated=tuple(sorted(regulated)), rate=timing.rate,
                           rate_warnings=tuple(warnings), vehicle_loop=vehicle, undetectable=undetectable)

    @cached_property
    def design(self) -> Design:
        des = super().design
        kal = pipeline.estimator_of(self.setup, self.linear)
        self._write_json(DESIGN, "design", payloads.design(self.setup, des, kal))
        return des

    @cached_property
    def gains(self) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], np.ndarray | None]:
        """(K_block, Ki_block, integral_states, Kv_block or None): from design.json when it is fresh,
        else a new design. ``Kv_block`` is None unless the design includes the rotors' lag."""
        if "design" not in self.__dict__ and self._reusable(DESIGN):
            data = self.payloads[DESIGN]
            ints = tuple(data.get("integral_states", ()))
            Ki = np.array(data.get("Ki_block", [[]] * N_INPUTS), dtype=float)
            Kv = (data.get("rotor_lag") or {}).get("Kv_block")
            return (np.array(data["K_block"], dtype=float), Ki.reshape(N_INPUTS, len(ints)), ints,
                    None if Kv is None else np.array(Kv, dtype=float))
        des = self.design
        return (des.K_block, des.Ki_block, des.integral_states,
                des.Kv_block if des.lag_time_constant is not None else None)

    @cached_property
    def margins(self) -> list:
        """Margins of every loop of the law that flies (the LQR design's: design model and coupled; a PID
        cascade's: each input broken at the plant); writes margins.json."""
        if self.setup.law == "pid":
            result = self.pid_margins
            payload = payloads.cascade_margins(self.setup, self.pid_lift, result)
        else:
            result = self.lqr_margins
            vehicle = pipeline.vehicle_loop_of(self.setup, self.linear, self.design)
            payload = payloads.margins(self.setup, self.design, result, vehicle)
        self._write_json(MARGINS, "margins", _with_notes(payload, result))
        return result

    @cached_property
    def full(self):
        """``design --full``: (FullDesign, comparison); writes design_full.json."""
        fd, comparison = compare.compare_full(self.setup, self.linear, self.design)
        self._write_json(DESIGN_FULL, "design_full", payloads.design_full(fd, comparison),
                         [d["backend"] for d in comparison["designs"].values()])
        return fd, comparison

    @cached_property
    def simulation(self) -> Flight:
        """The configured run with the design's gains (with ``schedule:``, the schedule's; with ``controller.flies:
        pid``, the PID cascade instead); writes sim.npz and sim.json."""
        linear, setup = self.linear, self.setup
        K, Ki, ints, Kv = self.gains
        loop = pipeline.closed_loop_of(setup, linear, K, Ki=Ki, integral_states=ints, Kv=Kv)
        if setup.schedule is not None:  # fly the schedule's gains (and write schedule.json beside)
            sched = self.schedule
            loop = sched.flown_by(loop)
        if setup.law == "pid":  # the PID cascade flies in place of the design (controller.flies: pid)
            loop = pipeline.pid_loop_of(setup, linear)
        sim = pipeline.simulation_of(setup, loop, progress=self.progress)
        flight = run_summary.flight_summary(setup, loop, sim)
        summary = summarize(sim, linear.u_trim, setup.Q_block, setup.R_block, setup.regulated,
                            noisy=pipeline.noisy(setup), twin=pipeline.twin_settling(setup, loop))
        meta = self._meta("simulation", sim.backend)
        self._write_npz(SIM_NPZ, payloads.simulation_arrays(sim, loop), meta)
        self._write_json(SIM_JSON, "simulation", payloads.simulation(sim, summary, flight), sim.backend)
        return Flight(sim=sim, loop=loop, metrics=summary, flight=flight)


    @cached_property
    def schedule(self):
        """The gain schedule (:func:`quadctl.schedule.envelope.schedule_of`); writes schedule.json and schedule.npz."""

        sched = schedule_of(self.setup)
        self._write_npz(SCHEDULE_NPZ, payloads.gain_schedule_arrays(sched), self._meta("schedule"))
        self._write_json(SCHEDULE_JSON, "schedule", _with_verdict(payloads.gain_schedule(sched), sched))
        return sched
