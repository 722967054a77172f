"""What a closed loop is made of, before any CasADi: its structure (:class:`LoopSpec`, what is baked
into its generated code), checked when it is made. The layouts of its constant vector and of its
exogenous row per step, which the structure sizes, are :mod:`quadctl.sim.loop_layout`.

:mod:`quadctl.sim.builder` builds the loop's CasADi functions from a spec; the runners marshal
constants and rows by its layouts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.design.gain_table import VARIABLES
from quadctl.layout import N_INPUTS, N_STATES
from quadctl.sim.loop_layout import N_RATES, PHI_LAYOUT, constant_size, exo_layout
from quadctl.sim.pid import N_LAW_STATES, n_constants

SATURATION_MODES = ("none", "box", "motors")
METHODS = ("rk4", "etdrk4")
"""Integrators of a loop with continuous feedback: classical RK4, or the exponential Runge-Kutta method
of order 4 of Hochbruck and Ostermann (ETDRK4; :data:`~quadctl.sim.loop_layout.PHI_LAYOUT`), exact on the
loop's linear part."""

N_ROTORS = 4
"""Rotor thrust states of a loop with rotor dynamics (one per rotor, N)."""


@dataclass(frozen=True)
class LoopSpec:
    """The structure of a closed loop: what is baked into its generated code.

    Cases that share a spec share one compiled library and run in the same lanes.

    Attributes
    ----------
    pattern : tuple of 48 bool
        Sparsity of the (4, 12) state gain, column-major.
    saturation : {"none", "box", "motors"}
    priority : bool
        Rotor saturation by priority (saturation ``motors`` only; :func:`quadctl.physics.motors.desaturate`): roll
        and pitch torques kept, then thrust, yaw given up first; else each rotor clipped and mixed back.
    integral : tuple of int
        Plant-state index that each controller integrator integrates.
    held : bool
        Sampled controller with a zero-order hold (else continuous feedback).
    noise : bool
        The loop takes the exogenous channels of :data:`~quadctl.sim.loop_layout.EXO_LAYOUT` every step.
    rotors : bool
        Rotor dynamics: the four rotor thrusts are plant states (saturation ``motors`` only).
    delay : int
        Controller samples from measurement to actuation (held loops only): a command buffer.
    lag_model : bool
        The controller propagates a model of the rotors' lag and feeds it back (``Kv``).
    wind : bool
        The loop takes the wind (:data:`~quadctl.sim.loop_layout.WIND_LAYOUT`) every step, after the noise's channels.
    measured : tuple of int
        State indices a Kalman filter measures (LQG); empty: the law measures the full state.
    reference : bool
        The loop takes a reference (:data:`~quadctl.sim.loop_layout.REFERENCE_LAYOUT`) every step, after the
        wind's channels.
    method : {"rk4", "etdrk4"}
        The integrator of ``step`` (continuous feedback), or of ``plant`` between a held loop's samples
        (its linear part the plant's, :meth:`quadctl.sim.loop.ClosedLoop.plant_linear_part`).
    phi_pattern : tuple of bool
        ETDRK4 only: the sparsity of its (nx, nx) constants (:data:`~quadctl.sim.loop_layout.PHI_LAYOUT`), column-major,
        the union over them: entries outside it are baked in as zero (a decoupled design's loop
        keeps its blocks). Empty: dense.
    schedule : tuple
        ``(variable, pieces, columns, degree)`` of a loop that flies a gain schedule
        (:func:`quadctl.sim.builder.scheduled_gain`), else empty: the scheduling variable
        (:data:`quadctl.design.gain_table.VARIABLES`), the number of pieces of the table's piecewise
        cubic, its gain columns (12: the state gain; ``12 + nz``: the integrator gains too) and the
        highest power of ``v`` whose coefficients are not all zero (0: ``nearest``, 1: ``linear``,
        at most 3: ``cubic``; the others are not read). ``pattern`` is then the union of the table's
        state-gain nonzeros.
    law : tuple
        The control law, when it is not LQR (empty): its structure, baked into the code (a PID cascade's,
        :func:`quadctl.sim.pid.structure_of`). The law's states follow the plant's in the loop state; its
        numbers are the ``law`` constants. Such a law is sampled (``held``) and measures the full state
        (no integrators, lag model, filter or gain schedule of an LQR design; ``pattern`` all false).
        Empty (LQR): the generated code, the constants and the cache key are those of a loop without the field.
    filter_order : int
        States per rate of the filter the law runs on the measured body rates (the gyro,
        :mod:`quadctl.linear.filters`): the law takes ``y = c g + d r_m`` in place of each rate ``r_m``;
        ``g`` advances once per sample (held loops), or with the plant (continuous). 0: raw rates.
    diagonal_inertia : bool
        The vehicle's inertia tensor is diagonal: its products ``(Jxy, Jxz, Jyz)`` are baked into the
        code as exact zeros instead of read from ``c``. The same numbers (with zero products every term
        they enter is an exact zero and the determinant of :func:`quadctl.physics.model.dynamics_expression`'s
        solve exactly 1), from fewer operations: 140 an evaluation of the model instead of 212, 7 divisions
        instead of 16 (the continuous loop's RK4 step: 189 fewer of 1 000, 12 fewer divisions of 40).
    """

    pattern: tuple[bool, ...]
    saturation: str = "none"
    priority: bool = False
    integral: tuple[int, ...] = ()
    held: bool = False
    noise: bool = False
    rotors: bool = False
    delay: int = 0
    lag_model: bool = False
    wind: bool = False
    measured: tuple[int, ...] = ()
    reference: bool = False
    method: str = "rk4"
    phi_pattern: tuple[bool, ...] = ()
    schedule: tuple = ()
    law: tuple = ()
    filter_order: int = 0
    diagonal_inertia: bool = False

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if self.schedule:
            _check_schedule(self)
        if self.phi_pattern and len(self.phi_pattern) != self.nx * self.nx:
            raise ValueError(f"phi_pattern: expected {self.nx * self.nx} entries, got {len(self.phi_pattern)}")
        if len(self.pattern) != N_INPUTS * N_STATES:
            raise ValueError(f"pattern: expected {N_INPUTS * N_STATES} entries, got {len(self.pattern)}")
        if self.saturation not in SATURATION_MODES:
            raise ValueError(f"saturation must be one of {SATURATION_MODES}, got {self.saturation!r}")
        if self.priority and self.saturation != "motors":
            raise ValueError("saturation by priority needs the rotors' mixing: saturation 'motors'")
        if self.rotors and self.saturation != "motors":
            raise ValueError("rotor dynamics need the rotors' mixing: saturation 'motors'")
        if self.delay < 0 or (self.delay and not self.held):
            raise ValueError(f"delay: a whole number of samples >= 0 of a held loop, got {self.delay!r}")
        if self.law:
            _check_law(self)

    @property
    def nz(self) -> int:
        """Controller states."""
        return len(self.integral)

    @property
    def n_plant(self) -> int:
        """Plant states ``[x; f]``: the rigid body, and the rotor thrusts of rotor dynamics."""
        return N_STATES + (N_ROTORS if self.rotors else 0)

    @property
    def n_buffer(self) -> int:
        """Entries of the delay's command buffer (4 per sample of delay)."""
        return self.delay * N_INPUTS

    @property
    def buffer_start(self) -> int:
        """Where the delay's command buffer starts in the loop state: its newest command first."""
        return self.n_plant + self.nz + self.n_lag + self.n_law

    @property
    def n_lag(self) -> int:
        """States of the controller's rotor lag model (one per input, or none)."""
        return N_INPUTS if self.lag_model else 0

    @property
    def n_filter(self) -> int:
        """States of the gyro filter (``filter_order`` per body rate)."""
        return N_RATES * self.filter_order

    @property
    def ny(self) -> int:
        """Measurements of the Kalman filter (0: full-state feedback)."""
        return len(self.measured)

    @property
    def n_estimate(self) -> int:
        """Estimator states (the 12 of the estimate, and the gyro filter's it models, with a Kalman filter;
        else none)."""
        return N_STATES + self.n_filter if self.measured else 0

    @property
    def n_law(self) -> int:
        """States of a law other than LQR (:attr:`law`), after the plant's; 0 for LQR."""
        if not self.law:
            return 0

        return N_LAW_STATES

    @property
    def n_law_constants(self) -> int:
        """Constants of a law other than LQR (its ``law`` entry of ``c``); 0 for LQR."""
        if not self.law:
            return 0

        return n_constants(self.law)

    @property
    def nx(self) -> int:
        """Loop states ``[x; f; z; l; s; b; g; xh]`` (``s``: a law's own states, :attr:`n_law`)."""
        return self.n_plant + self.nz + self.n_lag + self.n_law + self.n_buffer + self.n_filter + self.n_estimate

    @property
    def n_exo(self) -> int:
        """Exogenous channels per step."""
        return sum(size for _, size in exo_layout(self.noise, self.wind, self.reference))

    @property
    def schedule_shape(self) -> tuple[int, ...]:
        """``(pieces, columns)`` of the gain schedule's constants (empty: no schedule)."""
        return tuple(self.schedule[1:3])

    @property
    def n_constants(self) -> int:
        """Length of ``c``: the loop's constants, then (ETDRK4) the
        :data:`~quadctl.sim.loop_layout.PHI_LAYOUT` block."""
        return constant_size(self.nz, self.rotors, self.lag_model, self.ny, self.schedule_shape,
                             self.n_law_constants, self.filter_order) + self.n_phi

    @property
    def n_phi(self) -> int:
        """Entries of the ETDRK4 block at the end of ``c`` (0 for RK4)."""
        return len(PHI_LAYOUT) * self.nx * self.nx if self.method == "etdrk4" else 0

    def key(self) -> str:
        """A text naming the spec (part of the compile cache key)."""
        bits = "".join("1" if b else "0" for b in self.pattern)
        sat = self.saturation + ("+priority" if self.priority else "")
        return (f"{bits} sat={sat} int={','.join(map(str, self.integral))} "
                f"held={int(self.held)} noise={int(self.noise)}" + (" rotors=1" if self.rotors else "")
                + (f" delay={self.delay}" if self.delay else "") + (" lag_model=1" if self.lag_model else "")
                + (" wind=1" if self.wind else "")
                + (f" measured={','.join(map(str, self.measured))}" if self.measured else "")
                + (" reference=1" if self.reference else "")
                + (f" method={self.method}" if self.method != "rk4" else "")
                + (" phi=" + "".join("1" if b else "0" for b in self.phi_pattern) if self.phi_pattern else "")
                + (" schedule={}:{}:{}:{}".format(*self.schedule) if self.schedule else "")
                + (" law=" + ":".join(map(str, self.law)) if self.law else "")
                + (f" filter={self.filter_order}" if self.filter_order else "")
                + (" diagonal=1" if self.diagonal_inertia else ""))

    @classmethod
    def of_gain(cls, K, **kwargs) -> LoopSpec:
        """The spec whose pattern is the nonzeros of ``K`` (4, 12)."""
        return cls(tuple(bool(v) for v in (np.asarray(K) != 0).ravel(order="F")), **kwargs)


