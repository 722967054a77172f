"""Take a design to the vehicle: the controller as C, and the design as MATLAB ``.mat`` or JSON.

:func:`prepare` runs the stages of a setup once, checks that the design can leave quadctl (stable
on the coupled model, and, for a continuous design run at a rate, stable as the flight computer
samples it) and returns an :class:`Export`: the closed loop exactly as ``quadctl simulate`` runs
it (:mod:`quadctl.export.bundle`). The writers read only that object:

- :mod:`quadctl.export.c`: a C99 controller generated from the simulation's own control law
  (:func:`quadctl.sim.builder.build`), ``double`` or ``float``; a config that flies a reference
  (``simulation.reference``) gives one that takes the reference at each sample; its header's
  documentation comments are written by :mod:`quadctl.export.c_doc`;
- :mod:`quadctl.export.data`: the design as named, unit-carrying fields, written as a MATLAB v5
  ``.mat`` (:func:`scipy.io.savemat`) or as one self-describing JSON.
"""

from __future__ import annotations

from dataclasses import replace

from quadctl import artifacts
from quadctl.config import check_override
from quadctl.errors import ArgumentError, ArgumentTypeError, CheckFailed, ConfigError, RateError, ScheduleError
from quadctl.export.bundle import Export as Export
from quadctl.export.bundle import law_text as law_text
from quadctl.export.bundle import require_export
from quadctl.pipeline import Stages
from quadctl.present import schedule as schedule_words
from quadctl.schedule import envelope
from quadctl.setup import Setup, Timing
from quadctl.stages import verdict

PID_NOT_EXPORTED = ("controller.flies: pid: the export carries the LQR design, and the PID cascade that flies is the "
                    "flight stack's own (its gains are the stack's parameters): export with controller.flies: lqr")
"""Why a config that flies the PID cascade is not exported."""


def prepare(setup: Setup, rate: float | None = None, *, need_rate: bool = True,
            config_hash: str | None = None) -> Export:
    """Design ``setup`` and check that it can be exported.

    Parameters
    ----------
    setup : Setup
    rate : float, optional
        Hz to run a *continuous* design at (a config without ``controller.rate``): the design is
        emulated at that rate after the check ``quadctl check --rate`` makes.
    need_rate : bool
        A controller for a flight computer needs a rate (the C export); a ``.mat`` or JSON of a
        continuous design does not.
    config_hash : str, optional
        The config's digest, for the provenance of the exported files.

    Returns
    -------
    Export
        Its loop is the one ``quadctl simulate`` flies: with ``schedule:``, the schedule's gain table
        (:func:`quadctl.schedule.envelope.schedule_of`).

    Raises
    ------
    ConfigError
        The config flies the PID cascade (``controller.flies: pid``): the export carries the LQR
        design. No rate where one is needed or ``rate`` given for a config that has its own
        (:class:`~quadctl.errors.RateError`), outside
        ``controller.rate``'s bounds, or a gain schedule with values that do not trim
        (:class:`~quadctl.errors.ScheduleError`; exit 2).
    CheckFailed
        The design is unstable on the coupled model, the sampled loop of a continuous design is
        unstable at ``rate``, or a gain schedule fails its checks (exit 1; the message says which
        loop and why).
    DesignError
        A subsystem cannot be designed (exit 1).
    ArgumentTypeError
        ``setup`` is not a :class:`~quadctl.setup.Setup` (a :class:`~quadctl.pipeline.Stages`: give its
        ``setup``; a ``TypeError``).
    """

    if not isinstance(setup, Setup):
        raise ArgumentTypeError(f"prepare takes a Setup, export.prepare(stages.setup) or "
                                f"export.prepare(qc.setup_of(cfg)); got {type(setup).__name__}")
    if setup.law == "pid":
        raise ConfigError(PID_NOT_EXPORTED)
    if rate is not None:  # the bounds of controller.rate, which it stands for
        rate = check_override("rate", rate, key="controller.rate")
    timing = setup.timing
    timing.refuse_other_rate(rate)
    if rate is not None and timing.rate is None:  # the continuous design, run at that rate
        setup = replace(setup, timing=Timing(rate=float(rate)))
    elif setup.timing.rate is None and need_rate:
        raise RateError("the design is continuous (no controller.rate) and a flight computer samples: "
                        "give --rate HZ to run it at that rate, or set controller.rate "
                        "(with controller.design: discrete to design for it)")
    stages = Stages(setup)
    why = verdict("design", stages)
    if why is not None:
        raise CheckFailed(f"the design is {why} (every subsystem is stable "
                          "alone: the dropped couplings matter); `quadctl design` shows its eigenvalues")
    unstable = [w for w in stages.rate_warnings if not w.sampled_stable]
    if unstable:
        from quadctl.present.stages import rate_warning

        raise CheckFailed(f"not exported: {rate_warning(unstable[0], setup.timing.rate)}")
    loop, schedule = _flown(setup, stages.loop)
    return Export(setup=setup, linear=stages.linear, decoupled=stages.decoupled, design=stages.design,
                  loop=loop, rate_warnings=stages.rate_warnings, config_hash=config_hash, schedule=schedule)


