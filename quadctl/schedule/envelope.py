"""A gain schedule across the envelope: trim and design at each value of one variable (no I/O).

:func:`schedule_of` is the entry point: each value's flight condition (:func:`point_setup`) trimmed,
linearized and decoupled by the one chain of stages, the designs batched as a sweep's, the gains
made a :class:`~quadctl.design.gain_table.GainTable` and checked at frozen points on a finer grid
(:class:`FrozenChecks`); ``schedule_of(setup).table`` is what a loop flies. See
docs/guide/scheduling.md.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from quadctl import pipeline
from quadctl.design import linear_loop
from quadctl.design.discrete import c2d_batch
from quadctl.design.gain_table import OUTSIDE, VARIABLES, GainTable, flight_value
from quadctl.errors import ConfigError, QuadctlError, ScheduleError, TrimError
from quadctl.layout import N_INPUTS, N_STATES
from quadctl.linear import stability
from quadctl.linear.linearize import LinearModel, linearize_all
from quadctl.linear.trim import Trim, solve_trims
from quadctl.physics.motors import check_trim
from quadctl.setup import Setup
from quadctl.threads import one_thread


@dataclass(frozen=True)
class SchedulePoint:
    """One scheduling value: its trim and design, or why it has none.

    Attributes
    ----------
    value : float
        The scheduling variable's value (its unit: :data:`~quadctl.design.gain_table.VARIABLES`).
    velocity_ned : (3,) tuple of float
        m/s, the flight condition trimmed at (NED).
    yaw : float
        rad.
    trim : Trim or None
        None when no trim exists (``reason`` says why).
    linear : LinearModel or None
    K : (4, 12) ndarray or None
        The block gain, columns in ``STATE_NAMES`` order (``design.json``'s ``K_block``).
    Ki : (4, nz) ndarray or None
        The integrator gains (columns: :attr:`Schedule.integral_states`).
    stable : bool
        The design's closed loop on the coupled model is stable (marginal positions left out).
    core_eigenvalues : (k,) ndarray
        That loop's eigenvalues without the marginal modes (s, rad/s).
    actuator_commands : (4,) ndarray or None
        The trim's actuator commands (N per rotor with ``motors:``; the inputs with ``limits:``);
        None without actuators.
    reason : str or None
        Why the point has no trim or no design (None: it has both).
    """

    value: float
    velocity_ned: tuple[float, float, float]
    yaw: float
    trim: Trim | None = None
    linear: LinearModel | None = None
    K: np.ndarray | None = None
    Ki: np.ndarray | None = None
    stable: bool = False
    core_eigenvalues: np.ndarray | None = None
    actuator_commands: np.ndarray | None = None
    reason: str | None = None

    @property
    def trimmed(self) -> bool:
        return self.trim is not None

    @property
    def designed(self) -> bool:
        return self.K is not None


@dataclass(frozen=True)
class FrozenChecks:
    """The table's interpolated gains, each closed on the model frozen at its value.

    Attributes
    ----------
    values : (k,) ndarray
        The fine grid: each interval between the table's values split into ``check`` (the table's
        values included).
    stable : (k,) bool ndarray
        The frozen loop is stable (:func:`quadctl.linear.stability.verdict_stack`); False where no trim.
    eigenvalues : (k, n) complex ndarray
        Every eigenvalue of each frozen loop, as ``s`` (rad/s; ``ln z / Ts`` of a discrete design's
        loop); NaN where no trim.
    slowest : (k,) ndarray
        The largest real part of the loop's eigenvalues, marginal positions left out (rad/s): the
        slowest pole, positive when unstable; NaN where no trim.
    least_damping : (k,) ndarray
        :func:`quadctl.linear.stability.least_damping` of the same eigenvalues; NaN where no trim.
    worst : (k,) complex ndarray
        The eigenvalue with that largest real part; NaN where no trim.
    reasons : tuple of (str or None)
        Why a fine value has no trim (None where it trims).
    refinement : int
        Parts each interval between the table's values is split into (``schedule.check``).
    """

    values: np.ndarray
    stable: np.ndarray
    eigenvalues: np.ndarray
    slowest: np.ndarray
    least_damping: np.ndarray
    worst: np.ndarray
    reasons: tuple
    refinement: int = 1

    @property
    def passed(self) -> bool:
        return bool(np.all(self.stable))


@dataclass(frozen=True)
class Schedule:
    """A gain schedule: its points, the table of their gains, and the frozen-point checks.

    Attributes
    ----------
    variable : str
        ``speed``, ``climb`` or ``yaw``.
    unit : str
        The variable's unit.
    heading : float
        rad from north: the direction ``speed`` is measured along (the trim velocity's horizontal
        direction, or ``trim.yaw`` at hover); what :func:`quadctl.design.gain_table.scheduling_value`
        takes to read the variable from a state.
    interpolation : str
    outside : str
        What the table gives outside its values (:data:`~quadctl.design.gain_table.OUTSIDE`).
    points : tuple of SchedulePoint
        One per ``schedule.values`` entry, in order.
    table : GainTable
        The gains of the points that trim and design, ``[K, Ki]`` (4, 12 + nz) each.
    checks : FrozenChecks
    integral_states : tuple of str
        The states the integrators integrate (the table's columns after the 12 states).
    sample_time : float or None
        s of a discrete design (its gains, its loops); None: continuous.
    own_value : float
        The config's own flight condition's value of the variable.
    """

    variable: str
    unit: str
    heading: float
    interpolation: str
    outside: str
    points: tuple[SchedulePoint, ...]
    table: GainTable
    checks: FrozenChecks
    integral_states: tuple[str, ...]
    sample_time: float | None
    own_value: float

    @property
    def envelope(self) -> tuple[float, float]:
        """(lowest, highest) value of the table: the range that trims and designs."""
        return float(self.table.values[0]), float(self.table.values[-1])

    @property
    def jacobians(self) -> tuple[np.ndarray, np.ndarray]:
        """``(A, B)``, (P, 12, 12) and (P, 12, 4): the model linearized at each of the table's values
        (the points that designed), for :func:`quadctl.pipeline.scheduled_loop`."""
        good = [p for p in self.points if p.designed]
        return np.stack([p.linear.A for p in good]), np.stack([p.linear.B for p in good])

    def flown_by(self, loop):
        """``loop`` (:class:`quadctl.sim.loop.ClosedLoop`) flying this schedule: its table along its heading,
        its frozen loops held by the RK4 step, its Jacobians ETDRK4's linear parts
        (:func:`quadctl.pipeline.scheduled_loop`)."""
        return pipeline.scheduled_loop(loop, self.table, self.heading, self.checks.eigenvalues, self.jacobians)

    @property
    def passed(self) -> bool:
        """Every point designed stable and every frozen-point check stable."""
        return self.checks.passed and all(p.stable for p in self.points if p.designed)

    @property
    def undesigned(self) -> tuple[SchedulePoint, ...]:
        """The points with no trim or design (each with its ``reason``): ``quadctl schedule`` and ``export``
        refuse a schedule with any (exit 2), ``simulate`` warns of them
        (:func:`quadctl.present.schedule.missing`)."""
        return tuple(p for p in self.points if not p.designed)

    @property
    def unstable_points(self) -> tuple[SchedulePoint, ...]:
        """The points designed but unstable on the coupled model. With the frozen-point checks that fail, why
        the schedule fails (:attr:`passed`; in words: :func:`quadctl.present.schedule.verdict`)."""
        return tuple(p for p in self.points if p.designed and not p.stable)


def heading_of(setup: Setup) -> float:
    """rad from north: the trim velocity's horizontal direction, or ``trim.yaw`` at hover."""
    vn, ve, _ = setup.velocity_ned
    return float(np.arctan2(ve, vn)) if (vn or ve) else float(setup.yaw)


def point_setup(setup: Setup, value: float, heading: float | None = None) -> Setup:
    """``setup`` flying ``value`` of its schedule's variable (the other flight conditions kept)."""
    variable = setup.schedule.variable
    vn, ve, vd = setup.velocity_ned
    if variable == "speed":
        h = heading_of(setup) if heading is None else heading
        return replace(setup, velocity_ned=(float(value * np.cos(h)), float(value * np.sin(h)), vd))
    if variable == "climb":
        return replace(setup, velocity_ned=(vn, ve, 0.0 - float(value)))
    return replace(setup, yaw=float(value))


def own_value(setup: Setup, heading: float) -> float:
    """The config's own flight condition's value of the scheduling variable
    (:func:`~quadctl.design.gain_table.flight_value`, the rule the law reads from its reference)."""
    value = flight_value(setup.schedule.variable, np.asarray(setup.velocity_ned, dtype=float), setup.yaw, heading)
    return float(value) + 0.0  # no -0 in messages


def _flight_conditions(setups: list[Setup]) -> list:
    """Per setup (one config's, at different values of its variable): (Trim, LinearModel, actuator
    commands), or the trim stage's refusal (a TrimError, or the ActuatorLimitError of a trim outside
    the actuator limits). :func:`quadctl.pipeline.trim_of` and :func:`~quadctl.pipeline.linear_of` of
    every setup, batched (:func:`quadctl.linear.trim.solve_trims`: the same Newton, the same checks;
    :func:`quadctl.linear.linearize.linearize_all`: the same Jacobians)."""

    if not setups:
        return []
    base = setups[0]
    trims = solve_trims([s.velocity_ned for s in setups], [s.yaw for s in setups], base.position_ned,
                        base.vehicle, wind_ned=base.trim_wind)
    out: list = []
    for ps, trim in zip(setups, trims):
        if not isinstance(trim, TrimError):
            try:
                check_trim(ps.actuators, trim.u)
            except ConfigError as exc:
                trim = exc
        out.append(trim)
    flown = [k for k, trim in enumerate(out) if isinstance(trim, Trim)]
    linear = linearize_all([out[k].x for k in flown], [out[k].u for k in flown], base.vehicle, base.trim_wind)
    for k, lin in zip(flown, linear):  # pipeline.linear_of of each, in one call
        act = None if base.actuators is None else base.actuators.commands(out[k].u)
        out[k] = (out[k], lin, act)
    return out


def schedule_of(setup: Setup) -> Schedule:
    """The gain schedule of a setup whose config has ``schedule:``.

    Parameters
    ----------
    setup : Setup
        With :attr:`~quadctl.setup.Setup.schedule`.

    Returns
    -------
    Schedule

    Raises
    ------
    ScheduleError
        (a ConfigError) No ``schedule:`` section; a design that includes the rotors' lag; fewer than two values
        trim and design; the config's own flight condition outside the envelope (each names the
        key and the fix: exit 2).

    Examples
    --------
    >>> from quadctl import config
    >>> from quadctl.setup import setup_of
    >>> cfg = config.load("hover").model_copy(update={"schedule": config.ScheduleConfig(
    ...     variable="speed", values=[0, 1, 2])})
    >>> sched = schedule_of(setup_of(cfg))
    >>> sched.table.gains.shape, sched.envelope, sched.checks.passed
    ((3, 4, 12), (0.0, 2.0), True)
    """
    with one_thread():
        return _schedule(setup)


def _schedule(setup: Setup) -> Schedule:
    spec = setup.schedule
    if spec is None:
        raise ScheduleError("schedule: missing; add a schedule section (schedule: {variable: speed, values: "
                            "[0, 1, 2]}) to trim and design across the envelope")
    if setup.design_lag_time_constant is not None:
        raise ScheduleError("controller.rotor_lag = include: a gain schedule tables the state and integrator "
                            "gains only; set controller.rotor_lag: ignore to schedule this design")
    heading = heading_of(setup)
    values = [float(v) for v in spec.values]
    points, ints = _points(setup, values, heading)
    good = [p for p in points if p.designed]
    unit = VARIABLES[spec.variable]
    if len(good) < 2:
        bad = [p for p in points if not p.designed]
        raise ScheduleError(f"schedule.values: {len(good)} of {len(values)} values trim and design, a schedule needs "
                            f"two (at {bad[0].value:g} {unit}: {bad[0].reason}); narrow schedule.values to the "
                            "envelope the vehicle can fly")
    own = own_value(setup, heading)
    if not good[0].value <= own <= good[-1].value:
        key = {"speed": "trim.velocity_ned", "climb": "trim.velocity_ned", "yaw": "trim.yaw"}[spec.variable]
        raise ScheduleError(f"schedule.values: the config's own flight condition ({key}: {spec.variable} {own:g} "
                            f"{unit}) is outside the envelope that trims, [{good[0].value:g}, {good[-1].value:g}] "
                            f"{unit}; list values around {own:g} {unit} in schedule.values, or change {key}")
    gains = np.stack([np.hstack([p.K, p.Ki]) for p in good])
    table = GainTable.of(spec.variable, [p.value for p in good], gains, spec.interpolation)
    Ts = setup.timing.design_sample_time
    checks = frozen_checks(setup, table, ints, spec.check, heading, {p.value: p for p in good}, Ts)
    return Schedule(variable=spec.variable, unit=unit, heading=heading, interpolation=spec.interpolation,
                    outside=OUTSIDE, points=tuple(points), table=table, checks=checks, integral_states=ints,
                    sample_time=Ts, own_value=own)


def _points(setup: Setup, values: list[float], heading: float) -> tuple[list[SchedulePoint], tuple[str, ...]]:
    """Each value trimmed, linearized, decoupled, and all designed together (batched); and the
    states the designs integrate (the columns of ``Ki``, the same for every point)."""
    # the sweep's package brings its runner's processes and its figures: loaded when a schedule is designed,
    # not by every command that reads a schedule (simulate, export)
    from quadctl.sweep import batched
    from quadctl.sweep.prepare import Plant, Prepared


    points: list[SchedulePoint] = []
    preps, where = [], []
    setups = [point_setup(setup, value, heading) for value in values]
    for value, ps, found in zip(values, setups, _flight_conditions(setups)):
        base = SchedulePoint(value=value, velocity_ned=ps.velocity_ned, yaw=ps.yaw)
        if isinstance(found, QuadctlError):
            points.append(replace(base, reason=str(found)))
            continue
        trim, linear, act = found
        points.append(replace(base, trim=trim, linear=linear, actuator_commands=act))
        preps.append(Prepared(len(preps), {}, ps, Plant(linear, pipeline.decoupled_of(ps, linear))))
        where.append(len(points) - 1)
    stats = {"designs": 0, "fallbacks": 0}
    ints: tuple[str, ...] = ()
    for k, des in zip(where, batched.design_all(preps, stats)):
        if isinstance(des, str):
            points[k] = replace(points[k], reason=des)
        else:
            points[k] = replace(points[k], K=des.K_block, Ki=des.Ki_block, stable=bool(des.stable),
                                core_eigenvalues=des.core)
            ints = des.integral_states
    return points, ints


def fine_values(values, check: int) -> np.ndarray:
    """Each interval between ``values`` split into ``check`` equal parts, the values included:
    ``(len(values) - 1) * check + 1`` increasing values."""
    values = np.asarray(values, dtype=float)
    steps = np.arange(check) / check
    inner = (values[:-1, None] + np.diff(values)[:, None] * steps).ravel()
    return np.append(inner, values[-1])


def frozen_checks(setup: Setup, table: GainTable, integral_states, check: int, heading: float,
                  known: dict | None = None, sample_time: float | None = None) -> FrozenChecks:
    """The table's gains interpolated on a grid ``check`` times finer, each closed on the model
    trimmed and linearized at its value (frozen), and judged.

    Parameters
    ----------
    setup : Setup
        With ``schedule``.
    table : GainTable
        Gains ``[K, Ki]`` (n, 4, 12 + nz).
    integral_states : tuple of str
    check : int
        Parts each interval is split into.
    heading : float
        rad (:func:`heading_of`).
    known : dict, optional
        value -> :class:`SchedulePoint` whose linear model is reused (the table's own points).
    sample_time : float, optional
        s: the gains are a discrete design's, closed on the zero-order hold of each model.

    Returns
    -------
    FrozenChecks
    """
    known = known or {}
    fine = fine_values(table.values, check)
    nz = len(integral_states)
    n = N_STATES + nz
    A = np.zeros((len(fine), N_STATES, N_STATES))
    B = np.zeros((len(fine), N_STATES, N_INPUTS))
    reasons: list = [None] * len(fine)
    new = [i for i, v in enumerate(fine) if float(v) not in known]
    for i, v in enumerate(fine):
        if float(v) in known:
            A[i], B[i] = known[float(v)].linear.A, known[float(v)].linear.B
    for i, found in zip(new, _flight_conditions([point_setup(setup, fine[i], heading) for i in new])):
        if isinstance(found, QuadctlError):
            reasons[i] = str(found)
            continue
        A[i], B[i] = found[1].A, found[1].B
    G = table.at(fine)
    K, Ki = G[:, :, :N_STATES], G[:, :, N_STATES:]
    if sample_time is not None:

        A, B = c2d_batch(A, B, sample_time)
    A_cl = linear_loop.stack(A, B, K, Ki, tuple(integral_states), sample_time)
    trimmed = np.array([r is None for r in reasons])
    stable = np.zeros(len(fine), bool)
    eig = np.full((len(fine), n), np.nan, complex)
    slowest = np.full(len(fine), np.nan)
    damping = np.full(len(fine), np.nan)
    worst = np.full(len(fine), np.nan, complex)
    rows = np.nonzero(trimmed)[0]
    if rows.size:
        all_eig = np.linalg.eigvals(A_cl[rows])
        for j, i in enumerate(rows):
            e = all_eig[j]
            eig[i] = stability.s_plane(e, sample_time)
        for i, (core, _, ok) in zip(rows, stability.verdict_stack(A_cl[rows], K[rows], sample_time=sample_time)):
            stable[i] = ok
            k = int(np.argmax(core.real))
            worst[i], slowest[i] = core[k], core[k].real
            damping[i] = stability.least_damping(core)
    return FrozenChecks(values=fine, stable=stable, eigenvalues=eig, slowest=slowest, least_damping=damping,
                        worst=worst, reasons=tuple(reasons), refinement=check)
