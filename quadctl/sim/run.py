"""Simulation of the full nonlinear closed loop: RK4 at a fixed step, or ETDRK4
(``simulation.method: etdrk4``) on a graded schedule of steps (:mod:`quadctl.sim.etdrk4_plan`).

``u = u_ref(t) - K (x - x_ref(t))``: by default ``x_ref(t) = x_trim + x_rate t`` (positions drift at
the trim velocity) and ``u_ref = u_trim``; with ``simulation.reference`` the reference flown and its
feedforward; with a gain schedule ``K = G(v)`` (:mod:`quadctl.sim.builder`, "Gain schedule"). With
the integrators, sampling, saturation, noise and wind the loop has, run by
the engine of :mod:`quadctl.sim` (compiled where a C compiler works).

One entry runs a stack of cases by either integrator: :func:`stack_of` makes the
:class:`~quadctl.sim.cases.Cases` of the runs (RK4: a segment each, its step from
:mod:`quadctl.sim.plan`, :func:`rk4_cases`, which makes a sweep's lanes too from what the sweep
knows per case; ETDRK4: a segment per step of its schedule, :func:`exponential_stack`) and
:func:`run_stack` runs them; :func:`simulate_stack` is both for many loops in the SIMD lanes, and
:func:`simulate` the stack of one. A long run of one case goes in chunks so Ctrl-C stops it at once,
and noise and wind are drawn chunk by chunk (:class:`ExoStream`), so memory does not grow with the
duration.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from quadctl.design import linear_loop
from quadctl.design.gain_table import scheduling_value, scheduling_values
from quadctl.errors import TrimError
from quadctl.layout import N_STATES, PRODUCTS, STATE_INDEX, STATE_NAMES
from quadctl.metrics import MAX_SAMPLES
from quadctl.physics.noise import NoiseSpec, NoiseStream, exogenous_period
from quadctl.physics.wind import WindSpec, WindStream
from quadctl.sim.builder import LoopSpec, fill_constants_stack, heading_frame, pack_constants
from quadctl.sim.cases import Cases
from quadctl.sim.engine import LANES, runner
from quadctl.sim.etdrk4_plan import Segment, phi_constant_rows, phi_ladder, plan_schedule, record_strides
from quadctl.sim.pid import initial_states, structure_of
from quadctl.sim.plan import StepPlan, max_stable_steps, plan_held_step, plan_step, record_stride

if TYPE_CHECKING:  # the types of a loop's parts (their modules load only when a loop has one)
    from quadctl.config.pid import PidGains
    from quadctl.design.gain_table import GainTable
    from quadctl.design.kalman import Kalman
    from quadctl.linear.filters import RateFilter
    from quadctl.physics.motors import Actuators

VALID_PITCH = math.radians(85.0)
"""Beyond this pitch the Euler kinematics (``1/cos theta``) are near singular: the run stops."""
SETUPS_KEPT = 4
"""ETDRK4 stacks of one a loop keeps (:meth:`ClosedLoop.exponential_stack`): one per run settings, the latest."""
RUNAWAY = {"pN": 1e5, "pE": 1e5, "pD": 1e5, "u": 1e3, "v": 1e3, "w": 1e3,
           "phi": 1e3, "theta": VALID_PITCH, "psi": 1e3, "p": 1e4, "q": 1e4, "r": 1e4}
"""Bounds on |x - x_ref| (state units) past which a run counts as diverged; theta's is the model's range."""


def eigen_owners(A_cl, state_owner: dict[str, str], names=STATE_NAMES) -> tuple[np.ndarray, list[str]]:
    """Eigenvalues of ``A_cl`` and, for each, the subsystem of its eigenvector's largest state.

    ``names`` labels the rows of ``A_cl`` (default the 12 states; an LQI loop appends its
    integrators, each owned by the subsystem of the state it integrates).
    """
    eig, vec = np.linalg.eig(np.asarray(A_cl, dtype=float))
    owners = [state_owner.get(names[int(np.argmax(np.abs(vec[:, k])))], "unassigned")
              for k in range(len(eig))]
    return eig, owners


@dataclass(frozen=True)
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
        """``(A, B)`` of the design model at the trim, or ValueError naming how to build a loop with them."""
        if self.jacobians is None:
            raise ValueError("this ClosedLoop has no jacobians (A, B): build it with quadctl.pipeline.closed_loop_of")
        A, B = self.jacobians
        return np.asarray(A, dtype=float), np.asarray(B, dtype=float)

    def linear_part(self, point: int | None = None) -> np.ndarray:
        """The loop linearized at the reference in the loop state's order
        (:func:`quadctl.design.linear_loop.simulated`);
        ``point``: at the gain schedule's ``point``-th value instead, closed with the table's gains there
        (:attr:`schedule_jacobians`).

        Raises
        ------
        ValueError
            The loop was built without its ``jacobians`` (or ``schedule_jacobians``, for a ``point``).
        """

        A, B = self._jacobians()
        K, Ki = self.K, self.Ki
        if point is not None:
            if self.schedule_jacobians is None:
                raise ValueError("this ClosedLoop has no schedule_jacobians: build it with "
                                 "quadctl.pipeline.scheduled_loop and the schedule's points")
            A, B = (np.asarray(M[point], dtype=float) for M in self.schedule_jacobians)
            G = self.schedule.gains[point]
            K = G[:, :N_STATES]
            Ki = G[:, N_STATES:] if G.shape[1] > N_STATES else Ki
        act = self.actuators
        return linear_loop.simulated(A, B, K, Ki=Ki, integral_states=self.integral_states, Kv=self.Kv,
                                     lag_time_constant=self.lag_model_time_constant,
                                     rotor_time_constant=self.rotor_time_constant,
                                     mix=act.mix if act is not None else None, estimator=self.estimator,
                                     rate_filter=self.filter_form)

    def __getstate__(self):
        """The loop's fields (a pickle carries no kept stack: its runner's arrays are this process's)."""
        state = dict(self.__dict__)
        state.pop("_exponential_stacks", None)
        return state

    def exponential_stack(self, duration: float, dt="auto", *, tolerance: float | None = None,
                          max_samples: int = MAX_SAMPLES, reference=None, exo_period: float | None = None,
                          noise: bool = False, wind: bool = False) -> Stack:
        """:func:`exponential_stack` of this loop alone (from its trim: :meth:`Cases.starting` runs it from
        a state), kept with it (the :data:`SETUPS_KEPT` latest settings): a second run with the same
        settings computes no plan, φ-functions or constants again (nor marshals them for the runner).

        A :class:`~quadctl.physics.flatness.FlownReference` counts as the same when it flies the same
        path object, with the same steps (``jumps``) and parameters (its position range and, for a gain
        schedule, the pieces the plan is cut into are read from it).
        """
        key = (float(duration), dt if dt == "auto" else float(dt), tolerance, int(max_samples),
               exo_period, bool(noise), bool(wind),
               None if reference is None else (id(reference.path), tuple(reference.path.jumps),
                                                 np.asarray(reference.params).tobytes()))
        kept = self.__dict__.setdefault("_exponential_stacks", {})
        if key in kept:
            path, found = kept.pop(key)
            kept[key] = (path, found)  # the latest used last
            return found
        found = exponential_stack([self], [self.x_trim], duration, dt, tolerance=tolerance, max_samples=max_samples,
                                  reference=reference, exo_period=exo_period, noise=noise, wind=wind)
        kept[key] = (None if reference is None else reference.path, found)  # the path held: its id stays its own
        while len(kept) > SETUPS_KEPT:
            kept.pop(next(iter(kept)))
        return found

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
        ValueError
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
        """The law's structure baked into the code (:attr:`quadctl.sim.builder.LoopSpec.law`); empty: LQR."""
        if self.law is None:
            return ()

        return structure_of(self.law)

    @property
    def measured(self) -> tuple[str, ...]:
        """States the Kalman filter measures; empty without one."""
        return tuple(self.estimator.measured) if self.estimator is not None else ()

    def constants(self, sample_time: float | None = None) -> np.ndarray:
        """The constant vector ``c`` of this loop (:func:`quadctl.sim.builder.pack_constants`)."""
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
                raise ValueError("the Kalman filter's sample time must be the controller period (or both continuous)")
            if kal.rate_filter != self.rate_filter:
                raise ValueError("the Kalman filter's model must have the loop's gyro filter (controller.filters)")
            values.update(Ae=kal.A, Be=kal.B, Le=kal.gain)
        form = self.filter_form
        if form is not None:
            values.update(filter_A=form.A, filter_b=form.b, filter_c=form.c, filter_d=[form.d])
        return pack_constants(*self.constant_layout, **values, **self.gain_constants())

    @property
    def constant_layout(self) -> tuple[int, bool, bool, int, tuple[int, ...], int, int]:
        """``(nz, rotors, lag_model, ny, schedule, law, filter_order)``: the arguments of
        :func:`quadctl.sim.builder.constant_layout` that give the layout of :meth:`constants`."""
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
        (:func:`quadctl.sim.builder.fill_constants` writes them into a copy of another loop's)."""
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
        ``reference``, :class:`quadctl.physics.flatness.FlownReference`: its extent); rotor
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


