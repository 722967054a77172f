"""The exported controller as a Crazyflie out-of-tree controller app.

:func:`sources` writes the app: the exported C controller (in float, taking a reference each sample),
an adapter for the firmware's out-of-tree controller interface (``controller.h``; written from its
documentation, no firmware code in it) with the frames converted (:data:`FRAMES`), the build files
and a README. :func:`check` refuses what the app cannot serve (exit 2); :func:`platform_rows`
compares the vehicle with the firmware's defaults (:data:`FIRMWARE`), and :func:`flight_thrusts` takes the
rotor thrusts the configured flight asks of the firmware, for comparison with those it gives. What the adapter
does at each call is in the docs, docs/guide/export.md ("Into the flight stack: the Crazyflie app").
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from importlib import resources
from string import Template

import numpy as np

from quadctl.config.template import PRESETS
from quadctl.errors import ArgumentError, ConfigError
from quadctl.export import c
from quadctl.export.bundle import Export, law_text, require_export
from quadctl.present.platform import no_setpoint_flyable, rotors_to_add, setpoint_refused
from quadctl.text.escape import c_comment
from quadctl.text.setpoints import SETPOINT_NEEDS as NEEDS
from quadctl.version import __version__

LOOP_HZ = 1000
"""The firmware's stabilizer loop (``RATE_MAIN_LOOP`` in ``stabilizer_types.h``): the controller is
called at this rate."""
SETPOINTS = tuple(NEEDS)
"""What the app follows (in the order :func:`default_setpoint` tries them): ``position`` (x, y, z and
yaw held where the commander says, the high-level commander's go-to), ``velocity`` (the hover
setpoint: vx, vy, z (or vz) and yaw rate)."""
MODES = ("force", "force-torque")
"""The firmware's ``control_t`` modes the app can write."""
NUMBERING = ("front_right", "rear_right", "rear_left", "front_left")
"""The firmware's motors M1-M4 (quad-X): the numbering the app writes ``normalizedForces`` in."""
SPINS = (1.0, -1.0, 1.0, -1.0)
"""Their yaw reaction signs (+1: counter-clockwise seen from above): M1 and M3 counter-clockwise."""


@dataclass(frozen=True)
class Platform:
    """The firmware platform defaults the app is compared with (:data:`FIRMWARE` names each one's macro).

    ``vmotor2thrust`` holds the fit's coefficients, constant term first (N, N/V, N/V², N/V³); the thrust full
    PWM gives, :attr:`full_pwm_thrust`, is computed from them at :attr:`full_pwm_voltage`, never stored beside
    it."""

    name: str
    commit: str
    source: str
    mass: float
    arm_length: float
    max_thrust: float
    min_thrust: float
    vmotor2thrust: tuple[float, float, float, float]
    torque_coefficient: float
    min_thrust_source: str = "src/drivers/src/motors.c motorsCompensateBatteryVoltage"
    full_pwm_voltage: float = 4.2
    full_pwm_source: str = ("src/modules/src/power_distribution_quadrotor.c powerDistributionForceTorque and "
                            "powerDistributionCap, src/drivers/src/motors.c motorsCompensateBatteryVoltage")
    gyro_cutoff: float = 80.0
    gyro_order: int = 2
    gyro_source: str = "src/hal/src/sensors_bmi088_bmp3xx.c GYRO_LPF_CUTOFF_FREQ"

    def gyro_lowpass(self) -> str:
        """The sensor driver's gyro low-pass in words, as :meth:`quadctl.linear.filters.RateFilter.describe` has it."""
        from quadctl.linear.filters import Section

        return Section("lowpass", self.gyro_cutoff, self.gyro_order).describe()

    def gyro_filter(self) -> str:
        """The sensor driver's low-pass of ``sensors->gyro``, as the config's ``controller.filters`` writes it."""
        return f"controller.filters: {{gyro: {{cutoff: {self.gyro_cutoff:g}, order: {self.gyro_order}}}}}"

    def motors_section(self) -> str:
        """The firmware's rotors as the config's ``motors:`` writes them: the section force mode needs
        (:func:`check`), at the platform's arm, thrusts and torque coefficient."""
        return (f"motors: {{layout: x, arm_length: {self.arm_length:g}, max_thrust: {self.max_thrust:g}, "
                f"min_thrust: {self.min_thrust:.4g}, torque_coefficient: {self.torque_coefficient:.4g}}}")

    def thrust_at(self, volts):
        """N: a motor's thrust at ``volts`` (V) on it, by the battery compensation's cubic fit
        (:attr:`vmotor2thrust`)."""
        v = np.asarray(volts, dtype=float)
        return sum(c * v ** k for k, c in enumerate(self.vmotor2thrust))

    @property
    def full_pwm_thrust(self) -> float:
        """N per motor: what full PWM gives at :attr:`full_pwm_voltage`, the fit (:meth:`thrust_at`) there."""
        return float(self.thrust_at(self.full_pwm_voltage))

    def motors(self):
        """The firmware's own mixer as :class:`quadctl.physics.motors.Motors` (x layout, ``ARM_LENGTH``,
        ``THRUST2TORQUE``, its motors M1-M4 in :data:`NUMBERING`): what force-torque mode mixes the law's
        output with."""
        from quadctl.physics.motors import Motors

        return Motors(layout="x", arm_length=self.arm_length, torque_coefficient=self.torque_coefficient,
                      min_thrust=0.0, max_thrust=self.max_thrust, order=NUMBERING, spins=SPINS)


