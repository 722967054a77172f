"""A reference as the loop's exogenous rows (:data:`quadctl.sim.builder.REFERENCE_LAYOUT`).

The reference is tabulated on the exogenous clock of the run (the noise's period, else the
controller's, else :data:`quadctl.noise.DEFAULT_PERIOD`), as the noise and the wind are, so the
compiled one-case loop, the lanes and the interpreted runner take it through the same rows and
agree to round-off. Row ``j`` holds over ``[t_j, t_j + period)``, ``t_j = j period``:

- ``x_ref(t) = x_ref(t_j) + s r_j + s^2 (r_(j+1) - r_j) / (2 period)``, ``s = t - t_j``, with
  ``r_j = f(x_ref(t_j), u_ref(t_j))`` the model's rate (along a flat path, ``d x_ref / dt``:
  :mod:`quadctl.flatness`): the quadratic whose slope runs from ``r_j`` to ``r_(j+1)``, third-order
  accurate over the row;
- ``u_ref(t) = u_ref(t_j) + s (u_ref(t_(j+1)) - u_ref(t_j)) / period``: the feedforward interpolated.

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
from quadctl.sim.mapped import mapped
from quadctl.trajectory import Reference


@dataclass(frozen=True)
class FlownReference:
    """A path (:class:`quadctl.trajectory.Reference`) and the model parameters its feedforward
    assumes (the design model's :meth:`~quadctl.model.Vehicle.vector`: the controller's knowledge)."""

    path: Reference
    params: np.ndarray

    def exact(self, t) -> tuple[np.ndarray, np.ndarray]:
        """((n, 12), (n, 4)): the reference state and input at the times ``t`` (s)."""
        return feedforward(self.path.flat(t), self.params, mapped, self.path.remedy)  # compiled over the points

    def rows(self, j, period: float) -> np.ndarray:
        """``(len(j), 45)``: the exogenous reference rows of the absolute row indices ``j``."""
        j = np.asarray(j, dtype=np.int64)
        ends, where = np.unique(np.concatenate([j, j + 1]), return_inverse=True)  # a row's end: the next's start
        x, u = self.exact(ends * period)
        rate = mapped(build_model().f)(x, u, self.params)[0]
        a, b = where[:len(j)], where[len(j):]
        return np.hstack([(j * period)[:, None], x[a], rate[a], (rate[b] - rate[a]) / period,
                          u[a], (u[b] - u[a]) / period])

    def flown(self, rows: np.ndarray, t) -> tuple[np.ndarray, np.ndarray]:
        """((n, 12), (n, 4)): the reference the law used at times ``t`` under their ``rows``."""
        s = (np.asarray(t, dtype=float) - rows[:, 0])[:, None]
        n = N_STATES
        x = rows[:, 1:1 + n] + s * (rows[:, 1 + n:1 + 2 * n] + s / 2 * rows[:, 1 + 2 * n:1 + 3 * n])
        u = rows[:, 1 + 3 * n:5 + 3 * n] + s * rows[:, 5 + 3 * n:]
        return x, u

    def position_range(self, duration: float, samples: int = 2001) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) (3,) m: the extent of the reference's position over ``[0, duration]``."""
        starts = [p.t0 for p in self.path.pieces if 0 <= p.t0 <= duration]
        t = np.unique(np.concatenate([np.linspace(0.0, duration, samples), starts]))
        pos = self.path.flat(t).position[0]
        return pos.min(axis=0), pos.max(axis=0)
