"""The stages chained from a config: pure functions, no I/O.

Each takes the config (and upstream results) and returns the stage's result object.
"""

from __future__ import annotations

import numpy as np

from quadctl.analysis import Checks, check
from quadctl.config import Config, weight_matrix
from quadctl.decouple import Decoupled, decouple
from quadctl.layout import INPUT_NAMES, POSITION_STATES, STATE_INDEX, STATE_NAMES
from quadctl.linearize import LinearModel, linearize
from quadctl.lqr import Design, closed_loop_matrix, design
from quadctl.model import Vehicle
from quadctl.motors import Actuators, Motors, actuators_of, check_trim
from quadctl.noise import NoiseSpec
from quadctl.simulate import ClosedLoop, SimResult, eigen_owners, simulate
from quadctl.trim import Trim, solve_trim


def vehicle_of(cfg: Config) -> Vehicle:
    v = cfg.vehicle
    return Vehicle(mass=v.mass, gravity=v.gravity, inertia=tuple(v.inertia), drag=tuple(v.drag))


def trim_of(cfg: Config) -> Trim:
    t = cfg.trim
    return solve_trim(t.velocity_ned, t.yaw, t.position_ned, vehicle_of(cfg))


def linear_of(cfg: Config, trim: Trim) -> LinearModel:
    return linearize(trim.x, trim.u, vehicle_of(cfg))


def decoupled_of(cfg: Config, linear: LinearModel) -> Decoupled:
    return decouple(linear.A, linear.B, cfg.partition())


def checks_of(decoupled: Decoupled, linear: LinearModel) -> dict[str, Checks]:
    """Checks of every subsystem, then ``"full"`` for the 12-state model with all 4 inputs."""
    out = {s.name: check(s.A, s.B, s.C, s.states) for s in decoupled.subsystems}
    out["full"] = check(linear.A, linear.B, None, STATE_NAMES)
    return out


def weights_of(cfg: Config) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    return {name: (weight_matrix(w.Q, 0), weight_matrix(w.R, 0)) for name, w in cfg.lqr.items()}


