"""Reading artifacts back, with their provenance and content checked: what a later stage may reuse
(:func:`is_fresh`), and what is damaged (:class:`InvalidArtifact`)."""

from __future__ import annotations

import json
import os
import warnings
import zipfile
from pathlib import Path

import numpy as np

from quadctl.artifacts.meta import FORMAT_VERSION
from quadctl.artifacts.places import IS_A_DIRECTORY, reason_of, refuse_link
from quadctl.errors import ArtifactError, QuadctlNotice
from quadctl.layout import N_INPUTS, N_STATES, STATE_NAMES
from quadctl.version import __version__


class InvalidArtifact(ArtifactError):
    """An artifact whose provenance is intact but whose content is not what quadctl writes (a key
    missing, an array of the wrong shape, a value not finite): not fresh; recompute it.

    Uncaught it is a bad-input error (exit 2) that names the file, the key and the way out.
    """

    def __init__(self, path: Path | str, problem: str):
        super().__init__(f"{path}: invalid artifact: {problem}; delete it or rerun with --fresh")
        self.path = Path(path)
        self.problem = problem
        """What is wrong, in a few words (``K_block is 3×12, expected 4×12``)."""


NAMES = "state names"
"""Schema entry: a list of state names."""

SCHEMAS: dict[str, dict[str, tuple | str]] = {
    "trim.json": {"x": (N_STATES,), "u": (N_INPUTS,), "xdot": (N_STATES,), "residual": (), "iterations": ()},
    "linear.npz": {"A": (N_STATES, N_STATES), "B": (N_STATES, N_INPUTS), "x_trim": (N_STATES,),
                   "u_trim": (N_INPUTS,), "x_rate": (N_STATES,)},
    "design.json": {"K_block": (N_INPUTS, N_STATES), "integral_states": NAMES,
                    "Ki_block": (N_INPUTS, "integral_states")},
}
"""What a later stage reads back from each artifact: key -> shape of a finite float array (a
dimension given as a key is that key's length), or :data:`NAMES`. :func:`read_json` and
:func:`read_npz` check it for every artifact named here."""


def validate(path: Path | str, data: dict) -> None:
    """Check ``data`` (a JSON artifact, or an NPZ's arrays) against ``SCHEMAS[path.name]``.

    Raises
    ------
    InvalidArtifact
        Naming the file, the key and what is wrong.

    Examples
    --------
    >>> validate("runs/forward/trim.json", {"x": [0.0] * 12, "u": [0.6, 0, 0, 0], "xdot": [0.0] * 12,
    ...                                     "residual": 1e-15, "iterations": 4})
    >>> try:
    ...     validate("runs/forward/design.json", {"K_block": [[0.0] * 12] * 3, "integral_states": [],
    ...                                           "Ki_block": [[]] * 4})
    ... except InvalidArtifact as exc:
    ...     print(exc)
    runs/forward/design.json: invalid artifact: K_block is 3×12, expected 4×12; delete it or rerun with --fresh
    """
    schema = SCHEMAS.get(Path(path).name)
    if schema is None:
        return
    for key, spec in schema.items():
        problem = _problem(data, key, spec)
        if problem:
            raise InvalidArtifact(path, problem)


def _problem(data: dict, key: str, spec) -> str | None:
    if key not in data:
        return f"{key} is missing"
    value = data[key]
    if spec == NAMES:
        names = value.tolist() if isinstance(value, np.ndarray) else value
        if not isinstance(names, list) or not all(isinstance(n, str) and n in STATE_NAMES for n in names):
            return f"{key} is not a list of state names"
        return None
    try:
        array = np.asarray(value)
        if array.dtype.kind in "USV":  # "1.5" or "inf": a string, not a number quadctl wrote
            raise TypeError
        array = array.astype(float)  # a null (None) is NaN: caught as not finite below
    except (TypeError, ValueError):
        return f"{key} is not an array of numbers"
    expected = tuple(len(data.get(d) or ()) if isinstance(d, str) else d for d in spec)
    if array.shape != expected:
        return f"{key} is {_shape(array.shape)}, expected {_shape(expected)}"
    if not np.all(np.isfinite(array)):
        return f"{key} has values that are not finite"
    return None


def _shape(shape: tuple) -> str:
    return "a scalar" if not shape else "×".join(str(n) for n in shape)


def read_json(path: Path) -> dict:
    """Read a JSON artifact, checking its provenance and (for those in :data:`SCHEMAS`) content.

    Raises
    ------
    ArtifactError
        Corrupt (not JSON), or written in another format.
    InvalidArtifact
        Provenance intact, content not what quadctl writes (:func:`validate`).
    """
    _refuse_directory(path)
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ArtifactError(f"{path}: corrupted artifact ({reason_of(exc)}); "
                            "delete it or rerun with --fresh") from None
    _check_provenance(path, data if isinstance(data, dict) else {})
    validate(path, data)
    return data


def read_npz(path: Path) -> tuple[dict[str, np.ndarray], dict]:
    """Read an NPZ artifact: (arrays, meta); errors as :func:`read_json`."""
    _refuse_directory(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
        meta = json.loads(str(arrays.pop("meta")))
    except OSError as exc:  # a read that failed (permissions, a disk error): say why
        raise ArtifactError(f"{path}: corrupted artifact ({reason_of(exc)}); "
                            "delete it or rerun with --fresh") from None
    except (ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError):  # not NumPy's allow_pickle advice
        raise ArtifactError(f"{path}: corrupted artifact: not a valid quadctl artifact (an .npz of named arrays "
                            "and its meta record); rerun with --fresh to recompute it") from None
    _check_provenance(path, meta if isinstance(meta, dict) else {})
    validate(path, arrays)
    return arrays, meta


def _refuse_directory(path) -> None:
    refuse_link(Path(path))
    if Path(path).is_dir():
        raise ArtifactError(IS_A_DIRECTORY.format(path=path))


def _check_provenance(path, meta: dict) -> None:
    if meta.get("format_version") != FORMAT_VERSION or "config_hash" not in meta:
        version = meta.get("quadctl_version", "unknown")
        raise ArtifactError(f"{path}: written by quadctl {version} in another format; "
                            "delete it or rerun with --fresh")


def is_fresh(path: Path, cfg) -> bool:
    """True if ``path`` exists, was made from this exact config by this quadctl version, and
    holds what quadctl writes (:func:`validate`): then a stage may reuse it.

    False for a missing, stale or invalid artifact (recompute it). An invalid one is named first,
    in a :class:`~quadctl.errors.QuadctlNotice` (the command line prints it as ``quadctl: note:
    design.json in runs/forward is damaged (K_block is 3×12, expected 4×12); recomputed``): the
    result does not change, but the user learns that a file in their run folder was wrong.

    Raises
    ------
    ArtifactError
        It exists but is corrupt or of a foreign format.
    """
    path = Path(path)
    if os.path.islink(path):  # never read through a link: recomputed, and the write replaces the link
        return False
    if not path.exists():
        return False
    try:
        meta = read_npz(path)[1] if path.suffix == ".npz" else read_json(path)
    except InvalidArtifact as exc:
        warnings.warn(f"{path.name} in {path.parent} is damaged ({exc.problem}); recomputed", QuadctlNotice,
                      stacklevel=2)
        return False
    return meta.get("config_hash") == cfg.digest() and meta.get("quadctl_version") == __version__
