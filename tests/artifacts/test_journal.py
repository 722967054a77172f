"""A run folder's journals: the next holder of the folder finishes a dead session as Ctrl-C would have,
follows only journals that name quadctl's own files, and says what it did."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from quadctl import artifacts
from quadctl.artifacts.journal import signals_held

ASIDE = ".trim.json.quadctl-undo0000abcd.tmp"
"""A file set aside for a roll-back, as a session names it."""


def _journal(folder: Path, *records: dict) -> Path:
    path = folder / ".quadctl.journal.0123abcd"
    path.write_text("".join(json.dumps(r) + "\n" for r in records))
    return path


def test_a_dead_sessions_journal_puts_the_earlier_run_back(tmp_path):
    (tmp_path / "trim.json").write_bytes(b"the dead run's")
    (tmp_path / ASIDE).write_bytes(b"the earlier run's")
    (tmp_path / "sim.npz").write_bytes(b"made by the dead run")
    journal = _journal(tmp_path, {"path": "trim.json", "before": {"aside": ASIDE}}, {"replaced": ["trim.json"]},
                       {"wrote": "trim.json"}, {"replaced": ["design.json"]},
                       {"path": "sim.npz", "before": {"absent": True}})
    with open(journal, "a") as f:
        f.write('{"wrote": "sim.n')  # the line the kill cut short
    notes = artifacts.take_over(tmp_path)
    assert (tmp_path / "trim.json").read_bytes() == b"the earlier run's"
    assert not (tmp_path / "sim.npz").exists() and not (tmp_path / ASIDE).exists() and not journal.exists()
    assert len(notes) == 1 and notes[0].endswith("had removed design.json of the earlier config's run and not "
                                                 "written them again: the earlier run is put back")


def test_a_journal_that_names_files_outside_the_folder_is_not_followed(tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("mine")
    journal = _journal(folder, {"path": "../victim.txt", "before": {"absent": True}}, {"replaced": ["sim.npz"]})
    notes = artifacts.take_over(folder)
    assert victim.read_text() == "mine" and not journal.exists()
    assert len(notes) == 1 and "unfollowed" in notes[0] and "nothing was put back" in notes[0]


def test_a_journal_whose_set_aside_files_are_gone_puts_nothing_back_and_says_so(tmp_path):
    (tmp_path / "trim.json").write_bytes(b"the dead run's")
    _journal(tmp_path, {"path": "trim.json", "before": {"aside": ASIDE}}, {"replaced": ["linear.npz"]})
    notes = artifacts.take_over(tmp_path)
    assert (tmp_path / "trim.json").read_bytes() == b"the dead run's"
    assert len(notes) == 1 and notes[0].endswith(f"files it set aside are gone ({ASIDE}): nothing was put back")


def test_a_cleanup_without_the_folders_lock_keeps_what_a_journal_set_aside(tmp_path):
    """A sweep cleans its old temporaries without the folder's lock: a file a dead session set aside
    (old as the file it keeps) stays while a journal names it, for the next lock holder."""
    (tmp_path / ASIDE).write_bytes(b"the earlier run's")
    stray = tmp_path / ".sim.npz.quadctl-1a2b3c4d.tmp"
    stray.write_bytes(b"half written")
    _journal(tmp_path, {"path": "trim.json", "before": {"aside": ASIDE}})
    assert artifacts.remove_stale_temporaries(tmp_path, age=0.0) == [stray]
    assert (tmp_path / ASIDE).exists()


def _killed_removing(folder, which: str) -> int:
    """The exit code of a hover session (2 s, another config than the folder's) killed (exit 9) as it removes
    the second of the earlier config's files that ``which`` (a Python condition on ``path``) takes in."""
    code = ("import os, pathlib\n"
            "from quadctl import config\n"
            "from quadctl.workspace import Workspace\n"
            "real = pathlib.Path.unlink\n"
            "seen = []\n"
            "def removed(path, *args, **kwargs):\n"
            f"    if not path.name.startswith('.') and ({which}):  # an artifact, not a temporary or the journal\n"
            "        seen.append(path)\n"
            "        if len(seen) == 2:\n"
            "            os._exit(9)\n"
            "    return real(path, *args, **kwargs)\n"
            "pathlib.Path.unlink = removed\n"
            "cfg = config.load('hover')\n"
            "cfg = cfg.model_copy(update={'simulation': cfg.simulation.model_copy(update={'duration': 2.0})})\n"
            f"Workspace(cfg, {str(folder)!r}).trim\n")
    return subprocess.run([sys.executable, "-c", code], capture_output=True).returncode


def test_a_session_killed_while_it_removes_the_earlier_configs_artifacts_is_undone(tmp_path):
    """Killed between removing one of the earlier config's artifacts and the next: the removal was
    journaled before the file went, so the next session puts it back."""
    assert subprocess.run([sys.executable, "-m", "quadctl", "design", "-c", "hover", "-o", str(tmp_path)],
                          capture_output=True).returncode == 0
    before = (tmp_path / "trim.json").read_bytes()
    assert _killed_removing(tmp_path, "True") == 9  # trim.json is gone, linear.npz is next: killed there
    assert not (tmp_path / "trim.json").exists()
    notes = artifacts.take_over(tmp_path)
    assert (tmp_path / "trim.json").read_bytes() == before
    assert len(notes) == 1 and "had removed trim.json of the earlier config's run" in notes[0]


def test_a_session_killed_while_it_removes_the_earlier_configs_figures_is_undone(tmp_path):
    """Killed after it removed the earlier config's stage artifacts and a figure in plots/: the next
    session puts every one back, the figure in its folder too."""
    run = [sys.executable, "-m", "quadctl", "simulate", "-c", "hover", "-o", str(tmp_path), "--plot",
           "--set", "simulation.duration=1"]
    assert subprocess.run(run, capture_output=True, env={**os.environ, "MPLBACKEND": "Agg"}).returncode == 0
    def files():
        return {p.relative_to(tmp_path).as_posix(): p.read_bytes() for p in tmp_path.rglob("*")
                if p.is_file() and p.name != artifacts.LOCK_NAME}

    before = files()
    assert "plots/roll.png" in before
    assert _killed_removing(tmp_path, "path.parent.name == 'plots'") == 9  # one figure gone, at the next
    assert not (tmp_path / "sim.npz").exists() and len(list(tmp_path.glob("plots/*.png"))) == len(
        [n for n in before if n.startswith("plots/")]) - 1
    notes = artifacts.take_over(tmp_path)
    assert files() == before
    assert len(notes) == 1 and "sim.npz" in notes[0] and "plots/" in notes[0] and "put back" in notes[0]


def test_the_journal_is_on_the_disk_before_the_first_of_the_earlier_configs_artifacts_goes(tmp_path, monkeypatch):
    """A power cut right after the removal still finds the journal that puts the file back: the journal
    and its folder (its name, the files set aside) are fsynced before the first file goes."""
    from quadctl import config
    from quadctl.errors import QuadctlNotice
    from quadctl.workspace import Workspace

    cfg = config.load("hover")
    earlier = Workspace(cfg, tmp_path)
    assert earlier.trim.residual < 1e-6 and (tmp_path / "trim.json").is_file()  # the earlier config's run
    earlier.close()
    synced, seen_at_removal = set(), []
    real_fsync, real_unlink = os.fsync, Path.unlink

    def fsync(fd):
        info = os.fstat(fd)
        synced.add((info.st_dev, info.st_ino))
        real_fsync(fd)

    def unlink(path, *args, **kwargs):
        if not path.name.startswith(".") and not seen_at_removal:  # the first artifact removed
            journal = os.stat(next(tmp_path.glob(".quadctl.journal.*")))
            seen_at_removal.append({(journal.st_dev, journal.st_ino), (os.stat(tmp_path).st_dev,
                                                                     os.stat(tmp_path).st_ino)} <= synced)
        real_unlink(path, *args, **kwargs)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(Path, "unlink", unlink)
    changed = cfg.model_copy(update={"vehicle": cfg.vehicle.model_copy(update={"mass": cfg.vehicle.mass * 1.01})})
    ws = Workspace(changed, tmp_path)
    with pytest.warns(QuadctlNotice, match=r"removed trim\.json, made by another config"):
        assert ws.trim.residual < 1e-6
    assert ws.replaced == ["trim.json"] and seen_at_removal == [True]
    ws.close()


def test_a_dead_session_that_wrote_each_artifact_it_removed_again_is_kept(tmp_path):
    """As Ctrl-C at that point keeps it: the dead run is whole; only what it set aside goes."""
    (tmp_path / "trim.json").write_bytes(b"the dead run's")
    (tmp_path / ASIDE).write_bytes(b"the earlier run's")
    (tmp_path / "sim.npz").write_bytes(b"made by the dead run")
    _journal(tmp_path, {"path": "trim.json", "before": {"aside": ASIDE}}, {"replaced": ["trim.json"]},
             {"wrote": "trim.json"}, {"path": "sim.npz", "before": {"absent": True}}, {"wrote": "sim.npz"})
    assert artifacts.take_over(tmp_path) == []
    assert (tmp_path / "trim.json").read_bytes() == b"the dead run's"
    assert (tmp_path / "sim.npz").read_bytes() == b"made by the dead run"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sim.npz", "trim.json"]


def test_a_take_over_cut_short_is_finished_not_redone(tmp_path):
    """A put-back killed half way recorded each file it had put back: the next finishes the rest (the
    files already back have no set-aside file any more, and that is not a loss)."""
    (tmp_path / "trim.json").write_bytes(b"the earlier run's, back already")
    (tmp_path / "linear.npz").write_bytes(b"the dead run's")
    aside = ".linear.npz.quadctl-undo0000abce.tmp"
    (tmp_path / aside).write_bytes(b"the earlier run's")
    _journal(tmp_path, {"path": "trim.json", "before": {"aside": ASIDE}},
             {"path": "linear.npz", "before": {"aside": aside}}, {"replaced": ["sim.npz"]},
             {"undone": "trim.json"})
    notes = artifacts.take_over(tmp_path)
    assert (tmp_path / "linear.npz").read_bytes() == b"the earlier run's"
    assert (tmp_path / "trim.json").read_bytes() == b"the earlier run's, back already"
    assert len(notes) == 1 and notes[0].endswith("the earlier run is put back")


@pytest.mark.parametrize("line", ["[" * 100_000 + "]" * 100_000, b"\xff\xfe{}"], ids=["deep", "not-text"])
def test_a_journal_of_any_shape_is_a_note_not_an_error(tmp_path, line):
    journal = tmp_path / ".quadctl.journal.0123abcd"
    journal.write_bytes(line.encode() if isinstance(line, str) else line)
    notes = artifacts.take_over(tmp_path)
    assert len(notes) == 1 and "unfollowed" in notes[0] and not journal.exists()


def test_every_first_holder_of_the_folder_finishes_a_dead_session(tmp_path):
    """Not only the stages' workspace: a sweep, identify or export takes the folder by its lock, and the
    lock's first holder finishes what a dead session left."""
    (tmp_path / artifacts.MARK_NAME).write_text("")  # a run folder of quadctl's
    (tmp_path / "trim.json").write_bytes(b"the dead run's")
    (tmp_path / ASIDE).write_bytes(b"the earlier run's")
    _journal(tmp_path, {"path": "trim.json", "before": {"aside": ASIDE}}, {"replaced": ["sim.npz"]})
    with pytest.warns(Warning, match="the earlier run is put back"):
        with artifacts.locked(tmp_path):
            pass
    assert (tmp_path / "trim.json").read_bytes() == b"the earlier run's"


def test_ctrl_c_waits_until_a_put_back_is_done():
    """Held by a handler of its own, not a signal mask (a BLAS thread, unmasked, would take it and
    Python would raise at once): the block ends, then the Ctrl-C is raised."""
    done = []
    with pytest.raises(KeyboardInterrupt):
        with signals_held():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
            done.append(sum(range(10_000)))
    assert done == [sum(range(10_000))]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
