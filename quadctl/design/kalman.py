"""The steady-state Kalman filter of an LQG loop: one full 12-state filter on the coupled linear model.

:func:`kalman` designs it, discrete (MATLAB ``dlqe``: the filter gain ``M``, the law acting on
``x_hat[k|k]``) at a sampled controller's period or Kalman-Bucy (``lqe``) for a continuous one, with
the gyro filter's states when the loop has one; it refuses a measured set that leaves a mode that is
not stable unobservable. The two forms and the noise model are in the docs, docs/internals.md
("The Kalman filter").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from quadctl.design import discrete as dsc
from quadctl.design.riccati import solve
from quadctl.errors import ArgumentError, DesignError
from quadctl.layout import N_STATES, SENSOR_GROUPS, STATE_INDEX, STATE_NAMES
from quadctl.linear.analysis import check
from quadctl.linear.filters import RATE_STATES, filtered_output, series, state_names
from quadctl.physics.model import N_DISTURBANCES, Vehicle, build_model
from quadctl.text.messages import eig_text, show

if TYPE_CHECKING:
    from quadctl.linear.filters import RateFilter


@dataclass(frozen=True, eq=False)
class Kalman:
    """A steady-state Kalman filter.

    Attributes
    ----------
    form : {"filter", "kalman-bucy"}
        ``filter``: discrete, ``gain`` is the measurement-update gain ``M`` (MATLAB ``dlqe``'s ``M``);
        ``kalman-bucy``: continuous, ``gain`` is ``L`` of ``dx_hat/dt = ... + L (y - C x_hat)``.
    measured : tuple of str
        The measured states (rows of ``C``).
    A, B : (ne, ne), (ne, 4) ndarray
        The model the filter runs: ``Ad, Bd`` (discrete) or ``A, B``; ``ne = 12``, or ``12 + 3 m`` with a
        gyro filter of order ``m`` in it (:attr:`rate_filter`, state ``[x; g]``).
    C : (p, ne) ndarray
        Selects the measured states (a measured rate through the gyro filter: its filtered value).
    G : (ne, 6) ndarray
        How the process noise (body force N, torque N m) enters: ``Gd`` (held) or ``G``.
    Qn : (6, 6) ndarray
        Process noise covariance (discrete, per sample) or intensity (continuous, ``sigma^2 tau``).
    Rn : (p, p) ndarray
        Measurement noise covariance or intensity, same convention.
    gain : (12, p) ndarray
        ``M`` (filter form) or ``L`` (Kalman-Bucy).
    predictor_gain : (12, p) ndarray
        ``L = Ad M`` (discrete) or ``L``: the estimator's error dynamics are ``A - L C``.
    P : (12, 12) ndarray
        Steady covariance: a priori (discrete) or of the error (continuous).
    Z : (12, 12) ndarray
        A posteriori covariance ``P - M C P`` (discrete); equal to ``P`` (continuous).
    eigenvalues : (12,) complex ndarray
        Of ``A - L C`` (z for discrete, s for continuous).
    sample_time : float or None
        s; None for continuous.
    residual : float
        Relative residual of the Riccati solution.
    """

    form: Literal["filter", "kalman-bucy"]
    measured: tuple[str, ...]
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    G: np.ndarray
    Qn: np.ndarray
    Rn: np.ndarray
    gain: np.ndarray
    predictor_gain: np.ndarray
    P: np.ndarray
    Z: np.ndarray
    eigenvalues: np.ndarray
    sample_time: float | None
    residual: float
    rate_filter: RateFilter | None = None
    """:class:`quadctl.linear.filters.RateFilter` in the model (the rates measured after it); None: none."""

    @property
    def discrete(self) -> bool:
        return self.sample_time is not None

    @property
    def n_estimate(self) -> int:
        """States of the estimate: the 12 of ``x``, then the gyro filter's (3 per order)."""
        return self.A.shape[0]

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the estimate's states: :data:`~quadctl.layout.STATE_NAMES`, then the gyro filter's."""
        return model_names(self.rate_filter)

    def error_std(self) -> np.ndarray:
        """(12,) predicted steady standard deviation of ``x - x_hat`` the law acts on (``Z`` discrete)."""
        return np.sqrt(np.maximum(np.diag(self.Z), 0.0))


def model_names(rate_filter=None) -> tuple[str, ...]:
    """Names of the states of the filter's model: the 12 states, then those of a gyro filter (``rate_filter``)."""
    if rate_filter is None:
        return STATE_NAMES

    return (*STATE_NAMES, *state_names(rate_filter.order))


def selector(measured) -> np.ndarray:
    """(p, 12) ``C`` picking the measured states."""
    C = np.zeros((len(measured), N_STATES))
    for i, s in enumerate(measured):
        C[i, STATE_INDEX[s]] = 1.0
    return C


def noise_input(x_trim, u_trim, vehicle: Vehicle) -> np.ndarray:
    """(12, 6) ``G = df/dd``: how a body force (N) and torque (N m) enter the model at the trim."""
    import casadi as ca

    d = ca.SX.sym("d", N_DISTURBANCES)
    f = build_model().f_disturbed(ca.DM(np.asarray(x_trim, float)), ca.DM(np.asarray(u_trim, float)),
                                  ca.DM(vehicle.vector()), d)
    return np.asarray(ca.DM(ca.evalf(ca.jacobian(f, d))), dtype=float)


def require_detectable(A, C, measured, key: str = "estimator.measure", names=STATE_NAMES) -> None:
    """Refuse a measured set that leaves a mode that is not stable unobservable (PBH or the staircase:
    :func:`quadctl.linear.analysis.check`).

    Raises
    ------
    DesignError
        Naming the modes, the states they live in, and what to measure.
    """
    checks = check(A, np.zeros((A.shape[0], 1)), C, names)
    if checks.detectable:
        return
    bad = checks.undetectable_modes
    states = sorted({s for m in bad for s in _unobserved_states(A, C, m.eigenvalue, names) or m.states},
                    key=list(names).index)
    modes = ", ".join(eig_text(m.eigenvalue, 3) for m in bad)
    groups = [g for g, ss in SENSOR_GROUPS.items() if set(states) & set(ss)]
    raise DesignError(
        f"{key} = {show(list(measured))}: {', '.join(states)} not observable (modes at s = {modes}, not stable): "
        f"measure {' and '.join(states)}" + (f" (e.g. add {' or '.join(groups)})" if groups else ""))


def _unobserved_states(A, C, lam: complex, names=STATE_NAMES) -> tuple[str, ...]:
    """States the unobservable subspace at ``lam`` lives in: rows of the null space of
    ``[lam I - A; C]`` (rank tolerance of :func:`quadctl.linear.analysis.numerical_rank`) above a tenth
    of the largest."""
    n = A.shape[0]
    stacked = np.vstack([lam * np.eye(n) - A, C])
    _, sv, vh = np.linalg.svd(stacked)
    tol = max(stacked.shape) * np.finfo(float).eps * sv[0]
    null = vh[np.sum(sv > tol):].conj().T
    weight = np.linalg.norm(null, axis=1)
    return tuple(names[i] for i in range(n) if weight[i] > 0.1 * weight.max())


def kalman(A, B, G, measured, sensor_std, process_std, *, sample_time: float | None = None,
           period: float | None = None, rate_filter=None) -> Kalman:
    """The steady-state Kalman filter of ``dx/dt = A x + B u + G w``, ``y = C x + v``.

    Parameters
    ----------
    A : (12, 12) array_like
        Continuous linear model about the trim.
    B : (12, 4) array_like
    G : (12, 6) array_like
        Process noise input (:func:`noise_input`).
    measured : sequence of str
        Measured states.
    sensor_std : (p,) array_like
        Measurement standard deviations (state units), > 0.
    process_std : (6,) array_like
        Body force (N) and torque (N m) standard deviations.
    sample_time : float, optional
        s: the discrete filter at this period (:data:`Kalman.form` ``filter``); None: Kalman-Bucy.
    period : float, optional
        s the noise is held for: the continuous intensities ``sigma^2 period`` (required then). For a
        discrete filter, the process noise held over each sample has the same intensity: the variance
        ``sigma^2 period / sample_time`` (exact when ``period = sample_time``; default that).
    rate_filter : quadctl.linear.filters.RateFilter, optional
        The gyro filter the measured rates pass through (module doc): the model's state is ``[x; g]``,
        the filter at ``sample_time`` (continuous without one).

    Returns
    -------
    Kalman

    Raises
    ------
    DesignError
        A mode that is not stable is unobservable from ``measured``, or the Riccati equation is refused.
    ArgumentError
        A continuous filter without ``period``.
    """

    A, B, G = (np.asarray(M, dtype=float) for M in (A, B, G))
    measured = tuple(measured)
    names = model_names(rate_filter)
    form = rate_filter.form(sample_time) if rate_filter is not None else None
    rates = [STATE_INDEX[s] for s in RATE_STATES]
    Rn = np.diag(np.asarray(sensor_std, dtype=float) ** 2)
    Qn = np.diag(np.asarray(process_std, dtype=float) ** 2)
    if sample_time is None:
        if period is None:
            raise ArgumentError("kalman: period is None: a continuous filter (sample_time None) needs the s the noise "
                                "is held for, for its intensities; give period, or sample_time for a discrete filter")
        A, B = series(A, B, form, rates)
        G = np.vstack([G, np.zeros((A.shape[0] - G.shape[0], G.shape[1]))])
        C = filtered_output(selector(measured), form, rates)
        require_detectable(A, C, measured, names=names)
        Qn, Rn = Qn * period, Rn * period
        res = solve(A.T, C.T, G @ Qn @ G.T, Rn, name="estimator (Kalman-Bucy)", state_names=names)
        P = res.P
        L = np.linalg.solve(Rn, C @ P).T
        return Kalman(form="kalman-bucy", measured=measured, A=A, B=B, C=C, G=G, Qn=Qn, Rn=Rn, gain=L,
                      predictor_gain=L, P=P, Z=P, eigenvalues=np.linalg.eigvals(A - L @ C),
                      sample_time=None, residual=res.residual, rate_filter=rate_filter)
    Ad, Bd = dsc.c2d(A, B, sample_time)
    _, Gd = dsc.c2d(A, G, sample_time)
    if period is not None:  # r holds of sigma^2 in a sample act as one of sigma^2 / r (to first order in A Ts)
        Qn = Qn * (period / sample_time)
    Ad, Bd = series(Ad, Bd, form, rates)
    Gd = np.vstack([Gd, np.zeros((Ad.shape[0] - Gd.shape[0], Gd.shape[1]))])
    C = filtered_output(selector(measured), form, rates)
    if form is None:
        require_detectable(A, C, measured)
    else:  # on the continuous model and filter: a mode of x is unstable in s where it is in z
        continuous = rate_filter.form(None)
        require_detectable(series(A, B, continuous, rates)[0], filtered_output(selector(measured), continuous, rates),
                           measured, names=names)
    res = solve(Ad.T, C.T, Gd @ Qn @ Gd.T, Rn, discrete=True, name="estimator (discrete Kalman filter)",
                state_names=names)
    P = res.P
    M = np.linalg.solve(C @ P @ C.T + Rn, C @ P).T
    Z = P - M @ C @ P
    L = Ad @ M
    return Kalman(form="filter", measured=measured, A=Ad, B=Bd, C=C, G=Gd, Qn=Qn, Rn=Rn, gain=M,
                  predictor_gain=L, P=P, Z=(Z + Z.T) / 2, eigenvalues=np.linalg.eigvals(Ad - L @ C),
                  sample_time=float(sample_time), residual=res.residual, rate_filter=rate_filter)

