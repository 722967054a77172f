"""One identification from logs and a config: the stages run, and ``identified.json``.

The identified config it writes beside them, and what that config sets, is :mod:`quadctl.identify.config_edits`.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass

import numpy as np

from quadctl.artifacts.meta import metadata
from quadctl.config.controller_schema import MAX_DELAY_SAMPLES
from quadctl.config.schema import Config
from quadctl.errors import ArgumentTypeError, ArtifactError, LogError
from quadctl.identify import estimate as est
from quadctl.identify import plausibility
from quadctl.identify import windows as win
from quadctl.identify.config_edits import CURVE, changes
from quadctl.identify.grid import on_grid, require_window
from quadctl.identify.measurement import MEANING, UNITS, Airframe
from quadctl.present import identify as shown


@dataclass
class Identification:
    """The stages' fits (``thrust``, ``attitude``, ``yaw``), the refused stages and the logs."""

    logs: list
    fits: dict
    refused: dict
    stage_logs: dict  # stage -> log index
    airframe: Airframe
    config_name: str
    controller_rate: float | None = None
    """Hz, the config's ``controller.rate`` (None: continuous), at which a fitted delay is counted."""

    def delay_samples(self, written: bool = True) -> int | None:
        """The fitted delay as the nearest whole number of controller samples (``controller.delay`` counts
        them); None without a fitted delay or without a controller rate (a continuous controller has none), and
        (``written``) when it is more than ``controller.delay`` takes (:data:`MAX_DELAY_SAMPLES`)."""
        th = self.fits["thrust"]
        if "delay" not in th.names or self.controller_rate is None:
            return None
        n = round(th.value("delay") * self.controller_rate)
        return None if written and n > MAX_DELAY_SAMPLES else n

    def max_thrust(self) -> float:
        """N: a rotor's thrust at full command (the curve at 1)."""
        th = self.fits["thrust"]
        return th.value("c0") + th.value("c1") + th.value("c2")

    def max_thrust_std(self) -> float:
        """N: the standard deviation of :meth:`max_thrust`, from the thrust fit's covariance of c0, c1, c2."""
        th = self.fits["thrust"]
        k = [th.names.index(n) for n in ("c0", "c1", "c2")]
        return float(np.sqrt(max(float(np.sum(th.covariance[np.ix_(k, k)])), 0.0)))

    def entries(self) -> dict[str, dict]:
        """``{parameter: its identified.json entry}`` (:func:`entry`): every fitted parameter, and
        ``max_thrust``, the curve at full command (:data:`quadctl.identify.plausibility.RULES` has a rule for each)."""
        out = {}
        for fit in self.fits.values():
            for k, name in enumerate(fit.names):
                out[name] = entry(name, fit.values[k], *fit.interval(name), fit.std[k], UNITS[name],
                                  MEANING[name], fit.floors.get(name) if fit.at_floor(name) else None)
        top, std = self.max_thrust(), self.max_thrust_std()
        out["max_thrust"] = entry("max_thrust", top, top - est.Z95 * std, top + est.Z95 * std, std, "N",
                                  MAX_THRUST_MEANING, hover=self.airframe.hover_thrust())
        return out

    def implausible(self) -> tuple[str, ...]:
        """The parameters whose estimate is not plausible (:func:`entry`)."""
        return tuple(n for n, e in self.entries().items() if not e["plausible"])

    def withheld(self) -> dict[tuple[str, str], tuple[str, ...]]:
        """``{(section, key): implausible parameters}``: the keys the identified config does not write."""
        return plausibility.withheld(self.implausible())


MAX_THRUST_MEANING = "rotor thrust at full command (c0 + c1 + c2)"
"""The meaning ``identified.json`` gives ``max_thrust`` (:data:`quadctl.identify.measurement.MEANING` gives the
fitted parameters')."""


