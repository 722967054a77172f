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
import re
import tempfile
import warnings
import zipfile
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from quadctl import __version__
from quadctl.errors import ArtifactError, QuadctlNotice
from quadctl.layout import INPUT_NAMES, N_INPUTS, N_STATES, STATE_NAMES

FORMAT_VERSION = 1
"""Bumped when the layout of an artifact changes incompatibly."""


def default_out(cfg) -> Path:
    """The run directory of a config when none is given: ``runs/<config name>``."""
    return Path("runs") / cfg.name


def metadata(cfg, kind: str, backends=()) -> dict:
    """Provenance fields every artifact carries.

    ``backends``: the simulation backends the stage ran (``SimResult.backend``), which decide the
    ``compiler`` field (see :func:`quadctl.provenance.compiler`); empty when it ran no loop.
    """
    from quadctl import provenance

    return {
        "artifact": kind,
        "format_version": FORMAT_VERSION,
        "quadctl_version": __version__,
        "config_name": cfg.name,
        "config_hash": cfg.digest(),
        "created": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "state_names": list(STATE_NAMES),
        "input_names": list(INPUT_NAMES),
        "software": provenance.software(),
        "compiler": provenance.compiler(backends),
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


# ---------------------------------------------------------------------------------------
# Names: what quadctl writes, and only there

ARTIFACT_NAMES = frozenset({
    "config.yaml", "config.resolved.yaml",
    "trim.json", "linear.npz", "subsystems.json", "checks.json", "design.json", "sim.npz", "sim.json",
    "margins.json", "design_full.json", "schedule.json", "schedule.npz",
    "sweep.csv", "sweep.json", "sweep.png", "montecarlo.npz", "montecarlo.png",
    "quadctl_controller.h", "quadctl_controller.c", "quadctl_controller.mat", "quadctl_controller.json",
})
"""Every file quadctl writes at the top of a run directory (tests check the workspace's, the
sweep's and the exports' names are among them)."""
PLOTS = "plots"
SUBFOLDER_NAMES = {
    PLOTS: re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*\.png"),
    "sweep.parts": re.compile(r"chunk-[0-9]+\.json"),
    "report": re.compile(r"report\.(html|md)|[A-Za-z0-9_][A-Za-z0-9_.+-]*\.png"),
}
"""The subfolders quadctl writes into, and the names it writes there."""
TEMPORARY_TAG = "quadctl"
"""A temporary is ``.<artifact>.quadctl-<random>.tmp``: the tag, and the artifact's registered
name, are what let a later run prove the file is quadctl's before it deletes it."""
_TEMPORARY = re.compile(rf"\.(?P<name>.+)\.{TEMPORARY_TAG}-[a-z0-9_]+\.tmp")


def plot_path(folder: Path | str, stem: str) -> Path:
    """``folder/plots/<stem>.png``, refusing a ``stem`` that is not a plain file name.

    A stem made from a config's name (a subsystem's, say) must not lead out of the run
    directory: ``../x`` or ``a/b`` is refused with :class:`~quadctl.errors.ArtifactError`.

    >>> plot_path("runs/forward", "roll").as_posix()
    'runs/forward/plots/roll.png'
    """
    name = f"{stem}.png"
    if not SUBFOLDER_NAMES[PLOTS].fullmatch(name):
        raise ArtifactError(f"{stem!r}: cannot name a figure in {Path(folder) / PLOTS} (only letters, digits "
                            "and _ . + - make a file name there); rename it in the config")
    return Path(folder) / PLOTS / name


def _subfolder(path: Path) -> Path | None:
    """The artifact folder ``path`` is in (``plots/``, ``report/``, ``sweep.parts/``), or None at the
    top of the run directory.

    An artifact path is ``<run dir>/<registered name>`` or ``<run dir>/<subfolder>/<name>``.
    Artifact names are constants (and figure names pass :func:`plot_path`), so a path that is
    neither is a bug: ValueError, before anything is written or deleted.
    """
    if path.name in ARTIFACT_NAMES:
        return None
    pattern = SUBFOLDER_NAMES.get(path.parent.name)
    if pattern is not None and pattern.fullmatch(path.name):
        return path.parent
    raise ValueError(f"{path}: not an artifact name quadctl writes (ARTIFACT_NAMES, SUBFOLDER_NAMES)")


def _safe_place(path: Path) -> Path:
    """``path``, checked to be a place quadctl may write or delete: a registered artifact name in the
    run directory or in one of its artifact folders, where that folder is not a symbolic link.

    The safe-write layer's one rule: every write (:func:`_atomic_write`, :func:`write_together`)
    and every delete (:func:`remove`) goes through here, so nothing quadctl does follows a link
    out of the run directory. A link in place of an artifact *file* is replaced by the rename
    (never followed, its target untouched); a link in place of an artifact *folder* is refused.

    Raises
    ------
    ArtifactError
        The artifact folder is a symbolic link (exit code 2, the message names it).
    ValueError
        Not a name quadctl writes (a bug).
    """
    path = Path(path)
    sub = _subfolder(path)
    if sub is not None and os.path.islink(sub):
        raise ArtifactError(_LINK.format(path=sub))
    return path


_LINK = ("{path}: is a symbolic link where quadctl keeps its own folder; quadctl never writes or deletes through "
         "a link: remove the link, or choose another --out folder")


def check_folder(folder: Path | str) -> Path:
    """``folder``, an artifact folder (``plots``, ``report``, ``sweep.parts``), checked not to be a
    symbolic link before quadctl lists, reads or deletes anything in it; ArtifactError (exit 2)
    naming it otherwise."""
    folder = Path(folder)
    if folder.name not in SUBFOLDER_NAMES:
        raise ValueError(f"{folder}: not an artifact folder quadctl writes (SUBFOLDER_NAMES)")
    if os.path.islink(folder):
        raise ArtifactError(_LINK.format(path=folder))
    return folder


def _refuse_link(path: Path) -> None:
    """A file quadctl reads back as its own artifact must not be a link (to anything, anywhere)."""
    if os.path.islink(path):
        raise ArtifactError(f"{path}: is a symbolic link, not an artifact quadctl wrote; remove it or rerun "
                            "with --fresh (quadctl replaces it)")
    sub = path.parent
    if sub.name in SUBFOLDER_NAMES and os.path.islink(sub):
        raise ArtifactError(_LINK.format(path=sub))


# ---------------------------------------------------------------------------------------
# Writing


def _atomic_write(path: Path, data: bytes) -> None:
    """Write to a tagged temporary in the same folder, fsync, then rename over ``path``.

    Raises
    ------
    ArtifactError
        The folder cannot be made or written, or ``path`` is a directory (exit code 2: the
        message names the path and the way out).
    """
    write_together({path: data})


def write_together(files: dict[Path, bytes]) -> list[Path]:
    """Write a set of artifacts that belong together: every temporary first, then the renames.

    Each file is written to a tagged temporary in its folder and fsynced; only when all of them
    are whole are they renamed into place, one after the other. A failure (or Ctrl-C) before the
    renames leaves every old file as it was and no temporary; a ``kill -9`` between two renames
    can still leave a new file beside an old one, so files read together must also carry a
    check of each other (the C export's ``QUADCTL_PAIR``, :mod:`quadctl.export.c`). The
    temporaries of a killed writer are removed by :func:`remove_stale_temporaries`.

    Every path passes :func:`_safe_place` first (a link in place of a file is replaced, never
    followed; a link in place of an artifact folder is refused).

    Raises
    ------
    ArtifactError
        A folder cannot be made or written, a path is a directory, or an artifact folder is a
        symbolic link (exit code 2: the message names the path and the way out).
    """
    paths = [_safe_place(p) for p in files]
    written: list[tuple[str, Path]] = []
    path = paths[0] if paths else None
    try:
        for path, data in zip(paths, files.values()):
            written.append((_temporary(path, data), path))
        for tmp, path in written:
            os.replace(tmp, path)
    except OSError as exc:
        _discard(written)
        if isinstance(exc, ArtifactError):
            raise
        if path.is_dir() and not path.is_symlink():
            raise ArtifactError(_IS_A_DIRECTORY.format(path=path)) from None
        raise ArtifactError(f"{path}: cannot write the artifact ({_reason(exc)}); free the space or the "
                            "permission it needs, or choose another --out folder") from None
    except BaseException:
        _discard(written)
        raise
    return paths


def _temporary(path: Path, data: bytes) -> str:
    """``data`` in a new tagged temporary beside ``path``, fsynced; its name."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{TEMPORARY_TAG}-", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise ArtifactError(f"{path.parent}: cannot write artifacts there ({_reason(exc)}); "
                            "choose another --out folder") from None
    mode = 0o666 & ~_umask()  # mkstemp makes 0600; artifacts are shared like any file
    try:
        if hasattr(os, "fchmod"):  # not on Windows before Python 3.13
            os.fchmod(fd, mode)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        if not hasattr(os, "fchmod"):
            os.chmod(tmp, mode)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return tmp


def _discard(written) -> None:
    for tmp, _ in written:
        Path(tmp).unlink(missing_ok=True)


def remove(path: Path | str) -> bool:
    """Delete an artifact quadctl wrote (a figure of an earlier report, a sweep's chunk); True if one went.

    Only a registered artifact name in the run directory or one of its artifact folders (not a
    link), the file itself: a link in its place is removed, never its target.
    """
    path = _safe_place(Path(path))
    try:
        path.unlink()
    except FileNotFoundError:
        return False
    except OSError as exc:
        raise ArtifactError(f"{path}: cannot remove the old artifact ({_reason(exc)}); remove it, or choose "
                            "another --out folder") from None
    return True


STALE_TEMPORARY_AGE = 60.0
"""s; a temporary older than this was left by a killed run (a live write takes milliseconds)."""


def remove_stale_temporaries(folder: Path, age: float = STALE_TEMPORARY_AGE) -> list[Path]:
    """Delete the temporaries a killed quadctl left in ``folder``; return them.

    Only what quadctl can prove it wrote goes: a regular file named
    ``.<artifact>.quadctl-<random>.tmp`` (:data:`TEMPORARY_TAG`) whose ``<artifact>`` is a name
    quadctl writes in that very folder (:data:`ARTIFACT_NAMES` at the top, the
    :data:`SUBFOLDER_NAMES` patterns in ``plots/`` and ``sweep.parts/``), older than ``age`` (s,
    default :data:`STALE_TEMPORARY_AGE`; a writer that holds the folder's lock, :func:`locked`, knows
    every temporary there is a dead writer's and passes 0). Never recursive, never through a link:
    a user's ``.notes.tmp``, a ``.sim.npz.mine.tmp``, anything in a folder of their own or in the
    folder a linked ``plots`` points to stays.
    """
    import time

    folder = Path(folder)
    now = time.time()
    stale = []
    places = [(folder, ARTIFACT_NAMES.__contains__)]
    places += [(folder / sub, pattern.fullmatch) for sub, pattern in SUBFOLDER_NAMES.items()]
    for where, is_ours in places:
        if os.path.islink(where):
            continue
        try:
            entries = list(os.scandir(where))
        except OSError:  # no such folder (or unreadable): nothing of ours to remove
            continue
        for entry in entries:
            match = _TEMPORARY.fullmatch(entry.name)
            if not match or not is_ours(match["name"]) or not entry.is_file(follow_symlinks=False):
                continue
            try:
                if now - entry.stat(follow_symlinks=False).st_mtime >= age:
                    os.unlink(entry.path)
                    stale.append(Path(entry.path))
            except OSError:  # gone meanwhile, or a read-only folder: leave it
                continue
    return sorted(stale)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json(path: Path, payload: dict, indent: int | None = 1) -> Path:
    """Write ``payload`` as indented (``indent=None``: compact, several times faster to encode),
    key-sorted JSON, atomically."""
    text = json.dumps(jsonable(payload), indent=indent, sort_keys=True, allow_nan=False)
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


# ---------------------------------------------------------------------------------------
# Reading, with provenance and content checked


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
        raise ArtifactError(f"{path}: corrupted artifact ({_reason(exc)}); "
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
        raise ArtifactError(f"{path}: corrupted artifact ({_reason(exc)}); "
                            "delete it or rerun with --fresh") from None
    except (ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError):  # not NumPy's allow_pickle advice
        raise ArtifactError(f"{path}: corrupted artifact: not a valid quadctl artifact (an .npz of named arrays "
                            "and its meta record); rerun with --fresh to recompute it") from None
    _check_provenance(path, meta if isinstance(meta, dict) else {})
    validate(path, arrays)
    return arrays, meta


def _refuse_directory(path) -> None:
    _refuse_link(Path(path))
    if Path(path).is_dir():
        raise ArtifactError(_IS_A_DIRECTORY.format(path=path))


_IS_A_DIRECTORY = "{path}: is a directory, not a file quadctl can write; remove it or choose another --out folder"


def _check_provenance(path, meta: dict) -> None:
    if meta.get("format_version") != FORMAT_VERSION or "config_hash" not in meta:
        version = meta.get("quadctl_version", "unknown")
        raise ArtifactError(f"{path}: written by quadctl {version} in another format; "
                            "delete it or rerun with --fresh")


def _reason(exc: Exception) -> str:
    text = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return text.splitlines()[0][:120]


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


# ---------------------------------------------------------------------------------------
# One quadctl per run directory

LOCK_NAME = ".quadctl.lock"
"""The lock file in a run directory (it holds the pid of the quadctl that has the folder)."""

try:
    import fcntl
except ImportError:  # Windows: an O_EXCL lock file instead
    fcntl = None

_held: dict[str, int] = {}
"""Folders this process holds, with a count (:func:`locked` is re-entrant within a process)."""


@contextmanager
def locked(folder: Path | str):
    """Hold ``folder`` (a run directory) for this process while the block runs.

    Another quadctl writing the same folder at the same time (a config edited and rerun while an
    earlier run still simulates) would leave artifacts of two configs side by side; the second
    one is refused instead. With ``fcntl`` (Linux, macOS) the lock is ``flock`` on
    ``<folder>/.quadctl.lock``, released by the kernel however the holder ends (``kill -9``
    included), and the file is removed when the block ends (one left by a holder killed hard is
    unlocked and harmless: the next quadctl takes it); elsewhere the file is created with ``O_EXCL``
    and removed on exit (a holder killed hard leaves it: the message says to delete it).
    Re-entrant within one process.

    Raises
    ------
    ArtifactError
        The folder is held by another process (exit code 2): ``runs/x is in use by another
        quadctl (pid N); wait for it or use -o another folder``; or it cannot be created.
    """
    folder = Path(folder)
    key = os.path.abspath(folder)
    if key in _held:
        _held[key] += 1
        try:
            yield folder
        finally:
            if key in _held:  # holders may be released in any order (a workspace closed at exit)
                _held[key] -= 1
        return
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        why = "a file, not a folder" if folder.is_file() else _reason(exc)
        raise ArtifactError(f"{folder}: cannot write artifacts there ({why}); choose another --out folder") from None
    release = _lock_flock(folder) if fcntl is not None else _lock_exclusive(folder)
    _held[key] = 1
    try:
        yield folder
    finally:
        _held.pop(key, None)
        release()


_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_LINK_LOCK = "{path}: is a symbolic link, not quadctl's lock file; remove it (quadctl never writes through a link)"


def _in_use(folder: Path, pid: str, hint: str = "") -> ArtifactError:
    return ArtifactError(f"{folder} is in use by another quadctl (pid {pid or 'unknown'}); wait for it or "
                         f"use -o another folder{hint}")


def _lock_flock(folder: Path):
    path = folder / LOCK_NAME
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | _NOFOLLOW, 0o666)
        except OSError as exc:
            if os.path.islink(path):
                raise ArtifactError(_LINK_LOCK.format(path=path)) from None
            raise ArtifactError(f"{path}: cannot create the run directory's lock ({_reason(exc)}); "
                                "choose another --out folder") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            pid = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
            os.close(fd)
            raise _in_use(folder, pid) from None
        if _same_file(fd, path):
            break
        # the holder removed the file between our open and our lock: the lock we got is on a file
        # nobody else will open again; lock the one at the path now
        os.close(fd)
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)

    def release():
        # removed while still locked: a process that opened it meanwhile finds, once it has the lock,
        # that the path no longer names its file (:func:`_same_file`) and starts again on a new one
        try:
            path.unlink(missing_ok=True)
        except OSError:  # a read-only folder now: the file stays, harmless (never taken for an artifact)
            pass
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)

    return release


def _same_file(fd: int, path: Path) -> bool:
    """Whether ``path`` still names the open file ``fd`` (same device and inode)."""
    try:
        here = os.stat(path)
    except FileNotFoundError:
        return False
    held = os.fstat(fd)
    return (held.st_dev, held.st_ino) == (here.st_dev, here.st_ino)


def _lock_exclusive(folder: Path):
    path = folder / LOCK_NAME
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except FileExistsError:
        if os.path.islink(path):
            raise ArtifactError(_LINK_LOCK.format(path=path)) from None
        try:
            pid = path.read_text(encoding="ascii", errors="replace").strip()
        except OSError:
            pid = ""
        raise _in_use(folder, pid, f" (if no quadctl runs there, delete {path})") from None
    except OSError as exc:
        raise ArtifactError(f"{path}: cannot create the run directory's lock ({_reason(exc)}); "
                            "choose another --out folder") from None
    with os.fdopen(fd, "w", encoding="ascii") as fh:
        fh.write(f"{os.getpid()}\n")

    def release():
        path.unlink(missing_ok=True)

    return release
