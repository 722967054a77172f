"""Riccati equations of LQR: validated weights, stacked and one-case solvers, residuals, verdicts.

Continuous (CARE, MATLAB ``lqr``) and discrete (DARE, MATLAB ``dlqr``), both with an optional
cross weight ``N`` (cost ``x'Qx + u'Ru + 2 x'Nu``)::

    A'P + PA - (PB + N) R^-1 (B'P + N') + Q = 0,              K = R^-1 (B'P + N')
    A'PA - P - (A'PB + N)(R + B'PB)^-1 (B'PA + N') + Q = 0,   K = (R + B'PB)^-1 (B'PA + N')

``P`` is the stabilizing solution: ``A - B K`` has every eigenvalue in the open left half-plane
(inside the unit circle), with the margins of :mod:`quadctl.analysis`.

Methods. Substituting ``u = v - R^-1 N' x`` removes the cross term (``A - B R^-1 N'``,
``Q - N R^-1 N'``); then

- :func:`care_batch`: the ``n`` stable eigenvectors of the stacked Hamiltonians, ``P = U2 U1^-1``;
- :func:`dare_batch`: the structure-preserving doubling algorithm (SDA; Chu, Fan, Lin & Wang,
  Linear Algebra Appl. 396, 2005), products and solves only, which needs no inverse of ``A``;
- :func:`care_schur` (one case, larger ``n``): Laub's ordered real Schur vectors of the
  Hamiltonian (IEEE TAC 24, 1979);

each followed by :data:`NEWTON_STEPS` Newton steps (Kleinman's Lyapunov, Hewer's Stein
equation), which square the error. Every answer is residual-checked (``RICCATI_RTOL``) and its
loop stability-checked; the stacked solvers flag what fails (``ok``), :func:`solve` (behind
:func:`quadctl.design.lqr` and :func:`quadctl.design.discrete.dlqr`) falls back to SciPy's Schur solvers and
otherwise raises a :class:`~quadctl.errors.DesignError` that says why: invalid weights, a mode no
input reaches, a marginal mode ``Q`` does not see, or an ill-conditioned equation.
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
