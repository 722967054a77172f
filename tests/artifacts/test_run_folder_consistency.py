"""A run folder agrees with its config: a command that refuses its input (exit 2) after some stages
wrote puts the folder back byte for byte; a new config removes every artifact an earlier one made (its
stages', figures, report, sweep, exports), so none is left beside a config that did not make it
(quadctl.workspace, quadctl.artifacts.run_folder)."""

from __future__ import annotations

import json
import os
import time
import warnings

import pytest
from _paths import ROOT
from typer.testing import CliRunner

from quadctl import config
from quadctl.artifacts import config_hash_of
from quadctl.artifacts.places import STAGE_FILES
from quadctl.cli.app import app
from quadctl.errors import QuadctlNotice
from quadctl.workspace import Workspace


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


def _contents(folder):
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")}


def test_a_refused_command_leaves_the_folder_as_it_was(tmp_path):
    """The RK4 step is refused at the simulation stage, after trim, linear model and design of the
    changed config were computed: none of them, nor the config it was given, stays."""
    assert invoke("run", "-c", "hover", "-o", tmp_path).exit_code == 0
    before = _contents(tmp_path)
    res = invoke("simulate", "-c", "hover", "-o", tmp_path, "--set", "simulation.dt=0.001")
    assert res.exit_code == 2 and "is unstable for RK4" in res.stderr
    assert _contents(tmp_path) == before and not list(tmp_path.glob(".*.tmp"))
    assert len(res.stderr.splitlines()) == 1  # the error alone: no note of a removal the refusal undid


def test_a_new_config_removes_what_the_old_one_made(tmp_path):
    """A config whose check fails (exit 1) keeps what it computed, and the old design and run, made from
    another config, are gone: every stage artifact left names the config.yaml beside it."""
    assert invoke("run", "-c", "hover", "-o", tmp_path).exit_code == 0
    res = invoke("run", "-c", "hover", "-o", tmp_path, "--set", "controller.rate=200",
                 "--set", "controller.design=continuous")
    assert res.exit_code == 1
    left = {p.name for p in tmp_path.iterdir()}
    assert {"trim.json", "checks.json"} <= left and not left & {"design.json", "sim.npz", "sim.json"}
    removed = "trim.json, linear.npz, subsystems.json, checks.json, design.json, sim.npz, sim.json"
    assert f"removed {removed}, made by another config" in " ".join(res.stderr.split())
    digest = config_hash_of(tmp_path)
    assert digest is not None and digest != config.load("hover").digest()
    for name in left & {"trim.json", "subsystems.json", "checks.json"}:
        assert json.loads((tmp_path / name).read_text())["config_hash"] == digest, name


def test_roll_back_restores_what_was_overwritten_and_removes_what_was_new(tmp_path):
    hover, forward = config.load("hover"), config.load("forward")
    with Workspace(hover, tmp_path) as ws:
        assert ws.trim.residual < 1e-9
    before = _contents(tmp_path)
    with Workspace(forward, tmp_path) as ws, pytest.warns(QuadctlNotice, match="removed trim.json, made by another"):
        assert ws.design.stable
        assert {"design.json", "linear.npz"} <= {p.name for p in tmp_path.iterdir()}
        ws.roll_back()
    assert _contents(tmp_path) == before
    assert not list(tmp_path.glob(".*.tmp"))  # the files set aside went back, none is left
    with Workspace(forward, tmp_path) as ws, pytest.warns(QuadctlNotice, match="removed trim.json"):
        assert ws.trim.residual < 1e-9
        ws.keep()
        ws.roll_back()  # kept: nothing undone
    assert json.loads((tmp_path / "trim.json").read_text())["config_hash"] == forward.digest()
    assert not list(tmp_path.glob(".*.tmp"))  # kept: the old files set aside are gone with the workspace
    assert set(STAGE_FILES) >= set(_contents(tmp_path)) - {"config.yaml", "config.resolved.yaml"}


SHORT = ("--set", "simulation.duration=1")
def _users_figure() -> bytes:
    """A PNG a user drew (matplotlib's own, with no quadctl config hash in it)."""
    import io

    from matplotlib.figure import Figure

    buf = io.BytesIO()
    Figure(figsize=(1, 1)).savefig(buf, format="png")
    return buf.getvalue()


USERS_OWN = {"notes.txt": b"mine", "plots/notes.txt": b"mine", "report/notes.md": b"mine", "mine/roll.png": b"mine",
             "plots/my_sketch.png": _users_figure(), "report/logo.png": _users_figure()}
"""Files a user put into a run folder, beside and among quadctl's: under names quadctl does not write there,
and figures among quadctl's (a figure carries the hash of the config that drew it: theirs carry none)."""


