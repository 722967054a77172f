"""What a closed loop is made of, before any CasADi: its structure (:class:`LoopSpec`, what is baked
into its generated code), the layout of its constant vector (:func:`constant_layout`, filled by
:func:`pack_constants` and :func:`fill_constants_stack`) and of its exogenous row per step
(:func:`exo_layout`: noise, wind, a reference's expansions).

:mod:`quadctl.sim.builder` builds the loop's CasADi functions from a spec; the runners marshal
constants and rows by these layouts.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from quadctl.design.gain_table import VARIABLES
from quadctl.layout import N_INPUTS, N_STATES
from quadctl.physics.model import N_DISTURBANCES, N_PARAMS, N_WIND
from quadctl.sim.pid import N_LAW_STATES, n_constants

SATURATION_MODES = ("none", "box", "motors")
METHODS = ("rk4", "etdrk4")
"""Integrators of a loop with continuous feedback: classical RK4, or the exponential Runge-Kutta method
of order 4 of Hochbruck and Ostermann (ETDRK4; :data:`PHI_LAYOUT`), exact on the loop's linear part."""
PHI_LAYOUT: tuple[str, ...] = ("lin", "A21", "A31", "A32", "A41", "A42", "A51", "A52", "A54", "B1", "B4", "B5")
"""The ETDRK4 constants (each (nx, nx), column-major, after the loop's others), for one step ``h`` and
the loop's linear part ``L`` (:func:`quadctl.sim.etdrk4_matrices.phi_constants`), with ``phi_k = phi_k(hL)``
and ``psi_k = phi_k(hL/2)``: ``lin`` = ``L``, the stages' weights ``A21 = h psi1 / 2``,
``A31 = h (psi1 / 2 - psi2)``, ``A32 = h psi2``, ``A41 = h (phi1 - 2 phi2)``, ``A42 = h phi2``,
``A52 = h (psi2 / 2 - phi3 + phi2 / 4 - psi3 / 2)``, ``A54 = h psi2 / 4 - A52``,
``A51 = h psi1 / 2 - 2 A52 - A54``, and the step's ``B1 = h (phi1 - 3 phi2 + 4 phi3)``,
``B4 = h (4 phi3 - phi2)``, ``B5 = h (4 phi2 - 8 phi3)`` (:func:`quadctl.sim.builder.etdrk4`)."""

_BASE_LAYOUT: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("x_ref", (N_STATES,)),             # reference state at t = 0
    ("x_rate", (N_STATES,)),            # reference drift (m/s on positions): x_ref(t) = x_ref + x_rate t
    ("u_trim", (N_INPUTS,)),
    ("K", (N_INPUTS, N_STATES)),        # column-major
    ("params", (N_PARAMS,)),            # Vehicle.vector() of the simulated plant
    ("mix", (N_INPUTS, N_INPUTS)),      # [T, A, E, R] -> actuator commands (motors mode)
    ("mix_inv", (N_INPUTS, N_INPUTS)),  # actuator commands -> [T, A, E, R]
    ("lo", (N_INPUTS,)),                # actuator limits (saturation modes box and motors)
    ("hi", (N_INPUTS,)),
    ("Ts", (1,)),                       # controller period (s): the held integrators' Euler step
)
EXO_LAYOUT: tuple[tuple[str, int], ...] = (
    ("disturbance", N_DISTURBANCES),    # body force (N, 3) and torque (N m, 3) on the plant
    ("sensor", N_STATES),               # added to the state the controller measures (state units)
)
"""Exogenous channels of one step, in order, when the loop has noise."""
N_EXO = sum(size for _, size in EXO_LAYOUT)
WIND_LAYOUT: tuple[tuple[str, int], ...] = (
    ("wind", N_WIND),                   # the air's velocity over the ground, NED (m/s)
)
"""Exogenous channels of one step after the noise's, when the loop has wind."""
REFERENCE_LAYOUT: tuple[tuple[str, int], ...] = (
    ("ref_t", 1),                       # s: the time t_j the expansion is about
    ("ref_x", N_STATES),                # x_ref(t_j)
    ("ref_rate", N_STATES),             # d x_ref / dt at t_j
    ("ref_curvature", N_STATES),        # x_ref(t) = ref_x + s (ref_rate + s ref_curvature / 2), s = t - t_j
    ("ref_u", N_INPUTS),                # u_ref(t_j)
    ("ref_u_rate", N_INPUTS),           # u_ref(t) = ref_u + s ref_u_rate (the feedforward)
    ("step_ref_t", 1),                  # the same five of the expansion in force over the step
    ("step_ref_x", N_STATES),
    ("step_ref_rate", N_STATES),
    ("step_ref_curvature", N_STATES),
    ("step_ref_u", N_INPUTS),
    ("step_ref_u_rate", N_INPUTS),
)
"""Exogenous channels of one step after the wind's, when the loop flies a reference
(:mod:`quadctl.physics.trajectory`): it replaces ``x_ref + x_rate t`` and ``u_trim`` in the law. Two
expansions of the path (:class:`quadctl.physics.reference_rows.FlownReference`): the one in force at the
step's start ``t`` (the law's and the regulated reference's, :func:`quadctl.sim.builder.build`'s ``qc_law`` and
``qc_ref``),
and the one in force over the step (the one its midpoint falls in: every stage of an RK4 or ETDRK4
step). The runners choose them from the tabulated row before each step
(:func:`quadctl.physics.reference_rows.in_force`), so the generated step reads its columns with no
choice in it (a select per column would keep the compiler from vectorizing the lanes); they are
the same expansion but in a row a knot of the path splits."""
N_REFERENCE = sum(size for _, size in REFERENCE_LAYOUT)


