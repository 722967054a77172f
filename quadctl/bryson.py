"""Bryson's rule (``lqr.<name>.bryson``) evaluated on the vehicle a config describes.

:func:`bryson_weights` gives each rule's ``(Q, R)``: ``Q`` from the largest acceptable errors, ``R`` from a share
of each input's room around the trim, which it solves for the config's flight condition on the vehicle;
:func:`weight_error` is the line that says why a rule has no weights on this vehicle. :func:`quadctl.setup.setup_of`
takes both, once.
"""

from __future__ import annotations

import math

import numpy as np

from quadctl.config import Config
from quadctl.errors import TrimError
from quadctl.linear.trim import solve_trim
from quadctl.physics.model import Vehicle
from quadctl.physics.motors import Actuators, headroom


def bryson_weights(cfg: Config, vehicle: Vehicle, actuators: Actuators | None,
                   trim_wind=(0.0, 0.0, 0.0)) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``(Q, R)`` of each subsystem whose weights are Bryson's rule (``lqr.<name>.bryson``), on this vehicle.

    ``Q = diag(1 / e^2)`` of the largest acceptable errors ``e``; ``R = diag(1 / du^2)`` with ``du`` the
    rule's ``headroom`` share of each input's room around the trim (:func:`quadctl.physics.motors.headroom`, the
    nearer side), the trim solved for the config's flight condition on ``vehicle``.

    An input with no room around the trim (its rotors at a limit there), or a flight condition with no
    trim, gives NaN in ``R``: the stages that need no weights (trim, linearize) still run, and the design
    refuses them (:attr:`quadctl.setup.Setup.weight_error`, :func:`weight_error`).
    """
    rules = {name: w for name, w in cfg.lqr.items() if w.bryson is not None}
    if not rules:
        return {}

    try:
        trim = solve_trim(cfg.trim.velocity_ned, cfg.trim.yaw, cfg.trim.position_ned, vehicle, wind_ned=trim_wind)
        room = headroom(actuators, trim.u)
    except TrimError:  # the trim stage says why
        room = None
    out = {}
    for name, w in rules.items():
        steps = [w.bryson.headroom * min(room[inp]) if room is not None else math.nan
                 for inp in cfg.partition()[name].inputs]
        out[name] = (np.diag(1.0 / np.square(w.bryson.errors)),
                     np.diag([1.0 / s ** 2 if s > 0 else math.nan for s in steps]))
    return out


def weight_error(cfg: Config, weights: dict) -> str | None:
    """The one line that says why a Bryson rule has no weights on this vehicle (None: every weight is a number)."""
    for name, (_, R) in weights.items():
        if cfg.lqr[name].bryson is not None and np.isnan(np.diag(R)).any():
            inputs = ", ".join(cfg.partition()[name].inputs)
            return (f"{cfg.name}: lqr.{name}.bryson: {inputs} has no room around the trim (a rotor at its limit "
                    "there, or no trim): give Q and R, or motors that can hold the trim")
    return None