@pytest.fixture(scope="module")
def hover_run_and_report(tmp_path_factory):
    """``run --plot`` and ``report`` of hover (cut to 1 s) in one folder, with files of the user's own."""
    folder = tmp_path_factory.mktemp("hover") / "runs" / "hover"
    assert invoke("run", "-c", "hover", "--plot", "-o", folder, *SHORT).exit_code == 0
    assert invoke("report", "-c", "hover", "-o", folder, *SHORT).exit_code == 0
    for name, data in USERS_OWN.items():
        (folder / name).parent.mkdir(exist_ok=True)
        (folder / name).write_bytes(data)
    return folder


def _copy_of(folder, tmp_path):
    import shutil

    return shutil.copytree(folder, tmp_path / "runs" / "hover")


def _figures_and_report(folder):
    return sorted(p.relative_to(folder).as_posix() for sub in ("plots", "report") for p in (folder / sub).iterdir()
                  if p.relative_to(folder).as_posix() not in USERS_OWN)


def test_a_new_config_removes_the_earlier_configs_figures_and_report_too(tmp_path, hover_run_and_report):
    """run --plot and report of hover, then design with another mass into the same folder: the earlier
    config's figures (plots/) and report (report/) go with its stage artifacts, the note names each, and
    the user's own files stay; every artifact left was made by the config beside it."""
    from quadctl.artifacts import MadeBy, run_artifacts

    folder = _copy_of(hover_run_and_report, tmp_path)
    earlier = _figures_and_report(folder)
    assert "plots/roll.png" in earlier and {"report/report.html", "report/report.md", "report/sim-roll.png"} <= {
        *earlier}
    res = invoke("design", "-c", "hover", "-o", folder, *SHORT, "--set", "vehicle.mass=0.075")
    assert res.exit_code == 0, res.output
    note = " ".join(res.stderr.split())
    removed = "trim.json, linear.npz, subsystems.json, checks.json, design.json, sim.npz, sim.json, margins.json, "
    assert f"removed {removed}{', '.join(earlier)}, made by another config" in note
    assert _figures_and_report(folder) == []
    assert {name: (folder / name).read_bytes() for name in USERS_OWN} == USERS_OWN
    digest = config_hash_of(folder)
    made_by = MadeBy(folder, digest)
    assert digest != config.load("hover").digest()
    listed = {p.relative_to(folder).as_posix(): made_by(p) for p in run_artifacts(folder)}
    assert {name: listed.pop(name) for name in ("plots/my_sketch.png", "report/logo.png")} == dict.fromkeys(
        ("plots/my_sketch.png", "report/logo.png"))  # a user's figures: made by no config, left where they are
    assert listed == dict.fromkeys(["trim.json", "linear.npz", "subsystems.json", "design.json"], digest)


def _gone_at_roll_back(monkeypatch, folder) -> list:
    """What of the earlier figures and report was gone when the session put the folder back (one list a
    roll-back)."""
    rolled_back = Workspace.roll_back
    gone = []

    def roll_back(ws):
        gone.append([name for name in ("plots/roll.png", "report/report.html") if not (folder / name).exists()])
        return rolled_back(ws)

    monkeypatch.setattr(Workspace, "roll_back", roll_back)
    return gone


def test_a_refused_command_puts_the_earlier_configs_figures_and_report_back(tmp_path, hover_run_and_report,
                                                                             monkeypatch):
    """A changed config's run that removed the earlier figures and report, then refused its input (exit 2):
    they are back, byte for byte, with the rest of the earlier run."""
    folder = _copy_of(hover_run_and_report, tmp_path)
    before = _tree(folder)
    gone = _gone_at_roll_back(monkeypatch, folder)
    res = invoke("simulate", "-c", "hover", "-o", folder, "--plot", "--set", "simulation.dt=0.001")
    assert res.exit_code == 2 and "is unstable for RK4" in res.stderr
    assert gone == [["plots/roll.png", "report/report.html"]]  # removed with the stage artifacts, then put back
    assert _tree(folder) == before
    assert len(res.stderr.splitlines()) == 1  # no note of a removal the refusal undid


