"""Writing artifacts atomically: each through a tagged temporary, fsynced, then renamed into place
(a set that belongs together, all temporaries first); removing quadctl's own files and the temporaries
a killed run left."""

from __future__ import annotations

import io
import json
import os
import re
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from quadctl.artifacts.json_values import jsonable
from quadctl.artifacts.places import (
    ARTIFACT_NAMES,
    IS_A_DIRECTORY,
    SUBFOLDER_NAMES,
    reason_of,
    safe_place,
)
from quadctl.errors import ArtifactError
from quadctl.signals import signals_held

TEMPORARY_TAG = "quadctl"
"""A temporary is ``.<artifact>.quadctl-<random>.tmp``: the tag, and the artifact's registered
name, are what let a later run prove the file is quadctl's before it deletes it."""
_TEMPORARY = re.compile(rf"\.(?P<name>.+)\.{TEMPORARY_TAG}-[a-z0-9_]+\.tmp")


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
    are whole are they renamed into place, one after the other. A failure (or Ctrl-C, or SIGTERM)
    before the renames leaves every old file as it was and no temporary (a signal waits while a
    temporary is made: one that landed inside ``mkstemp`` left it behind, empty); a ``kill -9`` between two renames
    can still leave a new file beside an old one, so files read together must also carry a
    check of each other (the C export's ``QUADCTL_PAIR``, :mod:`quadctl.export.c`). The
    temporaries of a killed writer are removed by :func:`remove_stale_temporaries`.

    Every path passes :func:`safe_place` first (a link in place of a file is replaced, never
    followed; a link in place of an artifact folder is refused).

    Raises
    ------
    ArtifactError
        A folder cannot be made or written, a path is a directory, or an artifact folder is a
        symbolic link (exit code 2: the message names the path and the way out).
    """
    paths = [safe_place(p) for p in files]
    written: list[tuple[str, Path]] = []
    path = paths[0] if paths else None
    try:
        for path, data in zip(paths, files.values()):
            with signals_held():  # a temporary is made and listed whole (a Ctrl-C or SIGTERM waits), so it is discarded
                written.append((_temporary(path, data), path))
        for tmp, path in written:
            os.replace(tmp, path)
    except OSError as exc:
        _discard(written)
        if isinstance(exc, ArtifactError):
            raise
        if path.is_dir() and not path.is_symlink():
            raise ArtifactError(IS_A_DIRECTORY.format(path=path)) from None
        raise ArtifactError(f"{path}: cannot write the artifact ({reason_of(exc)}); free the space or the "
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
        raise ArtifactError(f"{path.parent}: cannot write artifacts there ({reason_of(exc)}); "
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
    path = safe_place(Path(path))
    try:
        path.unlink()
    except FileNotFoundError:
        return False
    except OSError as exc:
        raise ArtifactError(f"{path}: cannot remove the old artifact ({reason_of(exc)}); remove it, or choose "
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
    default :data:`STALE_TEMPORARY_AGE`; a writer that holds the folder's lock,
    :func:`~quadctl.artifacts.lock.locked`, knows every temporary there is a dead writer's and passes
    0). Never recursive, never through a link: a user's ``.notes.tmp``, a ``.sim.npz.mine.tmp``,
    anything in a folder of their own or in the folder a linked ``plots`` points to stays.
    """
    import time

    folder = Path(folder)
    now = time.time()
    stale = []
    # a file set aside for a roll-back keeps its file's time: while a journal names it (a dead session's,
    # for the next lock holder to finish: quadctl.artifacts.journal), it stays
    journaled = any(name.startswith(".quadctl.journal.") for name in _names_in(folder))
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
            if journaled and f".{TEMPORARY_TAG}-undo" in entry.name:
                continue
            try:
                if now - entry.stat(follow_symlinks=False).st_mtime >= age:
                    os.unlink(entry.path)
                    stale.append(Path(entry.path))
            except OSError:  # gone meanwhile, or a read-only folder: leave it
                continue
    return sorted(stale)


def _names_in(folder: Path) -> list[str]:
    try:
        return os.listdir(folder)
    except OSError:
        return []


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def json_bytes(payload: dict, indent: int | None = 1) -> bytes:
    """``payload`` as an artifact's JSON: indented (``indent=None``: compact, several times faster to encode),
    keys sorted, no NaN, a newline at the end."""
    return (json.dumps(jsonable(payload), indent=indent, sort_keys=True, allow_nan=False) + "\n").encode()


def write_json(path: Path, payload: dict, indent: int | None = 1) -> Path:
    """Write ``payload`` as :func:`json_bytes`, atomically."""
    _atomic_write(path, json_bytes(payload, indent))
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
