"""The measurement model of identification: the parameters a log fits, the airframe it cannot give, and
the force and torque the one CasADi model predicts from the rotor commands and the gyro.

:func:`measurement_function` writes the model with its parameters (:data:`PARAMETERS`) as inputs;
:func:`predict` evaluates it at every sample with its derivatives, which the fits
(:mod:`quadctl.identify.estimate`) take. The measurement model is in the docs, docs/internals.md
("Identification").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from quadctl import layout
from quadctl._lazy import lazy_import
from quadctl.config.vehicle_schema import MotorsConfig
from quadctl.physics.model import N_DISTURBANCES, N_PARAMS, dynamics_expression
from quadctl.physics.motors import Motors
from quadctl.signals import signals_held

ca = lazy_import("casadi")

PARAMETERS = ("c0", "c1", "c2", "Jxx", "Jyy", "Jzz", "k_m", "bias_A", "bias_E", "bias_R")
"""The model's identifiable parameters, in the order of the CasADi function's ``theta``."""
UNITS = {"c0": "N", "c1": "N", "c2": "N", "Jxx": "kg m^2", "Jyy": "kg m^2", "Jzz": "kg m^2", "k_m": "N m/N",
         "bias_A": "N m", "bias_E": "N m", "bias_R": "N m", "T_m": "s", "delay": "s"}
MEANING = {"c0": "rotor thrust at command 0", "c1": "rotor thrust, linear in the command",
           "c2": "rotor thrust, quadratic in the command", "Jxx": "roll inertia", "Jyy": "pitch inertia",
           "Jzz": "yaw inertia", "k_m": "yaw torque per newton of rotor thrust", "bias_A": "constant roll torque",
           "bias_E": "constant pitch torque", "bias_R": "constant yaw torque",
           "T_m": "motor time constant (lag of the command)", "delay": "pure delay of the command"}


@dataclass(frozen=True)
class Airframe:
    """What a log cannot give: mass, gravity, rotor geometry and spins, and the values a stage holds fixed.

    Attributes
    ----------
    mass : float
        kg.
    gravity : float
        m/s^2 (the fit does not take it: an accelerometer does not feel gravity; :meth:`hover_thrust` does).
    positions : (4, 2) ndarray
        Rotor positions ``(x, y)`` in the FRD body frame, m, rotor 1 first.
    spins : (4,) ndarray
        Yaw reaction sign of each rotor (+1 counter-clockwise seen from above).
    inertia : (3,) ndarray
        ``Jxx, Jyy, Jzz``, kg m^2 (a stage that does not fit one holds it).
    torque_coefficient : float
        N m per N.
    command_rate : float or None
        Hz: how often the vehicle's controller changes the rotor commands (the config's ``controller.rate``;
        ``inf`` for a continuous controller). A log that samples them less often holds them linear between
        its samples (:func:`quadctl.identify.grid.on_grid`); None: they change no faster than any log samples them.
    """

    mass: float
    gravity: float
    positions: np.ndarray
    spins: np.ndarray
    inertia: np.ndarray
    torque_coefficient: float
    command_rate: float | None = None

    @classmethod
    def from_config(cls, cfg) -> Airframe:
        """From a :class:`quadctl.config.Config` (vehicle and motors; default motors when absent)."""

        motors = Motors.from_config(cfg.motors if cfg.motors is not None else MotorsConfig())
        rate = cfg.controller.rate
        return cls(mass=cfg.vehicle.mass, gravity=cfg.vehicle.gravity, positions=motors.positions(),
                   spins=np.array(motors.rotor_spins()), inertia=np.array(cfg.vehicle.inertia, dtype=float),
                   torque_coefficient=motors.torque_coefficient,
                   command_rate=math.inf if rate is None else float(rate))

    def hover_thrust(self) -> float:
        """N: each rotor's share of the weight, ``m g`` over the rotors (the thrust each gives at hover)."""
        return self.mass * self.gravity / len(self.positions)

    def theta(self, **given) -> np.ndarray:
        """The full parameter vector (:data:`PARAMETERS`): the airframe's values, ``given`` over them."""
        base = {"c0": 0.0, "c1": 0.0, "c2": 0.0, "Jxx": self.inertia[0], "Jyy": self.inertia[1],
                "Jzz": self.inertia[2], "k_m": self.torque_coefficient, "bias_A": 0.0, "bias_E": 0.0, "bias_R": 0.0}
        base.update(given)
        return np.array([base[n] for n in PARAMETERS], dtype=float)


