"""Notices on a valid config: defaults it took and values that are likely a unit slip.

Nothing here refuses a config (that is :mod:`quadctl.config`'s validation); :func:`notices` returns
remarks the command line prints as one ``note`` or ``warning`` line each: the Mambo defaults a
partly given ``vehicle:`` or ``motors:`` section took, a radius of gyration implausible for the
vehicle's size (an inertia in kg mm^2 given as kg m^2), a thrust-to-weight below 1 or absurdly high.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from quadctl.config import Config, inertia_parts, yamlio
from quadctl.errors import ImplausibleConfig
from quadctl.text.messages import show


@dataclass(frozen=True)
class Notice:
    """A remark on a valid config, for the command line to print (one line each).

    Attributes
    ----------
    level : {"note", "warning"}
        ``note``: a default was taken for a key the author may have meant to give;
        ``warning``: the values are physically implausible (a unit slip, most likely).
    key : str
        The key path it is about (``vehicle.inertia``).
    message : str
        One line naming the file, the key, the values and the likely fix.
    """

    level: Literal["note", "warning"]
    key: str
    message: str

    def __str__(self) -> str:
        return self.message


MAMBO_KEYS = {"vehicle": ("mass", "inertia", "drag"),
              "motors": ("arm_length", "thrust_coefficient", "torque_coefficient", "max_thrust")}
"""Keys whose defaults are the report's Parrot Mambo: a section that gives some of them and not
the others flies a mix of two vehicles. (Gravity, the rotor layout and ``min_thrust = 0`` are
generic and not listed.)"""
GYRATION_TO_ARM = (0.1, 2.0)
"""Plausible radius of gyration ``sqrt(J/m)`` (largest axis) as a multiple of the arm length.
All the mass at the rotors gives 1 (about z); motors alone, at the arm ends, are 20 % or more of
a quadcopter's mass, which keeps it above about 0.4; guards and long booms can pass 1. The
report's Mambo has 0.75. A unit slip moves it by 30 times or more (grams for kilograms: /31.6;
g m^2 for kg m^2: x31.6)."""
GYRATION_TO_CUBE_ROOT_MASS = (0.02, 0.6)
"""Plausible ``sqrt(J/m) / m^(1/3)`` (m / kg^(1/3)) when no motors give the arm length: vehicles of
similar build have similar density, so their size grows as the cube root of their mass. The
27 g Crazyflie 2.0 (Jzz = 2.9e-5 kg m^2) and the 68 g Mambo both have 0.11; the band is five
times wider either way, and a mass in grams moves it by 316 times."""
THRUST_TO_WEIGHT = (1.0, 30.0)
"""Plausible ``4 max_thrust / (m g)``: below 1 the vehicle cannot hover; racing quadcopters
reach about 10 to 15. A thrust in grams-force moves it by 102 times."""
INERTIA_SLIPS = (("g m^2", 1e-3), ("kg cm^2", 1e-4), ("kg mm^2", 1e-6), ("g cm^2", 1e-7), ("g mm^2", 1e-9))
"""Units an inertia is often written in, and their value in kg m^2."""
ARM_SLIPS = (("mm", 1e-3), ("cm", 1e-2))
"""Units an arm length is often written in, and their value in m."""
CONTROLLER_RATES = (20.0, 1e5)
"""Hz: plausible ``controller.rate`` of a loop that stabilizes attitude. Flight computers close it
at 100 Hz to 8 kHz (the report's Mambo at 200 Hz, the Crazyflie firmware at 500 Hz, Betaflight's
gyro loop up to 8 kHz); below 20 Hz it is most likely kHz given as Hz (0.2 for 200 Hz). The upper
end is the schema's own bound."""
GRAM = 1e-3
GRAM_FORCE = 9.80665e-3
"""N."""


