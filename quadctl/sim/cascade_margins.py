"""Margins of a PID cascade's loops, broken at each plant input with the whole cascade closed around it.

The multi-rate cascade (:mod:`quadctl.sim.pid`), linearized about hover from the law the simulation
runs, is lifted to its frame (:func:`lifted`, :class:`Lifted`), where it is time-invariant. Every margin
is exact: stability, poles and the gain margins from the lifted loop's poles (:func:`exact_gain_margins`);
the phase and disk margins from its characteristic loci, the eigenvalues of the frame's transfer matrix
(:func:`loci_margins`: a constant gain on the input is that gain on every sample, so it commutes with the
lifted loop); the delay margin the least extra delay of the held input that makes the lifted loop
unstable (:func:`exact_delay_margin`). The method and its references are in the docs, docs/internals.md
("Margins of a PID cascade").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.design.margins import GRID_SPAN, POINTS_PER_DECADE, LoopMargins, disk_gain_range_db, gain_db, no_margin
from quadctl.layout import INPUT_NAMES
from quadctl.linear.stability import is_stable
from quadctl.signals import signals_held
from quadctl.sim import pid
from quadctl.sim.builder import build

ca = lazy_import("casadi")
scipy = lazy_import("scipy")

GAIN_SCAN = np.logspace(-3, 3, 241)
"""Loop-gain factors scanned outward from 1 for the exact gain margins (0.001 to 1000, 40 per decade: a band
of instability narrower than 6 % in gain between two stable ones would be missed), then bisected."""
FREQUENCY_AGREEMENT_DB = 1e-3
"""dB: a gain margin's frequency is that of the loci's crossing of the real axis when the gain read there is
within this of :func:`exact_gain_margins` (whose bisection stops where a pole is within the stability test's
1e-9 of the unit circle: for a slow pole near ``z = 1``, ~1e-5 dB from the crossing); otherwise none is given."""
LOCI_POINTS_PER_DECADE = 20
"""Frame frequencies ``theta`` per decade at which the characteristic loci are computed before each crossing
is refined by root finding and each least value by minimization: two crossings closer than a step apart (a
locus grazing ``|lam| = 1`` or the real axis) could be missed."""
LOCI_INFINITE = 1e10
"""An eigenvalue of ``L`` larger than this (a destabilizing gain below -200 dB) is taken as this, real."""
LOCI_ZERO = 1e-10
"""An eigenvalue of ``L`` smaller than this (a destabilizing gain above +200 dB; a loop of low rank over the
frame has such, their phase rounding noise) is taken as 0."""
LOCI_EXPLICIT = 1e4
"""Largest ``|L|`` entry at which the loci are the eigenvalues of ``L`` itself (those of order one then good
to ~1e-12); beyond it, of the pencil (:meth:`LiftedLoop.loci`)."""
DELAY_SCAN = (1 / 16) * 1.1 ** np.arange(90)
"""Delays in base samples scanned for the exact delay margin (1/16 to ~300 samples, 10 % apart), then refined
to the edge: a band of instability narrower than 10 % in delay between two stable ones would be missed."""


@dataclass(frozen=True)
class Lifted:
    """The cascade's loop about hover, linearized sample by sample (``N`` samples of one frame).

    Attributes
    ----------
    plant : (n, n) ndarray, (n, 4) ndarray
        The plant's ZOH map at the base rate on its states ``[x; f]`` (``f``: rotor thrusts when they lag).
    law_state : list of (nx, nx) ndarray
        ``dX_sampled/dX`` of the law at each phase (the plant rows the identity).
    law_command : list of (4, nx) ndarray
        ``du/dX`` of the law's command at each phase.
    sample_time : float
        s: the base period ``Ts``.
    states : (nx,) ndarray of int, optional
        Which of the simulated loop's states these are (:func:`read_states`); None: all.
    equilibrium : ndarray, optional
        The simulated loop's state at hover at phase 0 (every state), where the law was linearized.
    plant_rates : (n, n) ndarray, (n, 4) ndarray, optional
        The continuous model ``(A, B)`` whose zero-order hold at ``Ts`` is ``plant`` (for a delay of the held
        input by a fraction of a sample, :meth:`delayed_frame_map`); None: no delay margin.
    """

    plant: tuple[np.ndarray, np.ndarray]
    law_state: list
    law_command: list
    sample_time: float
    states: np.ndarray | None = None
    equilibrium: np.ndarray | None = None
    plant_rates: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def n_plant(self) -> int:
        return self.plant[0].shape[0]

    @property
    def frame(self) -> int:
        return len(self.law_state)

    def sample_map(self, p: int, j: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(M, G)``: ``X+ = M X + G v`` at phase ``p``, input ``j`` given ``v`` instead of the law's command
        (``j`` None: every loop closed, ``G`` empty)."""
        Ad, Bd = self.plant
        npl, nx = self.n_plant, self.law_state[p].shape[0]
        hold = np.eye(nx)
        hold[:npl, :npl] = Ad
        Du = self.law_command[p].copy()
        G = np.zeros((nx, 1))
        if j is not None:
            Du[j] = 0.0
            G[:npl, 0] = Bd[:, j]
        M = hold @ self.law_state[p]
        M[:npl] += Bd @ Du
        return M, G

    @property
    def frame_map(self) -> np.ndarray:
        """The closed loop's map over one frame (``nx``, ``nx``): its eigenvalues are the loop's poles in ``z``
        of the frame period ``N Ts``."""
        Phi = np.eye(self.law_state[0].shape[0])
        for p in range(self.frame):
            Phi = self.sample_map(p)[0] @ Phi
        return Phi

    def delayed_frame_map(self, j: int, delay: float) -> np.ndarray:
        """The closed loop's map over one frame with input ``j`` held ``delay`` s late (``d + f`` samples, ``f``
        in ``[0, 1)``): the plant is given the command of ``d + 1`` samples ago for the first ``f Ts`` of each
        sample and that of ``d`` samples ago for the rest (the zero-order hold shifted, exact at the base rate).
        State ``[X; u_j(k-1) .. u_j(k-d-1)]``."""
        if self.plant_rates is None:
            raise ValueError("a delay of the held input needs the continuous plant (Lifted.plant_rates)")
        Ts, npl, nx = self.sample_time, self.n_plant, self.law_state[0].shape[0]
        d = int(math.floor(delay / Ts + 1e-12))
        f = min(max(delay / Ts - d, 0.0), 1.0)
        late, early = _held_input(self.plant_rates, j, (1.0 - f) * Ts, f * Ts)
        n = nx + d + 1
        Phi = np.eye(n)
        for p in range(self.frame):
            M, _ = self.sample_map(p, j)
            S = np.zeros((n, n))
            S[:nx, :nx] = M
            row = self.law_command[p][j]
            now = np.zeros(n)  # u_j(k - d): the command computed now without delay, else the buffer's d-th
            if d == 0:
                now[:nx] = row
            else:
                now[nx + d - 1] = 1.0
            S[:npl] += np.outer(late, now)
            S[:npl, nx + d] += early  # u_j(k - d - 1)
            S[nx, :nx] = row  # the buffer shifts: u_j(k) in, the oldest out
            S[nx + 1:, nx:n - 1] = np.eye(d)
            Phi = S @ Phi
        return Phi

    def broken(self, j: int) -> LiftedLoop:
        """The loop broken at input ``j`` (:data:`quadctl.layout.INPUT_NAMES` order), lifted to the frame."""
        N, nx = self.frame, self.law_state[0].shape[0]
        Phi, Gam = np.eye(nx), np.zeros((nx, N))
        C, D = np.zeros((N, nx)), np.zeros((N, N))
        for p in range(N):
            M, G = self.sample_map(p, j)
            row = self.law_command[p][j]
            C[p] = row @ Phi
            D[p] = row @ Gam
            Phi, Gam = M @ Phi, M @ Gam
            Gam[:, p] += G[:, 0]
        return LiftedLoop(Phi=Phi, Gamma=Gam, C=C, D=D, sample_time=self.sample_time)


