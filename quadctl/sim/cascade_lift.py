"""A PID cascade's loop about hover, lifted to its frame and broken at each plant input.

The multi-rate cascade (:mod:`quadctl.sim.pid`), linearized about hover from the law the simulation
runs at every phase of its frame (:func:`lifted`), is time-invariant over the frame (:class:`Lifted`):
its map over one frame, that map with one input held late (:meth:`Lifted.delayed_frame_map`), and the
loop broken at one input (:class:`LiftedLoop`: its transfer matrix over the frame, the characteristic
loci, the poles of the loop closed through a gain). The margins read from these are
:mod:`quadctl.sim.cascade_margins`; the method and its references are in docs/internals.md ("Margins of
a PID cascade").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.design.margin_search import GRID_SPAN
from quadctl.linear.stability import is_stable
from quadctl.signals import signals_held
from quadctl.sim import pid
from quadctl.sim.builder import build

ca = lazy_import("casadi")
scipy = lazy_import("scipy")

LOCI_INFINITE = 1e10
"""An eigenvalue of ``L`` larger than this (a destabilizing gain below -200 dB) is taken as this, real."""
LOCI_ZERO = 1e-10
"""An eigenvalue of ``L`` smaller than this (a destabilizing gain above +200 dB; a loop of low rank over the
frame has such, their phase rounding noise) is taken as 0."""
LOCI_EXPLICIT = 1e4
"""Largest ``|L|`` entry at which the loci are the eigenvalues of ``L`` itself (those of order one then good
to ~1e-12); beyond it, of the pencil (:meth:`LiftedLoop.loci`)."""


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

    @cached_property
    def poles(self) -> np.ndarray:
        """The closed loop's poles in ``z`` of the frame period: the eigenvalues of :attr:`frame_map`, computed
        once (the flight's check and ``margins.json`` both read them)."""
        return np.linalg.eigvals(self.frame_map)

    @property
    def stable(self) -> bool:
        """Whether the cascade holds hover: every pole inside the unit circle (:func:`is_stable`)."""
        return bool(np.all(is_stable(self.poles, discrete=True)))

    @property
    def frame_time(self) -> float:
        """s: the frame period ``N Ts`` the poles are in ``z`` of."""
        return self.frame * self.sample_time

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
    Nyquist plots, as :class:`quadctl.design.broken_loops.BrokenLoop` gives its ``L``); the margins are from
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
        :class:`~quadctl.design.broken_loops.BrokenLoop` (closed loop: ``I + L`` singular)."""
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
    make the command the law computes the trim input (:func:`nearest_zero`: the integrators have more states than
    the command has inputs), the held setpoints the first sample's.
    With a delay (``loop.delay_samples``) the command computed is the one shifted into the buffer (the buffer
    holds the trim input), and the command applied, the buffer's oldest, is what the lifted loop breaks at.
    """

    gains = loop.law
    Ts = 1.0 / float(gains["rate_hz"])
    spec = loop.spec()
    c = loop.constants(Ts)
    e = np.zeros(spec.n_exo)
    X0 = loop.initial_loop_state(loop.x_trim)
    npl = spec.n_plant
    base = npl + spec.nz + spec.n_lag
    law = law_at_start(spec)
    u_trim = np.asarray(loop.u_trim, dtype=float)
    free = np.concatenate([np.arange(pid.state_slice(name).start, pid.state_slice(name).stop) + base
                           for name in ("vel_integral", "rate_integral")])

    jac = law_jacobians(spec)
    rows = (slice(None) if not spec.delay
            else slice(spec.buffer_start, spec.buffer_start + len(u_trim)))  # the command computed, in the buffer

    def computed(X):  # the command the law computes at X: applied at once, or shifted into the delay's buffer
        return evaluated(law, X, c, e)[1 if spec.delay else 0].ravel()[rows]

    def residual(values):
        X = X0.copy()
        X[free] = values
        return computed(X) - u_trim

    def residual_jacobian(values):  # exact, from CasADi: a few law calls, not one per free state and step
        X = X0.copy()
        X[free] = values
        Ju, JX = evaluated(jac, X, c, e)
        return (JX if spec.delay else Ju)[rows][:, free]

    X = X0.copy()
    X[free] = nearest_zero(residual, residual_jacobian, X0[free], scale=1.0 + float(np.max(np.abs(u_trim))))
    X = evaluated(law, X, c, e)[1].ravel()  # the held setpoints of a first sample, phase 1
    _, n_pos = gains.ratios
    phase = base + pid.state_slice("phase").start
    states, commands = [None] * n_pos, [None] * n_pos
    start = None
    chain = evaluated(frame_chain(spec, n_pos), X, c, e)  # each sample's state and Jacobians, in one call
    for k in range(n_pos):
        Ju, JX, X = chain[3 * k: 3 * k + 3]
        p = int(round(X[phase, 0]))
        if p == 0:
            start = X.ravel()
        commands[p], states[p] = Ju, JX
    keep = read_states(states, commands, npl)
    rates = plant_rates(loop)
    return Lifted(plant=_hold(rates, Ts), law_state=[S[np.ix_(keep, keep)] for S in states],
                  law_command=[U[:, keep] for U in commands], sample_time=Ts, states=keep, equilibrium=start,
                  plant_rates=rates)


