"""Rotors: the mixing matrix between [T, A, E, R] and the four rotor thrusts, and saturation.

The effectiveness ``M`` from the rotors' positions and spins (``[T, A, E, R]' = M f``, the mixer
``M^-1``), the flight stacks' numberings (:data:`NUMBERINGS`) and saturation by priority
(:func:`desaturate`) or clipping. The geometry, the default numbering and the saturation rules are
in the docs, docs/internals.md ("Rotors: mixing and saturation") and docs/guide/vehicle.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl.errors import ActuatorLimitError, ArgumentError, SaturationFailed
from quadctl.layout import INPUT_INDEX, INPUT_NAMES, INPUT_UNITS, N_INPUTS

SATURATED_RTOL = 1e-9
"""A rotor (or input) counts as saturated when within ``SATURATED_RTOL * (1 + |limit|)`` of a limit."""
SATURATION_FLAG = 0.01
"""A design is flagged as saturating when some actuator spends more than 1 % of the run at a limit."""
SATURATION_FAIL = 0.5
"""A design fails its check (exit 1, unless accepted) when some actuator is at a limit more than half
the run: it no longer flies the linear design, it flies its limits."""
SPINS = (1.0, -1.0, 1.0, -1.0)
"""Yaw reaction sign of rotors 1-4 of quadctl's own numbering (+1: counter-clockwise seen from above)."""
SPIN_SIGN = {"ccw": 1.0, "cw": -1.0}
"""A rotor's spin seen from above -> the sign of its yaw reaction torque on the body (FRD, z down)."""
POSITIONS = {
    "x": ("front_right", "rear_right", "rear_left", "front_left"),
    "+": ("front", "right", "rear", "left"),
}
"""Rotor positions of each layout, in quadctl's own numbering (clockwise seen from above)."""
NUMBERINGS: dict[str, tuple[str, str, str, str]] = {
    "quadctl": POSITIONS["x"],
    # Bitcraze crazyflie-firmware, src/modules/src/power_distribution_quadrotor.c
    # (powerDistributionForceTorque): M1 = T - roll - pitch - yaw (front right), M2 rear right,
    # M3 rear left, M4 front left; the yaw signs make M1 and M3 counter-clockwise seen from above.
    "crazyflie": ("front_right", "rear_right", "rear_left", "front_left"),
    # PX4 Airframes Reference (docs.px4.io, "Quadrotor x"): motor 1 front right (CCW), 2 rear left
    # (CCW), 3 front left (CW), 4 rear right (CW); PX4-SITL_gazebo-classic models/iris/iris.sdf.jinja
    # has the same order and turning directions (rotor_0 front right ccw ... rotor_3 back right cw).
    "px4": ("front_right", "rear_left", "front_left", "rear_right"),
    # Betaflight src/main/flight/mixer.c, mixerQuadX: REAR_R (M1, CW), FRONT_R (M2, CCW), REAR_L
    # (M3, CCW), FRONT_L (M4, CW); yaw_motors_reversed ("props out") turns every rotor the other way.
    "betaflight": ("rear_right", "front_right", "rear_left", "front_left"),
}
"""Quad-X motor orders of the flight stacks, rotor 1 first. Their default spins agree: front right
and rear left counter-clockwise seen from above."""


def default_spins(positions) -> tuple[float, ...]:
    """Yaw reaction signs for rotors at ``positions``: front right (x) or front (+) counter-clockwise,
    diagonal rotors alike, neighbours opposite."""
    ccw = {"front_right", "rear_left", "front", "rear"}
    return tuple(1.0 if p in ccw else -1.0 for p in positions)


