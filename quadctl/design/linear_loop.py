"""The linear closed loop of a design: the one place a loop ``A - B K`` is built, one case or a stack.

A plant ``(A, B)`` about the trim, continuous or held at ``sample_time``, closed by
``u = -K x - Kv l - Ki z``, with the rotors' lag, integrators, the controller's lag model
(:func:`with_lag_model`), a delay's buffer (:func:`delayed`) and the gyro filter, its states in the
order :mod:`quadctl.sim.builder` keeps them. Taken by the design's verdict (:func:`matrix`), the
margins and the check stage (:func:`vehicle`), the rate check (:func:`subsystem`), sweeps and
:mod:`quadctl.export.interop`. The loops flown through a Kalman filter, and the builder's loop
linearized, are :mod:`quadctl.design.lqg_loop`'s (built on these). The state layout is in the docs,
docs/internals.md ("The linear closed loop").
"""

from __future__ import annotations

import numpy as np

from quadctl.design import discrete, integral, lag
from quadctl.design.riccati import real_array
from quadctl.errors import DesignError
from quadctl.layout import N_STATES, STATE_INDEX, STATE_NAMES
from quadctl.linear import stability
from quadctl.linear.filters import RATE_STATES, with_rate_filter


def close(A, B, K) -> np.ndarray:
    """``A - B K``: the loop of ``u = -K x`` on ``x' = A x + B u`` (or ``x+ = A x + B u``).

    Parameters
    ----------
    A : (..., n, n) array_like
    B : (..., n, m) array_like
    K : (..., m, n) array_like
        Leading dimensions (a stack of loops) broadcast.

    Returns
    -------
    (..., n, n) ndarray

    Examples
    --------
    >>> close([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[2.0, 3.0]]).tolist()
    [[0.0, 1.0], [-2.0, -3.0]]
    """
    A, B, K = (np.asarray(M, dtype=float) for M in (A, B, K))
    return A - B @ K


def open_loop(A, B, integral_states=(), sample_time: float | None = None, *,
              rotor_time_constant: float | None = None, states=STATE_NAMES) -> tuple[np.ndarray, np.ndarray]:
    """The plant a gain ``[K, Kv_plant, Ki]`` closes: ``[x; v; z]`` with the rotors' lag, the hold and
    the integrators.

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
        The continuous plant of ``states``.
    integral_states : iterable of str
        States integrated (``dz/dt = -x_s``; sampled, ``z <- z - Ts x_s``).
    sample_time : float, optional
        s: the zero-order hold of the plant (with its lag) at this period.
    rotor_time_constant : float, optional
        s: every input reaches the plant through ``1 / (tau s + 1)``.
    states : sequence of str
        Names of the rows of ``A``.

    Returns
    -------
    (n + nv + nz, n + nv + nz) ndarray, (n + nv + nz, m) ndarray
    """
    Al, Bl = lag.lagged(A, B, rotor_time_constant)
    ints = tuple(integral_states)
    extra = Al.shape[0] - len(states)
    C = np.hstack([integral.selector(states, ints), np.zeros((len(ints), extra))])
    if sample_time is None:
        return integral.augment(Al, Bl, C)
    Ad, Bd = discrete.c2d(Al, Bl, sample_time)
    return integral.augment_discrete(Ad, Bd, C, sample_time)


