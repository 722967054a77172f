"""Laws side by side (:mod:`quadctl.compare`): one table, metric by metric, and what the runs shared.

Each reads ``compare.json``'s contents (:func:`quadctl.compare.payload`), so the terminal and the report,
which reads the file a ``quadctl compare`` left in the run folder, say the same.
"""

from __future__ import annotations

from quadctl.artifacts.json_values import decode_floats
from quadctl.compare import METRICS, parse_law
from quadctl.metrics import NOISE_LIMITED_WORDS
from quadctl.present.cells import NBSP, UNSTABLE, Mark, Table, num


def table(data: dict) -> Table:
    """One row per metric, one column per law, of ``compare.json``'s contents ``data`` (an infinite margin
    spelled ``"inf"``, as JSON has it)."""
    laws = decode_floats(data["laws"])
    rows = []
    for name, unit, _ in METRICS:
        label = f"{name.replace('_', ' ')} [{unit}]" if unit != "1" else name.replace("_", " ")
        rows.append((label, *[_cell(law.get(name), name, law) for law in laws]))
    rows.append(("rate [Hz]", *[num(law["rate"]) if law["rate"] else "continuous" for law in laws]))
    rows.append(("run", *[Mark(law["status"], "ok" if law["status"] == "ok" else "fail") for law in laws]))
    how = "LQR: on the coupled model"
    if any(parse_law(law["name"])[0] == "pid" for law in laws):
        how += ("; a PID cascade: lifted to its frame, gain and phase margins exact, the phase margin from its "
                "characteristic loci")
    if any(law.get("closed_loop_stable") is False for law in laws):
        how += f"; {UNSTABLE}: the law's closed loop is unstable, so it has no margin"
    no_rotors = ("rotor use '-': no rotors (the config has no motors:); "
                 if any(law.get("rotor_peak") is None for law in laws) else "")
    noise = (f"settling 'noise': noise-limited: {NOISE_LIMITED_WORDS}; "
             if any(law.get("settling_noise_limited") for law in laws) else "")
    return Table("compare-table", f"{data['config']}: laws side by side over {num(data['duration'])}{NBSP}s",
                 ("metric", *[law["name"] for law in laws]), tuple(rows),
                 caption="the same plant, initial offset, reference, wind and noise for every law; cost on the "
                         "config's LQR weights; settling '-': never within 2 % of the peak position error; "
                         f"{noise}{no_rotors}margins: the least over each law's loops broken at a plant input ({how})")


MARGINS = ("gain_margin", "phase_margin")
"""The metrics an unstable law's loops do not have (``closed_loop_stable`` false: None in ``compare.json``)."""


def _cell(value, name: str, law: dict) -> str:
    if value is None and name in MARGINS and law.get("closed_loop_stable") is False:
        return Mark(UNSTABLE, "fail")
    if value is None and name == "settling" and law.get("settling_noise_limited"):
        return "noise"
    return "-" if value is None else num(value)


def disturbance_sentence(data: dict) -> Mark:
    """Whether every law read the same noise and wind (their rows' digests), from ``compare.json``'s ``data``."""
    seeds = []
    if data["noise_seed"] is not None:
        seeds.append(f"noise seed {data['noise_seed']}")
    if data["wind_seed"] is not None:
        seeds.append(f"turbulence seed {data['wind_seed']}")
    what = " and ".join(seeds) or "no random disturbances"
    if len(data["laws"]) == 1:
        return Mark(f"One law flew, through {what} (rows every {num(data['exo_period'])} s, digest "
                    f"{data['laws'][0]['disturbances'][:12]}).", "ok")
    if data["identical_disturbances"]:
        return Mark(f"Every law flew through the same disturbances ({what}; rows every "
                    f"{num(data['exo_period'])} s, one digest {data['laws'][0]['disturbances'][:12]}).", "ok")
    return Mark("The laws read different disturbance rows: the comparison is not like for like.", "fail")


def gyro_filter_sentence(data: dict) -> Mark | None:
    """A warning when a PID cascade reads the body rates through its stack's gyro low-pass and the LQR design
    reads them raw (``compare.json``'s ``gyro_filter``): a stack's sensor driver filters the gyro for every
    controller (the Crazyflie's, PX4's), so the LQR design's margins and run lack a lag the vehicle has, and
    its margins read better than they are beside the cascade's. None: the laws read their rates alike."""
    laws = data["laws"]
    lqr = next((law for law in laws if law["name"] == "lqr"), None)
    filtered = [law for law in laws if parse_law(law["name"])[0] == "pid" and law.get("gyro_filter")]
    if lqr is None or "gyro_filter" not in lqr or lqr["gyro_filter"] or not filtered:
        return None
    which = "; ".join(f"{law['name']}: {law['gyro_filter']}" for law in filtered)
    cascades = ("the PID cascade reads the body rates behind its flight stack's gyro low-pass" if len(filtered) == 1
                else "the PID cascades read the body rates behind their flight stacks' gyro low-passes")
    hz = filtered[0].get("gyro_lowpass_hz")  # (a compare.json written before the key: the filter in words only)
    fix = f"--set controller.filters.gyro.cutoff={hz:g}" if hz is not None else "controller.filters.gyro"
    return Mark(f"Not like for like: {cascades} ({which}), which a stack's sensor driver runs for every controller, "
                "and the LQR design reads "
                "them raw (no controller.filters), so its margins and run lack that lag. Give the LQR design the "
                f"stack's filter, {fix}, to compare them behind the same one.", "warning")


def free_position_sentence(regulated: tuple[str, ...], laws) -> str | None:
    """A note when the LQR design leaves the horizontal position free; ``laws`` (the compared laws' names,
    ``lqr``, ``pid:<preset>``) say whether PID cascades, which hold it, are beside it."""
    if "pN" in regulated and "pE" in regulated:
        return None
    cascades = [law for law in laws if parse_law(law)[0] == "pid"]
    held = ("" if not cascades else
            ", where the PID cascade's position loop removes its own" if len(cascades) == 1 else
            ", where the PID cascades' position loops remove theirs")
    return ("The LQR design leaves pN and pE free (its guidance subsystem is not regulated): the horizontal part "
            f"of its position error stays or drifts{held}.")


def stale_sentence(made_from: str, current: str) -> Mark:
    """compare.json in the run folder was made from another config than the report's."""
    return Mark(f"compare.json in this run folder was made from another config (hash {made_from[:12]}, this one "
                f"{current[:12]}): run quadctl compare with the same config and settings to show it here.", "warning")
