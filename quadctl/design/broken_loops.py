"""The loops of a design broken at one plant input: ``L = k (sI - A)^-1 b`` (or in ``z``), the other loops closed.

:class:`BrokenLoop` is one such loop's transfer function; :func:`design_loops` yields every regulated loop
of a design (each subsystem alone, and the coupled vehicle), continuous or sampled, with the delay, the
rotors' lag and the gyro filter in it; :func:`lqg_loops` the loops through a Kalman filter. Their margins:
:func:`quadctl.design.margin_search.loop_margins`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.design import linear_loop, lqg_loop
from quadctl.layout import INPUT_INDEX, STATE_INDEX
from quadctl.linear.stability import free_positions, is_stable


@dataclass(frozen=True, eq=False)
class BrokenLoop:
    """``L = k (sI - A)^-1 b`` (or in ``z`` with ``sample_time``): a loop broken at one input."""

    A: np.ndarray
    b: np.ndarray
    k: np.ndarray
    sample_time: float | None = None

    def __call__(self, w) -> np.ndarray:
        """``L`` at frequencies ``w`` (rad/s), complex, same shape as ``w``."""
        w = np.atleast_1d(np.asarray(w, dtype=float))
        s = np.exp(1j * w * self.sample_time) if self.sample_time else 1j * w
        n = self.A.shape[0]
        M = s[:, None, None] * np.eye(n) - self.A[None, :, :]
        x = np.linalg.solve(M, np.broadcast_to(self.b, (len(w), n))[..., None])[..., 0]
        return x @ self.k

    def closed_loop_eigenvalues(self, gain: float = 1.0) -> np.ndarray:
        return np.linalg.eigvals(linear_loop.close(self.A, self.b[:, None], gain * self.k[None, :]))

    def is_stable(self, gain: float = 1.0) -> bool:
        return bool(np.all(is_stable(self.closed_loop_eigenvalues(gain), discrete=bool(self.sample_time))))


def broken_loop(A, B, K, j: int, sample_time: float | None = None) -> BrokenLoop:
    """The loop of ``u = -K x`` broken at input ``j``, the other inputs' loops closed.

    Parameters
    ----------
    A : (n, n) array_like
        Plant (discrete ``Ad`` with ``sample_time``).
    B : (n, m) array_like
    K : (m, n) array_like
    j : int
        Input to break at.
    sample_time : float, optional
        s; given, ``A`` and ``B`` are the ZOH plant.
    """
    A, B, K = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (A, B, K))
    return BrokenLoop(A=linear_loop.broken(A, B, K, j), b=B[:, j].copy(), k=K[j, :].copy(), sample_time=sample_time)


def design_loops(design, decoupled, A, B, sample_time: float | None = None, delay_samples: int = 0,
                 rotor_time_constant: float | None = None, rate_filter=None):
    """Yield ``(name, input, model, BrokenLoop)`` for every regulated loop of ``design``.

    ``model = "design"``: the subsystem alone (with its integrators), the loop the LQR guarantee
    is about. ``model = "coupled"``: the 12-state linear model, every other loop closed, position
    states that nothing feeds back left out. With ``sample_time`` (s: the controller's period, the
    design's own for a discrete design, or the rate a continuous design is run at) the loops are
    sampled, with ``delay_samples`` of delay on every input (:func:`quadctl.design.linear_loop.delayed`);
    ``rotor_time_constant`` puts the rotors' lag on every input (:func:`quadctl.design.lag.lagged`);
    ``rate_filter`` (:class:`quadctl.linear.filters.RateFilter`) the gyro filter in the law's rate path, in
    its continuous form or at ``sample_time``.
    """
    Ts = sample_time
    form = rate_filter.form(Ts) if rate_filter is not None else None
    for sub in design.subsystems:
        Aa, Ba, Ka = linear_loop.subsystem(sub, decoupled[sub.name], Ts, delay_samples=delay_samples,
                                           rotor_time_constant=rotor_time_constant, rate_filter=form)
        for j, inp in enumerate(sub.inputs):
            yield sub.name, inp, "design", broken_loop(Aa, Ba, Ka, j, Ts)
    Af, Bf, Kf = linear_loop.vehicle(design, A, B, Ts, delay_samples, rotor_time_constant, rate_filter=form)
    for sub in design.subsystems:
        for inp in sub.inputs:
            yield sub.name, inp, "coupled", broken_loop(Af, Bf, Kf, INPUT_INDEX[inp], Ts)


def lqg_loops(design, A, B, kal):
    """Yield ``(name, input, "lqg", BrokenLoop)``: every regulated input's loop with the Kalman filter in it.

    Loop state ``[x; x_hat; z]`` (``x_hat`` a priori for the discrete filter), the command
    ``c = -Kc [x; x_hat; z]`` (continuous: ``Kc = [0, K, Ki]``; discrete: the law on
    ``xc = M C x + (I - M C) x_hat``, ``Kc = [K M C, K (I - M C), Ki]``), the plant given ``c``
    except at the broken input ``j`` (given ``v``), the estimator and the integrators fed ``c`` and
    ``xc``. Positions nothing feeds back are left out in the coordinates ``[x; x - x_hat; z]``
    (there they drive nothing), as on the full-state coupled loop. With a gyro filter in the Kalman
    filter's model (``kal.rate_filter``) ``x`` is ``[x; g]``: the filter runs on the plant's rates and the
    estimator measures its output, so the loop broken at the plant input has both in it.

    Parameters
    ----------
    design : quadctl.design.Design
    A, B : (12, 12), (12, 4) array_like
        The continuous coupled linear model.
    kal : quadctl.design.kalman.Kalman
    """
    A = np.asarray(A, dtype=float)
    K, ints = design.K_block, design.integral_states
    nz, n, Ts = len(ints), kal.n_estimate, kal.sample_time  # n: the 12 states, and the gyro filter's modelled
    Z = np.zeros
    base, Bp, Be, Kc = lqg_loop.lqg(design, A, B, kal)
    T = np.eye(2 * n + nz)
    T[n:2 * n, :n], T[n:2 * n, n:2 * n] = np.eye(n), -np.eye(n)  # [x; x - x_hat; z]; T^-1 = T
    free = [STATE_INDEX[s] for s in free_positions(A, reads=(K,), integral_states=ints)]
    keep = [i for i in range(2 * n + nz) if i not in free]
    for sub in design.subsystems:
        for inp in sub.inputs:
            j = INPUT_INDEX[inp]
            others = Bp.copy()
            others[:, j] = 0.0
            Aa = linear_loop.close(base, np.vstack([others, Be, Z((nz, Bp.shape[1]))]), Kc)
            b = np.concatenate([Bp[:, j], Z(n), Z(nz)])
            At, bt, kt = T @ Aa @ T, T @ b, Kc[j] @ T
            yield sub.name, inp, "lqg", BrokenLoop(A=At[np.ix_(keep, keep)], b=bt[keep], k=kt[keep],
                                                   sample_time=Ts)