@dataclass(frozen=True)
class Motors:
    """Four rotors (defaults: the Parrot Mambo of docs/model.md).

    Parameters
    ----------
    layout : {"x", "+"}
    arm_length : float
        m, centre to rotor axis.
    thrust_coefficient : float
        N/(rad/s)^2: rotor thrust ``f = k omega^2``.
    torque_coefficient : float
        N m of yaw reaction torque per N of rotor thrust.
    min_thrust, max_thrust : float
        N per rotor.
    time_constant : float or None
        s: each rotor's thrust follows its command through ``df/dt = (f_cmd - f) / tau``;
        None: instantaneous.
    """

    layout: str = "x"
    arm_length: float = 0.0624
    thrust_coefficient: float = 4.72e-8
    torque_coefficient: float = 0.00241
    min_thrust: float = 0.0
    max_thrust: float = 0.33
    time_constant: float | None = None
    order: tuple[str, ...] | None = None
    """Position of rotors 1-4 (``POSITIONS[layout]`` names); None: quadctl's clockwise order."""
    spins: tuple[float, ...] | None = None
    """Yaw reaction sign of rotors 1-4 (+1: counter-clockwise seen from above); None: :func:`default_spins`."""
    saturation: str = "prioritize"
    """``prioritize`` (roll and pitch, then thrust, yaw given up first: :func:`desaturate`) or ``clip``."""
    xy: tuple[tuple[float, float], ...] | None = None
    """Rotor positions ``(x, y)`` (m, body frame), rotor 1 first (``motors.positions``); None: from
    ``layout`` and ``arm_length``."""
    thrust_curve: tuple[float, float, float] | None = None
    """N: ``(c0, c1, c2)`` of each rotor's thrust ``c0 + c1 s + c2 s^2`` at the command fraction ``s``, its shape
    scaled to ``max_thrust`` at full command (``motors.thrust_curve``, :func:`thrust_curve_problem`,
    :func:`scaled_thrust_curve`); None: the flight stack's own curve."""

    @classmethod
    def from_config(cls, cfg) -> Motors:
        """From a :class:`quadctl.config.MotorsConfig` (its ``numbering`` and ``spin`` resolved)."""
        data = cfg.model_dump()
        numbering, spin = data.pop("numbering", "quadctl"), data.pop("spin", None)
        curve = data.pop("thrust_curve", None)
        data["thrust_curve"] = tuple(float(c) for c in curve) if curve is not None else None
        xy = data.pop("positions", None)
        if xy is not None:  # the geometry as built: the positions in the vehicle's order, spins given
            return cls(**data, spins=tuple(SPIN_SIGN[s] for s in spin),
                       xy=tuple((float(x), float(y)) for x, y in xy))
        order = tuple(numbering) if isinstance(numbering, list) else (
            POSITIONS[cfg.layout] if numbering == "quadctl" else NUMBERINGS[numbering])
        spins = tuple(SPIN_SIGN[s] for s in spin) if spin is not None else None
        if order == POSITIONS[cfg.layout] and spins is None:
            order = None  # quadctl's own numbering: the arrays exactly as they always were
        return cls(**data, order=order, spins=spins)

    def rotor_positions(self) -> tuple[str, ...]:
        """Names of the positions of rotors 1-4 (``front_right``, ...); ``(x, y)`` when given as positions."""
        if self.xy is not None:
            return tuple(f"({x:g}, {y:g})" for x, y in self.xy)
        return self.order if self.order is not None else POSITIONS[self.layout]

    def rotor_spins(self) -> tuple[float, ...]:
        """Yaw reaction sign of rotors 1-4 (+1: counter-clockwise seen from above)."""
        if self.spins is not None:
            return self.spins
        return SPINS if self.order is None else default_spins(self.order)

    def positions(self) -> np.ndarray:
        """(4, 2) rotor positions ``(x, y)`` in the body frame, m, rotor 1 first (the vehicle's numbering).

        The ``x`` and ``+`` layouts are shorthands: ``x`` puts each rotor at ``(+-L / sqrt 2, +-L / sqrt 2)``,
        ``+`` on the axes; ``motors.positions`` gives any other geometry (a stretched X).
        """
        if self.xy is not None:
            return np.array(self.xy, dtype=float)
        if self.layout == "x":
            d = self.arm_length / math.sqrt(2.0)
            at = {"front_right": [d, d], "rear_right": [-d, d], "rear_left": [-d, -d], "front_left": [d, -d]}
        elif self.layout == "+":
            L = self.arm_length
            at = {"front": [L, 0.0], "right": [0.0, L], "rear": [-L, 0.0], "left": [0.0, -L]}
        else:
            raise ArgumentError(f"Motors: layout must be 'x' or '+', got {self.layout!r}; give xy (the rotor "
                                "positions) for any other geometry")
        return np.array([at[p] for p in self.rotor_positions()])

    def effectiveness(self) -> np.ndarray:
        """``M`` (4, 4): ``[T, A, E, R] = M f`` for rotor thrusts ``f`` (N), rotor 1 first."""
        pos = self.positions()
        return np.array([np.ones(4), -pos[:, 1], pos[:, 0], np.array(self.rotor_spins()) * self.torque_coefficient])

    def mixer(self) -> np.ndarray:
        """``M^-1`` (4, 4): rotor thrusts from ``[T, A, E, R]``; the one mixer every consumer takes
        (through :func:`actuators_of`: the simulated loop, the lanes, the C export, margins, reports)."""
        return np.linalg.inv(self.effectiveness())

    def describe(self) -> str:
        """The geometry in a few words: the preset and its arm, or the rotor positions."""
        if self.xy is None:
            return f"{self.layout} layout, arm {self.arm_length:g} m"
        return "rotors at " + ", ".join(f"({x:g}, {y:g})" for x, y in self.xy) + " m"

    def speed(self, thrust) -> np.ndarray:
        """Rotor speed (rad/s) for rotor thrust (N): ``sqrt(f / k)``."""
        return np.sqrt(np.maximum(np.asarray(thrust, dtype=float), 0.0) / self.thrust_coefficient)