@dataclass(frozen=True)
class LiftedLoop:
    """A loop broken at one input, lifted to the frame: ``y = (C (zI - Phi)^-1 Gamma + D) v``; closed, ``v = y``.

    Called at ``w`` (rad/s) it gives the fundamental harmonic ``L0(w) = phi^H L(e^(j w N Ts)) phi / N``,
    ``phi = [e^(j w p Ts)]_p`` (the response at ``w`` to a sinusoid at ``w``: the curve of the Bode and
    Nyquist plots, as :class:`quadctl.design.margins.BrokenLoop` gives its ``L``); the margins are from
    :meth:`loci` and :meth:`is_stable`, exact.
    """

    Phi: np.ndarray
    Gamma: np.ndarray
    C: np.ndarray
    D: np.ndarray
    sample_time: float

    @property
    def frame(self) -> int:
        return self.D.shape[0]

    def lifted_response(self, w) -> np.ndarray:
        """``L(z)`` (len(w), N, N), ``z = e^(j w N Ts)``, with the sign of
        :class:`~quadctl.design.margins.BrokenLoop` (closed loop: ``I + L`` singular)."""
        z = np.exp(1j * np.atleast_1d(np.asarray(w, dtype=float)) * self.frame * self.sample_time)
        n = self.Phi.shape[0]
        M = z[:, None, None] * np.eye(n) - self.Phi[None]
        return -(self.C[None] @ np.linalg.solve(M, np.broadcast_to(self.Gamma, (len(z),) + self.Gamma.shape))
                 + self.D[None])

    def frame_response(self, theta) -> np.ndarray:
        """``L(e^(j theta))`` (len(theta), N, N) at frame frequencies ``theta`` (rad per frame)."""
        return self.lifted_response(np.asarray(theta, dtype=float) / (self.frame * self.sample_time))

    def loci(self, theta, vectors: bool = False):
        """The eigenvalues ``lam`` (..., N) of ``L(e^(j theta))`` at frame frequencies ``theta`` (and, with
        ``vectors`` and a scalar ``theta``, their eigenvectors (N, N): the frame's input samples).

        Where ``L`` is large (near a pole of the loop on the unit circle: an integrator, ``theta`` -> 0) its
        eigenvalues of order one are lost to rounding when ``L`` is formed; there they are the finite
        eigenvalues of the pencil ``[[zI - Phi, -Gamma], [C, D + lam I]]``, on which QZ is backward stable. An
        eigenvalue below :data:`LOCI_ZERO` stands as 0, one beyond :data:`LOCI_INFINITE` as that value."""
        theta = np.atleast_1d(np.asarray(theta, dtype=float))
        N = self.frame
        vals = np.zeros((len(theta), N), dtype=complex)
        vecs = np.zeros((len(theta), N, N), dtype=complex) if vectors else None
        explicit = theta > 0  # at theta = 0 (z = 1) an integrator makes L infinite: the pencil only
        if explicit.any():
            L = self.frame_response(theta[explicit])
            small = np.abs(L).max(axis=(1, 2)) <= LOCI_EXPLICIT
            explicit[explicit] = small
            if vectors:
                vals[explicit], vecs[explicit] = np.linalg.eig(L[small])
            else:
                vals[explicit] = np.linalg.eigvals(L[small])
        for k in np.nonzero(~explicit)[0]:
            pv, pw = self._pencil(theta[k])
            vals[k] = pv
            if vectors:
                vecs[k] = pw
        vals = np.where(np.abs(vals) < LOCI_ZERO, 0.0, np.where(np.abs(vals) > LOCI_INFINITE, LOCI_INFINITE, vals))
        return (vals[0], vecs[0]) if vectors else vals

    def _pencil(self, theta: float):
        n, N = self.Phi.shape[0], self.frame
        M = np.zeros((n + N, n + N), dtype=complex)
        M[:n, :n] = np.exp(1j * theta) * np.eye(n) - self.Phi
        M[:n, n:], M[n:, :n], M[n:, n:] = -self.Gamma, self.C, self.D
        E = np.zeros_like(M)
        E[n:, n:] = -np.eye(N)
        vals, vecs = scipy.linalg.eig(M, E, right=True, check_finite=False)
        with np.errstate(invalid="ignore"):
            order = np.argsort(np.where(np.isfinite(vals), np.abs(vals), np.inf))[:N]
        vals = np.where(np.isfinite(vals[order]), vals[order], LOCI_INFINITE)
        return vals, vecs[n:, order]

    def __call__(self, w) -> np.ndarray:
        w = np.atleast_1d(np.asarray(w, dtype=float))
        phi = np.exp(1j * w[:, None] * np.arange(self.frame)[None, :] * self.sample_time)
        return np.einsum("wp,wpq,wq->w", phi.conj(), self.lifted_response(w), phi) / self.frame

    def closed_loop_eigenvalues(self, gain: float = 1.0) -> np.ndarray:
        """Eigenvalues (``z`` of the frame) of the loop closed through ``v = gain y``."""
        N = self.frame
        feed = gain * np.linalg.solve(np.eye(N) - gain * self.D, self.C)
        return np.linalg.eigvals(self.Phi + self.Gamma @ feed)

    def is_stable(self, gain: float = 1.0) -> bool:
        return bool(np.all(is_stable(self.closed_loop_eigenvalues(gain), discrete=True)))

    def grid(self, points_per_decade: int) -> np.ndarray:
        """rad/s from the slowest pole's frequency / 100 (at most Nyquist / 1000) to Nyquist ``pi / Ts``."""

        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.log(self.closed_loop_eigenvalues().astype(complex)) / (self.frame * self.sample_time)
        mags = np.abs(s[np.isfinite(s)])
        mags = mags[mags > 1e-9]
        hi = math.pi / self.sample_time
        lo = min((mags.min() if mags.size else 1.0) / GRID_SPAN, hi / 1e3)
        w = np.logspace(math.log10(lo), math.log10(hi), int(max(math.log10(hi / lo), 1.0) * points_per_decade) + 1)
        w[-1] = hi
        return w

    def frame_grid(self, points_per_decade: int) -> np.ndarray:
        """Frame frequencies ``theta`` (rad per frame) of :meth:`grid` up to ``pi``, with both ends, ``0`` and
        ``pi`` (``z = 1`` and ``-1``: with an even frame, the base rate's Nyquist frequency is at ``z = 1``)."""
        theta = self.grid(points_per_decade) * self.frame * self.sample_time
        return np.concatenate([[0.0], theta[theta < math.pi * (1 - 1e-9)], [math.pi]])


