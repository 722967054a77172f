"""Sampled-data LQR: zero-order-hold discretization, MATLAB ``lqrd``/``dlqr``, and what a rate realizes.

:func:`c2d` (and :func:`c2d_batch`) hold a plant over one sample, :func:`dlqr` and :func:`lqrd` design
in MATLAB's conventions (``lqrd``'s weights by Van Loan's exponential, :func:`lqrd_weights`),
:func:`s_equivalent` reads a discrete eigenvalue on the continuous scale, and :func:`rate_warnings`
says what a continuous design loses at a rate. The formulas are in the docs, docs/internals.md
("Sampled designs").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.design.riccati import LqrResult, as_stack, real_array, require_valid_weights, solve
from quadctl.errors import ArgumentError, DesignError
from quadctl.linear import stability

scipy = lazy_import("scipy")  # loaded on first use (then scipy.linalg on access): quadctl._lazy

SAMPLES_PER_POLE = 10.0
"""A sampled loop realizes a closed-loop pole ``s`` when ``|s| <= 2 pi rate / SAMPLES_PER_POLE``:
the rule of thumb of sampling at least ten times the fastest closed-loop frequency (Franklin,
Powell & Workman, *Digital Control of Dynamic Systems*, ch. 11, recommend 10 to 40). Beyond it the
ZOH's half-sample delay costs more than ``360 / (2 * 10) = 18`` degrees of phase at that pole."""


VAN_LOAN_SPAN = 1.0
"""Largest ``||A||_1 Ts`` over which :func:`lqrd_weights` integrates the weights with one Van Loan
exponential; a longer sample is split into ``2^k`` spans and doubled back. Past a few units the
exponential's blocks, which grow and decay in opposite directions, cancel: at 0.1 Hz the roll
loop's sampled Q came out indefinite. At 200 Hz the report's loops are at 0.05: one exponential."""


