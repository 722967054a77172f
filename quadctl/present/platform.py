"""The vehicle's numbers beside a flight stack's platform defaults, as sentences
(:func:`quadctl.export.crazyflie.platform_rows`), and a setpoint the flight stack's app cannot follow."""

from __future__ import annotations

from quadctl.text.setpoints import SETPOINT_OPTIONS

AGREE_RTOL = 0.005
"""A number agrees with the platform's when within 0.5 % of it (the platform's own rounding)."""


def platform_sentences(rows, platform, mode: str = "force") -> list[str]:
    """One sentence per number that differs from the platform's (by how much, in % of the
    platform's; in force mode, a maximum rotor thrust above the platform's with the firmware's clip),
    one for those that agree, and what to check when any differs.

    Parameters
    ----------
    rows : list of (quantity, key, value, firmware value, unit)
    platform : quadctl.export.crazyflie.Platform
    mode : str
        The app's output, ``force`` or ``force-torque`` (``--mode``).
    """
    where = f"{platform.source} at crazyflie-firmware {platform.commit[:12]}"
    differ, agree = [], []
    for quantity, key, value, theirs, unit in rows:
        rel = (value - theirs) / theirs
        if abs(rel) <= AGREE_RTOL:
            agree.append(f"{quantity} ({key} = {value:.4g} {unit})")
        else:
            clipped = (f"; in force mode the firmware clips each rotor at its {theirs:.4g} {unit}, where the design's "
                       f"saturation puts it at {value:.4g} {unit}"
                       if key == "motors.max_thrust" and value > theirs and mode == "force" else "")
            differ.append(f"{quantity}: {key} = {value:.4g} {unit}, the firmware's {theirs:.4g} {unit} "
                          f"({rel * 100:+.1f} %){clipped}")
    out = [f"differs from the firmware's {platform.name} ({where}): {d}" for d in differ]
    if agree:
        out.append(f"agrees with the firmware's defaults: {', '.join(agree)}")
    if differ:
        out.append("the design flies the config's vehicle, not the firmware's defaults: check that the config's "
                   "numbers are those of the vehicle you fly (`quadctl identify` takes them from its flight log)")
    return out




def no_setpoint_flyable(free: dict) -> str:
    """Why the app can follow no setpoint when none was asked: per setpoint the states the partition
    leaves ``free`` ({setpoint: states}).

    >>> no_setpoint_flyable({"position": ["pN", "pE", "pD"], "velocity": ["pD"]}).endswith(
    ...     "--setpoint velocity (the hover setpoint: vx, vy, z, yaw rate) needs pD")
    True
    """
    needs = "; ".join(f"{SETPOINT_OPTIONS[s]} needs {', '.join(states)}" for s, states in free.items())
    return ("subsystems: the partition regulates no setpoint's states, so the app can follow none; regulate "
            f"(add to a subsystem with regulate: true) what one of them needs: {needs}")


def setpoint_refused(setpoint: str, free, flyable) -> str:
    """Why a ``setpoint`` cannot be followed (the partition leaves the states ``free`` unregulated),
    and the way out: regulate them, or the ``flyable`` setpoints' option (none: regulating is the only one).

    >>> setpoint_refused("position", ["pN", "pE"], ["velocity"]).endswith(
    ...     "or export with --setpoint velocity (the hover setpoint: vx, vy, z, yaw rate)")
    True
    >>> "export with" in setpoint_refused("position", ["pN", "pE"], [])  # no setpoint the config flies
    False
    """
    names = ", ".join(free)
    other = [SETPOINT_OPTIONS[s] for s in flyable if s != setpoint]
    fix = f"regulate {names} (add them to a subsystem with regulate: true)"
    if other:
        fix += f" or export with {' or '.join(other)}"
    return (f"subsystems: the partition leaves {names} free (in no regulated subsystem), so a {setpoint} setpoint "
            f"cannot be followed: {fix}")