def test_a_new_config_removes_the_earlier_configs_sweep_and_exports_and_keeps_what_identify_wrote(tmp_path):
    """A sweep's outputs and chunks and every export (C, JSON, MAT, the Crazyflie app) of the earlier config
    go too, each judged by the config it names (or its companion's: sweep.csv by sweep.json); what identify
    wrote stays (made from flight logs: identified.yaml is the config a run in that folder may read)."""
    from quadctl.artifacts import MadeBy, run_artifacts

    folder = tmp_path / "run"
    spec = tmp_path / "mass.yaml"
    spec.write_text("parameters:\n  vehicle.mass: [0.026, 0.028]\nset:\n  simulation.duration: 1.0\n")
    assert invoke("sweep", "-c", "crazyflie", "-s", spec, "-o", folder).exit_code == 0
    for to in ("c", "json", "mat", "crazyflie"):
        assert invoke("export", "-c", "crazyflie", "--to", to, "-o", folder).exit_code == 0, to
    digest = config.load("crazyflie").digest()
    made = run_artifacts(folder)
    names = [p.relative_to(folder).as_posix() for p in made]
    assert {"sweep.csv", "sweep.json", "sweep.png", "sweep.parts/chunk-0000000.json", "quadctl_controller.c",
            "quadctl_controller.mat", "Makefile", "README.md", "src/quadctl_app.c"} <= set(names)
    assert {name: MadeBy(folder, None)(p) for name, p in zip(names, made)} == dict.fromkeys(names, digest)
    identified = {"identified.json": json.dumps({"artifact": "identified.json", "config_hash": "ab" * 32}).encode(),
                  "identified.yaml": b"# Identified by quadctl identify from a log\nname: crazyflie-identified\n",
                  "identify.png": b"a figure", "notes.txt": b"mine"}
    for name, data in identified.items():
        (folder / name).write_bytes(data)
    res = invoke("design", "-c", "crazyflie", "-o", folder, "--set", "vehicle.mass=0.03")
    assert res.exit_code == 0, res.output
    listed = [name for name in names if not name.startswith("sweep.parts/")] + ["sweep.parts/ (1 chunk)"]
    assert f"removed {', '.join(listed)}, made by another config" in " ".join(res.stderr.split())
    assert not any(p.exists() for p in made)
    assert {name: (folder / name).read_bytes() for name in identified} == identified


def test_a_roll_back_then_more_writes_leave_one_configs_artifacts(tmp_path):
    """A session rolled back (the earlier config's run is back) that then writes again (a library user
    going on): the earlier run's artifacts go again, as at its first write, and the config is written
    beside what it makes; never one config's artifacts beside another's config."""
    from quadctl.artifacts import MadeBy, run_artifacts

    hover, forward = config.load("hover"), config.load("forward")
    with Workspace(hover, tmp_path) as ws:
        assert ws.design.stable
    with Workspace(forward, tmp_path) as ws, pytest.warns(QuadctlNotice, match="removed trim.json"):
        assert ws.trim.residual < 1e-9
        ws.roll_back()
        assert config_hash_of(tmp_path) == hover.digest()
        assert ws.design.stable
    assert config_hash_of(tmp_path) == forward.digest()
    made_by = MadeBy(tmp_path, forward.digest())
    left = {p.name: made_by(p) for p in run_artifacts(tmp_path)}
    assert "design.json" in left and set(left.values()) == {forward.digest()}, left


def test_a_damaged_artifact_is_left_to_the_stage_that_reads_it(tmp_path):
    """Stale removal reads each artifact's provenance; one it cannot read is not removed (nor said to be)."""
    assert invoke("design", "-c", "hover", "-o", tmp_path).exit_code == 0
    (tmp_path / "design.json").write_text("{ not json")
    res = invoke("trim", "-c", "forward", "-o", tmp_path)
    assert res.exit_code == 0
    assert (tmp_path / "design.json").read_text() == "{ not json" and not (tmp_path / "linear.npz").exists()


def test_a_refused_report_keeps_the_report_and_what_it_shows(tmp_path):
    """report writes the report of a run that stops on bad input (the error is in it): the report and the
    stage artifacts it shows stay together, with the config that made them."""
    res = invoke("report", "-c", "hover", "-o", tmp_path, "--set", "simulation.dt=0.001")
    assert res.exit_code == 2
    assert (tmp_path / "report" / "report.html").exists() and (tmp_path / "design.json").exists()
    design = json.loads((tmp_path / "design.json").read_text())
    assert design["config_hash"] == config_hash_of(tmp_path)


def test_a_refused_report_puts_back_another_configs_run(tmp_path):
    """report refused (exit 2) in a folder that holds another config's run writes no report and puts that run
    back byte for byte, as every command does on exit 2: it had replaced the run with the refused one's."""
    assert invoke("simulate", "-c", "hover", "-o", tmp_path, "--plot", "--set", "simulation.duration=1").exit_code == 0
    before = _tree(tmp_path)
    res = invoke("report", "-c", "forward", "-o", tmp_path, "--set", "simulation.dt=0.001")
    assert res.exit_code == 2, res.output
    assert f"{tmp_path}: no report written: the folder holds another config's run, put back as it was" in res.stderr
    assert res.stderr.strip().splitlines()[-1].startswith("quadctl: error: ")
    assert _tree(tmp_path) == before