UNBOUNDED = 1e30
"""N m: the yaw bound of a rotor that gives no yaw torque (a finite stand-in for infinity, which the generated
C has no literal for; inside single precision, far past any torque)."""
PARALLEL_RTOL = 1e-9
"""Two of the yaw bounds in :func:`desaturate` are parallel (rotors turning alike) when their slopes differ by
less than this, relative: their difference is then round-off, and dividing by it would throw the thrust away."""
SATURATION_RULES = ("prioritize", "clip")
"""``motors.saturation``: how a command the rotors cannot produce is brought inside their limits."""

THRUST_CURVE_RISES_FROM = 0.1
"""Command fraction from which a thrust curve must rise to full command (slope ``c1 + 2 c2 s > 0``):
a falling curve turns the cascade's feedback over. Below it a fit of flight data (hover near
0.5) may curl: the identified Crazyflie curve has its least thrust at s = 0.04, 0.14 % of full thrust
below ``c0``. No steady flight holds a rotor there (the Crazyflie cascade's least collective command is
``thrust_min``, 20000 PWM, 0.31), only a torque's transient passes through."""


def thrust_curve_problem(curve) -> str | None:
    """Why ``curve`` ``(c0, c1, c2)`` (N) is not the shape of a rotor's thrust curve, or None: a coefficient
    not finite, no thrust at full command (``c0 + c1 + c2``, which ``motors.max_thrust`` scales to its own), or
    a slope ``c1 + 2 c2 s`` not positive somewhere on ``[THRUST_CURVE_RISES_FROM, 1]`` (linear in ``s``:
    checked at both ends). The sentence ends with the fix.

    Examples
    --------
    >>> thrust_curve_problem((0.0224, -0.0098, 0.1256)) is None
    True
    >>> thrust_curve_problem((0.1, 0.05, -0.1)).split(":")[0]
    'its slope c1 + 2 c2 s is -0.15 N at s = 1'
    """
    c0, c1, c2 = (float(c) for c in curve)
    if not all(math.isfinite(c) for c in (c0, c1, c2)):
        return "each coefficient must be a finite number of N: [c0, c1, c2] of thrust = c0 + c1 s + c2 s^2"
    s = THRUST_CURVE_RISES_FROM
    low, high = c1 + 2 * c2 * s, c1 + 2 * c2
    if not (low > 0 and high > 0):
        where = s if low <= 0 else 1.0
        return (f"its slope c1 + 2 c2 s is {min(low, high):.4g} N at s = {where:g}: the thrust must rise with the "
                f"command from s = {s:g} to 1, else the feedback turns over; check the order [c0, c1, c2], each in N")
    if not c0 + c1 + c2 > 0:
        return (f"its thrust at full command, c0 + c1 + c2 = {c0 + c1 + c2:.4g} N, is not positive: there is no "
                "curve to scale to motors.max_thrust; check the order [c0, c1, c2], each in N")
    return None


def scaled_thrust_curve(curve, max_thrust: float) -> np.ndarray:
    """(3,) N: the thrust curve ``curve`` ``(c0, c1, c2)`` scaled so that its thrust at full command is
    ``max_thrust``: ``motors.thrust_curve`` gives the shape, ``motors.max_thrust`` the one full-command thrust
    (as the flight stack's own curve is scaled to it). Identify writes both, the curve's sum as max_thrust.

    Examples
    --------
    >>> scaled_thrust_curve((0.02, 0.0, 0.1), 0.24)
    array([0.04, 0.  , 0.2 ])
    """
    c = np.asarray(curve, dtype=float)
    return c * (float(max_thrust) / float(c.sum()))


