"""The schema of what runs on the flight computer: ``controller:`` (its rate, discrete or emulated design,
the rotors' lag, the delay, the law that flies, a flight stack's PID cascade, the sensor filters) and
``estimator:`` (the Kalman filter the loop closes through), with the limits and units of their keys.

:class:`quadctl.config.schema.Config` takes them as its ``controller`` and ``estimator`` sections.
"""

from __future__ import annotations

from typing import Annotated, Literal, Optional, Union

from pydantic import Field, field_validator

from quadctl.config.pid import NAMES
from quadctl.config.schema_types import MAX_NOISE, NonNegative, Number, Positive, Section
from quadctl.layout import SENSOR_GROUPS, STATE_NAMES
from quadctl.text.messages import hint

MAX_RATE = 1e5
"""Hz: ten times the fastest flight controllers' loops (8 to 32 kHz)."""
MAX_DELAY_SAMPLES = 100
"""Controller samples of delay: half a second at 200 Hz, far past any loop that still flies (the
delay margin of a 200 Hz attitude loop is a few samples); each sample is four buffer states."""


class DelaySamples(Section):
    """A delay given in controller samples."""

    samples: Annotated[int, Field(strict=True, ge=0, le=MAX_DELAY_SAMPLES)] = Field(
        description="controller samples from measurement to actuation")


class PidConfig(Section):
    """A flight stack's PID cascade (quadctl.config.pid): a preset of its published defaults, and overrides."""

    preset: Literal["crazyflie", "px4"] = Field(
        "crazyflie", description="crazyflie: controller_pid of bitcraze/crazyflie-firmware (angles in deg, "
        "500 Hz attitude and rate, 100 Hz position and velocity, PWM out); px4: PX4's mc_pos_control, "
        "mc_att_control and mc_rate_control (rad, 400/200/100 Hz, normalized torques out)")
    attitude: Optional[Literal["euler", "px4"]] = Field(
        None, description="the attitude stage: euler, a PID per Euler angle error (the Crazyflie's "
        "attitude_pid_controller); px4, PX4's AttitudeControl (the quaternion error, the thrust axis's first and "
        "the yaw's weighted by att_yaw_weight, a P gain per axis, the reference's yaw rate fed forward, the rate "
        "limits; the crazyflie preset has no yaw weight: set values.att_yaw_weight, 0 holds no heading); absent: "
        "the preset's (crazyflie: euler, px4: px4)")
    values: dict[str, Number] = Field(
        default_factory=dict, description="name -> value in the stack's units, replacing the preset's "
        "(rate_roll_kp, att_roll_kp, vel_xy_kp, pos_z_ki, rate_hz ...: quadctl/config/pid_presets.yaml lists them "
        "with their sources, docs/guide/compare.md's The cascades their units)")

    @field_validator("values")
    @classmethod
    def _known(cls, values: dict) -> dict:

        unknown = sorted(set(values) - set(NAMES))
        if unknown:
            near = hint(unknown[0], NAMES)
            raise ValueError(f"unknown PID value {unknown[0]!r}; " + (near if near.startswith("did you mean") else
                                                                       f"use one of {', '.join(NAMES)}"))
        return values


class LowPassConfig(Section):
    """A low-pass filter: first order, or a second-order Butterworth."""

    cutoff: Positive = Field(description="Hz: the -3 dB frequency; below half the controller's rate")
    order: Literal[1, 2] = Field(2, description=(
        "1: first order (sampled: the PT1 with its exact pole exp(-2 pi cutoff Ts)); 2: Butterworth "
        "(sampled: the biquad of the bilinear transform prewarped at the cutoff, as PX4's LowPassFilter2p)"))


class NotchConfig(Section):
    """A notch filter (sampled: the bilinear biquad prewarped at its centre, as PX4's NotchFilter)."""

    center: Positive = Field(description="Hz: the frequency removed; below half the controller's rate")
    bandwidth: Positive = Field(description="Hz: the width between its -3 dB points (Q = center / bandwidth)")


