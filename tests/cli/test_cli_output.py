"""Output for logs and terminals: table width in a pipe, --width, a closed pipe, --json on every stage,
the simulation's progress bar, near names for a mistyped config file or command."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys

import pytest
from rich.console import Console
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli import progress, render
from quadctl.cli.app import app
from quadctl.cli.commands import COMMANDS
from quadctl.config import overrides
from quadctl.errors import ConfigError
from quadctl.sweep.gates import Gate
from quadctl.workspace import Workspace

runner = CliRunner()
DESIGN_HEADERS = ("subsystem", "closed-loop eigenvalues", "Riccati residual")


def _widest(text: str) -> int:
    return max(len(line.rstrip()) for line in text.splitlines())


@pytest.fixture(scope="module")
def hover_run(tmp_path_factory):
    """A run folder with hover's design, so that the commands below reuse it."""
    out = tmp_path_factory.mktemp("hover")
    assert runner.invoke(app, ["design", "-c", "hover", "-o", str(out)]).exit_code == 0
    return out


def test_a_pipe_gets_whole_tables(hover_run, monkeypatch):
    """Not a terminal, no COLUMNS: nothing cut (`control…`) or wrapped, whatever rich's 80 would do."""
    monkeypatch.delenv("COLUMNS", raising=False)
    res = runner.invoke(app, ["design", "-c", "hover", "-o", str(hover_run)])
    assert res.exit_code == 0, res.output
    assert "…" not in res.stdout
    header = next(line for line in res.stdout.splitlines() if "┃ subsystem" in line)
    assert all(h in header for h in DESIGN_HEADERS)
    assert _widest(res.stdout) > 80  # it does need more than 80 columns


def test_columns_and_width_set_the_width(hover_run, monkeypatch):
    monkeypatch.setenv("COLUMNS", "70")
    res = runner.invoke(app, ["design", "-c", "hover", "-o", str(hover_run)])
    assert res.exit_code == 0 and _widest(res.stdout) <= 70
    res = runner.invoke(app, ["--width", "100", "design", "-c", "hover", "-o", str(hover_run)])
    assert res.exit_code == 0 and 80 < _widest(res.stdout) <= 100
    res = runner.invoke(app, ["design", "-c", "hover", "-o", str(hover_run)])
    assert res.exit_code == 0 and _widest(res.stdout) <= 70  # the next call in this process: COLUMNS again


def test_a_columns_of_zero_or_too_few_still_prints(tmp_path):
    """COLUMNS=0 (a container or CI runner that knows no width) printed nothing at all, help and tables
    alike, with exit 0; COLUMNS=5 cut every cell to nothing: 0 is taken as unset, under 40 as 40."""
    def quadctl(columns, *args):
        return subprocess.run([sys.executable, "-m", "quadctl", *args], capture_output=True, text=True,
                              timeout=300, env={**os.environ, "COLUMNS": columns}, cwd=tmp_path)

    helped = quadctl("0", "--help")
    assert helped.returncode == 0 and "Usage: quadctl" in helped.stdout and "configs" in helped.stdout
    listed = quadctl("5", "configs")
    assert listed.returncode == 0 and "mambo-200hz" in listed.stdout
    assert 40 <= _widest(listed.stdout) <= 41  # the narrowest --width takes


def test_a_stdout_that_cannot_encode_a_character_gets_a_question_mark_not_an_internal_error(tmp_path):
    """An ASCII, Latin-1 or cp1252 stdout (Windows, redirected to a file) raised UnicodeEncodeError at
    the first `ö`, `✓`, `·` or `±` and exited 3, "please report it"."""
    listed = subprocess.run([sys.executable, "-m", "quadctl", "configs"], capture_output=True, text=True,
                            encoding="ascii", errors="strict", timeout=300, cwd=tmp_path,
                            env={**os.environ, "PYTHONIOENCODING": "ascii"})
    assert (listed.returncode, listed.stderr) == (0, "")
    assert "F?rster" in listed.stdout and "mambo-200hz" in listed.stdout


@pytest.mark.skipif(sys.platform in ("darwin", "win32"), reason="a file name there is Unicode: no stray byte")
def test_a_path_that_is_not_utf8_is_printed_as_given_on_a_strict_utf8_stdout(tmp_path):
    """A strict UTF-8 stdout (an en_US.UTF-8 locale) raised at the first byte of a path that is not UTF-8
    (read from the command line as a surrogate): exit 3. The bytes are now written back as given."""
    from quadctl import config

    name = os.fsencode(tmp_path) + b"/\xff.yaml"
    with open(name, "w", encoding="utf-8") as fh:
        fh.write(config.locate("hover").text)
    proc = subprocess.run([sys.executable, "-m", "quadctl", "configs", "--show", name], capture_output=True,
                          timeout=300, env={**os.environ, "PYTHONIOENCODING": "utf-8"})
    assert (proc.returncode, proc.stderr) == (0, b""), proc.stderr
    assert proc.stdout.startswith(b"# " + name + b", validated")