def exact_gain_margins(loop: LiftedLoop) -> tuple[float, float]:
    """(lower, upper) dB: the constant gains nearest 1, below and above, at which the lifted loop loses
    stability (``-inf`` / ``+inf``: none within :data:`GAIN_SCAN`). The loop is stable at gain 1."""

    def edge(a, b):  # a stable, b not
        for _ in range(45):  # the bracket's ratio to its 2^-45th power: ~1e-13 dB for a decade
            m = math.sqrt(a * b)
            a, b = (m, b) if loop.is_stable(m) else (a, m)
        return math.sqrt(a * b)

    upper = lower = None
    above = GAIN_SCAN[GAIN_SCAN > 1]
    prev = 1.0
    for g in above:
        if not loop.is_stable(g):
            upper = edge(prev, g)
            break
        prev = g
    prev = 1.0
    for g in GAIN_SCAN[GAIN_SCAN < 1][::-1]:
        if not loop.is_stable(g):
            lower = edge(prev, g)
            break
        prev = g
    return (gain_db(lower) if lower else -math.inf, gain_db(upper) if upper else math.inf)


@dataclass(frozen=True)
class LociMargins:
    """Margins from the characteristic loci of a lifted loop (:func:`loci_margins`); frequencies in rad/s of
    the base rate (:func:`base_frequency`), None where there is no such point."""

    gain_margin_db: tuple[float, float]
    phase_crossover_freqs: tuple[float | None, float | None]
    phase_margin_deg: float
    gain_crossover_freq: float | None
    disk_alpha: float
    disk_freq: float | None
    min_return_difference: float


