"""Values as JSON artifacts hold them: numpy arrays, complex numbers and non-finite floats as plain
JSON (:func:`jsonable`), and back (:func:`decode_floats`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

INFINITY = {math.inf: "inf", -math.inf: "-inf"}
"""How JSON artifacts spell an infinite float (JSON has no infinity): a string, so that ``null``
means only "not a number / does not apply"."""


def jsonable(value: Any) -> Any:
    """numpy arrays, complex numbers and non-finite floats as plain JSON values.

    The one place that maps values to JSON for every artifact and ``--json``:

    - a complex number is ``[re, im]``, so a complex-dtype array is a list of pairs, always
      (an array that may hold complex values, eigenvalues say, must be given as a complex
      dtype: a real-dtype array is written as plain floats);
    - ``inf`` and ``-inf`` are the strings ``"inf"`` and ``"-inf"`` (:data:`INFINITY`);
    - NaN is ``null``, as is None: not a number, or not applicable.

    >>> jsonable({"e": np.array([-2.0, 1 + 2j]), "gm": (-math.inf, 6.0), "w": float("nan")})
    {'e': [[-2.0, 0.0], [1.0, 2.0]], 'gm': ['-inf', 6.0], 'w': None}

    :func:`decode_floats` turns the strings back into floats.
    """
    kind = type(value)
    if kind is float:
        return value if value - value == 0.0 else _non_finite(value)
    if kind in _AS_IS:
        return value
    if kind is dict:  # a sweep's rows: ~50 plain scalars each, kept without a call (1000 rows: 0.04 -> 0.008 s)
        return {k if type(k) is str else str(k):
                v if type(v) in _AS_IS or (type(v) is float and v - v == 0.0) else jsonable(v)
                for k, v in value.items()}
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (complex, np.complexfloating)):
        return [jsonable(float(value.real)), jsonable(float(value.imag))]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if math.isfinite(value):
            return value
        return _non_finite(value)
    return value


_AS_IS = frozenset({str, int, bool, type(None)})
"""The types :func:`jsonable` returns unchanged (exactly these: a subclass such as ``np.float64``
or an ``IntEnum`` is converted)."""


def _non_finite(value: float):
    return None if math.isnan(value) else INFINITY[value]


def complex_values(values) -> np.ndarray | None:
    """``values`` as a complex array (None stays None).

    How a payload hands :func:`jsonable` an array that may hold complex numbers (eigenvalues),
    so that it is written as ``[re, im]`` pairs even when every value happens to be real.

    >>> jsonable(complex_values([-2.0, -3.0]))
    [[-2.0, 0.0], [-3.0, 0.0]]
    """
    return None if values is None else np.asarray(values, dtype=complex)


def decode_floats(value: Any) -> Any:
    """The inverse of :func:`jsonable` for infinities: ``"inf"`` / ``"-inf"`` back to floats,
    in nested dicts and lists (every other value unchanged).

    >>> decode_floats({"gm": ["-inf", 6.0], "name": "roll"})
    {'gm': [-inf, 6.0], 'name': 'roll'}
    """
    if isinstance(value, dict):
        return {k: decode_floats(v) for k, v in value.items()}
    if isinstance(value, list):
        return [decode_floats(v) for v in value]
    if isinstance(value, str) and value in _FROM_JSON:
        return _FROM_JSON[value]
    return value


_FROM_JSON = {text: number for number, text in INFINITY.items()}
