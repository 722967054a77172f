"""The LQR family: Riccati solves, gains per subsystem and on the coupled model, sampled designs.

Modules, each importing only those above it:

- :mod:`~quadctl.lqr.riccati`: the Riccati equations (CARE, DARE): validated weights, stacked and
  one-case solvers, residuals, the refusals that say why
- :mod:`~quadctl.lqr.integral`: integral action (LQI): a plant augmented with integrators
- :mod:`~quadctl.lqr.lag`: the rotors' first-order lag: a plant augmented with one lag state per input
- :mod:`~quadctl.lqr.discrete`: the zero-order hold, MATLAB ``dlqr``/``lqrd``, what a rate realizes
- :mod:`~quadctl.lqr.linear_loop`: the linear closed loop of a design, the one place ``A - B K`` is built
  (the design's, a subsystem's, the vehicle's with lag, lag model and delay; a stack)
- :mod:`~quadctl.lqr.decoupled`: :func:`lqr` (one case, MATLAB conventions) and the decoupled
  :func:`design` (one LQR per subsystem, assembled into the 4x12 gain)
- :mod:`~quadctl.lqr.coupled`: one LQR on the full coupled model, to compare with the decoupled design
- :mod:`~quadctl.lqr.gain_table`: a gain schedule's table (gains at the values of one scheduling
  variable, interpolated nearest, linear or cubic) and the scheduling variable read from a state

``from quadctl.lqr import lqr`` is the one-case entry point (MATLAB ``lqr``: ``K, P, E``).
"""

from quadctl.analysis import RICCATI_RTOL as RICCATI_RTOL
from quadctl.lqr.decoupled import Design as Design
from quadctl.lqr.decoupled import SubsystemDesign as SubsystemDesign
from quadctl.lqr.decoupled import design as design
from quadctl.lqr.decoupled import lqr as lqr
from quadctl.lqr.linear_loop import matrix as closed_loop_matrix
from quadctl.lqr.riccati import LqrResult as LqrResult
from quadctl.lqr.riccati import riccati_residual as riccati_residual
