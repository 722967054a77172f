"""References to fly: setpoint steps and waypoint missions, as flat outputs of time.

A reference is a path of the flat outputs, position ``p(t)`` (NED, m) and yaw ``psi(t)`` (rad), with
their derivatives up to snap and yaw acceleration, made of :class:`Piece`\\ s (a rest-to-rest shape of
:data:`SHAPES`, or a step): :func:`setpoint_reference` and :func:`mission_reference` build it,
:mod:`quadctl.physics.flatness` turns it into the state and input the controller flies. See
docs/guide/missions.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np

SHAPES: dict[str, tuple[float, ...]] = {
    "minimum-jerk": (0.0, 0.0, 0.0, 10.0, -15.0, 6.0),
    "minimum-snap": (0.0, 0.0, 0.0, 0.0, 35.0, -84.0, 70.0, -20.0),
}
"""Rest-to-rest shapes ``s(tau)``, polynomial coefficients in ascending powers: the quintic of least
integrated squared jerk and the septic of least integrated squared snap between rest states."""
TRAJECTORIES = ("minimum-jerk", "minimum-snap", "step")
"""``simulation.reference.trajectory`` values (``step``: the reference jumps to each waypoint)."""
YAW_RATE = 1.0
"""rad/s: the peak yaw rate of a waypoint leg (a leg that only turns lasts ``peak |dpsi| / YAW_RATE``)."""
ORDER = 5
"""Derivatives of position a path gives (0 to 4: position to snap)."""
ROUNDOFF = 1e-12
"""A shape's ``tau`` this close to its ends counts as on them: a leg evaluated at its end, ``t0 + T``
rounded, gives the limit asked for."""


def shape_derivatives(kind: str, tau, left: bool = False) -> np.ndarray:
    """``(5, n)``: ``s, s', s'', s''', s''''`` of the shape ``kind`` at ``tau`` (clipped to [0, 1]),
    the derivatives zero before it and from its end on (``left``: only after its end: at ``tau = 1``
    the limit from the left); within :data:`ROUNDOFF` of an end counts as on it.

    A ``step`` is 0 before ``tau = 0`` and 1 from it on, with zero derivatives.
    """
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    out = np.zeros((ORDER, tau.size))
    if kind == "step":
        out[0] = (tau >= 0).astype(float)
        return out
    clipped = np.clip(tau, 0.0, 1.0)
    for k, coef in enumerate(_derivatives(kind)):
        out[k] = np.polynomial.polynomial.polyval(clipped, coef)
    last = 1.0 + ROUNDOFF if left else 1.0 - ROUNDOFF  # the shape's end, taken from the left or the right
    end = tau > last
    out[1:, (tau < -ROUNDOFF) | end] = 0.0
    return out


@cache
def _derivatives(kind: str) -> tuple[np.ndarray, ...]:
    """The coefficients (ascending powers) of the shape ``kind``'s ``s`` and its first :data:`ORDER` - 1
    derivatives."""
    out = [np.asarray(SHAPES[kind], dtype=float)]
    for _ in range(ORDER - 1):
        out.append(np.polynomial.polynomial.polyder(out[-1]))
    return tuple(out)


def peak_rate(kind: str) -> float:
    """``max s'`` of a shape (at ``tau = 1/2`` by symmetry; 1 for a step): a leg's peak speed over its average."""
    return 1.0 if kind == "step" else float(np.polynomial.Polynomial(SHAPES[kind]).deriv()(0.5))


@dataclass(frozen=True)
class Piece:
    """One piece of a path from ``t0`` (s) on (see the module's formula); ``T`` s (0: a step)."""

    t0: float
    p0: tuple[float, float, float]
    v0: tuple[float, float, float]
    dp: tuple[float, float, float]
    psi0: float
    dpsi: float
    T: float
    shape: str


@dataclass(frozen=True)
class FlatPath:
    """Flat outputs sampled at ``n`` times.

    Attributes
    ----------
    t : (n,) ndarray, s
    position : (5, n, 3) ndarray
        Position and its derivatives (m, m/s, m/s^2, m/s^3, m/s^4), NED.
    yaw : (3, n) ndarray
        Yaw and its rate and acceleration (rad, rad/s, rad/s^2).
    """

    t: np.ndarray
    position: np.ndarray
    yaw: np.ndarray


@dataclass(frozen=True)
class Leg:
    """A waypoint leg: flown from ``start`` to ``end`` (s), then held until ``end + hold``."""

    start: float
    end: float
    hold: float
    position: tuple[float, float, float]
    yaw: float


@dataclass(frozen=True)
class Reference:
    """A path of pieces (:class:`Piece`, in time order) and, for a mission, its legs and tolerance (m)."""

    pieces: tuple[Piece, ...]
    legs: tuple[Leg, ...] = ()
    tolerance: float | None = None
    velocity_keys: tuple[str, ...] = ()
    """Setpoints: for each piece, the config key whose velocity it flies (``trim.velocity_ned`` until a
    setpoint gives one), for a refusal to name."""

    def remedy(self, t: float) -> str:
        """What to change in the config so that the vehicle can fly the path at ``t`` s (a refusal's fix):
        a setpoint's velocity, or a mission's speed and spacing."""
        if self.legs or not self.velocity_keys:
            return "lower simulation.reference.speed or space the waypoints further apart"
        starts = np.array([p.t0 for p in self.pieces])
        k = int(np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(self.pieces) - 1))
        return f"lower {self.velocity_keys[k]}: no attitude holds that velocity against the rotor drag"

    def flat(self, t, left=False) -> FlatPath:
        """The flat outputs at the times ``t`` (s), or where ``left`` ((n,) bool, or one for all) their
        limits from the left: at a piece's start the piece before it, at a shaped piece's end
        (:attr:`knots`) its shape's derivatives there rather than the held zeros."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        left = np.broadcast_to(np.asarray(left, dtype=bool), t.shape)
        starts = np.array([p.t0 for p in self.pieces])
        which = np.clip(np.where(left, np.searchsorted(starts, t, side="left"),
                                 np.searchsorted(starts, t, side="right")) - 1, 0, len(self.pieces) - 1)
        pos = np.zeros((ORDER, t.size, 3))
        yaw = np.zeros((3, t.size))
        for i, piece in enumerate(self.pieces):
            sel = which == i
            for side in (False, True):
                on = sel & (left == side)
                if on.any():
                    pos[:, on], yaw[:, on] = _piece_outputs(piece, t[on], side)
        return FlatPath(t=t, position=pos, yaw=yaw)

    @property
    def jumps(self) -> tuple[float, ...]:
        """s: the times after 0 at which the path's position, velocity, acceleration, yaw, yaw rate or
        yaw acceleration step (a setpoint, a step leg): where the feedforward jumps and the loop is
        kicked; a shaped leg's ends, where only jerk and snap change, are not among them."""
        out = []
        for before, piece in zip(self.pieces, self.pieces[1:]):
            t = np.array([piece.t0])
            (p0, y0), (p1, y1) = _piece_outputs(before, t), _piece_outputs(piece, t)
            if not (np.allclose(p0[:3], p1[:3], rtol=0, atol=1e-12) and np.allclose(y0, y1, rtol=0, atol=1e-12)):
                out.append(piece.t0)
        return tuple(out)

    @property
    def knots(self) -> np.ndarray:
        """s: the times after 0 at which the path's derivatives may step (increasing): each piece's
        start and each shaped piece's end (a leg's end, where its snap steps, and with it the
        feedforward's torques and the slope of the body rates): an expansion of the path on one side
        of a knot must not be used on the other."""
        ends = [p.t0 + p.T for p in self.pieces if p.T > 0] + [p.t0 for p in self.pieces]
        return np.unique(np.array([t for t in ends if t > 0], dtype=float))

    @property
    def end(self) -> float:
        """s: when the last leg reaches its waypoint (0 without legs)."""
        return self.legs[-1].end if self.legs else 0.0


def _piece_outputs(piece: Piece, t, left: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(position (5, n, 3), yaw (3, n))`` of ``piece`` at the times ``t`` (n,) s (its shape held at
    its ends outside ``[t0, t0 + T]``; ``left``: at its end, the limit from the left)."""
    dt = np.asarray(t, dtype=float) - piece.t0
    if piece.T > 0:
        s = shape_derivatives(piece.shape, dt / piece.T, left) / piece.T ** np.arange(ORDER)[:, None]
    else:
        s = shape_derivatives("step", dt)
    pos = s[:, :, None] * np.asarray(piece.dp)
    pos[0] += np.asarray(piece.p0) + np.outer(dt, piece.v0)
    pos[1] += np.asarray(piece.v0)
    yaw = s[:3] * piece.dpsi
    yaw[0] += piece.psi0
    return pos, yaw


def setpoint_reference(setpoints, position0, velocity0, yaw0: float) -> Reference:
    """The steps of ``setpoints`` (dicts with ``t`` and any of ``position``, ``velocity``, ``yaw``;
    ``t`` increasing) from the trim's ``position0``, ``velocity0`` (m, m/s, NED) and ``yaw0`` (rad)."""
    p, v, psi, t_last = np.asarray(position0, float), np.asarray(velocity0, float), float(yaw0), 0.0
    pieces, keys, key = [], [], "trim.velocity_ned"
    if not setpoints or setpoints[0]["t"] > 0:
        pieces.append(Piece(0.0, tuple(p), tuple(v), (0.0, 0.0, 0.0), psi, 0.0, 0.0, "step"))
        keys.append(key)
    for i, sp in enumerate(setpoints):
        t = float(sp["t"])
        p = p + v * (t - t_last)
        if sp.get("position") is not None:
            p = np.asarray(sp["position"], float)
        if sp.get("velocity") is not None:
            v = np.asarray(sp["velocity"], float)
            key = f"simulation.reference.setpoints[{i}].velocity"
        if sp.get("yaw") is not None:
            psi = float(sp["yaw"])
        pieces.append(Piece(t, tuple(p), tuple(v), (0.0, 0.0, 0.0), psi, 0.0, 0.0, "step"))
        keys.append(key)
        t_last = t
    return Reference(tuple(pieces), velocity_keys=tuple(keys))


def mission_reference(waypoints, position0, yaw0: float, speed: float, tolerance: float,
                      trajectory: str = "minimum-jerk") -> Reference:
    """The mission through ``waypoints`` (dicts with ``position``, optional ``yaw`` (default: the
    previous) and ``hold`` (s, default 0)) from ``position0`` (m) and ``yaw0`` (rad) at ``t = 0``,
    legs at peak speed ``speed`` (m/s) shaped by ``trajectory`` (:data:`TRAJECTORIES`)."""
    peak = peak_rate(trajectory)
    p, psi, t = np.asarray(position0, float), float(yaw0), 0.0
    pieces, legs = [], []
    for wp in waypoints:
        target = np.asarray(wp["position"], float)
        yaw = psi if wp.get("yaw") is None else float(wp["yaw"])
        T = max(peak * float(np.linalg.norm(target - p)) / speed, peak * abs(yaw - psi) / YAW_RATE)
        shape = "step" if trajectory == "step" else trajectory
        pieces.append(Piece(t, tuple(p), (0.0, 0.0, 0.0), tuple(target - p), psi, yaw - psi,
                            0.0 if shape == "step" else T, shape))
        hold = float(wp.get("hold") or 0.0)
        legs.append(Leg(start=t, end=t + T, hold=hold, position=tuple(target), yaw=yaw))
        p, psi, t = target, yaw, t + T + hold
    return Reference(tuple(pieces), tuple(legs), tolerance)


def waypoint_times(ref: Reference, t, position) -> list[float | None]:
    """Per leg, the first time (s) from its start that ``position`` ((n, 3) m at times ``t``) is
    within the tolerance of its waypoint, and not before the last waypoint reached; None: never."""
    return [a.reached for a in waypoint_approaches(ref, t, position)]


@dataclass(frozen=True)
class Approach:
    """How a flown path met one waypoint, over the span it is sought in (from its leg's start, and
    not before the waypoint before it was reached): ``reached`` the first time (s) within the
    tolerance (None: never), ``closest`` the least distance (m) and ``closest_at`` when (s); both
    None when the span is empty (the run ended first)."""

    reached: float | None
    closest: float | None
    closest_at: float | None


def waypoint_approaches(ref: Reference, t, position) -> list[Approach]:
    """Per leg of ``ref``, how ``position`` ((n, 3) m at the times ``t``, s) met its waypoint
    (:class:`Approach`)."""
    t = np.asarray(t, float)
    position = np.asarray(position, float)
    out: list[Approach] = []
    after = -math.inf
    for leg in ref.legs:
        dist = np.linalg.norm(position - np.asarray(leg.position), axis=1)
        span = np.nonzero((t >= leg.start) & (t >= after))[0]
        if not span.size:
            out.append(Approach(None, None, None))
            continue
        hit = span[dist[span] <= ref.tolerance]
        nearest = span[np.argmin(dist[span])]
        out.append(Approach(float(t[hit[0]]) if hit.size else None, float(dist[nearest]), float(t[nearest])))
        after = out[-1].reached if out[-1].reached is not None else after
    return out
