"""One identification from logs and a config: the stages run, ``identified.json`` and the identified config."""

from __future__ import annotations

import json
import re
from dataclasses import dataclass

import numpy as np

from quadctl.artifacts.meta import IDENTIFIED_CONFIG_HEAD, metadata
from quadctl.config import parse
from quadctl.config.schema import MAX_DELAY_SAMPLES
from quadctl.errors import LogError
from quadctl.identify import estimate as est
from quadctl.identify import windows as win


@dataclass
class Identification:
    """The stages' fits (``thrust``, ``attitude``, ``yaw``), the refused stages and the logs."""

    logs: list
    fits: dict
    refused: dict
    stage_logs: dict  # stage -> log index
    airframe: est.Airframe
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
        raise LogError(f"--window given {len(texts)} times for {count} log(s); give it once per LOG, in order")
    return [win.parse_window(t) for t in texts]


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
    """
    airframe = est.Airframe.from_config(config)
    p = win.plan(logs, windows)
    grids = {}

    def grid(i):
        if i not in grids:
            grids[i] = est.on_grid(logs[i])
        return grids[i]

    fits = {}
    i, w = p.chosen["thrust"]
    est.require_window(grid(i), w, logs[i].path, "thrust")
    fits["thrust"] = est.fit_thrust(grid(i), w, airframe, delay=delay)
    if "attitude" in p.chosen:
        i, w = p.chosen["attitude"]
        est.require_window(grid(i), w, logs[i].path, "attitude")
        fits["attitude"] = est.fit_attitude(grid(i), w, airframe, fits["thrust"])
    if "yaw" in p.chosen:
        i, w = p.chosen["yaw"]
        est.require_window(grid(i), w, logs[i].path, "yaw")
        fits["yaw"] = est.fit_yaw(grid(i), w, airframe, fits["thrust"], fits.get("attitude"))
    return Identification(logs=list(logs), fits=fits, refused=p.refused,
                          stage_logs={s: c[0] for s, c in p.chosen.items()}, airframe=airframe,
                          config_name=config.name, controller_rate=config.controller.rate)


def payload(ident: Identification, config_label: str, config=None) -> dict:
    """``identified.json``: values, 95 % intervals, units, windows, residuals, the logs' provenance
    (and, given the ``config``, the provenance every quadctl artifact carries)."""
    stages = {}
    for stage, fit in ident.fits.items():
        params = {}
        for k, name in enumerate(fit.names):
            lo, hi = fit.interval(name)
            params[name] = {"value": float(fit.values[k]), "interval95": [lo, hi], "std": float(fit.std[k]),
                            "unit": est.UNITS[name], "meaning": est.MEANING[name]}
        stages[stage] = {
            "log": ident.logs[ident.stage_logs[stage]].path, "windows_s": [list(w) for w in fit.windows],
            "samples": int(fit.t.size), "parameters": params, "residual_rms": fit.rms,
            "residual_unit": "N" if stage == "thrust" else "N m",
            "residual_correlation_s": fit.bandwidth / 2 * float(np.median(np.diff(fit.t))),
            **{k: v for k, v in fit.extra.items()}}

    meta = metadata(config, "identified.json") if config is not None else {}
    fitted_delay = "delay" in ident.fits["thrust"].names
    n = ident.delay_samples()
    return {**meta, "config": config_label, "logs": [log.provenance() for log in ident.logs], "stages": stages,
            "refused": dict(ident.refused),
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
    span = ",".join(f"{a:.4g}:{b:.4g}" for a, b in th.windows)
    lo, hi = th.interval("T_m")
    out[("motors", "time_constant")] = (f"{th.value('T_m'):.4g}", f"s, identified from {src} t {span} s "
                                        f"(95 %: {lo:.4g}-{hi:.4g}); the lag of the command, see the README")
    out[("controller", "rotor_lag")] = ("include", "the design models the identified motor lag "
                                         "(ignore: instantaneous rotors, and the lag only in the flown plant)")
    out[("motors", "max_thrust")] = (f"{ident.max_thrust():.4g}", f"N per rotor, the thrust curve at full command, "
                                     f"identified from {src} t {span} s")
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
        span_a = ",".join(f"{a:.4g}:{b:.4g}" for a, b in att.windows)
        jzz = ("Jzz lowered to Jxx + Jyy (the config's Jzz was above it, which no rigid body allows; a log gives "
               "Jzz only over the torque coefficient)") if lowered else "Jzz kept"
        out[("vehicle", "inertia")] = (
            "[" + ", ".join(f"{v:.4g}" for v in inertia) + "]",
            f"kg m^2, Jxx Jyy identified from {src_a} t {span_a} s with this config's rotor positions; {jzz}")
    if "yaw" in ident.fits:
        yaw = ident.fits["yaw"]
        src_y = ident.logs[ident.stage_logs["yaw"]].name
        span_y = ",".join(f"{a:.4g}:{b:.4g}" for a, b in yaw.windows)
        k_m = yaw.value("k_m") * inertia[2] / ident.airframe.inertia[2]  # the log fixes k_m / Jzz
        out[("motors", "torque_coefficient")] = (
            f"{k_m:.4g}", f"N m per N, identified from {src_y} t {span_y} s (k_m / Jzz, with the Jzz above)")
    return out


def identified_inertia(ident: Identification) -> tuple[list, bool]:
    """``([Jxx, Jyy, Jzz], lowered)``: the identified Jxx and Jyy (the config's without the attitude stage)
    and the config's Jzz, lowered to Jxx + Jyy when above it (the flat body's bound: no rigid body has
    Jzz > Jxx + Jyy, and a yaw log gives Jzz only over the torque coefficient)."""
    inertia = [float(v) for v in ident.airframe.inertia]
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


def identified_config(text: str, ident: Identification, name: str) -> str:
    """The config's YAML ``text`` with the identified values set, each changed line saying where it came from.

    Only the changed lines move: a key's line (and the comment lines continuing it, and those just above
    it, which spoke of the old value) is replaced in its section, or added at the section's top; a missing
    section is appended. A header names the config it came from, whose comments (its sources among them)
    stay, but for an editor's schema line relative to where it lay; its ``description`` says it was
    identified.
    """
    lines = text.splitlines()
    lines = [ln for ln in lines if "yaml-language-server:" not in ln]  # a schema path relative to where it lay
    logs = ", ".join(log.name for log in ident.logs)
    lines = [f"name: {name}" if re.match(r"^name:\s", ln)
             else f"description: {json.dumps(f'{ident.config_name}, identified from {logs}')}"
             if re.match(r"^description:\s+[^|>\s]", ln) else ln for ln in lines]  # (a block scalar stays)
    for (section, key), (value, comment) in changes(ident).items():
        new = f"  {key}: {value}  # {comment}"
        start = next((k for k, ln in enumerate(lines) if re.match(rf"^{section}:\s*(#.*)?$", ln)), None)
        if start is None:
            lines += [f"{section}:", new]
            continue
        end = next((k for k in range(start + 1, len(lines)) if re.match(r"^\S", lines[k])), len(lines))
        at = next((k for k in range(start + 1, end) if re.match(rf"^\s+{key}:", lines[k])), None)
        if at is None:
            lines.insert(start + 1, new)
            continue
        indent = len(lines[at]) - len(lines[at].lstrip())
        drop = at + 1
        while drop < end and _under(lines[drop], indent):
            drop += 1  # the old value's continued comment, or its block (delay:\n    samples: 1)
        above = at
        while above - 1 > start and lines[above - 1].startswith(" " * indent + "#"):
            above -= 1  # the comment just above the old value: its source
        lines[above:drop] = [" " * indent + new.lstrip()]
    head = (f"{IDENTIFIED_CONFIG_HEAD} {logs}: see identified.json. The rest is the config\n"
            f"# {ident.config_name}'s, its comments speaking of its values; each identified value says where it\n"
            "# came from.")
    out = head + "\n" + "\n".join(lines) + "\n"

    parse(out, f"the identified config of {name}")  # what it writes loads (ConfigError otherwise)
    return out
