"""The identified config: what an identification sets (:func:`changes`), and a config's YAML text with it written in.

Each function here takes the identification, ``ident``, a :class:`quadctl.identify.results.Identification`;
:mod:`quadctl.identify.results` imports this module (``identified.json`` says what is not written), so the type
is named here, not imported.

:func:`identified_config` edits only the lines it changes, each saying where its value came from, and keeps
the rest of the config (its comments among it); a value that is not plausible leaves the config's line, a
comment above it saying why.
"""

from __future__ import annotations

import re
from decimal import Decimal

from quadctl.artifacts.meta import IDENTIFIED_CONFIG_HEAD
from quadctl.config import parse, yamlio
from quadctl.errors import ConfigError
from quadctl.physics.motors import thrust_curve_problem
from quadctl.present import identify as shown


def changes(ident) -> dict:
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


def written_curve(ident) -> list[float]:
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


def identified_inertia(ident) -> tuple[list, bool]:
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


def identified_config(text: str, ident, name: str, sets=()) -> str:
    """The config's YAML ``text`` with the identified values set, each changed line saying where it came from.

    Only the changed lines move: a key's line (and the comment lines continuing it, and those just above
    it, which spoke of the old value) is replaced in its section, or added at the section's top; a missing
    section is appended. A value that is not plausible
    (:meth:`quadctl.identify.results.Identification.withheld`) leaves the config's line as it is, a comment
    above it saying why. A header names the config it came from, whose
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
