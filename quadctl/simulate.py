"""Fixed-step RK4 simulation of the full nonlinear closed loop.

``u = u_trim - K (x - x_ref(t))`` with ``x_ref(t) = x_trim + x_rate t`` (positions drift at
the trim velocity), integrated by the compiled loop of :mod:`quadctl.codegen`. The step is
chosen from the closed loop's spectrum: RK4 is stable for ``h lambda`` inside its stability
region, and accurate when ``|h lambda|`` is small.

A controller with a rate (``ClosedLoop.rate``) is sampled every ``Ts = 1 / rate`` and its
command held (zero-order hold); RK4 then integrates the plant under a constant input between
samples, so the step divides ``Ts`` and is chosen from the *open-loop* spectrum
(:func:`plan_held_step`). Integrators of an LQI controller (``ClosedLoop.integral_states``) are
carried as extra loop states; inputs are clipped by ``ClosedLoop.actuators``; noise arrays come
from :mod:`quadctl.noise`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from quadctl.analysis import STABILITY_MARGIN, is_stable
from quadctl.codegen import get_loop, pack_constants
from quadctl.errors import StepSizeError
from quadctl.layout import N_STATES, STATE_INDEX, STATE_NAMES
from quadctl.noise import NoiseSpec, realize

ACCURACY_STEP = 0.5
"""``dt: auto`` keeps ``|dt lambda| <= 0.5`` for the fastest eigenvalue: RK4's one-step error is then
below 5e-4 of the mode's own decay (|R(-0.5)| = 0.60677 against exp(-0.5) = 0.60653)."""
MAX_SAMPLES = 20_000
"""Default of ``simulation.max_samples``: a run keeps at most this many samples (every
``stride``-th step, and always the last). 10 s at the report's auto step (290 000 steps) is then
a sample every 0.5 ms: finer than any settling time or plot needs, and 4.5 MB of sim.npz."""
MAX_AUTO_STEPS_PER_SECOND = 1000
"""``dt: auto`` is never coarser than 1 ms, so plots and metrics resolve the slow loops."""
VALID_PITCH = math.radians(85.0)
"""Beyond this pitch the Euler kinematics (``1/cos theta``) are near singular: the run stops."""
RUNAWAY = {"pN": 1e5, "pE": 1e5, "pD": 1e5, "u": 1e3, "v": 1e3, "w": 1e3,
           "phi": 1e3, "theta": VALID_PITCH, "psi": 1e3, "p": 1e4, "q": 1e4, "r": 1e4}
"""Bounds on |x - x_ref| (state units) past which a run counts as diverged; theta's is the model's range."""


def rk4_amplification(z) -> np.ndarray:
    """``|R(z)|``, ``R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24``: RK4's growth per step on ``x' = lambda x``."""
    z = np.asarray(z, dtype=complex)
    return np.abs(1 + z * (1 + z / 2 * (1 + z / 3 * (1 + z / 4))))


def max_stable_step(eigenvalue: complex) -> float:
    """Largest ``h`` with ``|R(h lambda)| <= 1`` on all of ``(0, h]`` (inf for lambda = 0), in s."""
    lam = complex(eigenvalue)
    if abs(lam) == 0.0:
        return math.inf
    if not is_stable(lam):
        return 0.0
    scaled = np.linspace(1e-6, 3.0, 30001)  # RK4's region lies within |h lambda| < 2.9
    bad = np.nonzero(rk4_amplification(scaled * lam / abs(lam)) > 1.0 + 1e-12)[0]
    if bad.size == 0:
        return 3.0 / abs(lam)
    lo, hi = (scaled[bad[0] - 1] if bad[0] > 0 else 0.0), scaled[bad[0]]
    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if rk4_amplification(mid * lam / abs(lam)) <= 1.0 + 1e-12 else (lo, mid)
    return lo / abs(lam)


_BRACKET = (2.5, 3.0)
"""Along any ray into the closed left half-plane, RK4's region ``|R(z)| <= 1`` ends once, at
``|z|`` between 2.6155 and 2.9601 (scanned on 2001 directions, 64001 radii each): bisection
on this bracket finds the same boundary point that :func:`max_stable_step`
finds by its grid scan (tested)."""
_LEVEL = 1.0 + 1e-12
"""The amplification level :func:`max_stable_step` calls unstable."""