@dataclass(frozen=True)
class SimResult:
    """A simulation run.

    Attributes
    ----------
    t : (N+1,) ndarray
        s.
    x : (N+1, 12) ndarray
    u : (N+1, 4) ndarray
        Applied input (after any saturation).
    x_ref : (N+1, 12) ndarray
        The reference the controller regulates to.
    dt : float
    status : str
        ``ok``, ``diverged`` or ``left_valid_range``.
    message : str
        One line on how the run ended.
    wall_time : float
        s spent integrating (excludes compilation).
    steps : int
        Steps taken (RK4's, or ETDRK4's over its schedule).
    stride : int
        Samples are every ``stride``-th step (and the last); see ``max_samples``. ETDRK4: of the
        largest step (:func:`quadctl.sim.etdrk4_plan.record_strides`), so samples are equally spaced.
    backend : str
        ``compiled`` or ``casadi`` (no C compiler).
    plan : StepPlan

    Examples
    --------
    >>> import quadctl as qc
    >>> stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    >>> run = qc.simulate(stages.loop, stages.loop.x_trim, 0.5)  # from the trim: it stays there
    >>> run.status, run.x.shape[1], run.u.shape[1], round(float(run.t[-1]), 9)
    ('ok', 12, 4, 0.5)
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    x_ref: np.ndarray
    dt: float
    status: str
    message: str
    wall_time: float
    backend: str
    plan: StepPlan
    steps: int
    stride: int
    z: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(N+1, nz) integrator states of an LQI controller."""
    rotor_thrust: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(N+1, 4) N: each rotor's thrust, when the rotors lag (``motors.time_constant``); else empty
    (an instantaneous rotor's thrust is the clipped command ``mix u``)."""
    noise_seed: int | None = None
    lag_model: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(N+1, 4) the controller's rotor lag model ``l`` (deviation of ``[T, A, E, R]`` from trim; N, N m)
    when the design includes the lag (``controller.rotor_lag: include``); else empty."""
    wind: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """(N+1, 3) m/s NED: the wind the plant felt over each recorded step (empty: still air)."""
    wind_seed: int | None = None
    """The turbulence's seed (None: no turbulence)."""
    x_hat: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(N+1, 12) the Kalman filter's estimate of ``x`` (``x_ref`` plus its deviation estimate) of an
    LQG loop; else empty. A held (sampled) loop records the a priori estimate ``x_hat[k|k-1]``:
    predicted at sample ``k - 1``, held over the steps up to and including sample ``k``'s time (the
    updated ``x_hat[k|k]`` the law acts on is not recorded), so ``x - x_hat`` at the samples has the
    a priori covariance ``P``. A continuous loop records the Kalman-Bucy estimate at each step."""
    u_ref: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    """(N+1, 4) the feedforward input the law used (a run that flies a reference); else empty (``u_trim``)."""

    @property
    def steps_per_second(self) -> float:
        return self.steps / self.wall_time if self.wall_time > 0 else math.inf


class ExoStream:
    """The exogenous rows of a run (:func:`quadctl.sim.builder.exo_layout`) on one clock, drawn in order.

    Row ``j`` holds over ``[j period, (j + 1) period)``: the noise's sample ``j``
    (:class:`quadctl.physics.noise.NoiseStream`), then the wind at ``t = j period``
    (:class:`quadctl.physics.wind.WindStream`). The clock is the noise's period, else the controller's, else
    :data:`quadctl.physics.noise.DEFAULT_PERIOD`: never the RK4 step, so a seed gives the same run at any ``dt``.
    """

    def __init__(self, noise: NoiseSpec | None, wind: WindSpec | None, rate: float | None = None,
                 reference=None):
        self.period = exogenous_period(noise.period if noise is not None else None, rate)
        self.noise = NoiseStream(noise) if noise is not None else None
        self.wind = WindStream(wind, self.period) if wind is not None else None
        self.reference = reference
        """:class:`quadctl.physics.flatness.FlownReference` whose rows end each row, or None."""

    def index(self, steps, dt: float) -> np.ndarray:
        """The row each absolute RK4 step of ``dt`` takes (as the runners count)."""
        return np.floor(np.asarray(steps, dtype=float) * dt / self.period + 1e-9).astype(np.int64)

    def samples(self, first: int, last: int) -> np.ndarray:
        """Rows ``first .. last`` (inclusive); ``first`` never goes back before an earlier call's (the stack
        of one of :meth:`samples_of`).

        Raises
        ------
        TrimError
            The reference's path needs an attitude beyond the model's.
        """
        (got,) = ExoStream.samples_of([self], [(first, last)])
        if isinstance(got, TrimError):
            raise got
        return got

    @staticmethod
    def samples_of(streams, spans) -> list:
        """:meth:`samples` of many streams (``spans``: each one's ``(first, last)``), their references'
        rows tabulated together (:meth:`quadctl.physics.flatness.FlownReference.rows_of`, the rows each
        has alone): per stream its rows, or the TrimError refusing its reference."""
        parts: list = [[] for _ in streams]
        flying: dict[type, list] = {}  # the references' kind -> the streams that fly one
        for k, (stream, (first, last)) in enumerate(zip(streams, spans)):
            if stream.noise is not None:
                parts[k].append(stream.noise.samples(first, last))
            if stream.wind is not None:
                parts[k].append(stream.wind.samples(first, last))
            if stream.reference is not None:
                flying.setdefault(type(stream.reference), []).append(k)
        for kind, members in flying.items():
            tabulated = kind.rows_of([streams[k].reference for k in members],
                                     [np.arange(spans[k][0], spans[k][1] + 1) for k in members],
                                     [streams[k].period for k in members])
            for k, got in zip(members, tabulated):
                parts[k] = got if isinstance(got, TrimError) else [*parts[k], got]
        return [part if isinstance(part, TrimError) else np.hstack(part) for part in parts]

    def span(self, k0: int, m: int, dt: float) -> tuple[int, int]:
        """(first, last): the rows covering RK4 steps ``k0 .. k0 + m - 1`` of ``dt``."""
        first, last = (int(j) for j in self.index([k0, k0 + max(m, 1) - 1], dt))
        return first, last

    def rows(self, k0: int, m: int, dt: float) -> tuple[int, np.ndarray]:
        """(first row index, rows) covering RK4 steps ``k0 .. k0 + m - 1`` of ``dt``."""
        first, last = self.span(k0, m, dt)
        return first, self.samples(first, last)


def wind_felt(wind: WindSpec, period: float, ks, dt: float, block: int = 256) -> np.ndarray:
    """(len(ks), 3) m/s NED: the wind the plant felt over each absolute step in ``ks`` (increasing) of
    a run whose exogenous clock has ``period`` s; a fresh stream, ``block`` steps at a time (memory
    bounded by a block's span)."""
    stream = WindStream(wind, period)
    ks = np.asarray(ks)
    out = np.empty((len(ks), 3))
    for a in range(0, len(ks), block):
        j = np.floor(ks[a:a + block].astype(float) * dt / period + 1e-9).astype(np.int64)
        out[a:a + block] = stream.samples(int(j[0]), int(j[-1]))[j - j[0]]
    return out


def simulate(loop: ClosedLoop, x0, duration: float, dt="auto", *,
             noise: NoiseSpec | None = None, wind: WindSpec | None = None,
             max_samples: int = MAX_SAMPLES, progress=None, reference=None, method: str = "rk4",
             tolerance: float | None = None, exo_rate: float | None = None) -> SimResult:
    """RK4 (or ETDRK4) of the nonlinear closed loop from ``x0`` for ``duration`` seconds.

    Parameters
    ----------
    loop : ClosedLoop
    x0 : (12,) array_like
        Initial state (integrators, if any, start at zero; lagging rotors at their trim thrust).
    duration : float
        s.
    dt : float or "auto"
        s; see :func:`quadctl.sim.plan.plan_step` (continuous control) or
        :func:`quadctl.sim.plan.plan_held_step` (``loop.rate``).
    noise : NoiseSpec, optional
        Process and sensor noise; the same spec gives the same run.
    wind : WindSpec, optional
        Steady wind, gusts and turbulence (:mod:`quadctl.physics.wind`); the same spec gives the same run.
    max_samples : int
        Samples kept, at most: every :func:`record_stride`-th step and the last.
    progress : callable, optional
        ``progress(done, total)``: called with the steps done and the steps in all after each
        chunk of the run (:func:`run_stack`), for a caller that shows how far a long run is.
    reference : FlownReference, optional
        A reference to fly (:class:`quadctl.physics.flatness.FlownReference`): ``x_ref(t)`` and the feedforward
        ``u_ref(t)`` in place of ``x_trim + x_rate t`` and ``u_trim``; ``SimResult.x_ref`` is then the
        reference the law used.
    method : {"rk4", "etdrk4"}
        ``etdrk4``: the exponential integrator on the loop's linear part (continuous feedback only;
        :mod:`quadctl.sim.etdrk4_plan`), ``dt: auto`` its graded schedule.
    tolerance : float, optional
        The error ETDRK4's ``dt: auto`` aims at; None: ``simulation.tolerance``'s default.
    exo_rate : float, optional
        Hz of the exogenous clock when there is no noise (:class:`ExoStream`; None: the controller's
        rate): loops of different rates flown with one ``exo_rate`` feel the same wind (ETDRK4's steps
        divide its period).

    Returns
    -------
    SimResult
        A diverging run stops at the first bad state and keeps everything before it.

    Examples
    --------
    The hover design, flown 3 s from its configured offset (0.5 m low, tilted and turned), is back
    at its altitude (``pD``, index 2) to well within a millimetre:

    >>> import quadctl as qc
    >>> stages = qc.Stages(qc.setup_of(qc.load_config("hover")))
    >>> loop = stages.loop
    >>> run = qc.simulate(loop, stages.setup.initial_state(loop.x_trim), 3.0)
    >>> run.status, float(run.x[0, 2] - loop.x_trim[2]), bool(abs(run.x[-1, 2] - loop.x_trim[2]) < 1e-4)
    ('ok', 0.5, True)
    """
    stack = stack_of([loop], [x0], duration, dt, method=method, noise=noise, wind=wind, max_samples=max_samples,
                     reference=reference, tolerance=tolerance, exo_rate=exo_rate)
    run = runner(stack.spec, 1)
    start = time.perf_counter()
    (done, t, xs, us), = run_stack(stack, run, progress)
    wall = time.perf_counter() - start
    exo = stack.exo
    return _result(loop, stack.plans[0], run.backend, t, xs, us, done, stack.strides[0], wall, stack.cases.lo[0],
                   stack.cases.hi[0], noise if exo is not None and exo.noise is not None else None,
                   wind if exo is not None and exo.wind is not None else None, exo, t, 1.0, reference, stack.spec)


def _result(loop: ClosedLoop, plan: StepPlan, backend: str, t, xs, us, done: int, stride: int, wall: float,
            lo, hi, noise, wind, exo, ks, dt: float, reference=None, spec: LoopSpec | None = None) -> SimResult:
    """The :class:`SimResult` of a run's recorded rows (``t`` s; the wind felt and the reference flown at
    steps ``ks`` of ``dt``); ``spec``: the loop's (its state layout), when the caller has it."""
    spec = loop.spec() if spec is None else spec
    nz, n_plant, n_lag, ne = spec.nz, spec.n_plant, spec.n_lag, spec.n_estimate
    u_ref = np.zeros((0, len(loop.u_trim)))
    if reference is None:
        x_ref = loop.x_trim + np.outer(t, loop.x_rate)
    else:
        x_ref, u_ref = reference.flown(reference.rows(exo.index(ks, dt), exo.period), t)
    status, message = verdict(xs[:, :N_STATES], t, done, plan.n_steps, lo, hi)
    return SimResult(t=t, x=np.ascontiguousarray(xs[:, :N_STATES]), u=us, x_ref=x_ref, dt=plan.dt,
                     status=status, message=message, wall_time=wall, backend=backend, plan=plan,
                     steps=done, stride=stride, z=np.ascontiguousarray(xs[:, n_plant:n_plant + nz]),
                     rotor_thrust=np.ascontiguousarray(xs[:, N_STATES:n_plant]),
                     noise_seed=noise.seed if noise is not None else None,
                     lag_model=np.ascontiguousarray(xs[:, n_plant + nz:n_plant + nz + n_lag]),
                     wind=wind_felt(wind, exo.period, ks, dt) if wind is not None else np.zeros((0, 3)),
                     wind_seed=wind.seed if wind is not None else None,
                     x_hat=_estimate(loop, x_ref, xs[:, xs.shape[1] - ne:xs.shape[1] - ne + N_STATES],
                                     reference is not None) if ne
                     else np.zeros((0, 0)),
                     u_ref=u_ref)


def _estimate(loop: ClosedLoop, x_ref: np.ndarray, deviation: np.ndarray, reference: bool) -> np.ndarray:
    """(n, 12) the filter's estimate of ``x``: ``x_ref`` plus its deviation estimate, which the filter of a
    loop flying a ``reference`` keeps in its heading frame (:func:`quadctl.sim.builder.heading_frame`):
    turned back."""
    if not reference:
        return x_ref + deviation
    return x_ref + heading_frame(deviation, -loop.heading_offset(x_ref), lib=np)


def _linear_pieces(loop: ClosedLoop, plan: StepPlan, strides, reference) -> list[tuple]:
    """``(segment, stride, point)``: the plan's segments with their record strides, a continuous gain
    schedule's cut where the schedule value nearest the commanded one changes (``point``: its index; at
    records only, so records stay equally spaced), each flown on the loop closed there; ``point`` None:
    on the loop's own linear part (fixed gains, a sampled controller's plant, or no schedule_jacobians).

    A step's linear part may be any matrix (the nonlinear remainder carries the difference) without
    costing the method its order; the nearest point's keeps the remainder free of the fast modes that
    the gains move (the rate loops), so the steps the plan grades by stay stable along the schedule.
    """

    table = loop.schedule
    if table is None or loop.rate is not None or loop.schedule_jacobians is None:
        return [(seg, stride, None) for seg, stride in zip(plan.schedule, strides)]
    values = np.asarray(table.values, dtype=float)
    if reference is None:  # the law's reference is the trim (drifting in position): one value
        v = scheduling_value(table.variable, np.asarray(loop.x_trim, dtype=float), loop.schedule_heading)
        point = int(np.argmin(np.abs(values - v)))
        return [(seg, stride, point) for seg, stride in zip(plan.schedule, strides)]
    starts = [np.arange(seg.k0, seg.k0 + seg.n, stride) for seg, stride in zip(plan.schedule, strides)]
    t = np.concatenate([ks * seg.dt for ks, seg in zip(starts, plan.schedule)])  # where a piece may start
    v = scheduling_values(table.variable, reference.exact(t)[0], loop.schedule_heading)  # one mapped call
    nearest_all = np.argmin(np.abs(v[:, None] - values[None, :]), axis=1)
    bounds = np.cumsum([0, *map(len, starts)])
    pieces = []
    for i, (seg, stride, ks) in enumerate(zip(plan.schedule, strides, starts)):
        nearest = nearest_all[bounds[i]:bounds[i + 1]]
        cuts = [0, *np.flatnonzero(np.diff(nearest)) + 1]
        for a, b in zip(cuts, [*cuts[1:], len(ks)]):
            k_end = seg.k0 + seg.n if b == len(ks) else int(ks[b])
            pieces.append((Segment(seg.dt, k_end - int(ks[a]), int(ks[a])), stride, int(nearest[a])))
    return pieces


def exponential_plan(loop: ClosedLoop, duration: float, dt="auto", *, tolerance: float | None = None,
                     reference=None, exo_period: float | None = None, linear_part=None,
                     max_stable_dt: float | None = None) -> tuple[np.ndarray, StepPlan]:
    """ETDRK4's linear part and steps for ``loop``: the closed loop's (:meth:`ClosedLoop.linear_part`)
    graded by its modes, steps dividing the exogenous period ``exo_period`` (s; None: no exogenous
    inputs); a sampled controller's plant (:meth:`ClosedLoop.plant_linear_part`) graded by the
    closed loop's modes, which move it, in segments that start on samples
    (:func:`quadctl.sim.etdrk4_plan.plan_schedule`). ``linear_part`` and RK4's ``max_stable_dt`` (which
    the plan reports), when the caller has them (a sweep computes them for many loops at once).

    Raises
    ------
    StepSizeError
        A given step a sampled controller's period does not hold whole, or a runaway plan.
    """

    kicks = reference.path.jumps if reference is not None else ()
    if loop.rate is not None:
        L, eig = loop.plant_linear_part(), np.asarray(loop.eigenvalues)
        owners = list(loop.owners) or ["loop"] * len(eig)
        plan = plan_schedule(eig, owners, duration, dt, tolerance=tolerance, period=1.0 / loop.rate,
                             forced=reference is not None, held=True, kicks=kicks)
        rk4 = loop.plan(duration, "auto")  # reported: RK4's limit on the plant between samples
        return L, replace(plan, max_stable_dt=rk4.max_stable_dt, fastest_eigenvalue=rk4.fastest_eigenvalue,
                          fastest_owner=rk4.fastest_owner)
    L = loop.linear_part() if linear_part is None else linear_part
    eig = np.linalg.eigvals(L)
    if loop.schedule is not None and loop.schedule_jacobians is not None:  # graded by every point's modes
        eig = np.concatenate([eig, np.linalg.eigvals(loop.point_linear_parts).ravel()])
    return L, plan_schedule(eig, ["loop"] * len(eig), duration, dt, tolerance=tolerance, period=exo_period,
                            forced=reference is not None, max_stable_dt=max_stable_dt, kicks=kicks)


@dataclass(frozen=True)
class Stack:
    """``N`` runs of loops of one structure ready for a runner (:func:`stack_of`): each case's step plan
    and record stride (of its largest step), the loops' generated code (``spec``), the
    :class:`~quadctl.sim.cases.Cases` (RK4: a segment each; ETDRK4: a segment per step of its graded
    schedule), and the exogenous inputs they all take (drawn when the stack runs: :func:`run_stack`)."""

    plans: tuple
    strides: tuple
    spec: LoopSpec
    cases: Cases
    exo: ExoStream | None = None


def stack_of(loops, x0s, duration: float, dt="auto", *, method: str = "rk4", noise: NoiseSpec | None = None,
             wind: WindSpec | None = None, max_samples: int = MAX_SAMPLES, reference=None,
             tolerance: float | None = None, exo_rate: float | None = None, planned=None) -> Stack:
    """The :class:`Stack` of runs of ``loops`` from ``x0s`` (the arguments of :func:`simulate`): one
    case is a stack of one (an ETDRK4 case from the setup its loop keeps,
    :meth:`ClosedLoop.exponential_stack`); more run in the SIMD lanes, each case stepping as its one-case
    run does (ETDRK4: the φ-functions of all the loops' linear parts computed on the stack of them).
    ``planned``: each loop's ``(L, StepPlan)`` of :func:`exponential_plan`, when the caller has them.

    Raises
    ------
    ValueError
        Loops of different structures or controller rates, or an unknown method.
    StepSizeError
        A step that a loop cannot take.
    """
    loops = list(loops)
    if method not in ("rk4", "etdrk4"):
        raise ValueError(f"method must be 'rk4' or 'etdrk4', got {method!r}")
    rate = loops[0].rate
    if len(loops) > 1:
        if len({loop.spec() for loop in loops}) > 1:
            raise ValueError("the lanes run loops of one structure (LoopSpec): group the loops by loop.spec()")
        if any(loop.rate != rate for loop in loops):
            raise ValueError("the lanes run loops of one controller rate: group the loops by loop.rate")
    noisy = noise is not None and noise.active
    windy = wind is not None and wind.active
    exo = (ExoStream(noise if noisy else None, wind if windy else None, exo_rate or rate, reference)
           if noisy or windy or reference is not None else None)
    exo_period = exo.period if exo is not None else None
    if method == "rk4":
        plans = [loop.plan(duration, dt) for loop in loops]
        cases = rk4_cases(loops, x0s, plans, [loop.bounds(duration, reference) for loop in loops],
                          max_samples=max_samples, exo_period=exo_period or 1.0)
        return Stack(tuple(plans), tuple(int(s) for s in cases.stride[0]),
                     loops[0].spec(noisy, windy, reference is not None), cases, exo)
    if len(loops) == 1 and planned is None:  # the loop's kept stack of one, from x0
        kept = loops[0].exponential_stack(duration, dt, tolerance=tolerance, max_samples=max_samples,
                                          reference=reference, exo_period=exo_period, noise=noisy, wind=windy)
        return replace(kept, cases=kept.cases.starting(loops[0].initial_loop_state(x0s[0])), exo=exo)
    stack = exponential_stack(loops, x0s, duration, dt, tolerance=tolerance, max_samples=max_samples,
                              reference=reference, exo_period=exo_period, noise=noisy, wind=windy, planned=planned)
    return replace(stack, exo=exo)


def gain_constants(loops) -> dict[str, np.ndarray]:
    """The entries of :meth:`ClosedLoop.constants` that the gains set (``K``, a cascade's ``law``,
    ``Ki`` and its anti-windup pattern, ``Kv``, a gain schedule's table), each stacked over ``loops``
    (one structure): all that differs between two loops of one structure
    (:func:`quadctl.sim.builder.fill_constants_stack` writes them into copies of one's constants)."""
    first = loops[0]
    out = {"K": np.stack([loop.K for loop in loops])}
    if first.law is not None:
        out["law"] = np.array([loop.law.values for loop in loops], dtype=float)
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


def rk4_cases(loops, x0s, plans, bounds, *, max_samples=MAX_SAMPLES, exo=None, exo_period=1.0,
              shared=None) -> Cases:
    """The RK4 :class:`~quadctl.sim.cases.Cases` of ``loops`` (one lane spec) from ``x0s``, for
    :func:`stack_of` and a sweep's lanes alike: a segment each, of its ``plans`` step (its hold, its
    record stride for ``max_samples``, one value or one a case), between its ``bounds`` ``(lo, hi)``.

    ``exo``: per case ``(first, rows, period)``, its exogenous rows drawn (None: none given, the rows
    of ``exo_period`` drawn when the stack runs, :func:`run_stack`). ``shared``: per case a key; the
    cases of one key are one loop but for its gains (:meth:`ClosedLoop.gain_constants`) from one
    ``x0``: its constants and initial loop state are computed once, each case's gains written into a
    copy (:func:`quadctl.sim.builder.fill_constants_stack`); None: each case's own.
    """
    N = len(loops)
    samples = np.broadcast_to(np.asarray(max_samples), (N,))
    strides = [record_stride(plan.n_steps, int(m)) for plan, m in zip(plans, samples)]
    keys = range(N) if shared is None else shared
    groups: dict = {}
    for i, (key, plan) in enumerate(zip(keys, plans)):
        groups.setdefault((key, plan.sample_time), []).append(i)
    C: list = [None] * N
    X0: list = [None] * N
    for members in groups.values():
        first = loops[members[0]]
        c = first.constants(plans[members[0]].sample_time)
        x = first.initial_loop_state(x0s[members[0]])
        if len(members) == 1:
            C[members[0]], X0[members[0]] = c, x
            continue
        rows = fill_constants_stack(np.repeat(c[None], len(members), axis=0), *first.constant_layout,
                                    **gain_constants([loops[i] for i in members]))
        for i, row in zip(members, rows):
            C[i], X0[i] = row, x
    rows = None if exo is None else [e[1] for e in exo]
    return Cases.of(np.stack(X0), np.stack(C), [plan.dt for plan in plans], [plan.n_steps for plan in plans],
                    strides, np.stack([b[0] for b in bounds]), np.stack([b[1] for b in bounds]),
                    hold=[max(plan.hold, 1) for plan in plans], exo=rows,
                    exo_first=0 if rows is None else [e[0] for e in exo],
                    exo_period=exo_period if rows is None else [e[2] for e in exo])


def exponential_stack(loops, x0s, duration: float, dt="auto", *, tolerance: float | None = None,
                      max_samples: int = MAX_SAMPLES, reference=None, exo_period: float | None = None,
                      noise: bool = False, wind: bool = False, planned=None) -> Stack:
    """The :class:`Stack` of ETDRK4 runs of ``loops`` of one structure from ``x0s`` (``noise``, ``wind``:
    the runs have them; ``exo_period``: s of their exogenous rows, None: none; no rows drawn): each
    case its own linear part and graded schedule (:func:`exponential_plan`, or ``planned``), a segment
    a step, each segment's constants the loop's, then the φ-functions of its step and linear part. A
    sampled controller's segments start on its samples; a gain schedule's continuous loop flies each
    stretch on the loop closed at the schedule value nearest the commanded one (:func:`_linear_pieces`).
    The loops whose schedules start at one step share a φ ladder, computed on the stack of their linear
    parts (each matrix as its one-case run computes it, from that step up); the lanes step through their
    schedules together (segment ``i`` of every case per call)."""
    from quadctl.sim.etdrk4_plan import phi_pattern

    rate = loops[0].rate
    held = rate is not None
    period = 1.0 / rate if held else exo_period
    Ls, plans = zip(*(planned or [exponential_plan(loop, duration, dt, tolerance=tolerance, reference=reference,
                                                   exo_period=exo_period) for loop in loops]))
    strides = [record_strides(plan, max_samples) for plan in plans]
    pieces = [_linear_pieces(loop, plan, st, reference) for loop, plan, st in zip(loops, plans, strides)]
    points = [sorted({p for _, _, p in case if p is not None}) for case in pieces]
    parts = [loop.point_linear_parts[pts] if pts else np.asarray(L, dtype=float)[None]  # each case's linear parts
             for loop, L, pts in zip(loops, Ls, points)]
    rung: dict[float, list[int]] = {}
    for i, plan in enumerate(plans):
        rung.setdefault(min(seg.dt for seg in plan.schedule), []).append(i)
    blocks: list = [None] * len(loops)  # per case: {step: its parts' φ blocks}, and its first row in them
    patterns = []
    for members in rung.values():
        ladder = phi_ladder(np.concatenate([parts[i] for i in members]),
                            [seg.dt for i in members for seg in plans[i].schedule])
        rows = {h: phi_constant_rows(mats) for h, mats in ladder.items()}
        patterns.append(phi_pattern(ladder))
        for i, first in zip(members, np.cumsum([0, *(len(parts[i]) for i in members)])):
            blocks[i] = (rows, int(first))
    spec = loops[0].spec(noise, wind, reference is not None, method="etdrk4",
                         phi_pattern=tuple(bool(b) for b in np.array(patterns).any(axis=0)))
    S = max(map(len, pieces))
    bounds = [loop.bounds(duration, reference) for loop in loops]
    base = [loop.constants(period if held else None) for loop in loops]

    def block(i, seg, point):
        rows, first = blocks[i]
        return np.concatenate([base[i], rows[seg.dt][first + (0 if point is None else points[i].index(point))]])

    def per_piece(value, empty):  # a piece a case does not have: no steps, its last piece's constants
        return [[value(i, *pieces[i][k]) if k < len(pieces[i]) else empty(i, *pieces[i][-1])
                 for i in range(len(loops))] for k in range(S)]

    cases = Cases.graded([loop.initial_loop_state(x0) for loop, x0 in zip(loops, x0s)],
                         np.array(per_piece(lambda i, seg, _, point: block(i, seg, point),
                                            lambda i, seg, _, point: block(i, seg, point))),
                         per_piece(lambda i, seg, *_: seg.dt, lambda i, seg, *_: seg.dt),
                         per_piece(lambda i, seg, *_: seg.n, lambda *_: 0),
                         per_piece(lambda i, seg, stride, _: stride, lambda *_: 1),
                         per_piece(lambda i, seg, *_: seg.k0, lambda *_: 0),
                         np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds]),
                         hold=per_piece(lambda i, seg, *_: round(period / seg.dt) if held else 1, lambda *_: 1),
                         exo_period=exo_period if exo_period is not None else 1.0)
    return Stack(tuple(plans), tuple(st[-1] for st in strides), spec, cases)


