"""The safe-write layer: nothing written or deleted through a symbolic link, nothing deleted that
quadctl did not write, files that belong together replaced together.

Every writer (the stage artifacts, the figures, the report, the C/.mat/JSON exports, the sweep's
outputs and chunks) goes through :mod:`quadctl.artifacts`; each is tried with a link where its file
should be (to a file outside, dangling, to another artifact of the run folder: replaced, the
target untouched) and where its folder should be (to a folder outside, dangling, to another
folder of the run: refused, exit code 2, naming the link).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _paths import ROOT

from quadctl import artifacts, config, report
from quadctl.artifacts import writing
from quadctl.errors import ArtifactError
from quadctl.report.document import Document, Figure, Section, Text

PNG = b"\x89PNG\r\n\x1a\n" + b"\x00" * 16 + b"IEND\xaeB`\x82"


# ---------------------------------------------------------------------------------------
# The writers, each as (artifact folder or None, file name, write(run folder))


@pytest.fixture(scope="module")
def crazyflie_export():
    from quadctl import export
    from quadctl.setup import setup_of

    cfg = config.load("crazyflie")
    return export.prepare(setup_of(cfg), config_hash=cfg.digest()), cfg


def _doc() -> Document:
    return Document(title="t", subtitle="s", status=Text("ok"), generator="quadctl",
                    sections=(Section("figs", "Figures", (Figure("roll", "roll", PNG),)),))


def _sweep_store(run: Path):
    from quadctl.sweep import sweep_file
    from quadctl.sweep.store import SweepStore

    cfg = config.load("hover")
    spec = sweep_file.parse("parameters:\n  lqr.yaw.R[0]: [1, 2]\n", cfg, "s.yaml")
    return SweepStore(run, cfg, spec)


def _writers(export_and_cfg):
    exp, cfg = export_and_cfg
    from quadctl import export

    meta = artifacts.metadata(cfg, "export")
    return {
        "json": (None, "trim.json", lambda run: artifacts.write_json(run / "trim.json", {"a": 1})),
        "npz": (None, "linear.npz", lambda run: artifacts.write_npz(run / "linear.npz", {"A": np.eye(2)}, {})),
        "bytes": (None, "config.yaml", lambda run: artifacts.write_bytes(run / "config.yaml", b"name: x\n")),
        "figure": ("plots", "roll.png", lambda run: artifacts.write_bytes(artifacts.plot_path(run, "roll"), PNG)),
        "report": ("report", "report.md", lambda run: report.write(_doc(), run / report.FOLDER)),
        "export c": (None, "quadctl_controller.h", lambda run: export.write(exp, "c", run)),
        "export mat": (None, "quadctl_controller.mat", lambda run: export.write(exp, "mat", run)),
        "export json": (None, "quadctl_controller.json", lambda run: export.write(exp, "json", run, meta)),
        "sweep chunk": ("sweep.parts", "chunk-0000000.json",
                        lambda run: _sweep_store(run).save_chunk([{"case": 0, "x": 1.0}])),
        "sweep start": ("sweep.parts", "chunk-0000000.json", lambda run: _sweep_store(run).start(resume=False)),
    }


WRITERS = ["json", "npz", "bytes", "figure", "report", "export c", "export mat", "export json", "sweep chunk",
           "sweep start"]


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("writer", [w for w in WRITERS if w != "sweep start"])
@pytest.mark.parametrize("target", ["outside", "dangling", "run folder"])
def test_a_link_in_place_of_an_artifact_is_replaced_never_followed(tmp_path, crazyflie_export, writer, target):
    sub, name, write = _writers(crazyflie_export)[writer]
    run, user = tmp_path / "run", tmp_path / "user"
    user.mkdir()
    (user / name).write_bytes(b"the user's")
    folder = run / sub if sub else run
    folder.mkdir(parents=True)
    (run / "notes.txt").write_bytes(b"the run folder's")
    pointee = {"outside": user / name, "dangling": user / "missing", "run folder": run / "notes.txt"}[target]
    (folder / name).symlink_to(pointee)
    write(run)
    assert not (folder / name).is_symlink() and (folder / name).is_file()
    assert (user / name).read_bytes() == b"the user's" and not (user / "missing").exists()
    assert (run / "notes.txt").read_bytes() == b"the run folder's"


@pytest.mark.parametrize("writer", ["figure", "report", "sweep chunk", "sweep start"])
@pytest.mark.parametrize("target", ["outside", "dangling", "run folder"])
def test_a_link_in_place_of_an_artifact_folder_is_refused(tmp_path, crazyflie_export, writer, target):
    sub, name, write = _writers(crazyflie_export)[writer]
    run, user = tmp_path / "run", tmp_path / "user"
    user.mkdir()
    (user / name).write_bytes(b"the user's")
    (user / "holiday.png").write_bytes(b"the user's photo")
    (user / "chunk-0000007.json").write_bytes(b"the user's")
    run.mkdir()
    (run / "elsewhere").mkdir()
    pointee = {"outside": user, "dangling": tmp_path / "missing", "run folder": run / "elsewhere"}[target]
    (run / sub).symlink_to(pointee, target_is_directory=True)
    before = _snapshot(tmp_path)
    with pytest.raises(ArtifactError, match=rf"^{run / sub}: is a symbolic link where quadctl keeps its own "
                                            "folder; .*remove the link, or choose another --out folder"):
        write(run)
    assert _snapshot(tmp_path) == before and not (tmp_path / "missing").exists()


def test_report_into_a_linked_report_folder_exits_2_and_touches_nothing_there(tmp_path):
    """The issue's case, end to end: ``out/report`` a link to a user's folder of photos. Refused before
    any stage runs: nothing written anywhere, nothing deleted."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    photos = tmp_path / "photos"
    photos.mkdir()
    (photos / "holiday.png").write_bytes(b"a photo")
    out = tmp_path / "out"
    out.mkdir()
    (out / "report").symlink_to(photos, target_is_directory=True)
    res = CliRunner().invoke(app, ["report", "-c", "crazyflie", "-o", str(out)])
    assert res.exit_code == 2, res.output
    assert res.stderr == (f"quadctl: error: {out / 'report'}: is a symbolic link where quadctl keeps its own folder; "
                          "quadctl never writes or deletes through a link: remove the link, or choose another "
                          "--out folder\n")
    assert sorted(p.name for p in photos.iterdir()) == ["holiday.png"]
    assert (photos / "holiday.png").read_bytes() == b"a photo"
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["report"]