ZERO_STEPS = 20
"""Gauss-Newton steps :func:`nearest_zero` takes before it hands the search to SciPy's least squares."""


def nearest_zero(residual, jacobian, x0: np.ndarray, scale: float) -> np.ndarray:
    """A zero of ``residual`` (fewer equations than unknowns) near ``x0``: Gauss-Newton steps of least norm
    from ``x0`` (on a residual affine in ``x``, the zero nearest ``x0``, in one step), until the residual is
    within round-off of ``scale`` (1e-14 of it); else SciPy's trust-region least squares from where they got
    (a residual the steps do not settle)."""
    x = np.array(x0, dtype=float)
    for _ in range(ZERO_STEPS):
        r = residual(x)
        if np.max(np.abs(r)) <= 1e-14 * scale:
            return x
        x = x - np.linalg.lstsq(jacobian(x), r, rcond=None)[0]
    fit = scipy.optimize.least_squares(residual, x, jac=jacobian, xtol=1e-14, ftol=1e-14, gtol=1e-14)
    return fit.x


def _symbols(spec):
    return ca.SX.sym("X", spec.nx), ca.SX.sym("c", spec.n_constants), ca.SX.sym("e", spec.n_exo)


@lru_cache(maxsize=8)
def law_at_start(spec):
    """``(X, c, e) -> (u, X_sampled)``: the law of loop spec ``spec`` at the start of a run (t = 0), its
    outputs dense (for :func:`evaluated`)."""
    X, c, e = _symbols(spec)
    u, X_next = build(spec).law(X, 0.0, c, e)
    return ca.Function("qc_law_at_start", [X, c, e], [ca.densify(u), ca.densify(X_next)])


@lru_cache(maxsize=8)
def law_jacobians(spec):
    """``(X, c, e) -> (du/dX, dX_sampled/dX)``: the exact Jacobians of the law of loop spec ``spec`` at the
    start of a run (t = 0), built once per spec (a sweep's cases share it), dense."""
    X, c, e = _symbols(spec)
    u, X_next = build(spec).law(X, 0.0, c, e)
    return ca.Function("qc_law_jacobian", [X, c, e],
                       [ca.densify(ca.jacobian(u, X)), ca.densify(ca.jacobian(X_next, X))])


@lru_cache(maxsize=8)
def frame_chain(spec, samples: int):
    """``(X, c, e) -> (du/dX, dX_sampled/dX, X)`` at each of ``samples`` samples from ``X``, each sample's
    ``X`` the law's sampled state of the one before: a frame's linearization in one call."""
    X, c, e = _symbols(spec)
    law, jac = build(spec).law, law_jacobians(spec)
    outputs, Xk = [], X
    for _ in range(samples):
        outputs += [*jac(Xk, c, e), ca.densify(Xk)]
        Xk = law(Xk, 0.0, c, e)[1]
    return ca.Function("qc_frame_chain", [X, c, e], outputs)


def evaluated(fn, *args) -> list[np.ndarray]:
    """The dense outputs of CasADi function ``fn`` at ``args`` (numpy arrays), as numpy matrices: CasADi
    writes them straight into numpy's memory (its buffer), where converting its DM results cost more
    than the evaluation itself (about 80 µs a 53 x 53 Jacobian)."""
    buffer, run = fn.buffer()
    held = [np.ascontiguousarray(a, dtype=float).ravel() for a in args]
    out = [np.empty((fn.size2_out(k), fn.size1_out(k))) for k in range(fn.n_out())]  # column-major: transposed
    for k, a in enumerate(held):
        buffer.set_arg(k, memoryview(a))
    for k, o in enumerate(out):
        buffer.set_res(k, memoryview(o))
    run()
    return [o.T for o in out]


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