def max_stable_steps(eigenvalues) -> np.ndarray:
    """Largest stable RK4 step for each eigenvalue, vectorized (s).

    Same values as :func:`max_stable_step` applied one by one (to the last bits of the
    bisection), ~50 times faster: ``inf`` for a zero eigenvalue, ``0`` for one that is not stable.

    Parameters
    ----------
    eigenvalues : array_like of complex, any shape

    Returns
    -------
    ndarray of float, the same shape
    """
    lam = np.asarray(eigenvalues, dtype=complex)
    flat = lam.ravel()
    out = np.zeros(flat.shape)
    mag = np.abs(flat)
    out[mag == 0] = np.inf
    stable = flat.real < -STABILITY_MARGIN * np.maximum(1.0, mag)
    idx = np.nonzero(stable & (mag > 0))[0]
    if idx.size:
        direction = flat[idx] / mag[idx]
        lo = np.full(idx.size, _BRACKET[0])
        hi = np.full(idx.size, _BRACKET[1])
        bracketed = ((rk4_amplification(lo * direction) <= _LEVEL)
                     & (rk4_amplification(hi * direction) > _LEVEL))
        for _ in range(64):
            mid = (lo + hi) / 2
            inside = rk4_amplification(mid * direction) <= _LEVEL
            lo = np.where(inside, mid, lo)
            hi = np.where(inside, hi, mid)
        out[idx] = lo / mag[idx]
        for k in idx[~bracketed]:  # never seen; the exact scan decides
            out[k] = max_stable_step(flat[k])
    return out.reshape(lam.shape)


@dataclass(frozen=True)
class StepPlan:
    """The chosen step and why: ``dt`` (s), ``n_steps``, and the governing eigenvalue.

    With a sampled controller, ``hold`` RK4 steps make one controller period ``sample_time``.
    """

    dt: float
    n_steps: int
    max_stable_dt: float
    fastest_eigenvalue: complex
    fastest_owner: str
    auto: bool
    hold: int = 0
    sample_time: float | None = None


def plan_step(eigenvalues, owners, duration: float, dt="auto", *, limits=None) -> StepPlan:
    """Choose (``dt="auto"``) or check a user's RK4 step for a closed loop.

    Parameters
    ----------
    eigenvalues : (n,) array_like
        Closed-loop eigenvalues of the linear model (rad/s).
    owners : sequence of str
        For each eigenvalue, the subsystem it belongs to (for messages).
    duration : float
        s.
    dt : float or "auto"
    limits : (n,) array_like, optional
        ``max_stable_steps(eigenvalues)``, when a batch computed them already.

    Raises
    ------
    StepSizeError
        A user's step that RK4 cannot hold stable: names the eigenvalue, its subsystem and
        the largest step that works.
    """
    eig = np.asarray(eigenvalues, dtype=complex)
    limits = max_stable_steps(eig) if limits is None else np.asarray(limits, dtype=float)
    stable_modes = np.array([is_stable(e) for e in eig], dtype=bool)
    h_max = float(limits[stable_modes].min()) if stable_modes.any() else math.inf
    k_fast = int(np.argmax(np.abs(eig))) if eig.size else 0
    fastest = complex(eig[k_fast]) if eig.size else 0j
    if dt == "auto":
        h = min(ACCURACY_STEP / abs(fastest) if abs(fastest) > 0 else math.inf,
                0.5 * h_max, 1.0 / MAX_AUTO_STEPS_PER_SECOND, duration)
        n = max(1, math.ceil(duration / h - 1e-9))
        return StepPlan(duration / n, n, h_max, fastest, owners[k_fast] if eig.size else "", True)
    dt = float(dt)
    if dt > h_max:
        k = int(np.argmin(np.where(stable_modes, limits, np.inf)))
        raise StepSizeError(
            f"simulation.dt = {dt:g} s is unstable for RK4: the closed-loop eigenvalue "
            f"{_fmt_eig(eig[k])} rad/s (subsystem {owners[k]}) needs dt <= {h_max:.3g} s; "
            f"use dt: auto or a step of at most {_round_down(h_max):g} s")
    n = max(1, math.ceil(duration / dt - 1e-9))
    return StepPlan(dt, n, h_max, fastest, owners[k_fast] if eig.size else "", False)


