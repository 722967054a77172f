"""One command's writes into a run folder: the config beside what it makes, another config's run removed,
every change undoable.

A :class:`Session` holds the folder (:func:`~quadctl.artifacts.lock.locked`) from its start to :meth:`Session.close`.
Its first write also writes the config as given (``config.yaml``) and as resolved (``config.resolved.yaml``),
so a run folder always says what made it, and removes every artifact another config made there
(:mod:`quadctl.artifacts.run_folder`), with a notice naming them: one config's run a folder. Each file it writes
or removes can be put back (:meth:`Session.roll_back`; what a killed session left, by the next holder of the
folder: :mod:`quadctl.artifacts.journal`). An artifact folder (``plots/``, ``report/``, ``src/``, ``sweep.parts/``)
that removing another config's artifacts left empty goes when the session ends, kept: until then the files
set aside for a roll-back are in it, and a roll-back finds it where it was. A folder that holds anything else
(a user's file) stays.

:class:`quadctl.workspace.Workspace` is a session that also runs the stages; ``quadctl sweep`` and
``quadctl export`` write through one of their own.
"""

from __future__ import annotations

import contextlib
import os
import warnings
import weakref
from pathlib import Path

from quadctl.artifacts import lock, writing
from quadctl.artifacts.journal import NEW_FOLDER, Journal, undo
from quadctl.artifacts.meta import RESOLVED_CONFIG_HEAD
from quadctl.artifacts.places import STAGE_FILES, SWEEP_PARTS, default_out
from quadctl.artifacts.png_stamp import stamp_png
from quadctl.artifacts.run_folder import MadeBy, run_artifacts
from quadctl.errors import QuadctlNotice
from quadctl.signals import signals_held
from quadctl.version import __version__

CONFIG_GIVEN, CONFIG_RESOLVED = "config.yaml", "config.resolved.yaml"
HASH_NOTE = " (config_hash {})"
"""How ``config.resolved.yaml``'s first line ends: the digest of the config (:func:`config_hash_of`)."""


def config_hash_of(folder: Path | str) -> str | None:
    """The ``config_hash`` a run folder's ``config.resolved.yaml`` names (None: none there, or unreadable)."""
    try:
        with open(Path(folder) / CONFIG_RESOLVED, encoding="utf-8") as f:
            first = f.readline().rstrip("\n")
    except (OSError, UnicodeDecodeError):
        return None
    head, _, tail = HASH_NOTE.partition("{}")
    if not first.endswith(tail) or head not in first:
        return None
    return first.rpartition(head)[2][:-len(tail)] or None


def _listed(removed: list[str]) -> str:
    """The files a note names, a sweep's chunks counted (``sweep.parts/ (250 chunks)``): each of them is a
    line of its journal, not a file to read."""
    chunks = [name for name in removed if name.startswith(f"{SWEEP_PARTS}/")]
    named = [name for name in removed if name not in chunks]
    return ", ".join(named + ([f"{SWEEP_PARTS}/ ({len(chunks)} chunk{'s' * (len(chunks) != 1)})"] if chunks else []))


def _released(journal: Journal, hold: contextlib.ExitStack) -> None:
    """A session ends (closed, collected, or at the process's exit) with what it wrote standing: its journal
    goes first, then the files it set aside, the artifact folders it emptied of another config's files (if
    nothing is in them now), and last the folder's lock (:attr:`Session._hold`, in that order)."""
    journal.end()
    hold.close()


def _remove_if_empty(folders: set[Path]) -> None:
    """Remove each of ``folders`` that is empty; a folder with anything in it (a user's file, this session's
    own), a link, or one gone, stays as it is."""
    for folder in sorted(folders):
        with contextlib.suppress(OSError):
            folder.rmdir()
    folders.clear()