class _Ops:
    """min, max and select, elementwise, of numpy or of CasADi (one rule for both)."""

    def __init__(self, lib):
        if lib is np:
            self.min, self.max, self.where = np.minimum, np.maximum, np.where
        else:
            self.min, self.max, self.where = lib.fmin, lib.fmax, lib.if_else


def desaturate(cmd, mix, lo, hi, lib=np):
    """The command ``[T, A, E, R]`` brought inside the rotors' limits by priority: roll and pitch torques
    kept, then collective thrust, yaw given up first.

    Parameters
    ----------
    cmd : (4,) array or CasADi column
        Commanded ``[T, A, E, R]`` (N, N m x3).
    mix : (4, 4) array or CasADi matrix
        The mixer ``M^-1`` (rotor thrusts from ``[T, A, E, R]``); its thrust column must be positive
        (the centre of mass inside the rotors).
    lo, hi : (4,) array or CasADi column
        N, each rotor's thrust limits.
    lib : module
        ``numpy`` or ``casadi``: the same rule builds the simulated loop's expressions (and so the lanes'
        and the exported C's code) and evaluates on arrays.

    Returns
    -------
    u : (4,) array or CasADi column
        ``[T', A', E', R']``:

        1. ``A' = s A, E' = s E`` with ``s`` the largest in ``[0, 1]`` for which some thrust fits them with
           no yaw torque (no yaw is invented to make room);
        2. ``T'`` the thrust closest to ``T`` for which some yaw torque between 0 and ``R`` fits ``T', A', E'``;
        3. ``R'`` the yaw torque closest to ``R`` that fits ``T', A', E'`` (between 0 and ``R``: yaw is given
           up towards zero, never reversed or amplified).

        A command the rotors can produce is returned unchanged where the largest spread of roll and pitch
        thrusts lies between rotors that turn alike (every x, stretched x and + geometry).

    Notes
    -----
    Rotor ``i``'s thrust is ``c_i T + g_i + r_i R`` with ``c, a, e, r`` the mixer's columns and
    ``g_i = a_i A + e_i E``. Step 1: a thrust fits ``s g`` when ``(lo_i - s g_i) / c_i <= (hi_j - s g_j) / c_j``
    for every pair, so ``s`` is the least of 1 and ``(hi_j / c_j - lo_i / c_i) / (g_i / c_i - g_j / c_j)`` over
    the pairs whose denominator is positive. Step 2 eliminates ``R`` (Fourier-Motzkin): each rotor bounds
    ``R`` from below and above by a line in ``T``, as do 0 and ``R``; every lower bound below every upper
    bound is an interval of ``T``.
    """
    ops = _Ops(lib)
    n = 4
    T, A, E, R = cmd[0], cmd[1], cmd[2], cmd[3]
    c = [mix[i, 0] for i in range(n)]
    r = [mix[i, 3] for i in range(n)]
    g = [mix[i, 1] * A + mix[i, 2] * E for i in range(n)]
    s = 1.0
    for i in range(n):
        for j in range(n):
            if i != j:
                den = g[i] / c[i] - g[j] / c[j]
                bound = (hi[j] / c[j] - lo[i] / c[i]) / ops.where(den > 0, den, 1.0)
                s = ops.min(s, ops.where(den > 0, ops.max(bound, 0.0), 1.0))
    A2, E2 = s * A, s * E
    g = [mix[i, 1] * A2 + mix[i, 2] * E2 for i in range(n)]
    r0, r1 = ops.min(R, 0.0), ops.max(R, 0.0)
    # R >= alpha + beta T (lowers), R <= gamma + delta T (uppers); a rotor without yaw bounds T directly
    lowers, uppers = [(r0, 0.0)], [(r1, 0.0)]
    t_lo, t_hi = -UNBOUNDED, UNBOUNDED
    for i in range(n):
        pos, neg, none = r[i] > 0, r[i] < 0, r[i] == 0
        safe = ops.where(none, 1.0, r[i])
        slope = ops.where(none, 0.0, -c[i] / safe)
        at_lo, at_hi = (lo[i] - g[i]) / safe, (hi[i] - g[i]) / safe
        lowers.append((ops.where(pos, at_lo, ops.where(neg, at_hi, -UNBOUNDED)), slope))
        uppers.append((ops.where(pos, at_hi, ops.where(neg, at_lo, UNBOUNDED)), slope))
        t_lo = ops.max(t_lo, ops.where(none, (lo[i] - g[i]) / c[i], -UNBOUNDED))
        t_hi = ops.min(t_hi, ops.where(none, (hi[i] - g[i]) / c[i], UNBOUNDED))
    for alpha, beta in lowers:
        for gamma, delta in uppers:
            k, rhs = beta - delta, gamma - alpha  # alpha + beta T <= gamma + delta T  <=>  k T <= rhs
            flat = PARALLEL_RTOL * (ops.max(beta, -beta) + ops.max(delta, -delta))
            bound = rhs / ops.where(k > flat, k, ops.where(k < -flat, k, 1.0))
            t_hi = ops.min(t_hi, ops.where(k > flat, bound, UNBOUNDED))
            t_lo = ops.max(t_lo, ops.where(k < -flat, bound, -UNBOUNDED))
    T2 = ops.min(ops.max(T, t_lo), t_hi)
    # the yaw torques that fit T2 meet the segment [0, R] (step 2 chose T2 so): the one closest to R is in it.
    # Not clamped to the segment itself, whose ends tie at R = 0 and would blur the law's derivative there.
    y_lo, y_hi = -UNBOUNDED, UNBOUNDED
    for (alpha, beta), (gamma, delta) in zip(lowers[1:], uppers[1:]):
        y_lo = ops.max(y_lo, alpha + beta * T2)
        y_hi = ops.min(y_hi, gamma + delta * T2)
    R2 = ops.min(ops.max(R, y_lo), y_hi)
    if lib is np:
        return np.array([T2, A2, E2, R2], dtype=float)
    return lib.vertcat(T2, A2, E2, R2)