def test_roll_back_puts_a_replaced_link_back(tmp_path):
    elsewhere = tmp_path / "elsewhere.json"
    elsewhere.write_text("{}")
    run = tmp_path / "run"
    run.mkdir()
    (run / "trim.json").symlink_to(elsewhere)
    with Workspace(config.load("hover"), run) as ws:
        assert ws.trim.residual < 1e-9
        assert not (run / "trim.json").is_symlink()  # never written through a link: replaced
        ws.roll_back()
    assert (run / "trim.json").is_symlink() and (run / "trim.json").resolve() == elsewhere.resolve()
    assert elsewhere.read_text() == "{}"


def test_roll_back_without_hard_links_keeps_the_bytes(tmp_path, monkeypatch):
    """A file system with no hard links: the files are kept as their bytes, and put back the same."""
    from quadctl.artifacts import session

    def no_links(*_):
        raise OSError(1, "Operation not permitted")

    with Workspace(config.load("hover"), tmp_path) as ws:
        assert ws.trim.residual < 1e-9
    before = _contents(tmp_path)
    monkeypatch.setattr(session.os, "link", no_links)
    with Workspace(config.load("forward"), tmp_path) as ws, pytest.warns(QuadctlNotice, match="removed trim.json"):
        assert ws.design.stable
        ws.roll_back()
    assert _contents(tmp_path) == before and not list(tmp_path.glob(".*.tmp"))


def _tree(folder):
    """Every file below ``folder`` (hidden ones too: a file set aside, a temporary) with its bytes, and
    every folder: what "the folder as it was" compares."""
    import gc

    from quadctl.artifacts import LOCK_NAME

    gc.collect()  # a command's workspace, released (its lock and its files set aside go with it)
    if not folder.exists():
        return None
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else "folder") for p in folder.rglob("*")
            if p.name != LOCK_NAME}


def _full_disk_at(monkeypatch, name):
    """The disk fills up when ``name`` is written (as test_safe_writes does: the temporary's write fails)."""
    from quadctl.artifacts import writing

    temporary = writing._temporary

    def failing(path, data):
        if path.name == name:
            raise OSError(28, "No space left on device")
        return temporary(path, data)

    monkeypatch.setattr(writing, "_temporary", failing)


@pytest.fixture(scope="module")
def earlier_report(tmp_path_factory):
    """A folder with the report of another config (the square mission: a path figure hover has not), its
    run cut to 1 s: the report is written, and fails the mission it cannot finish (exit 1)."""
    folder = tmp_path_factory.mktemp("earlier") / "run"
    res = invoke("report", "-c", "square", "-o", folder, "--set", "simulation.duration=1")
    assert res.exit_code == 1 and "the run ends at 1 s, before the mission does" in res.output, res.output
    assert (folder / "report" / "sim-path.png").exists()
    return folder


@pytest.mark.parametrize("start,full_at", [("none", "report.html"),
                                           pytest.param("earlier", "report.md", marks=pytest.mark.slow),
                                           pytest.param("earlier", "sim-roll.png", marks=pytest.mark.slow)])
def test_a_report_the_disk_cannot_hold_leaves_the_folder_as_it_was(tmp_path, monkeypatch, request, start, full_at):
    """report on a full disk exits 2 and puts back every file it wrote or removed (stage artifacts, figures,
    report.md), as simulate does: never a report.md and figures without report.html."""
    import shutil

    folder = tmp_path / "run"
    if start == "earlier":  # (roll_back's own test puts back what was overwritten, without a report)
        shutil.copytree(request.getfixturevalue("earlier_report"), folder)
    before = _tree(folder)
    _full_disk_at(monkeypatch, full_at)
    res = invoke("report", "-c", "hover", "-o", folder, "--set", "simulation.duration=1")
    assert res.exit_code == 2, res.output
    assert res.stderr.strip().splitlines()[-1] == (
        f"quadctl: error: {folder / 'report' / full_at}: cannot write the artifact (No space left on device); free "
        "the space or the permission it needs, or choose another --out folder")
    assert _tree(folder) == before  # none: the folder the lock made is gone again


@pytest.mark.parametrize("command,full_at", [("simulate", "yaw.png"),
                                             pytest.param("margins", "margins-pitch-design.png",
                                                          marks=pytest.mark.slow)])
