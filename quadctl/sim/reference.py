"""A reference as the loop's exogenous rows (:data:`quadctl.sim.builder.REFERENCE_LAYOUT`).

The reference is tabulated on the exogenous clock of the run (the noise's period, else the
controller's, else :data:`quadctl.noise.DEFAULT_PERIOD`), as the noise and the wind are, so the
compiled one-case loop, the lanes and the interpreted runner take it through the same rows and
agree to round-off. Row ``j`` holds over ``[t_j, t_j + period)``, ``t_j = j period``:

- ``x_ref(t) = x_ref(t_j) + (t - t_j) f(x_ref(t_j), u_ref(t_j))``, the first-order expansion (``f``
  the model: along a flat path it is ``d x_ref / dt``, :mod:`quadctl.flatness`);
- ``u_ref = u_ref(t_j + period / 2)``: the feedforward at the row's midpoint, whose zero-order hold
  is second-order accurate over the row.

Tabulated rather than evaluated in the generated code: a mission's pieces, shapes and the Newton
solve of the flatness map stay in one place (Python, from the model), the generated code gains
only an affine expansion, and a run's reference is the same array whichever runner flies it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.flatness import feedforward
from quadctl.layout import N_STATES
from quadctl.model import build_model
from quadctl.trajectory import Reference


@dataclass(frozen=True)
class FlownReference:
    """A path (:class:`quadctl.trajectory.Reference`) and the model parameters its feedforward
    assumes (the design model's :meth:`~quadctl.model.Vehicle.vector`: the controller's knowledge)."""

    path: Reference
    params: np.ndarray

    def exact(self, t) -> tuple[np.ndarray, np.ndarray]:
        """((n, 12), (n, 4)): the reference state and input at the times ``t`` (s)."""
        return feedforward(self.path.flat(t), self.params)

    def rows(self, j, period: float) -> np.ndarray:
        """``(len(j), 29)``: the exogenous reference rows of the absolute row indices ``j``."""
        j = np.asarray(j, dtype=float)
        t0 = j * period
        x, u = self.exact(np.concatenate([t0, t0 + period / 2]))
        n = len(j)
        x0, u_mid = x[:n], u[n:]
        rate = np.asarray(build_model().f.map(n)(x0.T, u[:n].T, self.params), dtype=float).T
        return np.hstack([t0[:, None], x0, rate, u_mid])

    def flown(self, rows: np.ndarray, t) -> tuple[np.ndarray, np.ndarray]:
        """((n, 12), (n, 4)): the reference the law used at times ``t`` under their ``rows``."""
        t = np.asarray(t, dtype=float)
        x = rows[:, 1:1 + N_STATES] + rows[:, 1 + N_STATES:1 + 2 * N_STATES] * (t - rows[:, 0])[:, None]
        return x, rows[:, 1 + 2 * N_STATES:]

    def position_range(self, duration: float, samples: int = 2001) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) (3,) m: the extent of the reference's position over ``[0, duration]``."""
        starts = [p.t0 for p in self.path.pieces if 0 <= p.t0 <= duration]
        t = np.unique(np.concatenate([np.linspace(0.0, duration, samples), starts]))
        pos = self.path.flat(t).position[0]
        return pos.min(axis=0), pos.max(axis=0)
