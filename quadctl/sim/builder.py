"""The one closed-loop definition: CasADi functions of one step (RK4, or ETDRK4) of plant and controller.

Every runner is generated from what this module builds: the compiled one-case loop and the SIMD
lanes (emitted as C by :mod:`quadctl.native.emit`) and the interpreted fallback
(:mod:`quadctl.sim.interpreted`). The plant is :func:`quadctl.physics.model.build_model`; a loop's structure
is a :class:`LoopSpec`, its numbers one constant vector (:func:`constant_layout`), its per-step
inputs an exogenous row (:func:`exo_layout`). The loop's state, law, timings and features are
described in the docs, docs/internals.md ("The closed loop").
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.design.gain_table import VARIABLES, scheduling_value
from quadctl.layout import GRAVITY, N_INPUTS, N_STATES, PRODUCTS, STATE_INDEX
from quadctl.physics.model import N_DISTURBANCES, N_PARAMS, N_WIND, build_model
from quadctl.physics.motors import desaturate
from quadctl.physics.reference_rows import ROW_HALF
from quadctl.sim import pid
from quadctl.sim.pid import N_LAW_STATES, n_constants

ca = lazy_import("casadi")  # loaded on first use: see quadctl._lazy

SATURATION_MODES = ("none", "box", "motors")
METHODS = ("rk4", "etdrk4")
"""Integrators of a loop with continuous feedback: classical RK4, or the exponential Runge-Kutta method
of order 4 of Hochbruck and Ostermann (ETDRK4; :data:`PHI_LAYOUT`), exact on the loop's linear part."""
PHI_LAYOUT: tuple[str, ...] = ("lin", "A21", "A31", "A32", "A41", "A42", "A51", "A52", "A54", "B1", "B4", "B5")
"""The ETDRK4 constants (each (nx, nx), column-major, after the loop's others), for one step ``h`` and
the loop's linear part ``L`` (:func:`quadctl.sim.etdrk4_plan.phi_constants`), with ``phi_k = phi_k(hL)``
and ``psi_k = phi_k(hL/2)``: ``lin`` = ``L``, the stages' weights ``A21 = h psi1 / 2``,
``A31 = h (psi1 / 2 - psi2)``, ``A32 = h psi2``, ``A41 = h (phi1 - 2 phi2)``, ``A42 = h phi2``,
``A52 = h (psi2 / 2 - phi3 + phi2 / 4 - psi3 / 2)``, ``A54 = h psi2 / 4 - A52``,
``A51 = h psi1 / 2 - 2 A52 - A54``, and the step's ``B1 = h (phi1 - 3 phi2 + 4 phi3)``,
``B4 = h (4 phi3 - phi2)``, ``B5 = h (4 phi2 - 8 phi3)`` (:func:`etdrk4`)."""
ANTIWINDUP_TOL = 1e-10
"""An input counts as saturated when clipping changed it by more than this (N or N m): far above
the round-off of mixing and unmixing (~1e-15), far below any clip that matters."""

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
step's start ``t`` (the law's and the regulated reference's, :func:`build`'s ``qc_law`` and ``qc_ref``),
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
        (:func:`scheduled_gain`), else empty: the scheduling variable
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


_PN, _PE, _PSI, _P = STATE_INDEX["pN"], STATE_INDEX["pE"], STATE_INDEX["psi"], STATE_INDEX["p"]


def wrap_angle(angle, lib=np):
    """``angle`` (rad) wrapped into ``(-pi, pi]``: ``angle + 2 pi floor((pi - angle) / (2 pi))``, so
    an angle already there is returned bit for bit (``+ 0``), however many turns it is off. (The
    division is a product by ``0.5 / pi``: the floor sits on the law's path in every RK4 stage, and a
    divide there is a visible part of a continuous loop's step.)

    >>> float(wrap_angle(-np.pi)), float(wrap_angle(np.pi)), float(wrap_angle(0.25 + 6 * np.pi))
    (3.141592653589793, 3.141592653589793, 0.25)
    """
    return angle + 2 * np.pi * lib.floor((np.pi - angle) * (0.5 / np.pi))