@lru_cache(maxsize=16)
def measurement_function(rows: tuple[int, ...] = tuple(range(6)), names: tuple[str, ...] = PARAMETERS):
    """CasADi ``(z[4], omega[3], theta[10], mass, positions[8], spins[4]) -> (y, dy/dtheta, dy/dz)``.

    ``y = [m a (N, 3), J domega/dt (N m, 3)]``: the model's specific force times the mass and its
    angular acceleration times the diagonal inertia (a force and a torque, the fit's residual units);
    only its ``rows``, and the derivatives in the parameters ``names`` only (a stage's fit needs no more).
    """

    z = ca.SX.sym("z", 4)
    omega = ca.SX.sym("omega", 3)
    theta = ca.SX.sym("theta", len(PARAMETERS))
    mass = ca.SX.sym("mass")
    pos = ca.SX.sym("positions", 8)
    spins = ca.SX.sym("spins", 4)
    p = dict(zip(PARAMETERS, ca.vertsplit(theta)))
    f = p["c0"] + p["c1"] * z + p["c2"] * z * z
    x_pos, y_pos = pos[0:4], pos[4:8]
    u = ca.vertcat(ca.sum1(f), -ca.dot(y_pos, f), ca.dot(x_pos, f), p["k_m"] * ca.dot(spins, f))
    inertia = ca.vertcat(p["Jxx"], p["Jyy"], p["Jzz"])
    params = ca.SX.zeros(N_PARAMS)
    params[layout.MASS] = mass  # gravity 0: the accelerometer does not feel it
    params[layout.INERTIA] = inertia
    disturbance = ca.SX.zeros(N_DISTURBANCES)
    disturbance[3:6] = ca.vertcat(p["bias_A"], p["bias_E"], p["bias_R"])
    x = ca.vertcat(ca.SX.zeros(layout.BODY_RATES.start), omega)  # at rest in the air: no velocity, level
    xdot = dynamics_expression(x, u, params, disturbance)
    y = ca.vertcat(mass * xdot[layout.VELOCITY], inertia * xdot[layout.BODY_RATES])[list(rows)]
    free = ca.vertcat(*(p[n] for n in names))
    return ca.Function("identify_measure", [z, omega, theta, mass, pos, spins],
                       [y, ca.jacobian(y, free), ca.jacobian(y, z)],
                       ["z", "omega", "theta", "mass", "positions", "spins"], ["y", "dy_dtheta", "dy_dz"])


@lru_cache(maxsize=16)
def _mapped(n: int, rows: tuple[int, ...], names: tuple[str, ...]):
    return measurement_function(rows, names).map(n)


def predict(z: np.ndarray, omega: np.ndarray, theta: np.ndarray, airframe: Airframe,
            rows: tuple[int, ...] = tuple(range(6)), names: tuple[str, ...] = PARAMETERS):
    """The model's ``y`` (N, r), ``dy/dtheta`` (N, r, k) and ``dy/dz`` (N, r, 4) at every sample,
    for the rows ``rows`` of ``y`` and the parameters ``names``."""
    n = z.shape[0]
    pos = np.concatenate([airframe.positions[:, 0], airframe.positions[:, 1]])
    # Ctrl-C (or SIGTERM) is taken after CasADi's calls, not inside them: CasADi's Python wrapper turns an
    # interrupt that lands in its argument conversion into "NotImplementedError: Wrong number or type of
    # arguments", and DM.full() so interrupted returns None; the command ended in "internal error".
    with signals_held():
        y, jt, jz = _mapped(n, tuple(rows), tuple(names))(z.T, omega.T, theta, airframe.mass, pos, airframe.spins)
        y, jt, jz = y.full(), jt.full(), jz.full()
    r = len(rows)
    return y.T, jt.reshape(r, n, len(names)).transpose(1, 0, 2), jz.reshape(r, n, 4).transpose(1, 0, 2)
