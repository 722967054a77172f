"""The vehicle's numbers beside a flight stack's platform defaults, as sentences
(:func:`quadctl.export.crazyflie_platform.platform_rows`), and a setpoint the flight stack's app cannot follow."""

from __future__ import annotations

import numpy as np

from quadctl.present.cells import apart
from quadctl.text.setpoints import SETPOINT_OPTIONS

AGREE_RTOL = 0.005
"""A number agrees with the platform's when within 0.5 % of it (the platform's own rounding)."""


def platform_sentences(rows, platform, mode: str = "force") -> list[str]:
    """One sentence per number that differs from the platform's (by how much, in % of the
    platform's; in force mode, a maximum rotor thrust above the platform's with the firmware's clip),
    one for a least rotor thrust below the platform's (:func:`least_thrust_sentence`), one for those that
    agree, and what to check when any number of the vehicle differs.

    Parameters
    ----------
    rows : list of (quantity, key, value, firmware value, unit)
    platform : quadctl.export.crazyflie_platform.Platform
    mode : str
        The app's output, ``force`` or ``force-torque`` (``--mode``).
    """
    where = f"{platform.source} at crazyflie-firmware {platform.commit[:12]}"
    differ, agree, floor = [], [], []
    for quantity, key, value, theirs, unit in rows:
        rel = (value - theirs) / theirs
        if abs(rel) <= AGREE_RTOL:
            agree.append(f"{quantity} ({key} = {value:.4g} {unit})")
        elif key == "motors.min_thrust":  # a floor of the firmware's, not a number of the vehicle
            if value < theirs:
                floor.append(least_thrust_sentence(value, platform))
        else:
            clipped = (f"; in force mode the firmware clips each rotor at its {theirs:.4g} {unit}, where the design's "
                       f"saturation puts it at {value:.4g} {unit}"
                       if key == "motors.max_thrust" and value > theirs and mode == "force" else "")
            differ.append(f"{quantity}: {key} = {value:.4g} {unit}, the firmware's {theirs:.4g} {unit} "
                          f"({rel * 100:+.1f} %){clipped}")
    out = [f"differs from the firmware's {platform.name} ({where}): {d}" for d in differ] + floor
    if agree:
        out.append(f"agrees with the firmware's defaults: {', '.join(agree)}")
    if differ:
        out.append("the design flies the config's vehicle, not the firmware's defaults: check that the config's "
                   "numbers are those of the vehicle you fly (`quadctl identify` takes them from its flight log)")
    return out


def least_thrust_sentence(value: float, platform) -> str:
    """What the firmware does below its least rotor thrust
    (:attr:`quadctl.export.crazyflie_platform.Platform.min_thrust`), which the design's ``motors.min_thrust = value``
    (N) lies under."""
    floor = platform.min_thrust
    return (f"the firmware stops a motor asked for less than {floor:.4g} N (THRUST_MIN of {platform.source}; "
            f"{platform.min_thrust_source} gives it no voltage), in either mode, where the design takes a rotor as "
            f"able to give any thrust down to motors.min_thrust = {value:.4g} N: a rotor the design asks for less "
            f"loses all its thrust at once; set motors.min_thrust: {floor:.4g} to keep the design's saturation "
            "above it")