def test_a_backend_matplotlib_does_not_know_does_not_stop_the_figures(tmp_path):
    """MPLBACKEND=bogus (or another environment's backend) made `simulate --plot` an internal error, exit 3:
    matplotlib checks the variable on import, though quadctl draws into files with Agg and opens no window."""
    proc = subprocess.run([sys.executable, "-m", "quadctl", "simulate", "-c", "hover", "--plot", "-o", str(tmp_path),
                           "--set", "simulation.duration=0.1"], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "MPLBACKEND": "bogus"})
    assert (proc.returncode, proc.stderr) == (0, ""), proc.stderr
    assert (tmp_path / "plots" / "inputs.png").is_file()


def test_a_closed_pipe_ends_the_output_not_the_run(tmp_path):
    """`quadctl design | head -1`: exit 0 (never 1, "a check failed"), nothing on stderr, the work saved."""
    read, write = os.pipe()
    os.close(read)  # the reader has left before the first line
    proc = subprocess.run([sys.executable, "-m", "quadctl", "design", "-c", "hover", "-o", str(tmp_path)],
                          stdout=write, stderr=subprocess.PIPE, text=True, timeout=300)
    os.close(write)
    assert (proc.returncode, proc.stderr) == (0, "")
    assert (tmp_path / "design.json").exists()
    assert not (tmp_path / ".quadctl.lock").exists()  # and no lock file is left behind


def test_help_into_a_closed_pipe_exits_0():
    """`quadctl --help | head -1` exited 1 (rich's answer to the broken pipe), failing a `set -o pipefail` job."""
    for args in (["--help"], ["trim", "--help"]):
        read, write = os.pipe()
        os.close(read)
        proc = subprocess.run([sys.executable, "-m", "quadctl", *args], stdout=write, stderr=subprocess.PIPE,
                              text=True, timeout=300)
        os.close(write)
        assert (proc.returncode, proc.stderr) == (0, ""), args


def test_every_stage_command_has_json():
    stages = [m.NAME for m in COMMANDS if m.NAME != "configs"]
    for name in stages:
        res = runner.invoke(app, [name, "--help"], env={"COLUMNS": "200"})
        assert "--json" in res.output, name


def test_export_json_is_the_artifact_and_nothing_else(hover_run):
    res = runner.invoke(app, ["export", "--to", "json", "-c", "hover", "-o", str(hover_run), "--json"])
    assert res.exit_code == 0, res.output
    shown = json.loads(res.stdout)
    written = json.loads((hover_run / "quadctl_controller.json").read_text())
    assert shown["controller"] == written and shown["files"] == [str(hover_run / "quadctl_controller.json")]
    assert shown["integral_states"] == [] and shown["design"] == "continuous"