@dataclass(frozen=True)
class Actuators:
    """What the simulation clips: rotor thrusts (``motors``) or the inputs themselves (``box``).

    Attributes
    ----------
    mode : {"motors", "box"}
    names : tuple of str
        ``rotor 1``... or the input names.
    mix : (4, 4) ndarray
        ``[T, A, E, R]`` -> actuator commands (identity for box).
    mix_inv : (4, 4) ndarray
    lo, hi : (4,) ndarray
        Actuator limits (N per rotor, or N / N m; infinite where unlimited).
    motors : Motors or None
    priority : bool
        Rotor saturation by priority (:func:`desaturate`, ``motors.saturation: prioritize``); else each
        rotor clipped and mixed back.
    """

    mode: str
    names: tuple[str, ...]
    mix: np.ndarray
    mix_inv: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    motors: Motors | None = None
    priority: bool = False

    def commands(self, u) -> np.ndarray:
        """Actuator commands (..., 4) for inputs ``u`` (..., 4)."""
        return np.asarray(u, dtype=float) @ self.mix.T

    def at_limit(self, u) -> np.ndarray:
        """(..., 4) bool: actuator at (or beyond) a limit for inputs ``u``."""
        act = self.commands(u)
        tol_lo = SATURATED_RTOL * (1.0 + np.abs(np.where(np.isfinite(self.lo), self.lo, 0.0)))
        tol_hi = SATURATED_RTOL * (1.0 + np.abs(np.where(np.isfinite(self.hi), self.hi, 0.0)))
        return (act <= self.lo + tol_lo) | (act >= self.hi - tol_hi)


def has_rotors(actuators: Actuators | None) -> bool:
    """``actuators`` are rotors (``motors:``): what a PID cascade commands, and rotor thrusts to read."""
    return actuators is not None and actuators.mode == "motors"


def actuators_of(motors: Motors | None = None, limits: dict | None = None) -> Actuators | None:
    """The actuators of a config: rotors, box limits on named inputs, or None (unlimited)."""
    if motors is not None:
        mix = motors.mixer()
        return Actuators(mode="motors", names=tuple(f"rotor {i + 1}" for i in range(4)), mix=mix,
                         mix_inv=motors.effectiveness(), lo=np.full(4, motors.min_thrust),
                         hi=np.full(4, motors.max_thrust), motors=motors,
                         priority=motors.saturation == "prioritize")
    if limits:
        lo, hi = np.full(N_INPUTS, -np.inf), np.full(N_INPUTS, np.inf)
        for name, (low, high) in limits.items():
            lo[INPUT_INDEX[name]], hi[INPUT_INDEX[name]] = low, high
        return Actuators(mode="box", names=INPUT_NAMES, mix=np.eye(N_INPUTS), mix_inv=np.eye(N_INPUTS),
                         lo=lo, hi=hi)
    return None


