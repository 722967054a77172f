"""An identification as a table of values with their intervals, and its sentences."""

from __future__ import annotations

from quadctl.present.cells import Table

STAGE_TITLES = {"thrust": "thrust curve and motor lag", "attitude": "roll and pitch inertia",
                "yaw": "yaw torque coefficient"}


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


def time_from_start(clock: float) -> str:
    """The reader's phrase for the time it shows and takes: from the log's first sample."""
    return f"t = 0 at the first sample (the log's own clock read {clock:.9g} s there)"


def log_sentences(payload: dict) -> list[str]:
    """Per log: its format, samples and rate, and what the reader converted."""
    return [f"{log['path'].rsplit('/', 1)[-1]}: {log['format']}, {log['samples']} samples at {log['rate_hz']:.0f} Hz, "
            f"t {log['t_start']:.4g} to {log['t_end']:.4g} s; {'; '.join(log['conversions'])}."
            for log in payload["logs"]]


def values_table(payload: dict) -> Table:
    """Every identified value with its 95 % interval, unit, log and window (from ``identified.json``)."""
    rows = []
    for s in payload["stages"].values():
        log = s["log"].rsplit("/", 1)[-1]
        span = ", ".join(f"{a:.4g}-{b:.4g}" for a, b in s["windows_s"])
        for name, p in s["parameters"].items():
            lo, hi = p["interval95"]
            rows.append((name, f"{p['value']:.4g}", f"{lo:.4g} .. {hi:.4g}", p["unit"], p["meaning"], log, span))
    return Table(id="identified", title="Identified (95 % intervals from the fit's covariance, residual "
                 "autocorrelation included)", columns=("parameter", "value", "95 % interval", "unit", "meaning",
                                                       "log", "window (s)"), rows=tuple(rows), align="lrrlwll")


def sentences(payload: dict) -> list[str]:
    """The fit's quality and what was refused, one sentence each."""
    out = []
    th = payload["stages"].get("thrust")
    if th:
        out.append(f"Thrust fit: residual {th['residual_rms']:.4g} N RMS with the motor lag, "
                   f"{th['rms_without_lag']:.4g} N without (the lag explains "
                   f"{(1 - th['residual_rms'] / th['rms_without_lag']) * 100:.0f} % of the error).")
    delay = payload.get("delay_written")
    if delay is not None:
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
                       "the nearest whole samples).")
    for stage, reason in payload["refused"].items():
        out.append(f"Not identified, {STAGE_TITLES[stage]}: {reason}.")
    return out