def test_the_library_reports_the_simulation_s_progress(tmp_path, monkeypatch):
    from quadctl.sim import stack_run

    monkeypatch.setitem(stack_run.CHUNK_STEPS, "compiled", 500)
    monkeypatch.setitem(stack_run.CHUNK_STEPS, "casadi", 500)
    cfg = overrides.load(config.bundled("hover"), ["simulation.duration=1"])
    calls = []
    ws = Workspace(cfg, tmp_path, progress=lambda done, total: calls.append((done, total)))
    sim = ws.simulation.sim
    n = sim.plan.n_steps
    assert len(calls) == -(-n // 500) and calls[-1] == (sim.steps, n) == (n, n)
    assert [d for d, _ in calls] == sorted({d for d, _ in calls})  # each chunk further on


def _terminal(monkeypatch) -> io.StringIO:
    buf = io.StringIO()
    monkeypatch.setattr(render, "err", Console(file=buf, force_terminal=True, width=100))
    return buf


def _feed(monkeypatch, steps_per_second: float, total: int = 1000) -> None:
    clock = iter(float(i) for i in range(100))
    monkeypatch.setattr(progress.time, "perf_counter", lambda: next(clock))
    with progress.simulation_progress() as update:
        for done in range(100, total + 1, int(steps_per_second)):
            update(done, total)


def test_a_long_simulation_draws_a_bar_with_an_eta_on_a_terminal(monkeypatch):
    buf = _terminal(monkeypatch)
    _feed(monkeypatch, steps_per_second=100)  # 1000 steps at 100 per (fake) second: 10 s
    assert "simulate" in buf.getvalue() and "ETA" in buf.getvalue()


def test_a_short_simulation_a_pipe_or_json_get_no_bar(monkeypatch):
    buf = _terminal(monkeypatch)
    _feed(monkeypatch, steps_per_second=900)  # about 1 s
    assert buf.getvalue() == ""
    with progress.simulation_progress(quiet=True) as update:
        assert update is None
    monkeypatch.setattr(render, "err", Console(file=io.StringIO(), force_terminal=False))
    with progress.simulation_progress() as update:
        assert update is None



def test_a_sweep_draws_its_bar_on_a_terminal_and_does_its_work_meanwhile_once(monkeypatch):
    """The first call runs ``meanwhile`` (the figure's imports) and starts the bar; later calls advance it."""
    from quadctl.cli import render_sweep

    buf = _terminal(monkeypatch)
    monkeypatch.setattr(render_sweep, "err", render.err)
    calls = []
    with progress.sweep_progress(meanwhile=lambda: calls.append("meanwhile")) as update:
        for done in (3, 40, 100):
            update(done, 100)
    assert calls == ["meanwhile"]
    assert "sweep" in buf.getvalue() and "100/100" in buf.getvalue()
    with progress.sweep_progress(quiet=True, meanwhile=lambda: calls.append("quiet")) as update:
        update(0, 10)
        update(10, 10)
    assert calls == ["meanwhile", "quiet"] and "10/10" not in buf.getvalue()
    with progress.sweep_progress(quiet=True) as update:
        assert update is None

@pytest.mark.parametrize("mission", [True, False])
def test_a_mission_sweeps_table_shows_no_settling_time_and_the_others_do(mission):
    """A mission is gated on its waypoints and tracking error: its table's third column is the peak thrust,
    not a settling time it never asked for; a sweep without a mission keeps the settling time."""
    from types import SimpleNamespace

    from quadctl.cli.render_sweep import sweep_tables

    columns = ["stable", "settling_time.pD", "peak.T", "tracking.rms", "tracking.peak"] + \
        (["waypoints.reached"] if mission else []) + ["cost", "status"]
    gated = ["waypoints.reached", "tracking.peak"] if mission else ["tracking.peak"]
    rows = [{"case": 0, "reference.speed": 1.0, "settling_time.pD": 19.7, "peak.T": 0.8, "tracking.peak": 2e-8,
             "waypoints.reached": 4, "cost": 1.0, "status": "ok", "pass": True}]
    result = SimpleNamespace(columns=columns, rows=rows, ranked=lambda: rows)
    bounds = {"waypoints.reached": Gate("waypoints.reached", min=4), "tracking.peak": Gate("tracking.peak", max=0.1)}
    spec = SimpleNamespace(gates=[bounds[m] for m in gated], names=["reference.speed"])
    headers = [str(c.header) for c in sweep_tables(result, spec).renderables[0].columns]
    want = ["waypoints.reached", "tracking.peak", "peak T (N)"] if mission else \
        ["tracking.peak", "settle pD (s)", "peak T (N)"]
    assert headers == ["case", "parameters", *want, "result"]


@pytest.mark.parametrize("gated", [True, False])
def test_the_sweep_tables_say_what_they_rank_by(gated):
    """The best cases have the most slack at the gate each comes nearest to failing, the worst the least:
    the titles say so, not just "the smallest slack"; without gates, the LQR cost ranks them."""
    from types import SimpleNamespace

    from quadctl.cli.render_sweep import sweep_tables

    rows = [{"case": k, "vehicle.mass": 0.068, "settling_time.pD": 1.0 + k, "cost": 1.0 + k, "status": "ok",
             "pass": True} for k in range(12)]
    result = SimpleNamespace(columns=["settling_time.pD", "cost", "status"], rows=rows, ranked=lambda: rows)
    spec = SimpleNamespace(gates=[Gate("settling_time.pD", max=20.0)] if gated else [], names=["vehicle.mass"])
    titles = [str(table.title) for table in sweep_tables(result, spec).renderables]
    assert titles == (["Best of 12 cases (most slack at their tightest gate, relative to its bound)",
                       "Worst of 12 cases (least slack at their tightest gate, relative to its bound)"] if gated else
                      ["Best of 12 cases (lowest LQR cost)", "Worst of 12 cases (highest LQR cost)"])


def test_the_sweep_tables_show_the_gate_that_ranks_the_worst_cases_first():
    """The worst cases are ranked by their tightest gate: its column comes first, whatever the sweep file's
    order of gates (three columns are shown, and a fourth gate's would be off screen)."""
    from types import SimpleNamespace

    from quadctl.cli.render_sweep import sweep_tables

    rows = [{"case": k, "vehicle.mass": 0.068, "settling_time.pD": 0.5, "settling_time.phi": 1.0,
             "settling_time.theta": 1.0, "peak.T": 5.6 + 0.01 * k, "cost": 1.0, "status": "ok", "pass": True}
            for k in range(6)]
    result = SimpleNamespace(columns=["settling_time.pD", "settling_time.phi", "settling_time.theta", "peak.T",
                                      "cost", "status"], rows=rows, ranked=lambda: rows[::-1])
    gates = [Gate("settling_time.pD", max=2.0), Gate("settling_time.phi", max=2.0),
             Gate("settling_time.theta", max=2.0), Gate("peak.T", max=6.0)]
    headers = [str(c.header) for c in sweep_tables(result, SimpleNamespace(gates=gates, names=["vehicle.mass"]))
               .renderables[0].columns]
    assert headers == ["case", "parameters", "peak T (N)", "settle phi (s)", "settle theta (s)", "result"]


def test_a_mistyped_config_file_offers_the_file_beside_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "f450.yaml").write_text(config.bundled("hover").text)
    with pytest.raises(ConfigError, match=r"^f450\.yml: no such file and no bundled config of that name; "
                                          r"did you mean `f450\.yaml` \(a file here\)\? bundled: "):
        config.locate("f450.yml")
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "config.yaml").write_text("")
    with pytest.raises(ConfigError, match=r"did you mean `runs/config\.yaml` \(a file in runs\)\?"):
        config.locate("runs/confg.yaml")
    with pytest.raises(ConfigError, match=r"did you mean `hover`\? bundled"):  # no file near: a bundled name
        config.locate("hovr")