def plan_held_step(open_loop_eigenvalues, rate: float, duration: float, dt="auto") -> StepPlan:
    """Choose or check the RK4 step for a controller sampled at ``rate`` Hz (zero-order hold).

    Between samples the input is constant, so RK4 integrates the open-loop plant: the step
    must be stable and accurate for the open-loop eigenvalues, and divide the controller
    period ``Ts = 1 / rate`` into ``hold`` whole steps.

    Parameters
    ----------
    open_loop_eigenvalues : (n,) array_like
        Of the linear plant ``A`` (rad/s).
    rate : float
        Hz.
    duration : float
        s.
    dt : float or "auto"

    Raises
    ------
    StepSizeError
        A user's step that does not divide ``Ts``, or that RK4 cannot hold stable.
    """
    Ts = 1.0 / rate
    eig = np.asarray(open_loop_eigenvalues, dtype=complex)
    stable_modes = np.array([is_stable(e) for e in eig], dtype=bool)
    limits = max_stable_steps(eig)
    h_max = float(limits[stable_modes].min()) if stable_modes.any() else math.inf
    fastest = complex(eig[int(np.argmax(np.abs(eig)))]) if eig.size else 0j
    if dt == "auto":
        h = min(ACCURACY_STEP / abs(fastest) if abs(fastest) > 0 else math.inf, 0.5 * h_max,
                1.0 / MAX_AUTO_STEPS_PER_SECOND, Ts)
        hold = max(1, math.ceil(Ts / h - 1e-9))
    else:
        dt = float(dt)
        hold = max(1, round(Ts / dt))
        if abs(hold * dt - Ts) > 1e-9 * Ts:
            good = Ts / max(1, math.ceil(Ts / dt))
            raise StepSizeError(
                f"simulation.dt = {dt:g} s does not divide the controller period 1/rate = {Ts:g} s "
                f"(controller.rate = {rate:g} Hz); use dt: auto or {good:.6g} s")
        if dt > h_max:
            raise StepSizeError(
                f"simulation.dt = {dt:g} s is unstable for RK4 on the open-loop plant between "
                f"controller samples (needs dt <= {h_max:.3g} s); use dt: auto or {Ts / math.ceil(Ts / h_max):.6g} s")
    step = Ts / hold
    n = max(1, math.ceil(duration / step - 1e-9))
    return StepPlan(step, n, h_max, fastest, "open loop (held input)", dt == "auto", hold, Ts)


def eigen_owners(A_cl, state_owner: dict[str, str], names=STATE_NAMES) -> tuple[np.ndarray, list[str]]:
    """Eigenvalues of ``A_cl`` and, for each, the subsystem of its eigenvector's largest state.

    ``names`` labels the rows of ``A_cl`` (default the 12 states; an LQI loop appends its
    integrators, each owned by the subsystem of the state it integrates).
    """
    eig, vec = np.linalg.eig(np.asarray(A_cl, dtype=float))
    owners = [state_owner.get(names[int(np.argmax(np.abs(vec[:, k])))], "unassigned")
              for k in range(len(eig))]
    return eig, owners


@dataclass(frozen=True)
class ClosedLoop:
    """Everything the simulation needs: the plant parameters, the trim and the control law.

    Attributes
    ----------
    params : (8,) ndarray
        Vehicle parameter vector (:meth:`quadctl.model.Vehicle.vector`) of the simulated plant
        (it may differ from the design model's: model mismatch).
    x_trim : (12,) ndarray
    u_trim : (4,) ndarray
    x_rate : (12,) ndarray
        Drift of the reference (the trim velocity on positions, zero elsewhere).
    K : (4, 12) ndarray
    eigenvalues : (12,) ndarray
        Of the linear closed loop ``A - B K``.
    owners : list of str
        Subsystem of each eigenvalue.
    """

    params: np.ndarray
    x_trim: np.ndarray
    u_trim: np.ndarray
    x_rate: np.ndarray
    K: np.ndarray
    eigenvalues: np.ndarray
    owners: list = field(default_factory=list)
    rate: float | None = None
    """Hz of a sampled controller (zero-order hold); None: continuous feedback."""
    Ki: np.ndarray | None = None
    """(4, nz) integrator gains: ``u -= Ki z``."""
    integral_states: tuple[str, ...] = ()
    """The state each integrator integrates (``dz/dt = -(x_s - x_ref,s)``)."""
    actuators: object | None = None
    """:class:`quadctl.motors.Actuators` that clip the input; None: unlimited."""
    open_loop_eigenvalues: np.ndarray | None = None
    """Of the plant ``A``: what RK4 integrates between samples of a sampled controller."""


