"""The linear closed loop flown through a Kalman filter (LQG), and the loop the builder simulates.

The law acts on the filter's estimate (:mod:`quadctl.design.kalman`, continuous or discrete at the
controller period) instead of the state: :func:`lqg` breaks that loop at the plant input for the
margins, :func:`lqg_matrix` closes it, and :func:`lqg_vehicle` is the whole loop that flies (the
rotors' lag, the gyro filter, the integrators, the controller's lag model, the delay), the one the
check stage's verdict judges. :func:`simulated` is :mod:`quadctl.sim.builder`'s loop linearized at
the reference, with or without a filter. Built on :mod:`quadctl.design.linear_loop` (its ``close``
and ``vehicle_matrix``); the state layout is in the docs, docs/internals.md ("The Kalman filter",
"The linear closed loop").
"""

from __future__ import annotations

import numpy as np

from quadctl.design import discrete, integral, lag
from quadctl.design.linear_loop import close, vehicle_matrix
from quadctl.layout import N_STATES, STATE_INDEX, STATE_NAMES
from quadctl.linear import stability
from quadctl.linear.filters import RATE_STATES, series


def lqg(design, A, B, kal):
    """``(A, Bp, Be, Kc)`` of the loop closed through a Kalman filter (LQG): ``A - [Bp; Be; 0] Kc``.

    Loop state ``[x; x_hat; z]`` (``x_hat`` the a priori estimate of a discrete filter; with a gyro
    filter in the Kalman filter's model, ``kal.rate_filter``, ``x`` is the plant followed by the filter,
    ``[x; g]``, :func:`quadctl.linear.filters.series`, and ``x_hat`` its estimate, the law acting on the
    estimate of the 12 states), the
    command ``c = -Kc [x; x_hat; z]`` (continuous: ``Kc = [0, K, Ki]``; discrete: the law on
    ``xc = M C x + (I - M C) x_hat``, ``Kc = [K M C, K (I - M C), Ki]``); ``Bp`` carries it into
    the plant, ``Be`` into the estimator (which knows the command, not what the plant got: a loop
    broken at the plant input keeps ``Be``). The integrators integrate the estimate (``xc``).
    :mod:`quadctl.sim.builder` runs the same loop with the state ordered ``[x; z; x_hat]``.

    Parameters
    ----------
    design : quadctl.design.Design
    A, B : (12, 12), (12, 4) array_like
        The continuous coupled linear model.
    kal : quadctl.design.kalman.Kalman
        Continuous (Kalman-Bucy: ``kal.gain`` is ``L``) or discrete at the controller period
        (``kal.gain`` is ``M``, ``kal.A``, ``kal.B`` the ZOH model).

    Returns
    -------
    (2 ne + nz, 2 ne + nz) ndarray, (ne, 4) ndarray, (ne, 4) ndarray, (4, 2 ne + nz) ndarray
        ``ne = kal.n_estimate``: 12, or 12 and the gyro filter's states.
    """
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    K, ints = design.K_block, design.integral_states
    nz, n = len(ints), kal.n_estimate
    Ki = np.asarray(design.Ki_block, dtype=float).reshape(K.shape[0], nz)
    Cz = np.hstack([integral.selector(STATE_NAMES, ints), np.zeros((nz, n - N_STATES))])
    K = np.hstack([K, np.zeros((K.shape[0], n - N_STATES))])  # the law reads the estimate of x
    if kal.rate_filter is not None and kal.sample_time is None:
        A, B = series(A, B, kal.rate_filter.form(None), [STATE_INDEX[s] for s in RATE_STATES])
    C, G, Ts = kal.C, kal.gain, kal.sample_time
    Z = np.zeros
    if Ts is None:
        base = np.block([[A, Z((n, n)), Z((n, nz))], [G @ C, A - G @ C, Z((n, nz))],
                         [Z((nz, n)), -Cz, Z((nz, nz))]])
        Kc = np.hstack([Z(K.shape), K, Ki])
        Bp, Be = B, B
    else:
        Ad, Bd = kal.A, kal.B
        Mx, Mh = G @ C, np.eye(n) - G @ C
        base = np.block([[Ad, Z((n, n)), Z((n, nz))], [Ad @ Mx, Ad @ Mh, Z((n, nz))],
                         [-Ts * Cz @ Mx, -Ts * Cz @ Mh, np.eye(nz)]])
        Kc = np.hstack([K @ Mx, K @ Mh, Ki])
        Bp, Be = Bd, Bd
    return base, Bp, Be, Kc


def lqg_matrix(design, A, B, kal) -> np.ndarray:
    """The closed LQG loop of :func:`lqg` (state ``[x; x_hat; z]``, every state kept)."""
    base, Bp, Be, Kc = lqg(design, A, B, kal)
    return close(base, np.vstack([Bp, Be, np.zeros((len(design.integral_states), Bp.shape[1]))]), Kc)