def notices(cfg: Config, label: str = "<config>") -> list[Notice]:
    """What a valid config does that its author may not mean: defaults taken, implausible physics.

    Parameters
    ----------
    cfg : Config
    label : str
        The file, named in each message.

    Returns
    -------
    list of Notice
        A ``note`` listing the keys of a partly given ``vehicle:`` or ``motors:`` section that took
        the report's Mambo values, then a ``warning`` for each implausible quantity, naming the
        likely unit slip: the radius of gyration ``sqrt(J/m)`` against the arm length (or, with no
        motors, against the mass), the thrust-to-weight ratio, and Jzz below Jxx or Jyy; a ``note``
        when a steady wind is simulated but the trim is in still air (``trim.wind: false``); a
        ``warning`` for a controller rate below any attitude loop's (kHz given as Hz). An
        impossible inertia is refused on load instead (see ``quadctl.config.vehicle_checks.check_inertia``).

    Examples
    --------
    >>> from quadctl.config import bundled, parse
    >>> cfg = parse(bundled("forward").text.replace("mass: 0.068", "mass: 68"), "c.yaml")
    >>> [n.key for n in notices(cfg, "c.yaml")]
    ['vehicle.mass']
    """
    found = _defaults_taken(cfg, label)
    found += _rotor_lag_taken(cfg, label)
    found += _d_term_unused(cfg, label)
    found += _template_changed(cfg, label)
    found += _gyration(cfg, label)
    found += _rotor_positions(cfg, label)
    found += _thrust_to_weight(cfg, label)
    jxx, jyy, jzz = inertia_parts(cfg.vehicle.inertia)[0]
    if jzz < max(jxx, jyy):
        found.append(Notice("warning", "vehicle.inertia", (
            f"{label}: vehicle.inertia = {show(cfg.vehicle.inertia)}: Jzz is below Jxx or Jyy, but a flat "
            f"quadcopter has Jzz about Jxx + Jyy = {jxx + jyy:.3g} kg m^2; is the order [Jxx, Jyy, Jzz]?")))
    found += _controller_rate(cfg, label)
    wind = cfg.simulation.wind
    if wind is not None and any(wind.steady) and not cfg.trim.wind:
        found.append(Notice("note", "trim.wind", (
            f"{label}: simulation.wind.steady = {show(list(wind.steady))} m/s but trim.wind is false: the design is "
            "trimmed in still air and the steady wind pushes the vehicle off it; set trim.wind: true to trim in it")))
    return found


def _defaults_taken(cfg: Config, label: str) -> list[Notice]:
    taken = []
    for section, keys in MAMBO_KEYS.items():
        given = getattr(cfg, section)
        if given is None or section not in cfg.model_fields_set:
            continue
        taken += [(f"{section}.{k}", getattr(given, k)) for k in keys if k not in given.model_fields_set]
    if not taken:
        return []
    values = ", ".join(f"{path} = {show(value)}" for path, value in taken)
    return [Notice("note", taken[0][0], f"{label}: {', '.join(p for p, _ in taken)} not given: using the report's "
                   f"Parrot Mambo values ({values}); give your vehicle's own values")]


def _rotor_lag_taken(cfg: Config, label: str) -> list[Notice]:
    """A rotor time constant with ``controller.rotor_lag`` not given: say which the design took."""
    if cfg.motors is None or cfg.motors.time_constant is None or "rotor_lag" in cfg.controller.model_fields_set:
        return []
    return [Notice("note", "controller.rotor_lag", (
        f"{label}: motors.time_constant = {cfg.motors.time_constant:g} s with controller.rotor_lag not given: the "
        f"design ignores the lag (rotor_lag: ignore, the default) and only the simulated plant has it; set "
        f"rotor_lag: include to design with it, or ignore to silence this"))]


def _template_changed(cfg: Config, label: str) -> list[Notice]:
    """A config started from an ``init`` template whose vehicle's numbers changed: its description may still
    name the template's vehicle."""
    start = cfg.started_from
    if start is None or cfg.vehicle_digest() == start.vehicle_digest:
        return []
    return [Notice("note", "description", (
        f"{label}: started from quadctl init's {start.template} template, and vehicle: or motors: no longer hold "
        f"its numbers: check that description ({cfg.description!r}) names your vehicle, then set "
        f"started_from.vehicle_digest: {yamlio.flow(cfg.vehicle_digest())} (or remove started_from) to silence this"))]


def _d_term_unused(cfg: Config, label: str) -> list[Notice]:
    """``controller.filters.d_term`` on the LQR law, which has no D term: say it does nothing."""
    filters = cfg.controller.filters
    if filters is None or filters.d_term is None:
        return []
    return [Notice("note", "controller.filters.d_term", (
        f"{label}: controller.filters.d_term = {filters.d_term.cutoff:g} Hz: the LQR law has no D term (its rate "
        "feedback is proportional, filtered by controller.filters.gyro), so this filter is not in the loop; "
        "remove it, or filter the gyro instead"))]