def test_figures_the_disk_cannot_hold_leave_the_folder_as_it_was(tmp_path, monkeypatch, command, full_at):
    """simulate --plot, margins --plot: the figures drawn before the disk filled up go too, with the stages'
    artifacts and the plots/ folder the command made."""
    assert invoke("simulate", "-c", "hover", "-o", tmp_path, "--set", "simulation.duration=1").exit_code == 0
    before = _tree(tmp_path)
    _full_disk_at(monkeypatch, full_at)
    res = invoke(command, "-c", "forward", "-o", tmp_path, "--plot", "--set", "simulation.duration=1")
    assert res.exit_code == 2, res.output
    assert f"{full_at}: cannot write the artifact (No space left on device)" in res.stderr
    assert _tree(tmp_path) == before


KILLED = """
import os, signal, sys
from quadctl import config
from quadctl.workspace import Workspace
ws = Workspace(config.load(sys.argv[2]), sys.argv[1], fresh=True)
ws.design  # trim.json ... design.json rewritten: each set aside first, for a roll-back
ws.write_bytes(ws.out / "report" / "report.md", b"# half a report")  # the earlier report's, set aside too
print(sorted(p.name for p in ws.out.rglob(".*undo*")), flush=True)
os.kill(os.getpid(), signal.SIGKILL)  # as a kill -9 during report --fresh
"""


def _set_aside(folder):
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob(".*quadctl-undo*.tmp"))