def c2d(A, B, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretization (MATLAB ``c2d(..., 'zoh')``).

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    Ts : float
        Sample time, s.

    Returns
    -------
    Ad : (n, n) ndarray
    Bd : (n, m) ndarray

    Raises
    ------
    ArgumentError
        ``Ts`` is not a positive finite number of seconds, or ``A``, ``B`` are not real matrices of
        shapes (n, n) and (n, m).

    Examples
    --------
    A double integrator: ``Ad = [[1, Ts], [0, 1]]``, ``Bd = [Ts^2/2, Ts]``.

    >>> Ad, Bd = c2d([[0, 1], [0, 0]], [[0], [1]], 0.1)
    >>> np.round(Ad, 12).tolist(), np.round(Bd, 12).ravel().tolist()
    ([[1.0, 0.1], [0.0, 1.0]], [0.005, 0.1])
    """
    Ad, Bd = c2d_batch(_as2d(A, "A", "c2d")[None], _as2d(B, "B", "c2d")[None], _sample_times(Ts, 1, "c2d"))
    return Ad[0], Bd[0]


def c2d_batch(A, B, Ts) -> tuple[np.ndarray, np.ndarray]:
    """:func:`c2d` of stacked plants: one ``scipy.linalg.expm`` call over the stack.

    Parameters
    ----------
    A : (batch, n, n) array_like
    B : (batch, n, m) array_like
    Ts : float or (batch,) array_like
        Sample time(s), s.

    Returns
    -------
    Ad : (batch, n, n) ndarray
    Bd : (batch, n, m) ndarray

    Examples
    --------
    >>> Ad, Bd = c2d_batch([[[0.0]], [[-1.0]]], [[[1.0]], [[1.0]]], 0.5)
    >>> np.round(Ad.ravel(), 6).tolist(), np.round(Bd.ravel(), 6).tolist()
    ([1.0, 0.606531], [0.5, 0.393469])
    """
    A, B, *_ = as_stack(A, B, name="c2d_batch")
    batch, n, m = B.shape
    F = np.zeros((batch, n + m, n + m))
    F[:, :n, :n], F[:, :n, n:] = A, B
    with np.errstate(over="ignore", invalid="ignore"):  # sampled for hours, a plant overflows: inf, for the caller
        E = scipy.linalg.expm(F * _sample_times(Ts, batch, "c2d_batch")[:, None, None])
    return E[:, :n, :n], E[:, :n, n:]


def lqrd_weights(A, B, Q, R, Ts: float, N=None, *, name: str = "system"):
    """The ZOH plant and the discrete weights equivalent to the continuous cost (MATLAB ``lqrd``).

    ``[[Qd, Nd], [Nd', Rd]] = integral_0^Ts [[Phi, Gamma], [0, I]]' [[Q, N], [N', R]]
    [[Phi, Gamma], [0, I]] dtau`` with ``Phi = e^(A tau)``, ``Gamma = integral_0^tau e^(A s) ds B``,
    computed with Van Loan's block exponential (IEEE TAC 23, 1978).

    Returns
    -------
    Ad, Bd, Qd, Rd, Nd : ndarray
        Shapes (n, n), (n, m), (n, n), (m, m), (n, m).

    Raises
    ------
    ArgumentError
        Naming ``name``: ``Ts`` is not a positive finite number of seconds.
    DesignError
        Naming ``name``: the sampled plant or weights overflow (a sample time of hours).

    Examples
    --------
    The integrator ``x' = u``: ``Qd = q Ts``, ``Nd = q Ts^2 / 2``, ``Rd = r Ts + q Ts^3 / 3``.

    >>> _, _, Qd, Rd, Nd = lqrd_weights([[0.0]], [[1.0]], [[3.0]], [[2.0]], 0.5)
    >>> [round(float(v), 12) for v in (Qd[0, 0], Nd[0, 0], Rd[0, 0])]
    [1.5, 0.375, 1.125]
    """
    A, B, Q, R = (_as2d(M, label, name) for M, label in ((A, "A"), (B, "B"), (Q, "Q"), (R, "R")))
    Ts = float(_sample_times(Ts, 1, name)[0])
    out = lqrd_weights_batch(A[None], B[None], Q[None], R[None], Ts, None if N is None else _as2d(N, "N", name)[None])
    if not all(np.all(np.isfinite(M)) for M in out):
        raise overflow(name, Ts)
    return tuple(M[0] for M in out)


def overflow(name: str, Ts: float) -> DesignError:
    """The refusal of a plant whose sampled problem overflows (a sample time of hours)."""
    return DesignError(f"{name}: sampled every {Ts:.3g} s (controller.rate {1 / Ts:.3g} Hz) its response "
                       "overflows double precision; use a faster controller.rate")


def lqrd_weights_batch(A, B, Q, R, Ts, N=None):
    """:func:`lqrd_weights` of stacked problems: one ``scipy.linalg.expm`` call over the stack (over
    a fraction of a long sample, doubled back: :data:`VAN_LOAN_SPAN`).

    Parameters
    ----------
    A : (batch, n, n) array_like
    B : (batch, n, m) array_like
    Q : (batch, n, n) array_like
    R : (batch, m, m) array_like
    Ts : float or (batch,) array_like
        Sample time(s), s.
    N : (batch, n, m) array_like, optional

    Returns
    -------
    Ad, Bd, Qd, Rd, Nd : ndarray
        Shapes (batch, n, n), (batch, n, m), (batch, n, n), (batch, m, m), (batch, n, m).

    Raises
    ------
    ArgumentError
        A matrix is not numeric, the shapes do not stack, or a sample time is not positive and finite.
    """
    A, B, Q, R, N = as_stack(A, B, Q, R, N, name="lqrd_weights_batch")
    batch, n, m = B.shape
    k = n + m
    Ts = _sample_times(Ts, batch, "lqrd_weights_batch")
    # the exponential over a span where ||A|| h <= VAN_LOAN_SPAN, then doubled up to Ts
    with np.errstate(divide="ignore"):
        span = np.abs(A).sum(axis=1).max(axis=1, initial=0.0) * Ts / VAN_LOAN_SPAN
        halvings = np.where(span > 1.0, np.ceil(np.log2(span)), 0.0).astype(int)
    F = np.zeros((batch, k, k))
    F[:, :n, :n], F[:, :n, n:] = A, B
    W = _joint(Q, R, N)
    vl = np.zeros((batch, 2 * k, 2 * k))
    vl[:, :k, :k], vl[:, :k, k:], vl[:, k:, k:] = -F.transpose(0, 2, 1), W, F
    with np.errstate(over="ignore", invalid="ignore"):  # sampled for hours, a plant overflows: inf, for the caller
        E = scipy.linalg.expm(vl * (Ts / 2.0 ** halvings)[:, None, None])
        phi = E[:, k:, k:]
        Wd = phi.transpose(0, 2, 1) @ E[:, :k, k:]
        Wd = _doubled(phi.copy(), (Wd + Wd.transpose(0, 2, 1)) / 2, halvings)
        long = halvings > 0  # their ZOH plant from one exponential over the whole sample (squares compound errors)
        if long.any():
            phi[long] = scipy.linalg.expm(F[long] * Ts[long][:, None, None])
    return phi[:, :n, :n], phi[:, :n, n:], Wd[:, :n, :n], Wd[:, n:, n:], Wd[:, :n, n:]


def _doubled(phi, Wd, halvings):
    """:func:`lqrd_weights_batch`'s integrals over ``h`` doubled ``halvings`` times (per problem)."""
    for step in range(int(halvings.max(initial=0))):
        # over 2h: Wd(2h) = Wd(h) + phi(h)' Wd(h) phi(h), phi(2h) = phi(h)^2 (a sum of congruences:
        # no cancellation, where the one exponential's blocks over a long span cancel to garbage)
        more = halvings > step
        p = phi[more]
        Wd[more] = Wd[more] + p.transpose(0, 2, 1) @ Wd[more] @ p
        Wd[more] = (Wd[more] + Wd[more].transpose(0, 2, 1)) / 2
        phi[more] = p @ p
    return Wd


class LqrdWeightMap:
    """:func:`lqrd_weights` of one plant for any weights: the ZOH ``Ad``, ``Bd`` and the linear map
    from ``W = [[Q, N], [N', R]]`` to its sampled ``Wd = integral of phi(t)' W phi(t) dt`` over one
    sample, built from one Van Loan exponential per entry of ``W`` (``Wd`` is linear in ``W``).

    A sweep that varies only the weights of a plant samples them with a matrix product per case
    instead of an exponential of twice the size (the same numbers to round-off).
    """

    def __init__(self, A, B, Ts: float):
        A = real_array(A, "A", name="LqrdWeightMap", ndim=2)
        A = real_array(A, "A", name="LqrdWeightMap", shape=(A.shape[0], A.shape[0]))
        B = real_array(B, "B", name="LqrdWeightMap", ndim=2, shape=(A.shape[0], None))
        n, m = B.shape
        k = n + m
        basis = np.eye(k * k).reshape(k * k, k, k)  # W = e_p e_q', p, q = 0 .. k - 1
        stack = (np.broadcast_to(A, (k * k, n, n)), np.broadcast_to(B, (k * k, n, m)))
        Ad, Bd, Qd, Rd, Nd = lqrd_weights_batch(*stack, basis[:, :n, :n], basis[:, n:, n:], Ts, basis[:, :n, n:])
        Wd = _joint(Qd, Rd, Nd)
        self.n, self.m = n, m
        self.Ad, self.Bd = Ad[0], Bd[0]
        self.map = Wd.reshape(k * k, k * k).T
        """(k^2, k^2): ``vec(Wd) = map @ vec(W)`` for a symmetric ``W = [[Q, N], [N', R]]``
        (row-major ``vec``, ``k = n + m``; built from the blocks of each basis entry, so not the
        map of a general ``W``)."""

    def weights(self, Q, R, N=None):
        """``(Qd, Rd, Nd)`` of stacked weights: Q (batch, n, n), R (batch, m, m), N (batch, n, m)."""
        n, m = self.n, self.m
        Q = real_array(Q, "Q", name="LqrdWeightMap.weights", shape=(None, n, n))
        R = real_array(R, "R", name="LqrdWeightMap.weights", shape=(len(Q), m, m))
        batch = len(Q)
        N = np.zeros((batch, n, m)) if N is None else real_array(N, "N", name="LqrdWeightMap.weights",
                                                                  shape=(batch, n, m))
        W = _joint(Q, R, N)
        k = W.shape[1]
        Wd = (W.reshape(batch, k * k) @ self.map.T).reshape(batch, k, k)
        Wd = (Wd + Wd.transpose(0, 2, 1)) / 2
        return Wd[:, :n, :n], Wd[:, n:, n:], Wd[:, :n, n:]


def dlqr(A, B, Q, R, N=None, *, name: str = "system", state_names=None) -> LqrResult:
    """Discrete-time LQR (MATLAB ``dlqr``), solved by :func:`quadctl.design.riccati.solve`.

    Weights validated; quadctl's own residual-checked solver first (:func:`quadctl.design.riccati.dare_batch`:
    structure-preserving doubling and Newton-Hewer steps), SciPy's ``solve_discrete_are`` where it
    has no answer within ``RICCATI_RTOL`` and a stable loop.

    Parameters
    ----------
    A : (n, n) array_like
        Discrete state matrix.
    B : (n, m) array_like
    Q : (n, n) array_like
        Symmetric positive semidefinite.
    R : (m, m) array_like
        Symmetric positive definite.
    N : (n, m) array_like, optional
        Cross weight (``2 x' N u`` in the cost); ``[[Q, N], [N', R]]`` positive semidefinite.
    name : str
        Names the system in errors.
    state_names : sequence of str, optional
        Names the states of a refused mode in errors.

    Returns
    -------
    LqrResult
        ``E`` holds the eigenvalues ``z`` of ``A - B K`` (stable: :func:`quadctl.linear.stability.is_stable`).

    Raises
    ------
    DesignError
        Invalid weights, a mode that is not stable and that no input reaches, a mode on the unit
        circle invisible to ``Q``, or an equation too ill-conditioned to certify (named).
    ArgumentError
        A matrix that is not real numbers, or of a shape that does not fit, as for
        :func:`quadctl.design.lqr` (a ``ValueError``).

    Examples
    --------
    The sampled integrator ``x[k+1] = x[k] + Ts u[k]`` with ``Q = q``, ``R = r`` has
    ``P = (q Ts^2 + sqrt(q^2 Ts^4 + 4 q r Ts^2)) / (2 Ts^2)`` and ``K = Ts P / (r + Ts^2 P)``;
    with ``q = r = Ts = 1``, ``P`` is the golden ratio:

    >>> K, P, E = dlqr([[1.0]], [[1.0]], [[1.0]], [[1.0]])
    >>> round(float(P[0, 0]), 10), round(float(K[0, 0]), 10)
    (1.6180339887, 0.6180339887)
    """
    return solve(A, B, Q, R, N, discrete=True, name=name, state_names=state_names)


def lqrd(A, B, Q, R, Ts: float, N=None, *, name: str = "system", state_names=None) -> LqrResult:
    """Discrete LQR for a continuous plant sampled at ``Ts`` (MATLAB ``lqrd``).

    Parameters
    ----------
    A, B : array_like
        The continuous plant, (n, n) and (n, m).
    Q, R, N : array_like
        Continuous weights, as for ``lqr``.
    Ts : float
        s. It comes before ``N``: MATLAB's ``lqrd(A, B, Q, R, N, Ts)`` is ``lqrd(A, B, Q, R, Ts, N)`` here.
    name : str
        Names the system in errors.
    state_names : sequence of str, optional

    Returns
    -------
    LqrResult
        Of ``dlqr`` on :func:`lqrd_weights`.

    Raises
    ------
    DesignError
        The continuous weights are invalid (checked before they are integrated), or ``dlqr`` fails.
    ArgumentError
        ``Ts`` is not a positive finite number of seconds, or a matrix is not real numbers or of a shape
        that does not fit, as for :func:`quadctl.design.lqr`.

    Examples
    --------
    The scalar integrator ``x' = u`` at 10 Hz: the sampled gain is a little below the continuous
    ``sqrt(Q / R) = 1``, and the discrete closed-loop pole ``z`` a little off ``exp(-Ts)``.

    >>> import quadctl as qc
    >>> K, S, E = qc.lqrd([[0.0]], [[1.0]], [[1.0]], [[1.0]], 0.1)
    >>> round(float(K[0, 0]), 4), round(float(E[0].real), 4)
    (0.952, 0.9048)
    """
    if np.ndim(Ts) == 2 and np.ndim(N) == 0:  # MATLAB's argument order, lqrd(A, B, Q, R, N, Ts)
        raise ArgumentError(f"{name}: Ts has shape {np.shape(Ts)}, a matrix, and N is {N!r}: lqrd takes (A, B, Q, R, "
                            "Ts, N), the sample time before the cross weight (MATLAB's lqrd(A, B, Q, R, N, Ts) "
                            "puts N first)")
    require_valid_weights(A, B, Q, R, N, name=name)
    Ad, Bd, Qd, Rd, Nd = lqrd_weights(A, B, Q, R, Ts, N, name=name)
    return dlqr(Ad, Bd, Qd, Rd, Nd, name=name, state_names=state_names)


def s_equivalent(z, Ts: float) -> np.ndarray:
    """``ln(z) / Ts``: the continuous eigenvalue a discrete one corresponds to (rad/s).

    ``z = 0`` (a deadbeat mode) maps to ``-inf``.
    """
    z = np.asarray(z, dtype=complex)
    with np.errstate(divide="ignore"):
        return np.log(z) / Ts


def realizable_frequency(rate: float) -> float:
    """Fastest closed-loop pole a ``rate`` Hz loop realizes, ``2 pi rate / SAMPLES_PER_POLE`` (rad/s)."""
    return 2 * math.pi * rate / SAMPLES_PER_POLE


@dataclass(frozen=True)
class RateWarning:
    """A continuous loop whose closed-loop poles are too fast for the controller rate.

    Attributes
    ----------
    loop : str
        Subsystem name, or ``"coupled"`` for the assembled 12-state loop.
    pole : complex
        The fastest continuous closed-loop pole (rad/s).
    limit : float
        :func:`realizable_frequency` of the rate (rad/s).
    factor : float
        ``|pole| / limit``: how many times too fast.
    sampled_radius : float
        Spectral radius of the loop as the flight computer runs it (the continuous gain on the
        ZOH plant, ``Ad - Bd K``); ``>= 1`` means the sampled loop is unstable.

    Its sentence: :func:`quadctl.present.stages.rate_warning`.
    """

    loop: str
    pole: complex
    limit: float
    factor: float
    sampled_radius: float

    @property
    def sampled_stable(self) -> bool:
        return stability.is_stable(self.sampled_radius, discrete=True)


def spectral_radius(A_cl) -> float:
    """``max |eig(A_cl)|`` of a discrete closed loop (``>= 1``: not stable; ``inf`` when sampling it
    overflowed, as a fast loop sampled every few hours does)."""
    A_cl = _as2d(A_cl)
    if not np.all(np.isfinite(A_cl)):
        return math.inf
    return float(np.abs(np.linalg.eigvals(A_cl)).max())


def rate_warnings(loops, rate: float) -> list[RateWarning]:
    """Check continuous loops against a controller rate.

    Parameters
    ----------
    loops : iterable of (name, eigenvalues, sampled_closed_loop)
        Each loop's continuous closed-loop eigenvalues (rad/s), and the discrete closed-loop
        matrix of the same gains run at ``rate`` (ZOH plant, e.g. ``Ad - Bd K``).
    rate : float
        Hz.

    Returns
    -------
    list of RateWarning
        One per loop whose fastest pole exceeds :func:`realizable_frequency`, or whose sampled
        loop is unstable: subsystems fastest first, then the coupled loop.
    """
    limit = realizable_frequency(rate)
    out = []
    for name, eig, sampled in loops:
        eig = np.asarray(eig, dtype=complex)
        finite = eig[np.isfinite(eig)]
        if finite.size == 0:
            continue
        pole = complex(finite[int(np.argmax(np.abs(finite)))])
        radius = spectral_radius(sampled)
        if abs(pole) > limit or not stability.is_stable(radius, discrete=True):
            out.append(RateWarning(loop=name, pole=pole, limit=limit, factor=abs(pole) / limit,
                                   sampled_radius=radius))
    return sorted(out, key=lambda w: (w.loop == "coupled", -w.factor))


def _as2d(m, label: str = "matrix", name: str = "system") -> np.ndarray:
    return real_array(m, label, name=name, ndim=2)


def _joint(Q, R, N) -> np.ndarray:
    """``[[Q, N], [N', R]]`` of stacked weights: (batch, n + m, n + m)."""
    return np.concatenate([np.concatenate([Q, N], axis=2), np.concatenate([N.transpose(0, 2, 1), R], axis=2)], axis=1)


def _sample_times(Ts, batch: int, name: str) -> np.ndarray:
    """``Ts`` as (batch,) positive finite seconds, or an ArgumentError naming ``name`` and the bad one."""
    try:
        given = np.asarray(Ts)
        if given.dtype.kind not in "iuf":  # text ('0.1'), a bool, None: float() would take them
            raise TypeError
        times = np.broadcast_to(given.astype(float), (batch,))
    except (TypeError, ValueError):
        each = f", one or one per problem ({batch})" if batch > 1 else ""
        raise ArgumentError(f"{name}: Ts = {Ts!r}: the sample time must be a positive finite number of "
                            f"seconds{each}") from None
    bad = ~(np.isfinite(times) & (times > 0))
    if bad.any():
        raise ArgumentError(f"{name}: Ts = {float(times[bad][0])!r}: the sample time must be a positive finite "
                            "number of seconds")
    return times
