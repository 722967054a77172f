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


@pytest.mark.parametrize("sent_signal, code, word", [(signal.SIGINT, 130, "interrupted"),
                                                      (signal.SIGTERM, 143, "terminated")], ids=["ctrl-c", "sigterm"])
def test_ctrl_c_stops_a_sweep_within_a_second_and_its_workers_with_it(tmp_path, sent_signal, code, word):
    """Ctrl-C, and SIGTERM as Ctrl-C."""
    proc = _start_sweep(tmp_path)
    workers = _children(proc.pid)
    sent = time.monotonic()
    proc.send_signal(sent_signal)
    _, err = proc.communicate(timeout=30)
    took = time.monotonic() - sent
    assert proc.returncode == code, err
    assert took < 1.5, f"stopping took {took:.2f} s"
    assert "Traceback" not in err and word in err
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


def test_an_interrupted_sweep_says_where_its_chunks_are_and_that_resume_takes_them(tmp_path, monkeypatch):
    """Ctrl-C in a sweep keeps its finished chunks: its one line says where, and that --resume computes the rest
    (a simulate's line stays as it was: it has nothing to resume)."""
    from typer.testing import CliRunner

    from quadctl import sweep
    from quadctl.cli.app import app

    def stop(*_, **__):
        raise KeyboardInterrupt

    spec = tmp_path / "s.yaml"
    spec.write_text("parameters:\n  lqr.roll.R[0]: [1.0, 2.0]\n")
    monkeypatch.setattr(sweep, "execute", stop)
    res = CliRunner().invoke(app, ["sweep", "-c", "forward", "-s", str(spec), "-o", str(tmp_path / "out")])
    assert res.exit_code == 130
    assert res.stderr == (f"quadctl: error: interrupted; artifacts written before this point are complete; the "
                          f"chunks it finished are kept in {tmp_path / 'out' / sweep.PARTS}: the same command with "
                          "--resume computes only the rest\n")
    res = _interrupted_simulate(tmp_path / "sim", monkeypatch)
    assert res.exit_code == 130 and "--resume" not in res.stderr


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




