"""A CasADi function evaluated on many points at once, a row a point, in CasADi's virtual machine.

The convention :mod:`quadctl.physics.flatness` and :mod:`quadctl.native.mapped` (the same, compiled) share:
each argument is ``(n, size)`` (one row a point) or ``(size,)`` (the same for every point); each
output ``(n, size)``, a matrix output's entries column-major, as CasADi stores them.
"""

from __future__ import annotations

import numpy as np


def rows_of(args) -> tuple[list[np.ndarray], int]:
    """The arguments as contiguous float arrays, and the number of points ``n``."""
    arrays = [np.ascontiguousarray(a, dtype=float) for a in args]
    return arrays, max((len(a) for a in arrays if a.ndim == 2), default=1)


class Pointwise:
    """``fn`` on many points through ``fn.map(n)`` (built once per ``n``)."""

    backend = "casadi"

    def __init__(self, fn):
        self.fn = fn
        self._map = None

    def __call__(self, *args) -> list[np.ndarray]:
        arrays, n = rows_of(args)
        if self._map is None or self._map[0] != n:
            self._map = (n, self.fn.map(n))
        got = self._map[1](*[a.T if a.ndim == 2 else a for a in arrays])
        got = got if isinstance(got, (list, tuple)) else [got]
        outs = []
        for k, value in enumerate(got):  # map sets the points' blocks side by side
            rows, cols = self.fn.size_out(k)
            outs.append(np.asarray(value, dtype=float).reshape(rows, n, cols).transpose(1, 2, 0).reshape(n, -1))
        return outs