class Session:
    """One command's writes into the run folder ``out`` for the config ``cfg``; holds the folder until
    :meth:`close` (or the block of ``with``).

    Parameters
    ----------
    cfg : Config
        The config every artifact written carries (its ``digest()``), kept beside them (``to_yaml()``).
    out : path, optional
        Run directory (default ``runs/<config name>``).
    source_text : str, optional
        The YAML the config was read from (the file's text, or a bundled config's), kept as
        ``config.yaml``. Without it (a config built in Python) ``config.yaml`` is the validated
        config under a comment that says so.

    Raises
    ------
    ArtifactError
        The folder is another quadctl's now, a folder of a user's own, or cannot be made (exit 2).
    """

    def __init__(self, cfg, out: Path | str | None = None, *, source_text: str | None = None):
        self.cfg = cfg
        self.out = Path(out) if out is not None else default_out(cfg)
        self.source_text = source_text
        self._config_written = False
        self.written: list[Path] = []
        self._undo: list[tuple[Path, Path | bytes | str | object | None]] | None = []
        """Each file the session wrote or removed, and what it held before (:meth:`_before_change`); None: kept."""
        self.replaced: list[str] = []
        """The artifacts of another config this session removed, relative to the run folder (:meth:`_remove_stale`)."""
        self._emptied: set[Path] = set()
        """The artifact folders removing another config's artifacts emptied (removed at the end, if still empty)."""
        self._notes: list[str] | None = None
        """The notices :meth:`defer_notes` holds back until :meth:`close` (None: each is issued at once)."""
        self._hold = contextlib.ExitStack()
        self._hold.enter_context(lock.locked(self.out))  # one run at a time; the first finishes a dead one
        # the emptied folders go while the folder is still held (the next holder sees them as they are), after
        # the files set aside in them (their callbacks, added later, run first)
        self._hold.callback(_remove_if_empty, self._emptied)
        if lock.marked_by_this_hold(self.out):  # marked as quadctl's now: a roll-back takes the mark away
            self._undo.append((self.out / lock.MARK_NAME, None))
        self._journal = Journal(self.out)
        """What this session changes, as it changes it (:mod:`quadctl.artifacts.journal`)."""
        self._finalizer = weakref.finalize(self, _released, self._journal, self._hold)

    def close(self) -> None:
        """Release the run folder (the process's end releases it too), and issue the notices held back
        (:meth:`defer_notes`)."""
        notes = self._notes or []
        if self._notes is not None:
            self._notes = []
        for note in notes:
            warnings.warn(QuadctlNotice(note), stacklevel=2)
        self._finalizer()  # once: a later session's journal in this folder is not this one's to remove

    def defer_notes(self) -> None:
        """Hold back what this session says of the folder (the artifacts of another config it removed)
        until :meth:`close`: a command that refuses its input puts the folder back (:meth:`roll_back`), and
        the notices of what it undid are then not issued at all."""
        if self._notes is None:
            self._notes = []

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None and self.unreplaced:  # stopped halfway through replacing another config's run:
            self.roll_back()  # that run, whole (as the command line puts it back), not half of each
        self.close()

    def path(self, name: str) -> Path:
        return self.out / name

    # -- writing, as the functions of quadctl.artifacts.writing do, each change remembered ----------------

    def write_together(self, files: dict[Path, bytes]) -> list[Path]:
        """:func:`quadctl.artifacts.write_together` into the run folder, remembering what each file replaces:
        :meth:`roll_back` puts it back. A figure (``.png``) carries this config's hash (:meth:`stamp`)."""
        files = {Path(path): self.stamp(data) if Path(path).suffix == ".png" else data for path, data in files.items()}
        self.remember(*files)  # beside the config that made them: another config's artifacts go first
        paths = writing.write_together(files)
        self.record_written(*paths)
        return paths

    def write_bytes(self, path: Path | str, data: bytes) -> Path:
        """One file, as :meth:`write_together` writes them."""
        return self.write_together({Path(path): data})[0]

    def write_json(self, path: Path | str, payload: dict, indent: int | None = 1) -> Path:
        """:func:`quadctl.artifacts.write_json`, remembered as :meth:`write_together` remembers."""
        self.remember(path)
        return self._wrote(writing.write_json(Path(path), payload, indent))

    def write_npz(self, path: Path | str, arrays: dict, meta: dict) -> Path:
        """:func:`quadctl.artifacts.write_npz`, remembered as :meth:`write_together` remembers."""
        self.remember(path)
        return self._wrote(writing.write_npz(Path(path), arrays, meta))

    def remove(self, path: Path | str) -> bool:
        """Remove a file of the command's own (an earlier report's figure), remembered for :meth:`roll_back`
        as :meth:`write_bytes` remembers; True if one went."""
        self.remember(path)
        return writing.remove(Path(path))

    def stamp(self, png: bytes) -> bytes:
        """``png`` carrying this config's hash (:mod:`quadctl.artifacts.png_stamp`): the run folder tells
        it from a figure of another config, or one a user put there."""
        return stamp_png(png, self.cfg.digest())

    def remember(self, *paths: Path | str) -> None:
        """Remember what each of ``paths`` holds before the command writes it (by other means too: a drawing
        process of its own), for :meth:`roll_back`; :meth:`record_written` once it has."""
        self._write_config_files()
        for path in paths:
            self._before_change(Path(path))

    def record_written(self, *paths: Path | str) -> None:
        """The command wrote ``paths`` (after :meth:`remember`): this session's (an artifact of another config
        it replaces is written again)."""
        for path in paths:
            if Path(path).is_file():
                self._wrote(Path(path))

    # -- undoing ----------------------------------------------------------------------------------------

    @property
    def unreplaced(self) -> list[str]:
        """The artifacts of another config this session removed and has not yet written again for its own:
        while there are any, the folder holds neither run whole. Empty after :meth:`keep`."""
        if self._undo is None:
            return []
        return [name for name in self.replaced if self.path(name) not in self.written]

    def roll_back(self) -> bool:
        """Put back every file this session wrote or removed as it was before (the command refused its
        input: nothing it computed is kept), and remove the artifact folders it made, if empty again;
        after :meth:`keep`, nothing (and the notices of what it did are still said). Returns whether it
        put anything back."""
        if self._undo is None:
            return False
        undone = bool(self._undo)
        self._journal.rolling_back()
        self._journal.sync()  # on the disk before the first file goes back
        with signals_held():  # a second signal does not leave the folder half put back
            undo(self._undo, on_undone=self._journal.undone)
            self._journal.end()
        self._undo = []
        self.written.clear()
        self.replaced.clear()
        self._emptied.clear()  # each holds its files again
        self._config_written = False  # a later write puts this config beside it again, and its artifacts
        # only: those of the folder's config go first, as at the session's first write
        if self._notes is not None:  # what they said was undone
            self._notes.clear()
        return undone

    def keep(self) -> None:
        """Keep what this session wrote, whatever follows (:meth:`roll_back` does nothing after this)."""
        self._undo = None
        self._journal.end()

    def _before_change(self, path: Path) -> None:
        """Remember what ``path`` holds (once a session) before it is written or removed: the file set
        aside (:meth:`_set_aside`), a link's target (``"-> target"``), or None (absent, or unreadable:
        it cannot be put back)."""
        if self._undo is None or any(path == p for p, _ in self._undo):
            return
        if (path.parent != self.out and not os.path.lexists(path.parent)  # an artifact folder it will make
                and not any(path.parent == p for p, _ in self._undo)):
            self._undo.append((path.parent, NEW_FOLDER))
            self._journal.change(path.parent, NEW_FOLDER)
        try:
            before = (f"-> {os.readlink(path)}" if path.is_symlink()
                      else self._set_aside(path) if path.is_file() else None)
        except OSError:
            before = None
        self._undo.append((path, before))
        self._journal.change(path, before)

    def _set_aside(self, path: Path) -> Path | bytes:
        """The file at ``path`` kept for :meth:`roll_back` without copying it: a second name in the folder
        (a hard link; the atomic write gives ``path`` a new file, so this name keeps the old bytes), removed
        when the session closes and named as a temporary a killed run leaves for the next to clean up;
        its bytes where the file system has no hard links."""
        aside = path.parent / f".{path.name}.{writing.TEMPORARY_TAG}-undo{os.urandom(4).hex()}.tmp"
        # its removal is arranged before it exists: a Ctrl-C or SIGTERM between the two would leave it behind
        self._hold.callback(aside.unlink, missing_ok=True)
        try:
            os.link(path, aside)
        except OSError:
            return path.read_bytes()
        return aside

    def _wrote(self, path: Path) -> Path:
        self.written.append(path)
        if self._undo is not None:
            self._journal.wrote(path)
        return path

    # -- the config beside its artifacts, and no other's ----------------------------------------------------

    def _write_config_files(self) -> None:
        """``config.yaml`` (as given) and ``config.resolved.yaml``, at the session's first write."""
        if self._config_written:
            return
        resolved = self.cfg.to_yaml()
        given = self.source_text if self.source_text is not None else (
            "# built in Python, not read from a file: the validated config\n" + resolved)
        head = (f"{RESOLVED_CONFIG_HEAD} {__version__} validated it, every default filled in"
                f"{HASH_NOTE.format(self.cfg.digest())}\n")
        folder_hash = config_hash_of(self.out)
        if folder_hash != self.cfg.digest():
            self._remove_stale(folder_hash)
        for name, text in ((CONFIG_GIVEN, given), (CONFIG_RESOLVED, head + resolved)):
            self._before_change(self.path(name))
            self._wrote(writing.write_bytes(self.path(name), text.encode("utf-8")))
        self._config_written = True

    def _remove_stale(self, folder_hash: str | None) -> None:
        """Remove the artifacts another config made (:mod:`quadctl.artifacts.run_folder`: the stages', the
        figures and the report, a sweep's, the exports), with a notice naming them: quadctl never reuses
        them, and beside this config they would say what it did not make. A file whose provenance cannot be
        read (damaged, foreign) is left to the stage that reads it; a file quadctl does not write, always.
        ``folder_hash``: the config hash the folder's ``config.resolved.yaml`` names (None: none)."""
        made_by = MadeBy(self.out, folder_hash)
        digest = self.cfg.digest()
        removed, hashes = [], []
        for path in run_artifacts(self.out, first=STAGE_FILES):
            found = made_by(path) if path.is_file() and not path.is_symlink() else None
            if found is not None and found != digest:  # another config's
                name = path.relative_to(self.out).as_posix()
                hashes.append(found)
                self._before_change(path)
                if self._undo is not None:  # said before it goes: a kill right after still finds the earlier run
                    self._journal.replaced(name)
                removed.append(name)
        if removed and self._undo is not None:
            self._journal.sync()  # every removal said, on the disk (one fsync), before the first file goes
        for name in removed:
            path = self.path(name)
            self.replaced.append(name)
            path.unlink()
            if path.parent != self.out:
                self._emptied.add(path.parent)
        if removed:
            which = list(dict.fromkeys(hashes))  # each file's own (a sweep another config wrote here: its)
            note = (f"{self.out}: removed {_listed(removed)}, made by "
                    f"{'another config' if len(which) == 1 else 'other configs'} (config_hash {', '.join(which)})")
            if self._notes is None:
                warnings.warn(QuadctlNotice(note), stacklevel=2)
            else:
                self._notes.append(note)