def test_the_lock_file_is_never_written_through_a_link(tmp_path):
    user = tmp_path / "diary.txt"
    user.write_text("the user's")
    run = tmp_path / "run"
    run.mkdir()
    (run / artifacts.LOCK_NAME).symlink_to(user)
    with pytest.raises(ArtifactError, match=r"\.quadctl\.lock: is a symbolic link, not quadctl's lock file; remove it"):
        with artifacts.locked(run):
            pass
    assert user.read_text() == "the user's"


def test_stale_temporaries_are_not_removed_through_a_linked_folder(tmp_path):
    user = tmp_path / "user"
    user.mkdir()
    theirs = user / ".roll.png.quadctl-abcdefgh.tmp"
    theirs.write_text("x")
    old = os.path.getmtime(theirs) - 2 * artifacts.STALE_TEMPORARY_AGE
    os.utime(theirs, (old, old))
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "plots").symlink_to(user, target_is_directory=True)
    assert artifacts.remove_stale_temporaries(tmp_path / "run") == [] and theirs.exists()


def test_an_artifact_read_back_through_a_link_is_not_reused(tmp_path):
    from quadctl.workspace import Workspace

    cfg = config.load("hover")
    elsewhere = tmp_path / "elsewhere"
    Workspace(cfg, elsewhere).trim  # noqa: B018 - a fresh trim.json, outside the run folder
    run = tmp_path / "run"
    run.mkdir()
    (run / "trim.json").symlink_to(elsewhere / "trim.json")
    assert not artifacts.is_fresh(run / "trim.json", cfg)
    with pytest.raises(ArtifactError, match="trim.json: is a symbolic link, not an artifact quadctl wrote"):
        artifacts.read_json(run / "trim.json")
    ws = Workspace(cfg, run)
    ws.trim  # noqa: B018 - recomputed, and written in place of the link
    assert not (run / "trim.json").is_symlink() and ws.path("trim.json") in ws.written


