"""The estimator: rotor thrust curve, motor lag and delay, inertia and the torque coefficient from a log.

Three least-squares fits on the one CasADi model with its parameters as inputs (:func:`fit_thrust`,
:func:`fit_attitude`, :func:`fit_yaw`), each with 95 % intervals from a sandwich covariance that
takes the residuals' autocorrelation into account (:func:`sandwich`). The measurement model, the
rotor model (Eschmann, Albani & Loianno, IROS 2024) and the fits are in the docs, docs/internals.md
("Identification").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np

from quadctl import layout
from quadctl._lazy import lazy_import
from quadctl.config.vehicle_schema import MotorsConfig
from quadctl.errors import LogError
from quadctl.physics.model import N_DISTURBANCES, N_PARAMS, dynamics_expression
from quadctl.physics.motors import Motors
from quadctl.signals import signals_held

ca = lazy_import("casadi")
scipy = lazy_import("scipy")

PARAMETERS = ("c0", "c1", "c2", "Jxx", "Jyy", "Jzz", "k_m", "bias_A", "bias_E", "bias_R")
"""The model's identifiable parameters, in the order of the CasADi function's ``theta``."""
UNITS = {"c0": "N", "c1": "N", "c2": "N", "Jxx": "kg m^2", "Jyy": "kg m^2", "Jzz": "kg m^2", "k_m": "N m/N",
         "bias_A": "N m", "bias_E": "N m", "bias_R": "N m", "T_m": "s", "delay": "s"}
MEANING = {"c0": "rotor thrust at command 0", "c1": "rotor thrust, linear in the command",
           "c2": "rotor thrust, quadratic in the command", "Jxx": "roll inertia", "Jyy": "pitch inertia",
           "Jzz": "yaw inertia", "k_m": "yaw torque per newton of rotor thrust", "bias_A": "constant roll torque",
           "bias_E": "constant pitch torque", "bias_R": "constant yaw torque",
           "T_m": "motor time constant (lag of the command)", "delay": "pure delay of the command"}
TORQUE_ROWS = ("roll torque (N m)", "pitch torque (N m)", "yaw torque (N m)")
"""The name of each body axis's torque residual row (FRD), its unit in parentheses: a figure's labels and titles."""
ANGULAR_ACCELERATION_CUTOFF = 20.0
"""Hz: the gyro is low-passed (zero phase, 2nd-order Butterworth) before it is differentiated; the
model's torque goes through the same filter, so the fit compares like with like."""
BANDWIDTH_FACTOR = 2
"""The Newey-West sum runs to this many times the residual's correlation length."""
Z95 = 1.959963984540054
"""The normal 97.5 % quantile: a 95 % two-sided interval is ``value +- Z95 std``."""
LEAD_IN = 2.0
"""s of the log before (and after) a window that a fit computes through: the lag's memory (its
time constant, tens of ms) and the low-pass filter's settle in it to far below the noise."""
COMMANDS_SEEN = 0.99
"""A log sampled at this share of the vehicle's command rate or more (its median rate rounded) sees every
command it flew: :func:`on_grid` holds them between samples."""
_LAG_DELAY_STEP = 1e-4
"""s: the central difference of the lag in the delay (exact for a linearly interpolated command)."""


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
        its samples (:func:`on_grid`); None: they change no faster than any log samples them.
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


