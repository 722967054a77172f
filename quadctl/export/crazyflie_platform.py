"""The Crazyflie firmware platform the app runs on, and what a flight asks of it.

:data:`FIRMWARE` holds the firmware's platform defaults (:class:`Platform`: mass, arm, rotor thrust limits, the
battery compensation's fit, the gyro low-pass), with its motor numbering (:data:`NUMBERING`, :data:`SPINS`) and
the output modes the app can write (:data:`MODES`). :func:`platform_rows` sets the vehicle's numbers beside the
platform's, and :func:`flight_thrusts` takes the rotor thrusts the configured flight asks of the firmware
(:class:`FlightThrusts`), for comparison with those it gives. The app itself is :mod:`quadctl.export.crazyflie`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.errors import ArgumentError
from quadctl.export.bundle import Export, require_export

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
        (:func:`~quadctl.export.crazyflie.check`), at the platform's arm, thrusts and torque coefficient."""
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
        The config has rotors (``motors:``), which force mode needs (:func:`~quadctl.export.crazyflie.check`).
    """

    thrusts: np.ndarray
    t: np.ndarray
    mode: str
    message: str
    ok: bool
    rotors: bool

    def lowest(self) -> tuple[int, float]:
        """(motor index 0-3, N): the least thrust any motor is asked for (0 within the mixer's round-off
        about it, :data:`ZERO_THRUST`)."""
        i, k = np.unravel_index(int(np.argmin(self.thrusts)), self.thrusts.shape)
        least = float(self.thrusts[i, k])
        return int(k), 0.0 if abs(least) <= ZERO_THRUST else least

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
    numbered as the firmware's: :func:`~quadctl.export.crazyflie.check`); in force-torque mode the firmware
    mixes the law's output with its own constants (:meth:`Platform.motors`), and a config without ``motors:``
    is covered too.

    Returns
    -------
    FlightThrusts or None
        None in force mode without ``motors:`` (which :func:`~quadctl.export.crazyflie.check` refuses).
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