@dataclass(frozen=True)
class SimResult:
    """A simulation run.

    Attributes
    ----------
    t : (N+1,) ndarray
        s.
    x : (N+1, 12) ndarray
    u : (N+1, 4) ndarray
        Applied input (after any saturation).
    x_ref : (N+1, 12) ndarray
        The reference the controller regulates to.
    dt : float
    status : str
        ``ok``, ``diverged`` or ``left_valid_range``.
    message : str
        One line on how the run ended.
    wall_time : float
        s spent integrating (excludes compilation).
    steps : int
        RK4 steps taken.
    stride : int
        Samples are every ``stride``-th step (and the last); see ``max_samples``.
    backend : str
        ``compiled`` or ``casadi`` (no C compiler).
    plan : StepPlan
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    x_ref: np.ndarray
    dt: float
    status: str
    message: str
    wall_time: float
    backend: str
    plan: StepPlan
    steps: int
    stride: int
    z: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(N+1, nz) integrator states of an LQI controller."""
    noise_seed: int | None = None

    @property
    def steps_per_second(self) -> float:
        return self.steps / self.wall_time if self.wall_time > 0 else math.inf


def simulate(loop: ClosedLoop, x0, duration: float, dt="auto", *,
             noise: NoiseSpec | None = None, max_samples: int = MAX_SAMPLES) -> SimResult:
    """RK4 of the nonlinear closed loop from ``x0`` for ``duration`` seconds.

    Parameters
    ----------
    loop : ClosedLoop
    x0 : (12,) array_like
        Initial state (integrators, if any, start at zero).
    duration : float
        s.
    dt : float or "auto"
        s; see :func:`plan_step` (continuous control) or :func:`plan_held_step` (``loop.rate``).
    noise : NoiseSpec, optional
        Process and sensor noise; the same spec gives the same run.
    max_samples : int
        Samples kept, at most: every :func:`record_stride`-th step and the last.

    Returns
    -------
    SimResult
        A diverging run stops at the first bad state and keeps everything before it.
    """
    if loop.rate is not None:
        ol = loop.open_loop_eigenvalues if loop.open_loop_eigenvalues is not None else np.zeros(0)
        plan = plan_held_step(ol, loop.rate, duration, dt)
    else:
        plan = plan_step(loop.eigenvalues, loop.owners, duration, dt)
    nz = len(loop.integral_states)
    act = loop.actuators
    pattern = tuple(bool(v) for v in (loop.K != 0).ravel(order="F"))
    runner = get_loop(pattern, act.mode if act is not None else "none",
                      tuple(STATE_INDEX[s] for s in loop.integral_states))
    consts = dict(x_ref=loop.x_trim, x_rate=loop.x_rate, u_trim=loop.u_trim, K=loop.K, params=loop.params)
    if act is not None:
        consts.update(mix=act.mix, mix_inv=act.mix_inv, lo=act.lo, hi=act.hi)
    if nz:
        Ki = np.asarray(loop.Ki, dtype=float).reshape(len(loop.u_trim), nz)
        consts.update(Ki=Ki, antiwindup=(Ki.T != 0).astype(float), Ts=[plan.sample_time or 0.0])
    c = pack_constants(**consts)
    n = plan.n_steps
    bound = np.array([RUNAWAY[s] for s in STATE_NAMES])
    theta = STATE_INDEX["theta"]
    lo, hi = loop.x_trim - bound, loop.x_trim + bound
    lo[theta], hi[theta] = -VALID_PITCH, VALID_PITCH
    # positions drift with the reference: bound them around the farthest reference point
    drift = np.abs(loop.x_rate) * duration
    lo, hi = lo - drift, hi + drift
    lo_all = np.concatenate([lo, np.full(nz, -np.inf)])
    hi_all = np.concatenate([hi, np.full(nz, np.inf)])
    x0_all = np.concatenate([np.asarray(x0, dtype=float), np.zeros(nz)])
    dist, meas = realize(noise, n, plan.dt) if noise is not None and noise.active else (None, None)
    stride = record_stride(n, max_samples)
    start = time.perf_counter()
    done, ks, xs, us = run_in_chunks(runner, x0_all, plan.dt, n, c, dist, meas, plan.hold, stride,
                                     lo_all, hi_all)
    wall = time.perf_counter() - start
    t = plan.dt * ks
    x_ref = loop.x_trim + np.outer(t, loop.x_rate)
    status, message = _verdict(xs[:, :N_STATES], t, done, n, lo, hi)
    seed = noise.seed if noise is not None and noise.active else None
    return SimResult(t=t, x=np.ascontiguousarray(xs[:, :N_STATES]), u=us, x_ref=x_ref, dt=plan.dt, status=status,
                     message=message, wall_time=wall, backend=runner.backend, plan=plan, steps=done, stride=stride,
                     z=np.ascontiguousarray(xs[:, N_STATES:]), noise_seed=seed)