def check_trim(actuators: Actuators | None, u_trim) -> None:
    """Raise ActuatorLimitError (a ConfigError) when the trim itself is outside the actuator
    limits (no flight possible); the message names the limit's key, its value and the fix."""
    if actuators is None:
        return
    act = actuators.commands(u_trim)
    for i, name in enumerate(actuators.names):
        lo, hi = actuators.lo[i], actuators.hi[i]
        if lo <= act[i] <= hi:
            continue
        above = act[i] > hi
        if actuators.mode == "motors":
            key, unit = ("motors.max_thrust" if above else "motors.min_thrust"), "N"
            value = f"{hi if above else lo:.4g}"
            fix = f"{'raise' if above else 'lower'} {key} {'above' if above else 'below'} {act[i]:.4g} N"
        else:
            key, unit = f"limits.{name}", INPUT_UNITS[name]
            value = f"[{lo:.4g}, {hi:.4g}]"
            fix = f"widen {key} to include {act[i]:.4g} {unit}"
        raise ActuatorLimitError(
            f"{key} = {value}: the trim needs {name} = {act[i]:.4g} {unit}, outside the limits "
            f"[{lo:.4g}, {hi:.4g}] {unit}, so the vehicle cannot hold this flight condition; {fix}, "
            "or trim for a slower or lighter flight")


def headroom(actuators: Actuators, u_trim) -> dict[str, tuple[float, float]]:
    """Per input, how far it can move down and up from the trim, the others held at trim.

    Returns
    -------
    dict
        ``input name -> (down, up)``, both >= 0 (N or N m; inf when unlimited).
    """
    base = actuators.commands(u_trim)
    out = {}
    for j, name in enumerate(INPUT_NAMES):
        col = actuators.mix[:, j]
        up, down = math.inf, math.inf
        for i in range(len(base)):
            if col[i] > 0:
                up = min(up, (actuators.hi[i] - base[i]) / col[i])
                down = min(down, (base[i] - actuators.lo[i]) / col[i])
            elif col[i] < 0:
                up = min(up, (base[i] - actuators.lo[i]) / -col[i])
                down = min(down, (actuators.hi[i] - base[i]) / -col[i])
        out[name] = (max(down, 0.0), max(up, 0.0))
    return out


def saturation_fraction(actuators: Actuators, u) -> dict[str, float]:
    """Fraction of the recorded samples each actuator spends at a limit.

    ``u`` are the applied (already clipped) inputs of a run, (N, 4); clipping leaves a
    saturated actuator exactly at its limit, so this needs no record of the commands.
    """
    at = actuators.at_limit(np.atleast_2d(u))
    return {name: float(at[:, i].mean()) for i, name in enumerate(actuators.names)}


def require_within_limits(fractions: dict[str, float] | None, mode: str | None, *,
                          allowed: bool = False) -> None:
    """Raise :class:`~quadctl.errors.SaturationFailed` (exit 1) when an actuator is at a limit more than
    :data:`SATURATION_FAIL` of the run, unless ``allowed`` (``--allow-saturation``, ``allow: [saturation]``).

    Parameters
    ----------
    fractions : dict or None
        Actuator name -> fraction of the run at a limit (:func:`saturation_fraction`); None: no actuators.
    mode : {"motors", "box"} or None
        The :attr:`Actuators.mode` that clipped: the message names its key (``motors.max_thrust``, or the
        box of the input at its limit, ``limits.R``).
    """
    if not fractions or allowed:
        return
    worst = max(fractions, key=fractions.get)
    if fractions[worst] <= SATURATION_FAIL:
        return
    really = ("give the rotors the thrust they really have (motors.max_thrust)" if mode == "motors" else
              f"give {worst} the range the vehicle really has (limits.{worst})")
    raise SaturationFailed(
        f"the design saturates: {worst} is at a limit {fractions[worst] * 100:.3g} % of the run, more than "
        f"{SATURATION_FAIL * 100:g} %, so it flies its limits, not the design; lower the gains "
        f"(larger lqr R) or the initial offset, or {really}; "
        "--allow-saturation (or allow: [saturation] in the config) accepts it")


def saturates(fractions: dict[str, float]) -> bool:
    """True when some actuator is at a limit more than ``SATURATION_FLAG`` of the time."""
    return any(f > SATURATION_FLAG for f in fractions.values())