class FiltersConfig(Section):
    """The filters the flight stack runs on its sensors, in the simulated loop, the margins and the C export.

    The LQR is designed without them (on the rigid body, with the rotors' lag when included): the filter sits
    after the plant, so the LQR of the model with its states, unweighted, gives them zero gain and the others
    the gains they had (no ``design: include`` as for the rotors' lag). The margins and the vehicle's loop
    show what the filters cost. With ``estimator:`` the Kalman filter's
    model includes the gyro filter: it measures the filtered rates and estimates the filter's states too."""

    gyro: Optional[LowPassConfig] = Field(None, description=(
        "low-pass on the gyro: the law takes the filtered body rates p, q, r in place of the measured ones "
        "(PX4: 40 Hz, second order; Crazyflie: 30 Hz); with estimator: the Kalman filter measures the filtered "
        "rates, its model the plant followed by the filter (the gyro's noise taken at the filter's output); "
        "absent: none"))
    notch: Optional[NotchConfig] = Field(None, description=(
        "notch on the gyro, after the low-pass (a frame's resonance or the rotors' frequency); absent: none"))
    d_term: Optional[LowPassConfig] = Field(None, description=(
        "low-pass on the rate derivative of a law with a D term (PX4: 30 Hz); the LQR law has none (its "
        "rate feedback is proportional), so the lqr law does not use it"))


class ControllerConfig(Section):
    """How the controller runs on the flight computer."""

    rate: Optional[Annotated[Positive, Field(le=MAX_RATE)]] = Field(
        None, description="Hz; absent: continuous feedback, as in the report")
    design: Literal["discrete", "continuous"] = Field(
        "discrete", description="with a rate: discrete LQR at that rate (lqrd), or the continuous LQR "
        "run at that rate (emulation)")
    rotor_lag: Literal["ignore", "include"] = Field(
        "ignore", description="ignore: the design model's rotors are instantaneous (motors.time_constant lags "
        "the simulated plant only); include: the design model's inputs lag by motors.time_constant, and the "
        "controller feeds back its own model of the lag, propagated from its commands")
    delay: Optional[Union[NonNegative, DelaySamples]] = Field(
        None, description="s (a whole number of samples at the rate) or {samples: n}: from measurement to "
        "actuation; needs a rate; absent: none")
    flies: Literal["lqr", "pid"] = Field(
        "lqr", description="the law that flies: lqr, the LQR design of lqr: (as the report); pid, the PID cascade "
        "of pid: (position P, velocity PID, attitude PID, rate PID, each at its own rate) instead, at its own rate")
    pid: Optional[PidConfig] = Field(
        None, description="the PID cascade flown with flies: pid, and by quadctl compare; absent: the crazyflie "
        "preset")
    filters: Optional[FiltersConfig] = Field(
        None, description="the sensor filters the flight stack runs (gyro low-pass, notch); absent: raw rates")

    def delay_samples(self) -> int:
        """Samples of delay (0 when none); :func:`quadctl.config.checks._check_delay` has checked it is whole."""
        if self.delay is None:
            return 0
        if isinstance(self.delay, DelaySamples):
            return self.delay.samples
        return round(self.delay * self.rate) if self.rate is not None else 0


class EstimatorConfig(Section):
    """A steady-state Kalman filter: the loop closes through its estimate instead of the measured state."""

    measure: Annotated[list[str], Field(min_length=1)] = Field(description=(
        "measured quantities: state names or sensor groups (imu: phi theta psi p q r; baro: pD; "
        "mocap, gps: pN pE pD; flow: u v)"))
    sensor: dict[str, Positive] = Field(default_factory=dict, description=(
        "state name -> standard deviation of its measurement the filter assumes (state units); default "
        "simulation.noise.sensor's; every measured state needs one of the two, > 0"))
    force: Optional[Annotated[list[Annotated[NonNegative, Field(le=MAX_NOISE["force"])]],
                              Field(min_length=3, max_length=3)]] = Field(
        None, description="N, standard deviation of the body force process noise the filter assumes; "
        "default simulation.noise.force")
    torque: Optional[Annotated[list[Annotated[NonNegative, Field(le=MAX_NOISE["torque"])]],
                               Field(min_length=3, max_length=3)]] = Field(
        None, description="N m, standard deviation of the body torque process noise the filter assumes; "
        "default simulation.noise.torque")

    def measured(self) -> tuple[str, ...]:
        """The measured states, in state order (groups expanded)."""
        names = {s for item in self.measure for s in SENSOR_GROUPS.get(item, (item,))}
        return tuple(s for s in STATE_NAMES if s in names)