def test_the_report_removes_only_figures_an_earlier_report_wrote(tmp_path):
    folder = tmp_path / report.FOLDER
    first = Document(title="t", subtitle="s", status=Text("ok"), generator="quadctl", sections=(
        Section("figs", "Figures", (Figure("roll", "roll", PNG), Figure("pitch", "pitch", PNG))),))
    report.write(first, folder)
    (folder / "mine.png").write_bytes(b"the user's")
    report.write(_doc(), folder)  # shows roll only
    assert sorted(p.name for p in folder.glob("*.png")) == ["mine.png", "roll.png"]


def test_remove_deletes_a_link_in_place_of_an_artifact_never_its_target(tmp_path):
    """What a sweep does with an earlier Monte Carlo's files, and a report with an earlier figure."""
    user = tmp_path / "photo.png"
    user.write_bytes(b"the user's")
    (tmp_path / "run" / report.FOLDER).mkdir(parents=True)
    for where in (tmp_path / "run" / "montecarlo.png", tmp_path / "run" / report.FOLDER / "roll.png"):
        where.symlink_to(user)
        assert artifacts.remove(where) and not where.is_symlink()
    assert user.read_bytes() == b"the user's"


def test_remove_refuses_what_is_not_an_artifact(tmp_path):
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(ValueError, match="not an artifact name quadctl writes"):
        artifacts.remove(tmp_path / "notes.txt")
    assert (tmp_path / "notes.txt").exists()


# ---------------------------------------------------------------------------------------
# Files that belong together: the C header and source


def _pair(folder: Path) -> tuple[str, str]:
    import re

    header = (folder / "quadctl_controller.h").read_text()
    source = (folder / "quadctl_controller.c").read_text()
    return (re.search(r"#define QUADCTL_PAIR (\S+)", header)[1],
            re.search(r"#if !defined\(QUADCTL_PAIR\) \|\| QUADCTL_PAIR != (\S+)", source)[1])


KILLED_EXPORT = """
import os, signal, sys
from quadctl.artifacts import writing
steps, kill_at = [0], int(sys.argv[1])
def step(path):
    if "quadctl_controller." in os.fspath(path):  # the C pair's writes (not the config's beside them)
        steps[0] += 1
        if steps[0] == kill_at:
            os.kill(os.getpid(), signal.SIGKILL)
temporary, replace = writing._temporary, os.replace
def counted_temporary(*a):
    out = temporary(*a)
    step(out)
    return out
def counted_replace(*a):
    replace(*a)
    step(a[1])
writing._temporary, writing.os.replace = counted_temporary, counted_replace
sys.argv = ["quadctl", "export", "--to", "c", "-c", "drake-hover", "--rate", sys.argv[2], "-o", sys.argv[3]]
from quadctl.cli.entry import main
main()
"""


def _export(rate: str, out: Path, kill: int = 0) -> subprocess.CompletedProcess:
    """``quadctl export --to c`` of ``drake-hover``'s continuous design run at ``rate`` Hz (the same config
    at another rate: another pair, replaced in place, the config's run kept) in a new process, killed
    (SIGKILL) after its ``kill``-th write step of the pair (a temporary written, or a rename done; 0: never)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT),
                                                                      os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-c", KILLED_EXPORT, str(kill), rate, str(out)], env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def old_pair(tmp_path_factory) -> Path:
    """A run folder holding drake-hover's C pair run at 1000 Hz (the files an export at 500 Hz replaces)."""
    out = tmp_path_factory.mktemp("old-pair")
    assert _export("1000", out).returncode == 0
    return out