def heading_frame(dx, offset, lib=ca):
    """The deviation ``dx = x - x_ref`` (12,) as the law takes it: its ``pN, pE`` rotated into the
    reference's heading frame, ``offset`` (rad) the reference's yaw less the design's, and its
    ``psi`` wrapped into ``(-pi, pi]`` (:func:`wrap_angle`).

    The heading is a symmetry of the model: turning the vehicle and its reference by ``a`` about the
    vertical leaves the body velocities ``u, v, w``, the roll, pitch and rates unchanged and turns the
    horizontal position by ``a``, so ``R(-a) [dpN, dpE]`` is the position error the design saw at its
    own heading. At ``offset = 0`` every entry is ``dx``'s, bit for bit (``1 e + 0 e'``).

    Parameters
    ----------
    dx : (12,) CasADi column, or (..., 12) ndarray with ``lib=numpy``
    offset : CasADi scalar, or float or (...,) ndarray
    lib : module
        ``casadi`` or ``numpy``.
    """
    if lib is np:
        out = np.array(dx, dtype=float, copy=True)
        c, s = np.cos(offset), np.sin(offset)
        out[..., _PN] = c * dx[..., _PN] + s * dx[..., _PE]
        out[..., _PE] = c * dx[..., _PE] - s * dx[..., _PN]
        out[..., _PSI] = wrap_angle(out[..., _PSI])
        return out
    c, s = ca.cos(offset), ca.sin(offset)
    north = c * dx[_PN] + s * dx[_PE]
    east = c * dx[_PE] - s * dx[_PN]
    return ca.vertcat(north, east, dx[_PN + 2:_PSI], wrap_angle(dx[_PSI], ca), dx[_PSI + 1:])


def scheduled_gain(v, breaks, coefficients, pieces: int, mask: np.ndarray, degree: int = 3):
    """The table's gain ``G(v)`` (4, m) as CasADi expressions of the scheduling value ``v``.

    ``v`` is held to ``[breaks[0], breaks[pieces]]``; the piece ``i`` with ``breaks[i] <= v <
    breaks[i + 1]`` (the last piece also at its end, as :meth:`quadctl.design.gain_table.GainTable.at`)
    is chosen by a sum over pieces of ``if_else(indicator, coefficient, 0)``, exactly one term
    nonzero, so the selected coefficients are the table's, bit for bit; then Horner's rule in
    ``s = v - breaks[i]``. Only comparisons, ``if_else``, ``fmin``/``fmax`` and arithmetic: every
    runner (the emitted C of one case and of the lanes, CasADi's virtual machine) takes it alike.

    Parameters
    ----------
    v : CasADi scalar
        The scheduling value (:func:`quadctl.design.gain_table.scheduling_value`).
    breaks : CasADi column (pieces + 1,)
    coefficients : CasADi column
        The (4, pieces, 4, m) coefficients, column-major.
    pieces : int
    mask : (4, m) ndarray of bool
        Entries that may be nonzero; the others are structural zeros of the result.
    degree : int
        The highest power of ``s`` read (the table's higher coefficients are all zero): Horner's rule
        from there gives the bits of the full cubic's (``(0 s + 0) s + c = c``) for less work.
    """
    m = mask.shape[1]
    vc = ca.fmin(ca.fmax(v, breaks[0]), breaks[pieces])
    inside = []
    for i in range(pieces):
        lower = vc >= breaks[i] if i else None
        upper = vc < breaks[i + 1] if i < pieces - 1 else None
        inside.append(upper if lower is None else (lower if upper is None else ca.logic_and(lower, upper)))

    def select(values):
        if pieces == 1:
            return values[0]
        out = ca.if_else(inside[0], values[0], 0)
        for i in range(1, pieces):
            out = out + ca.if_else(inside[i], values[i], 0)
        return out

    s = vc - select([breaks[i] for i in range(pieces)])
    G = ca.SX(N_INPUTS, m)
    for col in range(m):
        for r in range(N_INPUTS):
            if not mask[r, col]:
                continue
            coef = [select([coefficients[k + 4 * (i + pieces * (r + N_INPUTS * col))] for i in range(pieces)])
                    for k in range(3 - degree, 4)]
            value = coef[0]
            for c in coef[1:]:
                value = value * s + c
            G[r, col] = value
    return G