FIRMWARE = Platform(
    name="Crazyflie 2.1+ (the firmware's default propellers)",
    commit="2a18fc299d7b48cf094d26c38a79f33dec64b5d7",
    source="src/platform/interface/platform_defaults_cf2.h",
    mass=0.029,                                   # CF_MASS, kg
    arm_length=0.046,                             # ARM_LENGTH, m
    max_thrust=0.12,                              # THRUST_MAX, N per motor
    min_thrust=0.012817578393224994,              # THRUST_MIN, N per motor (7000 / 65535 of THRUST_MAX)
    vmotor2thrust=(-0.02476537915958403,          # VMOTOR2THRUST0-3, N at V**0..V**3: a motor's thrust
                   0.06523793527519485,           # against its voltage, the battery compensation's fit
                   -0.026792504967750107,
                   0.006776789303971145),
    torque_coefficient=0.0069928948992470565,     # THRUST2TORQUE, m (N m per N)
)
"""bitcraze/crazyflie-firmware at :attr:`Platform.commit` (2026-08-21), :attr:`Platform.source`:
``CF_MASS``, ``ARM_LENGTH``, ``THRUST2TORQUE`` of the default (2.1+) propellers; ``THRUST_MAX`` and
``THRUST_MIN``, the rotor thrusts the battery compensation (on by default, ``CONFIG_ENABLE_THRUST_BAT_COMPENSATED``)
works between: a motor asked for more than ``THRUST_MAX`` is clipped there in force mode
(``powerDistributionForce`` in ``src/modules/src/power_distribution_quadrotor.c`` clips its share to [0, 1]),
one asked for less than ``THRUST_MIN`` gets no voltage at all, in either mode (:attr:`Platform.min_thrust_source`;
the idle thrust that could floor it instead, ``powerDistribution.idleThrust``, is 0 on a Crazyflie 2.x, whose
motors need no arming); ``VMOTOR2THRUST0`` to ``VMOTOR2THRUST3``, the fit of a motor's thrust against its
voltage (:attr:`Platform.vmotor2thrust`), which gives the top of force-torque mode, ``full_pwm_thrust`` (below);
and the second-order low-pass (``lpf2p``, at the 1 kHz sensor rate) the sensor driver runs on the gyro at
``GYRO_LPF_CUTOFF_FREQ`` before it hands ``sensors->gyro`` to any controller, the app's too (the ``crazyflie`` PID
preset's ``gyro_lpf_hz``).

``full_pwm_thrust`` is the top of force-torque mode, which has no clip at ``THRUST_MAX``
(:attr:`Platform.full_pwm_source`): ``powerDistributionForceTorque`` sets a negative share to 0 and scales the
others by ``THRUST_MAX`` to 1/65535 of full PWM, uncapped; the battery compensation
(``src/drivers/src/motors.c`` ``motorsCompensateBatteryVoltage``) turns each thrust into the motor voltage
that gives it, by the inverse of the cubic fit of thrust against motor voltage (``VMOTOR2THRUST0`` to
``VMOTOR2THRUST3`` of :attr:`Platform.source`), and divides it by the battery's low-passed voltage
(``batteryCompensation`` in ``src/modules/src/stabilizer.c``), again uncapped; ``powerDistributionCap`` then
lowers all four motors by what the highest is over full PWM (65535). A motor asked for more than the cubic gives
at the battery's voltage gets full PWM, and the other three lose as much PWM. ``full_pwm_thrust`` is the cubic at
:attr:`Platform.full_pwm_voltage`, a full LiPo's 4.2 V (where the firmware's filter of the battery's voltage
starts): the most full PWM gives at any charge. As the battery drains it gives less: 0.193 N at 3.7 V, 0.132 N at
the 3.2 V the firmware calls a low battery (``DEFAULT_BAT_LOW_VOLTAGE``), ``THRUST_MAX`` at 3.08 V. The
firmware's PWM is an integer: it caps from 65536 on, about 1.3e-5 N above ``full_pwm_thrust``, which the
warnings' four digits do not show."""