def test_ctrl_c_in_a_compiled_modules_initialization_is_taken_after_it(monkeypatch):
    """The commands import much late (a sweep imports matplotlib while its workers compute): a Ctrl-C
    inside the initialization of a compiled module (pybind11's: it runs Python, where the
    KeyboardInterrupt lands) waits for it to end (interrupted, the module was left half made: "internal
    error ImportError: initialization failed"); one in the Python around it is taken at once; a process
    that ignores SIGINT (a sweep's worker) keeps ignoring it."""
    from importlib.machinery import ExtensionFileLoader

    from quadctl.cli.entry import extensions_initialize_whole

    done = []

    def initialization(self, spec):  # a module's init that calls back into Python
        os.kill(os.getpid(), signal.SIGINT)
        done.append(sum(range(100_000)))  # bytecode after the signal, where its KeyboardInterrupt would land

    monkeypatch.setattr(ExtensionFileLoader, "create_module", initialization)
    with pytest.raises(KeyboardInterrupt):
        with extensions_initialize_whole():
            ExtensionFileLoader.create_module(None, None)
            done.append("the Python after it")  # not reached: the Ctrl-C is taken when the init ends
    assert done == [sum(range(100_000))]
    assert ExtensionFileLoader.create_module is initialization  # the loader as it was
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with pytest.raises(KeyboardInterrupt):
        with extensions_initialize_whole():
            os.kill(os.getpid(), signal.SIGINT)
            sum(range(100_000))
            done.append("the Python after the signal")  # not reached: taken at once
    assert done == [sum(range(100_000))]
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with extensions_initialize_whole():
            ExtensionFileLoader.create_module(None, None)  # the signal ignored, as before
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_sigterm_in_a_compiled_modules_initialization_is_taken_after_it_as_ctrl_c_is(monkeypatch):
    """SIGTERM, which the console script takes as Ctrl-C, waits for a compiled module's initialization
    to end as a Ctrl-C does, then stops the command as terminated."""
    from importlib.machinery import ExtensionFileLoader

    from quadctl.cli import entry, stops

    done = []

    def initialization(self, spec):
        os.kill(os.getpid(), signal.SIGTERM)
        done.append(sum(range(100_000)))

    monkeypatch.setattr(ExtensionFileLoader, "create_module", initialization)
    previous = signal.signal(signal.SIGTERM, stops.raise_terminated)
    try:
        with pytest.raises(stops.Terminated):
            with entry.extensions_initialize_whole():
                ExtensionFileLoader.create_module(None, None)
                done.append("the Python after it")  # not reached: taken when the init ends
        assert done == [sum(range(100_000))]
        assert signal.getsignal(signal.SIGTERM) is stops.raise_terminated
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_the_console_script_initializes_compiled_modules_whole():
    """A Ctrl-C inside the initialization of a compiled module the commands import is taken after it:
    the module is whole, the command ends with one line and 130."""
    code = ("import os, signal, sys\n"
            "from quadctl.cli.entry import main\n"
            "from importlib.machinery import ExtensionFileLoader\n"
            "real = ExtensionFileLoader.create_module\n"
            "def initialization(self, spec):  # the first compiled module: a Ctrl-C in its init\n"
            "    ExtensionFileLoader.create_module = real\n"
            "    os.kill(os.getpid(), signal.SIGINT)\n"
            "    module = real(self, spec)\n"
            "    sys.stderr.write(f'whole: {spec.name}\\n')\n"
            "    return module\n"
            "ExtensionFileLoader.create_module = initialization\n"
            "sys.argv = ['quadctl', 'configs']\n"
            "main()\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 130 and res.stderr.startswith("whole: "), res.stderr
    assert res.stderr.endswith("quadctl: error: interrupted\n") and "Traceback" not in res.stderr


def test_a_sweep_whose_figure_import_a_ctrl_c_cut_short_leaves_at_once(tmp_path):
    """A Ctrl-C that cuts short the figure's import (made while the workers compute) leaves what it
    imported half made, which killed the interpreter's exit 2 to 4 times in 30 on a loaded machine:
    after the command's cleanup (its line, its workers stopped) the process leaves without it."""
    spec = tmp_path / "s.yaml"
    spec.write_text("parameters:\n  lqr.roll.R[0]: [1.0, 1.1, 1.2, 1.3]\nset:\n  simulation.duration: 20.0\n")
    code = ("import atexit, os, signal, sys\n"
            "import quadctl.cli.commands.sweep as sweep_command\n"
            "def import_plots():  # the figure's import, cut short by a Ctrl-C\n"
            "    os.kill(os.getpid(), signal.SIGINT)\n"
            "    sum(range(100_000))\n"
            "sweep_command._import_plots = import_plots\n"
            "atexit.register(lambda: sys.stderr.write('the interpreter exited\\n'))\n"
            f"sys.argv = ['quadctl', 'sweep', '-c', 'hover', '-s', {str(spec)!r}, '-o', {str(tmp_path / 'out')!r},"
            " '-j', '2']\n"
            "from quadctl.cli.entry import main\n"
            "main()\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 130, res.stderr
    assert "interrupted" in res.stderr and "Traceback" not in res.stderr
    assert "the interpreter exited" not in res.stderr


def _interrupted_simulate(tmp_path: Path, monkeypatch, *extra, stop_with=KeyboardInterrupt):
    """``simulate`` into ``tmp_path``, Ctrl-C (or ``stop_with``) landing in its simulation stage (after trim
    and design wrote)."""
    from typer.testing import CliRunner

    from quadctl import pipeline
    from quadctl.cli.app import app

    def stop(*_, **__):
        raise stop_with

    with monkeypatch.context() as patch:
        patch.setattr(pipeline, "simulation_of", stop)
        return CliRunner().invoke(app, ["simulate", "-c", "hover", "-o", str(tmp_path), *extra])


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file() and p.name != ".quadctl.lock"}


def test_ctrl_c_after_a_config_change_puts_the_earlier_complete_run_back(tmp_path, monkeypatch):
    """The changed config's run removed the earlier run's artifacts, then was stopped before its own were all
    written: the folder is the earlier run's again, byte for byte, not half of each. Without a change of
    config, what was written stays (the same config's, complete as far as it went)."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    assert CliRunner().invoke(app, ["simulate", "-c", "hover", "-o", str(tmp_path),
                                    "--set", "simulation.duration=1"]).exit_code == 0
    before = _files(tmp_path)
    assert "sim.npz" in before
    res = _interrupted_simulate(tmp_path, monkeypatch, "--set", "simulation.duration=2")
    assert res.exit_code == 130
    assert res.stderr == ("quadctl: error: interrupted; the run folder is as the earlier config's run left it "
                          "(this one's artifacts were not all written)\n")  # and no note of what was removed
    assert _files(tmp_path) == before
    res = _interrupted_simulate(tmp_path, monkeypatch, "--set", "simulation.duration=1", "--fresh")
    assert res.exit_code == 130 and "artifacts written before this point are complete" in res.stderr
    assert "sim.npz" in _files(tmp_path)  # the same config: the earlier sim.npz is this config's, kept


def _tree(folder: Path) -> dict[str, bytes | str]:
    """Every file below ``folder`` with its bytes (figures, the report), and every folder; not the lock."""
    import gc

    gc.collect()  # a command's workspace, released (its lock and its files set aside go with it)
    return {p.relative_to(folder).as_posix(): p.read_bytes() if p.is_file() else "folder"
            for p in sorted(folder.rglob("*")) if p.name != ".quadctl.lock"}


def test_ctrl_c_after_a_config_change_puts_the_earlier_runs_figures_and_report_back(tmp_path, monkeypatch):
    """The changed config's run removed the earlier run's figures (plots/) and report (report/) with its
    stage artifacts, then was stopped: they are back, byte for byte, with the rest of the earlier run."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    short = ["--set", "simulation.duration=1"]
    for command in (["run", "--plot"], ["report"]):
        assert CliRunner().invoke(app, [*command, "-c", "hover", "-o", str(tmp_path), *short]).exit_code == 0
    before = _tree(tmp_path)
    assert {"plots/roll.png", "report/report.html", "report/sim-roll.png"} <= before.keys()
    from quadctl.workspace import Workspace

    rolled_back, gone = Workspace.roll_back, []

    def roll_back(ws):  # what of the earlier figures and report the stopped run had removed
        gone.extend(name for name in ("plots/roll.png", "report/report.html") if not (tmp_path / name).exists())
        return rolled_back(ws)

    monkeypatch.setattr(Workspace, "roll_back", roll_back)
    res = _interrupted_simulate(tmp_path, monkeypatch, "--plot", "--set", "simulation.duration=2")
    assert res.exit_code == 130
    assert gone == ["plots/roll.png", "report/report.html"]
    assert "the run folder is as the earlier config's run left it" in res.stderr
    assert _tree(tmp_path) == before


def test_ctrl_c_after_a_changed_configs_artifacts_are_all_written_keeps_the_new_run(tmp_path, monkeypatch):
    """Stopped while drawing its figures, a changed config's run has written every artifact it removed
    again: the new run is whole and stays; nothing is put back and nothing claims it was."""
    from typer.testing import CliRunner

    from quadctl.cli import figures
    from quadctl.cli.app import app

    assert CliRunner().invoke(app, ["simulate", "-c", "hover", "-o", str(tmp_path),
                                    "--set", "simulation.duration=1"]).exit_code == 0
    before = _files(tmp_path)

    def stop(*_, **__):
        raise KeyboardInterrupt

    monkeypatch.setattr(figures, "save_figures", stop)
    res = CliRunner().invoke(app, ["simulate", "-c", "hover", "-o", str(tmp_path), "--plot",
                                   "--set", "simulation.duration=2"])
    assert res.exit_code == 130 and "artifacts written before this point are complete" in res.stderr
    after = _files(tmp_path)
    assert after.keys() == before.keys() and after["sim.npz"] != before["sim.npz"]  # the 2 s run's


def test_sigterm_stops_a_run_as_ctrl_c_does_and_puts_the_earlier_run_back(tmp_path):
    """SIGTERM (`timeout`, a cancelled CI job, `docker stop`) after a config change, while the new
    run simulates: exit 143 with one line, and the folder is the earlier run's again, byte for byte
    (without the handler the process died at once, the earlier sim.npz gone with it)."""
    run = [sys.executable, "-m", "quadctl", "simulate", "-c", "hover", "-o", str(tmp_path)]
    assert subprocess.run([*run, "--set", "simulation.duration=1"], capture_output=True).returncode == 0
    before = _files(tmp_path)
    proc = subprocess.Popen([*run, "--set", "simulation.duration=2000"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while (tmp_path / "sim.npz").exists():  # the new run has set the earlier one's aside
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the new run never replaced the earlier one's artifacts"
        time.sleep(0.01)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 143, err
    assert err == ("quadctl: error: terminated; the run folder is as the earlier config's run left it "
                   "(this one's artifacts were not all written)\n")
    assert _files(tmp_path) == before


def test_a_bug_after_a_config_change_puts_the_earlier_complete_run_back(tmp_path, monkeypatch):
    """An internal error (exit 3) in the changed config's run, after it removed the earlier run's artifacts:
    the folder is put back as Ctrl-C puts it back, and the line says so."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    assert CliRunner().invoke(app, ["simulate", "-c", "hover", "-o", str(tmp_path),
                                    "--set", "simulation.duration=1"]).exit_code == 0
    before = _files(tmp_path)
    res = _interrupted_simulate(tmp_path, monkeypatch, "--set", "simulation.duration=2",
                                stop_with=ZeroDivisionError("a bug"))
    assert res.exit_code == 3, res.stderr
    assert "internal error ZeroDivisionError: a bug" in res.stderr
    assert "; the run folder is as the earlier config's run left it; rerun with --debug" in res.stderr
    assert _files(tmp_path) == before


def test_a_figure_drawer_dies_with_its_parent_killed_hard(tmp_path):
    """`simulate --plot` forks a child that draws half the figures: a `kill -9` of the command takes it
    too, so nothing writes into the folder after its lock died with the parent."""
    proc = subprocess.Popen([sys.executable, "-m", "quadctl", "simulate", "-c", "forward", "-o", str(tmp_path),
                             "--plot"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, "MPLBACKEND": "Agg"})
    def drawers() -> list[int]:  # forked: the command's own command line (a compiler it runs has another)
        own = (Path("/proc") / str(proc.pid) / "cmdline").read_bytes()
        found = []
        for pid in _children(proc.pid):
            try:
                if (Path("/proc") / str(pid) / "cmdline").read_bytes() == own:
                    found.append(pid)
            except OSError:
                continue
        return found

    deadline = time.monotonic() + 120
    while not drawers():  # the drawer is forked once the simulation is done
        assert proc.poll() is None, "the command ended before it forked a drawer"
        assert time.monotonic() < deadline, "no drawer was forked"
        time.sleep(0.005)
    drawers = drawers()
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    time.sleep(0.2)
    assert not any(_alive(d) for d in drawers), "the drawer outlived its killed parent"
    plots = tmp_path / "plots"
    drawn = sorted(p.name for p in plots.iterdir()) if plots.is_dir() else []
    time.sleep(3)  # what a drawer left alive would draw meanwhile
    assert (sorted(p.name for p in plots.iterdir()) if plots.is_dir() else []) == drawn


def test_a_process_forked_by_the_command_ends_on_sigterm_as_by_default():
    """The command answers SIGTERM as Ctrl-C; what it forks (a sweep's worker, a figure drawer) takes the
    default back before any of its own code runs: the pool stops a worker by SIGTERM, which must end it
    silently, not raise in it (a worker stopped while it started printed a traceback)."""
    code = ("import os, signal, sys\n"
            "from quadctl.cli import entry\n"
            "entry._terminate_as_interrupt()\n"
            "assert signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL\n"
            "pid = os.fork()\n"
            "if pid == 0:\n"
            "    os._exit(0 if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL else 1)\n"
            "sys.exit(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]))\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr


def _library_takes_the_ctrl_c(then):
    """A stage in which a Ctrl-C lands inside a library that takes it for its own error, as CasADi's Python
    wrapper does when the interrupt lands in its argument conversion: ``then(*args, **kwargs)`` is what the
    library does instead (raise its own error, return None, or carry on with the stage's work)."""

    def stage(*args, **kwargs):
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:
            return then(*args, **kwargs)
        raise AssertionError("the Ctrl-C was not raised")
    return stage


def _wrong_arguments(*_, **__):
    raise NotImplementedError("Wrong number or type of arguments for overloaded function 'Function_call'")


@pytest.mark.parametrize("then", ["its error", "None", "carried on"])
def test_a_ctrl_c_a_library_takes_for_its_own_still_stops_the_command(tmp_path, monkeypatch, then):
    """The command ends interrupted (130), not in 'internal error' (3) with the library's error, nor on
    with its work as if no Ctrl-C had come (0)."""
    from typer.testing import CliRunner

    from quadctl import pipeline
    from quadctl.cli.app import app

    instead = {"its error": _wrong_arguments, "None": lambda *_, **__: None,
               "carried on": pipeline.simulation_of}[then]
    with monkeypatch.context() as patch:
        patch.setattr(pipeline, "simulation_of", _library_takes_the_ctrl_c(instead))
        res = CliRunner().invoke(app, ["simulate", "-c", "hover", "-o", str(tmp_path)])
    assert res.exit_code == 130, res.output
    assert res.stderr.startswith("quadctl: error: interrupted") and "internal error" not in res.stderr, res.stderr
    if then == "carried on":  # what it finished is kept
        assert (tmp_path / "sim.npz").exists()


def test_a_process_forked_while_a_command_records_its_stops_has_the_handlers_from_before():
    """A sweep's worker forks while its command records Ctrl-C and SIGTERM: it is not that command, and
    takes the handlers back (with the command's, a SIGTERM the pool stops it with raised in it, traceback
    and all)."""
    from quadctl.cli.stops import stops_recorded

    before = signal.getsignal(signal.SIGINT)
    with stops_recorded():
        assert signal.getsignal(signal.SIGINT) is not before  # recording
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: say whether it has the handler from before, and leave
            os.write(write, b"1" if signal.getsignal(signal.SIGINT) is before else b"0")
            os._exit(0)
        os.waitpid(pid, 0)
        got = os.read(read, 1)
    assert got == b"1"
    assert signal.getsignal(signal.SIGINT) is before


def test_a_stop_the_moment_a_file_is_set_aside_leaves_no_set_aside_file(tmp_path, monkeypatch):
    """Ctrl-C (or SIGTERM) right after the session sets the earlier run's config.resolved.yaml aside for a
    roll-back, before anything else: the folder is the earlier run's again, with no set-aside file left in it
    (the removal of a set-aside file is arranged before the file exists)."""
    from typer.testing import CliRunner

    from quadctl.artifacts import session
    from quadctl.cli.app import app

    assert CliRunner().invoke(app, ["simulate", "-c", "hover", "-o", str(tmp_path),
                                    "--set", "simulation.duration=1"]).exit_code == 0
    before = _files(tmp_path)
    link = os.link

    def link_then_stop(src, dst, *args, **kwargs):
        link(src, dst, *args, **kwargs)
        if Path(src).name == "config.resolved.yaml":
            raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(session.os, "link", link_then_stop)
        res = CliRunner().invoke(app, ["simulate", "-c", "hover", "-o", str(tmp_path),
                                       "--set", "simulation.duration=2"])
    assert res.exit_code == 130, res.output
    assert _files(tmp_path) == before


def test_a_sigterm_that_reaches_a_forked_child_before_it_takes_its_handlers_back_ends_it_as_sigterm_does():
    """A sweep's worker stopped by its pool (SIGTERM) in the moment after its fork, while it still has the
    command's recording handler: it ends by the signal, not with Terminated raised in its fork hooks (which
    printed 'Exception ignored in _handlers_back_in_child' and a traceback)."""
    from quadctl.cli.stops import raise_terminated, stops_recorded

    previous = signal.signal(signal.SIGTERM, raise_terminated)  # as the console script sets it
    try:
        with stops_recorded():
            handler = signal.getsignal(signal.SIGTERM)
            pid = os.fork()
            if pid == 0:  # the child, as if the signal came before its fork hook restored the handlers
                try:
                    handler(signal.SIGTERM, None)
                except BaseException:
                    os._exit(7)
                os._exit(0)
            _, status = os.waitpid(pid, 0)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGTERM, status