@dataclass(frozen=True)
class LoopFunctions:
    """The CasADi functions of one spec (arguments in this order, all column vectors).

    ``step(X, t, dt, c, e) -> (X_next, u)``: one RK4 (or ETDRK4, :attr:`LoopSpec.method`) step with
    continuous feedback, and the input at its start (continuous specs).
    ``law(X, t, c, e) -> (u, X_sampled)``: the control law at ``X``, and ``X`` with its controller
    states advanced by one controller period (held specs; the input part serves both).
    ``plant(X, u, dt, c, e) -> X_next``: one RK4 step of the plant under a held ``u``; the
    controller states pass through (held specs).
    ``u`` is always the (clipped) command; with rotor dynamics the body gets ``mix_inv f``.
    ``ref(t, c, e) -> x_ref``: the reference state the law regulates to at ``t`` (what the metrics
    of a run measure the error against).
    """

    spec: LoopSpec
    law: ca.Function
    step: ca.Function | None = None
    plant: ca.Function | None = None
    ref: ca.Function | None = None
    remainder: ca.Function | None = None
    """ETDRK4 only: the nonlinear remainder ``N = rhs - L X`` of :func:`etdrk4`'s stages,
    ``(X, t, c, e) -> (N, u)`` (``N`` on the reference's expansion in force over the step, ``u`` the input
    at ``X`` on the one in force at ``t``: :data:`REFERENCE_LAYOUT`) with continuous feedback, ``(X, u, c, e) -> N``
    under a held input: what a one-case compiled loop evaluates, its stages' products in
    ``driver.c`` (``qc_etd``, the same operations in the same order)."""

    def functions(self) -> tuple[tuple[str, ca.Function], ...]:
        """(C name, function) of every function the driver calls."""
        named = [("qc_law", self.law)]
        named.append(("qc_plant", self.plant) if self.spec.held else ("qc_step", self.step))
        return (*named, ("qc_ref", self.ref))


