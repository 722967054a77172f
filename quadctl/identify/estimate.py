"""The estimator: rotor thrust curve, motor lag and delay, inertia and the torque coefficient from a log.

Three least-squares fits on the measurement model (:mod:`quadctl.identify.measurement`) of a log on a
uniform grid (:mod:`quadctl.identify.grid`): :func:`fit_thrust`, :func:`fit_attitude`, :func:`fit_yaw`,
each with 95 % intervals from a sandwich covariance that takes the residuals' autocorrelation into
account (:func:`quadctl.identify.least_squares.sandwich`). The fits are in the docs, docs/internals.md
("Identification").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quadctl.identify.grid import Grid, window_mask
from quadctl.identify.least_squares import levenberg_marquardt, sandwich
from quadctl.identify.measurement import PARAMETERS, Airframe, predict

TORQUE_ROWS = ("roll torque (N m)", "pitch torque (N m)", "yaw torque (N m)")
"""The name of each body axis's torque residual row (FRD), its unit in parentheses: a figure's labels and titles."""
Z95 = 1.959963984540054
"""The normal 97.5 % quantile: a 95 % two-sided interval is ``value +- Z95 std``."""


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
    x = levenberg_marquardt(rj, x0, scale, lower)
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
