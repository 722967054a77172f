"""RK4 step planning: the step a closed loop needs, chosen from its spectrum, or a user's step checked.

RK4 is stable for ``h lambda`` inside its stability region and accurate when ``|h lambda|`` is
small. With continuous feedback the closed loop's eigenvalues govern; with a sampled controller
(zero-order hold) RK4 integrates the plant under a constant input between samples, so the
open-loop eigenvalues govern and the step divides the controller period.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from quadctl.errors import QuadctlNotice, StepSizeError
from quadctl.linear.stability import is_stable
from quadctl.text.messages import eig_text

ACCURACY_STEP = 0.5
"""``dt: auto`` keeps ``|dt lambda| <= 0.5`` for the fastest eigenvalue: RK4's one-step error is then
below 5e-4 of the mode's own decay (|R(-0.5)| = 0.60677 against exp(-0.5) = 0.60653)."""
MAX_STEPS = 10**10
"""A plan of more RK4 steps is refused: about 40 min compiled (14 h without a compiler), far past any
flight worth simulating; it is almost always a unit slip (an inertia in kg m^2 entered as g cm^2
makes the rate poles 10^7 times faster) or a duration in ms. Also keeps the count far from where it
would wrap on its way to C's ``long``."""
ANNOUNCE_STEPS = 10**8
"""A plan of more RK4 steps is announced (a notice with the count) before the run starts."""
MAX_AUTO_STEPS_PER_SECOND = 1000
"""``dt: auto`` is never coarser than 1 ms, so plots and metrics resolve the slow loops."""
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


RK4_RAY_BRACKET = (2.5, 3.0)
"""Along any ray into the closed left half-plane, RK4's region ``|R(z)| <= 1`` ends once, at
``|z|`` between 2.6155 and 2.9601 (scanned on 2001 directions, 64001 radii each): bisection
on this bracket finds the same boundary point that :func:`max_stable_step`
finds by its grid scan (tested)."""
BISECTIONS = 52
"""Halvings of :data:`RK4_RAY_BRACKET` (width 1/2) in :func:`max_stable_steps`: after 50 the bracket is one
ulp of ``|z|`` in [2, 4) (2^-51), and every later halving leaves it as it is (checked bit for bit
against 64 on 21 000 eigenvalues); 52 keeps two to spare."""
REAL_AXIS = 2.785293563405945
"""Where the bisection of :func:`max_stable_steps` ends on the negative real axis (bit for bit, tested):
a real eigenvalue's ``|h lambda|`` limit, taken without bisecting."""
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
    if lam.size == 0:
        return np.zeros(lam.shape)
    flat = lam.ravel()
    out = np.zeros(flat.shape)
    mag = np.abs(flat)
    out[mag == 0] = np.inf
    stable = is_stable(flat)
    idx = np.nonzero(stable & (mag > 0))[0]
    direction = flat[idx] / mag[idx]
    axis = direction == -1  # a real eigenvalue: the negative real axis's known boundary
    out[idx[axis]] = REAL_AXIS / mag[idx[axis]]
    idx, direction = idx[~axis], direction[~axis]
    if idx.size:
        lo = np.full(idx.size, RK4_RAY_BRACKET[0])
        hi = np.full(idx.size, RK4_RAY_BRACKET[1])
        bracketed = ((rk4_amplification(lo * direction) <= _LEVEL)
                     & (rk4_amplification(hi * direction) > _LEVEL))
        for _ in range(BISECTIONS):
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
    method: str = "rk4"
    """The integrator: ``rk4``, or ``etdrk4`` (:mod:`quadctl.sim.etdrk4_plan`)."""
    schedule: tuple = ()
    """ETDRK4: its :class:`quadctl.sim.etdrk4_plan.Segment` s, in order; RK4: empty (``n_steps`` of ``dt``)."""


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
    stable_modes = np.asarray(is_stable(eig), dtype=bool)  # eig is 1-d: one verdict each
    h_max = float(limits[stable_modes].min()) if stable_modes.any() else math.inf
    k_fast = int(np.argmax(np.abs(eig))) if eig.size else 0
    fastest = complex(eig[k_fast]) if eig.size else 0j
    owner = owners[k_fast] if eig.size else ""
    if dt == "auto":
        h = min(ACCURACY_STEP / abs(fastest) if abs(fastest) > 0 else math.inf,
                0.5 * h_max, 1.0 / MAX_AUTO_STEPS_PER_SECOND, duration)
        n = step_count(duration, h, fastest, owner)
        return StepPlan(duration / n, n, h_max, fastest, owner, True)
    dt = float(dt)
    if dt > h_max:
        k = int(np.argmin(np.where(stable_modes, limits, np.inf)))
        raise StepSizeError(
            f"simulation.dt = {dt:g} s is unstable for RK4: the closed-loop eigenvalue "
            f"{eig_text(eig[k], 6)} rad/s (subsystem {owners[k]}) needs dt <= {h_max:.3g} s; "
            f"use dt: auto or a step of at most {_round_down(h_max):g} s")
    return StepPlan(dt, step_count(duration, dt, fastest, owner, given=dt), h_max, fastest, owner, False)


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
    stable_modes = np.asarray(is_stable(eig), dtype=bool)  # eig is 1-d: one verdict each
    limits = max_stable_steps(eig)
    h_max = float(limits[stable_modes].min()) if stable_modes.any() else math.inf
    fastest = complex(eig[int(np.argmax(np.abs(eig)))]) if eig.size else 0j
    if dt == "auto":
        h = min(ACCURACY_STEP / abs(fastest) if abs(fastest) > 0 else math.inf, 0.5 * h_max,
                1.0 / MAX_AUTO_STEPS_PER_SECOND, Ts)
        hold = max(1, math.ceil(Ts / h - 1e-9))
    else:
        dt = float(dt)
        hold = steps_per_sample(dt, Ts)
        if dt > h_max:
            raise StepSizeError(
                f"simulation.dt = {dt:g} s is unstable for RK4 on the open-loop plant between "
                f"controller samples (needs dt <= {h_max:.3g} s); use dt: auto or {Ts / math.ceil(Ts / h_max):.6g} s")
    step = Ts / hold
    n = step_count(duration, step, fastest, "the open-loop plant", given=None if dt == "auto" else dt)
    return StepPlan(step, n, h_max, fastest, "open loop (held input)", dt == "auto", hold, Ts)


