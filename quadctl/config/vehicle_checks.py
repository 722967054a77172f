"""The checks that a config describes a vehicle that can exist: its inertia and its rotors.

:func:`quadctl.config.checks.check_semantics` runs them on every validated config. A value that no
rigid body or no working rotor layout could have is a typo, a swapped or mis-scaled entry: each is
one :class:`~quadctl.errors.ConfigError` line (by the ``fail`` the caller passes) naming the key path,
the value and the fix. What is merely unusual is warned about instead (:mod:`quadctl.config.notices`).
"""

from __future__ import annotations

from quadctl.config.describe import UNION_HINTS
from quadctl.config.schema import Config
from quadctl.config.vehicle_schema import INERTIA_DESCRIPTION, MotorsConfig
from quadctl.config.weights import DEFINITENESS_RTOL, SYMMETRY_RTOL
from quadctl.physics.motors import NUMBERINGS, POSITIONS, Motors, thrust_curve_problem
from quadctl.text.messages import unknown as _unknown

INERTIA_TRIANGLE_RTOL = 0.10
"""Slack on the triangle inequality of the principal moments of inertia. Measured inertias
(pendulum tests, CAD) carry errors of a few percent: the report's Mambo itself has
Jxx + Jyy = 0.979 Jzz, 2 % under the bound. 10 % takes measurement error, not a swapped axis."""


def check_inertia(cfg: Config, fail) -> None:
    """Refuse an impossible inertia: a shape other than 3 values or 3 x 3, a tensor that is not
    symmetric positive definite, or principal moments that break the triangle inequality.

    For any rigid body ``Jxx + Jyy >= Jzz`` (and the same for each axis: ``Jzz`` is the integral of
    ``x^2 + y^2`` dm, ``Jxx + Jyy`` that of ``x^2 + y^2 + 2 z^2``); for a full tensor the principal
    moments (its eigenvalues) obey it. A vehicle that breaks it by more than
    :data:`INERTIA_TRIANGLE_RTOL` does not exist: the values are a typo, a swapped or mis-scaled
    entry, and a design for them is a design for no vehicle, so it is refused (exit 2). Everything
    merely unusual (a heavy, long-armed, tall vehicle) is only warned about, by :func:`quadctl.config.notices.notices`.
    """
    for path, inertia in (("vehicle.inertia", cfg.vehicle.inertia),
                          ("simulation.plant.inertia", cfg.simulation.plant and cfg.simulation.plant.inertia)):
        if inertia:
            _check_one(path, inertia, fail)


def _check_one(path: str, inertia: list, fail) -> None:
    import numpy as np

    nested = isinstance(inertia[0], list)
    if nested and (len(inertia) != 3 or any(not isinstance(row, list) or len(row) != 3 for row in inertia)) \
            or not nested and (len(inertia) != 3 or any(isinstance(v, list) for v in inertia)):

        fail(path, inertia, UNION_HINTS["inertia"])
    if not nested:
        for k, value in enumerate(inertia):
            if not value > 0:
                fail(f"{path}[{k}]", value, f"must be greater than 0 ({INERTIA_DESCRIPTION})")
        principal, axes = list(inertia), ("Jxx", "Jyy", "Jzz")
        hint = "check the order [Jxx, Jyy, Jzz] and that all three are in kg m^2"
    else:
        tensor = np.array(inertia, dtype=float)
        scale = float(np.abs(tensor).max())
        for i, j in ((0, 1), (0, 2), (1, 2)):
            if abs(tensor[i, j] - tensor[j, i]) > SYMMETRY_RTOL * scale:
                fail(path, inertia, f"not symmetric: {path}[{i}][{j}] = {tensor[i, j]:g} but {path}[{j}][{i}] = "
                     f"{tensor[j, i]:g}; an inertia tensor equals its transpose: give both the same value")
        for k in range(3):
            if not tensor[k, k] > 0:
                fail(f"{path}[{k}][{k}]", inertia[k][k], "a moment of inertia must be greater than 0 (kg m^2)")
        principal = [float(v) for v in np.linalg.eigvalsh(tensor)]
        if principal[0] <= DEFINITENESS_RTOL * principal[-1]:
            fail(path, inertia, f"not positive definite (smallest principal moment {principal[0]:.4g} kg m^2): the "
                 "products of inertia are too large for the moments; check their units (kg m^2) and signs "
                 "(the tensor's entry is Jxy = -integral of x y dm)")
        axes = ("J1", "J2", "J3")
        hint = "check the products of inertia and that every entry is in kg m^2"
    for k, axis in enumerate(axes):
        others = sum(principal) - principal[k]
        if others < principal[k] * (1 - INERTIA_TRIANGLE_RTOL):
            names = " + ".join(a for a in axes if a != axis)
            what = "" if not nested else "the principal moments "
            fail(path, inertia, f"no rigid body has {what}{names} = {others:.4g} below {axis} = {principal[k]:.4g} "
                 f"kg m^2 (the moments of inertia obey {names} >= {axis}); {hint}")