def entry(name: str, value: float, lo: float, hi: float, std: float, unit: str, meaning: str,
          floor: float | None = None, hover: float | None = None) -> dict:
    """One parameter of ``identified.json``: its value, 95 % interval, unit, rule and whether it passes it
    (``passes_rule``, :func:`quadctl.identify.plausibility.judge`), the fit's ``floor`` when the value sits
    on it (``fit_floor``: the floor, not an estimate), and ``plausible``: it passes its rule, off the floor.
    ``hover`` (N, a rotor's share of the weight), the bound of a rule that needs it, is kept as ``hover_thrust``."""
    passes = plausibility.judge(name, value, (lo, hi), hover=hover)
    return {"value": float(value), "interval95": [lo, hi], "std": float(std), "unit": unit, "meaning": meaning,
            "rule": plausibility.RULES[name].value, "passes_rule": passes, "fit_floor": floor,
            "plausible": passes and floor is None, **({} if hover is None else {"hover_thrust": float(hover)})}


def windows_per_log(texts, count: int):
    """The ``--window`` values, one per log, as lists of ``(t0, t1)``; None when none are given.

    Raises
    ------
    LogError
        Not one per log, or one not ``t0:t1``.
    """
    if not texts:
        return None
    if len(texts) != count:
        given = "once" if len(texts) == 1 else f"{len(texts)} times"
        raise LogError(f"--window given {given} for {count} log(s); give it once per LOG, in order")
    return [win.parse_window(t) for t in texts]


def _check_each_log_once(logs, windows) -> None:
    """Refuse a log given twice over the same windows (the same bytes, by their sha256): its samples would
    count twice, and every interval would come out narrower than the flight supports."""
    first = {}
    for i, log in enumerate(logs):
        key = (log.sha256, repr(windows[i] if windows else None))
        if key in first:
            raise LogError(f"{log.path}: the same log as {logs[first[key]].path} (sha256 {log.sha256[:12]}...), over "
                           "the same stretch; give each log once: its samples would count twice and narrow every "
                           "interval")
        first[key] = i


def identify(logs, config, windows=None, delay: bool = False) -> Identification:
    """Run every stage the logs support (:func:`quadctl.identify.windows.plan`).

    Parameters
    ----------
    logs : list of FlightLog
    config : quadctl.config.Config
        Mass, geometry, numbering; the inertia and torque coefficient a stage holds fixed.
    windows : list, optional
        Per log, its ``(t0, t1)`` windows or None (automatic).
    delay : bool
        Fit a pure delay beside the motor lag.

    Raises
    ------
    ArgumentTypeError
        ``config`` is not a validated Config (a config's name: load it first).
    LogError
        One log given twice over the same windows (its samples would count twice).
    """
    if not isinstance(config, Config):
        raise ArgumentTypeError(f"identify takes a validated Config, identify(logs, qc.load_config('crazyflie')); "
                                f"got {type(config).__name__}")
    _check_each_log_once(logs, windows)
    airframe = Airframe.from_config(config)
    p = win.plan(logs, windows, airframe)
    grids = {}

    def grid(i):
        if i not in grids:
            grids[i] = on_grid(logs[i], command_rate=airframe.command_rate)
        return grids[i]

    fits = {}
    i, w = p.chosen["thrust"]
    require_window(grid(i), w, logs[i].path, "thrust")
    fits["thrust"] = est.fit_thrust(grid(i), w, airframe, delay=delay)
    if "attitude" in p.chosen:
        i, w = p.chosen["attitude"]
        require_window(grid(i), w, logs[i].path, "attitude")
        fits["attitude"] = est.fit_attitude(grid(i), w, airframe, fits["thrust"])
    if "yaw" in p.chosen:
        i, w = p.chosen["yaw"]
        require_window(grid(i), w, logs[i].path, "yaw")
        fits["yaw"] = est.fit_yaw(grid(i), w, airframe, fits["thrust"], fits.get("attitude"))
    return Identification(logs=list(logs), fits=fits, refused=p.refused,
                          stage_logs={s: c[0] for s, c in p.chosen.items()}, airframe=airframe,
                          config_name=config.name, controller_rate=config.controller.rate)


