"""The closed loop a simulation flies: the plant's parameters, the trim and the control law
(:class:`ClosedLoop`), and what is read from a loop alone: its linear parts, the constants and structure
of its generated code (:mod:`quadctl.sim.builder`), the bounds a run stops at, and its RK4 step
(:meth:`ClosedLoop.plan`; ETDRK4's linear part and graded schedule are
:func:`quadctl.sim.etdrk4_stack.exponential_plan`'s).

``u = u_ref(t) - K (x - x_ref(t))``: by default ``x_ref(t) = x_trim + x_rate t`` (positions drift at
the trim velocity) and ``u_ref = u_trim``; with ``simulation.reference`` the reference flown and its
feedforward; with a gain schedule ``K = G(v)`` (:mod:`quadctl.sim.builder`, "Gain schedule"). With
the integrators, sampling, saturation, noise and wind the loop has, run by
the engine of :mod:`quadctl.sim` (compiled where a C compiler works).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from quadctl.design import lqg_loop
from quadctl.errors import ArgumentError
from quadctl.layout import N_STATES, PRODUCTS, STATE_INDEX, STATE_NAMES
from quadctl.sim.loop_layout import pack_constants
from quadctl.sim.loop_spec import LoopSpec
from quadctl.sim.pid import initial_states, structure_of
from quadctl.sim.pid_mixing import pwm_thrust_curve
from quadctl.sim.plan import StepPlan, max_stable_steps, plan_held_step, plan_step

if TYPE_CHECKING:  # the types of a loop's parts (their modules load only when a loop has one)
    from quadctl.config.pid import PidGains
    from quadctl.design.gain_table import GainTable
    from quadctl.design.kalman import Kalman
    from quadctl.linear.filters import RateFilter
    from quadctl.physics.motors import Actuators


VALID_PITCH = math.radians(85.0)
"""Beyond this pitch the Euler kinematics (``1/cos theta``) are near singular: the run stops."""
TURNED_OVER = math.radians(90.0)
"""A roll this far from the trim's turns the rotors' thrust sideways or down: the vehicle is lost (it tumbles
and falls), and the run stops as diverged. (A roll cannot reach it while the pitch runs past
:data:`VALID_PITCH` first; the model itself holds at any roll.)"""
RUNAWAY = {"pN": 1e5, "pE": 1e5, "pD": 1e5, "u": 1e3, "v": 1e3, "w": 1e3,
           "phi": TURNED_OVER, "theta": VALID_PITCH, "psi": 1e3, "p": 1e4, "q": 1e4, "r": 1e4}
"""Bounds on |x - x_ref| (state units) past which a run counts as diverged; theta's is the model's range, phi's
a vehicle turned over."""


def eigen_owners(A_cl, state_owner: dict[str, str], names=STATE_NAMES) -> tuple[np.ndarray, list[str]]:
    """Eigenvalues of ``A_cl`` and, for each, the subsystem of its eigenvector's largest state.

    ``names`` labels the rows of ``A_cl`` (default the 12 states; an LQI loop appends its
    integrators, each owned by the subsystem of the state it integrates).
    """
    eig, vec = np.linalg.eig(np.asarray(A_cl, dtype=float))
    owners = [state_owner.get(names[int(np.argmax(np.abs(vec[:, k])))], "unassigned")
              for k in range(len(eig))]
    return eig, owners


@dataclass(frozen=True, eq=False)
class ClosedLoop:
    """Everything the simulation needs: the plant parameters, the trim and the control law.

    Attributes
    ----------
    params : (11,) ndarray
        Vehicle parameter vector (:meth:`quadctl.physics.model.Vehicle.vector`) of the simulated plant
        (it may differ from the design model's: model mismatch).
    x_trim : (12,) ndarray
    u_trim : (4,) ndarray
    x_rate : (12,) ndarray
        Drift of the reference (the trim velocity on positions, zero elsewhere).
    K : (4, 12) ndarray
    eigenvalues : (12,) ndarray
        Of the linear closed loop ``A - B K``.
    owners : list of str
        Subsystem of each eigenvalue.

    Examples
    --------
    A setup's loop is :attr:`quadctl.pipeline.Stages.loop` (:func:`quadctl.pipeline.closed_loop_of`
    builds one from any gains):

    >>> import quadctl as qc
    >>> loop = qc.Stages(qc.setup_of(qc.load_config("hover"))).loop
    >>> loop.K.shape, loop.rate, sorted(set(loop.owners))  # hover: the free positions are "guidance"
    ((4, 12), None, ['altitude', 'guidance', 'pitch', 'roll', 'yaw'])
    """

    params: np.ndarray
    x_trim: np.ndarray
    u_trim: np.ndarray
    x_rate: np.ndarray
    K: np.ndarray
    eigenvalues: np.ndarray
    owners: list = field(default_factory=list)
    rate: float | None = None
    """Hz of a sampled controller (zero-order hold); None: continuous feedback."""
    Ki: np.ndarray | None = None
    """(4, nz) integrator gains: ``u -= Ki z``."""
    integral_states: tuple[str, ...] = ()
    """The state each integrator integrates (``dz/dt = -(x_s - x_ref,s)``)."""
    actuators: Actuators | None = None
    """:class:`quadctl.physics.motors.Actuators` that clip the input; None: unlimited."""
    open_loop_eigenvalues: np.ndarray | None = None
    """Of the plant ``A``: what RK4 integrates between samples of a sampled controller."""
    delay_samples: int = 0
    """Controller samples from measurement to actuation (a sampled controller's command buffer)."""
    Kv: np.ndarray | None = None
    """(4, 4) gain on the controller's rotor lag model (``controller.rotor_lag: include``): ``u -= Kv l``."""
    lag_model_time_constant: float | None = None
    """s of the controller's rotor lag model (the design's; None: no model)."""
    estimator: Kalman | None = None
    """:class:`quadctl.design.kalman.Kalman` the law closes through (LQG); None: the measured state."""
    jacobians: tuple | None = None
    """``(A, B)`` of the design model at the trim: the exponential integrator's linear part
    (:meth:`linear_part`); None: only RK4 runs the loop."""
    schedule: GainTable | None = None
    """:class:`quadctl.design.gain_table.GainTable` the law flies: ``G(v)`` in place of ``K`` (and of ``Ki``
    when the table has the integrator gains), ``v`` read from the reference (:mod:`quadctl.sim.builder`,
    "Gain schedule"); None: the fixed gains. ``K`` stays the design at the trim (the step plan's)."""
    schedule_heading: float = 0.0
    """rad: the heading a ``speed`` schedule measures along (the trim's yaw)."""
    schedule_eigenvalues: np.ndarray | None = None
    """rad/s: the eigenvalues of the schedule's frozen loops (its interpolated gains on the model at
    each value), which the continuous loop's RK4 step holds stable too; None: the loop's own only."""
    law: PidGains | None = None
    """:class:`quadctl.config.pid.PidGains` of the PID cascade that flies in place of the LQR gains
    (:mod:`quadctl.sim.pid`; ``K`` is then zero and ``rate`` the cascade's base rate); None: LQR."""
    rate_filter: RateFilter | None = None
    """:class:`quadctl.linear.filters.RateFilter` the law runs on the measured body rates (``controller.filters``),
    at the controller's period (continuous without a rate); None: raw rates."""
    schedule_jacobians: tuple | None = None
    """``(A, B)``, (P, 12, 12) and (P, 12, 4): the design model trimmed and linearized at each of the
    schedule's values, whose loops closed with the table's gains are ETDRK4's linear parts
    (:meth:`linear_part`); None: a continuous scheduled loop's ETDRK4 takes the trim's."""

    @property
    def rotor_time_constant(self) -> float | None:
        """s: the rotors' first-order lag (``motors.time_constant``); None: instantaneous rotors."""
        motors = self.actuators.motors if self.actuators is not None else None
        return motors.time_constant if motors is not None else None

    @property
    def filter_form(self):
        """The gyro filter's :class:`~quadctl.linear.filters.StateSpace` at the loop's timing (None: no filter)."""
        if self.rate_filter is None:
            return None
        return self.rate_filter.form(None if self.rate is None else 1.0 / self.rate)

    def plan(self, duration: float, dt="auto", *, limits=None) -> StepPlan:
        """The RK4 step: from the closed loop's spectrum, or the open loop's under a held input
        (both with the rotors' lag, :func:`rotor_eigenvalues`). ``limits``: the largest stable step of
        each of :attr:`eigenvalues` (:func:`quadctl.sim.plan.max_stable_steps`), when the caller has
        them (a sweep's, of a chunk's loops at once); the other eigenvalues' are computed here."""
        lag = rotor_eigenvalues(self.rotor_time_constant)
        if self.rate is not None:
            ol = self.open_loop_eigenvalues if self.open_loop_eigenvalues is not None else np.zeros(0)
            return plan_held_step(np.concatenate([ol, lag]), self.rate, duration, dt)
        est = self.estimator.eigenvalues if self.estimator is not None else np.zeros(0)
        model = rotor_eigenvalues(self.lag_model_time_constant) if self.Kv is not None else np.zeros(0)
        sched = self.schedule_eigenvalues if self.schedule_eigenvalues is not None else np.zeros(0)
        form = self.filter_form
        filt = np.zeros(0)
        if form is not None:  # the filter's own poles, and the loop's with it (linearized at the trim)
            filt = np.linalg.eigvals(form.A)
            if self.jacobians is not None and self.estimator is None:
                filt = np.concatenate([filt, np.linalg.eigvals(self.linear_part())])
        extra = (lag, model, est, sched, filt)
        if not any(len(e) for e in extra):  # the loop's own spectrum (a sweep's plain loops: no copies)
            return plan_step(self.eigenvalues, self.owners, duration, dt, limits=limits)
        eig = np.concatenate([self.eigenvalues, *extra])
        if limits is not None:
            limits = np.concatenate([limits, max_stable_steps(eig[len(self.eigenvalues):])])
        return plan_step(eig,
                         [*self.owners, *["rotors"] * len(lag), *["rotor lag model"] * len(model),
                          *["estimator"] * len(est), *["gain schedule"] * len(sched),
                          *["gyro filter"] * len(filt)], duration, dt, limits=limits)

    def _jacobians(self) -> tuple[np.ndarray, np.ndarray]:
        """``(A, B)`` of the design model at the trim, or an ArgumentError naming how to build a loop with them."""
        if self.jacobians is None:
            raise ArgumentError("this ClosedLoop has no jacobians (A, B): build it with "
                                "quadctl.pipeline.closed_loop_of")
        A, B = self.jacobians
        return np.asarray(A, dtype=float), np.asarray(B, dtype=float)

    def linear_part(self, point: int | None = None) -> np.ndarray:
        """The loop linearized at the reference in the loop state's order
        (:func:`quadctl.design.lqg_loop.simulated`);
        ``point``: at the gain schedule's ``point``-th value instead, closed with the table's gains there
        (:attr:`schedule_jacobians`).

        Raises
        ------
        ArgumentError
            The loop was built without its ``jacobians`` (or ``schedule_jacobians``, for a ``point``).
        """

        A, B = self._jacobians()
        K, Ki = self.K, self.Ki
        if point is not None:
            if self.schedule_jacobians is None:
                raise ArgumentError("this ClosedLoop has no schedule_jacobians: build it with "
                                    "quadctl.pipeline.scheduled_loop and the schedule's points")
            A, B = (np.asarray(M[point], dtype=float) for M in self.schedule_jacobians)
            G = self.schedule.gains[point]
            K = G[:, :N_STATES]
            Ki = G[:, N_STATES:] if G.shape[1] > N_STATES else Ki
        act = self.actuators
        return lqg_loop.simulated(A, B, K, Ki=Ki, integral_states=self.integral_states, Kv=self.Kv,
                                  lag_time_constant=self.lag_model_time_constant,
                                  rotor_time_constant=self.rotor_time_constant,
                                  mix=act.mix if act is not None else None, estimator=self.estimator,
                                  rate_filter=self.filter_form)

    @property
    def kept(self) -> dict:
        """What this process keeps with the loop to reuse (by its maker's key: the ETDRK4 stacks of
        :func:`quadctl.sim.etdrk4_stack.kept_exponential_stack`); a pickle carries none of it."""
        return self.__dict__.setdefault("_kept", {})

    def __getstate__(self):
        """The loop's fields (a pickle carries nothing :attr:`kept`: its runner's arrays are this process's)."""
        state = dict(self.__dict__)
        state.pop("_kept", None)
        return state

    @cached_property
    def point_linear_parts(self) -> np.ndarray:
        """(P, n, n): :meth:`linear_part` at each of the gain schedule's values (its ``schedule_jacobians``)."""
        return np.stack([self.linear_part(p) for p in range(len(self.schedule.values))])

    def plant_linear_part(self) -> np.ndarray:
        """The plant linearized at the trim under a held input, in the loop state's order: what ETDRK4
        integrates exactly between a sampled controller's samples. ``[x; f]``: ``A`` (and, with rotor
        dynamics, ``B mix_inv`` from the rotor thrusts and ``-1/tau`` on them); the controller states
        do not move between samples (zero rows).

        Raises
        ------
        ArgumentError
            The loop was built without its ``jacobians``.
        """
        A, B = self._jacobians()
        nx = len(self.initial_loop_state(self.x_trim))
        L = np.zeros((nx, nx))
        L[:N_STATES, :N_STATES] = A
        tau = self.rotor_time_constant
        if tau is not None:
            rotors = slice(N_STATES, N_STATES + len(self.u_trim))
            L[:N_STATES, rotors] = B @ self.actuators.mix_inv
            L[rotors, rotors] = -np.eye(len(self.u_trim)) / tau
        return L

    def spec(self, noise: bool = False, wind: bool = False, reference: bool = False, method: str = "rk4",
             phi_pattern: tuple[bool, ...] = ()) -> LoopSpec:
        """The structure of this loop's generated code (``reference``: it flies a reference)."""
        act = self.actuators
        table = self.schedule
        K = self.K if table is None else np.any(table.coefficients[..., :N_STATES] != 0, axis=(0, 1))
        return LoopSpec.of_gain(K, saturation=act.mode if act is not None else "none",
                                priority=act is not None and act.priority,
                                method=method, phi_pattern=phi_pattern,
                                schedule=(table.variable, *self.schedule_shape, self.schedule_degree)
                                if table is not None else (),
                                integral=tuple(STATE_INDEX[s] for s in self.integral_states),
                                held=self.rate is not None, noise=noise,
                                rotors=self.rotor_time_constant is not None, delay=self.delay_samples,
                                lag_model=self.Kv is not None, wind=wind,
                                measured=tuple(STATE_INDEX[s] for s in self.measured), reference=reference,
                                law=self.law_structure,
                                filter_order=self.rate_filter.order if self.rate_filter is not None else 0,
                                diagonal_inertia=not np.any(np.asarray(self.params)[PRODUCTS]))

    @property
    def law_structure(self) -> tuple:
        """The law's structure baked into the code (:attr:`quadctl.sim.loop_spec.LoopSpec.law`); empty: LQR."""
        if self.law is None:
            return ()

        return structure_of(self.law)

    @property
    def measured(self) -> tuple[str, ...]:
        """States the Kalman filter measures; empty without one."""
        return tuple(self.estimator.measured) if self.estimator is not None else ()

    def constants(self, sample_time: float | None = None) -> np.ndarray:
        """The constant vector ``c`` of this loop (:func:`quadctl.sim.loop_layout.pack_constants`)."""
        values = dict(x_ref=self.x_trim, x_rate=self.x_rate, u_trim=self.u_trim, params=self.params,
                      Ts=[sample_time or 0.0])
        act = self.actuators
        if act is not None:
            values.update(mix=act.mix, mix_inv=act.mix_inv, lo=act.lo, hi=act.hi)
        tau = self.rotor_time_constant
        if tau is not None:
            values.update(tau=[tau])
        if self.Kv is not None:
            values.update(tau_model=[self.lag_model_time_constant])
        kal = self.estimator
        if kal is not None:
            if kal.discrete != (self.rate is not None) or (
                    kal.discrete and not math.isclose(kal.sample_time, 1.0 / self.rate, rel_tol=1e-12)):
                raise ArgumentError(f"this ClosedLoop's Kalman filter has sample_time {kal.sample_time} s and the loop "
                                    f"rate {self.rate} Hz: the filter's sample time must be the controller period "
                                    "(or both continuous); design it at the loop's rate, quadctl.pipeline.estimator_of")
            if kal.rate_filter != self.rate_filter:
                raise ArgumentError("this ClosedLoop's Kalman filter models another gyro filter than the loop's "
                                    "(controller.filters): design it with the loop's, quadctl.pipeline.estimator_of")
            values.update(Ae=kal.A, Be=kal.B, Le=kal.gain)
        form = self.filter_form
        if form is not None:
            values.update(filter_A=form.A, filter_b=form.b, filter_c=form.c, filter_d=[form.d])
        return pack_constants(*self.constant_layout, **values, **self.gain_constants())

    @property
    def constant_layout(self) -> tuple[int, bool, bool, int, tuple[int, ...], int, int]:
        """``(nz, rotors, lag_model, ny, schedule, law, filter_order)``: the arguments of
        :func:`quadctl.sim.loop_layout.constant_layout` that give the layout of :meth:`constants`."""
        return (len(self.integral_states), self.rotor_time_constant is not None, self.Kv is not None,
                len(self.measured), self.schedule_shape, len(self.law.values) if self.law is not None else 0,
                self.rate_filter.order if self.rate_filter is not None else 0)

    @property
    def schedule_degree(self) -> int:
        """The highest power of the schedule's pieces with a nonzero coefficient (0 without a schedule)."""
        table = self.schedule
        if table is None:
            return 0
        nonzero = [k for k in range(4) if np.any(table.coefficients[k] != 0)]
        return 3 - nonzero[0] if nonzero else 0

    @property
    def schedule_shape(self) -> tuple[int, ...]:
        """``(pieces, columns)`` of the gain schedule (empty without one)."""
        table = self.schedule
        return () if table is None else (len(table.breaks) - 1, table.coefficients.shape[-1])

    def gain_constants(self) -> dict[str, np.ndarray]:
        """The entries of :meth:`constants` that the gains set: :func:`gain_constants` of this loop alone
        (:func:`quadctl.sim.loop_layout.fill_constants` writes them into a copy of another loop's)."""
        return {name: value[0] for name, value in gain_constants([self]).items()}

    def heading_offset(self, x_ref) -> np.ndarray:
        """(n,) rad: the yaw of each reference state ``x_ref`` (n, 12) less the yaw its gain was designed
        at (the trim's; a yaw schedule's value held to its ends): the angle the law turns the position
        error by (:func:`quadctl.sim.builder.heading_frame`)."""
        psi = np.asarray(x_ref, dtype=float)[..., STATE_INDEX["psi"]]
        table = self.schedule
        if table is not None and table.variable == "yaw":
            return psi - np.clip(psi, table.breaks[0], table.breaks[-1])
        return psi - self.x_trim[STATE_INDEX["psi"]]

    def initial_loop_state(self, x0) -> np.ndarray:
        """The loop state ``[x0; f; z; l; s; b; g; xh]`` a run starts from: the rotors (if they lag) at their
        trim thrusts ``mix u_trim``, the integrators and the lag model (deviation from trim) at zero, a PID
        cascade's states (:func:`quadctl.sim.pid.initial_states`), the delay's buffer at the trim input, the
        gyro filter at rest."""
        parts = [np.asarray(x0, dtype=float)]
        if self.rotor_time_constant is not None:
            parts.append(self.actuators.commands(self.u_trim))
        parts.append(np.zeros(len(self.integral_states) + (len(self.u_trim) if self.Kv is not None else 0)))
        if self.law is not None:

            parts.append(initial_states(self.law, x0, self.u_trim))
        parts.append(np.tile(np.asarray(self.u_trim, dtype=float), self.delay_samples))
        parts.append(np.zeros(3 * self.rate_filter.order if self.rate_filter is not None else 0))
        parts.append(np.zeros(self.estimator.n_estimate if self.estimator is not None else 0))
        return np.concatenate(parts)

    def bounds(self, duration: float, reference=None) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the loop state ``[x; f; z]`` past which a run stops (:data:`RUNAWAY`).

        Positions drift with the reference: they are bounded around its farthest point (a flown
        ``reference``, :class:`quadctl.physics.reference_rows.FlownReference`: its extent); rotor
        thrusts and integrators are unbounded (a NaN still stops the run).
        """
        bound = np.array([RUNAWAY[s] for s in STATE_NAMES])
        lo, hi = self.x_trim - bound, self.x_trim + bound
        theta = STATE_INDEX["theta"]
        lo[theta], hi[theta] = -VALID_PITCH, VALID_PITCH
        drift = np.abs(self.x_rate) * duration
        if reference is not None:
            low, high = reference.position_range(duration)
            drift = np.zeros(N_STATES)
            lo[:3], hi[:3] = low - bound[:3], high + bound[:3]
        free = len(self.initial_loop_state(self.x_trim)) - N_STATES
        return (np.concatenate([lo - drift, np.full(free, -np.inf)]),
                np.concatenate([hi + drift, np.full(free, np.inf)]))


def rotor_eigenvalues(time_constant: float | None) -> np.ndarray:
    """The rotor lag's four eigenvalues ``-1/tau`` (rad/s), for the RK4 step; none without a lag."""
    if time_constant is None:
        return np.zeros(0)
    return np.full(4, -1.0 / time_constant)


def gain_constants(loops) -> dict[str, np.ndarray]:
    """The entries of :meth:`ClosedLoop.constants` that the gains set (``K``, a cascade's ``law`` and the thrust
    curve its PWM flies, which is the preset's when the vehicle has none,
    ``Ki`` and its anti-windup pattern, ``Kv``, a gain schedule's table), each stacked over ``loops``
    (one structure): all that differs between two loops of one structure
    (:func:`quadctl.sim.loop_layout.fill_constants_stack` writes them into copies of one's constants)."""
    first = loops[0]
    out = {"K": np.stack([loop.K for loop in loops])}
    if first.law is not None:
        out["law"] = np.array([loop.law.values for loop in loops], dtype=float)
        out["thrust_curve"] = np.array([pwm_thrust_curve(loop.law, loop.actuators) for loop in loops])
    nz = len(first.integral_states)
    if nz:
        Ki = np.array([loop.Ki for loop in loops], dtype=float).reshape(len(loops), len(first.u_trim), nz)
        out.update(Ki=Ki, antiwindup=(Ki.transpose(0, 2, 1) != 0).astype(float))
    if first.Kv is not None:
        out.update(Kv=np.stack([loop.Kv for loop in loops]))
    if first.schedule is not None:
        tables = [loop.schedule for loop in loops]
        coefficients = np.stack([table.coefficients for table in tables])
        out.update(schedule_heading=np.array([[loop.schedule_heading] for loop in loops]),
                   schedule_breaks=np.stack([table.breaks for table in tables]), schedule_coefficients=coefficients)
        if nz and coefficients.shape[-1] > N_STATES:  # the integrators the table's Ki drives
            out["antiwindup"] = np.any(coefficients[..., N_STATES:] != 0, axis=(1, 2)).transpose(0, 2, 1).astype(float)
    return out
