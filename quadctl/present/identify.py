"""An identification as a table of values with their intervals, and its sentences."""

from __future__ import annotations

from quadctl.present.cells import Table, percent

STAGE_TITLES = {"thrust": "thrust curve and motor lag", "attitude": "roll and pitch inertia",
                "yaw": "yaw torque coefficient"}


def seconds(t: float) -> str:
    """A log time as identify shows it, to the millisecond, trailing zeros dropped, so a window given with
    ``--window`` reads back as typed (15.755, not 15.76).

    >>> seconds(15.755), seconds(8.67), seconds(30.0), seconds(17.49631)
    ('15.755', '8.67', '30', '17.496')
    """
    return f"{t:.3f}".rstrip("0").rstrip(".")


def config_needed() -> str:
    """Why ``identify`` refuses to run without ``-c``, and what to pass."""
    return ("identify needs the config of the vehicle flown (the fit takes its mass, rotor positions and "
            "numbering): add -c NAME or -c FILE, e.g. -c crazyflie for the bundled Crazyflie logs "
            "(`quadctl configs` lists the bundled configs)")


def ulog_corrupt(said: str, topic: str) -> str:
    """A ULog that pyulog found damaged (``said``: its line) and whose ``topic`` it could not read."""
    return f"the ULog is truncated or corrupt (pyulog: {said.rstrip('!.')}), so its {topic} topic cannot be read"


def ulog_read_past_corruption(name: str, said: str) -> str:
    """A ULog that pyulog found damaged but read: its samples may have gaps."""
    return (f"{name}: the ULog is damaged (pyulog: {said.rstrip('!.')}); its topics were read past the damage, "
            "so a window there may lack samples (identify refuses a window with a gap)")


def _cut_where(size: int, at: int | None, declared: int | None, data_at: int | None) -> str:
    """Where a ULog cut short ends (:class:`quadctl.identify.ulog.UlogEnd`'s fields, bytes)."""
    section = "before its data section begins" if data_at is None else f"in its data section (from byte {data_at})"
    if at is None:  # whole messages, but no data section
        return f"the ULog looks cut short: it ends after {size} bytes, {section}"
    if declared is None:
        inside = f"inside the 3-byte header of the message at byte {at}"
    else:
        there = size - at - 3
        inside = (f"inside the message at byte {at}, which declares {declared} bytes and has {there} "
                  f"({declared - there} missing)")
    return f"the ULog looks cut short: it ends after {size} bytes, {inside}, {section}"


def ulog_cut_short(topic: str, **end) -> str:
    """A ULog that ends inside a message or before its data (``end``: where) and so lacks ``topic``: the
    error, with its fix (not a logging profile: the log is incomplete, not configured wrong)."""
    return (f"{_cut_where(**end)}, so it holds no {topic} samples; copy the whole log from the vehicle again "
            "(a full card or a power loss during logging cuts a log short)")


def ulog_read_cut_short(name: str, t_end: float, **end) -> str:
    """A ULog that looks cut short (``end``: where) whose topics were read up to ``t_end`` (s from its first
    sample)."""
    return (f"{name}: {_cut_where(**end)}; its samples end there, at t = {t_end:.4g} s, and identify fits "
            "what is there")


def time_from_start(clock: float) -> str:
    """The reader's phrase for the time it shows and takes: from the log's first sample."""
    return f"t = 0 at the first sample (the log's own clock read {clock:.9g} s there)"


def log_sentences(payload: dict) -> list[str]:
    """Per log: its format, samples and rate, and what the reader converted."""
    return [f"{log['path'].rsplit('/', 1)[-1]}: {log['format']}, {log['samples']} samples at {log['rate_hz']:.0f} Hz, "
            f"t {log['t_start']:.4g} to {log['t_end']:.4g} s; {'; '.join(log['conversions'])}."
            for log in payload["logs"]]