def _killed_mid_session(folder, name="hover"):
    """A process that rewrote some artifacts of ``folder`` and was killed (SIGKILL) before its workspace
    closed: the files it set aside for a roll-back are left."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-c", KILLED, str(folder), name], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == -9, proc.stderr
    left = _set_aside(folder)
    assert len(left) >= 5, (left, proc.stdout)
    return left


@pytest.mark.parametrize("command", [["trim"], ["design"], ["export", "--to", "json"]])
def test_files_set_aside_by_a_killed_run_are_removed_by_the_next_command(tmp_path, command):
    """A kill -9 mid-session leaves `.checks.json.quadctl-undo….tmp` and its kind; the next command that
    holds the folder (no other process does) removes every one, however old the file it kept."""
    folder = tmp_path / "run"
    assert invoke("design", "-c", "hover", "-o", folder).exit_code == 0
    (folder / "report").mkdir()
    (folder / "report" / "report.md").write_text("# an earlier report\n")
    assert "report/.report.md.quadctl-undo" in " ".join(_killed_mid_session(folder))
    res = invoke(*command, "-c", "hover", "-o", folder)
    assert res.exit_code == 0, res.output
    assert _set_aside(folder) == []
    assert (folder / "report" / "report.md").read_bytes() == b"# half a report"  # what the killed run wrote stays


def test_a_command_refused_while_another_process_holds_the_folder_touches_nothing(tmp_path):
    """The folder's first holder finishes what a killed session left (its journal: the files it set aside
    go back or go); a command refused meanwhile, the folder in use, changes nothing there."""
    folder = tmp_path / "run"
    assert invoke("design", "-c", "hover", "-o", folder).exit_code == 0
    assert _killed_mid_session(folder)
    from test_folder_lock import _holder

    other = _holder(folder)
    try:
        held = _contents(folder)
        assert _set_aside(folder) == []  # the holder took the dead session up
        res = invoke("trim", "-c", "hover", "-o", folder)
        assert res.exit_code == 2 and "is in use by another quadctl" in res.stderr
        assert _contents(folder) == held
    finally:
        other.kill()
        other.wait()


def test_a_second_workspace_of_the_process_leaves_the_first_ones_files_set_aside(tmp_path):
    """Re-entrant in one process: the second holder removes nothing, so the first still rolls back, however
    old the files it set aside (a set-aside name keeps its file's time)."""
    with Workspace(config.load("hover"), tmp_path) as ws:
        assert ws.design.stable
    before = _contents(tmp_path)
    old = time.time() - 3600
    for path in tmp_path.iterdir():
        os.utime(path, (old, old))
    with Workspace(config.load("forward"), tmp_path) as first, \
            pytest.warns(QuadctlNotice, match="removed trim.json"):
        assert first.trim.residual < 1e-9
        with Workspace(config.load("forward"), tmp_path) as second:
            assert second.out == first.out
        first.roll_back()
    assert _contents(tmp_path) == before


def test_a_kept_session_says_what_it_removed_even_when_its_command_then_refuses(tmp_path):
    """The notices a workspace holds back (defer_notes) are said at close; a roll-back after keep() undoes
    nothing, so it drops none of them (a report that keeps what it computed, then exits 2)."""
    with Workspace(config.load("hover"), tmp_path) as ws:
        assert ws.trim.residual < 1e-9
    ws = Workspace(config.load("forward"), tmp_path)
    ws.defer_notes()
    assert ws.trim.residual < 1e-9  # written: the other config's trim.json removed
    ws.keep()
    ws.roll_back()
    with pytest.warns(QuadctlNotice, match="removed trim.json, made by another config"):
        ws.close()


def test_every_figure_quadctl_draws_carries_the_hash_of_its_config(hover_run_and_report):
    """The figures of run --plot (drawn in a forked child or here) and of the report carry hover's
    config_hash in a PNG text chunk that other PNG readers see too; a figure without one is nobody's."""
    from matplotlib.image import imread

    from quadctl.artifacts.png_stamp import KEYWORD, stamp_of, stamp_png, stamped

    digest = config_hash_of(hover_run_and_report)
    figures = sorted((hover_run_and_report / "plots").glob("*.png")) + sorted(
        (hover_run_and_report / "report").glob("*.png"))
    ours = [p for p in figures if p.relative_to(hover_run_and_report).as_posix() not in USERS_OWN]
    assert len(ours) >= 6 and {stamp_of(p) for p in ours} == {digest}
    assert stamp_of(hover_run_and_report / "plots" / "my_sketch.png") is None
    roll = hover_run_and_report / "plots" / "roll.png"
    assert KEYWORD + b"\0" + digest.encode() in roll.read_bytes() and imread(str(roll)).ndim == 3
    assert stamped(stamp_png(USERS_OWN["plots/my_sketch.png"], "f" * 64)) == "f" * 64
    with pytest.raises(ValueError, match="not a PNG"):
        stamp_png(b"mine", digest)


# -- the commands that run no stages: a sweep, an export -------------------------------------------------

HEAVIER = ("--set", "vehicle.mass=0.075")
"""hover with another mass: another config (another config_hash), as fast to run."""
TWO_CASES = "parameters:\n  lqr.roll.R[0]: [1.0, 1.1]\nset:\n  simulation.duration: 1.0\n"


@pytest.fixture(scope="module")
def heavier_run(tmp_path_factory):
    """``simulate --plot`` of hover with another mass (1 s): stage artifacts and figures in ``plots/``."""
    folder = tmp_path_factory.mktemp("heavier") / "run"
    assert invoke("simulate", "-c", "hover", "--plot", "-o", folder, *SHORT, *HEAVIER).exit_code == 0
    return folder


def _two_cases(tmp_path):
    spec = tmp_path / "two.yaml"
    spec.write_text(TWO_CASES)
    return spec


def _only_hovers(folder) -> None:
    """Every artifact of ``folder`` was made by hover, the config beside them, and no artifact folder is
    left empty."""
    from quadctl.artifacts import SUBFOLDER_NAMES, MadeBy, run_artifacts

    digest = config.load("hover").digest()
    assert config_hash_of(folder) == digest
    made_by = MadeBy(folder, digest)
    assert {p.relative_to(folder).as_posix(): made_by(p) for p in run_artifacts(folder)} == {
        p.relative_to(folder).as_posix(): digest for p in run_artifacts(folder)}
    assert [sub for sub in SUBFOLDER_NAMES if (folder / sub).exists() and not any((folder / sub).iterdir())] == []


@pytest.mark.parametrize("command", [("sweep", "-j", "1"), ("export", "--to", "json")], ids=["sweep", "export"])
def test_a_sweep_or_an_export_removes_the_run_of_another_config_and_the_folders_it_emptied(
        tmp_path, heavier_run, command):
    """quadctl sweep and quadctl export of hover into the folder of another config's run: that run goes (its
    stage artifacts and figures, with a note naming them, and the plots/ folder they leave empty), and the
    config written beside the sweep or the export is hover's."""
    folder = _copy_of(heavier_run, tmp_path)
    earlier = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()
                     and not p.name.startswith(".") and p.name not in ("config.yaml", "config.resolved.yaml"))
    assert {"trim.json", "sim.npz", "plots/roll.png"} <= set(earlier)
    extra = ("-s", _two_cases(tmp_path)) if command[0] == "sweep" else ()
    res = invoke(*command, "-c", "hover", "-o", folder, *extra)
    assert res.exit_code == 0, res.output
    assert "trim.json, linear.npz" in res.stderr and "plots/roll.png" in res.stderr
    assert "made by another config" in " ".join(res.stderr.split())
    assert not any((folder / name).exists() for name in earlier) and not (folder / "plots").exists()
    assert (folder / ("sweep.csv" if command[0] == "sweep" else "quadctl_controller.json")).is_file()
    _only_hovers(folder)