def record_stride(n_steps: int, max_samples: int) -> int:
    """The smallest stride whose records (steps ``0, stride, 2 stride, ...`` and the last, see
    :func:`quadctl.codegen.record_rows`) number at most ``max_samples`` (>= 2) for ``n_steps``."""
    return (n_steps - 1) // (max_samples - 1) + 1 if n_steps > 1 else 1


CHUNK_STEPS = 250_000
"""Steps per call into the compiled loop (~50 ms): Python sees Ctrl-C between calls."""


def run_in_chunks(runner, x0, dt, n, c, dist, meas, hold, stride, lo, hi):
    """``runner.run`` over ``n`` steps, in chunks aligned to the hold and the record stride.

    Every chunk starts on a controller sample and a recorded step, so the rows are those of one
    long call; between chunks Python handles signals (Ctrl-C stops a long run at once).

    Returns
    -------
    (done, ks, xs, us) : as :meth:`quadctl.codegen.CompiledLoop.run`.
    """
    unit = math.lcm(stride, max(hold, 1))
    chunk = max(unit, CHUNK_STEPS // unit * unit)
    parts_k, parts_x, parts_u = [], [], []
    x = np.ascontiguousarray(x0, dtype=float)
    start = 0
    while True:
        m = min(chunk, n - start)
        window = slice(start, start + m)
        done, ks, xs, us = runner.run(
            x, dt * start, dt, m, c,
            None if dist is None else np.ascontiguousarray(dist[window]),
            None if meas is None else np.ascontiguousarray(meas[window]), hold, stride, lo, hi)
        last = start + m >= n or done < m
        keep = len(ks) if last else len(ks) - 1  # a chunk's last row is the next one's first
        parts_k.append(ks[:keep] + start)
        parts_x.append(xs[:keep])
        parts_u.append(us[:keep])
        if last:
            return start + done, np.concatenate(parts_k), np.concatenate(parts_x), np.concatenate(parts_u)
        x = np.ascontiguousarray(xs[-1])
        start += m


def _verdict(xs, t, done, n, lo, hi) -> tuple[str, str]:
    if done == n:
        return "ok", f"completed {n} steps to t = {t[-1]:.6g} s"
    last = xs[-1]
    bad = [i for i in range(N_STATES) if not (lo[i] <= last[i] <= hi[i])]
    name = STATE_NAMES[bad[0]] if bad else "?"
    if not np.all(np.isfinite(last)):
        return "diverged", f"diverged at t = {t[-1]:.4g} s: {name} is not finite; saved {_steps(done)}"
    if name == "theta":
        return "left_valid_range", (
            f"left the model's valid range at t = {t[-1]:.4g} s: pitch {math.degrees(last[bad[0]]):.1f} deg "
            f"is beyond +-{math.degrees(VALID_PITCH):.0f} deg (Euler kinematics singular at 90); saved {_steps(done)}")
    return "diverged", (f"diverged at t = {t[-1]:.4g} s: {name} = {last[bad[0]]:.3g} ran away; "
                        f"saved {_steps(done)}")


def _steps(n: int) -> str:
    return f"{n} step" if n == 1 else f"{n} steps"


def _fmt_eig(e: complex) -> str:
    return f"{e.real:.6g}" if abs(e.imag) < 1e-9 else f"{e.real:.6g}{e.imag:+.6g}j"


def _round_down(h: float) -> float:
    """``h`` rounded down to 2 significant digits."""
    exp = math.floor(math.log10(h))
    return math.floor(h / 10 ** (exp - 1)) * 10 ** (exp - 1)
