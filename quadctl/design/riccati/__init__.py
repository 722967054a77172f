"""Riccati equations of LQR: validated weights, stacked and one-case solvers, residuals, verdicts.

Continuous (CARE, MATLAB ``lqr``) and discrete (DARE, ``dlqr``), with an optional cross weight ``N``:
:func:`care_batch` (stable eigenvectors of stacked Hamiltonians), :func:`dare_batch` (structure-
preserving doubling), :func:`care_schur` (Laub's ordered Schur vectors), each polished by
:data:`NEWTON_STEPS` Newton steps and residual-checked (``RICCATI_RTOL``); :func:`solve` (behind
:func:`quadctl.design.lqr`) falls back to SciPy and otherwise raises a
:class:`~quadctl.errors.DesignError` that says why. The equations and methods are in the docs,
docs/internals.md ("The Riccati equations").
"""

from quadctl.design.riccati.single import LqrResult, care_schur, require_stabilizable, solve, unstabilizable_mode
from quadctl.design.riccati.stacked import (
    KRONECKER_MAX_N,
    NEWTON_STEPS,
    ROUNDOFF_RTOL,
    SDA_STEPS,
    BatchLqr,
    care_batch,
    dare_batch,
    dare_residual,
    dare_residuals,
    riccati_residual,
    riccati_residuals,
)
from quadctl.design.riccati.weights import (
    SEMIDEFINITE_RTOL,
    WeightCheck,
    as_problem,
    as_stack,
    real_array,
    require_valid_weights,
)

__all__ = ["KRONECKER_MAX_N", "NEWTON_STEPS", "ROUNDOFF_RTOL", "SDA_STEPS", "SEMIDEFINITE_RTOL", "BatchLqr",
           "LqrResult", "WeightCheck", "as_problem", "as_stack", "real_array", "care_batch", "care_schur", "dare_batch",
           "dare_residual", "dare_residuals", "require_stabilizable", "require_valid_weights", "riccati_residual",
           "riccati_residuals", "solve", "unstabilizable_mode"]
