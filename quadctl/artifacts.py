"""The run directory: writing and reading artifacts atomically, with provenance.

Every artifact carries ``quadctl_version``, ``config_hash``, ``config_name``, ``state_names``,
``input_names``; JSON artifacts also a ``created`` timestamp, the only field that differs
between two runs of the same config (NPZ artifacts are byte-identical). JSON is written
with sorted keys and NPZ with fixed zip timestamps, so the same config gives byte-identical
artifacts apart from ``created``.
"""

from __future__ import annotations

import io
import json
import math
import os
import tempfile
import zipfile
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from quadctl import __version__
from quadctl.errors import ArtifactError
from quadctl.layout import INPUT_NAMES, STATE_NAMES

FORMAT_VERSION = 1
"""Bumped when the layout of an artifact changes incompatibly."""


def metadata(cfg, kind: str) -> dict:
    """Provenance fields every artifact carries."""
    return {
        "artifact": kind,
        "format_version": FORMAT_VERSION,
        "quadctl_version": __version__,
        "config_name": cfg.name,
        "config_hash": cfg.digest(),
        "created": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "state_names": list(STATE_NAMES),
        "input_names": list(INPUT_NAMES),
    }


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
        return None if math.isnan(value) else INFINITY[value]
    return value


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


def _atomic_write(path: Path, data: bytes) -> None:
    """Write to a temporary file in the same folder, fsync, then rename over ``path``."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise ArtifactError(f"{path.parent}: cannot write artifacts there ({exc.strerror}); "
                            "choose another --out folder") from None
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes 0600; artifacts are shared like any file
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


STALE_TEMPORARY_AGE = 60.0
"""s; a temporary older than this was left by a killed run (a live write takes milliseconds)."""


def remove_stale_temporaries(folder: Path) -> list[Path]:
    """Delete temporaries that a killed run left in ``folder`` (``.<name>.*.tmp``); return them."""
    import time

    folder = Path(folder)
    if not folder.is_dir():
        return []
    now = time.time()
    stale = [p for p in folder.rglob(".*.tmp") if now - p.stat().st_mtime > STALE_TEMPORARY_AGE]
    for p in stale:
        p.unlink(missing_ok=True)
    return stale


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json(path: Path, payload: dict) -> Path:
    """Write ``payload`` as indented, key-sorted JSON, atomically."""
    text = json.dumps(jsonable(payload), indent=1, sort_keys=True, allow_nan=False)
    _atomic_write(path, (text + "\n").encode())
    return Path(path)


def write_npz(path: Path, arrays: dict[str, Any], meta: dict) -> Path:
    """Write arrays (and ``meta`` as a JSON string under ``meta``) as an NPZ, atomically.

    Zip entries get a fixed timestamp, and ``created`` is left out of ``meta`` (the zip's CRCs
    would carry it), so the same arrays give the same bytes.
    """
    meta = {k: v for k, v in meta.items() if k != "created"}
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        items = dict(arrays)
        items["meta"] = np.array(json.dumps(jsonable(meta), sort_keys=True))
        for name in sorted(items):
            arr = np.asarray(items[name])
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            member = io.BytesIO()
            np.lib.format.write_array(member, arr, allow_pickle=False)
            zf.writestr(info, member.getvalue())
    _atomic_write(path, buf.getvalue())
    return Path(path)


def write_bytes(path: Path, data: bytes) -> Path:
    _atomic_write(path, data)
    return Path(path)


def read_json(path: Path) -> dict:
    """Read a JSON artifact; ArtifactError names the file if it is corrupt or foreign."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ArtifactError(f"{path}: corrupted artifact ({_reason(exc)}); "
                            "delete it or rerun with --fresh") from None
    _check_provenance(path, data if isinstance(data, dict) else {})
    return data


def read_npz(path: Path) -> tuple[dict[str, np.ndarray], dict]:
    """Read an NPZ artifact: (arrays, meta)."""
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
        meta = json.loads(str(arrays.pop("meta")))
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError) as exc:
        raise ArtifactError(f"{path}: corrupted artifact ({_reason(exc)}); "
                            "delete it or rerun with --fresh") from None
    _check_provenance(path, meta)
    return arrays, meta


def _check_provenance(path, meta: dict) -> None:
    if meta.get("format_version") != FORMAT_VERSION or "config_hash" not in meta:
        version = meta.get("quadctl_version", "unknown")
        raise ArtifactError(f"{path}: written by quadctl {version} in another format; "
                            "delete it or rerun with --fresh")


def _reason(exc: Exception) -> str:
    text = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return text.splitlines()[0][:120]


def is_fresh(path: Path, cfg) -> bool:
    """True if ``path`` exists and was made from this exact config by this quadctl version.

    Raises ArtifactError if it exists but is corrupt or of a foreign format.
    """
    path = Path(path)
    if not path.exists():
        return False
    meta = read_npz(path)[1] if path.suffix == ".npz" else read_json(path)
    return meta.get("config_hash") == cfg.digest() and meta.get("quadctl_version") == __version__