def yaml_digest(data: str | bytes) -> str:
    """The sha256 of ``identified.yaml``'s bytes: as written (``data`` text, UTF-8 encoded), or as read."""
    return hashlib.sha256(data.encode() if isinstance(data, str) else data).hexdigest()


def require_unedited(folder, force: bool = False) -> None:
    """Refuse to write over an ``identified.yaml`` in ``folder`` that is not the one quadctl last wrote there.

    quadctl records the sha256 of the bytes it writes (``identified.json``'s ``identified_yaml_sha256``,
    :func:`payload`); a file whose bytes differ was edited by hand (or was written by a quadctl that kept no
    record). ``force`` writes over it all the same.

    Raises
    ------
    ArtifactError
        The file differs from the record, or there is no record (exit 2); nothing is written.
    """
    from pathlib import Path

    path = Path(folder) / "identified.yaml"
    if force or not os.path.lexists(path):  # a link too; os.path's: a name too long for the system is none
        return
    try:
        recorded = json.loads((Path(folder) / "identified.json").read_text(encoding="utf-8"))
        recorded = recorded.get("identified_yaml_sha256") if isinstance(recorded, dict) else None
    except (OSError, ValueError):
        recorded = None
    try:
        same = recorded is not None and yaml_digest(path.read_bytes()) == recorded
    except OSError:
        same = False
    if not same:
        raise ArtifactError(shown.edited(path, recorded is not None))


def payload(ident: Identification, config_label: str, config=None, written: str | None = None, sets=()) -> dict:
    """``identified.json``: values, 95 % intervals, units, windows, residuals, the logs' provenance
    (and, given the ``config``, the provenance every quadctl artifact carries), each value's rule and
    whether it passes it (``plausible``), the keys not written for a value that does not (``not_written``),
    and, given the identified config's text as ``written``, the sha256 of its bytes
    (``identified_yaml_sha256``: :func:`require_unedited` tells a hand edit by it); the ``--set`` values
    the fit's config took (``set``)."""
    stages, found = {}, ident.entries()
    for stage, fit in ident.fits.items():
        params = {name: found[name] for name in fit.names}
        derived = {"derived": {"max_thrust": found["max_thrust"]}} if stage == "thrust" else {}
        stages[stage] = {
            "log": ident.logs[ident.stage_logs[stage]].path, "windows_s": [list(w) for w in fit.windows],
            "samples": int(fit.t.size), "parameters": params, "residual_rms": fit.rms,
            "residual_unit": "N" if stage == "thrust" else "N m",
            "residual_correlation_s": fit.bandwidth / 2 * float(np.median(np.diff(fit.t))),
            **{k: v for k, v in fit.extra.items()}, **derived}

    meta = metadata(config, "identified.json") if config is not None else {}
    fitted_delay = "delay" in ident.fits["thrust"].names
    withheld = ident.withheld()
    n = None if ("controller", "delay") in withheld else ident.delay_samples()
    kept = [key for key, (value, _) in changes(ident).items() if value is None]
    return {**meta, "config": config_label, "set": list(sets), "logs": [log.provenance() for log in ident.logs],
            "stages": stages,
            "refused": dict(ident.refused),
            "implausible": list(ident.implausible()),
            "not_written": {f"{section}.{key}": list(withheld.get((section, key), CURVE)) for section, key in kept},
            **({"identified_yaml_sha256": yaml_digest(written)} if written is not None else {}),
            "delay_written": None if not fitted_delay else {
                "samples": n, "rate_hz": ident.controller_rate, "s": None if n is None else n / ident.controller_rate,
                "fitted_samples": ident.delay_samples(written=False), "max_samples": MAX_DELAY_SAMPLES},
            "held": {"mass_kg": ident.airframe.mass, "rotor_positions_m": ident.airframe.positions.tolist(),
                     "Jzz_kg_m2": float(ident.airframe.inertia[2])},
            "structure": "each rotor's command lags first-order through T_m (after the pure delay, when fitted); "
                         "its thrust is c0 + c1 z + c2 z^2 of the lagged command z"}
