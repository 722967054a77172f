"""Shapes and weights of Riccati problems, checked once for every solver (SciPy's ``_are_validate_args``).

One problem (:func:`as_problem`) or a stack of them (:func:`as_stack`); :class:`WeightCheck` decides
for each whether its weights are valid and says why not, in one line naming the matrix, what was
found and the fix. The one-case solvers raise that line as a :class:`~quadctl.errors.DesignError`;
the stacked ones mark the entry not ok.
"""

from __future__ import annotations

import numpy as np

from quadctl.errors import ArgumentError, DesignError

SEMIDEFINITE_RTOL = 1e-12
"""``Q`` and ``[[Q, N], [N', R]]`` count as positive semidefinite while their most negative eigenvalue
is above ``-SEMIDEFINITE_RTOL`` times the scale of the cost, the largest eigenvalue magnitude of
``[[Q, N], [N', R]]``: room for the round-off of computed weights, measured against that scale
because a weight that is zero (``Q = 0``) is computed as noise of the other weights' size.
Van Loan's integrals (:func:`quadctl.design.discrete.lqrd_weights`) of 20 000 random stiff problems
(``|eig(A)| Ts <= 10``, rank-deficient ``Q``) came out at -4.7e-16 at worst (``tests/design/test_riccati.py``
checks quadctl's own subsystems); a weight that is really indefinite is far below (CAREX 2.5: -13.2
against 0.23)."""


def real_array(M, label: str, *, name: str = "system", shape: tuple | None = None, ndim: int | None = None,
               error: type[Exception] = ArgumentError) -> np.ndarray:
    """``M`` as a float array, refusing what a float conversion would change or lose.

    The one check of a matrix argument for every public function that takes one (the Riccati
    solvers, :mod:`quadctl.design.discrete`, :func:`quadctl.design.closed_loop_matrix`, :mod:`quadctl.export.interop`):
    quadctl's solvers are real-only, so a complex matrix is refused (NumPy's conversion would drop
    its imaginary part with only a ``ComplexWarning`` and the answer would be certified for another
    problem), as are text, objects and ragged lists. ``ndim`` pads with leading axes
    (:func:`numpy.atleast_2d` for 2); ``shape`` is then checked, ``None`` entries free.

    Parameters
    ----------
    M : array_like
    label : str
        The argument's name in the message (``A``, ``K_block``).
    name : str
        The system or function the message names first.
    shape : tuple of int or None, optional
    ndim : int, optional
    error : exception class
        Raised with the message (default :class:`~quadctl.errors.ArgumentError`).

    Examples
    --------
    >>> real_array([[1, 2]], "B", shape=(1, 2)).dtype
    dtype('float64')
    >>> try:
    ...     real_array([[2, 1 - 2j], [0, -3j]], "A", name="dlqr")
    ... except ArgumentError as exc:
    ...     print(str(exc)[:72])
    dlqr: A is complex (dtype complex128); quadctl solves real problems only
    """
    if M is None:
        raise error(f"{name}: {label} is None; give an array of numbers")
    try:
        arr = np.asarray(M)
    except (TypeError, ValueError) as exc:
        raise error(f"{name}: {label} is not a numeric matrix ({exc}); give an array of numbers") from None
    if arr.dtype.kind == "c":
        raise error(f"{name}: {label} is complex (dtype {arr.dtype}); quadctl solves real problems only: give the "
                    "real matrix (SciPy's solve_continuous_are and solve_discrete_are take complex ones)")
    if arr.dtype.kind not in "biuf":
        if hasattr(M, "toarray"):  # scipy.sparse: np.asarray wraps it in a 0-d object array
            raise error(f"{name}: {label} is a sparse matrix ({type(M).__name__}); give the dense one, "
                        f"{label}.toarray()")
        raise error(f"{name}: {label} is not a numeric matrix (dtype {arr.dtype}); give an array of numbers")
    arr = arr.astype(float)
    if ndim is not None and arr.ndim < ndim:
        arr = arr.reshape((1,) * (ndim - arr.ndim) + arr.shape)
    if shape is not None and (arr.ndim != len(shape)
                              or any(e is not None and e != d for e, d in zip(shape, arr.shape))):
        want = " x ".join("?" if e is None else str(e) for e in shape)
        raise error(f"{name}: {label} has shape {arr.shape}, expected {want}")
    return arr