def exo_layout(noise: bool, wind: bool, reference: bool = False) -> tuple[tuple[str, int], ...]:
    """The exogenous channels of a loop (name, size), in the order of one step's row."""
    return (EXO_LAYOUT if noise else ()) + (WIND_LAYOUT if wind else ()) + (REFERENCE_LAYOUT if reference else ())


N_ROTORS = 4
"""Rotor thrust states of a loop with rotor dynamics (one per rotor, N)."""
N_RATES = 3
"""Body rates the gyro filter runs on (``p, q, r``, the last three states)."""


def constant_layout(nz: int = 0, rotors: bool = False, lag_model: bool = False, ny: int = 0,
                    schedule: tuple[int, ...] = (), n_law: int = 0,
                    filter_order: int = 0) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """Names and shapes of the constant vector ``c`` of a loop with ``nz`` integrators.

    ``Ki`` (4, nz) is the integrator gain (``u -= Ki z``), ``antiwindup`` (nz, 4) is 1 where
    input ``j``'s saturation freezes integrator ``i``; ``tau`` (s) is the rotors' time constant
    (loops with rotor dynamics); ``Kv`` (4, 4) the gain on the controller's rotor lag model and
    ``tau_model`` (s) the model's time constant (loops with a lag model); ``Ae`` (ne, ne), ``Be``
    (ne, 4) and ``Le`` (ne, ny) are the Kalman filter's model and gain of a loop with ``ny``
    measurements (LQG; ``ne = 12``, or ``12 + 3 filter_order`` in a loop with a gyro filter, which the
    Kalman filter's model then includes). A loop with a gain schedule of ``schedule = (p, m)``, ``p`` pieces of ``m``
    gain columns (:attr:`LoopSpec.schedule`), ends with ``schedule_heading`` (rad, the direction
    ``speed`` is measured along), ``schedule_breaks`` (p + 1,) and ``schedule_coefficients``
    (4, p, 4, m): :class:`quadctl.design.gain_table.GainTable`'s ``breaks`` and ``coefficients``.
    A loop flying a law other than LQR (:attr:`LoopSpec.law`) then has its ``law`` constants (``n_law``
    of them). A loop with a gyro filter of ``filter_order`` states per rate (:attr:`LoopSpec.filter_order`)
    ends with the filter's ``filter_A`` (m, m), ``filter_b``, ``filter_c`` (m,) and ``filter_d`` (1,)
    (:class:`quadctl.linear.filters.StateSpace`, the same on each rate).
    Matrices (and the coefficients) are stored column-major.
    """
    out = _BASE_LAYOUT
    if nz:
        out = out + (("Ki", (N_INPUTS, nz)), ("antiwindup", (nz, N_INPUTS)))
    if rotors:
        out = out + (("tau", (1,)),)
    if lag_model:
        out = out + (("Kv", (N_INPUTS, N_INPUTS)), ("tau_model", (1,)))
    if ny:
        ne = N_STATES + N_RATES * filter_order  # the estimate: x, then the gyro filter's states it models
        out = out + (("Ae", (ne, ne)), ("Be", (ne, N_INPUTS)), ("Le", (ne, ny)))
    if schedule:
        pieces, columns = schedule
        out = out + (("schedule_heading", (1,)), ("schedule_breaks", (pieces + 1,)),
                     ("schedule_coefficients", (4, pieces, N_INPUTS, columns)))
    if n_law:
        out = out + (("law", (n_law,)),)
    if filter_order:
        m = filter_order
        out = out + (("filter_A", (m, m)), ("filter_b", (m,)), ("filter_c", (m,)), ("filter_d", (1,)))
    return out


def constant_size(nz: int = 0, rotors: bool = False, lag_model: bool = False, ny: int = 0,
                  schedule: tuple[int, ...] = (), n_law: int = 0, filter_order: int = 0) -> int:
    """Length of ``c`` for ``nz`` integrators (and rotor dynamics, a lag model, ``ny`` measurements,
    a gain schedule's ``(pieces, columns)``, a law's constants, a gyro filter)."""
    return sum(int(np.prod(shape)) for _, shape in constant_layout(nz, rotors, lag_model, ny, schedule, n_law,
                                                                   filter_order))


