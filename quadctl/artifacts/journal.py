"""A run folder's journals: what a session changes there, a line a change as it makes it, so that the
next quadctl to take the folder finishes a session that never ended (``kill -9``, a crash of the
process) as Ctrl-C would have ended it.

A session (:class:`quadctl.workspace.Workspace`) keeps the files it replaces as hard links beside them
(``.<artifact>.quadctl-undo<random>.tmp``) and its journal, ``.quadctl.journal.<random>``, says what each
change was: the file's path, what it held before (a file set aside, a link, nothing), the earlier config's
artifacts it removed (``replaced``) and the artifacts it wrote. A session that ends removes its journal,
then the files it set aside. The next holder of the folder's lock reads what a dead session left
(:func:`take_up`): when it had removed another config's artifacts and not yet written each again, the
earlier run is put back, byte for byte; otherwise what it wrote stays.

A line written is the kernel's at once, so a ``kill -9`` loses none of it; a power cut loses what is not
yet on the disk. The journal is fsynced (:meth:`Journal.sync`), with the folders of its name and of the
files it set aside, where the undo comes to depend on it: before the first of another config's artifacts
is removed, before a roll-back starts, and from then on before each file is replaced; and once synced,
its removal at the session's end is fsynced too, before the files it set aside go. A session that
replaces none of another config's artifacts fsyncs nothing: a dead one's journal would be left as it is.

A journal is followed only when every path in it is one quadctl writes in that very folder (a name of
:data:`~quadctl.artifacts.places.ARTIFACT_NAMES`, or of :data:`~quadctl.artifacts.places.SUBFOLDER_NAMES`
in its subfolder, never through a link) and every file it set aside is still there; otherwise it is
set aside unfollowed, with a note.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
from pathlib import Path

from quadctl.artifacts.places import ARTIFACT_NAMES, SUBFOLDER_NAMES
from quadctl.artifacts.writing import _TEMPORARY, TEMPORARY_TAG, write_bytes
from quadctl.signals import signals_held

JOURNAL = re.compile(r"\.quadctl\.journal\.[0-9a-f]{8}")
"""A session's journal's name: ``.quadctl.journal.<random>``."""
NEW_FOLDER = object()
"""What a session's change record holds for an artifact folder it made (removed again if empty)."""
LOST = object()
"""A file's earlier bytes that a journal cannot hold (set aside as bytes, where links fail)."""


class Journal:
    """One session's journal in ``folder``; the file is made at the first :meth:`add`."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.path = self.folder / f".quadctl.journal.{os.urandom(4).hex()}"
        self.synced = False
        """Whether the undo depends on the journal being on disk (:meth:`sync` was called)."""
        self._folders = {self.folder}
        """The folders whose new names (the journal's, the files set aside) the next :meth:`sync` fsyncs."""

    def add(self, record: dict) -> None:
        """Append ``record`` at once: a line written is the kernel's, so a ``kill -9`` after it loses
        none of it (a power cut may, until :meth:`sync`). Best effort: in a folder that takes no journal,
        only the session itself can undo (Ctrl-C, a refusal)."""
        _add(self.path, record)

    def sync(self) -> None:
        """Put the journal on the disk (fsync), and the names of it and of the files it set aside since the
        last sync (their folders fsynced): call it before a change only the journal can undo after a power
        cut. Best effort, as :meth:`add`."""
        with contextlib.suppress(OSError):
            fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)  # not made here: no journal, nothing to sync
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            self.synced = True
        for folder in sorted(self._folders):
            with contextlib.suppress(OSError):
                _fsync_folder(folder)
        self._folders.clear()

    def end(self) -> None:
        """The session ended: its journal goes (before the files it set aside, which name nothing then);
        once synced, for good before they go (its folder fsynced): a power cut then cannot leave the
        journal and those files to undo a session that ended."""
        self._folders.add(self.folder)  # a later add makes the file again
        with contextlib.suppress(OSError):
            self.path.unlink(missing_ok=True)
            if self.synced:
                _fsync_folder(self.folder)
                self.synced = False

    def change(self, path: Path, before) -> None:
        """Record that the session changes ``path``, which held ``before`` (as :func:`undo` takes it);
        once the journal is synced, synced again before a file is replaced (``before`` is not None)."""
        if isinstance(before, Path):
            self._folders.add(before.parent)
        self.add({"path": self._relative(path), "before": _encoded(before, self.folder)})
        if self.synced and before is not None and before is not NEW_FOLDER:
            self.sync()

    def wrote(self, path: Path) -> None:
        self.add({"wrote": self._relative(path)})

    def replaced(self, name: str) -> None:
        """Record, before it goes, that the session removes ``name``, another config's artifact."""
        self.add({"replaced": [name]})

    def rolling_back(self) -> None:
        """Record that the session puts everything back (a refused input): a kill in the middle leaves
        the rest for the next to put back, whatever the session had written."""
        self.add({"rolling_back": True})

    def undone(self, path: Path) -> None:
        """Record that ``path`` is back as it was: a roll-back cut short is finished, not redone."""
        self.add({"undone": self._relative(path)})

    def _relative(self, path: Path) -> str:
        return os.path.relpath(path, self.folder)