def steps_per_sample(dt: float, Ts: float) -> int:
    """The whole number of steps of ``dt`` s in the controller period ``Ts`` s (what RK4 and ETDRK4
    take of a sampled controller's given step).

    Raises
    ------
    StepSizeError
        ``dt`` does not divide ``Ts``.
    """
    hold = max(1, round(Ts / dt))
    if abs(hold * dt - Ts) > 1e-9 * Ts:
        good = Ts / max(1, math.ceil(Ts / dt))
        raise StepSizeError(
            f"simulation.dt = {dt:g} s does not divide the controller period 1/rate = {Ts:g} s "
            f"(controller.rate = {1.0 / Ts:g} Hz); use dt: auto or {good:.6g} s")
    return hold


def step_count(duration: float, step: float, fastest: complex, owner: str, *, given: float | None = None) -> int:
    """RK4 steps of ``step`` s covering ``duration`` s, or a StepSizeError past :data:`MAX_STEPS`.

    ``given``: the user's ``simulation.dt`` (s) the step comes from (None: ``dt: auto`` chose it), which
    the refusal then names. A plan past :data:`ANNOUNCE_STEPS` is announced (a
    :class:`quadctl.errors.QuadctlNotice`).
    """
    count = duration / step
    if not count <= MAX_STEPS and given is not None:
        raise StepSizeError(
            f"simulation.dt = {given:g} s makes simulation.duration = {duration:g} s {count:.3g} steps, more than "
            f"the {MAX_STEPS:.0e} quadctl runs; use dt: auto, or a step of at least {duration / MAX_STEPS:.3g} s")
    if not count <= MAX_STEPS:
        raise StepSizeError(
            f"simulation.duration = {duration:g} s at an RK4 step of {step:.3g} s is {count:.3g} steps, more "
            f"than the {MAX_STEPS:.0e} quadctl runs (the step follows the fastest eigenvalue, "
            f"{eig_text(fastest, 6)} rad/s in {owner}); shorten simulation.duration, or check the units of "
            "vehicle.inertia and the weights (a slip by 1e6 makes the loop that much faster)")
    n = max(1, math.ceil(count - 1e-9))
    if n > ANNOUNCE_STEPS:
        warnings.warn(QuadctlNotice(
            f"simulating {n:.3g} RK4 steps of {step:.3g} s (fastest eigenvalue {eig_text(fastest, 6)} rad/s in "
            f"{owner}): about {n / 4e6 / 60:.0f} min compiled; Ctrl-C stops it and keeps nothing"), stacklevel=3)
    return n


def record_stride(n_steps: int, max_samples: int) -> int:
    """The smallest stride whose records (steps ``0, stride, 2 stride, ...`` and the last, see
    :func:`quadctl.sim.cases.record_rows`) number at most ``max_samples`` (>= 2) for ``n_steps``."""
    return (n_steps - 1) // (max_samples - 1) + 1 if n_steps > 1 else 1


def _round_down(h: float) -> float:
    """``h`` rounded down to 2 significant digits."""
    exp = math.floor(math.log10(h))
    return math.floor(h / 10 ** (exp - 1)) * 10 ** (exp - 1)