ROTOR_LAG = PRESETS["crazyflie"].motors["time_constant"][0]
"""s: the Crazyflie 2.x's rotor lag, as the Crazyflie template of ``quadctl init`` writes it: the time constant
``quadctl identify`` finds in the bundled flight ``log10`` (docs/guide/identify.md; its 95 % interval is
checked to hold this value in tests/identify/test_identify_estimates.py). A design that leaves it out is
told so at export (:func:`lag_sentence`)."""

FRAMES = (
    ("pN, pE, pD", "state->position x, y, z (m, world x forward, y left, z up)", "pN = x, pE = -y, pD = -z"),
    ("u, v, w", "state->velocity (m/s, world) and state->attitudeQuaternion",
     "body velocity = R(q)^T velocity (FLU), then v and w negated"),
    ("phi, theta, psi", "state->attitude roll, pitch, yaw (deg; pitch in the legacy sign, nose up positive)",
     "phi = roll, theta = pitch, psi = -yaw, in rad, psi wrapped into (-pi, pi]"),
    ("p, q, r", "sensors->gyro x, y, z (deg/s, body x forward, y left, z up)", "p = x, q = -y, r = -z, in rad/s"),
)
"""Each conversion the adapter makes: (quadctl states, the firmware's fields, the conversion)."""

APP_FILES = ("Makefile", "Kbuild", "app-config", "README.md", "src/Kbuild", "src/quadctl_app.c",
             "src/quadctl_crazyflie.c", "src/quadctl_crazyflie.h")
"""The app's own files (beside ``src/quadctl_controller.h`` and ``.c``)."""
TEMPLATES = "export/templates/crazyflie"


def quadrants(positions) -> tuple[str, ...]:
    """Where each rotor is, from its body position ``(x, y)`` (FRD, m): ``front_right`` (x > 0, y > 0),
    ``rear_right``, ``rear_left``, ``front_left``; ``on_axis`` for a rotor on the x or y axis (a ``+``
    layout), which no firmware motor is.

    >>> quadrants([[0.03, 0.03], [-0.03, 0.03], [-0.03, -0.03], [0.03, -0.03]])
    ('front_right', 'rear_right', 'rear_left', 'front_left')
    """
    out = []
    for x, y in np.asarray(positions, dtype=float):
        if x == 0.0 or y == 0.0:
            out.append("on_axis")
        else:
            out.append(("front" if x > 0 else "rear") + ("_right" if y > 0 else "_left"))
    return tuple(out)


def divider(rate: float) -> int:
    """Firmware loop calls per controller sample: ``1000 / rate``.

    Raises
    ------
    ConfigError
        ``rate`` does not divide the firmware's 1 kHz loop.
    """
    n = LOOP_HZ / float(rate)
    if n < 1 or abs(n - round(n)) > 1e-9:
        near = [r for r in (1000, 500, 250, 200, 100) if r <= 2 * rate]
        raise ConfigError(f"controller.rate = {rate:g} Hz does not divide the Crazyflie's {LOOP_HZ} Hz stabilizer "
                          f"loop: set controller.rate to a divisor of {LOOP_HZ} (e.g. {near[0] if near else 100})")
    return int(round(n))