def _check_schedule(spec: LoopSpec) -> None:
    """Refuse a gain schedule the loop cannot fly (:attr:`LoopSpec.schedule`)."""

    variable, pieces, columns, degree = spec.schedule
    if degree not in (0, 1, 2, 3):
        raise ValueError(f"schedule: the degree of a piecewise cubic is 0 to 3, got {degree!r}")
    if variable not in VARIABLES:
        raise ValueError(f"schedule: unknown scheduling variable {variable!r}: use one of {', '.join(VARIABLES)}")
    if int(pieces) != pieces or pieces < 1:
        raise ValueError(f"schedule: a whole number of pieces >= 1, got {pieces!r}")
    if columns not in (N_STATES, N_STATES + spec.nz):
        raise ValueError(f"schedule: {columns} gain columns; a loop with {spec.nz} integrators schedules "
                         f"{N_STATES} (the state gain) or {N_STATES + spec.nz} (with the integrator gains)")


def _check_law(spec: LoopSpec) -> None:
    """Refuse a law other than LQR in a loop it cannot fly (:attr:`LoopSpec.law`)."""
    if spec.law[0] != "pid":
        raise ValueError(f"law: unknown control law {spec.law[0]!r}: use a PID cascade's structure")
    if not spec.held:
        raise ValueError("law: a PID cascade runs sampled, at its own rate: held=True")
    if spec.saturation != "motors":
        raise ValueError("law: a PID cascade makes rotor commands: saturation 'motors' (the config's motors:)")
    if (spec.nz or spec.lag_model or spec.measured or spec.schedule or spec.filter_order or spec.method != "rk4"
            or any(spec.pattern)):
        raise ValueError("law: a PID cascade has no LQR gain, integrators, lag model, Kalman filter, gyro filter "
                         "of controller.filters (it runs its stack's own) or gain schedule, and runs with RK4")