def values_table(payload: dict) -> Table:
    """Every identified value with its 95 % interval, unit, log and window (from ``identified.json``); one
    that fails its rule (not written) marked so beside its interval."""
    rows = []
    for s in payload["stages"].values():
        log = s["log"].rsplit("/", 1)[-1]
        span = ", ".join(f"{seconds(a)}-{seconds(b)}" for a, b in s["windows_s"])
        for name, p in {**s["parameters"], **s.get("derived", {})}.items():
            lo, hi = p["interval95"]
            mark = ("" if p["plausible"] else f" ({NOT_PLAUSIBLE[p['rule']]})" if not p["passes_rule"]
                    else " (at the fit's floor: not written)")
            rows.append((name, f"{p['value']:.4g}", f"{lo:.4g} .. {hi:.4g}{mark}", p["unit"], p["meaning"], log,
                         span))
    return Table(id="identified", title="Identified (95 % intervals from the fit's covariance, residual "
                 "autocorrelation included)", columns=("parameter", "value", "95 % interval", "unit", "meaning",
                                                       "log", "window (s)"), rows=tuple(rows), align="lrrlwll")


def sentences(payload: dict) -> list[str]:
    """The fit's quality and what was refused, one sentence each."""
    out = []
    th = payload["stages"].get("thrust")
    if th:
        share = 1 - th['residual_rms'] / th['rms_without_lag']
        explains = (f"the lag explains {percent(share, places=0)} of the error" if round(share * 100) >= 0 else
                    # a lag the log does not resolve (its rotors follow the commands within a sample or two)
                    f"the lag explains none of the error: it is {percent(-share, places=0)} larger with it")
        out.append(f"Thrust fit: residual {th['residual_rms']:.4g} N RMS with the motor lag, "
                   f"{th['rms_without_lag']:.4g} N without ({explains}).")
    delay = payload.get("delay_written")
    if delay is not None and "controller.delay" not in payload.get("not_written", {}):  # (else: implausible())
        fitted = th["parameters"]["delay"]["value"]
        if delay["samples"] is None and delay.get("fitted_samples") is not None:
            out.append(f"The fitted delay, {fitted * 1e3:.4g} ms, is {delay['fitted_samples']} samples at "
                       f"{delay['rate_hz']:g} Hz, more than controller.delay takes ({delay['max_samples']}): it is "
                       "not written into the identified config (a delay that long is rarely the rotors'; check the "
                       "log's timing).")
        elif delay["samples"] is None:
            out.append(f"The fitted delay, {fitted * 1e3:.4g} ms, is not written into the identified config: "
                       "its controller runs continuous (no controller.rate), and controller.delay counts "
                       "controller samples; set controller.rate (Hz) and controller.delay: {samples: n}, n the "
                       "delay times the rate, rounded.")
        else:
            out.append(f"The fitted delay, {fitted * 1e3:.4g} ms, is written as controller.delay: "
                       f"{{samples: {delay['samples']}}} ({delay['s'] * 1e3:.4g} ms at {delay['rate_hz']:g} Hz, "
                       "the nearest whole samples). Fly the vehicle's own PID cascade on it before you keep it "
                       "(quadctl compare -c on the identified config): a delay the cascade the vehicle flies cannot "
                       "hold is more likely the shape of the rotors' lag than a delay.")
    if th and "motors.thrust_curve" in payload.get("not_written", {}) and "max_thrust" not in payload["implausible"]:
        curve = [float(f"{th['parameters'][n]['value']:.4g}") for n in ("c0", "c1", "c2")]
        out.append(f"Not written, motors.thrust_curve and motors.max_thrust: {curve_withheld(curve)}.")
    for stage, reason in payload["refused"].items():
        out.append(f"Not identified, {STAGE_TITLES[stage]}: {reason}.")
    return out


def curve_withheld(curve) -> str:
    """Why the identified thrust ``curve`` ``[c0, c1, c2]`` (N, as written) and its thrust at full command are not
    written: it falls (:func:`quadctl.physics.motors.thrust_curve_problem`); what stays; the cure."""
    from quadctl.physics.motors import thrust_curve_problem

    problem = thrust_curve_problem(curve) or "rises"
    return (f"the identified curve {[float(c) for c in curve]} N is no rotor's: {problem.split('; ')[0]}; the "
            "config's thrust curve and max_thrust stay (a log whose rotors sweep more of the command range pins "
            "the curve's low end)")


NOT_PLAUSIBLE = {"positive": "reaches zero: not written", "non-negative": "negative: not written",
                 "lifts": "reaches the hover thrust: not written"}
