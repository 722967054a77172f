"""The stages chained from a config: pure functions, no I/O.

Each takes the config (and upstream results) and returns the stage's result object.
"""

from __future__ import annotations

import numpy as np

from quadctl.analysis import Checks, check
from quadctl.config import Config, weight_matrix
from quadctl.decouple import Decoupled, decouple
from quadctl.layout import POSITION_STATES, STATE_INDEX, STATE_NAMES
from quadctl.linearize import LinearModel, linearize
from quadctl.lqr import Design, design
from quadctl.model import Vehicle
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


def design_of(cfg: Config, decoupled: Decoupled, linear: LinearModel) -> Design:
    return design(decoupled, linear.A, linear.B, weights_of(cfg))


def state_owner(cfg: Config) -> dict[str, str]:
    """State name -> the subsystem it belongs to."""
    return {s: name for name, sub in cfg.partition().items() for s in sub.states}


def reference_rate(trim: Trim) -> np.ndarray:
    """(12,) drift of the reference: the trim's position rates (its earth velocity)."""
    rate = np.zeros(len(STATE_NAMES))
    for s in POSITION_STATES:
        rate[STATE_INDEX[s]] = trim.xdot[STATE_INDEX[s]]
    return rate


def closed_loop_of(cfg: Config, linear: LinearModel, K: np.ndarray, x_rate: np.ndarray) -> ClosedLoop:
    eig, owners = eigen_owners(linear.A - linear.B @ K, state_owner(cfg))
    return ClosedLoop(params=vehicle_of(cfg).vector(), x_trim=linear.x_trim, u_trim=linear.u_trim,
                      x_rate=x_rate, K=K, eigenvalues=eig, owners=owners)


def initial_state(cfg: Config, x_trim: np.ndarray) -> np.ndarray:
    """Trim state plus the config's ``simulation.initial_offset``."""
    x0 = np.array(x_trim, dtype=float)
    for name, value in cfg.simulation.initial_offset.items():
        x0[STATE_INDEX[name]] += value
    return x0


def simulation_of(cfg: Config, loop: ClosedLoop) -> SimResult:
    return simulate(loop, initial_state(cfg, loop.x_trim), cfg.simulation.duration, cfg.simulation.dt)