def _gyration(cfg: Config, label: str) -> list[Notice]:
    """The radius of gyration against the arm length (or the mass): catches a slip in either."""
    mass, inertia = cfg.vehicle.mass, list(inertia_parts(cfg.vehicle.inertia)[0])
    axis = ("Jxx", "Jyy", "Jzz")[inertia.index(max(inertia))]
    # the arm length is the preset's (motors.positions give the geometry itself: the mass alone is the check)
    arm = cfg.motors.arm_length if cfg.motors is not None and cfg.motors.positions is None else None

    def ratio(m: float, j: float) -> float:
        radius = math.sqrt(j / m)
        return radius / arm if arm is not None else radius / m ** (1 / 3)

    band = GYRATION_TO_ARM if arm is not None else GYRATION_TO_CUBE_ROOT_MASS
    now = ratio(mass, max(inertia))
    if band[0] <= now <= band[1]:
        return []
    radius = math.sqrt(max(inertia) / mass)
    if arm is not None:
        against = (f"{radius / arm:.3g} times motors.arm_length = {arm:g} m (a quadcopter's radius of gyration is "
                   f"{band[0]:g} to {band[1]:g} times its arm length)")
    else:
        cube = mass ** (1 / 3)
        against = (f"a {mass:g} kg quadcopter's is {band[0] * cube:.2g} to {band[1] * cube:.2g} m ({band[0]:g} to "
                   f"{band[1]:g} m times the cube root of the mass in kg)")
    middle = math.sqrt(band[0] * band[1])

    def fits(m: float, j: float) -> float:  # distance (in decades) from the middle of the band, if inside
        r = ratio(m, j)
        return abs(math.log10(r / middle)) if band[0] <= r <= band[1] else math.inf

    if now > band[1]:
        unit, factor = min(INERTIA_SLIPS, key=lambda s: fits(mass, max(inertia) * s[1]))
        key = "vehicle.inertia"
        guess = (f"is it in {unit}? that is {show([float(f'{j * factor:.6g}') for j in inertia])} kg m^2"
                 if math.isfinite(fits(mass, max(inertia) * factor)) else
                 "check its units (kg m^2) and vehicle.mass (kg)")
    else:  # too small a radius for the arm or the mass: a mass in grams, or an arm in mm or cm
        key, guess = "vehicle.mass", ("check the units: vehicle.mass in kg, vehicle.inertia in kg m^2" + (
            ", motors.arm_length in m" if arm is not None else ""))
        # the slip that lands in the middle of the band, the mass's own size (against the inertia) deciding
        # between a mass and an arm: a mass slip also puts sqrt(J/m) / m^(1/3) out of its band
        slips = [(fits(mass * GRAM, max(inertia)), "vehicle.mass",
                  f"is vehicle.mass in grams? {mass:g} g is {mass * GRAM:g} kg")]
        if arm is not None and _within(math.sqrt(max(inertia) / mass) / mass ** (1 / 3), GYRATION_TO_CUBE_ROOT_MASS):
            slips = [(abs(math.log10(radius / (arm * factor) / middle))
                      if _within(radius / (arm * factor), band) else math.inf, "motors.arm_length",
                      f"is motors.arm_length in {unit}? {arm:g} {unit} is {arm * factor:g} m")
                     for unit, factor in ARM_SLIPS]
        distance, slip_key, slip_guess = min(slips, key=lambda s: s[0])
        if math.isfinite(distance):
            key, guess = slip_key, slip_guess
    if key == "motors.arm_length":  # lead with the key that slipped
        return [Notice("warning", key, (
            f"{label}: motors.arm_length = {arm:g} m is {arm / radius:.3g} times the radius of gyration sqrt({axis}/m) "
            f"= {radius:.3g} m of vehicle.inertia = {show(inertia)} kg m^2 and vehicle.mass = {mass:g} kg (a "
            f"quadcopter's arm is {1 / band[1]:g} to {1 / band[0]:g} times its radius of gyration); {guess}"))]
    given = [f"vehicle.inertia = {show(inertia)} kg m^2", f"vehicle.mass = {mass:g} kg"]
    if key == "vehicle.mass":  # lead with the key that slipped
        given.reverse()
    return [Notice("warning", key, (
        f"{label}: {given[0]} with {given[1]} gives a radius of gyration sqrt({axis}/m) = {radius:.3g} m, but "
        f"{against}; {guess}"))]


def _controller_rate(cfg: Config, label: str) -> list[Notice]:
    """A controller rate too slow for an attitude loop: kHz given as Hz, most likely."""
    rate = cfg.controller.rate
    if rate is None or rate >= CONTROLLER_RATES[0]:
        return []
    guess = (f"is controller.rate in kHz? {rate:g} kHz is {rate * 1e3:g} Hz" if _within(rate * 1e3, (100.0, 8e3))
             else "check controller.rate (Hz)")
    return [Notice("warning", "controller.rate", (
        f"{label}: controller.rate = {rate:g} Hz is below {CONTROLLER_RATES[0]:g} Hz, slower than any attitude loop "
        f"a flight computer closes (they run at 100 Hz to 8 kHz); {guess}"))]


