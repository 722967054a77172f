"""One identification from logs and a config: the stages run, ``identified.json`` and the identified config."""

from __future__ import annotations

import hashlib
import json
import os
import re
from dataclasses import dataclass
from decimal import Decimal

import numpy as np

from quadctl.artifacts.meta import IDENTIFIED_CONFIG_HEAD, metadata
from quadctl.config import parse, yamlio
from quadctl.config.controller_schema import MAX_DELAY_SAMPLES
from quadctl.config.schema import Config
from quadctl.errors import ArgumentTypeError, ArtifactError, ConfigError, LogError
from quadctl.identify import estimate as est
from quadctl.identify import plausibility
from quadctl.identify import windows as win
from quadctl.identify.grid import on_grid, require_window
from quadctl.identify.measurement import MEANING, UNITS, Airframe
from quadctl.physics.motors import thrust_curve_problem
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


def changes(ident: Identification) -> dict:
    """``{(section, key): (yaml value, comment)}``: what the identified config sets, and where each came from."""
    out = {}
    th = ident.fits["thrust"]
    src = ident.logs[ident.stage_logs["thrust"]].name
    span = ",".join(f"{shown.seconds(a)}:{shown.seconds(b)}" for a, b in th.windows)
    lo, hi = th.interval("T_m")
    out[("motors", "time_constant")] = (_number(th.value("T_m")), f"s, identified from {src} t {span} s "
                                        f"(95 %: {lo:.4g}-{hi:.4g}); the lag of the command: docs/guide/identify.md, "
                                        "Which lag")
    out[("controller", "rotor_lag")] = ("include", "the design models the identified motor lag "
                                         "(ignore: instantaneous rotors, and the lag only in the flown plant)")
    curve = written_curve(ident)
    top = float(sum(Decimal(repr(c)) for c in curve))  # the written curve at full command, to its last digit
    where = f"identified from {src} t {span} s"
    problem = thrust_curve_problem(curve)
    if problem is None:
        out[("motors", "max_thrust")] = (yamlio.flow(top), f"N per rotor, the thrust curve at full command "
                                         f"(c0 + c1 + c2), {where}")
        out[("motors", "thrust_curve")] = (yamlio.flow(curve), f"N: c0, c1, c2 of a rotor's thrust c0 + c1 s + c2 "
                                           f"s^2 at the command s (of full), {where}")
    else:  # a curve no rotor has: neither it nor its thrust at full command (the config's pair stays together)
        out[("motors", "max_thrust")] = out[("motors", "thrust_curve")] = (None, "not written: "
                                                                           + shown.curve_withheld(curve))
    n = ident.delay_samples()
    if n is not None:
        d_lo, d_hi = th.interval("delay")
        out[("controller", "delay")] = (
            f"{{samples: {n}}}", f"{n / ident.controller_rate * 1e3:.4g} ms at {ident.controller_rate:g} Hz, the whole "
            f"samples nearest the pure delay of the rotor commands, {th.value('delay') * 1e3:.4g} ms (95 %: "
            f"{d_lo * 1e3:.4g}-{d_hi * 1e3:.4g}), identified from {src} t {span} s with motors.time_constant")
    inertia, lowered = identified_inertia(ident)
    if "attitude" in ident.fits:
        att = ident.fits["attitude"]
        src_a = ident.logs[ident.stage_logs["attitude"]].name
        span_a = ",".join(f"{shown.seconds(a)}:{shown.seconds(b)}" for a, b in att.windows)
        jzz = ("Jzz lowered to Jxx + Jyy (the config's Jzz was above it, which no rigid body allows; a log gives "
               "Jzz only over the torque coefficient)") if lowered else "Jzz kept"
        out[("vehicle", "inertia")] = (
            yamlio.flow([float(f"{v:.4g}") for v in inertia]),
            f"kg m^2, Jxx Jyy identified from {src_a} t {span_a} s with this config's rotor positions; {jzz}")
    if "yaw" in ident.fits:
        yaw = ident.fits["yaw"]
        src_y = ident.logs[ident.stage_logs["yaw"]].name
        span_y = ",".join(f"{shown.seconds(a)}:{shown.seconds(b)}" for a, b in yaw.windows)
        k_m = yaw.value("k_m") * inertia[2] / ident.airframe.inertia[2]  # the log fixes k_m / Jzz
        out[("motors", "torque_coefficient")] = (
            _number(k_m), f"N m per N, identified from {src_y} t {span_y} s (k_m / Jzz, with the Jzz above)")
    found = ident.entries()
    for key, names in ident.withheld().items():
        if key in out:  # not written: the config's value stays, and the comment says why
            out[key] = (None, shown.withheld_comment({n: found[n] for n in names}))
    return out


