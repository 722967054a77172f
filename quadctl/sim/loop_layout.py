"""The layouts of a closed loop's numbers, before any CasADi: its constant vector ``c``
(:func:`constant_layout`, filled by :func:`pack_constants`, :func:`fill_constants` and
:func:`fill_constants_stack`; ETDRK4's matrices after it, :data:`PHI_LAYOUT`) and its exogenous row per
step (:func:`exo_layout`: noise, wind, a reference's expansions).

:mod:`quadctl.sim.loop_spec` says which of these a loop has; :mod:`quadctl.sim.builder` reads them in the
generated code, and the runners marshal constants and rows by them.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from quadctl.layout import N_INPUTS, N_STATES
from quadctl.physics.model import N_DISTURBANCES, N_PARAMS, N_WIND

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
    gain columns (:attr:`~quadctl.sim.loop_spec.LoopSpec.schedule`), ends with ``schedule_heading`` (rad, the direction
    ``speed`` is measured along), ``schedule_breaks`` (p + 1,) and ``schedule_coefficients``
    (4, p, 4, m): :class:`quadctl.design.gain_table.GainTable`'s ``breaks`` and ``coefficients``.
    A loop flying a law other than LQR (:attr:`~quadctl.sim.loop_spec.LoopSpec.law`) then has its ``law``
    constants (``n_law`` of them) and ``thrust_curve`` (4, 3): each rotor's ``(c0, c1, c2)``, N, of its thrust
    ``c0 + c1 s + c2 s^2`` at the command fraction ``s`` (:func:`quadctl.sim.pid_mixing.pwm_thrust_curve`). A loop
    with a gyro filter of ``filter_order`` states per rate
    (:attr:`~quadctl.sim.loop_spec.LoopSpec.filter_order`) ends with the filter's ``filter_A`` (m, m),
    ``filter_b``, ``filter_c`` (m,) and ``filter_d`` (1,)
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
        out = out + (("law", (n_law,)), ("thrust_curve", (N_INPUTS, 3)))
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