def weights_block(cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """(Q_block (12, 12), R_block (4, 4)): the subsystems' weights on the plant states and inputs.

    An LQI subsystem's Q also weighs its integrators; only its plant-state block is kept here
    (the cost the metrics report is on the plant).
    """
    Q = np.zeros((len(STATE_NAMES),) * 2)
    R = np.zeros((len(INPUT_NAMES),) * 2)
    weights = weights_of(cfg)
    for name, sub in cfg.partition().items():
        if name in weights:
            si = [STATE_NAMES.index(s) for s in sub.states]
            ii = [INPUT_NAMES.index(i) for i in sub.inputs]
            Qw, Rw = weights[name]
            Q[np.ix_(si, si)] = Qw[:len(si), :len(si)]
            R[np.ix_(ii, ii)] = Rw
    return Q, R


def design_rate(cfg: Config) -> float | None:
    """Hz of a discrete design: ``controller.rate`` when ``controller.design`` is discrete, else None."""
    ctl = cfg.controller
    return ctl.rate if ctl.rate is not None and ctl.design == "discrete" else None


def integral_of(cfg: Config) -> dict[str, list[str]]:
    """``subsystem -> states`` with integral action (``lqr.<subsystem>.integral``)."""
    return {name: list(w.integral) for name, w in cfg.lqr.items() if w.integral}


def design_of(cfg: Config, decoupled: Decoupled, linear: LinearModel) -> Design:
    return design(decoupled, linear.A, linear.B, weights_of(cfg), rate=design_rate(cfg),
                  integral=integral_of(cfg))


def actuators_of_config(cfg: Config) -> Actuators | None:
    """Rotors (``motors:``), box limits (``limits:``), or None."""
    motors = Motors.from_config(cfg.motors) if cfg.motors is not None else None
    return actuators_of(motors, cfg.limits)


def plant_of(cfg: Config) -> Vehicle:
    """The simulated vehicle: ``vehicle:`` with ``simulation.plant`` overrides (model mismatch)."""
    base = vehicle_of(cfg)
    over = cfg.simulation.plant
    if over is None:
        return base
    return Vehicle(mass=over.mass or base.mass, gravity=over.gravity or base.gravity,
                   inertia=tuple(over.inertia) if over.inertia else base.inertia,
                   drag=tuple(over.drag) if over.drag is not None else base.drag)


def noise_of(cfg: Config) -> NoiseSpec | None:
    """``simulation.noise`` as a spec (None when absent)."""
    noise = cfg.simulation.noise
    return None if noise is None else NoiseSpec.from_config(noise, cfg.controller.rate)


def state_owner(cfg: Config) -> dict[str, str]:
    """State name -> the subsystem it belongs to."""
    return {s: name for name, sub in cfg.partition().items() for s in sub.states}


def reference_rate(trim: Trim) -> np.ndarray:
    """(12,) drift of the reference: the trim's position rates (its earth velocity)."""
    rate = np.zeros(len(STATE_NAMES))
    for s in POSITION_STATES:
        rate[STATE_INDEX[s]] = trim.xdot[STATE_INDEX[s]]
    return rate


def closed_loop_of(cfg: Config, linear: LinearModel, K: np.ndarray, x_rate: np.ndarray, *,
                   Ki: np.ndarray | None = None, integral_states=()) -> ClosedLoop:
    """The loop to simulate: the design's gains on the config's plant, rate, actuators.

    ``Ki`` (4, nz) and ``integral_states`` come from an LQI design (``Design.Ki_block``,
    ``Design.integral_states``). The eigenvalues (for the RK4 step) are those of the
    continuous closed loop including the integrators; a sampled controller steps on the
    open-loop plant's instead.
    """
    integral_states = tuple(integral_states)
    if integral_of(cfg) and not integral_states:
        raise ValueError("the config has integral action (lqr.<subsystem>.integral): pass Ki and "
                         "integral_states from the design, or call pipeline.loop_of(cfg, linear, design, x_rate)")
    A_cl = closed_loop_matrix(linear.A, linear.B, K, Ki, integral_states)
    names = (*STATE_NAMES, *integral_states)
    eig, owners = eigen_owners(A_cl, state_owner(cfg), names)
    actuators = actuators_of_config(cfg)
    check_trim(actuators, linear.u_trim)
    return ClosedLoop(params=plant_of(cfg).vector(), x_trim=linear.x_trim, u_trim=linear.u_trim,
                      x_rate=x_rate, K=K, eigenvalues=eig, owners=owners, rate=cfg.controller.rate,
                      Ki=Ki if integral_states else None, integral_states=integral_states,
                      actuators=actuators, open_loop_eigenvalues=np.linalg.eigvals(linear.A))


def initial_state(cfg: Config, x_trim: np.ndarray) -> np.ndarray:
    """Trim state plus the config's ``simulation.initial_offset``."""
    x0 = np.array(x_trim, dtype=float)
    for name, value in cfg.simulation.initial_offset.items():
        x0[STATE_INDEX[name]] += value
    return x0


def simulation_of(cfg: Config, loop: ClosedLoop) -> SimResult:
    sim = cfg.simulation
    return simulate(loop, initial_state(cfg, loop.x_trim), sim.duration, sim.dt, noise=noise_of(cfg),
                    max_samples=sim.max_samples)


# ---------------------------------------------------------------------------------------
# Flight: controller rate, motors, margins, integral action, noise, the full design (issue 5)


def loop_of(cfg: Config, linear: LinearModel, des: Design, x_rate: np.ndarray) -> ClosedLoop:
    """:func:`closed_loop_of` for a design: its state gain *and* its integrators (LQI)."""
    return closed_loop_of(cfg, linear, des.K_block, x_rate, Ki=des.Ki_block,
                          integral_states=des.integral_states)


def rate_warnings_of(cfg: Config, decoupled: Decoupled, linear: LinearModel, rate: float):
    """Loops of the *continuous* design that ``rate`` Hz cannot realize (``check``'s warning).

    Each subsystem (with its integrators) and the coupled loop are checked: the fastest
    continuous closed-loop pole against :func:`quadctl.discrete.realizable_frequency`, and the
    continuous gains run through a zero-order hold at ``rate`` (stable or not).

    Returns
    -------
    list of quadctl.discrete.RateWarning
    """
    from quadctl import discrete, integral

    des = design(decoupled, linear.A, linear.B, weights_of(cfg), integral=integral_of(cfg))
    Ts = 1.0 / rate
    loops = []
    for sub in des.subsystems:
        dsub = decoupled[sub.name]
        Ad, Bd = discrete.c2d(dsub.A, dsub.B, Ts)
        Aa, Ba = integral.augment_discrete(Ad, Bd, integral.selector(sub.states, sub.integral), Ts)
        Ka = np.hstack([sub.K, sub.Ki]) if sub.Ki is not None else sub.K
        loops.append((sub.name, sub.eigenvalues, Aa - Ba @ Ka))
    sampled = closed_loop_matrix(linear.A, linear.B, des.K_block, des.Ki_block, des.integral_states, Ts)
    keep = [i for i in range(sampled.shape[0])
            if i >= len(STATE_NAMES) or STATE_NAMES[i] not in des.marginal_states]
    core = [e for e in des.full_eigenvalues if abs(e) > 1e-9 or not des.marginal_states]
    loops.append(("coupled", core, sampled[np.ix_(keep, keep)]))
    return discrete.rate_warnings(loops, rate)


def initial_demand(cfg: Config, linear: LinearModel, des: Design) -> dict[str, float]:
    """``|K (x0 - x_trim)|`` per input: what the configured initial offset asks for at t = 0."""
    dx0 = initial_state(cfg, linear.x_trim) - linear.x_trim
    du = des.K_block @ dx0
    return {name: float(abs(du[j])) for j, name in enumerate(INPUT_NAMES)}


def flight_summary(cfg: Config, loop: ClosedLoop, sim: SimResult) -> dict:
    """What issue 5 adds to ``sim.json``: controller sampling, saturation, noise RMS, integrators.

    Returns
    -------
    dict
        ``controller`` (rate Hz, design kind, RK4 steps per sample), ``peak_delta`` (max |u - u_trim|
        per input), ``rms_error`` and ``rms_error_second_half`` (per state, state units),
        ``saturation`` (None without actuators; else per actuator the fraction of the run at a
        limit, ``saturates`` when one exceeds 1 %, peak commands, rotor speeds), ``noise``
        (seed and period, or None), ``integral`` (states and final integrator values), ``plant``
        (the simulated vehicle's parameters when they differ from the design model).
    """
    from quadctl import motors, noise

    duration = float(sim.t[-1]) if len(sim.t) else 0.0
    out: dict = {
        "controller": {"rate": cfg.controller.rate,
                       "design": (cfg.controller.design if cfg.controller.rate else "continuous"),
                       "hold_steps": sim.plan.hold, "sample_time": sim.plan.sample_time},
        "peak_delta": {name: float(np.abs(sim.u[:, j] - loop.u_trim[j]).max())
                       for j, name in enumerate(INPUT_NAMES)},
        "rms_error": noise.rms_deviation(sim.t, sim.x, sim.x_ref),
        "rms_error_second_half": noise.rms_deviation(sim.t, sim.x, sim.x_ref, duration / 2),
        "saturation": None, "noise": None,
        "integral": {"states": list(loop.integral_states),
                     "final": {s: float(sim.z[-1, i]) for i, s in enumerate(loop.integral_states)}},
        "plant": cfg.simulation.plant.model_dump(exclude_none=True) if cfg.simulation.plant else None,
    }
    act = loop.actuators
    if act is not None:
        fractions = motors.saturation_fraction(act, sim.u)
        commands = act.commands(sim.u)
        sat = {"mode": act.mode, "actuators": list(act.names), "fraction": fractions,
               "saturates": motors.saturates(fractions), "flag_above": motors.SATURATION_FLAG,
               "low": act.lo, "high": act.hi,
               "peak_command": {n: float(commands[:, i].max()) for i, n in enumerate(act.names)},
               "min_command": {n: float(commands[:, i].min()) for i, n in enumerate(act.names)}}
        if act.motors is not None:
            speeds = act.motors.speed(commands)
            sat["peak_rotor_speed"] = {n: float(speeds[:, i].max()) for i, n in enumerate(act.names)}
            sat["trim_rotor_thrust"] = list(act.commands(loop.u_trim))
        out["saturation"] = sat
    spec = noise_of(cfg)
    if spec is not None and spec.active:
        out["noise"] = {"seed": spec.seed, "period": spec.period, "process_std": spec.process_std,
                        "sensor_std": dict(zip(STATE_NAMES, spec.sensor_std))}
    return out


def compare_full(cfg: Config, linear: LinearModel, trim: Trim, des: Design):
    """``design --full``: one coupled LQR with the same cost, both simulated on the nonlinear model.

    Both runs start from the configured offset on the configured plant and actuators, *without*
    noise, so settling times and peaks measure the designs, not one noise realization.

    Returns
    -------
    (FullDesign, dict)
        The full design and :func:`quadctl.full.compare` of the two runs (``decoupled``, ``full``),
        with each run's metrics and status.
    """
    from quadctl import full
    from quadctl.metrics import summarize

    fd = full.full_design(des, linear.A, linear.B)
    x_rate = reference_rate(trim)
    dx0 = initial_state(cfg, linear.x_trim) - linear.x_trim
    regulated = [s for sub in cfg.partition().values() if sub.regulate for s in sub.states]
    Q = des.Q_block
    runs = {}
    for label, K, Ki in (("decoupled", des.K_block, des.Ki_block), ("full", fd.K, fd.Ki)):
        loop = closed_loop_of(cfg, linear, K, x_rate, Ki=Ki, integral_states=des.integral_states)
        sim = simulate(loop, initial_state(cfg, loop.x_trim), cfg.simulation.duration, cfg.simulation.dt)
        met = summarize(sim, linear.u_trim, Q, des.R_block, regulated)
        met["peak_delta"] = {name: float(np.abs(sim.u[:, j] - linear.u_trim[j]).max())
                             for j, name in enumerate(INPUT_NAMES)}
        met["linear_cost"] = full.linear_cost(linear.A, linear.B, K, Ki, des, dx0)
        runs[label] = met
    return fd, full.compare(runs, regulated)