def flight_sentences(flight, platform) -> list[tuple[str, str]]:
    """The configured flight's rotor thrusts against the firmware's limits: a note with the lowest and the
    highest, then a warning for each limit the flight goes past: below
    :attr:`~quadctl.export.crazyflie_platform.Platform.min_thrust` a motor stops, in either mode; above
    :attr:`~quadctl.export.crazyflie_platform.Platform.max_thrust` it is clipped in force mode, and above
    :attr:`~quadctl.export.crazyflie_platform.Platform.full_pwm_thrust` it is capped at full PWM in force-torque mode
    (all four lowered alike), a limit that falls as the battery drains.

    Parameters
    ----------
    flight : quadctl.export.crazyflie_platform.FlightThrusts
    platform : quadctl.export.crazyflie_platform.Platform

    Returns
    -------
    list of (level, sentence)
        ``level`` is ``note`` or ``warning``.
    """
    force = flight.mode == "force"
    (i_lo, lo), (i_hi, hi) = flight.lowest(), flight.highest()
    run = (f"quadctl simulate's run, {float(flight.t[-1]):.3g} s" if flight.ok else
           f"quadctl simulate's run, which stopped at t = {float(flight.t[-1]):.3g} s: {flight.message}")
    full = f"{platform.full_pwm_thrust:.4g} N"
    battery = f"on a full battery ({platform.full_pwm_voltage:g} V)"
    top = (f"clips one above {platform.max_thrust:.4g} N" if force else
           f"caps one at full PWM, lowering all four alike: {full} {battery}, less as it drains (no clip at "
           f"{platform.max_thrust:.4g} N in force-torque mode)")
    out = [("note", f"the configured flight ({run}) asks the firmware's motors for {lo:.4g} N (M{i_lo + 1}) to "
                    f"{hi:.4g} N (M{i_hi + 1}) in {flight.mode} mode: the firmware stops a motor below "
                    f"{platform.min_thrust:.4g} N and {top}")]
    stopped = flight.stopped(platform.min_thrust)
    if stopped.any():
        fix = (f"set motors.min_thrust: {platform.min_thrust:.4g} (the design's saturation, which the app flies, then "
               "asks no less)" if force else
               f"{_to_force_mode(flight, platform, f'motors.min_thrust: {platform.min_thrust:.4g}')} (the app's "
               "saturation then asks no less)")
        motors = ", ".join(f"M{k + 1}" for k in np.flatnonzero(stopped.any(axis=0)))
        out.append(("warning", f"the configured flight asks {motors} for thrusts between 0 and the "
                               f"{platform.min_thrust:.4g} N under which the firmware stops a motor "
                               f"({100 * flight.share_stopped(platform.min_thrust):.3g} % of the run), where the "
                               f"vehicle loses thrust the design counts on; {fix}, or fly gentler gains or offsets"))
    if force and flight.above(platform.max_thrust).any():
        asked, limit = apart(hi, platform.max_thrust)
        out.append(("warning", f"the configured flight asks M{i_hi + 1} for {asked} N, above the "
                               f"{limit} N at which the firmware clips a motor in force mode: some "
                               f"motor is above it {100 * flight.share_above(platform.max_thrust):.3g} % of the run, "
                               "where the vehicle lacks thrust the design counts on; set motors.max_thrust: "
                               f"{platform.max_thrust:.4g} to saturate the design where the firmware does"))
    if not force and flight.above(platform.full_pwm_thrust).any():
        asked, limit = apart(hi, platform.full_pwm_thrust)
        fix = _to_force_mode(flight, platform, f"motors.max_thrust: {platform.max_thrust:.4g}")
        out.append(("warning", f"the configured flight asks M{i_hi + 1} for {asked} N, above the {limit} N full "
                               f"PWM gives a motor {battery}, at which the firmware caps a motor in force-torque "
                               "mode and lowers the other three by as much PWM: some motor is above it "
                               f"{100 * flight.share_above(platform.full_pwm_thrust):.3g} % of the run, where the "
                               f"vehicle lacks thrust and torque the design counts on; {fix} (the app's saturation "
                               "then asks no more), or fly gentler gains or offsets"))
    return out


def _to_force_mode(flight, platform, key: str) -> str:
    """The way from a force-torque flight to force mode, whose saturation is the design's: with the config's
    rotors, export with ``--mode force`` and ``key`` (``motors.name: value``) set; without them (``motors:``,
    which force mode needs), add the firmware's (:meth:`~quadctl.export.crazyflie_platform.Platform.motors_section`)."""
    if flight.rotors:
        return f"export with --mode force and {key}"
    return f"add the rotors force mode needs, {rotors_to_add(platform)}, and export with --mode force"


def rotors_to_add(platform) -> str:
    """The ``motors:`` section to add where force mode finds none: the ``platform``'s
    (:meth:`~quadctl.export.crazyflie_platform.Platform.motors_section`), the vehicle's own numbers where they
    differ. The refusal of force mode without rotors (:func:`quadctl.export.crazyflie.check`) and the warnings that
    send a force-torque flight to force mode (:func:`flight_sentences`) both name it."""
    return f"{platform.motors_section()} (the firmware's; your vehicle's own where they differ)"


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
