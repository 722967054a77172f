"""Fixed-step RK4 simulation of the full nonlinear closed loop.

``u = u_trim - K (x - x_ref(t))`` with ``x_ref(t) = x_trim + x_rate t`` (positions drift at
the trim velocity), integrated by the compiled loop of :mod:`quadctl.codegen`. The step is
chosen from the closed loop's spectrum: RK4 is stable for ``h lambda`` inside its stability
region, and accurate when ``|h lambda|`` is small.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from quadctl.analysis import is_stable
from quadctl.codegen import get_loop, pack_constants
from quadctl.errors import StepSizeError
from quadctl.layout import N_STATES, STATE_INDEX, STATE_NAMES

ACCURACY_STEP = 0.5
"""``dt: auto`` keeps ``|dt lambda| <= 0.5`` for the fastest eigenvalue: RK4's one-step error is then
below 5e-4 of the mode's own decay (|R(-0.5)| = 0.60677 against exp(-0.5) = 0.60653)."""
MAX_RECORDS = 200_000
"""A run keeps at most this many samples (every ``stride``-th step, and always the last)."""
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


@dataclass(frozen=True)
class StepPlan:
    """The chosen step and why: ``dt`` (s), ``n_steps``, and the governing eigenvalue."""

    dt: float
    n_steps: int
    max_stable_dt: float
    fastest_eigenvalue: complex
    fastest_owner: str
    auto: bool


def plan_step(eigenvalues, owners, duration: float, dt="auto") -> StepPlan:
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

    Raises
    ------
    StepSizeError
        A user's step that RK4 cannot hold stable: names the eigenvalue, its subsystem and
        the largest step that works.
    """
    eig = np.asarray(eigenvalues, dtype=complex)
    limits = np.array([max_stable_step(e) for e in eig])
    stable_modes = np.array([is_stable(e) for e in eig])
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


def eigen_owners(A_cl, state_owner: dict[str, str]) -> tuple[np.ndarray, list[str]]:
    """Eigenvalues of ``A_cl`` and, for each, the subsystem of its eigenvector's largest state."""
    eig, vec = np.linalg.eig(np.asarray(A_cl, dtype=float))
    owners = [state_owner.get(STATE_NAMES[int(np.argmax(np.abs(vec[:, k])))], "unassigned")
              for k in range(len(eig))]
    return eig, owners


@dataclass(frozen=True)
class ClosedLoop:
    """Everything the simulation needs: the plant parameters, the trim and the control law.

    Attributes
    ----------
    params : (8,) ndarray
        Vehicle parameter vector (:meth:`quadctl.model.Vehicle.vector`).
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
        Samples are every ``stride``-th step (and the last); see ``MAX_RECORDS``.
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

    @property
    def steps_per_second(self) -> float:
        return self.steps / self.wall_time if self.wall_time > 0 else math.inf


def simulate(loop: ClosedLoop, x0, duration: float, dt="auto") -> SimResult:
    """RK4 of the nonlinear closed loop from ``x0`` for ``duration`` seconds.

    Parameters
    ----------
    loop : ClosedLoop
    x0 : (12,) array_like
        Initial state.
    duration : float
        s.
    dt : float or "auto"
        s; see :func:`plan_step`.

    Returns
    -------
    SimResult
        A diverging run stops at the first bad state and keeps everything before it.
    """
    plan = plan_step(loop.eigenvalues, loop.owners, duration, dt)
    pattern = tuple(bool(v) for v in (loop.K != 0).ravel(order="F"))
    runner = get_loop(pattern, "none")
    c = pack_constants(x_ref=loop.x_trim, x_rate=loop.x_rate, u_trim=loop.u_trim, K=loop.K,
                       params=loop.params)
    n = plan.n_steps
    bound = np.array([RUNAWAY[s] for s in STATE_NAMES])
    theta = STATE_INDEX["theta"]
    lo, hi = loop.x_trim - bound, loop.x_trim + bound
    lo[theta], hi[theta] = -VALID_PITCH, VALID_PITCH
    # positions drift with the reference: bound them around the farthest reference point
    drift = np.abs(loop.x_rate) * duration
    lo, hi = lo - drift, hi + drift
    stride = max(1, math.ceil(n / MAX_RECORDS))
    start = time.perf_counter()
    done, ks, xs, us = runner.run(x0, 0.0, plan.dt, n, c, None, None, 0, stride, lo, hi)
    wall = time.perf_counter() - start
    t = plan.dt * ks
    x_ref = loop.x_trim + np.outer(t, loop.x_rate)
    status, message = _verdict(xs, t, done, n, lo, hi)
    return SimResult(t=t, x=xs, u=us, x_ref=x_ref, dt=plan.dt, status=status, message=message,
                     wall_time=wall, backend=runner.backend, plan=plan, steps=done, stride=stride)


def _verdict(xs, t, done, n, lo, hi) -> tuple[str, str]:
    if done == n:
        return "ok", f"completed {n} steps to t = {t[-1]:.6g} s"
    last = xs[-1]
    bad = [i for i in range(N_STATES) if not (lo[i] <= last[i] <= hi[i])]
    name = STATE_NAMES[bad[0]] if bad else "?"
    if not np.all(np.isfinite(last)):
        return "diverged", f"diverged at t = {t[-1]:.4g} s: {name} is not finite; saved {done} steps"
    if name == "theta":
        return "left_valid_range", (
            f"left the model's valid range at t = {t[-1]:.4g} s: pitch {math.degrees(last[bad[0]]):.1f} deg "
            f"is beyond +-{math.degrees(VALID_PITCH):.0f} deg (Euler kinematics singular at 90); saved {done} steps")
    return "diverged", (f"diverged at t = {t[-1]:.4g} s: {name} = {last[bad[0]]:.3g} ran away; "
                        f"saved {done} steps")


def _fmt_eig(e: complex) -> str:
    return f"{e.real:.6g}" if abs(e.imag) < 1e-9 else f"{e.real:.6g}{e.imag:+.6g}j"


def _round_down(h: float) -> float:
    """``h`` rounded down to 2 significant digits."""
    exp = math.floor(math.log10(h))
    return math.floor(h / 10 ** (exp - 1)) * 10 ** (exp - 1)