def written_curve(ident: Identification) -> list[float]:
    """N: the identified ``[c0, c1, c2]`` as the identified config writes them, each to 4 significant digits."""
    th = ident.fits["thrust"]
    return [float(f"{th.value(name):.4g}") for name in CURVE]


CURVE = ("c0", "c1", "c2")
"""The thrust curve's parameters: what ``not_written`` gives for ``motors.thrust_curve`` and ``motors.max_thrust``
when the curve falls (:func:`quadctl.physics.motors.thrust_curve_problem`), plausible as each of them is."""


def _number(value: float) -> str:
    """``value`` to 4 significant digits, as YAML that any reader reads as a float (``1.0e-05``, not ``1e-05``,
    which PyYAML's ``safe_load`` reads as text: :func:`quadctl.config.yamlio.flow`)."""
    return yamlio.flow(float(f"{value:.4g}"))


def identified_inertia(ident: Identification) -> tuple[list, bool]:
    """``([Jxx, Jyy, Jzz], lowered)``: the identified Jxx and Jyy (the config's without the attitude stage, or
    when either is not plausible)
    and the config's Jzz, lowered to Jxx + Jyy when above it (the flat body's bound: no rigid body has
    Jzz > Jxx + Jyy, and a yaw log gives Jzz only over the torque coefficient)."""
    inertia = [float(v) for v in ident.airframe.inertia]
    if ("vehicle", "inertia") in ident.withheld():  # an implausible Jxx or Jyy: the config's inertia stays
        return inertia, False
    if "attitude" in ident.fits:
        inertia[0], inertia[1] = ident.fits["attitude"].value("Jxx"), ident.fits["attitude"].value("Jyy")
    lowered = "attitude" in ident.fits and inertia[2] > inertia[0] + inertia[1]
    if lowered:
        inertia[2] = inertia[0] + inertia[1]
    return inertia, lowered


def _under(line: str, indent: int) -> bool:
    """Whether ``line`` belongs to the key above it at ``indent``: a line of its block (indented deeper), or
    a comment continuing its line's comment (indented past the block's keys)."""
    deeper = len(line) - len(line.lstrip())
    if line.strip().startswith("#"):
        return deeper > indent + 2
    return bool(line.strip()) and deeper > indent


def identified_config(text: str, ident: Identification, name: str, sets=()) -> str:
    """The config's YAML ``text`` with the identified values set, each changed line saying where it came from.

    Only the changed lines move: a key's line (and the comment lines continuing it, and those just above
    it, which spoke of the old value) is replaced in its section, or added at the section's top; a missing
    section is appended. A value that is not plausible (:meth:`Identification.withheld`) leaves the
    config's line as it is, a comment above it saying why. A header names the config it came from, whose
    comments (its sources among them) stay, but for an editor's schema line relative to where it lay; its
    ``description`` says it was identified. The ``--set`` values ``sets`` (``KEY=VALUE`` texts, as the fit
    took them) are put in first, each at its section's key (the whole value there, as YAML flow), saying so.
    """
    lines = text.splitlines()
    lines = [ln for ln in lines if "yaml-language-server:" not in ln]  # a schema path relative to where it lay
    logs = ", ".join(log.name for log in ident.logs)
    for top, key, value, given in _set_values(text, sets):
        if key is None:
            _put_top(lines, top, value, shown.set_comment(given))
        else:
            _put(lines, top, key, yamlio.flow(value), shown.set_comment(given))
    lines = [f"name: {name}" if re.match(r"^name:\s", ln)
             else f"description: {yamlio.flow(f'{ident.config_name}, identified from {logs}')}"
             if re.match(r"^description:\s+[^|>\s]", ln) else ln for ln in lines]  # (a block scalar stays)
    for (section, key), (value, comment) in changes(ident).items():
        if value is None:
            _keep(lines, section, key, comment, after=NEIGHBOURS.get((section, key)))
        else:
            _put(lines, section, key, value, comment, after=NEIGHBOURS.get((section, key)))
    head = (f"{IDENTIFIED_CONFIG_HEAD} {logs}: see identified.json. The rest is the config\n"
            f"# {ident.config_name}'s, its comments speaking of its values; each identified value says where it\n"
            "# came from.")
    out = head + "\n" + "\n".join(lines) + "\n"

    parse(out, f"the identified config of {name}")  # what it writes loads (ConfigError otherwise)
    return out