def test_an_export_removes_another_configs_crazyflie_app_and_its_src_folder(tmp_path):
    """The Crazyflie app of one config, then the JSON export of another in the same folder: the app goes,
    its src/ folder with it; a folder that holds a file of the user's own stays, with that file."""
    folder = tmp_path / "run"
    assert invoke("export", "-c", "crazyflie", "--to", "crazyflie", "-o", folder).exit_code == 0
    assert (folder / "src" / "quadctl_app.c").is_file()
    (folder / "plots").mkdir()
    (folder / "plots" / "notes.txt").write_text("mine")
    res = invoke("export", "-c", "crazyflie", "--to", "json", "-o", folder, "--set", "vehicle.mass=0.03")
    assert res.exit_code == 0, res.output
    assert "src/quadctl_app.c" in res.stderr and not (folder / "src").exists()
    assert not (folder / "Makefile").exists() and (folder / "quadctl_controller.json").is_file()
    assert (folder / "plots" / "notes.txt").read_text() == "mine"


def _stopped_at(monkeypatch, where: str):
    """Ctrl-C where a sweep writes its tables (after its chunks), or where an export writes its files."""
    from quadctl.artifacts import writing
    from quadctl.sweep import store

    def stop(*_, **__):
        raise KeyboardInterrupt

    monkeypatch.setattr(*((store.SweepStore, "finish") if where == "sweep" else (writing, "write_together")), stop)


@pytest.mark.parametrize("command", [("sweep", "-j", "1"), ("export", "--to", "mat")], ids=["sweep", "export"])
@pytest.mark.parametrize("stop", ["ctrl-c", "full disk"])
def test_a_sweep_or_an_export_stopped_or_refused_puts_the_earlier_run_back(tmp_path, heavier_run, monkeypatch,
                                                                          command, stop):
    """Ctrl-C (exit 130) or a full disk (exit 2) after the sweep or the export removed another config's run
    and before its own files were all written: the earlier run is back, byte for byte, its plots/ folder too,
    and no chunk, table or export of hover is left beside it."""
    folder = _copy_of(heavier_run, tmp_path)
    before = _tree(folder)
    extra = ("-s", _two_cases(tmp_path)) if command[0] == "sweep" else ()
    if stop == "ctrl-c":
        _stopped_at(monkeypatch, command[0])
    else:
        _full_disk_at(monkeypatch, "sweep.json" if command[0] == "sweep" else "quadctl_controller.mat")
    res = invoke(*command, "-c", "hover", "-o", folder, *extra)
    if stop == "ctrl-c":
        assert res.exit_code == 130 and "the run folder is as the earlier config's run left it" in res.stderr
        # a sweep says the finished work it takes with it (its one chunk), which --resume then cannot use
        assert ("the 1 chunk this sweep finished went with them" in res.stderr) is (command[0] == "sweep")
    else:
        assert res.exit_code == 2 and "No space left on device" in res.stderr
        assert len(res.stderr.splitlines()) == 1  # the error alone: no note of a removal the refusal undid
    assert _tree(folder) == before


@pytest.mark.parametrize("start", ["empty", "this config's sweep"])
def test_a_sweep_refused_in_a_folder_of_its_own_config_keeps_its_chunks_for_resume(tmp_path, monkeypatch, start):
    """A full disk at sweep.json (exit 2) after the chunks were written, in a folder that held nothing of
    another config: the chunks are finished work and stay, and --resume computes none of their cases again."""
    folder = tmp_path / "run"
    spec = _two_cases(tmp_path)
    if start != "empty":
        assert invoke("sweep", "-c", "hover", "-s", spec, "-o", folder, "-j", "1").exit_code == 0
    with monkeypatch.context() as patch:
        _full_disk_at(patch, "sweep.json")
        res = invoke("sweep", "-c", "hover", "-s", spec, "-o", folder, "-j", "1")
    assert res.exit_code == 2 and "No space left on device" in res.stderr, res.output
    assert sorted((folder / "sweep.parts").glob("chunk-*.json"))
    res = invoke("sweep", "-c", "hover", "-s", spec, "-o", folder, "-j", "1", "--resume")
    assert res.exit_code == 0, res.output
    assert "(0 computed, 2 resumed)" in res.output, res.output


def test_a_library_sweep_stopped_after_it_removed_another_configs_run_puts_that_run_back(tmp_path, heavier_run):
    """sweep.execute in Python (its own session), Ctrl-C after its first chunk, in a folder of another config's
    run: the earlier run is back whole, as the command line leaves it, not half of each."""
    from quadctl import config, sweep

    folder = _copy_of(heavier_run, tmp_path)
    before = _tree(folder)
    cfg = config.load("hover")

    def stop(done, total):
        if done:  # a chunk is written: the earlier run's artifacts are gone
            raise KeyboardInterrupt

    with warnings.catch_warnings(record=True) as said, pytest.raises(KeyboardInterrupt):
        warnings.simplefilter("always")
        sweep.execute(cfg, sweep.load(_two_cases(tmp_path), cfg), folder, jobs=1, progress=stop,
                      plot=False)
    assert _tree(folder) == before
    assert not [w for w in said if "removed" in str(w.message)]  # nothing said of a removal put back