def pack_constants(nz: int = 0, rotors: bool = False, lag_model: bool = False, ny: int = 0,
                   schedule: tuple[int, ...] = (), n_law: int = 0, filter_order: int = 0, **values) -> np.ndarray:
    """The ``c`` vector of one case; missing entries are zero (``mix``, ``mix_inv``: identity).

    Raises
    ------
    ValueError
        An entry has the wrong shape, or is not in the layout.
    """
    return fill_constants(_slots(nz, rotors, lag_model, ny, tuple(schedule), n_law, filter_order)[1].copy(), nz,
                          rotors, lag_model, ny, schedule, n_law, filter_order, **values)


def fill_constants(out: np.ndarray, nz: int = 0, rotors: bool = False, lag_model: bool = False, ny: int = 0,
                   schedule: tuple[int, ...] = (), n_law: int = 0, filter_order: int = 0, **values) -> np.ndarray:
    """Write ``values`` into their slots of a ``c`` vector of that layout (in place; returned):
    what :func:`pack_constants` does to the defaults, for a sweep that writes each case's gains
    into a copy of its loop's constants.

    Raises
    ------
    ValueError
        An entry has the wrong shape, or is not in the layout.
    """
    slots = _slots(nz, rotors, lag_model, ny, tuple(schedule), n_law, filter_order)[0]
    for name, value in values.items():
        where, shape = _slot_of(slots, name, values)
        arr = np.asarray(value, dtype=float)
        if arr.size != where.stop - where.start or (arr.ndim > 1 and arr.shape != shape):
            raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
        out[where] = arr.reshape(shape).ravel(order="F")
    return out


def fill_constants_stack(out: np.ndarray, nz: int = 0, rotors: bool = False, lag_model: bool = False, ny: int = 0,
                         schedule: tuple[int, ...] = (), n_law: int = 0, filter_order: int = 0,
                         **values) -> np.ndarray:
    """:func:`fill_constants` of ``N`` cases at once: ``out`` (N, nc), each of ``values`` the ``N``
    cases' entries stacked, (N, *shape) (or (N, size)); in place, returned. Each row is what
    :func:`fill_constants` writes into that row alone.

    Raises
    ------
    ValueError
        An entry has the wrong shape, or is not in the layout.
    """
    slots = _slots(nz, rotors, lag_model, ny, tuple(schedule), n_law, filter_order)[0]
    N = len(out)
    for name, value in values.items():
        where, shape = _slot_of(slots, name, values)
        arr = np.asarray(value, dtype=float)
        size = where.stop - where.start
        if arr.shape[:1] != (N,) or arr[0].size != size or (arr.ndim > 2 and arr.shape[1:] != shape):
            raise ValueError(f"{name}: expected {N} entries of shape {shape}, got {arr.shape}")
        arr = arr.reshape(N, *shape)
        out[:, where] = arr.transpose(0, *range(arr.ndim - 1, 0, -1)).reshape(N, -1)  # each entry column-major
    return out


def _slot_of(slots: dict, name: str, values: dict) -> tuple[slice, tuple[int, ...]]:
    if name not in slots:
        raise ValueError(f"unknown constants: {sorted(set(values) - set(slots))}")
    return slots[name]


@lru_cache(maxsize=16)
def _slots(nz: int, rotors: bool = False, lag_model: bool = False, ny: int = 0, schedule: tuple[int, ...] = (),
           n_law: int = 0, filter_order: int = 0) -> tuple[dict[str, tuple[slice, tuple[int, ...]]], np.ndarray]:
    """Each constant's slice of ``c`` and shape, and ``c`` with every default in."""
    slots, offset = {}, 0
    for name, shape in constant_layout(nz, rotors, lag_model, ny, schedule, n_law, filter_order):
        size = int(np.prod(shape))
        slots[name] = (slice(offset, offset + size), shape)
        offset += size
    template = np.zeros(offset)
    for name in ("mix", "mix_inv"):
        template[slots[name][0]] = np.eye(N_INPUTS).ravel(order="F")
    template.setflags(write=False)
    return slots, template


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
        The loop takes the exogenous channels of :data:`EXO_LAYOUT` every step.
    rotors : bool
        Rotor dynamics: the four rotor thrusts are plant states (saturation ``motors`` only).
    delay : int
        Controller samples from measurement to actuation (held loops only): a command buffer.
    lag_model : bool
        The controller propagates a model of the rotors' lag and feeds it back (``Kv``).
    wind : bool
        The loop takes the wind (:data:`WIND_LAYOUT`) every step, after the noise's channels.
    measured : tuple of int
        State indices a Kalman filter measures (LQG); empty: the law measures the full state.
    reference : bool
        The loop takes a reference (:data:`REFERENCE_LAYOUT`) every step, after the wind's channels.
    method : {"rk4", "etdrk4"}
        The integrator of ``step`` (continuous feedback), or of ``plant`` between a held loop's samples
        (its linear part the plant's, :meth:`quadctl.sim.loop.ClosedLoop.plant_linear_part`).
    phi_pattern : tuple of bool
        ETDRK4 only: the sparsity of its (nx, nx) constants (:data:`PHI_LAYOUT`), column-major,
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
        """Length of ``c``: the loop's constants, then (ETDRK4) the :data:`PHI_LAYOUT` block."""
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