def lqg_vehicle(design, A, B, kal, delay_samples: int = 0, rotor_time_constant: float | None = None, *,
                keep_free: bool = False) -> np.ndarray:
    """The closed loop the vehicle flies through the Kalman filter ``kal``: :func:`vehicle_matrix`'s plant
    (the rotors' lag, the gyro filter, the integrators, the controller's lag model, the delay) with the
    law acting on the filter's estimate, as :mod:`quadctl.sim.builder` runs it.

    The state is ``[s; z; l; b; e]``: ``s`` the plant ``[x; v; g]`` (:func:`quadctl.design.lag.lagged`'s
    lag states ``v``, the gyro filter's ``g``), ``z`` the integrators, ``l`` the lag model, ``b`` the
    delay's buffer and ``e = [x; g] - x_hat`` the estimate's error (a similarity of the loop in
    ``x_hat``). Sampled (``kal`` discrete at the controller period): the law acts on the updated
    estimate ``xc = x_hat + M (y - C x_hat)``, the integrators integrate it, and the a priori estimate
    is predicted under the input the plant gets (after the delay), ``x_hat <- Ae xc + Be u``.
    Continuous (Kalman-Bucy): ``dx_hat/dt = Ae x_hat + Be u + L (y - C x_hat)``, the law on ``x_hat``.
    Without the rotors' lag and the delay it is :func:`lqg_matrix`'s loop (the separation principle:
    ``eig(A - B K)`` of the integrators' loop and ``eig(Ae - Ae M C)``, or ``eig(A - L C)``).

    Parameters
    ----------
    design : quadctl.design.Design
    A, B : (12, 12), (12, 4) array_like
        The continuous coupled linear model.
    kal : quadctl.design.kalman.Kalman
        Its ``sample_time`` is the loop's; its ``rate_filter`` the loop's gyro filter.
    delay_samples : int
        Controller samples of delay (sampled loops).
    rotor_time_constant : float, optional
        s of the rotors' lag (the filter's model does not have it).
    keep_free : bool
        Keep the positions nothing reads (:func:`quadctl.linear.stability.free_positions`); in the
        error coordinates their columns are their own (the estimate's error does not depend on the
        plant), so leaving them out leaves the other eigenvalues.

    Returns
    -------
    (N, N) ndarray
    """
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    Ts, ints = kal.sample_time, design.integral_states
    if delay_samples and Ts is None:
        raise ValueError("a delay is counted in controller samples: a continuous filter's loop has none")
    rates = [STATE_INDEX[s] for s in RATE_STATES]
    Al, Bl = lag.lagged(A, B, rotor_time_constant)
    if Ts is not None:
        Al, Bl = discrete.c2d(Al, Bl, Ts)
    As, Bs = series(Al, Bl, kal.rate_filter.form(Ts) if kal.rate_filter is not None else None, rates)
    ns, ne, m = As.shape[0], kal.n_estimate, B.shape[1]
    nz, nl, nb = len(ints), m if design.lag_time_constant is not None else 0, m * delay_samples
    E = np.zeros((ne, ns))  # [x; g] of the plant: what the filter estimates
    E[:N_STATES, :N_STATES] = np.eye(N_STATES)
    E[N_STATES:, ns - (ne - N_STATES):] = np.eye(ne - N_STATES)
    K = np.hstack([design.K_block, np.zeros((m, ne - N_STATES))])  # the law reads the estimate of x
    Ki = np.asarray(design.Ki_block, dtype=float).reshape(m, nz)
    Cz = np.hstack([integral.selector(STATE_NAMES, ints), np.zeros((nz, ne - N_STATES))])
    C, G = kal.C, kal.gain
    # blocks of the state [s; z; l; b; x_hat]
    o = np.cumsum([0, ns, nz, nl, nb, ne])
    S, Z, Lm, Bf, H = (slice(o[i], o[i + 1]) for i in range(5))
    N = o[-1]
    # what the law acts on: xc = Xs s + Xh x_hat
    Xs, Xh = (G @ C @ E, np.eye(ne) - G @ C) if Ts is not None else (np.zeros((ne, ns)), np.eye(ne))
    cmd = np.zeros((m, N))
    cmd[:, S], cmd[:, H], cmd[:, Z] = -K @ Xs, -K @ Xh, -Ki
    if nl:
        cmd[:, Lm] = -np.asarray(design.Kv_block, dtype=float)
    applied = cmd
    if nb:  # the oldest command reaches the plant
        applied = np.zeros((m, N))
        applied[:, o[4] - m:o[4]] = np.eye(m)
    M = np.zeros((N, N))
    M[S, S] = As
    M[S] += Bs @ applied
    if Ts is not None:
        M[Z, S], M[Z, H] = -Ts * Cz @ Xs, -Ts * Cz @ Xh
        M[Z, Z] = np.eye(nz)
        if nl:
            a = lag.model_pole(design.lag_time_constant, Ts)
            M[Lm] = (1 - a) * cmd
            M[Lm, Lm] += a * np.eye(m)
        if nb:  # b_1 <- command, b_k <- b_(k-1)
            M[o[3]:o[3] + m] = cmd
            M[o[3] + m:o[4], o[3]:o[4] - m] = np.eye(nb - m)
        M[H, S], M[H, H] = kal.A @ Xs, kal.A @ Xh
        M[H] += kal.B @ applied
    else:
        M[Z, H] = -Cz
        if nl:
            M[Lm] = cmd / design.lag_time_constant
            M[Lm, Lm] -= np.eye(m) / design.lag_time_constant
        M[H] = kal.B @ applied
        M[H, S] += G @ C @ E
        M[H, H] += kal.A - G @ C
    T = np.eye(N)  # x_hat -> e = E s - x_hat (T is its own inverse)
    T[H, S], T[H, H] = E, -np.eye(ne)
    M = T @ M @ T
    if keep_free:
        return M
    free = [STATE_INDEX[s] for s in stability.free_positions(A, reads=(design.K_block,), integral_states=ints)]
    keep = [i for i in range(N) if i not in free]
    return M[np.ix_(keep, keep)]


