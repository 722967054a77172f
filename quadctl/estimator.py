"""The steady-state Kalman filter of an LQG loop: one full 12-state filter on the coupled linear model.

The filter runs on the linear model about the trim, in deviation coordinates: it estimates
``dx = x - x_ref(t)`` from ``y = C (x + n_s) - C x_ref(t)``, under the input deviation
``du = u - u_trim`` the plant was actually given (after clipping and any delay), and the law uses
the estimate in place of the measured state, ``u = u_trim - K dx_hat``. It is *one* filter on the
coupled 12-state model (not one per subsystem): the decoupled partition drops couplings the
filter would then not know about, and the full filter costs a 12 x p gain.

Two forms, after the controller's timing (MATLAB conventions; python-control's GitHub
thread 1173 shows how easily they are confused):

- sampled controller (``controller.rate``, discrete or emulated design): the discrete filter of
  the zero-order-hold model ``Ad, Bd`` at the controller period, MATLAB ``dlqe(Ad, Gd, C, Qn, Rn)``.
  The gain is the **filter (measurement-update) gain** ``M``: with ``P`` the a priori covariance,
  ``M = P C' (C P C' + Rn)^-1`` and ``Z = P - M C P`` the a posteriori one. Each sample
  updates ``x_hat[k|k] = x_hat[k|k-1] + M (y[k] - C x_hat[k|k-1])``, the law acts on
  ``x_hat[k|k]`` (MATLAB ``kalman(..., 'current')``), then predicts
  ``x_hat[k+1|k] = Ad x_hat[k|k] + Bd du[k]``. The predictor gain is ``L = Ad M``; the
  estimator's eigenvalues are those of ``Ad - L C`` (equal to those of ``(I - M C) Ad``).
  The process noise is the body force and torque held over each sample (as the simulation draws
  it when ``simulation.noise.period`` is the controller period): ``Gd`` is ``G`` through the same
  hold, exact for that noise.
- continuous controller: the Kalman-Bucy filter, MATLAB ``lqe(A, G, C, W, V)``,
  ``dx_hat/dt = A x_hat + B du + L (y - C x_hat)``, ``L = P C' V^-1``, integrated in every RK4
  stage. The intensities of held noise of std ``sigma`` and period ``tau`` are ``sigma^2 tau``
  (their spectrum at low frequency).

Both Riccati equations are solved as the dual LQR problem by :func:`quadctl.design.riccati.solve`
(validated, residual-checked). The measured set must leave every mode that is not stable
observable (PBH, :func:`quadctl.analysis.check`, rank tolerance ``max(shape) eps sigma_max``);
else :func:`kalman` refuses with the modes and the states they live in.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from quadctl.analysis import check
from quadctl.errors import DesignError
from quadctl.layout import N_STATES, SENSOR_GROUPS, STATE_INDEX, STATE_NAMES
from quadctl.messages import eig_text, show
from quadctl.model import N_DISTURBANCES, Vehicle, build_model
from quadctl.stability import is_stable


@dataclass(frozen=True)
class Kalman:
    """A steady-state Kalman filter.

    Attributes
    ----------
    form : {"filter", "kalman-bucy"}
        ``filter``: discrete, ``gain`` is the measurement-update gain ``M`` (MATLAB ``dlqe``'s ``M``);
        ``kalman-bucy``: continuous, ``gain`` is ``L`` of ``dx_hat/dt = ... + L (y - C x_hat)``.
    measured : tuple of str
        The measured states (rows of ``C``).
    A, B : (12, 12), (12, 4) ndarray
        The model the filter runs: ``Ad, Bd`` (discrete) or ``A, B``.
    C : (p, 12) ndarray
        Selects the measured states.
    G : (12, 6) ndarray
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

    @property
    def discrete(self) -> bool:
        return self.sample_time is not None

    def error_std(self) -> np.ndarray:
        """(12,) predicted steady standard deviation of ``x - x_hat`` the law acts on (``Z`` discrete)."""
        return np.sqrt(np.maximum(np.diag(self.Z), 0.0))


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


def require_detectable(A, C, measured, key: str = "estimator.measure") -> None:
    """Refuse a measured set that leaves a mode that is not stable unobservable (PBH).

    Raises
    ------
    DesignError
        Naming the modes, the states they live in, and what to measure.
    """
    checks = check(A, np.zeros((A.shape[0], 1)), C, STATE_NAMES)
    bad = [m for m in checks.pbh_obsv if not m.passed and not is_stable(m.eigenvalue)]
    if not bad:
        return
    states = sorted({s for m in bad for s in _unobserved_states(A, C, m.eigenvalue)}, key=STATE_INDEX.get)
    modes = ", ".join(eig_text(m.eigenvalue, 3) for m in bad)
    groups = [g for g, ss in SENSOR_GROUPS.items() if set(states) & set(ss)]
    raise DesignError(
        f"{key} = {show(list(measured))}: {', '.join(states)} not observable (modes at s = {modes}, not stable): "
        f"measure {' and '.join(states)}" + (f" (e.g. add {' or '.join(groups)})" if groups else ""))


def _unobserved_states(A, C, lam: complex) -> tuple[str, ...]:
    """States the unobservable subspace at ``lam`` lives in: rows of the null space of
    ``[lam I - A; C]`` (rank tolerance of :func:`quadctl.analysis.numerical_rank`) above a tenth of the largest."""
    n = A.shape[0]
    stacked = np.vstack([lam * np.eye(n) - A, C])
    _, sv, vh = np.linalg.svd(stacked)
    tol = max(stacked.shape) * np.finfo(float).eps * sv[0]
    null = vh[np.sum(sv > tol):].conj().T
    weight = np.linalg.norm(null, axis=1)
    return tuple(STATE_NAMES[i] for i in range(n) if weight[i] > 0.1 * weight.max())


def kalman(A, B, G, measured, sensor_std, process_std, *, sample_time: float | None = None,
           period: float | None = None) -> Kalman:
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
        s the noise is held for: the continuous intensities ``sigma^2 period`` (required then).

    Returns
    -------
    Kalman

    Raises
    ------
    DesignError
        A mode that is not stable is unobservable from ``measured``, or the Riccati equation is refused.
    """
    from quadctl.design import discrete as dsc
    from quadctl.design.riccati import solve

    A, B, G = (np.asarray(M, dtype=float) for M in (A, B, G))
    measured = tuple(measured)
    C = selector(measured)
    require_detectable(A, C, measured)
    Rn = np.diag(np.asarray(sensor_std, dtype=float) ** 2)
    Qn = np.diag(np.asarray(process_std, dtype=float) ** 2)
    if sample_time is None:
        if period is None:
            raise ValueError("a continuous filter needs the noise period (s) for its intensities")
        Qn, Rn = Qn * period, Rn * period
        res = solve(A.T, C.T, G @ Qn @ G.T, Rn, name="estimator (Kalman-Bucy)", state_names=STATE_NAMES)
        P = res.P
        L = np.linalg.solve(Rn, C @ P).T
        return Kalman(form="kalman-bucy", measured=measured, A=A, B=B, C=C, G=G, Qn=Qn, Rn=Rn, gain=L,
                      predictor_gain=L, P=P, Z=P, eigenvalues=np.linalg.eigvals(A - L @ C),
                      sample_time=None, residual=res.residual)
    Ad, Bd = dsc.c2d(A, B, sample_time)
    _, Gd = dsc.c2d(A, G, sample_time)
    res = solve(Ad.T, C.T, Gd @ Qn @ Gd.T, Rn, discrete=True, name="estimator (discrete Kalman filter)",
                state_names=STATE_NAMES)
    P = res.P
    M = np.linalg.solve(C @ P @ C.T + Rn, C @ P).T
    Z = P - M @ C @ P
    L = Ad @ M
    return Kalman(form="filter", measured=measured, A=Ad, B=Bd, C=C, G=Gd, Qn=Qn, Rn=Rn, gain=M,
                  predictor_gain=L, P=P, Z=(Z + Z.T) / 2, eigenvalues=np.linalg.eigvals(Ad - L @ C),
                  sample_time=float(sample_time), residual=res.residual)

