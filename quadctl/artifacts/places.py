"""Where quadctl writes: the run directory, the names of what it writes there, and the one rule that
keeps every write, read and delete on those names and off symbolic links."""

from __future__ import annotations

import os
import re
from pathlib import Path

from quadctl.errors import ArtifactError


def default_out(cfg) -> Path:
    """The run directory of a config when none is given: ``runs/<config name>``."""
    return Path("runs") / cfg.name


TRIM, LINEAR, SUBSYSTEMS, CHECKS, DESIGN, SIM_NPZ, SIM_JSON = (
    "trim.json", "linear.npz", "subsystems.json", "checks.json", "design.json", "sim.npz", "sim.json")
MARGINS, DESIGN_FULL = "margins.json", "design_full.json"
SCHEDULE_JSON, SCHEDULE_NPZ = "schedule.json", "schedule.npz"
STAGE_FILES = (TRIM, LINEAR, SUBSYSTEMS, CHECKS, DESIGN, SIM_NPZ, SIM_JSON, MARGINS, DESIGN_FULL, SCHEDULE_JSON,
               SCHEDULE_NPZ)
"""The artifacts the stages write (:class:`quadctl.workspace.Workspace`; each carries the ``config_hash`` it was
made from), in the order the stages make them."""
ARTIFACT_NAMES = frozenset({
    "config.yaml", "config.resolved.yaml", *STAGE_FILES, "compare.json",
    "sweep.csv", "sweep.json", "sweep.png", "montecarlo.npz", "montecarlo.png",
    "quadctl_controller.h", "quadctl_controller.c", "quadctl_controller.mat", "quadctl_controller.json",
    "identified.json", "identified.yaml", "identify.png",
    "Makefile", "Kbuild", "app-config", "README.md",  # the Crazyflie app (quadctl.export.crazyflie)
})
"""Every file quadctl writes at the top of a run directory (tests check the workspace's, the
sweep's and the exports' names are among them)."""
PLOTS = "plots"
OWN_FIGURES = ("inputs", "wind", "path", "tracking", "schedule")
"""The figures quadctl draws beside one per subsystem, named alike (``plots/<stem>.png``, the report's
``sim-<stem>.png``): the inputs, the wind, a reference's path and tracking error, the gain schedule. A
subsystem of one of these names would share its figure's file, and lose it: the config refuses them."""
SWEEP_PARTS = "sweep.parts"
"""The subfolder of a sweep's finished chunks (:mod:`quadctl.sweep.store`), read back by ``--resume``."""
SUBFOLDER_NAMES = {
    PLOTS: re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*\.png"),
    SWEEP_PARTS: re.compile(r"chunk-[0-9]+\.json"),
    "report": re.compile(r"report\.(html|md)|[A-Za-z0-9_][A-Za-z0-9_.+-]*\.png"),
    "src": re.compile(r"Kbuild|quadctl_(controller|crazyflie)\.[ch]|quadctl_app\.c"),  # the Crazyflie app's
}
"""The subfolders quadctl writes into, and the names it writes there."""


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


def safe_place(path: Path) -> Path:
    """``path``, checked to be a place quadctl may write or delete: a registered artifact name in the
    run directory or in one of its artifact folders, where that folder is not a symbolic link.

    The safe-write layer's one rule: every write (:func:`~quadctl.artifacts.writing._atomic_write`,
    :func:`~quadctl.artifacts.writing.write_together`) and every delete
    (:func:`~quadctl.artifacts.writing.remove`) goes through here, so nothing quadctl does follows a
    link out of the run directory. A link in place of an artifact *file* is replaced by the rename
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


def refuse_link(path: Path) -> None:
    """A file quadctl reads back as its own artifact must not be a link (to anything, anywhere)."""
    if os.path.islink(path):
        raise ArtifactError(f"{path}: is a symbolic link, not an artifact quadctl wrote; remove it or rerun "
                            "with --fresh (quadctl replaces it)")
    sub = path.parent
    if sub.name in SUBFOLDER_NAMES and os.path.islink(sub):
        raise ArtifactError(_LINK.format(path=sub))


IS_A_DIRECTORY = "{path}: is a directory, not a file quadctl can write; remove it or choose another --out folder"
"""The message for a directory where an artifact file is to be written or read."""


def reason_of(exc: Exception) -> str:
    """Why an I/O call failed, in a few words (the OS's reason, its first line, at most 120 characters)."""
    text = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return text.splitlines()[0][:120]
