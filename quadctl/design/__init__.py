"""The controller design: Riccati solves, LQR gains per subsystem and on the coupled model, sampled
designs, and the margins of the loops they close.

Modules, each importing only those above it:

- :mod:`~quadctl.design.riccati`: the Riccati equations (CARE, DARE), stacked and one-case solvers
- :mod:`~quadctl.design.integral`: integral action (LQI): a plant augmented with integrators
- :mod:`~quadctl.design.lag`: the rotors' first-order lag: a plant augmented with one lag state per input
- :mod:`~quadctl.design.discrete`: the zero-order hold, MATLAB ``dlqr``/``lqrd``, what a rate realizes
- :mod:`~quadctl.design.linear_loop`: the linear closed loop of a design, the one place ``A - B K`` is built
- :mod:`~quadctl.design.lqg_loop`: the loops flown through a Kalman filter, and the builder's loop linearized
- :mod:`~quadctl.design.stacked`: the one engine of the decoupled design: a stack of subsystem problems solved at once
- :mod:`~quadctl.design.decoupled`: :func:`lqr` (one case) and the decoupled :func:`design` (the 4x12 gain)
- :mod:`~quadctl.design.coupled`: one LQR on the full coupled model, to compare with the decoupled design
- :mod:`~quadctl.design.gain_table`: a gain schedule's table and the scheduling variable read from a state
- :mod:`~quadctl.design.margins`: a loop's margins as values, and the guarantee and requirement they are judged by
- :mod:`~quadctl.design.broken_loops`: every regulated loop of a design broken at one plant input (LQR and LQG)
- :mod:`~quadctl.design.margin_search`: a broken loop's margins found on its frequency response (not imported by
  the package: SciPy loads only for them)
- :mod:`~quadctl.design.margin_findings`: what the margins say (findings, as values), every loop of a design judged

``from quadctl.design import lqr`` is the one-case entry point (MATLAB ``lqr``: ``K, P, E``).
"""

from quadctl.design.decoupled import Design as Design
from quadctl.design.decoupled import SubsystemDesign as SubsystemDesign
from quadctl.design.decoupled import design as design
from quadctl.design.decoupled import lqr as lqr
from quadctl.design.linear_loop import matrix as closed_loop_matrix
from quadctl.design.riccati import LqrResult as LqrResult
from quadctl.design.riccati import riccati_residual as riccati_residual
from quadctl.linear.analysis import RICCATI_RTOL as RICCATI_RTOL

__all__ = ["RICCATI_RTOL", "Design", "LqrResult", "SubsystemDesign", "closed_loop_matrix", "design", "lqr",
           "riccati_residual"]