def _set_values(text: str, sets) -> list[tuple[str, str | None, object, list[str]]]:
    """``(section, key or None, value, the --set texts)`` per key of the config that the ``--set``
    values ``sets`` change: the whole value at ``section.key`` (or at a top-level key) as the config with
    them has it, and the values that changed it."""
    if not sets:
        return []
    from quadctl.config import overrides

    merged = overrides.apply(yamlio.load(text, "the config", ConfigError), [overrides.parse(t) for t in sets])
    found: dict[tuple, list[str]] = {}
    for t in sets:
        keys = overrides.parse(t).keys
        top = keys[0]
        found.setdefault((top, keys[1] if len(keys) > 1 and isinstance(merged.get(top), dict) else None), []).append(t)
    return [(top, key, merged[top] if key is None else merged[top][key], texts) for (top, key), texts in found.items()]


def _section(lines: list[str], section: str):
    """``(start, end)``: the line of ``section:`` and the first line after its block; None when absent."""
    start = next((k for k, ln in enumerate(lines) if re.match(rf"^{section}:\s*(#.*)?$", ln)), None)
    if start is None:
        return None
    end = next((k for k in range(start + 1, len(lines)) if re.match(r"^\S", lines[k])), len(lines))
    return start, end


NEIGHBOURS = {("motors", "thrust_curve"): "max_thrust"}
"""A key the identified config adds, and the key of its section it goes after (when the section has it)."""


def _put(lines: list[str], section: str, key: str, value: str, comment: str, after: str | None = None) -> None:
    """Set ``section.key: value  # comment`` in ``lines``: the key's line (its continued comment, its block and
    the comment just above it, which spoke of the old value) replaced, or added after the key ``after`` (with its
    block) when the section has it, else at the section's top."""
    new = f"  {key}: {value}  # {comment}"
    found = _section(lines, section)
    if found is None:
        lines += [f"{section}:", new]
        return
    start, end = found
    at = next((k for k in range(start + 1, end) if re.match(rf"^\s+{key}:", lines[k])), None)
    if at is None:
        below, indent = _below(lines, start, end, after)
        lines.insert(below, " " * indent + new.lstrip())
        return
    indent = len(lines[at]) - len(lines[at].lstrip())
    drop = at + 1
    while drop < end and _under(lines[drop], indent):
        drop += 1  # the old value's continued comment, or its block (delay:\n    samples: 1)
    above = at
    while above - 1 > start and lines[above - 1].startswith(" " * indent + "#"):
        above -= 1  # the comment just above the old value: its source
    lines[above:drop] = [" " * indent + new.lstrip()]


def _put_top(lines: list[str], key: str, value, comment: str) -> None:
    """Set the top-level ``key`` to ``value`` (a mapping as a block of its keys, each as YAML flow; else one
    line), ``# comment`` after the key: its line and block replaced, or added at the end."""
    if isinstance(value, dict):
        new = [f"{key}:  # {comment}", *(f"  {k}: {yamlio.flow(v)}" for k, v in value.items())]
    else:
        new = [f"{key}: {yamlio.flow(value)}  # {comment}"]
    start = next((k for k, ln in enumerate(lines) if re.match(rf"^{key}:", ln)), None)
    if start is None:
        lines += new
        return
    end = next((k for k in range(start + 1, len(lines)) if re.match(r"^\S", lines[k])), len(lines))
    lines[start:end] = new


def _keep(lines: list[str], section: str, key: str, comment: str, after: str | None = None) -> None:
    """Leave ``section.key`` as the config has it, the comment ``comment`` (why) on the line above it (when the
    config leaves the key out: after the key ``after`` and its block, or at the section's top; at the end when
    it leaves the section out)."""
    found = _section(lines, section)
    if found is None:
        lines.append(f"# {section}.{key}: {comment}")
        return
    start, end = found
    at = next((k for k in range(start + 1, end) if re.match(rf"^\s+{key}:", lines[k])), None)
    if at is None:
        below, indent = _below(lines, start, end, after)
        lines.insert(below, f"{' ' * indent}# {key}: {comment}")
        return
    indent = lines[at][:len(lines[at]) - len(lines[at].lstrip())]
    lines.insert(at, f"{indent}# {key}: {comment}")


def _below(lines: list[str], start: int, end: int, after: str | None) -> tuple[int, int]:
    """``(line, indent)`` where a key the section (``lines[start:end]``) leaves out goes: below the key ``after``
    and its block, at its indent, when the section has it; else the section's first line, indented 2."""
    near = next((k for k in range(start + 1, end) if after and re.match(rf"^\s+{after}:", lines[k])), None)
    if near is None:
        return start + 1, 2
    indent = len(lines[near]) - len(lines[near].lstrip())
    below = near + 1
    while below < end and _under(lines[below], indent):
        below += 1
    return below, indent