def unregulated(exp: Export) -> dict[str, list[str]]:
    """``{setpoint: the states it needs (:data:`NEEDS`) that the partition leaves free}``, for each of
    :data:`SETPOINTS` in order."""
    return {s: [x for x in NEEDS[s] if x not in exp.setup.regulated] for s in SETPOINTS}


def flyable_setpoints(exp: Export) -> tuple[str, ...]:
    """The setpoints (:data:`SETPOINTS`, in order) whose states (:data:`NEEDS`) the partition all regulates."""
    return tuple(s for s, free in unregulated(exp).items() if not free)


def default_setpoint(exp: Export) -> str:
    """The setpoint the app follows when none is asked: the first of :data:`SETPOINTS` the config can
    fly (:func:`flyable_setpoints`: ``position`` when the partition regulates pN, pE, pD and psi,
    ``velocity`` when it leaves the position free, as the bundled ``crazyflie`` does), else
    ``position`` (which :func:`check` refuses, naming what each setpoint needs regulated).

    >>> from quadctl import config, export, setup
    >>> default_setpoint(export.prepare(setup.setup_of(config.load("crazyflie"))))
    'velocity'
    """
    require_export(exp, "default_setpoint")
    return (flyable_setpoints(exp) or SETPOINTS)[0]


def check(exp: Export, setpoint: str | None = None, mode: str = "force") -> None:
    """Refuse what the app cannot serve (:class:`~quadctl.errors.ConfigError`, exit 2).

    Parameters
    ----------
    exp : Export
        Prepared with a rate.
    setpoint : {"position", "velocity"}, optional
        What the commander gives (:data:`SETPOINTS`); default :func:`default_setpoint`.
    mode : {"force", "force-torque"}

    Raises
    ------
    ConfigError
        The rate does not divide 1 kHz; force mode without rotors (``motors:``) or with a rotor
        numbering other than the firmware's; a Kalman filter (``estimator:``; the firmware estimates
        the state); a trim that is not a hover (the commander's setpoints are about a hover); a
        setpoint that needs a state the partition leaves free.
    ArgumentError
        An unknown ``setpoint`` or ``mode``.
    """
    require_export(exp, "check")
    asked, setpoint = setpoint, default_setpoint(exp) if setpoint is None else setpoint
    if setpoint not in SETPOINTS:
        raise ArgumentError(f"setpoint must be one of {SETPOINTS}, got {setpoint!r}")
    if mode not in MODES:
        raise ArgumentError(f"mode must be one of {MODES}, got {mode!r}")
    divider(exp.rate)
    loop = exp.loop
    act = loop.actuators
    if mode == "force":
        if act is None or act.mode != "motors":
            raise ConfigError("motors: is absent: force mode writes each rotor's thrust, so the config needs its "
                              f"rotors: add them, {rotors_to_add(FIRMWARE)}, or export with --mode force-torque")
        motors = act.motors
        where, spins = quadrants(motors.positions()), tuple(float(v) for v in motors.rotor_spins())
        if where != NUMBERING or spins != SPINS:
            turn = ", ".join("ccw" if v > 0 else "cw" for v in spins)
            raise ConfigError(
                f"motors.numbering: rotors 1-4 are {', '.join(where)} spinning {turn}, not the Crazyflie's "
                "motors M1-M4 (front_right, rear_right, rear_left, front_left spinning ccw, cw, ccw, cw): set "
                "motors.layout: x and motors.numbering: crazyflie (and no motors.spin)")
    filt = loop.rate_filter
    if filt is not None and not firmware_gyro_filter(filt):
        raise ConfigError(
            f"controller.filters: {filt.describe()}, but the firmware's sensor driver low-passes the gyro itself "
            f"({FIRMWARE.gyro_lowpass()}, {FIRMWARE.gyro_source}) before the app "
            f"reads it, and the app flies that filter alone: set {FIRMWARE.gyro_filter()}, the filter the vehicle "
            "has, or remove controller.filters")
    if loop.estimator is not None:
        raise ConfigError("estimator: the app takes the firmware's state estimate (its Kalman filter): remove "
                          "estimator: from the config to export the full-state law for the Crazyflie")
    if np.any(np.asarray(loop.x_rate) != 0.0):
        raise ConfigError("trim.velocity_ned is not zero: the commander's setpoints are positions and velocities "
                          "about a hover; trim at velocity_ned: [0, 0, 0]")
    free = unregulated(exp)
    if free[setpoint] and asked is None:  # none asked, and none flyable
        raise ConfigError(no_setpoint_flyable(free))
    if free[setpoint]:
        raise ConfigError(setpoint_refused(setpoint, free[setpoint], flyable_setpoints(exp)))


