"""What a key a sweep varies reaches: the simulated vehicle or its environment only (:func:`plant_side`),
or the design too, and what the Kalman filter takes as the noise it assumes (:func:`filter_reads`). A
sweep whose every parameter is plant-side is an uncertainty study: one design, many vehicles.
"""

from __future__ import annotations

MC_PARAMETER = ("simulation", "noise", "seed")
"""The key path of a Monte Carlo over noise seeds: one kind of uncertainty study (see :func:`plant_side`)."""
RUN_KEYS = (("simulation", "duration"), ("simulation", "dt"), ("simulation", "max_samples"),
            ("simulation", "reference"))
"""Keys under ``simulation.`` that set the run (its length, step, records, the reference it is
commanded to fly), not the vehicle or its environment: a sweep of them is no uncertainty study
(its trajectories would not share a grid, or fly different commands)."""


def plant_side(keys: tuple, rotor_lag: str = "ignore", trim_wind: bool = False, estimator=None) -> bool:
    """Whether a parameter changes only the simulated vehicle or its environment, never the design.

    Plant-side: every key under ``simulation.`` but :data:`RUN_KEYS` (``simulation.plant.*``, the
    mass and inertia errors; ``simulation.noise.*``, but what a Kalman filter takes from it, see
    :func:`filter_reads`; the initial offset; ``simulation.wind.*``, but the steady wind while
    ``trim.wind`` is true: the design is trimmed in it), ``controller.delay`` (the design does not
    see it) and ``motors.time_constant`` while ``controller.rotor_lag`` is ``ignore`` (with
    ``include`` the design is made for it). ``estimator``: the config's ``estimator:`` section
    (None: no filter).

    Examples
    --------
    >>> plant_side(("simulation", "plant", "mass")), plant_side(("vehicle", "mass"))
    (True, False)
    >>> plant_side(("motors", "time_constant")), plant_side(("motors", "time_constant"), "include")
    (True, False)
    >>> plant_side(("simulation", "wind", "steady", 0)), plant_side(("simulation", "wind", "steady", 0), trim_wind=True)
    (True, False)
    """
    keys = tuple(keys)
    if keys[:3] == ("simulation", "wind", "steady") and trim_wind:
        return False
    if filter_reads(keys, estimator):
        return False
    if keys[:1] == ("simulation",):
        return keys[:2] not in RUN_KEYS
    if keys[:2] == ("controller", "delay"):
        return True
    return keys[:2] == ("motors", "time_constant") and rotor_lag == "ignore"


def filter_reads(keys: tuple, estimator) -> bool:
    """Whether the Kalman filter of ``estimator:`` (a config section, or None) takes the value at
    ``keys`` as the noise it assumes: ``simulation.noise.period`` (its sample period), and the
    force, torque and sensor deviations it does not set itself.

    >>> filter_reads(("simulation", "noise", "seed"), None), filter_reads(("simulation", "noise", "period"), None)
    (False, False)
    """
    if estimator is None or tuple(keys[:2]) != ("simulation", "noise"):
        return False
    if len(keys) < 3 or keys[2] == "period":
        return True
    if keys[2] in ("force", "torque"):
        return getattr(estimator, keys[2]) is None
    if keys[2] == "sensor":
        return len(keys) < 4 or keys[3] not in estimator.sensor
    return False