@lru_cache(maxsize=32)
def build(spec: LoopSpec) -> LoopFunctions:
    """Build the loop functions of ``spec`` (cached per spec)."""
    model = build_model()
    nz, nx, npl, nl = spec.nz, spec.nx, spec.n_plant, spec.n_lag
    c = ca.SX.sym("c", spec.n_constants)
    parts, offset = {}, 0
    for name, shape in constant_layout(nz, spec.rotors, spec.lag_model, spec.ny, spec.schedule_shape,
                                       spec.n_law_constants, spec.filter_order):
        size = int(np.prod(shape))
        block = c[offset:offset + size]
        parts[name] = ca.reshape(block, *shape) if len(shape) == 2 else block
        offset += size
    mask = ca.DM(np.reshape(np.asarray(spec.pattern, dtype=float), (N_INPUTS, N_STATES), order="F"))
    gain = parts["K"] * mask  # structural zeros vanish from the generated code
    e = ca.SX.sym("e", spec.n_exo)
    if spec.noise:
        disturbance = e[:N_DISTURBANCES]
        sensor = e[N_DISTURBANCES:N_EXO]
    else:
        disturbance, sensor = ca.DM.zeros(N_DISTURBANCES), ca.DM.zeros(N_STATES)
    n_wind_end = spec.n_exo - (N_REFERENCE if spec.reference else 0)
    if spec.wind:
        wind = e[n_wind_end - N_WIND:n_wind_end]

        def f(x, u, p, d):
            return model.f_disturbed_wind(x, u, p, d, wind)
    else:
        f = model.f_disturbed

    def saturate(cmd):
        if spec.saturation == "none":
            return cmd
        if spec.priority:  # roll and pitch kept, then thrust, yaw given up first (quadctl.physics.motors.desaturate)
            return desaturate(cmd, parts["mix"], parts["lo"], parts["hi"], lib=ca)
        act = parts["mix"] @ cmd if spec.saturation == "motors" else cmd
        act = ca.if_else(act < parts["lo"], parts["lo"], act)
        act = ca.if_else(act > parts["hi"], parts["hi"], act)
        return parts["mix_inv"] @ act if spec.saturation == "motors" else act

    ne = spec.n_estimate
    measured = list(spec.measured)
    ng, mf = spec.n_filter, spec.filter_order
    og = npl + nz + nl + spec.n_law + spec.n_buffer  # where the gyro filter's states start

    def gyro(X):
        """The measured body rates ``r_m`` (rad/s): what the gyro filter takes."""
        return X[_P:_P + N_RATES] + sensor[_P:_P + N_RATES]

    def filtered_rates(X):
        """``y = c g + d r_m`` on each rate: what the law takes in place of the measured rates."""
        g, r = X[og:og + ng], gyro(X)
        return ca.vertcat(*[ca.dot(parts["filter_c"], g[k * mf:(k + 1) * mf]) + parts["filter_d"] * r[k]
                            for k in range(N_RATES)])

    def filter_update(X):
        """``A g + b r_m`` on each rate: the filter's next state (held loops) or its rate (continuous)."""
        g, r = X[og:og + ng], gyro(X)
        return ca.vertcat(*[parts["filter_A"] @ g[k * mf:(k + 1) * mf] + parts["filter_b"] * r[k]
                            for k in range(N_RATES)])

    half = ROW_HALF  # one expansion's columns (REFERENCE_LAYOUT holds two)
    n_ref = n_wind_end
    stage = {"over_step": False}  # True while a step's stages are built: they read the step's expansion

    def expansion(t):
        """The expansion the loop reads at ``t`` (:data:`REFERENCE_LAYOUT`): its columns and ``s`` (the
        time from its anchor): the one in force at the step's start, or in a step's stages the one in
        force over the step."""
        start = n_ref + (half if stage["over_step"] else 0)
        ref = e[start:start + half]
        return ref, t - ref[0]

    def x_ref(t):
        """The reference state at ``t``: the row's expansion, or the trim drifting at ``x_rate``."""
        if not spec.reference:
            return parts["x_ref"] + parts["x_rate"] * t
        ref, s = expansion(t)
        return ref[1:1 + N_STATES] + s * (ref[1 + N_STATES:1 + 2 * N_STATES]
                                          + s / 2 * ref[1 + 2 * N_STATES:1 + 3 * N_STATES])

    def u_ref(t):
        """The feedforward input at ``t``: the row's, or the trim input."""
        if not spec.reference:
            return parts["u_trim"]
        ref, s = expansion(t)
        return ref[1 + 3 * N_STATES:1 + 3 * N_STATES + N_INPUTS] + s * ref[1 + 3 * N_STATES + N_INPUTS:]

    def design_yaw(psi_ref):
        """The yaw the gain acting at reference yaw ``psi_ref`` was designed at: the trim's, or a yaw
        schedule's value held to its ends (inside them the design's own yaw: no rotation)."""
        if spec.schedule and spec.schedule[0] == "yaw":
            pieces = spec.schedule[1]
            return ca.fmin(ca.fmax(psi_ref, parts["schedule_breaks"][0]), parts["schedule_breaks"][pieces])
        return parts["x_ref"][_PSI]

    def heading_offset(t):
        """rad: the reference's yaw less the yaw its gain was designed at (0 at the trim's heading)."""
        psi_ref = x_ref(t)[_PSI]
        return psi_ref - design_yaw(psi_ref)

    def measured_deviation(X, t):
        """``x_m - x_ref(t)`` in the reference's heading frame (:func:`heading_frame`). A loop without a
        reference holds the trim, whose yaw is the design's: only its yaw error is wrapped (turning by
        a zero angle would cost a sine and a cosine per stage for the same bits)."""
        x_m = X[:N_STATES] + sensor
        if ng:
            x_m = ca.vertcat(x_m[:_P], filtered_rates(X))
        dx = x_m - x_ref(t)
        if not spec.reference:
            return ca.vertcat(dx[:_PSI], wrap_angle(dx[_PSI], ca), dx[_PSI + 1:])
        return heading_frame(dx, heading_offset(t))

    def predicted(xh):
        """``C xh``: the measurements the estimate predicts (a measured rate through the gyro filter's
        model, ``c g_h + d r_h``, when the loop has one: :func:`quadctl.linear.filters.filtered_output`)."""
        if not ng:
            return xh[measured]
        rows = []
        for i in measured:
            k = i - _P
            if 0 <= k < N_RATES:
                gh = xh[N_STATES + k * mf:N_STATES + (k + 1) * mf]
                rows.append(parts["filter_d"] * xh[i] + ca.dot(parts["filter_c"], gh))
            else:
                rows.append(xh[i])
        return ca.vertcat(*rows)

    def innovation(X, t):
        """``y - C xh``: the measured deviation (its rates filtered, with a gyro filter) less its prediction."""
        return measured_deviation(X, t)[measured] - predicted(X[nx - ne:])

    def estimate(X, t):
        """The filter's estimate the law acts on: updated (held loops), or ``xh``; (ne,)."""
        xh = X[nx - ne:]
        return xh + parts["Le"] @ innovation(X, t) if spec.held else xh

    def deviation(X, t):
        """What the law acts on: the measured deviation, or the filter's (updated, held) estimate of it."""
        if not ne:
            return measured_deviation(X, t)
        return estimate(X, t)[:N_STATES]

    def gains(t):
        """(state gain (4, 12), integrator gain (4, nz)) at ``t``: the constants, or the schedule's
        ``G(v)`` at the scheduling value of the reference the law uses."""
        if not spec.schedule:
            return gain, parts.get("Ki")

        variable, pieces, columns, degree = spec.schedule
        heading = (parts["schedule_heading"] + heading_offset(t) if spec.reference and variable != "yaw"
                   else parts["schedule_heading"])
        v = scheduling_value(variable, x_ref(t), heading, lib=ca)
        mask = np.hstack([np.reshape(np.asarray(spec.pattern, dtype=bool), (N_INPUTS, N_STATES), order="F"),
                          np.ones((N_INPUTS, columns - N_STATES), dtype=bool)])
        G = scheduled_gain(v, parts["schedule_breaks"], parts["schedule_coefficients"], pieces, mask, degree)
        return G[:, :N_STATES], (G[:, N_STATES:] if columns > N_STATES else parts.get("Ki"))

    def control(X, t):
        """(u, dz/dt) at loop state ``X`` and time ``t``."""
        z = X[npl:npl + nz]
        err = deviation(X, t)
        state_gain, integral_gain = gains(t)
        cmd = u_ref(t) - state_gain @ err
        if nl:
            cmd = cmd - parts["Kv"] @ X[npl + nz:npl + nz + nl]
        if nz == 0:
            return saturate(cmd), ca.SX(0, 1)
        cmd = cmd - integral_gain @ z
        u = saturate(cmd)
        rate = -ca.vertcat(*[err[i] for i in spec.integral])  # MATLAB lqi: dz/dt = r - y
        if spec.saturation != "none":
            clipped = ca.if_else(ca.fabs(u - cmd) > ANTIWINDUP_TOL, 1, 0)
            frozen = parts["antiwindup"] @ clipped
            rate = ca.if_else(frozen > 0.5, 0, rate)
        return u, rate

    X = ca.SX.sym("X", nx)
    t, dt = ca.SX.sym("t"), ca.SX.sym("dt")
    u_held = ca.SX.sym("u", N_INPUTS)
    params = parts["params"]
    if spec.diagonal_inertia:  # the products of inertia as exact zeros: every term they enter vanishes
        params = ca.vertcat(params[:PRODUCTS.start], ca.DM.zeros(PRODUCTS.stop - PRODUCTS.start),
                            params[PRODUCTS.stop:])

    def rk4(rhs, Y):
        stage["over_step"] = True
        k1 = rhs(Y, t)
        k2 = rhs(Y + dt / 2 * k1, t + dt / 2)
        k3 = rhs(Y + dt / 2 * k2, t + dt / 2)
        k4 = rhs(Y + dt * k3, t + dt)
        stage["over_step"] = False
        return Y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def body(Y, u):
        """d[x; f]/dt under the command ``u``: the body under ``u``, or under its rotors' thrusts."""
        if not spec.rotors:
            return f(Y[:N_STATES], u, params, disturbance)
        thrust = Y[N_STATES:npl]
        xdot = f(Y[:N_STATES], parts["mix_inv"] @ thrust, params, disturbance)
        return ca.vertcat(xdot, (parts["mix"] @ u - thrust) / parts["tau"])

    def lag_rate(Y, u):
        """dl/dt of the controller's lag model under its command ``u``."""
        return (u - parts["u_trim"] - Y[npl + nz:npl + nz + nl]) / parts["tau_model"]

    n_law = spec.n_law
    if spec.law:  # a PID cascade (quadctl.sim.pid): its own states after the plant's

        command, s_next = pid.law(spec.law, X[npl:npl + n_law], X[:N_STATES] + sensor, x_ref(t), u_ref(t),
                                  parts["law"], parts["mix"], parts["mix_inv"], parts["hi"], parts["Ts"],
                                  params[GRAVITY])
        u_now, X_sampled = saturate(command), ca.vertcat(X[:npl], s_next)
    else:
        u_now, z_rate = control(X, t)
        X_sampled = ca.vertcat(X[:npl], X[npl:npl + nz] + parts["Ts"] * z_rate) if nz else X[:npl]
    if nl:  # the lag model's exact ZOH over one sample under the held command
        a = ca.exp(-parts["Ts"] / parts["tau_model"])
        X_sampled = ca.vertcat(X_sampled, a * X[npl + nz:npl + nz + nl] + (1 - a) * (u_now - parts["u_trim"]))
    if spec.delay:  # apply the oldest command, shift the newest in
        b0, nb = spec.buffer_start, spec.n_buffer
        buffer = X[b0:b0 + nb]
        u_now, X_sampled = buffer[nb - N_INPUTS:], ca.vertcat(X_sampled, u_now, buffer[:nb - N_INPUTS])
    if ng:  # the gyro filter takes this sample (held loops)
        X_sampled = ca.vertcat(X_sampled, filter_update(X) if spec.held else X[og:og + ng])
    if ne and spec.held:  # predict from the updated estimate under the applied input
        xc = estimate(X, t)
        X_sampled = ca.vertcat(X_sampled, parts["Ae"] @ xc + parts["Be"] @ (u_now - u_ref(t)))
    elif ne:
        X_sampled = ca.vertcat(X_sampled, X[nx - ne:])
    law = ca.Function("qc_law", [X, t, c, e], ca.cse([u_now, X_sampled]), ["X", "t", "c", "e"], ["u", "X_sampled"])
    ref = ca.Function("qc_ref", [t, c, e], [x_ref(t)], ["t", "c", "e"], ["x_ref"])
    if spec.held:
        def plant_rhs(Y, ts):
            xdot = body(Y, u_held)
            return ca.vertcat(xdot, ca.DM.zeros(nx - npl)) if nx > npl else xdot

        X_next = etdrk4(plant_rhs, X, t, dt, phi_block(c, spec)) if spec.method == "etdrk4" else rk4(plant_rhs, X)
        plant = ca.Function("qc_plant", [X, u_held, dt, c, e], [ca.cse(X_next)],
                            ["X", "u", "dt", "c", "e"], ["X_next"])
        remainder = None
        if spec.method == "etdrk4":
            N = plant_rhs(X, t) - phi_block(c, spec)["lin"] @ X
            remainder = ca.Function("qc_rem", [X, u_held, c, e], [ca.cse(N)], ["X", "u", "c", "e"], ["N"])
        return LoopFunctions(spec=spec, law=law, plant=plant, ref=ref, remainder=remainder)

    def closed_rhs(Y, ts):
        u, rate = control(Y, ts)
        xdot = body(Y, u)
        xdot = ca.vertcat(xdot, rate) if nz else xdot
        xdot = ca.vertcat(xdot, lag_rate(Y, u)) if nl else xdot
        xdot = ca.vertcat(xdot, filter_update(Y)) if ng else xdot
        if ne:  # Kalman-Bucy
            xh = Y[nx - ne:]
            xh_dot = parts["Ae"] @ xh + parts["Be"] @ (u - u_ref(ts)) + parts["Le"] @ innovation(Y, ts)
            xdot = ca.vertcat(xdot, xh_dot)
        return xdot

    remainder = None
    if spec.method == "etdrk4":
        stage["over_step"] = True  # every stage reads the expansion in force over the step
        X_next = etdrk4(closed_rhs, X, t, dt, phi_block(c, spec))
        N = closed_rhs(X, t) - phi_block(c, spec)["lin"] @ X
        stage["over_step"] = False
        remainder = ca.Function("qc_rem", [X, t, c, e], ca.cse([N, u_now]), ["X", "t", "c", "e"], ["N", "u"])
    else:
        X_next = rk4(closed_rhs, X)
    step = ca.Function("qc_step", [X, t, dt, c, e], ca.cse([X_next, u_now]),
                       ["X", "t", "dt", "c", "e"], ["X_next", "u"])
    return LoopFunctions(spec=spec, law=law, step=step, ref=ref, remainder=remainder)


