"""The jobs of a sweep chunk that runs ETDRK4 (``simulation.method: etdrk4``), as
:func:`quadctl.sweep.batched.loops_of` makes RK4's.

Each case's loop is :func:`quadctl.pipeline.closed_loop_of`'s (with the linearization ETDRK4 takes as
its linear part) and its plan is made here (a refused step is the case's row); the cases of one
structure and one set of exogenous inputs (noise, wind, reference, duration, step and tolerance: an
:class:`ExponentialJob`'s ``group``) run together through :func:`quadctl.sweep.batched.simulate_all`,
which hands them to the simulation's one entry, :func:`quadctl.sim.run.simulate_stack`: **each case
on its own graded schedule**, its numbers those of its one-case run, deterministic whatever the chunk.
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from quadctl import pipeline
from quadctl.errors import QuadctlError, StepSizeError
from quadctl.physics.motors import check_trim
from quadctl.physics.noise import exogenous_period
from quadctl.sim.etdrk4_plan import rk4_limits
from quadctl.sim.run import exponential_plan
from quadctl.sweep.batched import _estimator

if TYPE_CHECKING:
    from quadctl.sim.plan import StepPlan
    from quadctl.sim.run import ClosedLoop


@dataclass(frozen=True)
class ExponentialJob:
    """A case ready for the exponential lanes (what the evaluation reads of a job: ``plan``, ``lo``,
    ``hi``, ``exo_period``)."""

    loop: ClosedLoop
    x0: np.ndarray
    plan: StepPlan
    lo: np.ndarray
    hi: np.ndarray
    exo_period: float
    group: tuple
    """The cases that can share lanes: structure, rate and simulation inputs (by value)."""
    linear_part: np.ndarray
    """ETDRK4's linear part of the loop (:func:`quadctl.sim.run.exponential_plan`)."""


def jobs_of(live) -> list:
    """Per (prep, design): an :class:`ExponentialJob`, a refused step's message, or a QuadctlError."""

    out: list = []
    loops: list = []
    for prep, des in live:
        setup, linear = prep.setup, prep.plant.linear
        try:
            check_trim(setup.actuators, linear.u_trim)
            loops.append(pipeline.closed_loop_of(setup, linear, des.K_block, Ki=des.Ki_block,
                                                 integral_states=des.integral_states, Kv=des.Kv,
                                                 estimator=_estimator(prep)))
        except QuadctlError as exc:
            loops.append(exc)
    # the linear parts, and RK4's limit each plan reports, of all the continuous loops at once
    parts, limits = {}, {}
    shapes: dict = {}
    for k, loop in enumerate(loops):
        if not isinstance(loop, QuadctlError) and loop.rate is None:
            parts[k] = loop.linear_part()
            shapes.setdefault(parts[k].shape, []).append(k)
    for members in shapes.values():
        eig = np.linalg.eigvals(np.stack([parts[k] for k in members]))
        limits.update(zip(members, rk4_limits(eig)))
    for k, ((prep, _), loop) in enumerate(zip(live, loops)):
        setup, linear = prep.setup, prep.plant.linear
        if isinstance(loop, QuadctlError):
            out.append(loop)
            continue
        noise = setup.noise if setup.noise is not None and setup.noise.active else None
        wind = setup.wind if setup.wind is not None and setup.wind.active else None
        flown = setup.flown_reference
        exogenous = noise is not None or wind is not None or flown is not None
        period = exogenous_period(noise.period if noise is not None else None, loop.rate)
        try:
            L, plan = exponential_plan(loop, setup.duration, setup.dt, reference=flown,
                                       exo_period=period if exogenous else None, linear_part=parts.get(k),
                                       max_stable_dt=limits.get(k), tolerance=setup.tolerance)
        except StepSizeError as exc:
            out.append(str(exc))
            continue
        lo, hi = loop.bounds(setup.duration, flown)
        inputs = pickle.dumps((noise, wind, setup.reference, flown.params.tobytes() if flown else None))
        group = (loop.spec(), loop.rate, setup.duration, setup.dt, setup.tolerance, setup.max_samples, inputs)
        out.append(ExponentialJob(loop, setup.initial_state(linear.x_trim), plan, lo, hi, period, group, L))
    return out