def loci_margins(loop: LiftedLoop, points_per_decade: int = LOCI_POINTS_PER_DECADE) -> LociMargins:
    """Gain, phase and disk margins of a lifted loop from its characteristic loci (module docstring).

    A constant gain ``g`` (complex: gain and phase) on the broken input is ``g I`` on the frame's samples and
    commutes with the loop: the loop closed through it has a pole on the unit circle exactly where
    ``-1/g`` is an eigenvalue ``lam`` of ``L(e^(j theta))`` (:meth:`LiftedLoop.lifted_response`'s sign), so the
    destabilizing gains on the circle are ``g = -1/lam``, ``theta`` in ``[0, pi]`` (the loci over
    ``(pi, 2 pi)`` are the conjugates). Crossings of ``|lam| = 1`` and of the real axis are found on a log
    grid of ``theta`` and refined by root finding; the disk margin's minimum by bounded minimization.

    Parameters
    ----------
    loop : LiftedLoop
        A loop stable at gain 1.
    points_per_decade : int
        Grid density in ``theta`` before refinement.

    Returns
    -------
    LociMargins
        Gain margins nearest 1 (dB), the smallest ``|arg g|`` with ``|g| = 1`` (deg; ``inf``: none), the
        smallest balanced disk ``alpha`` (:func:`quadctl.design.margins.disk_gain_range_db`) and
        ``min |1 + lam|``.
    """

    theta = loop.frame_grid(points_per_decade)
    lam = loop.loci(theta)
    if not np.all(np.isfinite(lam[0])):  # z = 1 a pole the pencil cannot separate (a singular pencil): left out
        theta, lam = theta[1:], lam[1:]

    def eig(t):
        return loop.loci(t, vectors=True)

    def mag(lams):  # changes sign where one |lam| crosses 1: symmetric in the eigenvalues, so no tracking
        with np.errstate(divide="ignore"):
            return np.prod(np.where(lams == 0, -1.0, np.log(np.abs(lams))), axis=-1)

    def imag(lams):  # changes sign where one lam crosses the real axis (those taken as 0 or infinite aside)
        return np.prod(np.where((lams == 0) | (np.abs(lams) >= LOCI_INFINITE), 1.0, lams.imag), axis=-1)

    def refine(fn, k):  # None: the sign change was rounding (the ends, computed alone, agree)
        a, b = theta[k], theta[k + 1]
        f = lambda t: float(fn(loop.loci(t)[0]))  # noqa: E731
        if (f(a) > 0) == (f(b) > 0):
            return None
        return float(scipy.optimize.brentq(f, a, b, xtol=1e-14, rtol=1e-14, maxiter=200))

    pm, w_pm = math.inf, None
    for t in (t for t in (refine(mag, k) for k in _sign_changes(mag(lam))) if t is not None):
        vals, vecs = eig(t)
        with np.errstate(divide="ignore"):
            i = int(np.argmin(np.abs(np.log(np.abs(vals)))))
        phase = math.degrees(abs(float(np.angle(-1.0 / vals[i]))))
        if phase < pm:
            pm, w_pm = phase, base_frequency(loop, t, vecs[:, i])
    gains = []  # (critical gain, rad/s): -1/λ real and positive, λ an eigenvalue of L (its loci)
    for t in (t for t in (refine(imag, k) for k in _sign_changes(imag(lam))) if t is not None):
        L_eig, vecs = eig(t)
        with np.errstate(divide="ignore", invalid="ignore"):
            i = int(np.nanargmin(np.abs(L_eig.imag) / np.abs(L_eig)))
        if L_eig[i].real < 0 and abs(L_eig[i].imag) <= 1e-9 * abs(L_eig[i]):
            gains.append((-1.0 / L_eig[i].real, base_frequency(loop, t, vecs[:, i])))
    for end in {theta[0], theta[-1]} & {0.0, math.pi}:  # z = 1, -1: L is real, its real eigenvalues real gains
        L_eig, vecs = eig(end)
        for i in np.nonzero((np.abs(L_eig.imag) <= 1e-12 * np.abs(L_eig)) & (L_eig.real < 0)
                            & (np.abs(L_eig) < LOCI_INFINITE))[0]:
            gains.append((-1.0 / L_eig[i].real, base_frequency(loop, end, vecs[:, i])))
    above = min((g for g in gains if g[0] > 1), default=None)
    below = max((g for g in gains if g[0] < 1), default=None)

    def disk(lams):  # the balanced disk through -1/lam: alpha = 2 |1 + lam| / |1 - lam|
        with np.errstate(divide="ignore"):
            return np.min(2 * np.abs(1 + lams) / np.abs(1 - lams), axis=-1)

    alpha, t_disk = _least(disk, lam, theta, loop.loci)
    rd, _ = _least(lambda lams: np.min(np.abs(1 + lams), axis=-1), lam, theta, loop.loci)
    vals, vecs = eig(t_disk)
    i = int(np.argmin(disk(vals[:, None])))
    return LociMargins(
        gain_margin_db=(gain_db(below[0]) if below else -math.inf, gain_db(above[0]) if above else math.inf),
        phase_crossover_freqs=(below[1] if below else None, above[1] if above else None),
        phase_margin_deg=pm, gain_crossover_freq=w_pm, disk_alpha=alpha,
        disk_freq=base_frequency(loop, t_disk, vecs[:, i]), min_return_difference=rd)


