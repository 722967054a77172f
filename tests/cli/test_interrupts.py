"""Stopping runs: Ctrl-C answers within a second and never prints a traceback; a killed sweep
leaves no worker behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

LONG_SWEEP = """\
parameters:
  lqr.roll.R[0]: [1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6, 1.7, 1.8, 1.9, 2.0, 2.1, 2.2, 2.3, 2.4, 2.5]
set:
  simulation.duration: 200.0
chunk_size: 8
"""
"""16 cases of 200 s at the report's auto step (5.8 M RK4 steps each): seconds per chunk."""


def _children(pid: int) -> list[int]:
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                out.append(int(entry.name))
    return out


def _alive(pid: int) -> bool:
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _start_sweep(tmp_path: Path) -> subprocess.Popen:
    spec = tmp_path / "long.yaml"
    spec.write_text(LONG_SWEEP)
    proc = subprocess.Popen([sys.executable, "-m", "quadctl", "sweep", "-c", "forward", "-s", str(spec),
                             "-j", "2", "-o", str(tmp_path / "out")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while len(_children(proc.pid)) < 2:  # the workers are computing (the warm-up case ran)
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the sweep never started its workers"
        time.sleep(0.05)
    time.sleep(0.5)
    return proc


def test_ctrl_c_stops_a_sweep_within_a_second_and_its_workers_with_it(tmp_path):
    proc = _start_sweep(tmp_path)
    workers = _children(proc.pid)
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    took = time.monotonic() - sent
    assert proc.returncode == 130, err
    assert took < 1.5, f"Ctrl-C took {took:.2f} s"
    assert "Traceback" not in err and "interrupted" in err
    assert not any(_alive(w) for w in workers)


def test_a_killed_sweep_leaves_no_worker_behind(tmp_path):
    proc = _start_sweep(tmp_path)
    workers = _children(proc.pid)
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    deadline = time.monotonic() + 3
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(_alive(w) for w in workers), "workers outlived their killed parent"


def test_ctrl_c_while_the_commands_import_prints_one_line_not_a_traceback():
    """Ctrl-C that lands while the console script imports typer and the commands (its first ~0.2 s;
    before that Python itself is starting, which no program controls)."""
    code = ("import sys\n"
            "class Interrupt:\n"
            "    def find_spec(self, name, path=None, target=None):\n"
            "        if name == 'typer':\n"
            "            raise KeyboardInterrupt\n"
            "sys.meta_path.insert(0, Interrupt())\n"
            "sys.argv = ['quadctl', 'configs']\n"
            "from quadctl.cli.entry import main\n"
            "main()\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 130 and res.stderr == "quadctl: error: interrupted\n", res.stderr