def as_problem(A, B, Q, R, N=None, *, name: str = "system"):
    """``(A, B, Q, R, N)`` as float 2-D arrays of consistent shapes (``N`` zero when not given).

    Raises
    ------
    ArgumentError
        A matrix is not numeric, or its shape does not fit (the message names it).
    """
    mats = {label: real_array(M, label, name=name, ndim=2)
            for label, M in (("A", A), ("B", B), ("Q", Q), ("R", R), ("N", N)) if M is not None or label != "N"}
    if np.ndim(A) == 1 and np.size(A) > 1:
        raise ArgumentError(f"{name}: A has shape {np.shape(A)}, a 1-D array; give the (n, n) state matrix")
    n, m = mats["A"].shape[0], mats["B"].shape[-1]
    if np.ndim(B) == 1 and mats["B"].shape[1] == n != 1:  # padded to a row: one input was meant as a column
        raise ArgumentError(f"{name}: B has shape {np.shape(B)}, a 1-D array read as the row (1, {n}); for one input "
                            f"give the column, shape ({n}, 1): [[b1], [b2], ...] or np.reshape(B, (-1, 1))")
    for label, M, shape in (("Q", Q, (n, n)), ("R", R, (m, m)), ("N", N, (n, m))):
        if np.ndim(M) == 1 and np.size(M) > 1:  # padded to a row, it was reported as shape (1, k)
            fix = f": np.diag({label}) for a diagonal weight" if label != "N" and np.size(M) == shape[0] else ""
            raise ArgumentError(f"{name}: {label} has shape {np.shape(M)}, a 1-D array; give the {shape} matrix{fix}")
    mats.setdefault("N", np.zeros((n, m)))
    _check_shapes(mats, (), n, m, name)
    return tuple(mats[k] for k in "ABQRN")


def as_stack(A, B, Q=None, R=None, N=None, *, name: str):
    """Stacked float arrays ``A (batch, n, n)``, ``B (batch, n, m)``, ``Q``, ``R``, ``N`` with their
    shapes checked; ``N`` zero when not given, ``Q`` and ``R`` None when not given.

    Raises
    ------
    ArgumentError
        A matrix is not numeric, or the shapes do not stack (the message names the matrix and ``name``).
    """
    mats = {label: real_array(M, label, name=name) for label, M in (("A", A), ("B", B), ("Q", Q), ("R", R))
            if M is not None}
    if mats["B"].ndim != 3:
        raise ArgumentError(f"{name}: B has shape {mats['B'].shape}; stack the problems as A (batch, n, n), "
                            "B (batch, n, m), Q (batch, n, n), R (batch, m, m)")
    batch, n, m = mats["B"].shape
    mats["N"] = np.zeros((batch, n, m)) if N is None else real_array(N, "N", name=name)
    _check_shapes(mats, (batch,), n, m, name)
    return tuple(mats.get(k) for k in "ABQRN")


def _check_shapes(mats: dict, lead: tuple, n: int, m: int, name: str) -> None:
    if "R" in mats and not (n and m):  # a weighted problem (not c2d's plant) with nothing to regulate or no input
        raise ArgumentError(f"{name}: the problem has {n} states and {m} inputs (B has shape {mats['B'].shape}); "
                            "an LQR problem needs at least one of each")
    expected = {"A": (n, n), "B": (n, m), "Q": (n, n), "R": (m, m), "N": (n, m)}
    for label, M in mats.items():
        shape = (*lead, *expected[label])
        if M.shape != shape:
            raise ArgumentError(f"{name}: {label} has shape {M.shape}, expected {shape} "
                                f"(A is n x n, B n x m, Q n x n, R m x m, N n x m with n = {n}, m = {m})")