"""What a value that fails its rule (:class:`quadctl.identify.plausibility.Rule`) shows beside its interval."""
RULE_WORDS = {"positive": "a positive quantity whose 95 % interval reaches zero or below",
              "non-negative": "negative, which it cannot be",
              "lifts": "a rotor's thrust at full command whose 95 % interval reaches its share of the weight "
                       "(m g / 4 = {hover_thrust:.4g} N, the config's mass and gravity) or below: four rotors at "
                       "full command may not lift the vehicle"}
"""Why a value that fails its rule is not plausible (formatted with its identified.json entry)."""


def _estimate(name: str, p: dict) -> str:
    """``T_m = 0.008 s (95 %: -0.004 to 0.02 s) is ...``: an identified.json entry ``p`` of ``name``, and why
    it is not plausible: its rule (:data:`RULE_WORDS`), and the fit's floor when it sits there."""
    lo, hi = p["interval95"]
    why = [] if p["passes_rule"] else [RULE_WORDS[p["rule"]].format(**p)]
    if p.get("fit_floor") is not None:
        why.append(f"on the fit's floor ({p['fit_floor']:.4g} {p['unit']}, two samples of the log: the log resolves "
                   "nothing shorter)")
    return f"{name} = {p['value']:.4g} {p['unit']} (95 %: {lo:.4g} to {hi:.4g} {p['unit']}) is {', and '.join(why)}"


def withheld_comment(failed: dict) -> str:
    """The identified config's comment on a key left as the config had it: which estimates are not plausible
    (``failed``: ``{name: identified.json entry}``) and why."""
    said = "; ".join(_estimate(n, p) for n, p in failed.items())
    return f"not identified: {said}; the config's value stays (identified.json: plausible false)"


def implausible(payload: dict, folder) -> str:
    """The one line ``identify`` ends with (exit 1) when an estimate fails its rule: which, what was kept, the cure."""
    found = {}
    for s in payload["stages"].values():
        found.update({**s["parameters"], **s.get("derived", {})})
    failed = {n: p for n, p in found.items() if n in payload["implausible"]}
    said = "; ".join(_estimate(n, p) for n, p in failed.items())
    them = "them" if len(failed) > 1 else "it"
    flagged = [key for key, needs in payload["not_written"].items() if set(needs) & set(failed)]  # (not a curve
    # that falls, which its own sentence names)
    kept = (f"{folder}/identified.yaml leaves {', '.join(flagged)} as the config has "
            f"{'them' if len(flagged) > 1 else 'it'}"
            if flagged else f"{folder}/identified.yaml does not take {them}")
    cures = dict.fromkeys(CURES.get(p["rule"] if not p["passes_rule"] else None, CURE) for p in failed.values())
    return f"not plausible: {said}; {kept} (identified.json flags {them}): {'; or '.join(cures)}"


CURE = "fit a window that excites it more (--window), or a longer log"
"""What to do about an estimate the log does not resolve (its interval reaches past its rule's bound, or it sits
on the fit's floor)."""
CURES = {"lifts": "check vehicle.mass and vehicle.gravity against the vehicle flown (--set vehicle.mass=KG), or fit "
                  "a log that climbs at full command (a curve the log did not fly there is extrapolated)"}
"""What to do about a value that fails its rule, where it is not :data:`CURE`."""


def set_comment(sets) -> str:
    """The identified config's comment on a value ``--set`` gave the fit, on one line (a line break in a
    value shown as ``\\n``: a YAML comment ends at the line's end).

    >>> set_comment(["vehicle.mass=0.03", "description=two\\nlines"])
    'given on the command line (--set vehicle.mass=0.03, --set description=two\\\\nlines)'
    """
    return "given on the command line (" + ", ".join(f"--set {repr(t)[1:-1]}" for t in sets) + ")"


def edited(path, recorded: bool) -> str:
    """Why ``identify`` refuses to write over ``path``: an identified.yaml edited since quadctl wrote it
    (``recorded``: identified.json records the sha256 of what it wrote, and the bytes differ), or one it has
    no record of writing; and the two ways on: keep the file under another name, or discard it."""
    found = ("changed since quadctl identify wrote it (its bytes differ from the sha256 identified.json records)"
             if recorded else "quadctl has no record of writing it (identified.json beside it records no sha256 of it)")
    return (f"{path}: {found}; identify would write over it: to keep it move it to another name "
            f"(mv {path} my-vehicle.yaml) or identify into another folder (-o DIR), or pass --force to write over it")