def simulated(A, B, K, *, Ki=None, integral_states=(), Kv=None, lag_time_constant: float | None = None,
              rotor_time_constant: float | None = None, mix=None, estimator=None, rate_filter=None) -> np.ndarray:
    """The continuous loop :mod:`quadctl.sim.builder` simulates, linearized at the reference, in its state
    order ``[x; f; z; l; g; xh]`` (every state kept): the linear part of its exponential integrator.

    It is :func:`vehicle_matrix` (or :func:`lqg_matrix`, reordered from ``[x; x_hat; z]``) with the
    rotors' lag in the builder's coordinates, the thrusts ``f = mix v`` (deviations from trim).

    Parameters
    ----------
    A, B : (12, 12), (12, 4) array_like
        The continuous coupled linear model.
    K : (4, 12) array_like
    Ki : (4, nz) array_like, optional
    integral_states : sequence of str
    Kv : (4, 4) array_like, optional
        Gain on the controller's lag model (with ``lag_time_constant``, s).
    rotor_time_constant : float, optional
        s of the rotors' lag; ``mix`` (4, 4) maps ``[T, A, E, R]`` to the rotor thrusts.
    estimator : quadctl.design.kalman.Kalman, optional
        A continuous (Kalman-Bucy) filter the law closes through.
    rate_filter : quadctl.linear.filters.StateSpace, optional
        The continuous gyro filter the law takes the rates through (state ``[x; f; z; l; g]``).

    Returns
    -------
    (nx, nx) ndarray

    Raises
    ------
    ValueError
        A discrete filter, or a filter with the rotors' lag (no such loop here).
    """
    from types import SimpleNamespace

    K = np.atleast_2d(np.asarray(K, dtype=float))
    nz = len(integral_states)
    Ki = np.zeros((K.shape[0], 0)) if Ki is None else np.asarray(Ki, dtype=float).reshape(K.shape[0], nz)
    design = SimpleNamespace(K_block=K, Ki_block=Ki, integral_states=tuple(integral_states),
                             lag_time_constant=lag_time_constant if Kv is not None else None, Kv_block=Kv)
    if estimator is not None:
        if estimator.sample_time is not None or rotor_time_constant is not None:
            raise ValueError("the simulated LQG loop is linearized here for a continuous filter, without rotor lag")
        if (rate_filter is None) != (estimator.rate_filter is None):
            raise ValueError("the Kalman filter's model and the loop must have the same gyro filter")
        n, ne = N_STATES, estimator.n_estimate  # [x; g; x_hat; z] -> the builder's [x; z; g; x_hat]
        order = [*range(n), *range(2 * ne, 2 * ne + nz), *range(n, 2 * ne)]
        return lqg_matrix(design, A, B, estimator)[np.ix_(order, order)]
    M = vehicle_matrix(design, A, B, None, 0, rotor_time_constant, keep_free=True, rate_filter=rate_filter)
    if rotor_time_constant is not None:
        T = np.eye(len(M))
        T[N_STATES:N_STATES + 4, N_STATES:N_STATES + 4] = mix
        M = T @ M @ np.linalg.inv(T)
    return M
