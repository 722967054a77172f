"""The vehicle's numbers beside a flight stack's platform defaults, as sentences
(:func:`quadctl.export.crazyflie.platform_rows`)."""

from __future__ import annotations

AGREE_RTOL = 0.005
"""A number agrees with the platform's when within 0.5 % of it (the platform's own rounding)."""


def platform_sentences(rows, platform) -> list[str]:
    """One sentence per number that differs from the platform's (by how much, in % of the
    platform's), one for those that agree, and the cure when any differs.

    Parameters
    ----------
    rows : list of (quantity, key, value, firmware value, unit)
    platform : quadctl.export.crazyflie.Platform
    """
    where = f"{platform.source} at crazyflie-firmware {platform.commit[:12]}"
    differ, agree = [], []
    for quantity, key, value, theirs, unit in rows:
        rel = (value - theirs) / theirs
        if abs(rel) <= AGREE_RTOL:
            agree.append(f"{quantity} ({key} = {value:.4g} {unit})")
        else:
            differ.append(f"{quantity}: {key} = {value:.4g} {unit}, the firmware's {theirs:.4g} {unit} "
                          f"({rel * 100:+.1f} %)")
    out = [f"differs from the firmware's {platform.name} ({where}): {d}" for d in differ]
    if agree:
        out.append(f"agrees with the firmware's defaults: {', '.join(agree)}")
    if differ:
        out.append("the design flies the config's vehicle, not the firmware's: identify the vehicle you fly from "
                   "a flight log (`quadctl identify`) and design on the identified config")
    return out