def gain(K, Ki=None, Kv=None, *, n_lag: int = 0) -> np.ndarray:
    """The gain ``[K, Kv, Ki]`` on ``[x; v; z]`` (:func:`open_loop`'s state).

    Parameters
    ----------
    K : (m, n) array_like
    Ki : (m, nz) array_like, optional
        None: no integrators.
    Kv : (m, n_lag) array_like, optional
        Gain on the lag states; zero when None.
    n_lag : int
        Lag states in the plant (0 or m).
    """
    K = np.atleast_2d(np.asarray(K, dtype=float))
    parts = [K]
    if n_lag:
        parts.append(np.zeros((K.shape[0], n_lag)) if Kv is None else np.asarray(Kv, dtype=float))
    if Ki is not None:
        Ki = np.asarray(Ki, dtype=float)
        parts.append(Ki.reshape(K.shape[0], Ki.size // K.shape[0]))
    return np.hstack(parts) if len(parts) > 1 else K


def matrix(A, B, K, Ki=None, integral_states=(), sample_time=None, *, Kv=None,
           lag_time_constant: float | None = None) -> np.ndarray:
    """The coupled closed loop of ``[x; z]`` under ``u = -K x - Ki z`` (deviations from trim).

    Continuous: ``[[A - B K, -B Ki], [-C, 0]]``. With ``sample_time`` (a discrete controller on
    the ZOH plant): ``[[Ad - Bd K, -Bd Ki], [-Ts C, I]]``. ``C`` selects ``integral_states``.
    With ``lag_time_constant`` the plant's inputs lag (:func:`quadctl.design.lag.lagged`): the state is
    ``[x; v; z]`` and the gain ``[K, Kv]`` on ``[x; v]`` (``Kv`` (4, 4), zero when None): the loop a
    design that includes the lag sees.

    Parameters
    ----------
    A : (12, 12) array_like
    B : (12, 4) array_like
    K : (4, 12) array_like
    Ki : (4, nz) array_like, optional
    integral_states : sequence of str
    sample_time : float, optional
        s.
    Kv : (4, 4) array_like, optional
    lag_time_constant : float, optional
        s.

    Returns
    -------
    (12 + nv + nz, 12 + nv + nz) ndarray

    Raises
    ------
    ArgumentError
        A matrix that is complex, not numeric, or of a shape that does not fit (named).
    """

    who = "closed_loop_matrix"  # its public name (quadctl.design.closed_loop_matrix)
    A = real_array(A, "A", name=who, ndim=2)
    n = A.shape[0]
    A = real_array(A, "A", name=who, shape=(n, n))
    B = real_array(B, "B", name=who, ndim=2, shape=(n, None))
    m = B.shape[1]
    K = real_array(K, "K", name=who, ndim=2, shape=(m, n))
    if lag_time_constant is not None:
        A, B = lag.lagged(A, B, lag_time_constant)
        K = np.hstack([K, np.zeros((m, m)) if Kv is None else real_array(Kv, "Kv", name=who, shape=(m, m))])
    nz = len(integral_states)
    Ki = np.zeros((m, 0)) if Ki is None else real_array(Ki, "Ki", name=who)
    if Ki.size != m * nz:
        raise DesignError(f"{who}: Ki has shape {Ki.shape}, expected {m} x {nz} (inputs x integral_states)")
    Ki = Ki.reshape(m, nz)
    if sample_time is not None:
        A, B = discrete.c2d(A, B, sample_time)
    return stack(A, B, K, Ki, integral_states, sample_time)


def stack(A, B, K, Ki, integral_states, sample_time=None) -> np.ndarray:
    """:func:`matrix` of stacked gains on a plant already held: ``(A, B)`` continuous, or the ZOH
    plant ``(Ad, Bd)`` of ``sample_time``.

    Parameters
    ----------
    A : (..., n, n) array_like
    B : (..., n, m) array_like
    K : (..., m, n) array_like
    Ki : (..., m, nz) array_like
    integral_states : sequence of str
        Of the first 12 states.
    sample_time : float, optional
        s: the integrators accumulate ``z <- z - Ts x_s``.

    Returns
    -------
    (..., n + nz, n + nz) ndarray
    """
    A, B, K, Ki = (np.asarray(M, dtype=float) for M in (A, B, K, Ki))
    n, nz = A.shape[-1], len(integral_states)
    C = np.hstack([integral.selector(STATE_NAMES, integral_states), np.zeros((nz, n - N_STATES))])
    lead = np.broadcast_shapes(A.shape[:-2], B.shape[:-2], K.shape[:-2], Ki.shape[:-2])
    out = np.zeros((*lead, n + nz, n + nz))
    out[..., :n, :n] = close(A, B, K)
    out[..., :n, n:] = -(B @ Ki)
    if sample_time is None:
        out[..., n:, :n] = -C
    else:
        out[..., n:, :n] = -sample_time * C
        out[..., n:, n:] = np.eye(nz)
    return out


def subsystem(sub, plant, sample_time: float | None = None, *, delay_samples: int = 0,
              rotor_time_constant: float | None = None,
              rate_filter=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B, K)`` of one subsystem's loop on its own model: the plant with the rotors' lag, the
    hold and the delay, the gain ``[K, Kv, Ki]`` (the lag states fed back only by a design that
    includes the lag).

    Parameters
    ----------
    sub : quadctl.design.decoupled.SubsystemDesign
    plant : quadctl.linear.decouple.Subsystem
        Its ``A``, ``B``.
    sample_time : float, optional
    delay_samples : int
        Of a sampled loop.
    rotor_time_constant : float, optional
    rate_filter : quadctl.linear.filters.StateSpace, optional
        The gyro filter at the loop's timing: the law takes the subsystem's rates through it.
    """
    As, Bs = open_loop(plant.A, plant.B, sub.integral, sample_time, rotor_time_constant=rotor_time_constant,
                       states=sub.states)
    n_lag = len(sub.inputs) if rotor_time_constant is not None else 0
    Ka = gain(sub.K, sub.Ki, sub.Kv if n_lag else None, n_lag=n_lag)
    if sample_time is not None:
        As, Bs, Ka = delayed(As, Bs, Ka, delay_samples)
    return with_rate_filter(As, Bs, Ka, rate_filter, [i for i, s in enumerate(sub.states) if s in RATE_STATES])


def vehicle(design, A, B, sample_time: float | None = None, delay_samples: int = 0,
            rotor_time_constant: float | None = None, *, keep_free: bool = False, rate_filter=None):
    """``(A, B, K)`` of the loop the vehicle has: the design's gains on the coupled model with the
    rotors' lag, the integrators, the controller's lag model (a design that includes the lag) and
    the delay; the positions left free (:func:`quadctl.linear.stability.free_positions`) left out.

    Parameters
    ----------
    design : quadctl.design.decoupled.Design
        ``K_block``, ``Ki_block``, ``integral_states``, ``lag_time_constant``, ``Kv_block``.
    A : (12, 12) array_like
    B : (12, 4) array_like
        The continuous coupled linear model.
    sample_time : float, optional
        s of a sampled controller (the hold).
    delay_samples : int
        Controller samples of delay (sampled loops).
    rotor_time_constant : float, optional
        s of the rotors' lag.
    keep_free : bool
        Keep every state (the loop state is then :mod:`quadctl.sim.builder`'s ``[x; f; z; l; b; g]``).
    rate_filter : quadctl.linear.filters.StateSpace, optional
        The gyro filter at the loop's timing (continuous, or at ``sample_time``): the law takes the
        body rates through it.

    Returns
    -------
    (N, N) ndarray, (N, 4) ndarray, (4, N) ndarray
        The loop is ``A - B K`` (:func:`close`); ``B`` and ``K`` break it at the plant input.
    """
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    K, ints = design.K_block, design.integral_states
    Aa, Ba = open_loop(A, B, ints, sample_time, rotor_time_constant=rotor_time_constant)
    n_lag = Aa.shape[0] - N_STATES - len(ints)
    Ka = gain(K, design.Ki_block, n_lag=n_lag)
    keep = list(range(Aa.shape[0]))
    if not keep_free:
        free = [STATE_INDEX[s] for s in stability.free_positions(A, reads=(K,), integral_states=ints)]
        keep = [i for i in range(Aa.shape[0]) if i not in free]
        Aa, Ba, Ka = Aa[np.ix_(keep, keep)], Ba[keep], Ka[:, keep]
    rates = [keep.index(STATE_INDEX[s]) for s in RATE_STATES]
    if design.lag_time_constant is not None:
        Aa, Ba, Ka = with_lag_model(Aa, Ba, Ka, design.Kv_block, design.lag_time_constant, sample_time)
    if sample_time is not None:
        Aa, Ba, Ka = delayed(Aa, Ba, Ka, delay_samples)
    return with_rate_filter(Aa, Ba, Ka, rate_filter, rates)


def vehicle_matrix(design, A, B, sample_time: float | None = None, delay_samples: int = 0,
                   rotor_time_constant: float | None = None, *, keep_free: bool = False,
                   rate_filter=None) -> np.ndarray:
    """``A - B K`` of :func:`vehicle`: continuous, or the ``z``-domain loop of a controller sampled
    every ``sample_time`` s (with ``delay_samples`` of delay, and the gyro filter ``rate_filter``)."""
    return close(*vehicle(design, A, B, sample_time, delay_samples, rotor_time_constant, keep_free=keep_free,
                          rate_filter=rate_filter))


def broken(A, B, K, j: int) -> np.ndarray:
    """``A - B_o K_o``: the loop of ``u = -K x`` with input ``j``'s feedback removed (every other
    input's loop closed), where a loop is broken for its margins."""
    A, B, K = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (A, B, K))
    others = [i for i in range(B.shape[1]) if i != j]
    return close(A, B[:, others], K[others, :])


def delayed(A, B, K, samples: int):
    """``(A, B, K)`` of a discrete plant with ``samples`` of delay on every input, exactly.

    The state gains ``m`` shift states per sample, ``[x; b_1; ...; b_n]``: ``x <- A x + B b_n``,
    ``b_1 <- u``, ``b_k <- b_(k-1)``; the gain ignores them (``[K, 0]``). ``samples = 0`` returns
    the plant unchanged.

    Examples
    --------
    One sample on ``x <- x + u``: ``L(z) = k / (z (z - 1))``.

    >>> Ad, Bd, Kd = delayed(np.eye(1), np.eye(1), np.eye(1), 1)
    >>> Ad.tolist(), Bd.ravel().tolist(), Kd.ravel().tolist()
    ([[1.0, 1.0], [0.0, 0.0]], [0.0, 1.0], [1.0, 0.0])
    """
    A, B, K = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (A, B, K))
    if samples == 0:
        return A, B, K
    n, m = B.shape
    N = n + m * samples
    Aa = np.zeros((N, N))
    Aa[:n, :n] = A
    Aa[:n, N - m:] = B
    for k in range(1, samples):  # b_(k+1) <- b_k
        Aa[n + k * m:n + (k + 1) * m, n + (k - 1) * m:n + k * m] = np.eye(m)
    Ba = np.zeros((N, m))
    Ba[n:n + m] = np.eye(m)
    return Aa, Ba, np.hstack([K, np.zeros((K.shape[0], m * samples))])


def with_lag_model(A, B, K, Kv, time_constant: float, sample_time: float | None = None):
    """``(A, B, K)`` of a state-feedback loop whose controller also propagates a model ``l`` of the
    inputs' lag from its own command and feeds it back: ``u_c = -K X - Kv l``.

    ``dl/dt = (u_c - l) / tau`` (continuous), or ``l <- a l + (1 - a) u_c``, ``a = exp(-Ts / tau)``
    (its exact ZOH, sampled). ``l`` is a controller state: its rows are in ``A`` (the command it
    follows is the controller's, before the loop's break point) and ``B`` has none, so a loop
    broken at an input sees the model as part of the controller (:mod:`quadctl.sim.builder` runs
    the same model).

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    K : (m, n) array_like
    Kv : (m, m) array_like
    time_constant : float
        s of the model.
    sample_time : float, optional
        s of a sampled loop (``A``, ``B`` the ZOH plant).

    Returns
    -------
    (n + m, n + m) ndarray, (n + m, m) ndarray, (m, n + m) ndarray
    """
    A, B, K, Kv = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (A, B, K, Kv))
    n, m = B.shape
    Aa = np.zeros((n + m, n + m))
    Aa[:n, :n] = A
    if sample_time is None:
        Aa[n:, :n] = -K / time_constant
        Aa[n:, n:] = -(np.eye(m) + Kv) / time_constant
    else:
        a = lag.model_pole(time_constant, sample_time)
        Aa[n:, :n] = -(1 - a) * K
        Aa[n:, n:] = a * np.eye(m) - (1 - a) * Kv
    return Aa, np.vstack([B, np.zeros((m, m))]), np.hstack([K, Kv])
