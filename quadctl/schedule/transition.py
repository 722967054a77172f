"""A transition across a gain schedule flown twice: with the scheduled gains and with one fixed design.

The setup's reference (``simulation.reference``, for example velocity setpoints from hover to the
top speed and back) is flown from the trim by the loop of the schedule's gains
(:func:`quadctl.pipeline.scheduled_loop`) and by the loop of the setup's own design at its trim
(the fixed design), both without noise, on the same plant, actuators and step. Each run is
summarized by what separates them: whether it completes, the peak tracking error, the fraction
of the run at an actuator limit, the peak attitude, and whether the flown scheduling variable
stays on the schedule's grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl import pipeline
from quadctl.design.gain_table import scheduling_values
from quadctl.errors import ArgumentError
from quadctl.layout import STATE_INDEX
from quadctl.native.mapped import mapped
from quadctl.physics import motors
from quadctl.physics.model import build_model
from quadctl.schedule.envelope import heading_of, schedule_of
from quadctl.setup import Setup
from quadctl.sim.loop import ClosedLoop
from quadctl.sim.run import SimResult

ON_GRID_MARGIN = 0.1
"""A run stays on the schedule's grid while its scheduling value is within the grid's span widened by
this fraction of it at each end (a tracking overshoot of a tenth of the span is still on the grid)."""
LABELS = ("scheduled", "fixed")
"""The two runs, in the order :class:`Transition` and its figure give them."""


@dataclass(frozen=True)
class Transition:
    """The two runs of one transition and their numbers.

    Attributes
    ----------
    scheduled, fixed : SimResult
        The schedule's gains; the setup's design at its trim.
    loops : dict of str -> ClosedLoop
        Each run's loop, by label (:data:`LABELS`).
    summary : dict
        ``variable`` and ``grid`` ([first, last] value, the variable's unit), and per label
        :func:`run_summary`.
    """

    scheduled: SimResult
    fixed: SimResult
    loops: dict
    summary: dict

    def runs(self) -> dict[str, SimResult]:
        """The runs by label (:data:`LABELS`)."""
        return {"scheduled": self.scheduled, "fixed": self.fixed}


def fly_transition(setup: Setup, table=None) -> Transition:
    """Fly the setup's reference with the gain table and with the setup's fixed design.

    Parameters
    ----------
    setup : Setup
        With ``schedule:`` and ``simulation.reference`` (a transition across the schedule's grid).
    table : GainTable, optional
        The schedule's gains (:class:`quadctl.design.gain_table.GainTable`); default the setup's
        (:func:`quadctl.schedule.envelope.schedule_of`).

    Raises
    ------
    ArgumentError
        The setup has no ``schedule:`` or no ``simulation.reference``.
    """
    if setup.schedule is None or setup.reference is None:
        missing = "schedule (schedule:)" if setup.schedule is None else "reference (simulation.reference)"
        raise ArgumentError(f"fly_transition: the setup has no {missing}: a transition flies a schedule (schedule:) "
                            "along a reference (simulation.reference); give the setup of a config with both")
    stages = pipeline.Stages(setup)
    fixed = stages.loop
    if table is None:
        schedule = schedule_of(setup)
        scheduled, table = schedule.flown_by(fixed), schedule.table
    else:
        scheduled = pipeline.scheduled_loop(fixed, table, heading_of(setup))
    loops = {"scheduled": scheduled, "fixed": fixed}
    sims = {label: pipeline.simulation_of(setup, loop, noise=False) for label, loop in loops.items()}
    grid = (float(table.values[0]), float(table.values[-1]))
    summary = {"variable": table.variable, "grid": list(grid),
               **{label: run_summary(setup, loops[label], sims[label], grid) for label in LABELS}}
    return Transition(scheduled=sims["scheduled"], fixed=sims["fixed"], loops=loops, summary=summary)


def run_summary(setup: Setup, loop: ClosedLoop, sim: SimResult, grid: tuple[float, float]) -> dict:
    """One run's numbers: ``status`` and ``message`` (:func:`quadctl.sim.run.verdict`),
    ``position_error`` (peak ``|p - p_ref|``, m), ``velocity_error`` (peak ``|V - V_ref|`` of the earth-frame
    velocities, m/s: the model's position rates, so an attitude error is not read as one of velocity),
    ``saturation`` (the largest fraction of the run any actuator spent at a limit;
    0 without limits), ``saturates`` (above :data:`quadctl.physics.motors.SATURATION_FLAG`), ``peak_attitude``
    (deg, largest ``|phi|`` and ``|theta|``), ``flown_range`` (the scheduling variable's extent) and
    ``on_grid`` (it stays within the grid, :data:`ON_GRID_MARGIN`)."""

    pos = np.linalg.norm(sim.x[:, :3] - sim.x_ref[:, :3], axis=1)
    vel = np.linalg.norm(_velocity_ned(sim.x, sim.u, loop.params) - _velocity_ned(sim.x_ref, sim.u, loop.params),
                         axis=1)
    act = loop.actuators
    fraction = max(motors.saturation_fraction(act, sim.u).values()) if act is not None else 0.0
    attitude = np.abs(sim.x[:, [STATE_INDEX["phi"], STATE_INDEX["theta"]]]).max()
    flown = scheduling_values(setup.schedule.variable, sim.x, heading_of(setup))
    margin = ON_GRID_MARGIN * (grid[1] - grid[0])
    return {"status": sim.status, "message": sim.message, "completed": sim.status == "ok",
            "duration": float(sim.t[-1]), "position_error": float(pos.max()), "velocity_error": float(vel.max()),
            "saturation": float(fraction), "saturates": bool(fraction > motors.SATURATION_FLAG),
            "peak_attitude": math.degrees(float(attitude)),
            "flown_range": [float(flown.min()), float(flown.max())],
            "on_grid": bool(flown.min() >= grid[0] - margin and flown.max() <= grid[1] + margin)}


def _velocity_ned(x, u, params) -> np.ndarray:
    """(n, 3) m/s: the earth-frame (NED) velocity of each state row, the model's position rates (which
    read neither the input nor the parameters)."""

    return mapped(build_model().f)(x, u, params)[0][:, :3]
