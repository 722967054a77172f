"""The RK4 step ``dt: auto`` chooses: within the accuracy and stability bounds and never coarser than 1 ms,
continuous or held between a sampled controller's samples."""

from __future__ import annotations

import numpy as np
import pytest

from quadctl.sim.plan import ACCURACY_STEP, plan_held_step, plan_step

MS = 1e-3
"""s: the auto step is never coarser than a millisecond (docs/guide/flying.md: five steps per 5 ms sample)."""
SLOW = np.array([0.0, -2.1, -0.4 + 1.5j, -0.4 - 1.5j])
FAST = np.array([-3000.0, -50.0 + 400.0j, -50.0 - 400.0j, -2.0])


def _bounds(eig):
    """The coarsest step the rules allow: |dt lambda| <= ACCURACY_STEP at the fastest eigenvalue, 1 ms."""
    fastest = np.abs(eig).max()
    return min(ACCURACY_STEP / fastest if fastest else np.inf, MS)


@pytest.mark.parametrize("eig", [SLOW, FAST], ids=["slow", "fast"])
def test_the_auto_step_of_a_continuous_loop_is_the_coarsest_the_rules_allow(eig):
    """The step is ACCURACY_STEP / |lambda_max| or 1 ms, whichever is finer, stretched only to a whole number
    of steps in the run (by less than one step in the run's count)."""
    duration = 2.0
    plan = plan_step(eig, ["loop"] * len(eig), duration)
    bound = _bounds(eig)
    assert plan.auto and plan.n_steps * plan.dt == pytest.approx(duration, rel=1e-12)
    assert plan.dt <= bound * (1 + 1e-12)
    assert plan.dt > bound * plan.n_steps / (plan.n_steps + 1)  # no finer than a whole count needs


@pytest.mark.parametrize("rate", [30.0, 200.0, 300.0, 450.0, 1000.0, 1500.0])
@pytest.mark.parametrize("eig", [SLOW, FAST], ids=["slow", "fast"])
def test_the_auto_step_of_a_sampled_loop_divides_its_period_in_the_fewest_steps_the_rules_allow(rate, eig):
    """Held between samples, ``hold`` steps make one period Ts = 1 / rate exactly, each within the bounds
    (and Ts), and one step fewer would break them."""
    Ts = 1.0 / rate
    plan = plan_held_step(eig, rate, 1.0)
    bound = min(_bounds(eig), Ts)
    assert plan.hold * plan.dt == pytest.approx(Ts, rel=1e-12)
    assert plan.dt <= bound * (1 + 1e-9)
    assert plan.hold == 1 or Ts / (plan.hold - 1) > bound * (1 + 1e-9)
