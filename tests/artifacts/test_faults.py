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


FINAL = "plots/inputs.png"
"""The last file `run --plot` writes: while it is missing, the run has not completed."""

WINDOWS = [  # (an artifact that exists, one that does not yet, a pause between seeing one and killing)
    ("trim.json", "sim.npz", 0.0),            # during linearize, decouple, check, design
    ("design.json", "sim.npz", 0.15),         # during the simulation
    ("sim.json", "plots/altitude.png", 0.0),  # between the artifacts and the first figure
    ("plots/roll.png", FINAL, 0.0),           # between figures
]
AFTER_THE_SIMULATION = pytest.mark.compiler  # interpreted, its 1.8 M steps take minutes: no window in 2 min


def _window(earlier: str, later: str, pause: float):
    marks = [AFTER_THE_SIMULATION] if later != "sim.npz" else []
    if earlier in ("trim.json", "plots/roll.png"):  # the windows beside the default ones: with the slow tests
        marks.append(pytest.mark.slow)
    return pytest.param(earlier, later, pause, id=f"after {earlier}", marks=marks)


def _kill_between(proc: subprocess.Popen, out: Path, earlier: str, later: str, pause: float) -> bool:
    """Kill ``proc`` once ``earlier`` exists and ``later`` does not yet; False if that moment was missed."""
    deadline = time.time() + 120
    while not (out / earlier).exists():
        if proc.poll() is not None or time.time() > deadline:
            break
        time.sleep(0.001)
    time.sleep(pause)
    landed = (out / earlier).exists() and not (out / later).exists() and proc.poll() is None
    proc.kill()
    proc.communicate(timeout=60)
    return landed


@pytest.mark.parametrize("earlier, later, pause", [_window(*w) for w in WINDOWS])
def test_sigkill_mid_run_leaves_whole_artifacts(tmp_path, earlier, later, pause):
    """A `kill -9` that lands mid-run (proved: the run was alive, a later artifact not yet written,
    the run never completed) leaves every file it wrote whole, and no visible half-written one."""
    for attempt in range(3):
        out = tmp_path / f"attempt-{attempt}"
        proc = _start(out)
        if _kill_between(proc, out, earlier, later, pause):
            break
    else:
        pytest.fail(f"three runs gave no moment with {earlier} written and {later} not yet")
    assert proc.returncode == -signal.SIGKILL  # the kill ended it, not the end of its work
    assert not (out / FINAL).exists()          # the run did not complete
    names = _assert_whole(out)
    assert Path(earlier).name in names


def test_sigint_exits_130_with_a_message_and_keeps_artifacts(tmp_path):
    proc = _start(tmp_path)
    deadline = time.time() + 60
    # after the design: the simulation and six figures, a second or more of work, are left. (A
    # SIGINT that lands inside a CasADi call, as during the linearization, can be lost: seen about 1
    # time in 30, the run then completing; CasADi's own interrupt handling is the suspect.)
    while not (tmp_path / "design.json").exists() and time.time() < deadline:
        time.sleep(0.005)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err.decode()
    assert "interrupted; artifacts written before this point are complete" in err.decode()
    assert "Traceback" not in err.decode()
    assert "design.json" in _assert_whole(tmp_path) and not (tmp_path / FINAL).exists()  # stopped mid-run


def _old(path: Path) -> Path:
    old = time.time() - 2 * artifacts.STALE_TEMPORARY_AGE
    os.utime(path, (old, old), follow_symlinks=False)
    return path


def test_a_killed_runs_stale_temporary_is_cleaned_up(tmp_path):
    (tmp_path / "plots").mkdir()
    ours = [tmp_path / ".trim.json.quadctl-abc123_x.tmp", tmp_path / "plots" / ".roll.png.quadctl-q1w2e3r4.tmp"]
    for path in ours:
        path.write_text('{"half')
        _old(path)
    live = tmp_path / ".sim.npz.quadctl-def45678.tmp"  # maybe a live writer's: left alone
    live.write_text("")
    assert artifacts.remove_stale_temporaries(tmp_path) == sorted(ours)
    assert not any(p.exists() for p in ours) and live.exists()


def test_cleanup_deletes_only_what_quadctl_can_prove_it_wrote(tmp_path):
    """A user's files that merely look temporary survive, whatever their age."""
    (tmp_path / "mine").mkdir()
    (tmp_path / "plots").mkdir()
    theirs = [tmp_path / ".notes.tmp", tmp_path / ".sim.npz.mine.tmp", tmp_path / ".trim.json.abc.tmp",
              tmp_path / ".notes.txt.quadctl-abcdefgh.tmp",         # not a name quadctl writes
              tmp_path / ".roll.png.quadctl-abcdefgh.tmp",          # a figure name, but not in plots/
              tmp_path / "plots" / ".trim.json.quadctl-abcdefgh.tmp",  # an artifact name, but in plots/
              tmp_path / "mine" / ".trim.json.quadctl-abcdefgh.tmp"]   # a folder of the user's: never recursive
    for path in theirs:
        path.write_text("the user's")
        _old(path)
    shaped_dir = tmp_path / ".design.json.quadctl-abcdefgh.tmp"
    shaped_dir.mkdir()
    _old(shaped_dir)
    link = tmp_path / ".sim.json.quadctl-abcdefgh.tmp"
    link.symlink_to(tmp_path / ".notes.tmp")
    _old(link)
    assert artifacts.remove_stale_temporaries(tmp_path) == []
    assert all(p.read_text() == "the user's" for p in theirs) and shaped_dir.is_dir() and link.is_symlink()


