"""Artifact-backed stages: run a stage, write its artifact, reuse upstream artifacts.

:class:`Workspace` is :class:`quadctl.pipeline.Stages` with a run folder; what each artifact holds
is :mod:`quadctl.payloads`.

A :class:`Workspace` couples a config to a run directory. Each stage writes its artifact
atomically; an upstream artifact is reused only when its ``config_hash`` and quadctl
version match, otherwise it is recomputed and rewritten (never a stale result). The first
write of a session also writes the config as given (``config.yaml``) and as resolved
(``config.resolved.yaml``), so a run directory always says what made it; every artifact another
config made is then removed, with a notice naming them: the stages' (:data:`STAGE_FILES`), the figures,
the report, a sweep's outputs, the exports (:mod:`quadctl.artifacts.run_folder`; a file quadctl does not
write stays). Every write of a session can be undone
(:meth:`Workspace.roll_back`): a command that refuses its input after some stages ran puts the
folder back as it found it.
"""

from __future__ import annotations

import contextlib
import os
import warnings
import weakref
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from quadctl import artifacts, payloads, pipeline
from quadctl.artifacts import default_out
from quadctl.artifacts.journal import NEW_FOLDER, Journal, undo
from quadctl.artifacts.meta import RESOLVED_CONFIG_HEAD
from quadctl.config import Config
from quadctl.design import Design
from quadctl.design.discrete import RateWarning
from quadctl.design.kalman import require_detectable, selector
from quadctl.errors import DesignError, QuadctlNotice
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
from quadctl.signals import signals_held
from quadctl.sim.loop import ClosedLoop
from quadctl.sim.run import SimResult
from quadctl.version import __version__

TRIM, LINEAR, SUBSYSTEMS, CHECKS, DESIGN, SIM_NPZ, SIM_JSON = (
    "trim.json", "linear.npz", "subsystems.json", "checks.json", "design.json", "sim.npz", "sim.json")
MARGINS, DESIGN_FULL = "margins.json", "design_full.json"
SCHEDULE_JSON, SCHEDULE_NPZ = "schedule.json", "schedule.npz"
CONFIG_GIVEN, CONFIG_RESOLVED = "config.yaml", "config.resolved.yaml"
SWEEP_PARTS = "sweep.parts"
HASH_NOTE = " (config_hash {})"
"""How ``config.resolved.yaml``'s first line ends: the digest of the config (:func:`config_hash_of`)."""
STAGE_FILES = (TRIM, LINEAR, SUBSYSTEMS, CHECKS, DESIGN, SIM_NPZ, SIM_JSON, MARGINS, DESIGN_FULL, SCHEDULE_JSON,
               SCHEDULE_NPZ)
"""The artifacts the stages write (each carries the ``config_hash`` it was made from)."""


def config_hash_of(folder: Path | str) -> str | None:
    """The ``config_hash`` a run folder's ``config.resolved.yaml`` names (None: none there, or unreadable)."""
    try:
        with open(Path(folder) / CONFIG_RESOLVED, encoding="utf-8") as f:
            first = f.readline().rstrip("\n")
    except (OSError, UnicodeDecodeError):
        return None
    head, _, tail = HASH_NOTE.partition("{}")
    if not first.endswith(tail) or head not in first:
        return None
    return first.rpartition(head)[2][:-len(tail)] or None


def _listed(removed: list[str]) -> str:
    """The files a note names, a sweep's chunks counted (``sweep.parts/ (250 chunks)``): each of them is a
    line of its journal, not a file to read."""
    chunks = [name for name in removed if name.startswith(f"{SWEEP_PARTS}/")]
    named = [name for name in removed if name not in chunks]
    return ", ".join(named + ([f"{SWEEP_PARTS}/ ({len(chunks)} chunk{'s' * (len(chunks) != 1)})"] if chunks else []))


def _released(journal: Journal, hold: contextlib.ExitStack) -> None:
    """A session dropped without :meth:`Workspace.close` (collected, or at the process's exit): what it
    wrote stands, so its journal goes first, then the files it set aside and the folder's lock."""
    journal.end()
    hold.close()


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