CHUNK_STEPS = {"compiled": 250_000, "casadi": 20_000}
"""Steps per call into the runner, by backend (~5 M and ~0.2 M steps/s): 0.05 to 0.1 s each, so
Python sees Ctrl-C between calls at once."""


def run_stack(stack: Stack, run, progress=None) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """The runs of ``stack`` by ``run`` (a runner of its spec, :func:`quadctl.sim.engine.runner`): per case
    ``(done, t, xs, us)``, steps completed, recorded times (s), loop states (r, nx) and inputs (r, 4).

    The exogenous rows are drawn for the whole run at once; a case alone longer than the runner's
    chunk (:data:`CHUNK_STEPS`) runs in chunks instead (:func:`_in_chunks`: Ctrl-C between them, the
    rows drawn as it goes). ``progress(done, total)``, if given, is called with a case alone's steps
    done after each call.
    """
    cases, exo = stack.cases, stack.exo
    total = int(cases.n[:, 0].sum())
    if len(cases) == 1 and total > CHUNK_STEPS.get(run.backend, CHUNK_STEPS["compiled"]):
        return [_in_chunks(run, cases, exo, progress)]
    if exo is not None:
        taken = cases.n > 0  # the rows through the last step of any segment
        rows = exo.samples(0, int(exo.index((cases.k0 + cases.n - 1)[taken], cases.dt[taken]).max(initial=0)))
        cases = cases.starting(cases.x0, exo=[rows] * len(cases))
    out = run.run(cases)
    if progress is not None and len(cases) == 1:
        progress(out[0][0], total)
    return out