def phi_block(c, spec: LoopSpec) -> dict:
    """The ETDRK4 matrices of :data:`PHI_LAYOUT` in ``c`` (after the loop's constants), with the
    entries outside ``spec.phi_pattern`` zero."""
    nx = spec.nx
    offset = spec.n_constants - spec.n_phi
    mask = (ca.DM(np.reshape(np.asarray(spec.phi_pattern, dtype=float), (nx, nx), order="F"))
            if spec.phi_pattern else None)
    out = {}
    for name in PHI_LAYOUT:
        M = ca.reshape(c[offset:offset + nx * nx], nx, nx)
        out[name] = M * mask if mask is not None else M
        offset += nx * nx
    return out


def etdrk4(rhs, X, t, h, phi: dict):
    """One step of the stiffly accurate exponential Runge-Kutta method of order 4 of Hochbruck and
    Ostermann (SIAM J. Numer. Anal. 43, 2005, eq. 5.19) of ``X' = rhs(X, t)`` split as ``L X + N(X, t)``,
    with ``L`` and the matrices of ``h`` in ``phi`` (:data:`PHI_LAYOUT`), written about the step's
    start ``X`` (the linear part acts on ``Y - X``)::

        U2 = X + A21 G1                             G1 = G(X, t) = rhs(X, t)
        U3 = X + A31 G1 + A32 G2                    G2 = G(U2, t + h/2)
        U4 = X + A41 G1 + A42 (G2 + G3)             G3 = G(U3, t + h/2)
        U5 = X + A51 G1 + A52 (G2 + G3) + A54 G4    G4 = G(U4, t + h)
        X+ = X + B1 G1 + B4 G4 + B5 G5              G5 = G(U5, t + h/2)

    with ``G(Y, s) = N(Y, s) + L X = rhs(Y, s) - L (Y - X)``. This is the method's usual form
    (``U2 = e^(hL/2) X + A21 N1``, ...) with ``e^(hL/2) - 1 = A21 L`` and its kin used exactly: in
    floating point the usual form adds the error of those identities times ``X`` at every step, a
    drift away from an equilibrium the loop holds (1e-11 to 1e-10 over 1 s of hover at 1e4 to 1e5
    steps) that this form does not have.

    It keeps its order 4 when ``L`` is stiff and ``N`` is not small (its stiff order conditions): Cox
    and Matthews' four-stage ETDRK4 falls to order 1 to 2 at steps beyond the fast modes' time scale
    on a loop whose remainder couples to them (a mission's tilted thrust). Exact when ``N`` is a
    quadratic in ``t`` along the solution (a linear loop: ``L`` is its matrix).
    """
    L = phi["lin"]
    LX = L @ X

    def G(Y, ts):
        return (rhs(Y, ts) - L @ Y) + LX

    g1 = G(X, t)
    g2 = G(X + phi["A21"] @ g1, t + h / 2)
    g3 = G(X + phi["A31"] @ g1 + phi["A32"] @ g2, t + h / 2)
    g23 = g2 + g3
    g4 = G(X + phi["A41"] @ g1 + phi["A42"] @ g23, t + h)
    g5 = G(X + phi["A51"] @ g1 + phi["A52"] @ g23 + phi["A54"] @ g4, t + h / 2)
    return X + phi["B1"] @ g1 + phi["B4"] @ g4 + phi["B5"] @ g5
