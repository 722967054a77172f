"""The rules a weight matrix (LQR's Q or R) obeys: its shape, its range, symmetry and definiteness.

:func:`check_weight` checks one weight and says what is wrong; :func:`diagonal_weights_pass` applies
the same rules to many diagonals at once (a sweep checks thousands).
"""

from __future__ import annotations

from quadctl.errors import ConfigError
from quadctl.text.messages import show

SYMMETRY_RTOL = 1e-10
"""Relative tolerance of the symmetry test, scaled by the matrix's largest entry."""
DEFINITENESS_RTOL = 1e-12
"""Eigenvalues above ``-rtol * max|eig|`` count as nonnegative (PSD test), as in SciPy's ``_are``."""


WEIGHT_RANGE = (1e-15, 1e15)
"""Magnitudes a nonzero entry of Q or R may have. The gains depend only on the ratios of the
weights, and Bryson's rule (1/largest error^2) gives 1e-6 to 1e12 for vehicles from nano to heavy
lift; past this range the Riccati solution, which holds products of weights, loses its digits
(lqr.yaw.Q = [1e300, 1] designed a 1e150 gain and crashed the simulation)."""


def weight_matrix(value: list, size: int):
    """A weight as a (size, size) numpy array: a list is a diagonal, a nested list a matrix."""
    import numpy as np

    arr = np.asarray(value, dtype=float)
    return np.diag(arr) if arr.ndim == 1 else arr


def _out_of_range(magnitudes):
    """Where a weight's magnitude is neither 0 nor within :data:`WEIGHT_RANGE` (any shape, elementwise)."""
    import numpy as np

    mag = np.asarray(magnitudes, dtype=float)
    return (mag != 0) & ~((mag >= WEIGHT_RANGE[0]) & (mag <= WEIGHT_RANGE[1]))


def _definite(low, top, definite: bool):
    """Whether a weight whose smallest eigenvalue is ``low`` and largest magnitude ``top`` (arrays of
    many weights, or floats) is positive definite (``definite``, for R) or semidefinite (Q), up to the
    floor :data:`DEFINITENESS_RTOL` of its scale."""
    import numpy as np

    floor = DEFINITENESS_RTOL * np.maximum(top, 1e-300)
    return low > floor if definite else low >= -floor


def check_weight(value: list, size: int, path: str, label: str, *, definite: bool,
                 names: list[str]) -> None:
    """Check Q (PSD) or R (PD): size, symmetry, definiteness; raise ConfigError naming ``path``.

    The range and definiteness rules are :func:`_out_of_range` and :func:`_definite`, which
    :func:`diagonal_weights_pass` applies to many diagonals at once.
    """
    import numpy as np

    nested = bool(value) and isinstance(value[0], list)
    if nested and any(not isinstance(row, list) for row in value):
        raise ConfigError(f"{label}: {path}: mixes numbers and rows; give a list (diagonal) or a list of rows")
    if (not nested and len(value) != size) or (nested and (len(value) != size or any(
            len(row) != size for row in value))):
        expect = f"{size} value{'s' if size != 1 else ''} (one per {', '.join(names)}) or a {size}x{size} matrix"
        if not nested:
            got = f"{len(value)} values"
        elif len({len(row) for row in value}) == 1:
            got = f"{len(value)}x{len(value[0])}"
        else:  # rows of different lengths: a shape would name one of them only
            got = f"rows of {', '.join(str(len(row)) for row in value)} values"
        raise ConfigError(f"{label}: {path} = {show(value)}: expected {expect}, got {got}")
    flat = np.abs(np.array(value, dtype=float)).ravel()
    bad = np.flatnonzero(_out_of_range(flat))
    if bad.size:
        k = int(bad[0])
        where = f"{path}[{k}]" if not nested else f"{path}[{k // size}][{k % size}]"
        entry = value[k] if not nested else value[k // size][k % size]
        raise ConfigError(f"{label}: {where} = {show(entry)}: a weight must be 0 or between {WEIGHT_RANGE[0]:g} "
                          f"and {WEIGHT_RANGE[1]:g} in magnitude; the gains depend only on the "
                          "ratios of the weights: scale Q and R together")
    if nested:
        mat = weight_matrix(value, size)
        scale = max(float(np.abs(mat).max()), 1.0)
        if not np.allclose(mat, mat.T, rtol=0, atol=SYMMETRY_RTOL * scale):
            raise ConfigError(f"{label}: {path} = {show(value)}: not symmetric; make it equal to its transpose")
        eig = np.linalg.eigvalsh((mat + mat.T) / 2)
        low, top = float(eig.min()), float(np.abs(eig).max())
    else:  # a diagonal is symmetric and its eigenvalues are its entries
        low, top = float(min(value)), float(flat.max())
    if not _definite(low, top, definite):
        kind, fix = ("positive definite", "positive") if definite else ("positive semidefinite", "nonnegative")
        raise ConfigError(f"{label}: {path} = {show(value)}: must be {kind} "
                          f"(smallest eigenvalue {low:.3g}); use {fix} weights")


def diagonal_weights_pass(values, *, definite: bool):
    """Which of many diagonal weights :func:`check_weight` passes, at once (a sweep checks thousands):
    the same rules (:func:`_out_of_range`, :func:`_definite`) on each row.

    Parameters
    ----------
    values : (N, size) array_like of float
        One diagonal a row, finite (the schema's check comes first).
    definite : bool

    Returns
    -------
    (N,) ndarray of bool
        True where :func:`check_weight` raises nothing; a False row goes through it for its message.
    """
    import numpy as np

    w = np.asarray(values, dtype=float)
    mag = np.abs(w)
    return ~_out_of_range(mag).any(axis=1) & _definite(w.min(axis=1), mag.max(axis=1), definite)