def test_a_run_in_a_folder_keeps_the_users_temporary_looking_files(tmp_path):
    for name in (".notes.tmp", ".sim.npz.mine.tmp"):
        (tmp_path / name).write_text("keep")
        _old(tmp_path / name)
    proc = subprocess.run([sys.executable, "-m", "quadctl", "trim", "-c", "hover", "-o", str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / ".notes.tmp").read_text() == "keep" and (tmp_path / ".sim.npz.mine.tmp").read_text() == "keep"
    assert (tmp_path / "trim.json").exists()


@pytest.mark.parametrize("engine", [pytest.param("compiled", marks=pytest.mark.compiler), "casadi"])
def test_ctrl_c_stops_a_long_simulation_promptly(tmp_path, engine):
    """The loop runs in chunks of ~0.1 s (compiled, or in CasADi's VM), so an interrupt does not wait
    for the whole run: it stops within a second."""
    from quadctl import config

    path = tmp_path / "long.yaml"
    path.write_text(config.locate("forward-script-q")[1].replace("duration: 10.0", "duration: 600.0"))
    cmd = [sys.executable, "-m", "quadctl", "simulate", "-c", str(path), "-o", str(tmp_path / "out")]
    env = {**os.environ, **({"QUADCTL_NO_COMPILE": "1"} if engine == "casadi" else {})}
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env,
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
    assert waited < 1.0, f"Ctrl-C took {waited:.1f} s to stop the run"


def _folder(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file() and p.name != ".quadctl.lock"}


def _die_in(folder: Path, stage: str) -> None:
    """A session of the hover config at 2 s in ``folder`` that computes ``stage`` and then dies as a
    `kill -9` would: no handler, no clean-up, nothing closed."""
    code = ("import os\n"
            "from quadctl import config\n"
            "from quadctl.workspace import Workspace\n"
            "cfg = config.load('hover')\n"
            "cfg = cfg.model_copy(update={'simulation': cfg.simulation.model_copy(update={'duration': 2.0})})\n"
            f"ws = Workspace(cfg, {str(folder)!r})\n"
            f"ws.{stage}\n"
            "os._exit(9)\n")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True).returncode == 9


def _simulate(folder: Path, duration: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "quadctl", "simulate", "-c", "hover", "-o", str(folder),
                           "--set", f"simulation.duration={duration}"], capture_output=True, text=True)


def test_a_run_killed_after_it_replaced_the_earlier_configs_artifacts_is_undone_by_the_next(tmp_path):
    """A changed config's run died (`kill -9`, a crash) after it removed the earlier run's artifacts and
    before it wrote each again: the next command takes up its journal as Ctrl-C would have ended it,
    and the folder is the earlier run's again, byte for byte (before the journal, the next command
    removed the earlier run's set-aside files with the dead run's other temporaries)."""
    assert _simulate(tmp_path, "1").returncode == 0
    before = _folder(tmp_path)
    _die_in(tmp_path, "trim")
    assert "sim.npz" not in _folder(tmp_path) and list(tmp_path.glob(".quadctl.journal.*"))
    from quadctl import config
    from quadctl.errors import QuadctlNotice
    from quadctl.workspace import Workspace

    with pytest.warns(QuadctlNotice, match=r"had removed linear\.npz, subsystems\.json, design\.json, sim\.npz, "
                                           r"sim\.json of the earlier config's run and not written them again: the "
                                           r"earlier run is put back"):
        Workspace(config.load("hover"), tmp_path).close()  # the next session to take the folder
    assert _folder(tmp_path) == before


def test_a_run_killed_after_it_wrote_every_artifact_again_is_kept(tmp_path):
    """Dead after it wrote again each artifact it had removed: its run is whole and stays, as after a
    Ctrl-C at that point; only its temporaries go."""
    assert _simulate(tmp_path, "1").returncode == 0
    before = _folder(tmp_path)
    _die_in(tmp_path, "simulation")
    dead = _folder(tmp_path)
    assert dead["sim.npz"] != before["sim.npz"]
    from quadctl import config
    from quadctl.workspace import Workspace

    Workspace(config.load("hover"), tmp_path).close()
    assert _folder(tmp_path) == {k: v for k, v in dead.items()
                                 if ".quadctl-undo" not in k and not k.startswith(".quadctl.journal.")}
    assert not any(".quadctl-" in name or name.startswith(".quadctl.journal") for name in _folder(tmp_path))
