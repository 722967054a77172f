"""A flown reference's rows: a path and its feedforward tabulated as the loop's exogenous reference rows.

A reference (:class:`quadctl.physics.trajectory.Reference`) and the feedforward that flies it
(:mod:`quadctl.physics.flatness`) are tabulated on the run's exogenous clock, a row a period: each
row holds two expansions of the reference (:data:`ROW_HALF` columns each), the second from the first
knot of the path inside the row (a piece's start, a leg's end), so no expansion is flown past the
knot that ends its span (:class:`FlownReference`). :func:`in_force` says which expansion holds at a
time; ``driver.c``'s ``qc_after`` is the same rule in C.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.errors import TrimError
from quadctl.layout import N_INPUTS, N_STATES
from quadctl.native.mapped import mapped
from quadctl.physics.flatness import feedforward, feedforward_of
from quadctl.physics.model import build_model
from quadctl.physics.trajectory import Reference


@dataclass(frozen=True)
class FlownReference:
    """A path (:class:`quadctl.physics.trajectory.Reference`) and the model parameters its feedforward
    assumes (the design model's :meth:`~quadctl.physics.model.Vehicle.vector`: the controller's knowledge).

    Its rows (:meth:`rows`) are the loop's exogenous reference rows
    (:data:`quadctl.sim.loop_layout.REFERENCE_LAYOUT`), tabulated on the exogenous clock of the run (the
    noise's period, else the controller's, else :data:`quadctl.physics.noise.DEFAULT_PERIOD`), as the noise
    and the wind are, so the compiled one-case loop, the lanes and the interpreted runner take it
    through the same rows and agree to round-off. Row ``j`` holds over ``[t_j, t_j + period)``, ``t_j = j period``,
    and expands the path over each smooth span of it: the whole row, or, where a knot of the path lies
    inside it (:attr:`quadctl.physics.trajectory.Reference.knots`: a piece's start, a leg's end, where the
    snap steps and with it the torques and the slope of the body rates), ``[t_j, t_b)`` and ``[t_b,
    t_j + period)`` each on its own (the first knot; the second expansion from ``t_b`` on). Over a span
    ``[a, b)`` of length ``h``:

    - ``x_ref(t) = x_ref(a) + s r_a + s^2 (r_b - r_a) / (2 h)``, ``s = t - a``, with
      ``r = f(x_ref, u_ref)`` the model's rate (along a flat path, ``d x_ref / dt``:
      :mod:`quadctl.physics.flatness`) at ``a`` and at ``b`` (the limit from the left: the span's own
      piece): the quadratic whose slope runs from ``r_a`` to ``r_b``, third-order accurate over the span;
    - ``u_ref(t) = u_ref(a) + s (u_ref(b) - u_ref(a)) / h``: the feedforward interpolated.

    So no expansion is flown past the knot that ends its span (a leg's expansion past the leg's end,
    where the reference's body rates would run on and jump back at the next row).

    Tabulated rather than evaluated in the generated code: a mission's pieces, shapes and the Newton
    solve of the flatness map stay in one place (Python, from the model), the generated code gains
    only an affine expansion, and a run's reference is the same array whichever runner flies it.
    """

    path: Reference
    params: np.ndarray

    def exact(self, t) -> tuple[np.ndarray, np.ndarray]:
        """((n, 12), (n, 4)): the reference state and input at the times ``t`` (s)."""
        return feedforward(self.path.flat(t), self.params, mapped, self.path.remedy)  # compiled over the points

    def rows(self, j, period: float) -> np.ndarray:
        """``(len(j), 90)``: the exogenous reference rows of the absolute row indices ``j`` (the stack of
        one of :meth:`rows_of`).

        Raises
        ------
        TrimError
            The path needs an attitude beyond the model's (:func:`~quadctl.physics.flatness.feedforward`).
        """
        (got,) = type(self).rows_of([self], [j], [period])
        if isinstance(got, TrimError):
            raise got
        return got

    @classmethod
    def rows_of(cls, references, js, periods) -> list:
        """:meth:`rows` of many references at once, their feedforward solved together
        (:func:`~quadctl.physics.flatness.feedforward_of`) and their model's rates in one call: per
        reference its rows (the same numbers as its own :meth:`rows`), or the TrimError refusing its path.

        Parameters
        ----------
        references : list of FlownReference
        js : list of (n_k,) int array_like
            Each reference's absolute row indices.
        periods : list of float
            Each reference's exogenous clock (s).
        """
        if not references:
            return []
        plans = [_row_spans(ref.path, np.asarray(j, dtype=np.int64), period)
                 for ref, j, period in zip(references, js, periods)]
        flown = feedforward_of([ref.path.flat(plan.t, plan.left) for ref, plan in zip(references, plans)],
                               [ref.params for ref in references], mapped, [ref.path.remedy for ref in references])
        out: list = list(flown)
        good = [k for k, got in enumerate(flown) if not isinstance(got, TrimError)]
        if not good:
            return out
        sizes = [len(plans[k].t) for k in good]
        rates = mapped(build_model().f)(np.vstack([flown[k][0] for k in good]), np.vstack([flown[k][1] for k in good]),
                                        np.repeat([references[k].params for k in good], sizes, axis=0))[0]
        for k, rate in zip(good, np.split(rates, np.cumsum(sizes)[:-1])):
            (x, u), plan = flown[k], plans[k]
            out[k] = np.hstack([_expansion(x, u, rate, *ends) for ends in plan.ends])
        return out

    @staticmethod
    def flown(rows: np.ndarray, t) -> tuple[np.ndarray, np.ndarray]:
        """((n, 12), (n, 4)): the reference the law used at times ``t`` under their ``rows`` (each row's
        expansion in force at ``t``: :func:`in_force`)."""
        return _expanded(in_force(rows, t)[:, :ROW_HALF], t)

    def position_range(self, duration: float, samples: int = 2001) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) (3,) m: the extent of the reference's position over ``[0, duration]``."""
        starts = [p.t0 for p in self.path.pieces if 0 <= p.t0 <= duration]
        t = np.unique(np.concatenate([np.linspace(0.0, duration, samples), starts]))
        pos = self.path.flat(t).position[0]
        return pos.min(axis=0), pos.max(axis=0)


SPLIT_ROUNDOFF = 1e-12
"""A time within this (relative, s per s) of a row's split counts as on it, and takes the second
expansion (the limit from the right): a run's time ``k dt``, rounded, that lands on a knot."""
ROW_HALF = 1 + 3 * N_STATES + 2 * N_INPUTS
"""Columns of one expansion of a reference row: ``t``, ``x``, rate, curvature, ``u``, ``u`` rate
(:data:`quadctl.sim.loop_layout.REFERENCE_LAYOUT` holds two)."""


def in_force(rows: np.ndarray, at, over=None) -> np.ndarray:
    """``(n, 2 ROW_HALF)``: per tabulated row (``rows`` (n, 2 :data:`ROW_HALF`), :meth:`FlownReference.rows`)
    the expansion in force at the times ``at`` (n,) s, then the one in force at ``over`` (n,) s (default
    ``at``): what the loop reads (:data:`quadctl.sim.loop_layout.REFERENCE_LAYOUT`, ``over`` a step's
    midpoint). A row's second expansion is in force from its split ``t_b`` on (to within
    :data:`SPLIT_ROUNDOFF`) when the row has one (``t_b`` after the first's anchor), its first
    before. ``driver.c``'s ``qc_after`` is this rule in C (the compiled runners choose there)."""
    first, second = rows[:, :ROW_HALF], rows[:, ROW_HALF:]
    split = second[:, 0]
    has = split > first[:, 0]
    edge = split - SPLIT_ROUNDOFF * (1 + np.abs(split))

    def chosen(t):
        return np.where((has & (np.asarray(t, dtype=float) > edge))[:, None], second, first)

    return np.hstack([chosen(at), chosen(at if over is None else over)])


@dataclass(frozen=True)
class _RowSpans:
    """Where :meth:`FlownReference.rows_of` solves the feedforward for its rows: at the times ``t`` (m,)
    s, where ``left`` (m,) their limits from the left (:meth:`quadctl.physics.trajectory.Reference.flat`),
    and per row its two expansions' anchor and end times and the indices into those points of their
    start and end, ``((t_j, t_b, a, b), (t_b, t_(j+1), c, d))`` (each (rows,)): the second a copy of the
    first in a row with no knot inside."""

    t: np.ndarray
    left: np.ndarray
    ends: tuple


def _row_spans(path: Reference, j: np.ndarray, period: float) -> _RowSpans:
    """The points that expand rows ``j`` of ``path`` on the clock ``period`` (s).

    Row ``j`` spans ``[t_j, t_(j+1))``. Where a knot of the path (a piece's start or a leg's end:
    :attr:`quadctl.physics.trajectory.Reference.knots`) lies strictly inside it, at ``t_b`` (the first,
    if more than one), its first expansion spans ``[t_j, t_b)`` and ends on the limit from the left at
    ``t_b``, its second spans ``[t_b, t_(j+1))`` from the limit from the right. Every expansion ends on
    its limit from the left, so none reaches across a knot: a leg's expansion is not flown past the
    leg's end. A knot within round-off of the grid counts as on it (taken there).
    """
    tol = 1e-9 * period
    knots = np.append(path.knots, np.inf)
    t_j, t_n = j * period, (j + 1) * period

    def snapped(t):
        """(times, on a knot): ``t``, or the knot within ``tol`` of it."""
        k = np.clip(np.searchsorted(knots, t), 1, len(knots) - 1)
        near = np.where(np.abs(knots[k - 1] - t) < np.abs(knots[k] - t), knots[k - 1], knots[k])
        on = np.abs(near - t) <= tol
        return np.where(on, near, t), on

    inside = knots[np.searchsorted(knots, t_j + tol, side="right")]
    split = inside < t_n - tol
    t_b = np.where(split, inside, t_j)
    (ta, _), (tn, on_n) = snapped(t_j), snapped(t_n)
    t_all = np.concatenate([ta, np.where(split, t_b, tn), np.where(split, t_b, ta), tn])
    left = np.concatenate([np.zeros_like(split), split | on_n, np.zeros_like(split), on_n])
    order = np.lexsort((~left, t_all))  # by time, a knot's left limit before its right
    new = np.ones(len(order), dtype=bool)
    new[1:] = (np.diff(t_all[order]) != 0) | (np.diff(left[order]) != 0)
    index = np.empty(len(order), dtype=np.int64)
    index[order] = np.cumsum(new) - 1
    a, b, c, d = np.split(index, 4)
    return _RowSpans(t_all[order][new], left[order][new], ((t_j, np.where(split, t_b, t_n), a, b), (t_b, t_n, c, d)))


def _expansion(x, u, rate, t0, t_end, a, b) -> np.ndarray:
    """(rows, :data:`ROW_HALF`): per row the expansion about ``t0`` (rows,) s from its point ``a`` to its
    point ``b`` (indices into the points' states ``x``, inputs ``u`` and model rates ``rate``), used up to
    ``t_end`` (rows,) s (the row's end; the first expansion of a split row ends at ``t_b``, where its
    point ``b`` is): ``t0``, ``x`` and its rate at ``a``, the curvature that takes the rate to ``b``'s,
    ``u`` at ``a`` and its slope to ``b``'s."""
    span = (t_end - t0)[:, None]
    return np.hstack([t0[:, None], x[a], rate[a], (rate[b] - rate[a]) / span, u[a], (u[b] - u[a]) / span])


def _expanded(rows: np.ndarray, t) -> tuple[np.ndarray, np.ndarray]:
    """((n, 12), (n, 4)): one expansion (:data:`ROW_HALF` columns of ``rows``) at the times ``t``."""
    s = (np.asarray(t, dtype=float) - rows[:, 0])[:, None]
    n = N_STATES
    x = rows[:, 1:1 + n] + s * (rows[:, 1 + n:1 + 2 * n] + s / 2 * rows[:, 1 + 2 * n:1 + 3 * n])
    u = rows[:, 1 + 3 * n:1 + 3 * n + N_INPUTS] + s * rows[:, 1 + 3 * n + N_INPUTS:]
    return x, u
