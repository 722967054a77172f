"""A run folder's artifacts and the config that made each: what goes when another config writes there
(:class:`quadctl.workspace.Workspace`, at its first write).

A run's artifacts are every file quadctl writes in the folder (:data:`~quadctl.artifacts.places.ARTIFACT_NAMES`
at its top, the :data:`~quadctl.artifacts.places.SUBFOLDER_NAMES` in its artifact folders: the stages'
artifacts, figures, the report, compare.json, a sweep's tables and chunks, the exports), but for the config
files, which the session rewrites itself, and for what ``quadctl identify`` wrote (made from flight logs:
``identified.yaml`` is a config, the one a run in that folder may read). A file of any other name (a user's
own) is never one of them.

Which config made an artifact (:class:`MadeBy`): the ``config_hash`` it carries (a JSON or NPZ artifact's
provenance, a MAT file's field, a figure's PNG text chunk (:mod:`quadctl.artifacts.png_stamp`), the
``Config sha256`` line of generated C or of the Crazyflie app's README); for a file that carries none, its
companion's (sweep.csv and sweep.png: sweep.json's; the C source: its header's); for the report's pages
(``report/report.html`` and ``.md``, written only beside the config they were made from), the folder's
config's, the one ``config.resolved.yaml`` names. None when it cannot be read, and for a figure without
the chunk (a user's, or one an earlier quadctl drew): such a file is left where it is.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from pathlib import Path

from quadctl.artifacts.places import ARTIFACT_NAMES, SUBFOLDER_NAMES
from quadctl.artifacts.png_stamp import stamp_of
from quadctl.artifacts.reading import read_json, read_npz
from quadctl.errors import ArtifactError

NOT_THE_RUNS = frozenset({"config.yaml", "config.resolved.yaml", "identified.json", "identified.yaml", "identify.png"})
"""Names quadctl writes in a run folder that are not a run's artifacts: the config (rewritten by the session
that writes there) and what ``quadctl identify`` made from flight logs."""
BY_THE_FOLDERS_CONFIG = frozenset({"report/report.html", "report/report.md"})
"""Files that carry no provenance and are written only beside the config they were made from (a
:class:`~quadctl.workspace.Workspace` writes its config first): the folder's config made them."""
COMPANIONS = {
    "sweep.csv": "sweep.json", "sweep.png": "sweep.json", "montecarlo.png": "montecarlo.npz",
    "quadctl_controller.c": "quadctl_controller.h",
    "Makefile": "README.md", "Kbuild": "README.md", "app-config": "README.md",  # the Crazyflie app's
    "src/Kbuild": "README.md", "src/quadctl_app.c": "README.md", "src/quadctl_crazyflie.c": "README.md",
    "src/quadctl_controller.c": "src/quadctl_controller.h",
}
"""A file that carries no provenance -> the file written with it that does (paths relative to the run folder)."""
_TEXT_STAMP = re.compile(rb"config sha256:? ([0-9a-f]{64})", re.IGNORECASE)
"""The config's hash in the opening comment of generated C (``Config sha256: ...``) and the app's README."""
_STAMP_HEAD = 4096


def run_artifacts(folder: Path | str, first: Iterable[str] = ()) -> list[Path]:
    """The run's artifacts in ``folder`` (regular files, never through a link): the names of ``first`` in
    that order, then the rest of the top, sorted, then each artifact folder's files, sorted."""
    folder = Path(folder)
    top = [name for name in _files(folder) if name in ARTIFACT_NAMES and name not in NOT_THE_RUNS]
    order = {name: i for i, name in enumerate(first)}
    found = [folder / name for name in sorted(top, key=lambda n: (order.get(n, len(order)), n))]
    for sub in sorted(SUBFOLDER_NAMES):
        pattern = SUBFOLDER_NAMES[sub]
        if not os.path.islink(folder / sub):
            found += [folder / sub / name for name in sorted(_files(folder / sub)) if pattern.fullmatch(name)]
    return found


def _files(folder: Path) -> list[str]:
    try:
        return [e.name for e in os.scandir(folder) if e.is_file(follow_symlinks=False)]
    except OSError:  # no such folder, or unreadable: nothing of ours listed
        return []


class MadeBy:
    """The ``config_hash`` of the config that made each artifact of ``folder`` (None: not known), read once:
    what a file said is kept after it goes (a figure's companion may go first).

    ``folder_hash``: the folder's config's (``config.resolved.yaml``), read before it is rewritten."""

    def __init__(self, folder: Path | str, folder_hash: str | None):
        self.folder = Path(folder)
        self.folder_hash = folder_hash
        self._read: dict[Path, str | None] = {}

    def __call__(self, path: Path) -> str | None:
        path = Path(path)
        if path not in self._read:
            self._read[path] = self._made_by(path)
        return self._read[path]

    def _made_by(self, path: Path) -> str | None:
        relative = path.relative_to(self.folder).as_posix()
        if relative in COMPANIONS:
            return self(self.folder / COMPANIONS[relative])
        if relative in BY_THE_FOLDERS_CONFIG:
            return self.folder_hash
        if os.path.islink(path) or not path.is_file():
            return None
        return _carried(path)


def _carried(path: Path) -> str | None:
    """The ``config_hash`` the file itself carries (None: none, or unreadable)."""
    try:
        if path.suffix == ".json":
            found = read_json(path)
        elif path.suffix == ".npz":
            found = read_npz(path)[1]
        elif path.suffix == ".mat":
            from scipy.io import loadmat

            found = {"config_hash": str(loadmat(str(path), variable_names=["config_hash"])["config_hash"][0])}
        elif path.suffix == ".png":
            return stamp_of(path)
        elif path.suffix == ".h" or path.name == "README.md":
            with open(path, "rb") as fh:
                match = _TEXT_STAMP.search(fh.read(_STAMP_HEAD))
            return match[1].decode("ascii").lower() if match else None
        else:
            return None
    except (ArtifactError, OSError, ValueError, KeyError, IndexError):  # damaged or foreign: left to its reader
        return None
    found = found.get("config_hash") if isinstance(found, dict) else None
    return found if isinstance(found, str) and found else None
