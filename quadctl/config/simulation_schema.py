"""The config's ``simulation:`` section: the run (duration, step, integrator, samples kept), the
initial offset, the noise, the wind (steady, gusts, Dryden turbulence), the simulated plant's
differences from the vehicle and the reference flown, with the bounds and units of their keys.
"""

from __future__ import annotations

from typing import Annotated, Literal, Optional, Union

from pydantic import Field

from quadctl.config.schema_types import MAX_NOISE, Matrix, NonNegative, Number, Positive, Section, Vector3
from quadctl.config.vehicle_schema import INERTIA_DESCRIPTION, Drag, Gravity, Mass
from quadctl.metrics import MAX_SAMPLES


class NoiseConfig(Section):
    """Process and sensor noise: zero-mean Gaussian, drawn every ``period`` and held in between."""

    seed: Annotated[int, Field(strict=True, ge=0)] = Field(0, description="random seed; same seed, same run")
    force: Annotated[list[Annotated[NonNegative, Field(le=MAX_NOISE["force"])]], Field(min_length=3, max_length=3)] \
        = Field([0.0, 0.0, 0.0], description="N, standard deviation of the body-frame force disturbance")
    torque: Annotated[list[Annotated[NonNegative, Field(le=MAX_NOISE["torque"])]], Field(min_length=3, max_length=3)] \
        = Field(
        [0.0, 0.0, 0.0], description="N m, standard deviation of the body torque disturbance")
    sensor: dict[str, NonNegative] = Field(
        default_factory=dict, description="state name -> standard deviation of its measurement (state units)")
    period: Optional[Positive] = Field(
        None, description="s between noise samples; default the controller period, or 5 ms if continuous")


MAX_WIND = 50.0
"""m/s per axis of a steady wind or a gust: past hurricane force (33 m/s) and twice the severe
turbulence's 45 kt at 20 ft; larger is a unit slip (km/h, knots)."""
MAX_GUSTS = 100
"""Gusts of one run: a gust every 0.1 s of a 10 s run; more belongs in turbulence."""
MAX_TURBULENCE_SIGMA = 20.0
"""m/s: above the severe low-altitude intensity (4.5 m/s vertical, 9 m/s along the wind at 10 ft)."""
TURBULENCE_LENGTH = (1.0, 1e4)
"""m: turbulence scales from a metre (at the ground) to MIL-HDBK-1797's high-altitude 1750 ft and beyond;
shorter makes the turbulence white at the step, longer a steady wind."""
MAX_WIND_ALTITUDE = 304.8
"""m: the top of the low-altitude Dryden model (1000 ft, MIL-HDBK-1797 §B.4.4.1)."""

WindComponent = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=-MAX_WIND, le=MAX_WIND)]
WindVector = Annotated[list[WindComponent], Field(min_length=3, max_length=3)]


class GustConfig(Section):
    """A 1-cosine gust (MIL-F-8785C §3.7.3.4), in time: rises over ``length``, holds, falls back."""

    start: NonNegative = Field(description="s, when the gust begins")
    length: Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=3600)] = Field(
        description="s to rise from 0 to the amplitude (and to fall back)")
    amplitude: WindVector = Field(description="m/s, the gust's peak wind, NED")
    hold: Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0, le=86_400.0)] = Field(
        0.0, description="s at the amplitude between rise and fall; past the run's end: the specification's gust, "
        "which stays")


class TurbulenceConfig(Section):
    """Dryden turbulence (MIL-HDBK-1797 low altitude): an intensity and altitude, or sigma and length_scale."""

    intensity: Optional[Literal["light", "moderate", "severe"]] = Field(
        None, description="wind at 20 ft of 15, 30 or 45 kt (sigma_w = 0.1 W20); or give sigma and length_scale")
    altitude: Optional[Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=MAX_WIND_ALTITUDE)]] = Field(
        None, description="m above ground for the intensity's scales (at least 10 ft); default the trim's altitude")
    sigma: Optional[Annotated[list[Annotated[NonNegative, Field(le=MAX_TURBULENCE_SIGMA)]],
                              Field(min_length=3, max_length=3)]] = Field(
        None, description="m/s, standard deviations [along the mean wind, across it, down]")
    length_scale: Optional[Annotated[list[Annotated[float, Field(
        strict=True, allow_inf_nan=False, ge=TURBULENCE_LENGTH[0], le=TURBULENCE_LENGTH[1])]],
        Field(min_length=3, max_length=3)]] = Field(
        None, description="m, [L_u, L_v, L_w] of MIL-HDBK-1797's \"2L\" Dryden form (L_v, L_w half of "
        "MIL-F-8785C's)")
    airspeed: Optional[Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, le=100)]] = Field(
        None, description="m/s turning the spatial spectra into time; default the trim's airspeed, at least 1 m/s")
    seed: Annotated[int, Field(strict=True, ge=0)] = Field(0, description="random seed; same seed, same wind")