KILLED_SWEEP = """
import os, sys
from quadctl.sweep import store
save = store.SweepStore.save_chunk
def save_and_die(self, rows, traces=None):  # its first chunk written: kill -9
    save(self, rows, traces)
    os._exit(9)
store.SweepStore.save_chunk = save_and_die
sys.argv = ["quadctl", "sweep", "-c", "hover", "-s", sys.argv[2], "-o", sys.argv[1], "-j", "1"]
from quadctl.cli.entry import main
main()
"""


def test_a_sweep_killed_after_it_removed_another_configs_run_is_undone_by_the_next_command(tmp_path, heavier_run):
    """A kill -9 once the sweep had removed the earlier config's run and written a chunk of its own: the next
    quadctl to take the folder puts the earlier run back (its journal), and removes the chunk."""
    import subprocess
    import sys

    from quadctl import artifacts

    folder = _copy_of(heavier_run, tmp_path)
    before = _tree(folder)
    proc = subprocess.run([sys.executable, "-c", KILLED_SWEEP, str(folder), str(_two_cases(tmp_path))],
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 9, proc.stderr
    assert list(folder.glob("sweep.parts/chunk-*.json")) and not (folder / "trim.json").exists()
    notes = artifacts.take_over(folder)
    assert len(notes) == 1 and "the earlier run is put back" in notes[0]
    assert _tree(folder) == before


KILLED_EXPORT = """
import os, sys
from quadctl.artifacts import writing
write_together = writing.write_together
def write_some_and_die(files):  # the first of the export's files written: kill -9
    first = dict(list(files.items())[:1])
    write_together(first)
    os._exit(9)
writing.write_together = write_some_and_die
sys.argv = ["quadctl", "export", "--to", "c", "-c", "crazyflie", "-o", sys.argv[1]]
from quadctl.cli.entry import main
main()
"""


def test_an_export_killed_after_it_removed_another_configs_export_is_undone_by_the_next_command(tmp_path):
    """mambo-200hz's C pair in the folder; crazyflie's export removes it and is killed (kill -9) with one of its
    own files written: the next quadctl to take the folder puts mambo-200hz's run back, pair and all."""
    import subprocess
    import sys

    from quadctl import artifacts

    folder = tmp_path / "run"
    assert invoke("export", "--to", "c", "-c", "mambo-200hz", "-o", folder).exit_code == 0
    before = _tree(folder)
    proc = subprocess.run([sys.executable, "-c", KILLED_EXPORT, str(folder)], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 9, proc.stderr
    assert _tree(folder) != before  # mid-way: the pair is another's, or gone
    notes = artifacts.take_over(folder)
    assert len(notes) == 1 and "the earlier run is put back" in notes[0]
    assert _tree(folder) == before


def _without_the_users_files(folder, tmp_path):
    """A copy of ``folder`` (a run and its report) without the files of the user's own."""
    copy = _copy_of(folder, tmp_path)
    for name in USERS_OWN:
        (copy / name).unlink()
    (copy / "mine").rmdir()
    return copy


@pytest.mark.parametrize("refused", [False, True], ids=["design", "refused"])
def test_a_new_config_removes_the_artifact_folders_it_emptied_and_a_refusal_keeps_them(
        tmp_path, hover_run_and_report, refused):
    """Without files of the user's own in plots/ and report/, removing the earlier config's figures and report
    leaves them empty: they go too when the command ends. A command refused (exit 2) after it removed them
    puts the folders back with every file in them."""
    folder = _without_the_users_files(hover_run_and_report, tmp_path)
    before = _tree(folder)
    assert before["plots"] == before["report"] == "folder"
    if refused:
        res = invoke("simulate", "-c", "hover", "-o", folder, "--set", "simulation.dt=0.001")
        assert res.exit_code == 2 and "is unstable for RK4" in res.stderr
        assert _tree(folder) == before
    else:
        res = invoke("design", "-c", "hover", "-o", folder, *SHORT, *HEAVIER)
        assert res.exit_code == 0, res.output
        assert "plots/roll.png" in res.stderr and "report/report.html" in res.stderr
        assert not (folder / "plots").exists() and not (folder / "report").exists()