def _in_chunks(run, cases: Cases, exo: ExoStream | None, progress=None):
    """``(done, t, xs, us)`` of the one case of ``cases``: segment after segment, each in chunks of
    :data:`CHUNK_STEPS` (whole controller periods, each starting on a sample), a chunk's exogenous rows
    drawn before it; a chunk's final record is the next one's start (kept once)."""
    chunk = CHUNK_STEPS.get(run.backend, CHUNK_STEPS["compiled"])
    total, n_all, last = 0, int(cases.n[:, 0].sum()), int(cases.last[0])
    x = cases.x0[0]
    parts: tuple[list, list, list] = ([], [], [])
    for s in range(last + 1):
        dt, hold, stride = float(cases.dt[s, 0]), int(cases.hold[s, 0]), int(cases.stride[s, 0])
        k0, end = int(cases.k0[s, 0]), int(cases.k0[s, 0] + cases.n[s, 0])
        step = max(hold, chunk // hold * hold)
        while k0 < end:
            m = min(step, end - k0)
            rows, first = None, 0
            if exo is not None:
                first, row = exo.rows(k0, m, dt)
                rows = [row]
            piece = Cases.of(x, cases.c[s, 0], dt, m, stride, cases.lo, cases.hi, hold=hold, k0=k0, exo=rows,
                             exo_first=first, exo_period=cases.exo_period[0])
            (done, t, xs, us), = run.run(piece)
            total += done
            if progress is not None:
                progress(total, n_all)
            final = done < m or (k0 + m >= end and s == last)
            keep = len(t) if final else len(t) - 1
            for part, got in zip(parts, (t, xs, us)):
                part.append(got[:keep])
            if final:
                return total, *(np.concatenate(p) for p in parts)
            x = xs[-1]
            k0 += m
    return total, *(np.concatenate(p) for p in parts)


def simulate_stack(loops, x0s, duration: float, dt="auto", *, method: str = "rk4", noise: NoiseSpec | None = None,
                   wind: WindSpec | None = None, max_samples: int = MAX_SAMPLES, reference=None,
                   tolerance: float | None = None, exo_rate: float | None = None,
                   planned=None) -> tuple[list[StepPlan], str, list]:
    """Runs of several loops of one structure from ``x0s``, as :func:`simulate` runs each (its arguments;
    the RK4 or ETDRK4 runs of :func:`stack_of`), in the SIMD lanes (:data:`quadctl.sim.engine.LANES` at a
    time; one case alone: the one-case loop). Every loop takes the same exogenous inputs: a
    ``reference`` (:class:`quadctl.physics.flatness.FlownReference`), noise and wind, tabulated once for the run.

    Returns
    -------
    (plans, backend, runs)
        Each loop's :class:`StepPlan`, the runner's backend, and per loop ``(done, t, xs, us)``: steps
        completed, recorded times (s), loop states (r, nx) and inputs (r, 4), as :func:`simulate`
        records them.

    Raises
    ------
    ValueError
        Loops of different structures or controller rates.

    Examples
    --------
    Three designs of the hover loop (gains scaled) in the lanes: each as its own run.

    >>> import numpy as np, quadctl as qc
    >>> from dataclasses import replace
    >>> from quadctl.sim.run import simulate_stack
    >>> loop = qc.Stages(qc.setup_of(qc.load_config("hover"))).loop
    >>> loops = [replace(loop, K=loop.K * k) for k in (0.8, 1.0, 1.2)]
    >>> plans, backend, runs = simulate_stack(loops, [loop.x_trim + 0.1] * 3, 0.5)
    >>> one = qc.simulate(loops[2], loop.x_trim + 0.1, 0.5)
    >>> bool(np.abs(runs[2][2][:, :12] - one.x).max() < 1e-12), len(runs)
    (True, 3)
    """

    stack = stack_of(loops, x0s, duration, dt, method=method, noise=noise, wind=wind, max_samples=max_samples,
                     reference=reference, tolerance=tolerance, exo_rate=exo_rate, planned=planned)
    run = runner(stack.spec, 1 if len(stack.cases) == 1 else LANES)
    return list(stack.plans), run.backend, run_stack(stack, run)


STATUS_WORDS = {"ok": "completed", "diverged": "diverged", "left_valid_range": "left the valid range"}
"""Each :func:`verdict` status in words, for a figure's legend or a summary line."""


def verdict(xs, t, done, n, lo, hi) -> tuple[str, str]:
    """(status, message) of a run: ``ok``, ``diverged`` or ``left_valid_range``."""
    if done == n:
        return "ok", f"completed {n} steps to t = {t[-1]:.6g} s"
    last = xs[-1]
    bad = [i for i in range(N_STATES) if not (lo[i] <= last[i] <= hi[i])]
    name = STATE_NAMES[bad[0]] if bad else "?"
    if not np.all(np.isfinite(last)):
        return "diverged", f"diverged at t = {t[-1]:.4g} s: {name} is not finite; saved {_steps(done)}"
    if name == "theta":
        return "left_valid_range", (
            f"left the model's valid range at t = {t[-1]:.4g} s: pitch {math.degrees(last[bad[0]]):.1f} deg "
            f"is beyond +-{math.degrees(VALID_PITCH):.0f} deg (Euler kinematics singular at 90); saved {_steps(done)}")
    return "diverged", (f"diverged at t = {t[-1]:.4g} s: {name} = {last[bad[0]]:.3g} ran away; "
                        f"saved {_steps(done)}")


def _steps(n: int) -> str:
    return f"{n} step" if n == 1 else f"{n} steps"


