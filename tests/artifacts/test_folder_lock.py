"""One quadctl per run directory: `artifacts.locked`, held across processes."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from quadctl import artifacts
from quadctl.artifacts import lock
from quadctl.errors import ArtifactError

HOLD = textwrap.dedent("""
    import sys, time
    from quadctl import artifacts
    from quadctl.artifacts import lock
    if sys.argv[2] == "exclusive":
        lock.fcntl = None
    with artifacts.locked(sys.argv[1]):
        print("held", flush=True)
        time.sleep(float(sys.argv[3]))
    print("released", flush=True)
""")


def _holder(folder, mode="flock", seconds=60.0) -> subprocess.Popen:
    """Another process that takes the folder and says so."""
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(folder), mode, str(seconds)],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


MODES = ["flock", pytest.param("exclusive", id="O_EXCL (no fcntl)")]


@pytest.fixture(params=MODES)
def mode(request, monkeypatch):
    if request.param == "exclusive":
        monkeypatch.setattr(lock, "fcntl", None)
    elif lock.fcntl is None:
        pytest.skip("no fcntl on this platform")
    return request.param


def test_a_folder_held_by_another_process_is_refused_with_its_pid(tmp_path, mode):
    folder = tmp_path / "runs" / "x"
    other = _holder(folder, mode)
    try:
        with pytest.raises(ArtifactError, match=rf"^{folder} is in use by another quadctl \(pid {other.pid}\); "
                                                r"wait for it or use -o another folder"):
            with artifacts.locked(folder):
                pytest.fail("two processes held the same run directory")
        with artifacts.locked(tmp_path / "runs" / "y"):  # another folder is free
            pass
    finally:
        other.kill()
        other.wait()
    if mode == "exclusive":  # a holder killed hard leaves its file: the message says what to do
        with pytest.raises(ArtifactError, match=rf"if no quadctl runs there, delete {folder / artifacts.LOCK_NAME}"):
            with artifacts.locked(folder):
                pass
        (folder / artifacts.LOCK_NAME).unlink()
    with artifacts.locked(folder):  # flock: the kernel released it when the holder died
        pass


def test_the_folder_is_free_again_when_the_holder_is_done(tmp_path, mode):
    other = _holder(tmp_path, mode, seconds=0.2)
    assert other.stdout.readline().strip() == "released"
    other.wait(timeout=30)
    with artifacts.locked(tmp_path):
        pass
    with artifacts.locked(tmp_path):  # and after we are done too
        pass


def test_the_lock_is_reentrant_within_a_process_and_held_until_the_outer_block_ends(tmp_path):
    with artifacts.locked(tmp_path):
        with artifacts.locked(tmp_path):
            pass
        probe = subprocess.run([sys.executable, "-c", HOLD, str(tmp_path), "flock", "0"], capture_output=True,
                               text=True, timeout=60)
        assert probe.returncode != 0 and f"pid {os.getpid()}" in probe.stderr  # still ours
    other = _holder(tmp_path, "flock", seconds=0)
    other.wait(timeout=30)


def test_the_lock_file_holds_the_pid_and_is_not_an_artifact(tmp_path):
    with artifacts.locked(tmp_path):
        assert (tmp_path / artifacts.LOCK_NAME).read_text().strip() == str(os.getpid())
    assert artifacts.LOCK_NAME not in artifacts.ARTIFACT_NAMES  # the file may stay: never taken for one


def test_two_commands_on_one_run_folder_are_not_run_side_by_side(tmp_path):
    """The workspace and the sweep hold the folder: a second quadctl on it is refused, whole."""
    import subprocess
    import sys
    import time

    held = subprocess.Popen([sys.executable, "-c", (
        "import sys, time\n"
        "from quadctl import config\n"
        "from quadctl.workspace import Workspace\n"
        f"ws = Workspace(config.load('hover'), {str(tmp_path)!r})\n"
        "print('held', flush=True)\n"
        "time.sleep(30)\n")], stdout=subprocess.PIPE, text=True)
    try:
        assert held.stdout.readline().strip() == "held"
        for args in (["simulate", "-c", "hover"], ["sweep", "-c", "hover", "-s", str(_sweep_file(tmp_path))]):
            res = subprocess.run([sys.executable, "-m", "quadctl", *args, "-o", str(tmp_path)],
                                 capture_output=True, text=True, timeout=120)
            assert res.returncode == 2, res.stderr
            assert f"{tmp_path} is in use by another quadctl (pid {held.pid})" in res.stderr
        assert not (tmp_path / "sim.npz").exists() and not (tmp_path / "sweep.csv").exists()
    finally:
        held.kill()
        held.wait()
    started = time.monotonic()
    res = subprocess.run([sys.executable, "-m", "quadctl", "trim", "-c", "hover", "-o", str(tmp_path)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr  # the holder is gone: the folder is free again
    assert not (tmp_path / artifacts.LOCK_NAME).exists()  # and the command leaves no lock file behind
    assert time.monotonic() - started < 60


def _sweep_file(tmp_path):
    path = tmp_path.parent / "lock-sweep.yaml"
    path.write_text("parameters:\n  lqr.roll.R[0]: [1.0, 2.0]\nset:\n  simulation.duration: 0.05\n")
    return path


def test_the_lock_file_is_removed_when_the_holder_is_done(tmp_path, mode):
    with artifacts.locked(tmp_path):
        with artifacts.locked(tmp_path):
            pass
        assert (tmp_path / artifacts.LOCK_NAME).exists()  # the inner block does not release it
    assert not (tmp_path / artifacts.LOCK_NAME).exists()
    other = _holder(tmp_path, mode, seconds=0)
    assert other.stdout.readline().strip() == "released"
    other.wait(timeout=30)
    assert not (tmp_path / artifacts.LOCK_NAME).exists()  # nor in a run folder after another process


@pytest.mark.skipif(lock.fcntl is None, reason="flock only")
def test_a_lock_taken_on_a_file_its_holder_removed_meanwhile_is_taken_again_on_the_new_file(tmp_path, monkeypatch):
    """The holder's release (remove, then unlock) can fall between our open and our flock: the lock we
    got is on a file the path no longer names, and a third process would lock a new one beside us."""
    real_flock = lock.fcntl.flock
    calls = []

    def flock_after_the_holder_left(fd, op):
        if not calls and op & lock.fcntl.LOCK_EX:
            (tmp_path / artifacts.LOCK_NAME).unlink()  # the holder's release, just before our lock
        calls.append(op)
        return real_flock(fd, op)

    monkeypatch.setattr(lock.fcntl, "flock", flock_after_the_holder_left)
    with artifacts.locked(tmp_path):
        monkeypatch.setattr(lock.fcntl, "flock", real_flock)
        probe = subprocess.run([sys.executable, "-c", HOLD, str(tmp_path), "flock", "0"], capture_output=True,
                               text=True, timeout=60)
        assert probe.returncode != 0 and f"pid {os.getpid()}" in probe.stderr  # the path's file is ours
    assert len([op for op in calls if op & lock.fcntl.LOCK_EX]) == 2  # taken again on the new file


def test_a_hold_that_ends_with_nothing_written_leaves_no_folder_it_made(tmp_path):
    """A command refused after it took its run folder (compare of a config without rotors) left the folder it
    made, empty, with its parents: the folders a hold makes go again while empty; one that was there, or one
    with a file in it, stays."""
    new = tmp_path / "runs" / "new"
    with pytest.raises(RuntimeError, match="refused"), artifacts.locked(new):
        assert new.is_dir()
        raise RuntimeError("refused")
    assert not (tmp_path / "runs").exists()
    with artifacts.locked(new):
        (new / "mine.txt").write_text("kept")
    assert (new / "mine.txt").read_text() == "kept"
    there = tmp_path / "there"
    there.mkdir()
    with artifacts.locked(there):
        pass
    assert there.is_dir()