@dataclass(frozen=True)
class Grid:
    """A log on a uniform time grid (the lag is then one recursive filter).

    Attributes
    ----------
    t : (N,) ndarray
        s.
    dt : float
        s.
    acc, gyro : (N, 3) ndarray
        Linearly interpolated.
    alpha : (N, 3) ndarray
        Angular acceleration, rad/s^2: the gyro low-passed (:data:`ANGULAR_ACCELERATION_CUTOFF`), differentiated.
    cmd : (N, 4) ndarray
        Held (a command is a step until the next), or, with ``linear_commands``, linear between samples.
    acc_lowpass_hz, gyro_lowpass_hz : float or None
        The low-passes the vehicle ran on its sensors before it logged them
        (:attr:`quadctl.identify.flight_log.FlightLog.acc_lowpass_hz`): :meth:`as_logged` applies them.
    linear_commands : bool
        The commands moved between the log's samples (its controller changes them more often than the log
        samples them): the rotors' lag takes them linear from one sample to the next (:meth:`lagged`).
    """

    t: np.ndarray
    dt: float
    acc: np.ndarray
    gyro: np.ndarray
    alpha: np.ndarray
    cmd: np.ndarray
    acc_lowpass_hz: float | None = None
    gyro_lowpass_hz: float | None = None
    linear_commands: bool = False

    def lagged(self, time_constant: float, delay: float = 0.0, *, in_delay: bool = True):
        """The grid's commands through the rotors' lag (:func:`lagged`), held or linear between samples as the
        grid takes them (:attr:`linear_commands`)."""
        return lagged(self.cmd, self.dt, time_constant, delay, in_delay=in_delay, linear=self.linear_commands)

    def around(self, windows, margin: float = LEAD_IN) -> Grid:
        """The grid from ``margin`` s before the first window to ``margin`` after the last (the lag and
        the low-pass filter settle in the margin; nothing outside it changes the fit)."""
        t0 = min(a for a, _ in windows) - margin
        t1 = max(b for _, b in windows) + margin
        keep = slice(int(np.searchsorted(self.t, t0)), int(np.searchsorted(self.t, t1, side="right")))
        return replace(self, t=self.t[keep], acc=self.acc[keep], gyro=self.gyro[keep], alpha=self.alpha[keep],
                       cmd=self.cmd[keep])

    def as_logged(self, values: np.ndarray, sensor: str) -> np.ndarray:
        """``values`` (on axis 0, this grid's samples) through the low-pass the vehicle ran on ``sensor``
        (``"acc"`` or ``"gyro"``) before logging it, causal, from rest at its first value; unchanged when it
        ran none. A model's prediction so filtered compares with the log without the filter's lag."""
        hz = self.acc_lowpass_hz if sensor == "acc" else self.gyro_lowpass_hz
        if hz is None:
            return values
        b, a = _butter_at(float(hz), float(self.dt))
        rest = scipy.signal.lfilter_zi(b, a).reshape((-1,) + (1,) * (values.ndim - 1)) * values[:1]
        return scipy.signal.lfilter(b, a, values, axis=0, zi=rest)[0]

    def lowpass(self, values: np.ndarray) -> np.ndarray:
        """The zero-phase filter applied to the gyro, on axis 0 of ``values``."""
        b, a = _butter(self.dt)
        return scipy.signal.filtfilt(b, a, values, axis=0)


@lru_cache(maxsize=8)
def _butter(dt: float):
    return scipy.signal.butter(2, ANGULAR_ACCELERATION_CUTOFF * 2.0 * dt)


@lru_cache(maxsize=8)
def _butter_at(hz: float, dt: float):
    """``(b, a)``: the second-order Butterworth low-pass at ``hz`` (analog), carried to the sample time ``dt``
    (s) by the bilinear transform. The vehicle ran its filter at its own sensor rate (the Crazyflie's ``lpf2p``
    at 1 kHz); a log may be sampled slower, down to a rate whose Nyquist frequency is below the cutoff (an
    80 Hz gyro filter in a 100 Hz log), where a digital design at the log's rate does not exist. The analog
    filter on the log's rate holds at any rate: its lag at low frequencies (``sqrt(2) / (2 pi hz)``) is kept
    exactly. Not prewarped, as ``lpf2p`` is at its rate: at 1 kHz that moves the cutoff by 0.3 % at 30 Hz and
    2 % at 80 Hz (0.05 ms of the gyro filter's 2.8 ms lag)."""
    b, a = scipy.signal.butter(2, 2.0 * math.pi * hz, analog=True)
    return scipy.signal.bilinear(b, a, fs=1.0 / dt)


def on_grid(log, rate: float | None = None, command_rate: float | None = None) -> Grid:
    """The log resampled at ``rate`` (Hz; default its median rate rounded to 10 Hz).

    ``command_rate`` (Hz, :attr:`Airframe.command_rate`) is how often the vehicle changes its commands. A log
    that samples them at least that often sees each step: they are held between samples. A log that samples
    them less often (a 100 Hz log of a 500 Hz controller) sees a command that moved since its last sample:
    they are taken linear between samples (:attr:`Grid.linear_commands`); held, they would lag the rotors by
    half a sample more than they do, and the fit would take it off the rotors' lag."""
    if rate is None:
        rate = max(10.0, round(1.0 / float(np.median(np.diff(log.t))) / 10.0) * 10.0)
    dt = 1.0 / rate
    t = log.t[0] + dt * np.arange(int(math.floor((log.t[-1] - log.t[0]) / dt)) + 1)
    acc = np.column_stack([np.interp(t, log.t, log.acc[:, i]) for i in range(3)])
    gyro = np.column_stack([np.interp(t, log.t, log.gyro[:, i]) for i in range(3)])
    linear = command_rate is not None and rate < COMMANDS_SEEN * command_rate
    if linear:
        cmd = np.column_stack([np.interp(t, log.t, log.cmd[:, i]) for i in range(4)])
    else:
        cmd = log.cmd[np.clip(np.searchsorted(log.t, t, side="right") - 1, 0, log.t.size - 1)]
    grid = Grid(t=t, dt=dt, acc=acc, gyro=gyro, alpha=np.zeros_like(gyro), cmd=cmd,
                acc_lowpass_hz=log.acc_lowpass_hz, gyro_lowpass_hz=log.gyro_lowpass_hz, linear_commands=linear)
    return replace(grid, alpha=np.gradient(grid.lowpass(gyro), dt, axis=0))