def _add(journal: Path, record: dict) -> None:
    with contextlib.suppress(OSError):
        with open(journal, "a", encoding="utf-8") as f:
            f.write(json.dumps(record) + "\n")


def _fsync_folder(folder: Path) -> None:
    """fsync a folder: the names made or removed in it are on the disk (nothing to do on Windows, which
    cannot open a folder)."""
    if os.name == "nt":
        return
    fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _encoded(before, folder: Path) -> dict:
    if before is NEW_FOLDER:
        return {"folder": True}
    if isinstance(before, Path):
        return {"aside": os.path.relpath(before, folder)}
    if isinstance(before, str):
        return {"link": before[3:]}
    if before is None:
        return {"absent": True}
    return {"lost": True}


def undo(changes: list, on_undone=None) -> list[Path]:
    """Put back each ``(path, what it held before)`` of a session's changes, the last first: a file set
    aside (a Path), a link (``"-> target"``), a file's bytes, absent (None: the session made it), an
    artifact folder the session made (:data:`NEW_FOLDER`: removed if empty again), or :data:`LOST`;
    ``on_undone(path)`` after each that is back. Run it inside :func:`quadctl.signals.signals_held`.
    Returns the paths it could not put back."""
    failed = []
    for path, before in reversed(changes):
        try:
            if before is LOST:
                failed.append(path)
                continue
            if before is NEW_FOLDER:
                path.rmdir()
            elif isinstance(before, str):  # a link the session replaced
                path.unlink(missing_ok=True)
                os.symlink(before[3:], path)
            elif isinstance(before, Path):  # the file itself, set aside
                os.replace(before, path)
                before.unlink(missing_ok=True)  # still there when the write never came: a rename between
                # two names of one file does nothing
            elif before is not None:
                write_bytes(path, before)
            elif path.is_file() or path.is_symlink():  # made by the session (never a folder in its way)
                path.unlink()
        except OSError:  # best effort: the rest still goes back
            if before is not NEW_FOLDER:
                failed.append(path)
            continue
        if on_undone is not None:
            on_undone(path)
    return failed


def journals(folder: Path) -> list[Path]:
    """The session journals in ``folder`` (regular files named as :data:`JOURNAL`)."""
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    return sorted(Path(e.path) for e in entries if JOURNAL.fullmatch(e.name) and e.is_file(follow_symlinks=False))


def take_up(folder: Path) -> list[str]:
    """Finish the sessions whose journals are in ``folder`` (the caller holds its lock, and no session
    of its own process does: every journal there is a dead session's) as Ctrl-C would have, and remove
    their journals. Returns what to tell the user (one note a journal that did something or was not
    followed)."""
    folder = Path(folder)
    notes = []
    for path in journals(folder):
        try:
            note = _finish(folder, path)
        except Exception as exc:  # a journal of any shape is a note, never an error of the command
            note = _unfollowed(folder, path, f"{type(exc).__name__} while reading it")
        if note:
            notes.append(note)
        with contextlib.suppress(OSError):
            path.unlink()
    return notes


def _unfollowed(folder: Path, journal: Path, why: str) -> str:
    return f"{folder}: left {journal.name} unfollowed ({why}; it is removed): nothing was put back"


class _NotOurs(ValueError):
    pass


DEAD = "a quadctl command that never finished (killed, or its process crashed)"