class WindConfig(Section):
    """Wind: steady, gusts and turbulence, summed; acts through the rotor drag on the air-relative velocity."""

    steady: WindVector = Field([0.0, 0.0, 0.0], description="m/s, the air's velocity over the ground, NED")
    gusts: Annotated[list[GustConfig], Field(max_length=MAX_GUSTS)] = Field(
        default_factory=list, description="1-cosine gusts (MIL-F-8785C)")
    turbulence: Optional[TurbulenceConfig] = Field(None, description="Dryden turbulence; absent: none")


class PlantConfig(Section):
    """The simulated vehicle where it differs from the design model (model mismatch)."""

    mass: Optional[Mass] = Field(None, description="kg")
    gravity: Optional[Gravity] = Field(None, description="m/s^2")
    inertia: Optional[Matrix] = Field(None, description=INERTIA_DESCRIPTION)
    drag: Optional[Annotated[list[Drag], Field(min_length=3, max_length=3)]] = Field(
        None, description="1/(m/s), the Kc diagonal")


class SetpointConfig(Section):
    """A step of the reference at time ``t``: any of position, velocity and yaw (the others continue)."""

    t: NonNegative = Field(description="s, from the start of the run; increasing along the list")
    position: Optional[Vector3] = Field(None, description="m, NED")
    velocity: Optional[Vector3] = Field(None, description="m/s, NED")
    yaw: Optional[Number] = Field(None, description="rad")


class WaypointConfig(Section):
    """A waypoint of a mission, flown to in order."""

    position: Vector3 = Field(description="m, NED")
    yaw: Optional[Number] = Field(None, description="rad; absent: the previous waypoint's (or the trim's)")
    hold: NonNegative = Field(0.0, description="s to stay at the waypoint before the next leg")


class ReferenceConfig(Section):
    """A reference to fly: setpoint steps, or a waypoint mission with its feedforward."""

    setpoints: Optional[list[SetpointConfig]] = Field(
        None, description="steps of position, velocity and yaw at given times")
    waypoints: Optional[list[WaypointConfig]] = Field(None, description="a mission from the trim position, in order")
    speed: Positive = Field(1.0, description="m/s: the peak speed of each leg of a mission")
    tolerance: Positive = Field(0.1, description="m: a waypoint counts as reached within this distance")
    trajectory: Literal["minimum-jerk", "minimum-snap", "step"] = Field(
        "minimum-jerk", description="the shape of each leg (step: the reference jumps to the waypoint)")


ETDRK4_TOLERANCE = 1e-8
"""Default of ``simulation.tolerance``: the error ETDRK4's ``dt: auto`` aims at (state units, about the
final-state error of a 10 s run). Declared here only: the setup resolves an absent tolerance to it, and
the simulation's functions called without a config read it from here."""

class SimulationConfig(Section):
    """Closed-loop simulation settings."""

    duration: Positive = Field(10.0, description="s")
    dt: Union[Literal["auto"], Positive] = Field("auto", description="s, or auto")
    initial_offset: dict[str, Number] = Field(
        default_factory=dict, description="state name -> offset from trim (state units)")
    noise: Optional[NoiseConfig] = Field(None, description="process and sensor noise; absent: none")
    wind: Optional[WindConfig] = Field(None, description="steady wind, gusts and turbulence; absent: still air")
    plant: Optional[PlantConfig] = Field(
        None, description="simulated vehicle parameters that differ from vehicle: (model mismatch)")
    max_samples: Annotated[int, Field(strict=True, ge=2)] = Field(
        MAX_SAMPLES, description="samples kept (every k-th RK4 step and the last) for sim.npz, metrics and plots")
    reference: Optional[ReferenceConfig] = Field(
        None, description="setpoints or waypoints to fly; absent: hold the trim (moving with its velocity)")
    method: Literal["rk4", "etdrk4"] = Field(
        "rk4", description="rk4: classical Runge-Kutta, its step held stable by the fastest loop; etdrk4: "
        "exponential Runge-Kutta (Hochbruck-Ostermann, order 4) exact on the loop's linearization, dt: auto a "
        "graded step schedule (a sampled controller's plant between samples)")
    tolerance: Optional[Annotated[Positive, Field(ge=1e-14, le=1e-2)]] = Field(
        None, description="etdrk4 with dt: auto: the error the step schedule aims at (state units); absent: "
        f"{ETDRK4_TOLERANCE:g}")