def firmware_gyro_filter(filt) -> bool:
    """Whether ``filt`` (:class:`quadctl.linear.filters.RateFilter`) is the firmware's sensor driver's gyro
    low-pass (:attr:`Platform.gyro_cutoff`, :attr:`Platform.gyro_order`), alone."""
    return (len(filt.sections) == 1 and filt.sections[0].kind == "lowpass"
            and filt.sections[0].order == FIRMWARE.gyro_order
            and abs(filt.sections[0].frequency - FIRMWARE.gyro_cutoff) <= 1e-9 * FIRMWARE.gyro_cutoff)


def gyro_sentence(exp: Export) -> str | None:
    """What the export says when the design reads raw rates, though the firmware filters the gyro the app reads:
    the margins, the simulation and the comparison with the PID cascade have no filter the vehicle has."""
    require_export(exp, "gyro_sentence")
    if exp.loop.rate_filter is not None:
        return None
    return (f"the firmware low-passes the gyro ({FIRMWARE.gyro_lowpass()}, {FIRMWARE.gyro_source}) before the "
            "app's law reads it, but the config has no controller.filters: its "
            "margins, simulation and comparison read raw rates, which the vehicle does not have; set "
            f"{FIRMWARE.gyro_filter()} to check the design behind the filter (the app leaves it to the firmware)")


def lag_sentence(exp: Export, config: str, sets=()) -> str | None:
    """What the export says when the config has no rotor lag at all (``motors.time_constant``): its design,
    margins and simulation take the rotors as instantaneous, though the Crazyflie's lag (:data:`ROTOR_LAG`)
    is long enough to unsettle a design made without it; ``config`` and ``sets`` are how the user named the
    config (``-c``, each ``--set`` as given), for the command that checks the design exported."""
    require_export(exp, "lag_sentence")
    if exp.setup.rotor_time_constant is not None:
        return None
    check = shlex.join(["quadctl", "margins", "-c", config, *(w for s in sets for w in ("--set", s)),
                        "--set", f"motors.time_constant={ROTOR_LAG:g}"])
    return (f"the config gives the rotors no lag (motors.time_constant), but a Crazyflie's rotors lag about "
            f"{1e3 * ROTOR_LAG:.0f} ms (quadctl identify on its flight logs): check the design on it before you fly, "
            f"{check}, and design with it (controller.rotor_lag: include) if it does not hold")


def law(exp: Export, setpoint: str) -> str:
    """The app's control law in one paragraph (:func:`quadctl.export.bundle.law_text`): the reference is the
    commander's ``setpoint`` setpoints, through the app's adapter, about the hover trim."""
    return law_text(exp.loop, exp.sample_time, reference=True,
                    source=f"the commander's {setpoint} setpoints, through the app's adapter",
                    feedforward="the hover trim's roll, pitch and input")


def platform_rows(exp: Export, platform: Platform = FIRMWARE) -> list[tuple[str, str, float, float, str]]:
    """The vehicle's numbers beside the firmware platform's defaults.

    Returns
    -------
    list of (quantity, config key, config value, firmware value, unit)
        Mass, arm length, maximum and least rotor thrust and torque coefficient (the rotor rows only
        with ``motors:``).
    """
    require_export(exp, "platform_rows")
    setup = exp.setup
    rows = [("mass", "vehicle.mass", float(setup.vehicle.mass), platform.mass, "kg")]
    act = exp.loop.actuators
    if act is not None and act.mode == "motors":
        m = act.motors
        rows += [("arm length", "motors.arm_length", float(m.arm_length), platform.arm_length, "m"),
                 ("maximum rotor thrust", "motors.max_thrust", float(m.max_thrust), platform.max_thrust, "N"),
                 ("least rotor thrust", "motors.min_thrust", float(m.min_thrust), platform.min_thrust, "N"),
                 ("torque coefficient", "motors.torque_coefficient", float(m.torque_coefficient),
                  platform.torque_coefficient, "N m/N")]
    return rows


