"""Faults lose nothing: real runs killed at random points leave every artifact whole."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from quadctl import artifacts

PNG_END = b"IEND\xaeB`\x82"


def _assert_whole(folder: Path) -> list[str]:
    """Every visible file in ``folder`` parses completely; returns their names."""
    names = []
    for path in sorted(folder.rglob("*")):
        if path.is_dir() or path.name.startswith("."):
            continue
        names.append(path.name)
        if path.suffix == ".json":
            json.loads(path.read_text())
        elif path.suffix == ".npz":
            with np.load(path) as npz:
                for key in npz.files:
                    npz[key]  # noqa: B018 - reading every member checks its CRC
        elif path.suffix == ".png":
            data = path.read_bytes()
            assert data.startswith(b"\x89PNG") and data.endswith(PNG_END), path
    return names


def _start(out: Path) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "quadctl", "run", "-c", "forward-script-q", "-o", str(out), "--plot"]
    # a child of a background job inherits an ignored SIGINT: give it the default back
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            env={**os.environ, "MPLBACKEND": "Agg"},
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


@pytest.mark.parametrize("delay", [0.4, 0.9, 1.3, 1.7, 2.2, 3.0])
def test_sigkill_at_any_point_leaves_whole_artifacts(tmp_path, delay):
    proc = _start(tmp_path)
    time.sleep(delay)
    proc.kill()
    proc.wait()
    _assert_whole(tmp_path)


def test_sigint_exits_130_with_a_message_and_keeps_artifacts(tmp_path):
    proc = _start(tmp_path)
    deadline = time.time() + 60
    while not (tmp_path / "trim.json").exists() and time.time() < deadline:
        time.sleep(0.005)
    proc.send_signal(signal.SIGINT)  # the run has a second or more of work left
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err.decode()
    assert "interrupted; artifacts written before this point are complete" in err.decode()
    assert "Traceback" not in err.decode()
    assert "trim.json" in _assert_whole(tmp_path)


def test_a_killed_runs_stale_temporary_is_cleaned_up(tmp_path):
    stale = tmp_path / ".trim.json.abc.tmp"
    stale.write_text('{"half')
    old = time.time() - 2 * artifacts.STALE_TEMPORARY_AGE
    os.utime(stale, (old, old))
    fresh = tmp_path / ".sim.npz.def.tmp"  # maybe a live writer's: left alone
    fresh.write_text("")
    assert artifacts.remove_stale_temporaries(tmp_path) == [stale]
    assert not stale.exists() and fresh.exists()


def test_ctrl_c_stops_a_long_simulation_promptly(tmp_path):
    """The compiled loop runs in ~50 ms chunks, so an interrupt does not wait for the whole run."""
    from quadctl import config

    path = tmp_path / "long.yaml"
    path.write_text(config.resolve("forward-script-q")[1].replace("duration: 10.0", "duration: 600.0"))
    cmd = [sys.executable, "-m", "quadctl", "simulate", "-c", str(path), "-o", str(tmp_path / "out")]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 60
    while not (tmp_path / "out" / "design.json").exists() and time.time() < deadline:
        time.sleep(0.01)
    time.sleep(0.5)  # well inside the ~20 s integration (1.1e8 steps)
    sent = time.time()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    waited = time.time() - sent
    assert proc.returncode == 130, err.decode()
    assert waited < 5.0, f"Ctrl-C took {waited:.1f} s to stop the run"