def test_a_mistyped_command_is_one_clean_line():
    res = runner.invoke(app, ["simulte"])
    assert res.exit_code == 2
    assert res.stderr == ("quadctl: error: no such command 'simulte'; did you mean 'simulate'? "
                          "(quadctl --help lists the commands)\n")


def test_the_sweep_tables_show_a_noise_limited_settling_time_as_noise():
    """A row's settling time its noise_limited names reads `noise`, as in quadctl simulate; one that never
    settled, `-`."""
    import io
    from types import SimpleNamespace

    from rich.console import Console

    from quadctl.cli.render_sweep import sweep_tables

    rows = [{"case": 0, "vehicle.mass": 0.068, "settling_time.p": None, "settling_time.v": None, "status": "ok",
             "noise_limited": ["p"], "pass": True}]
    result = SimpleNamespace(columns=["settling_time.p", "settling_time.v", "status"], rows=rows, ranked=lambda: rows)
    gates = [Gate("settling_time.p", max=1.0), Gate("settling_time.v", max=1.0)]
    spec = SimpleNamespace(gates=gates, names=["vehicle.mass"])
    console = Console(width=200, file=io.StringIO())
    console.print(sweep_tables(result, spec))
    line = next(line for line in console.file.getvalue().splitlines() if "mass=0.068" in line)
    assert [cell.strip() for cell in line.split("│")[3:5]] == ["noise", "-"]


@pytest.mark.parametrize(("computed", "backend", "where"), [
    (0, [], ""), (2, [], " on local (no case simulated)"), (2, ["compiled-simd"], " on local (compiled-simd)")])
def test_the_sweep_line_names_where_cases_ran_only_when_some_did(computed, backend, where):
    """A sweep resumed whole computed nothing: its line said "on local (-)"; a sweep none of whose cases
    simulated (every one refused) said "(-)" too."""
    from types import SimpleNamespace

    from quadctl.cli.render_sweep import sweep_line

    stats = {"steps": 0, "designs": 0, "design_cpu": 0.0, "design_time": 0.0, "fallbacks": 0,
             "backend": backend, "executor": "local"}
    result = SimpleNamespace(rows=[{}, {}], computed=computed, wall_time=0.0, stats=stats, failed=[])
    line = sweep_line(SimpleNamespace(result=result, reused=2 - computed))
    resumed = ", 2 resumed" if not computed else ""
    assert line == f"2 cases ({computed} computed{resumed}) in 0.00 s{where}; [green]all pass[/green]"