class WeightCheck:
    """What is wrong with the weights of each stacked problem (SciPy's ``_are_validate_args``, plus
    definiteness): finite entries, ``Q`` and ``R`` symmetric to 100 ulp of their 1-norm, ``R``
    positive definite (smallest eigenvalue above ``m`` ulp of its largest), ``Q`` and
    ``[[Q, N], [N', R]]`` positive semidefinite (``SEMIDEFINITE_RTOL``).

    ``ok`` is the (batch,) mask of valid problems; :meth:`reason` explains entry ``k`` in one line.
    """

    def __init__(self, A, B, Q, R, N):
        self._mats = {"A": A, "B": B, "Q": Q, "R": R, "N": N}
        batch = len(B)
        finite = np.isfinite(np.concatenate([M.reshape(batch, -1) for M in self._mats.values()], axis=1)).all(axis=1)
        if finite.all():  # the common case, in three calls
            self._finite = dict.fromkeys(self._mats, finite)
            clean = self._mats
        else:
            self._finite = {label: np.isfinite(M).all(axis=(-2, -1)) for label, M in self._mats.items()}
            clean = {label: np.where(finite[:, None, None], M, 0.0) for label, M in self._mats.items()}
        self._asym, self._sym_tol, self._eig = {}, {}, {}
        with np.errstate(all="ignore"):
            for label in "QR":
                M = clean[label]
                self._asym[label] = norm1(M - M.transpose(0, 2, 1))
                self._sym_tol[label] = 100 * np.spacing(norm1(M))
                self._eig[label] = np.linalg.eigvalsh(M)  # reads one triangle: the symmetric part's, if symmetric
            cross = np.any(clean["N"] != 0, axis=(1, 2))
            if cross.any():
                W = np.concatenate([np.concatenate([clean["Q"], clean["N"]], axis=2),
                                    np.concatenate([clean["N"].transpose(0, 2, 1), clean["R"]], axis=2)], axis=1)
                self._eig["W"] = np.linalg.eigvalsh(W)
            else:
                self._eig["W"] = np.zeros((len(cross), 1))
            # the cost's scale, max |eig([[Q, N], [N', R]])|: that of Q and R alone when N = 0
            self._scale = np.max([np.abs(self._eig[k]).max(axis=1) for k in "QRW"], axis=0)
        self._tests = [  # (failed mask, reason) in the order they are reported
            *((~self._finite[label], self._nonfinite) for label in "ABQRN"),
            *((self._asym[label] > self._sym_tol[label], self._asymmetric) for label in "QR"),
            (self._not_definite("R"), self._indefinite_r),
            (self._not_semidefinite("Q"), self._indefinite_q),
            (cross & self._not_semidefinite("W"), self._indefinite_w),
        ]
        self._labels = [*"ABQRN", "Q", "R", "R", "Q", "W"]
        self.ok = ~np.logical_or.reduce([mask for mask, _ in self._tests])

    def _not_definite(self, label):
        lam = self._eig[label]
        return ~(lam[:, 0] > lam.shape[1] * np.finfo(float).eps * np.abs(lam).max(axis=1))

    def _not_semidefinite(self, label):
        return self._eig[label][:, 0] < -SEMIDEFINITE_RTOL * self._scale

    def reason(self, k: int) -> str | None:
        """Why problem ``k`` is refused (one line, without the system's name), or None."""
        for (mask, explain), label in zip(self._tests, self._labels):
            if mask[k]:
                return explain(label, k)
        return None

    def _nonfinite(self, label, k):
        M = self._mats[label][k]
        i, j = np.argwhere(~np.isfinite(M))[0]
        return (f"{label} has a non-finite entry ({M[i, j]} at [{i}, {j}]); every entry of A, B, Q, R "
                "and N must be a finite number")

    def _asymmetric(self, label, k):
        M = self._mats[label][k]
        i, j = np.unravel_index(np.argmax(np.abs(M - M.T)), M.shape)
        return (f"{label} is not symmetric: {label}[{i}, {j}] = {M[i, j]:.6g} but {label}[{j}, {i}] = "
                f"{M[j, i]:.6g} (|{label} - {label}'|_1 = {self._asym[label][k]:.3g}, tolerance "
                f"{self._sym_tol[label][k]:.3g}); make it symmetric, e.g. ({label} + {label}') / 2")

    def _indefinite_r(self, label, k):
        lam = self._eig["R"][k]
        return (f"R is not positive definite: its smallest eigenvalue is {lam[0]:.3g} (largest {lam[-1]:.3g}); "
                "every input needs a positive weight: make R symmetric positive definite, "
                "e.g. a diagonal of positive values")

    def _indefinite_q(self, label, k):
        lam = self._eig["Q"][k]
        return (f"Q is not positive semidefinite: its most negative eigenvalue is {lam[0]:.3g} "
                f"(largest {lam[-1]:.3g}), so the cost would reward some deviations; make Q positive "
                "semidefinite, e.g. C' C or a diagonal of non-negative values")

    def _indefinite_w(self, label, k):
        lam = self._eig["W"][k]
        return (f"[[Q, N], [N', R]] is not positive semidefinite: its most negative eigenvalue is "
                f"{lam[0]:.3g} (largest {lam[-1]:.3g}): the cross weight N is too large for Q and R "
                "(x'Qx + 2x'Nu + u'Ru goes negative); shrink N, or raise Q or R")


def require_valid_weights(A, B, Q, R, N=None, *, name: str = "system") -> None:
    """Raise a DesignError naming the system, the matrix, what was found and the fix (see :class:`WeightCheck`).

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    Q : (n, n) array_like
    R : (m, m) array_like
    N : (n, m) array_like, optional
    name : str
        Names the system in the error.

    Examples
    --------
    CAREX 2.5 (Abels & Benner 1999) at eps = 0 weighs the states with an indefinite ``Q``:

    >>> require_valid_weights([[3, 1], [4, 2]], [[1], [1]], [[-11, -5], [-5, -2]], [[1]], name="carex")
    Traceback (most recent call last):
    ...
    quadctl.errors.DesignError: carex: Q is not positive semidefinite: its most negative eigenvalue is -13.2 ...
    """
    A, B, Q, R, N = as_problem(A, B, Q, R, N, name=name)
    reason = WeightCheck(*(M[None] for M in (A, B, Q, R, N))).reason(0)
    if reason is not None:
        raise DesignError(f"{name}: {reason}")


def neutral(ok, A, B, Q, R, N):
    """The stack with the entries that are not ok replaced by a harmless problem (A = -I, B = 0,
    Q = I, R = I, N = 0), so that no NaN or indefinite weight reaches LAPACK."""
    if ok.all():
        return A, B, Q, R, N
    n, m = B.shape[1:]
    bad = ~ok[:, None, None]
    return (np.where(bad, -np.eye(n), A), np.where(bad, 0.0, B), np.where(bad, np.eye(n), Q),
            np.where(bad, np.eye(m), R), np.where(bad, 0.0, N))


def norm1(M) -> np.ndarray:
    """Matrix 1-norms (largest column sum) of a stack."""
    return np.abs(M).sum(axis=-2).max(axis=-1)