def lagged(cmd: np.ndarray, dt: float, time_constant: float, delay: float = 0.0, *, in_delay: bool = True,
           linear: bool = False):
    """The commands delayed by ``delay`` and lagged through ``time_constant``: exact for commands held from
    one sample to the next or, with ``linear``, moving linearly from one sample to the next.

    Returns
    -------
    z, dz_dT, dz_dd : (N, 4) ndarray
        The lagged commands and their derivatives in the time constant and the delay (1/s; None
        without ``in_delay``).
    """
    a = math.exp(-dt / time_constant)
    da = a * dt / time_constant ** 2  # da/dT
    # z_k = a z_{k-1} + (1 - a) u_{k-1} + b (u_k - u_{k-1}): b = 0 for a held command; for a linear one,
    # the lag's response to the ramp, b = 1 - (T / dt) (1 - a)
    b = 1.0 - time_constant / dt * (1.0 - a) if linear else 0.0
    db = -(1.0 - a) / dt + time_constant / dt * da if linear else 0.0  # db/dT

    def run(d):
        shifted = _delayed(cmd, d / dt)
        # from rest at the first command (z_0 = u_0)
        z = scipy.signal.lfilter([b, 1 - a - b], [1.0, -a], shifted - shifted[0], axis=0) + shifted[0]
        return z, shifted

    z, shifted = run(delay)
    # dz_k/dT = a dz_{k-1}/dT + da/dT (z_{k-1} - u_{k-1}) + db/dT (u_k - u_{k-1})
    drive = np.vstack([np.zeros((1, 4)), (z[:-1] - shifted[:-1]) * da + np.diff(shifted, axis=0) * db])
    dz_dt = scipy.signal.lfilter([1.0], [1.0, -a], drive, axis=0)
    if not in_delay:
        return z, dz_dt, None
    h = _LAG_DELAY_STEP
    dz_dd = (run(delay + h)[0] - run(max(delay - h, 0.0))[0]) / (delay + h - max(delay - h, 0.0))
    return z, dz_dt, dz_dd


def _delayed(cmd: np.ndarray, shift: float) -> np.ndarray:
    """``cmd`` shifted later by ``shift`` samples (linear between samples; the first value before)."""
    if shift <= 0:
        return cmd
    n = cmd.shape[0]
    s = np.arange(n) - shift
    lo = np.clip(np.floor(s).astype(int), 0, n - 1)
    hi = np.clip(lo + 1, 0, n - 1)
    w = np.clip(s - np.floor(s), 0.0, 1.0)[:, None]
    out = (1 - w) * cmd[lo] + w * cmd[hi]
    out[s < 0] = cmd[0]
    return out