def _sign_changes(v) -> np.ndarray:
    pos = v > 0
    return np.nonzero(pos[:-1] != pos[1:])[0]


def _least(fn, lam, theta, loci, near: float = 1.1, candidates: int = 3) -> tuple[float, float]:
    """``(min, theta)`` of ``fn`` of the loci: the grid's least few local minima within ``near`` times its least,
    each refined by bounded minimization between its neighbours (two nearly equal minima both)."""
    vals = fn(lam)
    n = len(theta)
    local = [k for k in range(n) if vals[k] <= vals[max(k - 1, 0)] and vals[k] <= vals[min(k + 1, n - 1)]
             and vals[k] <= near * vals.min()]
    best = (float("inf"), float(theta[0]))
    for k in sorted(local, key=lambda k: vals[k])[:candidates]:
        best = min(best, (float(vals[k]), float(theta[k])))
        lo, hi = theta[max(k - 1, 0)], theta[min(k + 1, n - 1)]
        res = scipy.optimize.minimize_scalar(lambda t: float(fn(loci(t)[0])), bounds=(lo, hi), method="bounded",
                                             options={"xatol": 1e-10 * hi})
        best = min(best, (float(res.fun), float(res.x)))
    return best


def base_frequency(loop: LiftedLoop, theta: float, v) -> float:
    """rad/s at the base rate of the input ``v`` (``N`` samples of one frame, repeated times ``e^(j theta)``
    each frame): the input is a sum of the ``N`` sinusoids ``e^(j w_k k Ts)``, ``w_k = (theta + 2 pi k) / (N Ts)``,
    that the base rate tells apart; the one of largest amplitude, folded into ``[0, pi / Ts]``. For ``N = 1``
    it is ``theta / Ts``."""
    N, Ts = loop.frame, loop.sample_time
    k = np.arange(N)
    F = np.exp(1j * np.outer(k, theta + 2 * math.pi * k) / N)  # F[p, k] = e^(j w_k p Ts)
    c = np.linalg.solve(F, np.asarray(v, dtype=complex))
    w = (theta + 2 * math.pi * int(np.argmax(np.abs(c)))) / N
    return abs(math.remainder(w, 2 * math.pi)) / Ts