def _finish(folder: Path, journal: Path) -> str:
    try:
        lines = journal.read_text(encoding="utf-8").splitlines()
    except ValueError:
        return _unfollowed(folder, journal, "it is not text")
    except OSError as exc:
        return _unfollowed(folder, journal, f"it cannot be read: {exc.strerror or exc}")
    changes, replaced, wrote, undone, rolling_back = [], [], set(), set(), False
    try:
        for line in lines:
            try:
                record = json.loads(line)
            except ValueError:  # the line the kill cut short
                continue
            if not isinstance(record, dict):
                raise _NotOurs(line)
            if "path" in record:
                changes.append(_change(folder, record))
            elif "wrote" in record:
                wrote.add(_place(folder, record["wrote"]))
            elif "undone" in record:
                undone.add(_place(folder, record["undone"]))
            elif "replaced" in record:
                for name in record["replaced"]:
                    if _place(folder, name) not in replaced:
                        replaced.append(_place(folder, name))
            elif record.get("rolling_back") is True:
                rolling_back = True
    except (_NotOurs, TypeError, KeyError, AttributeError):
        return _unfollowed(folder, journal, "it names files quadctl does not write there")
    unreplaced = [p for p in replaced if p not in wrote]
    if not unreplaced and not rolling_back:  # the dead session had written each artifact it removed again
        return ""
    left = [(path, before) for path, before in changes if path not in undone]
    missing = [before for _, before in left if isinstance(before, Path) and not before.is_file()]
    gone = [p for p in unreplaced if not _still_in_place(p, dict(changes).get(p))]  # all said before the first went
    what = (f"had removed {_names(folder, gone)} of the earlier config's run and not written them again" if gone
            else f"was about to remove {_names(folder, unreplaced)} of the earlier config's run" if unreplaced
            else "was putting the folder back as it found it")
    if missing:
        return (f"{folder}: {DEAD} {what}, and files it set aside are gone ({_names(folder, missing)}): "
                "nothing was put back")
    with signals_held():
        failed = undo(left, on_undone=lambda path: _add(journal, {"undone": os.path.relpath(path, folder)}))
        journal.unlink(missing_ok=True)
    note = f"{folder}: {DEAD} {what}: the earlier run is put back"
    return note + (f", but for {_names(folder, failed)}, which could not be" if failed else "")


def _still_in_place(path: Path, before) -> bool:
    """Whether ``path`` is still the file the session set aside as ``before`` (it was not removed)."""
    try:
        return isinstance(before, Path) and os.path.samefile(path, before)
    except OSError:
        return False


def _names(folder: Path, paths) -> str:
    return ", ".join(os.path.relpath(p, folder) for p in paths)


def _place(folder: Path, relative) -> Path:
    """``folder/relative`` when it is a place quadctl writes in ``folder``; else :class:`_NotOurs`."""
    if not isinstance(relative, str) or os.path.isabs(relative):
        raise _NotOurs(relative)
    parts = relative.split("/")
    if len(parts) == 1 and (parts[0] in ARTIFACT_NAMES or parts[0] in SUBFOLDER_NAMES):
        return folder / parts[0]
    if len(parts) == 2 and parts[0] in SUBFOLDER_NAMES and SUBFOLDER_NAMES[parts[0]].fullmatch(parts[1]) \
            and not os.path.islink(folder / parts[0]):
        return folder / parts[0] / parts[1]
    raise _NotOurs(relative)


def _change(folder: Path, record: dict):
    path = _place(folder, record["path"])
    before = record.get("before")
    if not isinstance(before, dict):
        raise _NotOurs(record)
    if before.get("folder"):
        if path.name not in SUBFOLDER_NAMES or path.parent != folder:
            raise _NotOurs(record)
        return path, NEW_FOLDER
    if path.name in SUBFOLDER_NAMES and path.parent == folder:
        raise _NotOurs(record)  # a folder is only ever made, never a file's place
    if "aside" in before:
        aside = before["aside"]
        if not isinstance(aside, str) or os.path.isabs(aside):
            raise _NotOurs(record)
        aside_path = folder / aside
        match = _TEMPORARY.fullmatch(aside_path.name)
        if aside_path.parent != path.parent or not match or match["name"] != path.name \
                or f".{TEMPORARY_TAG}-undo" not in aside_path.name:
            raise _NotOurs(record)
        return path, aside_path
    if "link" in before:
        if not isinstance(before["link"], str):
            raise _NotOurs(record)
        return path, f"-> {before['link']}"
    return path, None if before.get("absent") else LOST


def take_over(folder: Path) -> list[str]:
    """What the first holder of ``folder``'s lock does (no other quadctl holds it, so nothing there is
    live): finish the dead sessions (:func:`take_up`), then remove every quadctl temporary, the files
    they set aside too. Returns the notes for the user."""
    from quadctl.artifacts.writing import remove_stale_temporaries

    notes = take_up(folder)
    remove_stale_temporaries(folder, age=0.0)
    return notes