@dataclass
class Estimate:
    """One stage's fit.

    Attributes
    ----------
    stage : str
    names : tuple of str
    values, std : (k,) ndarray
    covariance : (k, k) ndarray
    windows : list of (t0, t1)
    t : (M,) ndarray
        The window's sample times, s.
    measured, predicted : (M, r) ndarray
        The fitted quantities (N or N m), one column per residual row (``rows``).
    rows : tuple of str
        What each column is, its unit in parentheses (``thrust (N)``, :data:`TORQUE_ROWS`).
    rms : float
        Root mean square of the residual.
    bandwidth : int
        Samples of residual autocorrelation the covariance accounts for.
    extra : dict
        Stage-specific numbers (the thrust stage's fit without a lag).
    floors : dict
        ``{name: the least value the fit takes}`` of a parameter held above a floor (the motor lag: two
        samples of the log); a value on it is the floor, not an estimate.
    """

    stage: str
    names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    windows: list
    t: np.ndarray
    measured: np.ndarray
    predicted: np.ndarray
    rows: tuple[str, ...]
    rms: float
    bandwidth: int
    extra: dict = field(default_factory=dict)
    floors: dict = field(default_factory=dict)

    def value(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def at_floor(self, name: str) -> bool:
        """Whether ``name`` sits on its floor (:attr:`floors`, within a relative 1e-9: the fit clips to it)."""
        floor = self.floors.get(name)
        return floor is not None and self.value(name) <= floor + 1e-9 * abs(floor)

    def interval(self, name: str) -> tuple[float, float]:
        """The 95 % interval of ``name``."""
        i = self.names.index(name)
        return float(self.values[i] - Z95 * self.std[i]), float(self.values[i] + Z95 * self.std[i])

    @property
    def residual(self) -> np.ndarray:
        return self.measured - self.predicted


def window_mask(t: np.ndarray, windows) -> np.ndarray:
    """True at samples inside any ``(t0, t1)`` of ``windows``."""
    mask = np.zeros(t.shape, dtype=bool)
    for t0, t1 in windows:
        mask |= (t >= t0) & (t <= t1)
    return mask


def sandwich(jac: np.ndarray, res: np.ndarray) -> tuple[np.ndarray, int]:
    """The least-squares covariance ``H^-1 S H^-1`` with ``S`` a Newey-West (Bartlett) sum of the
    residual's scores over their autocorrelation.

    Parameters
    ----------
    jac : (N, r, k) ndarray
        ``d residual / d parameters`` at each sample.
    res : (N, r) ndarray

    Returns
    -------
    covariance : (k, k) ndarray
    bandwidth : int
        The lag the sum runs to: twice the lag where the residual's autocorrelation first falls below 0.05.
    """
    n = res.shape[0]
    scores = np.einsum("nrk,nr->nk", jac, res)
    flat = jac.reshape(-1, jac.shape[2])
    hess_inv = np.linalg.inv(flat.T @ flat)
    bandwidth = BANDWIDTH_FACTOR * correlation_length(res)
    size = 1 << int(math.ceil(math.log2(n + bandwidth + 1)))
    spec = np.fft.rfft(scores, size, axis=0)
    # gamma[l, a, b] = sum_t scores[t + l, a] scores[t, b], every lag at once
    gamma = np.fft.irfft(spec[:, :, None] * spec[:, None, :].conj(), size, axis=0)[: bandwidth + 1]
    weights = 1.0 - np.arange(bandwidth + 1) / (bandwidth + 1.0)
    s = gamma[0] + np.einsum("l,lab->ab", weights[1:], gamma[1:] + gamma[1:].transpose(0, 2, 1))
    cov = hess_inv @ s @ hess_inv
    return (cov + cov.T) / 2.0 * n / max(n - jac.shape[2], 1), bandwidth


def correlation_length(res: np.ndarray) -> int:
    """Samples until the residual's autocorrelation (averaged over its columns) first falls below 0.05."""
    r = res - res.mean(axis=0)
    n = r.shape[0]
    size = 1 << int(math.ceil(math.log2(2 * n)))
    spec = np.fft.rfft(r, size, axis=0)
    acf = np.fft.irfft(np.abs(spec) ** 2, size, axis=0)[:n].sum(axis=1)
    acf = acf / acf[0] if acf[0] > 0 else np.zeros(n)
    below = np.nonzero(acf < 0.05)[0]
    return int(max(1, min(below[0] if below.size else n // 5, n // 5)))


def _levenberg_marquardt(residual_and_jacobian, x0: np.ndarray, scale: np.ndarray, lower: np.ndarray,
                         iterations: int = 50):
    """Minimize ``|r(x)|^2`` from ``x0`` (``scale``: typical sizes; ``lower``: bounds held by clipping)."""
    x = x0.copy()
    r, j = residual_and_jacobian(x)
    cost = float(np.sum(r ** 2))
    mu = 1e-3
    for _ in range(iterations):
        js = j * scale
        g = js.T @ r
        h = js.T @ js
        step = -np.linalg.solve(h + mu * np.diag(np.diag(h)), g) * scale
        trial = np.maximum(x + step, lower)
        r_t, j_t = residual_and_jacobian(trial)
        cost_t = float(np.sum(r_t ** 2))
        if cost_t < cost:
            done = cost - cost_t < 1e-9 * cost  # a relative 1e-9 of the cost: far inside any interval
            x, r, j, cost, mu = trial, r_t, j_t, cost_t, max(mu / 5.0, 1e-9)
            if done:
                break
        else:
            mu *= 10.0
            if mu > 1e8:
                break
    return x


def fit_thrust(grid: Grid, windows, airframe: Airframe, *, delay: bool = False,
               time_constant: float = 0.05) -> Estimate:
    """Thrust curve ``c0, c1, c2`` (N), ``T_m`` (s) and, with ``delay``, a pure delay (s) from ``m a_z``.

    Parameters
    ----------
    grid : Grid
    windows : list of (t0, t1)
        s, the samples fitted.
    airframe : Airframe
        Its mass (kg) scales the specific force to the rotors' total thrust.
    delay : bool
        Fit a pure delay too (else none: the paper's structure).
    time_constant : float
        s, the starting guess of ``T_m``.
    """
    grid = grid.around(windows)
    mask = window_mask(grid.t, windows)
    meas = airframe.mass * grid.acc[mask, 2]
    omega = grid.gyro
    names = ("c0", "c1", "c2", "T_m") + (("delay",) if delay else ())
    logged = grid.as_logged  # the model's thrust through the accelerometer's low-pass, as the log has it

    def rj(x):
        z, dz_dT, dz_dd = grid.lagged(x[3], x[4] if delay else 0.0, in_delay=delay)
        theta = airframe.theta(c0=x[0], c1=x[1], c2=x[2])
        y, jt, jz = predict(z, omega, theta, airframe, rows=(2,), names=names[:3])
        jac = [-jt[:, 0, :]]
        jac.append(-np.einsum("nj,nj->n", jz[:, 0, :], dz_dT)[:, None])
        if delay:
            jac.append(-np.einsum("nj,nj->n", jz[:, 0, :], dz_dd)[:, None])
        return meas - logged(y[:, 0], "acc")[mask], logged(np.hstack(jac), "acc")[mask]

    def curve(z):
        """The thrust curve by linear least squares for given rotor commands, on the grid (the model is linear
        in it, and so is the filter)."""
        _, jt, _ = predict(z, omega, airframe.theta(), airframe, rows=(2,), names=names[:3])
        basis = logged(jt[:, 0, :], "acc")[mask]
        c, *_ = np.linalg.lstsq(basis, meas, rcond=None)
        return c, float(np.sqrt(np.mean((meas - basis @ c) ** 2)))

    # the curve at the starting lag, then everything together
    c_start, _ = curve(grid.lagged(time_constant, in_delay=False)[0])
    x0 = np.r_[c_start, time_constant, [0.005] if delay else []]
    scale = np.r_[0.01, 0.01, 0.1, 0.01, [0.005] if delay else []]
    lower = np.r_[-np.inf, -np.inf, -np.inf, 2 * grid.dt, [0.0] if delay else []]
    x = _levenberg_marquardt(rj, x0, scale, lower)
    r, j = rj(x)
    cov, bandwidth = sandwich(j[:, None, :], r[:, None])
    no_lag, rms_no_lag = curve(grid.cmd)  # the same curve with no lag (the paper's comparison)
    z = grid.lagged(x[3], x[4] if delay else 0.0, in_delay=False)[0][mask]
    return Estimate(stage="thrust", names=names, values=x, std=np.sqrt(np.diag(cov)), covariance=cov,
                    windows=list(windows), t=grid.t[mask], measured=-meas[:, None], predicted=(-(meas - r))[:, None],
                    rows=("total thrust (N)",), rms=float(np.sqrt(np.mean(r ** 2))), bandwidth=bandwidth,
                    floors={"T_m": float(lower[3])},
                    extra={"rms_without_lag": rms_no_lag, "curve_without_lag": [float(v) for v in no_lag],
                           "commands_flown": [float(np.quantile(z, 0.01)), float(np.quantile(z, 0.99))]})


def _torque_fit(stage, grid, windows, airframe, thrust: Estimate, names, axes, given) -> Estimate:
    """A linear-in-parameters torque fit: ``J alpha`` against the model's torque, both low-passed alike.

    The rotors come from ``thrust``; its uncertainty is carried into this fit's covariance (the
    sensitivity of this fit's values to the thrust stage's, by one-sided differences of one std).
    """
    grid = grid.around(windows)
    mask = window_mask(grid.t, windows)
    rows = tuple(3 + a for a in axes)
    x0 = np.array([airframe.theta(**given)[PARAMETERS.index(n)] for n in names])
    axis_of = {"Jxx": 0, "Jyy": 1, "Jzz": 2}

    def rj(x, rotors):
        z = grid.lagged(rotors["T_m"], rotors.get("delay", 0.0), in_delay=False)[0]
        curve = {n: rotors[n] for n in ("c0", "c1", "c2")}
        theta = airframe.theta(**curve, **given, **dict(zip(names, x)))
        y, jt, _ = predict(z, grid.gyro, theta, airframe, rows=rows, names=tuple(names))
        inertia = theta[[PARAMETERS.index(n) for n in ("Jxx", "Jyy", "Jzz")]]
        measured = (inertia * grid.alpha)[:, axes]  # J domega/dt, N m
        d_measured = np.zeros((z.shape[0], len(axes), len(names)))
        for k, n in enumerate(names):
            if n in axis_of and axis_of[n] in axes:
                d_measured[:, axes.index(axis_of[n]), k] = grid.alpha[:, axis_of[n]]
        # the model's torque through the gyro's own low-pass (the log's), then the one alpha took
        pred = grid.lowpass(grid.as_logged(y, "gyro"))
        jac_pred = grid.lowpass(grid.as_logged(jt.reshape(z.shape[0], -1), "gyro")).reshape(z.shape[0], len(axes), -1)
        return (measured - pred)[mask], (d_measured - jac_pred)[mask], measured[mask], pred[mask]

    def solve(rotors, x, steps=8):
        for _ in range(steps):  # Gauss-Newton: the torque is linear in these parameters, one step settles it
            r, j, _, _ = rj(x, rotors)
            step = -np.linalg.lstsq(j.reshape(-1, len(names)), r.reshape(-1), rcond=None)[0]
            x = x + step
            if np.all(np.abs(step) <= 1e-9 * (np.abs(x) + 1e-12)):
                break
        return x

    rotors = dict(zip(thrust.names, thrust.values))
    x = solve(rotors, x0)
    r, j, measured, pred = rj(x, rotors)
    cov, bandwidth = sandwich(j, r)
    sensitivity = np.zeros((len(names), len(thrust.names)))
    for i, n in enumerate(thrust.names):
        nudged = dict(rotors, **{n: rotors[n] + thrust.std[i]})
        sensitivity[:, i] = (solve(nudged, x, steps=1) - x) / thrust.std[i]  # linear: one step is exact
    cov = cov + sensitivity @ thrust.covariance @ sensitivity.T
    return Estimate(stage=stage, names=tuple(names), values=x, std=np.sqrt(np.diag(cov)), covariance=cov,
                    windows=list(windows), t=grid.t[mask], measured=measured, predicted=pred,
                    rows=tuple(TORQUE_ROWS[a] for a in axes), rms=float(np.sqrt(np.mean(r ** 2))),
                    bandwidth=bandwidth)


def fit_attitude(grid: Grid, windows, airframe: Airframe, thrust: Estimate) -> Estimate:
    """``Jxx, Jyy`` (kg m^2) and constant roll and pitch torques (N m), the rotors from ``thrust``.

    The residual is a torque, ``J domega/dt`` against the model's: the error of a log's torque is in
    the rotors' modelled thrust, not in the gyro, so the fit takes the torque as what errs.
    """
    return _torque_fit("attitude", grid, windows, airframe, thrust, ("Jxx", "Jyy", "bias_A", "bias_E"), (0, 1), {})


def fit_yaw(grid: Grid, windows, airframe: Airframe, thrust: Estimate, attitude: Estimate | None = None) -> Estimate:
    """The torque coefficient ``k_m`` (N m/N) and a constant yaw torque, ``Jzz`` held (the airframe's)."""
    given = {} if attitude is None else {n: attitude.value(n) for n in ("Jxx", "Jyy")}
    return _torque_fit("yaw", grid, windows, airframe, thrust, ("k_m", "bias_R"), (2,), given)


def require_window(grid: Grid, windows, path: str, stage: str, minimum: float = 1.0) -> None:
    """Raise LogError when the windows hold less than ``minimum`` seconds of the log."""
    have = window_mask(grid.t, windows).sum() * grid.dt
    if have < minimum:
        spans = ", ".join(f"{a:g}:{b:g}" for a, b in windows) or "none"
        raise LogError(f"{path}: the {stage} window ({spans}) holds {have:.3g} s of the log "
                       f"(from {grid.t[0]:.4g} to {grid.t[-1]:.4g} s), less than {minimum:g} s; "
                       "give --window t0:t1 inside the flight")