ZERO_THRUST = 1e-12
"""N: a rotor thrust within this of 0 is the saturation's 0, and within this over a limit is the limit, mixed to
rotors with round-off (a rotor saturated at ``motors.max_thrust = 0.12`` comes out 0.12000000000000002 N)."""


@dataclass(frozen=True)
class FlightThrusts:
    """The rotor thrusts the configured flight asks the firmware for (:func:`flight_thrusts`).

    Attributes
    ----------
    thrusts : (N+1, 4) ndarray
        N: each motor's thrust (M1-M4) at each recorded sample of the run, as the app hands it over:
        ``quadctl_mix``'s in force mode, the firmware's own mix of the law's output in force-torque mode.
    t : (N+1,) ndarray
        s.
    mode : str
        The app's output, ``force`` or ``force-torque``.
    message : str
        How the run ended (:attr:`quadctl.sim.run.SimResult.message`); ``ok`` says it completed.
    ok : bool
        The run completed.
    rotors : bool
        The config has rotors (``motors:``), which force mode needs (:func:`check`).
    """

    thrusts: np.ndarray
    t: np.ndarray
    mode: str
    message: str
    ok: bool
    rotors: bool

    def lowest(self) -> tuple[int, float]:
        """(motor index 0-3, N): the least thrust any motor is asked for."""
        i, k = np.unravel_index(int(np.argmin(self.thrusts)), self.thrusts.shape)
        return int(k), float(self.thrusts[i, k])

    def highest(self) -> tuple[int, float]:
        """(motor index 0-3, N): the most thrust any motor is asked for."""
        i, k = np.unravel_index(int(np.argmax(self.thrusts)), self.thrusts.shape)
        return int(k), float(self.thrusts[i, k])

    def stopped(self, limit: float) -> np.ndarray:
        """(N+1, 4) bool: the thrusts a firmware that stops a motor below ``limit`` (N) does not give, where
        the design asks for some: above 0 and below ``limit``. A thrust of 0 (the saturation's, within the
        mixer's round-off :data:`ZERO_THRUST`) is given as asked."""
        return (self.thrusts > ZERO_THRUST) & (self.thrusts < limit)

    def share_stopped(self, limit: float) -> float:
        """The share of the run's samples in which some motor is asked for a thrust it is not given
        (:meth:`stopped`)."""
        return float(np.mean(np.any(self.stopped(limit), axis=1)))

    def above(self, limit: float) -> np.ndarray:
        """(N+1, 4) bool: the thrusts over ``limit`` (N) by more than the mixer's round-off (:data:`ZERO_THRUST`):
        a rotor the design's saturation holds at the limit asks for the limit."""
        return self.thrusts > limit + ZERO_THRUST

    def share_above(self, limit: float) -> float:
        """The share of the run's samples in which some motor is asked for more than ``limit`` (N) (:meth:`above`)."""
        return float(np.mean(np.any(self.above(limit), axis=1)))

    def summary(self, platform: Platform) -> dict:
        """The flight against ``platform``'s limits, as ``quadctl export --to crazyflie --json`` gives it under
        ``flight`` (docs/guide/export.md lists the keys).

        Returns
        -------
        dict
            ``completed`` (bool); ``lowest``, ``highest`` (N, any motor); ``stopped``, ``above_max``,
            ``above_full_pwm``: the shares of the run's samples (0 to 1) in which some motor is asked for less than
            :attr:`Platform.min_thrust` (:meth:`share_stopped`), more than :attr:`Platform.max_thrust` (force
            mode's clip) or more than :attr:`Platform.full_pwm_thrust` (force-torque mode's cap)
            (:meth:`share_above`). The share of the limit the mode does not have is None: force-torque mode has no
            clip at ``max_thrust``, and force mode clips there, under full PWM.
        """
        force = self.mode == "force"
        return {"completed": self.ok, "lowest": self.lowest()[1], "highest": self.highest()[1],
                "stopped": self.share_stopped(platform.min_thrust),
                "above_max": self.share_above(platform.max_thrust) if force else None,
                "above_full_pwm": None if force else self.share_above(platform.full_pwm_thrust)}