class Workspace(pipeline.Stages):
    """Stages of one config in one run directory: :class:`quadctl.pipeline.Stages` that reuses
    each stage's fresh artifact and writes the ones it computes.

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
        super().__init__(setup_of(cfg))
        self.cfg = cfg
        self.progress = progress
        self.out = Path(out) if out is not None else default_out(cfg)
        self.fresh = fresh
        self.source_text = source_text
        self._config_written = False
        self.written: list[Path] = []
        self._undo: list[tuple[Path, Path | bytes | str | object | None]] | None = []
        """Each file the session wrote or removed, and what it held before (:meth:`_before_change`); None: kept."""
        self.reused: list[Path] = []
        self.replaced: list[str] = []
        """The artifacts of another config this session removed, relative to the run folder (:meth:`_remove_stale`)."""
        self._made_by: artifacts.MadeBy | None = None
        """Which config made each artifact of the folder, when this session removes another config's."""
        self._notes: list[str] | None = None
        """The notices :meth:`defer_notes` holds back until :meth:`close` (None: each is issued at once)."""
        self.payloads: dict[str, dict] = {}
        """JSON artifacts written or reused in this session, by file name (what ``--json`` prints);
        a reused artifact is parsed once, here."""
        self._hold = contextlib.ExitStack()
        self._hold.enter_context(artifacts.locked(self.out))  # one run at a time; the first finishes a dead one
        if artifacts.lock.marked_by_this_hold(self.out):  # marked as quadctl's now: a roll-back takes the mark away
            self._undo.append((self.out / artifacts.MARK_NAME, None))
        self._journal = Journal(self.out)
        """What this session changes, as it changes it (:mod:`quadctl.artifacts.journal`)."""
        self._finalizer = weakref.finalize(self, _released, self._journal, self._hold)  # a session never closed

    def close(self) -> None:
        """Release the run folder (the process's end releases it too), and issue the notices held back
        (:meth:`defer_notes`)."""
        notes = self._notes or []
        if self._notes is not None:
            self._notes = []
        for note in notes:
            warnings.warn(QuadctlNotice(note), stacklevel=2)
        self._journal.end()  # before the files it names as set aside go
        self._hold.close()
        self._finalizer.detach()  # a later session's journal in this folder is not this one's to remove

    def defer_notes(self) -> None:
        """Hold back what this session says of the folder (the artifacts of another config it removed)
        until :meth:`close`: a command that refuses its input puts the folder back (:meth:`roll_back`), and
        the notices of what it undid are then not issued at all."""
        if self._notes is None:
            self._notes = []

    def __enter__(self) -> Workspace:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def path(self, name: str) -> Path:
        return self.out / name

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

    def write_bytes(self, path: Path | str, data: bytes) -> Path:
        """Write a file of the command's own into the run folder (a figure, the report), atomically as an
        artifact is, remembering what it replaces: :meth:`roll_back` puts it back with the stages' artifacts,
        so a command has one way to put its folder back. A figure (``.png``) carries this config's hash
        (:meth:`stamp`)."""
        path = Path(path)
        self._write_config_files()  # beside the config that made it: another config's artifacts go first
        self._before_change(path)
        self._wrote(artifacts.write_bytes(path, self.stamp(data) if path.suffix == ".png" else data))
        return path

    def stamp(self, png: bytes) -> bytes:
        """``png`` carrying this config's hash (:mod:`quadctl.artifacts.png_stamp`): the run folder tells
        it from a figure of another config, or one a user put there."""
        return artifacts.stamp_png(png, self.cfg.digest())

    def remember(self, *paths: Path | str) -> None:
        """Remember what each of ``paths`` holds before the command writes it by other means (a drawing
        process of its own), for :meth:`roll_back`, as :meth:`write_bytes` does; :meth:`record_written`
        once it has."""
        self._write_config_files()
        for path in paths:
            self._before_change(Path(path))

    def record_written(self, *paths: Path | str) -> None:
        """The command wrote ``paths`` by other means (after :meth:`remember`): this session's, as what
        :meth:`write_bytes` writes (an artifact of another config it replaces is written again)."""
        for path in paths:
            if Path(path).is_file():
                self._wrote(Path(path))

    def remove(self, path: Path | str) -> bool:
        """Remove a file of the command's own (an earlier report's figure), remembered for :meth:`roll_back`
        as :meth:`write_bytes` remembers; True if one went."""
        path = Path(path)
        self._write_config_files()
        self._before_change(path)
        return artifacts.remove(path)

    @property
    def unreplaced(self) -> list[str]:
        """The artifacts of another config this session removed and has not yet written again for its own:
        while there are any, the folder holds neither run whole. Empty after :meth:`keep`."""
        if self._undo is None:
            return []
        return [name for name in self.replaced if self.path(name) not in self.written]

    def roll_back(self) -> bool:
        """Put back every file this session wrote or removed as it was before (the command refused its
        input: nothing it computed is kept), and remove the artifact folders it made, if empty again;
        after :meth:`keep`, nothing (and the notices of what it did are still said). Returns whether it
        put anything back."""
        if self._undo is None:
            return False
        undone = bool(self._undo)
        self._journal.rolling_back()
        with signals_held():  # a second signal does not leave the folder half put back
            undo(self._undo, on_undone=self._journal.undone)
            self._journal.end()
        self._undo = []
        self.written.clear()
        self.replaced.clear()
        self.reused.clear()
        self.payloads.clear()  # the folder's files are the earlier ones again: read afresh if reused
        self._config_written = False  # a later write puts this config beside it again, and its artifacts
        # only: those of the folder's config go first, as at the session's first write
        if self._notes is not None:  # what they said was undone
            self._notes.clear()
        return undone

    def keep(self) -> None:
        """Keep what this session wrote, whatever follows (:meth:`roll_back` does nothing after this)."""
        self._undo = None
        self._journal.end()

    def _before_change(self, path: Path) -> None:
        """Remember what ``path`` holds (once a session) before it is written or removed: the file set
        aside (:meth:`_set_aside`), a link's target (``"-> target"``), or None (absent, or unreadable:
        it cannot be put back)."""
        if self._undo is None or any(path == p for p, _ in self._undo):
            return
        if (path.parent != self.out and not os.path.lexists(path.parent)  # an artifact folder it will make
                and not any(path.parent == p for p, _ in self._undo)):
            self._undo.append((path.parent, NEW_FOLDER))
            self._journal.change(path.parent, NEW_FOLDER)
        try:
            before = (f"-> {os.readlink(path)}" if path.is_symlink()
                      else self._set_aside(path) if path.is_file() else None)
        except OSError:
            before = None
        self._undo.append((path, before))
        self._journal.change(path, before)

    def _set_aside(self, path: Path) -> Path | bytes:
        """The file at ``path`` kept for :meth:`roll_back` without copying it: a second name in the folder
        (a hard link; the atomic write gives ``path`` a new file, so this name keeps the old bytes), removed
        when the workspace closes and named as a temporary a killed run leaves for the next to clean up;
        its bytes where the file system has no hard links."""
        aside = path.parent / f".{path.name}.{artifacts.TEMPORARY_TAG}-undo{os.urandom(4).hex()}.tmp"
        try:
            os.link(path, aside)
        except OSError:
            return path.read_bytes()
        self._hold.callback(aside.unlink, missing_ok=True)
        return aside

    def _wrote(self, path: Path) -> None:
        self.written.append(path)
        if self._undo is not None:
            self._journal.wrote(path)

    def _write_json(self, name: str, kind: str, payload: dict, backends=()) -> None:
        self._write_config_files()
        full = artifacts.jsonable({**self._meta(kind, backends), **payload})
        self.payloads[name] = full
        self._before_change(self.path(name))
        self._wrote(artifacts.write_json(self.path(name), full))

    def _write_npz(self, name: str, arrays: dict, meta: dict) -> None:
        self._write_config_files()
        self._before_change(self.path(name))
        self._wrote(artifacts.write_npz(self.path(name), arrays, meta))

    def _write_config_files(self) -> None:
        """``config.yaml`` (as given) and ``config.resolved.yaml``, at the session's first write."""
        if self._config_written:
            return
        resolved = self.cfg.to_yaml()
        given = self.source_text if self.source_text is not None else (
            "# built in Python, not read from a file: the validated config\n" + resolved)
        head = (f"{RESOLVED_CONFIG_HEAD} {__version__} validated it, every default filled in"
                f"{HASH_NOTE.format(self.cfg.digest())}\n")
        if self._folder_digest() != self.cfg.digest():
            self._remove_stale()
        for name, text in ((CONFIG_GIVEN, given), (CONFIG_RESOLVED, head + resolved)):
            self._before_change(self.path(name))
            self._wrote(artifacts.write_bytes(self.path(name), text.encode("utf-8")))
        self._config_written = True

    def _folder_digest(self) -> str | None:
        return config_hash_of(self.out)

    def _remove_stale(self) -> None:
        """Remove the artifacts another config made (:mod:`quadctl.artifacts.run_folder`: the stages', the
        figures and the report, a sweep's, the exports), with a notice naming them: quadctl never reuses
        them, and beside this config they would say what it did not make. A file whose provenance cannot be
        read (damaged, foreign) is left to the stage that reads it; a file quadctl does not write, always."""
        self._made_by = artifacts.MadeBy(self.out, config_hash_of(self.out))
        removed, hashes = [], []
        for path in artifacts.run_artifacts(self.out, first=STAGE_FILES):
            if path.is_file() and not path.is_symlink() and self._made_by_another_config(path):
                name = path.relative_to(self.out).as_posix()
                hashes.append(self._made_by(path))
                self._before_change(path)
                if self._undo is not None:  # said before it goes: a kill right after still finds the earlier run
                    self._journal.replaced(name)
                self.replaced.append(name)
                path.unlink()
                removed.append(name)
        if removed:
            which = list(dict.fromkeys(hashes))  # each file's own (a sweep another config wrote here: its)
            note = (f"{self.out}: removed {_listed(removed)}, made by "
                    f"{'another config' if len(which) == 1 else 'other configs'} (config_hash {', '.join(which)})")
            if self._notes is None:
                warnings.warn(QuadctlNotice(note), stacklevel=2)
            else:
                self._notes.append(note)

    def _made_by_another_config(self, path: Path) -> bool:
        found = self._made_by(path)
        return found is not None and found != self.cfg.digest()

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
        fd, comparison = pipeline.compare_full(self.setup, self.linear, self.design)
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
        flight = pipeline.flight_summary(setup, loop, sim)
        summary = summarize(sim, linear.u_trim, setup.Q_block, setup.R_block, setup.regulated,
                            noisy=pipeline.noisy(setup))
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
