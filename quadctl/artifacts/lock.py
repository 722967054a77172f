"""One quadctl per run directory: the folder's lock (``flock``, or an ``O_EXCL`` file where there is no
``fcntl``), re-entrant within a process; and only a folder that is quadctl's, so that no file of a
user's own folder is written over (:func:`claim`)."""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

from quadctl.artifacts.places import ARTIFACT_NAMES, SUBFOLDER_NAMES, reason_of
from quadctl.errors import ArtifactError

LOCK_NAME = ".quadctl.lock"
"""The lock file in a run directory (it holds the pid of the quadctl that has the folder)."""
MARK_NAME = ".quadctl"
"""The file that marks a folder as quadctl's (:func:`claim`), written the first time quadctl takes it."""
MARK_TEXT = ("quadctl writes its artifacts in this folder, over those of earlier runs. It writes only into a new or "
             "empty folder, or one with this file: never over the files of a folder it did not make.\n")
COMMON_NAMES = frozenset({"config.yaml", "README.md", "Makefile", "Kbuild", "app-config", "sweep.csv", "sweep.png",
                          "montecarlo.png", "identify.png"})
"""Names quadctl writes (:data:`~quadctl.artifacts.places.ARTIFACT_NAMES`) that a user's own folder may hold
too: they do not show that a folder is quadctl's (its other names do: ``trim.json``, ``quadctl_controller.c``...)."""
OWN_FILES = ("report/report.html", "src/quadctl_app.c")
"""Files in quadctl's subfolders that show a folder is quadctl's (a report, the Crazyflie app; and any chunk of a
sweep in ``sweep.parts``)."""

try:
    import fcntl
except ImportError:  # Windows: an O_EXCL lock file instead
    fcntl = None

_held: dict[str, int] = {}
_marked: set[str] = set()
"""Folders whose mark this process's hold wrote (:func:`marked_by_this_hold`)."""
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
        why = "a file, not a folder" if folder.is_file() else reason_of(exc)
        raise ArtifactError(f"{folder}: cannot write artifacts there ({why}); choose another --out folder") from None
    release = _lock_flock(folder) if fcntl is not None else _lock_exclusive(folder)
    try:
        marked = claim(folder)
    except BaseException:
        release()
        raise
    _held[key] = 1
    if marked:
        _marked.add(key)
    try:
        yield folder
    except BaseException:
        if key in _marked and not _names(folder):  # stopped before writing anything: the folder as it was
            unmark(folder)
        raise
    finally:
        _held.pop(key, None)
        _marked.discard(key)
        release()


def claim(folder: Path) -> bool:
    """Take ``folder`` as quadctl's, or refuse it before anything is written there: quadctl writes over
    its own files only. A folder marked as quadctl's (:data:`MARK_NAME`) is taken; so is one that holds
    nothing named as what quadctl writes (:data:`~quadctl.artifacts.places.ARTIFACT_NAMES`, its
    subfolders: a new or empty folder, or one with a user's own files beside, which quadctl leaves
    alone), or one that shows it is a run folder of a quadctl before the mark (a name only quadctl writes,
    not one of :data:`COMMON_NAMES`, or one of :data:`OWN_FILES`); it is then marked. A folder whose
    ``config.yaml``, ``README.md``, ``Makefile`` or ``plots`` quadctl did not write (``-o .`` in a
    project folder) is refused. Returns whether it wrote the mark.

    Raises
    ------
    ArtifactError
        The folder holds files named as quadctl's that quadctl did not write (exit code 2), naming them.
    """
    mark = folder / MARK_NAME
    if mark.is_file() and not mark.is_symlink():
        return False
    try:
        named = [e.name for e in os.scandir(folder) if not e.is_symlink()  # a link is refused where it is met
                 and (e.name in ARTIFACT_NAMES or e.name in SUBFOLDER_NAMES and _holds_ours(folder / e.name))]
    except OSError as exc:
        raise ArtifactError(f"{folder}: cannot read the folder ({reason_of(exc)}); choose another --out folder") \
            from None
    ours = any(name in ARTIFACT_NAMES and name not in COMMON_NAMES for name in named) \
        or any((folder / own).is_file() for own in OWN_FILES) or _has_chunks(folder / "sweep.parts")
    if named and not ours:
        raise ArtifactError(f"{folder}: holds {', '.join(sorted(named))}, which quadctl did not write and would write "
                            "over: give -o a new or empty folder, or one quadctl made")
    try:
        fd = os.open(mark, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW, 0o666)
    except OSError:  # there meanwhile (a link: never written through), or a read-only folder: the writes say so
        return False
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(MARK_TEXT)
    return True


def marked_by_this_hold(folder: Path | str) -> bool:
    """Whether this process's hold of ``folder`` (:func:`locked`) wrote its mark: a writer that puts the
    folder back as it found it (:meth:`quadctl.workspace.Workspace.roll_back`) takes the mark away too."""
    return os.path.abspath(folder) in _marked


def unmark(folder: Path | str) -> None:
    """Remove ``folder``'s mark (:data:`MARK_NAME`), never through a link."""
    mark = Path(folder) / MARK_NAME
    try:
        if mark.is_file() and not mark.is_symlink():
            mark.unlink()
    except OSError:  # read-only meanwhile: harmless, the folder stays quadctl's
        pass


def _holds_ours(sub: Path) -> bool:
    """Whether the subfolder ``sub`` (``plots``, ``src``...) holds a file named as quadctl writes there
    (:data:`~quadctl.artifacts.places.SUBFOLDER_NAMES`): a project's own ``src/`` does not."""
    if sub.is_symlink() or not sub.is_dir():
        return sub.exists()  # a file where quadctl makes a folder: in its way
    try:
        return any(SUBFOLDER_NAMES[sub.name].fullmatch(e.name) for e in os.scandir(sub))
    except OSError:
        return True


def _has_chunks(parts: Path) -> bool:
    """Whether ``parts`` (not a link) holds a chunk a stopped sweep kept."""
    return parts.is_dir() and not parts.is_symlink() and _holds_ours(parts)


def _names(folder: Path) -> list[str]:
    """What the folder holds besides quadctl's lock and mark."""
    try:
        return [e.name for e in os.scandir(folder) if e.name not in (LOCK_NAME, MARK_NAME)]
    except OSError:
        return []


def held(folder: Path | str) -> bool:
    """Whether this process holds ``folder`` (:func:`locked`): a second holder here must leave the files
    the first set aside (its roll-back needs them), while the first knows every quadctl temporary there
    is a dead run's (no other process holds the folder, and none here did before)."""
    return os.path.abspath(folder) in _held


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
            raise ArtifactError(f"{path}: cannot create the run directory's lock ({reason_of(exc)}); "
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
        raise ArtifactError(f"{path}: cannot create the run directory's lock ({reason_of(exc)}); "
                            "choose another --out folder") from None
    with os.fdopen(fd, "w", encoding="ascii") as fh:
        fh.write(f"{os.getpid()}\n")

    def release():
        path.unlink(missing_ok=True)

    return release