def exact_delay_margin(lift: Lifted, j: int) -> float | None:
    """s: the least extra delay of input ``j``'s held command (:meth:`Lifted.delayed_frame_map`) that puts a
    pole of the lifted loop on the unit circle, scanned over :data:`DELAY_SCAN` then bisected (None: none
    within the scan, or no continuous plant). The loop is stable without it."""
    if lift.plant_rates is None:
        return None
    Ts = lift.sample_time

    def stable(tau):
        return bool(np.all(is_stable(np.linalg.eigvals(lift.delayed_frame_map(j, tau)), discrete=True)))

    def radius(tau):
        return float(np.max(np.abs(np.linalg.eigvals(lift.delayed_frame_map(j, tau))))) - 1.0

    prev = 0.0
    for tau in DELAY_SCAN * Ts:
        if not stable(tau):
            # the spectral radius is continuous in the delay: its crossing of 1 in the bracket is the edge
            return float(scipy.optimize.brentq(radius, prev, float(tau), xtol=1e-13 * tau, rtol=1e-13))
        prev = float(tau)
    return None


def lifted(loop) -> Lifted:
    """The cascade's loop ``loop`` (:class:`quadctl.sim.loop.ClosedLoop` with a ``law``) linearized about
    hover at every phase of its frame (:func:`_lifted`), Ctrl-C and SIGTERM taken when it is done.

    Its least-squares trim calls the CasADi law from Python hundreds of times: a KeyboardInterrupt raised in
    CasADi's argument conversion is swallowed by its wrapper, which then matches another overload, and the
    work went on as if no Ctrl-C had come.
    """
    with signals_held():
        return _lifted(loop)