def _flown(setup: Setup, loop):
    """(the loop ``quadctl simulate`` flies, its schedule): ``(loop, None)``, or with ``schedule:`` the
    schedule's gains (:func:`quadctl.schedule.envelope.schedule_of`, flown as
    :func:`quadctl.pipeline.scheduled_loop`), which must pass the schedule's checks to leave quadctl,
    and that schedule."""
    if setup.schedule is None:
        return loop, None

    schedule = envelope.schedule_of(setup)
    if schedule.undesigned:  # a controller for the vehicle covers every value asked, or none is made
        raise ScheduleError(schedule_words.missing(schedule))
    if not schedule.passed:
        raise CheckFailed(f"not exported: the gain schedule fails its checks: {schedule_words.verdict(schedule)} "
                          "(`quadctl schedule` shows them)")
    return schedule.flown_by(loop), schedule


TARGETS = ("c", "mat", "json", "crazyflie")
"""What :func:`write` writes: the C controller, the MATLAB ``.mat``, the JSON, the Crazyflie app."""


def files(exp: Export, to: str, folder, meta: dict | None = None, *, setpoint: str | None = None,
          mode: str = "force") -> dict:
    """The export ``to`` (one of :data:`TARGETS`) as the files to write into ``folder``, each checked whole
    and nothing written: ``{path: bytes}``, for :func:`write` or a run folder's session
    (:meth:`quadctl.artifacts.Session.write_together`, as ``quadctl export`` writes them).

    Parameters
    ----------
    exp : Export
    to : {"c", "mat", "json", "crazyflie"}
    folder : path
        The run folder.
    meta : dict, optional
        Provenance for the JSON (:func:`quadctl.artifacts.metadata`).
    setpoint, mode : str
        The Crazyflie app's setpoints (default: what the config can fly,
        :func:`quadctl.export.crazyflie.default_setpoint`) and output mode
        (:func:`quadctl.export.crazyflie.sources`).

    Returns
    -------
    dict of pathlib.Path to bytes
        ``quadctl_controller.h`` and ``.c``; or ``quadctl_controller.mat``; or ``quadctl_controller.json``;
        or the Crazyflie app's files (:data:`quadctl.export.crazyflie.APP_FILES` and the controller
        in ``src/``).

    Raises
    ------
    ConfigError
        The Crazyflie app cannot serve the config (:func:`quadctl.export.crazyflie.check`).
    ArgumentError, ArgumentTypeError
        An unknown ``to``, or ``exp`` is not an :class:`Export`.
    """
    return _files(exp, to, folder, meta, setpoint, mode, "files")


def _files(exp: Export, to: str, folder, meta: dict | None, setpoint: str | None, mode: str, who: str) -> dict:
    """:func:`files`; ``who`` is named when ``exp`` is no :class:`Export`."""
    import io
    from pathlib import Path

    from quadctl.export import c, crazyflie, data

    if to not in TARGETS:
        raise ArgumentError(f"to must be one of {TARGETS}, got {to!r}")
    require_export(exp, who)
    folder = Path(folder)
    if to == "c":
        return {folder / name: text.encode() for name, text in c.sources(exp).items()}
    if to == "crazyflie":
        return {folder / name: text.encode() for name, text in crazyflie.sources(exp, setpoint, mode).items()}
    if to == "mat":
        buf = io.BytesIO()
        data.write_mat(buf, exp)
        return {folder / data.MAT_FILE: buf.getvalue()}
    return {folder / data.JSON_FILE: artifacts.json_bytes(data.json_payload(exp, meta))}


def write(exp: Export, to: str, folder, meta: dict | None = None, *, setpoint: str | None = None,
          mode: str = "force") -> list:
    """Write the export ``to`` (:func:`files`) into ``folder``, atomically; the paths.

    ``folder`` is created if missing, and held (:func:`quadctl.artifacts.locked`) while it is written; the
    temporaries an earlier, killed writer left there are removed first. The files are written as they are:
    a run folder's rule (one config's run, undone when the command fails) is a session's, which
    ``quadctl export`` writes through (:class:`quadctl.artifacts.Session`).

    Raises
    ------
    ConfigError
        The Crazyflie app cannot serve the config (:func:`quadctl.export.crazyflie.check`):
        nothing is written.
    ArgumentError, ArgumentTypeError
        An unknown ``to``, or ``exp`` is not an :class:`Export`: nothing is written.

    Notes
    -----
    The files are written together (:func:`quadctl.artifacts.write_together`: every temporary whole
    before the first rename), and the two C files each carry the other's ``QUADCTL_PAIR``: a pair
    that a kill between the renames leaves half-replaced does not compile.
    """
    written = _files(exp, to, folder, meta, setpoint, mode, "write")  # checked whole before the folder is touched
    with artifacts.locked(folder):  # one quadctl writes a folder at a time (the first holder finishes a dead one)
        return artifacts.write_together(written)