@pytest.mark.parametrize("kill_after", [1, 2, 3], ids=["first temporary", "both temporaries", "first rename"])
def test_a_kill_between_the_c_files_leaves_no_pair_that_compiles_and_the_next_export_cleans_up(tmp_path, kill_after,
                                                                                              old_pair):
    """``kill -9`` aimed after each write of ``export --to c`` but the last: the files on disk are the
    old pair, or a mixed pair whose source refuses the header (#error); the temporaries left behind
    are removed by the next export, which writes a matched pair."""
    import shutil

    from quadctl.native.compile import find_compiler

    out = tmp_path / "run"
    shutil.copytree(old_pair, out)

    def export(rate: str, kill: int = 0):
        return _export(rate, out, kill)

    old = _pair(out)
    assert old[0] == old[1]
    killed = export("500", kill_after)
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    header_id, source_id = _pair(out)
    temporaries = sorted(p.name for p in out.glob(".quadctl_controller.*.tmp"))
    assert temporaries, "the kill left no temporary: it did not land mid-write"
    if kill_after < 3:
        assert (header_id, source_id) == old  # no rename yet: the old pair, whole
    else:
        assert header_id != source_id  # the new header beside the old source
        compiler = find_compiler()
        if compiler is not None:
            res = subprocess.run([compiler, "-std=c99", "-c", str(out / "quadctl_controller.c"), "-o",
                                  str(tmp_path / "x.o")], capture_output=True, text=True)
            assert res.returncode != 0 and "come from different exports: export again" in res.stderr
    again = export("500")
    assert again.returncode == 0, again.stderr
    header_id, source_id = _pair(out)
    assert header_id == source_id != old[0]
    assert not list(out.glob(".*.tmp"))


def test_write_together_renames_only_when_every_file_is_whole(tmp_path, monkeypatch):
    """A failure while writing the second file leaves the first file's old content, and no temporary."""
    a, b = tmp_path / "quadctl_controller.h", tmp_path / "quadctl_controller.c"
    a.write_text("old h")
    b.write_text("old c")
    temporary = writing._temporary

    def failing(path, data):
        if path == b:
            raise OSError(28, "No space left on device")
        return temporary(path, data)

    monkeypatch.setattr(writing, "_temporary", failing)
    with pytest.raises(ArtifactError, match=r"quadctl_controller\.c: cannot write the artifact \(No space left"):
        artifacts.write_together({a: b"new h", b: b"new c"})
    assert a.read_text() == "old h" and b.read_text() == "old c"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["quadctl_controller.c", "quadctl_controller.h"]


def test_a_signal_while_a_temporary_is_made_leaves_no_temporary(tmp_path, monkeypatch):
    """Ctrl-C (or SIGTERM) landing just after the temporary file exists, before its name is kept:
    the signal waits until the temporary is listed, then stops the write, which discards it (it was
    left behind, empty, when a SIGTERM landed there: seen in CI)."""
    target = tmp_path / "trim.json"
    target.write_text("old")
    mkstemp = writing.tempfile.mkstemp

    def interrupted(*args, **kwargs):
        made = mkstemp(*args, **kwargs)
        signal.raise_signal(signal.SIGINT)  # Python's handler raises KeyboardInterrupt at once, unless held
        return made

    monkeypatch.setattr(writing.tempfile, "mkstemp", interrupted)
    with pytest.raises(KeyboardInterrupt):
        artifacts.write_together({target: b"new"})
    assert [p.name for p in tmp_path.iterdir()] == ["trim.json"] and target.read_text() == "old"