def _lifted(loop) -> Lifted:
    """:func:`lifted`, its Ctrl-C not held.

    The law's equilibrium is found first: the plant at trim, the integrators (velocity and rate) that
    make the command the law computes the trim input (least squares), the held setpoints the first sample's.
    With a delay (``loop.delay_samples``) the command computed is the one shifted into the buffer (the buffer
    holds the trim input), and the command applied, the buffer's oldest, is what the lifted loop breaks at.
    """

    gains = loop.law
    Ts = 1.0 / float(gains["rate_hz"])
    spec = loop.spec()
    funcs = build(spec)
    c = loop.constants(Ts)
    e = np.zeros(spec.n_exo)
    X0 = loop.initial_loop_state(loop.x_trim)
    npl = spec.n_plant
    base = npl + spec.nz + spec.n_lag
    law = funcs.law
    u_trim = np.asarray(loop.u_trim, dtype=float)
    free = np.concatenate([np.arange(pid.state_slice(name).start, pid.state_slice(name).stop) + base
                           for name in ("vel_integral", "rate_integral")])

    def computed(X):  # the command the law computes at X: applied at once, or shifted into the delay's buffer
        if not spec.delay:
            return np.asarray(law(X, 0.0, c, e)[0]).ravel()
        return np.asarray(law(X, 0.0, c, e)[1]).ravel()[spec.buffer_start:spec.buffer_start + len(u_trim)]

    def residual(values):
        X = X0.copy()
        X[free] = values
        return computed(X) - u_trim

    fit = scipy.optimize.least_squares(residual, X0[free], xtol=1e-14, ftol=1e-14, gtol=1e-14)
    X = X0.copy()
    X[free] = fit.x
    X = np.asarray(law(X, 0.0, c, e)[1]).ravel()  # the held setpoints of a first sample, phase 1
    Xs = ca.SX.sym("X", spec.nx)
    u_sym, X_next = law(Xs, 0.0, c, e)
    jac = ca.Function("qc_law_jacobian", [Xs], [ca.jacobian(u_sym, Xs), ca.jacobian(X_next, Xs)])
    _, n_pos = gains.ratios
    phase = base + pid.state_slice("phase").start
    states, commands = [None] * n_pos, [None] * n_pos
    start = None
    for _ in range(n_pos):
        p = int(round(X[phase]))
        if p == 0:
            start = X.copy()
        Ju, JX = (np.asarray(m) for m in jac(X))
        commands[p], states[p] = Ju, JX
        X = np.asarray(law(X, 0.0, c, e)[1]).ravel()
    keep = read_states(states, commands, npl)
    rates = plant_rates(loop)
    return Lifted(plant=_hold(rates, Ts), law_state=[S[np.ix_(keep, keep)] for S in states],
                  law_command=[U[:, keep] for U in commands], sample_time=Ts, states=keep, equilibrium=start,
                  plant_rates=rates)


def read_states(law_state, law_command, n_plant: int) -> np.ndarray:
    """Indices of the loop states something reads: the plant's, and each law state that the command or
    another read state depends on at some phase. The others (an integrator of gain zero, a filter the
    values switch off) only follow the loop: their eigenvalues (1) are neither controllable nor
    observable, and they are left out, as the LQR loops leave out the positions nothing feeds back."""
    nx = law_state[0].shape[0]
    keep = np.ones(nx, dtype=bool)
    while True:
        read = np.zeros(nx, dtype=bool)
        read[:n_plant] = True
        for S, U in zip(law_state, law_command):
            read |= np.any(U != 0, axis=0)
            others = (S - np.diag(np.diag(S)))[keep]  # what the kept states read, their own past aside
            read |= np.any(others != 0, axis=0)
        if np.array_equal(read & keep, keep):
            return np.nonzero(keep)[0]
        keep &= read


def _hold(rates, t: float) -> tuple[np.ndarray, np.ndarray]:
    """``(e^(A t), int_0^t e^(A s) ds B)`` of ``rates = (A, B)``."""
    A, B = rates
    n, m = B.shape
    E = scipy.linalg.expm(np.block([[A, B], [np.zeros((m, n + m))]]) * t)
    return E[:n, :n], E[:n, n:]