def check_rotors(motors: MotorsConfig, fail) -> None:
    """``motors.numbering``: each of the layout's positions once (a preset names a quad-x order);
    ``motors.spin``: diagonal rotors alike, neighbours opposite (else yaw is not separable from roll
    and pitch: the mixer is singular)."""

    if motors.positions is not None:
        _check_positions(motors, fail)
        return
    allowed = POSITIONS[motors.layout]
    numbering = motors.numbering
    if isinstance(numbering, str):
        if numbering != "quadctl" and motors.layout != "x":
            fail("motors.numbering", numbering, f"{numbering} is a quad-x order; for layout + give the 4 positions, "
                 f"rotor 1 first ({', '.join(allowed)})")
        order = allowed if numbering == "quadctl" else NUMBERINGS[numbering]
    else:
        for i, where in enumerate(numbering):
            if where not in allowed:
                fail(f"motors.numbering[{i}]", where,
                     _unknown(where, allowed, f"rotor position of layout {motors.layout}"))
        if len(numbering) != 4 or len(set(numbering)) != 4:
            fail("motors.numbering", numbering, f"must name each of the 4 positions once, rotor 1 first: "
                 f"{', '.join(allowed)} in the vehicle's order")
        order = tuple(numbering)
    if motors.spin is not None:
        spin = dict(zip(order, motors.spin))
        first, diagonal, *_ = ("front_right", "rear_left", "rear_right", "front_left") if motors.layout == "x" \
            else ("front", "rear", "right", "left")
        others = [p for p in allowed if p not in (first, diagonal)]
        if spin[first] != spin[diagonal] or any(spin[p] == spin[first] for p in others):
            fail("motors.spin", motors.spin, f"diagonal rotors must turn alike and neighbours opposite ({first} and "
                 f"{diagonal} one way, {' and '.join(others)} the other), else yaw cannot be told from roll and pitch; "
                 "check the order against motors.numbering")


def check_thrust_curve(motors: MotorsConfig, fail) -> None:
    """``motors.thrust_curve``: it rises with the command, and has a thrust at full command to scale to
    ``motors.max_thrust`` (:func:`quadctl.physics.motors.thrust_curve_problem`)."""
    if motors.thrust_curve is not None:
        problem = thrust_curve_problem(motors.thrust_curve)
        if problem:
            fail("motors.thrust_curve", motors.thrust_curve, problem)


MIXER_RCOND = 1e-6
"""The rotors' effectiveness matrix (thrust, roll, pitch and yaw from the four thrusts, each row scaled to its
largest entry) must have a reciprocal condition number above this: below, one axis (yaw, usually: spins that
are not alternate) cannot be commanded apart from the others and the mixer's thrusts run to infinity."""


def _check_positions(motors: MotorsConfig, fail) -> None:
    """``motors.positions``: given with the spins, in the vehicle's own order (no preset numbering), and a
    geometry that commands thrust, roll, pitch and yaw independently."""
    import numpy as np

    if motors.spin is None:
        fail("motors.spin", None, "motors.positions needs each rotor's turning direction, rotor 1 first: "
             "spin: [ccw, cw, ccw, cw] (seen from above; diagonal rotors alike)")
    if motors.numbering != "quadctl":
        fail("motors.numbering", motors.numbering, "motors.positions are already in the vehicle's order, rotor 1 "
             "first; remove motors.numbering")
    for i, (x, y) in enumerate(motors.positions):
        if x == 0.0 and y == 0.0:
            fail(f"motors.positions[{i}]", [x, y], "a rotor at the centre of mass gives no torque; give its "
                 "[x, y] in m (x forward, y right)")
    m = Motors.from_config(motors).effectiveness()
    largest = np.max(np.abs(m), axis=1, keepdims=True)
    rcond = 0.0 if not np.all(largest > 0) else 1.0 / np.linalg.cond(m / largest)
    if not rcond > MIXER_RCOND:
        fail("motors.positions", motors.positions, f"with motors.spin = {motors.spin} the rotors cannot command "
             f"thrust, roll, pitch and yaw independently (the reciprocal condition number of the mixer is "
             f"{rcond:.2g}, not above {MIXER_RCOND:g}); put the rotors around the centre of mass, diagonal rotors "
             "turning alike")