def _rotor_positions(cfg: Config, label: str) -> list[Notice]:
    """``motors.positions`` against the radius of gyration, as :func:`_gyration` holds an arm length: rotors
    given in mm or cm. Only when the mass and inertia agree with each other (else that slip is the warning)."""
    if cfg.motors is None or cfg.motors.positions is None:
        return []
    mass, inertia = cfg.vehicle.mass, inertia_parts(cfg.vehicle.inertia)[0]
    radius = math.sqrt(max(inertia) / mass)
    distance = sum(math.hypot(x, y) for x, y in cfg.motors.positions) / len(cfg.motors.positions)
    if not _within(radius / mass ** (1 / 3), GYRATION_TO_CUBE_ROOT_MASS) or _within(radius / distance, GYRATION_TO_ARM):
        return []
    slips = [(unit, factor) for unit, factor in ARM_SLIPS if _within(radius / (distance * factor), GYRATION_TO_ARM)]
    if slips:
        unit, factor = slips[0]
        guess = (f"are motors.positions in {unit}? {distance:.3g} {unit} is {distance * factor:.3g} m: give each "
                 f"rotor's [x, y] in m")
    else:
        guess = "check their units (m), and vehicle.inertia's (kg m^2)"
    return [Notice("warning", "motors.positions", (
        f"{label}: motors.positions puts the rotors {distance:.3g} m from the centre on average, "
        f"{distance / radius:.3g} times the radius of gyration sqrt(J/m) = {radius:.3g} m of vehicle.inertia and "
        f"vehicle.mass (a quadcopter's arm is {1 / GYRATION_TO_ARM[1]:g} to {1 / GYRATION_TO_ARM[0]:g} times its "
        f"radius of gyration); {guess}"))]


def _within(value: float, band: tuple[float, float]) -> bool:
    return band[0] <= value <= band[1]


def _thrust_to_weight(cfg: Config, label: str) -> list[Notice]:
    if cfg.motors is None:
        return []
    mass, g, thrust = cfg.vehicle.mass, cfg.vehicle.gravity, cfg.motors.max_thrust
    ratio = 4 * thrust / (mass * g)
    low, high = THRUST_TO_WEIGHT
    if low <= ratio <= high:
        return []
    # a unit slip is guessed only when the ratio is far outside the band (a slip moves it 10x or more)
    if ratio < low:
        key, what = "motors.max_thrust", "the vehicle cannot hover"
        if ratio < low / 2 and low <= ratio / GRAM <= high:
            key, guess = "vehicle.mass", f"is vehicle.mass in grams? {mass:g} g is {mass * GRAM:g} kg"
        elif ratio < low / 2 and low <= ratio * 9.80665 <= high:
            guess = f"is motors.max_thrust in kilograms-force? {thrust:g} kgf is {thrust * 9.80665:.3g} N"
        else:
            guess = "check motors.max_thrust (N per rotor) and vehicle.mass (kg)"
    else:
        key, what = "motors.max_thrust", (f"a quadcopter's is {low:g} to {high:g}, a racing "
                                        "quadcopter's about 10")
        if ratio > 2 * high and low <= ratio * GRAM_FORCE <= high:
            guess = f"is motors.max_thrust in grams-force? {thrust:g} gf is {thrust * GRAM_FORCE:.3g} N"
        else:
            guess = "check motors.max_thrust (N per rotor) and vehicle.mass (kg)"
    given = [f"motors.max_thrust = {thrust:g} N per rotor", f"vehicle.mass = {mass:g} kg"]
    if key == "vehicle.mass":  # lead with the key that slipped
        given.reverse()
    return [Notice("warning", key, (
        f"{label}: {given[0]} with {given[1]} is a thrust-to-weight ratio of {ratio:.3g} (4 rotors); {what}; {guess}"))]


def require_plausible(cfg: Config, found: list[Notice], label: str = "<config>") -> None:
    """Raise :class:`~quadctl.errors.ImplausibleConfig` (exit 1) when ``found`` holds a warning and the
    config does not say ``allow: [implausible]``: a design for a unit slip is a design for no vehicle.

    The warnings themselves carry the values and the fix; the error names their keys.
    """
    keys = list(dict.fromkeys(n.key for n in found if n.level == "warning"))
    if not keys or "implausible" in cfg.allow:
        return
    many = sum(n.level == "warning" for n in found) > 1
    warnings = "the warnings above give" if many else "the warning above gives"
    raise ImplausibleConfig(
        f"{label}: {', '.join(keys)} implausible ({warnings} "
        "the likely slip and the fix); correct the value, or add `allow: [implausible]` to the config if the "
        "vehicle really is so")