def _held_input(rates, j: int, late: float, early: float) -> tuple[np.ndarray, np.ndarray]:
    """What one sample of the plant gets from input ``j`` held for the last ``late`` s of it (the command now)
    and for the first ``early`` s (the command before): ``(int_0^late e^(A s) ds b, e^(A late) int_0^early
    e^(A s) ds b)``."""
    Al, Bl = _hold(rates, late)
    _, Be = _hold(rates, early)
    return Bl[:, j], Al @ Be[:, j]


def plant_rates(loop) -> tuple[np.ndarray, np.ndarray]:
    """The plant's continuous model ``(A, B)`` on ``[x; f]``: the linear model (``loop.jacobians``),
    through the rotors' lag when they lag (each rotor's thrust ``f' = (mix u - f) / tau``)."""
    A, B = (np.asarray(m, dtype=float) for m in loop.jacobians)
    tau = loop.rotor_time_constant
    if tau is not None:
        mix, mix_inv = np.asarray(loop.actuators.mix), np.asarray(loop.actuators.mix_inv)
        n, m = A.shape[0], mix.shape[0]
        A = np.block([[A, B @ mix_inv], [np.zeros((m, n)), -np.eye(m) / tau]])
        B = np.vstack([np.zeros((n, B.shape[1])), mix / tau])
    return A, B


def cascade_margins(loop, *, title: str = "PID", lift: Lifted | None = None) -> list:
    """Margins of every input's loop of a PID cascade, broken at the plant input (``model = "cascade"``).

    Parameters
    ----------
    loop : quadctl.sim.loop.ClosedLoop
        A loop flying a PID cascade (:func:`quadctl.pipeline.pid_loop_of`).
    title : str
        The law's name, for the loop's label.
    lift : Lifted, optional
        :func:`lifted` ``loop``, when already computed.

    Returns
    -------
    list of quadctl.design.margins.LoopMargins
        One per input ``T, A, E, R``, every margin exact: the gain margins from the lifted loop's poles
        (:func:`exact_gain_margins`; their frequencies the loci's where they agree, :data:`FREQUENCY_AGREEMENT_DB`),
        phase and disk margins from its characteristic loci (:func:`loci_margins`), the delay margin the least
        extra delay of the held input (:func:`exact_delay_margin`); ``freq`` and ``response`` the fundamental
        harmonic (:class:`LiftedLoop`, for the plots). A delay (``loop.delay_samples``, the cascade's samples) is
        in every loop, before the break: the margins are beyond it, as the LQR loops' are.
    """
    from threadpoolctl import threadpool_limits

    lift = lifted(loop) if lift is None else lift
    # hundreds of small eigenproblems (36 to 100 wide): BLAS threads only contend (quadctl.threads says why)
    with threadpool_limits(limits=1):
        return [_input_margins(loop, lift, j, inp, title) for j, inp in enumerate(INPUT_NAMES)]


def _input_margins(loop, lift: Lifted, j: int, inp: str, title: str):

    broken = lift.broken(j)
    w = broken.grid(POINTS_PER_DECADE)
    labels = dict(loop=title, input=inp, model="cascade", sample_time=broken.sample_time, freq=w,
                  response=broken(w), delay_samples=loop.delay_samples)
    loci = loci_margins(broken)
    if not broken.is_stable():
        return no_margin(min_return_difference=loci.min_return_difference, **labels)
    exact = exact_gain_margins(broken)
    # the loci's crossing of the real axis names the frequency where it gives the exact margin
    freqs = tuple(w if w is not None and abs(a - b) <= FREQUENCY_AGREEMENT_DB else None
                  for w, a, b in zip(loci.phase_crossover_freqs, exact, loci.gain_margin_db))
    return LoopMargins(
        stable=True, gain_margin_db=exact, phase_crossover_freqs=freqs, phase_margin_deg=loci.phase_margin_deg,
        gain_crossover_freq=loci.gain_crossover_freq, disk_alpha=loci.disk_alpha,
        disk_gain_db=disk_gain_range_db(loci.disk_alpha),
        disk_phase_deg=math.degrees(2 * math.atan(loci.disk_alpha / 2)), disk_freq=loci.disk_freq,
        min_return_difference=loci.min_return_difference, delay_margin=exact_delay_margin(lift, j), **labels)
