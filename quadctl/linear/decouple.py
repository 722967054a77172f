"""Partition the 12-state linear model into subsystems, and account for what that drops.

A subsystem keeps the diagonal block ``A[S, S]`` of its states ``S`` and the columns of
``B`` for its inputs. An unregulated subsystem (the report's ``guidance``) may name states
as its inputs; their columns are then taken from ``A``. Every other entry of ``A`` and
``B`` is a coupling that the decoupled design ignores: :func:`decouple` lists them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.layout import INPUT_INDEX, INPUT_NAMES, STATE_INDEX, STATE_NAMES, unit_of

DROP_RTOL = 1e-12
"""An entry counts as dropped when ``|value| > DROP_RTOL * max|A|, max|B|`` (round-off is not a term)."""


@dataclass(frozen=True, eq=False)
class Subsystem:
    """One block of a partition.

    Attributes
    ----------
    name : str
    states : tuple of str
    inputs : tuple of str
        Input names, or state names for an unregulated subsystem driven by states.
    A : (n, n) ndarray
    B : (n, m) ndarray
    C : (p, n) ndarray
        Measured outputs (identity unless the config names ``outputs``).
    regulated : bool
    """

    name: str
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    regulated: bool

    @property
    def state_index(self) -> list[int]:
        """Indices of ``states`` in the 12-state vector."""
        return [STATE_INDEX[s] for s in self.states]


@dataclass(frozen=True)
class DroppedTerm:
    """An entry of A or B that the partition ignores.

    ``name`` reads ``d(u)/d(T)``: the derivative of ``du/dt`` with respect to ``T``;
    ``relative`` is ``|value|`` scaled by the largest entry of the same matrix.
    """

    name: str
    matrix: str
    row: str
    column: str
    value: float
    relative: float
    unit: str


@dataclass(frozen=True, eq=False)
class Decoupled:
    """A partition of a linear model.

    Attributes
    ----------
    subsystems : tuple of Subsystem
    dropped : tuple of DroppedTerm
        A's terms, then B's, each by ``|value|``, largest first.
    A_kept : (12, 12) ndarray
        The block model the partition keeps, in the 12-state layout (dropped terms zeroed).
    """

    subsystems: tuple[Subsystem, ...]
    dropped: tuple[DroppedTerm, ...]
    A_kept: np.ndarray

    def __getitem__(self, name: str) -> Subsystem:
        for sub in self.subsystems:
            if sub.name == name:
                return sub
        raise KeyError(name)

    @property
    def regulated(self) -> tuple[Subsystem, ...]:
        """The subsystems that get an LQR loop."""
        return tuple(s for s in self.subsystems if s.regulated)


def decouple(A, B, partition: dict) -> Decoupled:
    """Split ``(A, B)`` into the subsystems of ``partition``.

    Parameters
    ----------
    A : (12, 12) array_like
    B : (12, 4) array_like
    partition : dict
        ``name -> {states, inputs, regulate, outputs}`` (mappings or objects with those
        attributes, such as the config's ``SubsystemConfig``).

    Returns
    -------
    Decoupled
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    kept_a = np.zeros_like(A, dtype=bool)
    kept_b = np.zeros_like(B, dtype=bool)
    subs = []
    for name, spec in partition.items():
        spec = spec if isinstance(spec, dict) else spec.model_dump()
        states = tuple(spec["states"])
        inputs = tuple(spec["inputs"])
        rows = [STATE_INDEX[s] for s in states]
        a_sub = A[np.ix_(rows, rows)]
        kept_a[np.ix_(rows, rows)] = True
        b_cols = []
        for inp in inputs:
            if inp in INPUT_INDEX:
                b_cols.append(B[rows, INPUT_INDEX[inp]])
                kept_b[rows, INPUT_INDEX[inp]] = True
            else:  # a state used as an input (the report's guidance)
                b_cols.append(A[rows, STATE_INDEX[inp]])
                kept_a[rows, STATE_INDEX[inp]] = True
        outputs = spec.get("outputs") or states
        c = np.eye(len(states))[[states.index(o) for o in outputs]]
        subs.append(Subsystem(name=name, states=states, inputs=inputs, A=a_sub,
                              B=np.column_stack(b_cols), C=c,
                              regulated=bool(spec.get("regulate", True))))
    dropped = _dropped_terms(A, kept_a, "A", STATE_NAMES) + _dropped_terms(B, kept_b, "B", INPUT_NAMES)
    dropped.sort(key=lambda d: (d.matrix, -abs(d.value)))
    return Decoupled(subsystems=tuple(subs), dropped=tuple(dropped),
                     A_kept=np.where(kept_a, A, 0.0))


def _dropped_terms(mat, kept, label, column_names) -> list[DroppedTerm]:
    scale = float(np.abs(mat).max()) or 1.0
    out = []
    for i, j in zip(*np.nonzero(~kept & (np.abs(mat) > DROP_RTOL * scale))):
        row, col = STATE_NAMES[i], column_names[j]
        out.append(DroppedTerm(
            name=f"d({row})/d({col})", matrix=label, row=row, column=col,
            value=float(mat[i, j]), relative=float(abs(mat[i, j]) / scale),
            unit=_derivative_unit(row, col)))
    return out


def _derivative_unit(row: str, col: str) -> str:
    """Unit of ``d(row_dot)/d(col)``: (unit of row)/s per unit of col."""
    num, den = unit_of(row), unit_of(col)
    return f"({num})/s/({den})"
