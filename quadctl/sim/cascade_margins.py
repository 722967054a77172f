"""Margins of a PID cascade's loops, broken at each plant input with the whole cascade closed around it.

The multi-rate cascade (:mod:`quadctl.sim.pid`), linearized about hover from the law the simulation
runs, is lifted to its frame (:func:`lifted`, :class:`Lifted`): stability, poles and the gain margins
(:func:`exact_gain_margins`) are exact; phase, disk and delay margins are read from the loop's
fundamental harmonic by :func:`quadctl.design.margins.loop_margins`. The method and its references
are in the docs, docs/internals.md ("Margins of a PID cascade").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.layout import INPUT_NAMES
from quadctl.linear.stability import is_stable

ca = lazy_import("casadi")
scipy = lazy_import("scipy")

GAIN_SCAN = np.logspace(-3, 3, 241)
"""Loop-gain factors scanned outward from 1 for the exact gain margins (0.001 to 1000, 40 per decade: a band
of instability narrower than 6 % in gain between two stable ones would be missed), then bisected."""
FREQUENCY_AGREEMENT_DB = 0.01
"""dB: a gain margin's frequency is the fundamental harmonic's phase crossover when the margin read there is
within this of the exact one (the outer holds' aliases do not move it); otherwise none is given."""


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
    """

    plant: tuple[np.ndarray, np.ndarray]
    law_state: list
    law_command: list
    sample_time: float
    states: np.ndarray | None = None
    equilibrium: np.ndarray | None = None

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

    Behaves as :class:`quadctl.design.margins.BrokenLoop` for :func:`quadctl.design.margins.loop_margins`:
    called at ``w`` (rad/s) it gives the fundamental harmonic ``L0`` (module docstring); :meth:`is_stable`
    is exact.
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
        from quadctl.design.margins import GRID_SPAN

        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.log(self.closed_loop_eigenvalues().astype(complex)) / (self.frame * self.sample_time)
        mags = np.abs(s[np.isfinite(s)])
        mags = mags[mags > 1e-9]
        hi = math.pi / self.sample_time
        lo = min((mags.min() if mags.size else 1.0) / GRID_SPAN, hi / 1e3)
        w = np.logspace(math.log10(lo), math.log10(hi), int(max(math.log10(hi / lo), 1.0) * points_per_decade) + 1)
        w[-1] = hi
        return w


def exact_gain_margins(loop: LiftedLoop) -> tuple[float, float]:
    """(lower, upper) dB: the constant gains nearest 1, below and above, at which the lifted loop loses
    stability (``-inf`` / ``+inf``: none within :data:`GAIN_SCAN`). The loop is stable at gain 1."""
    from quadctl.design.margins import _db

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
    return (_db(lower) if lower else -math.inf, _db(upper) if upper else math.inf)


def lifted(loop) -> Lifted:
    """The cascade's loop ``loop`` (:class:`quadctl.sim.run.ClosedLoop` with a ``law``) linearized about
    hover at every phase of its frame.

    The law's equilibrium is found first: the plant at trim, the integrators (velocity and rate) that
    make the command the law computes the trim input (least squares), the held setpoints the first sample's.
    With a delay (``loop.delay_samples``) the command computed is the one shifted into the buffer (the buffer
    holds the trim input), and the command applied, the buffer's oldest, is what the lifted loop breaks at.
    """
    from quadctl.sim import pid
    from quadctl.sim.builder import build

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
    return Lifted(plant=zoh_plant(loop, Ts), law_state=[S[np.ix_(keep, keep)] for S in states],
                  law_command=[U[:, keep] for U in commands], sample_time=Ts, states=keep, equilibrium=start)


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


def zoh_plant(loop, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The plant's exact zero-order-hold map at ``Ts`` on ``[x; f]``: the linear model (``loop.jacobians``),
    through the rotors' lag when they lag (each rotor's thrust ``f' = (mix u - f) / tau``)."""
    A, B = (np.asarray(m, dtype=float) for m in loop.jacobians)
    tau = loop.rotor_time_constant
    if tau is not None:
        mix, mix_inv = np.asarray(loop.actuators.mix), np.asarray(loop.actuators.mix_inv)
        n, m = A.shape[0], mix.shape[0]
        A = np.block([[A, B @ mix_inv], [np.zeros((m, n)), -np.eye(m) / tau]])
        B = np.vstack([np.zeros((n, B.shape[1])), mix / tau])
    n, m = B.shape
    E = scipy.linalg.expm(np.block([[A, B], [np.zeros((m, n + m))]]) * Ts)
    return E[:n, :n], E[:n, n:]


def cascade_margins(loop, *, title: str = "PID", lift: Lifted | None = None) -> list:
    """Margins of every input's loop of a PID cascade, broken at the plant input (``model = "cascade"``).

    Parameters
    ----------
    loop : quadctl.sim.run.ClosedLoop
        A loop flying a PID cascade (:func:`quadctl.pipeline.pid_loop_of`).
    title : str
        The law's name, for the loop's label.
    lift : Lifted, optional
        :func:`lifted` ``loop``, when already computed.

    Returns
    -------
    list of quadctl.design.margins.LoopMargins
        One per input ``T, A, E, R``; the gain margins exact (:func:`exact_gain_margins`; their frequencies
        where the fundamental harmonic agrees, :data:`FREQUENCY_AGREEMENT_DB`), phase, disk and
        delay margins from the fundamental harmonic (module docstring), exact when the cascade runs at
        one rate (``loop.law.ratios == (1, 1)``). A delay (``loop.delay_samples``, the cascade's samples) is in
        every loop, before the break: the margins are beyond it, as the LQR loops' are.
    """
    from quadctl.design.margins import POINTS_PER_DECADE, loop_margins, no_margin

    lift = lifted(loop) if lift is None else lift
    out = []
    for j, inp in enumerate(INPUT_NAMES):
        broken = lift.broken(j)
        m = loop_margins(broken, name=title, input_name=inp, model="cascade",
                         grid=broken.grid(POINTS_PER_DECADE))
        if m.stable:
            exact = exact_gain_margins(broken)
            # a crossover of the fundamental harmonic names the frequency only where it gives the exact margin
            freqs = tuple(w if w is not None and abs(a - b) <= FREQUENCY_AGREEMENT_DB else None
                          for w, a, b in zip(m.phase_crossover_freqs, exact, m.gain_margin_db))
            m = replace(m, gain_margin_db=exact, phase_crossover_freqs=freqs)
        else:
            m = no_margin(loop=title, input=inp, model="cascade", sample_time=broken.sample_time,
                          min_return_difference=m.min_return_difference, freq=m.freq, response=m.response)
        out.append(replace(m, delay_samples=loop.delay_samples))
    return out