def flight_thrusts(exp: Export, mode: str = "force", platform: Platform = FIRMWARE) -> FlightThrusts | None:
    """Fly the configured run (``quadctl simulate``'s: its initial offset, reference, wind and noise) and
    take each motor's thrust as the app hands it to the firmware.

    In force mode that is the design's own mixer and saturation (``quadctl_mix``, the config's rotors,
    numbered as the firmware's: :func:`check`); in force-torque mode the firmware mixes the law's output
    with its own constants (:meth:`Platform.motors`), and a config without ``motors:`` is covered too.

    Returns
    -------
    FlightThrusts or None
        None in force mode without ``motors:`` (which :func:`check` refuses).
    """
    from quadctl.pipeline import simulation_of

    require_export(exp, "flight_thrusts")
    if mode not in MODES:
        raise ArgumentError(f"mode must be one of {MODES}, got {mode!r}")
    act = exp.loop.actuators
    rotors = act is not None and act.mode == "motors"
    if mode == "force" and not rotors:
        return None
    run = simulation_of(exp.setup, exp.loop)
    u = np.asarray(run.u, dtype=float)
    # force-torque: the firmware gives a motor its mixed share, or nothing when that is negative
    thrusts = act.commands(u) if mode == "force" else np.maximum(u @ platform.motors().mixer().T, 0.0)
    return FlightThrusts(thrusts=thrusts, t=np.asarray(run.t, dtype=float), mode=mode, message=run.message,
                         ok=run.status == "ok", rotors=rotors)


def _mass(exp: Export) -> float:
    return float(exp.setup.vehicle.mass)


def _c_float(v: float) -> str:
    return f"{float(v)!r}f"


def sources(exp: Export, setpoint: str | None = None, mode: str = "force") -> dict[str, str]:
    """The app's files: ``{path relative to the app folder: text}``; ``setpoint`` default
    :func:`default_setpoint`.

    The controller is :func:`quadctl.export.c.sources` with the reference as an input
    (``quadctl_step_ref``): the commander's setpoint is the law's reference.

    Raises
    ------
    ConfigError
        What :func:`check` refuses.
    """

    setpoint = default_setpoint(exp) if setpoint is None else setpoint
    check(exp, setpoint, mode)
    loop = exp.loop
    ctrl = c.sources(exp, reference=True,  # the firmware filters the gyro the adapter reads: once (check)
                     gyro_filtered_by=f"the firmware's sensor driver's ({FIRMWARE.gyro_source})")
    n = divider(exp.rate)
    x_trim = np.asarray(loop.x_trim, dtype=float)
    u_trim = np.asarray(loop.u_trim, dtype=float)
    values = {
        "CONFIG": c_comment(exp.name), "VERSION": __version__, "CONFIG_HASH": exp.config_hash or "not recorded",
        "RATE": f"{float(exp.rate):g}", "DIVIDER": str(n), "LOOP_HZ": str(LOOP_HZ),
        "MODE": mode, "MODE_MACRO": "QUADCTL_CF_FORCE_TORQUE" if mode == "force-torque" else "QUADCTL_CF_FORCE",
        "SETPOINT": setpoint,
        "HOLDS_POSITION": "1" if all(s in exp.setup.regulated for s in ("pN", "pE")) else "0",
        "TRIM_PN": _c_float(x_trim[0]), "TRIM_PE": _c_float(x_trim[1]), "TRIM_PD": _c_float(x_trim[2]),
        "TRIM_PSI": _c_float(x_trim[8]), "TRIM_T": _c_float(u_trim[0]),
        "COMMIT": FIRMWARE.commit, "PLATFORM_SOURCE": FIRMWARE.source,
        "FW_ARM": f"{FIRMWARE.arm_length:g}", "FW_TORQUE": f"{FIRMWARE.torque_coefficient:g}",
        "FW_MAX": f"{FIRMWARE.max_thrust:g}", "MASS": f"{_mass(exp):g}",
    }
    files = {}
    base = resources.files("quadctl").joinpath(TEMPLATES)
    for name in APP_FILES:
        text = base.joinpath(name.replace("/", "__")).read_text(encoding="utf-8")
        files[name] = Template(text).substitute(values)
    for name, text in ctrl.items():
        files[f"src/{name}"] = text
    return files

