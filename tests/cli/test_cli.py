"""Every command through typer's CliRunner: output, artifacts, exit codes, --json, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


def test_help_lists_commands_and_exit_codes():
    res = invoke("--help")
    assert res.exit_code == 0
    for name in ("trim", "linearize", "decouple", "check", "design", "simulate", "run", "configs"):
        assert name in res.output
    assert "Exit codes" in res.output and "2 bad input" in res.output


@pytest.mark.parametrize("command,artifact", [
    ("trim", "trim.json"), ("linearize", "linear.npz"), ("decouple", "subsystems.json"),
    ("check", "checks.json"), ("design", "design.json"), ("simulate", "sim.json"),
])
def test_each_stage_writes_its_artifact(tmp_path, command, artifact):
    res = invoke(command, "-o", tmp_path)
    assert res.exit_code == 0, res.output
    assert (tmp_path / artifact).exists()


def test_trim_reports_the_report_numbers(tmp_path):
    res = invoke("trim", "-o", tmp_path)
    assert "0.652166" in res.output and "-0.211854" in res.output and "residual" in res.output
    data = json.loads((tmp_path / "trim.json").read_text())
    assert data["state_names"][7] == "theta" and round(data["x"][7], 4) == -0.2119
    assert data["config_hash"] and data["quadctl_version"]


def test_json_output_is_parseable_and_matches_the_artifact(tmp_path):
    res = invoke("design", "-o", tmp_path, "--json")
    payload = json.loads(res.stdout)
    assert payload == json.loads((tmp_path / "design.json").read_text())
    assert np.array(payload["K_block"]).shape == (4, 12)
    assert len(payload["full_closed_loop_eigenvalues"][0]) == 2  # [re, im]


@pytest.mark.parametrize("command,artifact", [("trim", "trim.json"), ("check", "checks.json")])
def test_json_prints_the_artifact_whether_new_or_reused(tmp_path, command, artifact):
    first = json.loads(invoke(command, "-o", tmp_path, "--json").stdout)
    again = json.loads(invoke(command, "-o", tmp_path, "--json").stdout)  # trim.json is reused now
    on_disk = json.loads((tmp_path / artifact).read_text())
    assert first.keys() == again.keys() == on_disk.keys()


def test_linearize_json_names_its_arrays(tmp_path):
    data = json.loads(invoke("linearize", "-o", tmp_path, "--json").stdout)
    assert data["state_names"][0] == "pN" and np.array(data["B"]).shape == (12, 4)


def test_decouple_names_dropped_terms(tmp_path):
    res = invoke("decouple", "-o", tmp_path)
    assert "d(w)/d(theta)" in res.output and "d(u)/d(T)" in res.output
    data = json.loads((tmp_path / "subsystems.json").read_text())
    assert data["subsystems"]["guidance"]["regulated"] is False
    assert any(d["name"] == "d(u)/d(T)" for d in data["dropped"])


def test_check_states_tolerance(tmp_path):
    res = invoke("check", "-o", tmp_path, "-c", "hover")
    assert res.exit_code == 0 and "tolerance" in res.output
    data = json.loads((tmp_path / "checks.json").read_text())
    assert data["subsystems"]["roll"]["stabilizable"] and data["full"]["ctrb_rank"] == 12
    assert "staircase" in res.output
    assert data["full"]["staircase"]["controllable_dim"] == 12
    assert data["subsystems"]["roll"]["staircase"]["observable_dim"] == 3
    # hovering at zero yaw, u drives pN and nothing drives pE (subsystems.json: A = 0, B = [[1, 0], [0, 0]])
    assert data["subsystems"]["guidance"]["staircase"] == {
        "controllable_dim": 1, "observable_dim": 2, "unobservable": [],
        "uncontrollable": [{"eigenvalue": [0.0, 0.0], "states": ["pE"]}]}


def test_simulate_reports_speed_and_plots(tmp_path):
    res = invoke("simulate", "-o", tmp_path, "--plot")
    assert res.exit_code == 0, res.output
    assert "M steps/s" in res.output
    pngs = sorted(p.name for p in (tmp_path / "plots").glob("*.png"))
    assert pngs == ["altitude.png", "guidance.png", "inputs.png", "pitch.png", "roll.png", "yaw.png"]
    with np.load(tmp_path / "sim.npz") as npz:
        assert npz["x"].shape[1] == 12 and npz["u"].shape[1] == 4 and str(npz["status"]) == "ok"
        assert list(npz["state_names"])[0] == "pN"
    summary = json.loads((tmp_path / "sim.json").read_text())
    assert summary["metrics"]["settling_time"]["pD"] < 2.0
    assert summary["metrics"]["peak"]["T"] > 0.6


QUIET_MAMBO_SETTLING = {"pD": 8.019, "u": 3.5700000000000003, "v": 2.376, "w": 6.796, "phi": 0.495,
                        "theta": 0.41100000000000003, "psi": 2.013, "p": 1.02, "q": 0.249, "r": 2.4010000000000002}
"""s: mambo-200hz's settling times without its noise (record times at 1 ms), as simulate gave them before
noise-limited settling times existed."""


def test_noise_limits_mambo_s_rate_settling_and_its_noise_free_run_keeps_its_numbers(tmp_path):
    """With its sensor and process noise, mambo-200hz's p, q, u and v still cross their 2 % band in the
    last second of the 10 s run: sim.json lists them as noise-limited with no settling time, the table
    shows ``noise`` and says what it means; the attitude keeps its number. The same config without
    noise keeps every settling time a number, the same as before."""
    res = invoke("simulate", "-c", "mambo-200hz", "-o", tmp_path / "noisy")
    assert res.exit_code == 0, res.output
    met = json.loads((tmp_path / "noisy" / "sim.json").read_text())["metrics"]
    assert met["noise_limited"] == ["u", "v", "p", "q"]
    assert all(met["settling_time"][s] is None for s in met["noise_limited"])
    assert 0.4 < met["settling_time"]["phi"] < 0.7 and 0.4 < met["settling_time"]["theta"] < 0.7
    rows = {line.split("│")[1].strip(): line.split("│")[3].strip() for line in res.output.splitlines()
            if line.count("│") >= 6}
    assert rows["p"] == rows["q"] == rows["u"] == rows["v"] == "noise" and rows["phi"] not in ("noise", "-")
    assert "noise: noise-limited" in " ".join(res.output.split())
    text = config.locate("mambo-200hz")[1]
    quiet = _write(tmp_path, text[:text.index("  noise:")])
    res = invoke("simulate", "-c", quiet, "-o", tmp_path / "quiet")
    assert res.exit_code == 0, res.output
    met = json.loads((tmp_path / "quiet" / "sim.json").read_text())["metrics"]
    assert met["noise_limited"] == [] and met["settling_time"] == QUIET_MAMBO_SETTLING
    assert "noise-limited" not in res.output


def test_an_error_still_coming_down_at_the_end_of_a_noisy_run_never_settled_and_noise_is_said_as_its_rule(tmp_path):
    """Cut at 3 s, mambo-200hz's altitude error is still coming down smoothly (its integrator), at 15 % of its
    largest, far outside its 2 % band: it never settled ('-'), noise or not, and is not noise-limited. Its roll
    rate, down to the noise, is; the table's footnote gives the rule (quadctl.metrics.NOISE_LIMITED_WORDS)."""
    from quadctl.metrics import NOISE_LIMITED_WORDS

    res = invoke("simulate", "-c", "mambo-200hz", "-o", tmp_path, "--set", "simulation.duration=3")
    assert res.exit_code == 0, res.output
    met = json.loads((tmp_path / "sim.json").read_text())["metrics"]
    assert "pD" not in met["noise_limited"] and met["settling_time"]["pD"] is None
    assert abs(met["final_error"]["pD"]) > 0.1 * met["peak_error"]["pD"]
    assert "p" in met["noise_limited"]
    said = " ".join(res.output.split())
    assert NOISE_LIMITED_WORDS in said and "│ pD │ m │ - │" in said


def test_run_executes_every_stage(tmp_path):
    res = invoke("run", "-o", tmp_path, "-c", "forward-script-q")
    assert res.exit_code == 0, res.output
    for name in ("trim.json", "linear.npz", "subsystems.json", "checks.json", "design.json", "sim.npz"):
        assert (tmp_path / name).exists()


@pytest.mark.parametrize("name,dropped", [("hover", "1 term dropped"), ("forward", "10 terms dropped")])
def test_run_prints_each_stage_on_one_line_with_counts_in_words(tmp_path, name, dropped):
    """Through a pipe (80 columns) the forward trim line (82 characters) wrapped mid-number; hover said
    "1 terms dropped"."""
    res = invoke("run", "-o", tmp_path, "-c", name)
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    trim = next(line for line in lines if line.startswith("✓ trim"))
    assert trim.endswith(f"residual {json.loads((tmp_path / 'trim.json').read_text())['residual']:.1e}")
    assert f"✓ decouple   5 subsystems, {dropped}" in lines
    assert all(line.startswith(("✓ ", "artifacts in")) for line in lines), lines


def test_configs_lists_and_shows(tmp_path):
    res = invoke("configs")
    assert "forward" in res.output and "hover" in res.output
    shown = invoke("configs", "--show", "hover")
    assert "velocity_ned" in shown.output
    assert config.parse(shown.output, "shown") == config.load("hover")  # round trip, long lines unwrapped
    own = tmp_path / "mine.yaml"
    own.write_text(shown.output)
    assert invoke("trim", "-c", own, "-o", tmp_path).exit_code == 0


def test_configs_show_prints_the_description_as_written_on_one_line():
    shown = invoke("configs", "--show", "crazyflie").output.splitlines()
    description = next(line for line in shown if line.startswith("description:"))
    assert description == f"description: '{config.load('crazyflie').description}'"
    assert "Förster" in description


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "c.yaml"
    path.write_text(text)
    return path


def test_bad_config_is_one_line_exit_2(tmp_path):
    cfg = _write(tmp_path, "name: x\nlqr: {}\nvehicle: {mass: -1}\n")
    res = runner.invoke(app, ["trim", "-c", str(cfg), "-o", str(tmp_path)])
    assert res.exit_code == 2
    assert res.stderr.strip().count("\n") == 0
    assert "vehicle.mass = -1" in res.stderr and "Traceback" not in res.output + res.stderr


def test_unknown_bundled_name_lists_the_bundled_ones():
    res = runner.invoke(app, ["trim", "-c", "fowrard"])
    assert res.exit_code == 2
    assert ("bundled: crazyflie, crazyflie-speed-schedule, crazyflie-wind, drake-hover, forward, forward-script-q, "
            "hover") in res.stderr


def test_unstabilizable_partition_fails_check_with_exit_1(tmp_path):
    """Swap the torques: the yaw torque R cannot move the roll loop's states."""
    text = config.locate("hover")[1]
    text = text.replace("roll:     {states: [v, phi, p], inputs: [A]}", "roll:     {states: [v, phi, p], inputs: [R]}")
    text = text.replace("yaw:      {states: [psi, r], inputs: [R]}", "yaw:      {states: [psi, r], inputs: [A]}")
    cfg = _write(tmp_path, text)
    res = runner.invoke(app, ["check", "-c", str(cfg), "-o", str(tmp_path)])
    assert res.exit_code == 1, res.output
    assert "roll is not stabilizable" in res.stderr and "yaw is not stabilizable" in res.stderr
    res = runner.invoke(app, ["design", "-c", str(cfg), "-o", str(tmp_path)])
    assert res.exit_code == 1
    assert "not stabilizable: the mode at eigenvalue 0 (in " in res.stderr


def test_unstable_step_is_bad_input(tmp_path):
    text = config.locate("forward")[1]
    cfg = _write(tmp_path, text.replace("dt: auto", "dt: 0.001"))
    res = runner.invoke(app, ["simulate", "-c", str(cfg), "-o", str(tmp_path)])
    assert res.exit_code == 2
    assert "subsystem roll" in res.stderr and "use dt: auto" in res.stderr


def test_python_dash_m_and_version():
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "quadctl", "--version"], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.startswith("quadctl ")


USAGE_ERRORS = {
    "a rate below its bound": (["check", "--rate", "-5"],
                               "quadctl: error: --rate = -5: must be greater than 0.0 (Hz; absent: continuous "
                               "feedback, as in the report); --rate is controller.rate"),
    "a rate that is no number": (["check", "--rate=fast"],
                                 "quadctl: error: --rate fast: not a number; give --rate a number"),
    "an export target that does not exist": (["export", "--to", "py"],
                                             "quadctl: error: --to py: must be one of c, mat, json, crazyflie"),
    "a misspelt export target": (["export", "--to", "jsn"],
                                 "quadctl: error: --to jsn: must be one of c, mat, json, crazyflie; "
                                 "did you mean `json`?"),
    "no export target": (["export"], "quadctl: error: quadctl export needs --to c | mat | json | crazyflie; add it "
                                     "(`quadctl export --help` describes it)"),
    # a missing argument: the line read "quadctl init needs name" and "quadctl identify needs logs"
    "no name to init": (["init"], "quadctl: error: quadctl init needs NAME; give it, as `quadctl init NAME` "
                                  "(`quadctl init --help` describes it)"),
    "no log to identify": (["identify", "-c", "crazyflie"], "quadctl: error: quadctl identify needs LOG, one or more; "
                                                            "give it, as `quadctl identify LOG ...`"),
    "no worker": (["sweep", "-j", "0"], "quadctl: error: --jobs 0: out of range; give --jobs a value of at least 1"),
    # a whole-number option given a fraction or an exponent: the line said "out of range"
    "a fraction of a worker": (["sweep", "-j", "2.5"], "quadctl: error: --jobs 2.5: not a whole number; give --jobs "
                                                       "one in digits, at least 1"),
    "a width in exponent form": (["--width", "1e3", "trim"], "quadctl: error: --width 1e3: not a whole number; give "
                                                             "--width one in digits, at least 40"),
    "an unknown option": (["trim", "--bogus"], "quadctl: error: --bogus: quadctl trim has no such option; its "
                                               "options: --config, --out, --set, --json, --fresh, --help"),
    "a misspelt option": (["trim", "--jsn"], "quadctl: error: --jsn: quadctl trim has no such option; "
                                             "did you mean `--json`?"),
    "an option without its value": (["check", "--rate"], "quadctl: error: quadctl check: option '--rate' requires "
                                                         "an argument; see `quadctl check --help`"),
    "an unknown command": (["trmi"], "quadctl: error: no such command 'trmi'; did you mean 'trim'? "
                                     "(quadctl --help lists the commands)"),
    # quadctl's own options after the command: the line said only "quadctl trim has no such option"
    "--debug after the command": (["trim", "-c", "hover", "--debug"],
                                  "quadctl: error: --debug: an option of quadctl itself, not of quadctl trim: give it "
                                  "before the command, as `quadctl --debug trim ...`"),
    "--width after the command": (["design", "--width", "100"],
                                  "quadctl: error: --width: an option of quadctl itself, not of quadctl design: give "
                                  "it before the command, as `quadctl --width COLUMNS design ...`"),
    "--version after the command": (["sweep", "--version"], "quadctl: error: --version: an option of quadctl "
                                                            "itself, not of quadctl sweep: run `quadctl --version`"),
    # and a command's options before it: the line listed quadctl's own options only
    "-c before the command": (["-c", "schedule", "run"],
                              "quadctl: error: -c: an option of a command, not of quadctl itself: give it after the "
                              "command, as `quadctl run -c ...`"),  # -c's value is no command
    "--json with no command": (["--json"], "quadctl: error: --json: an option of a command, not of quadctl itself: "
                                           "give it after the command, as `quadctl COMMAND --json ...`"),
    "an unknown option before the command": (["--bogus", "trim"], "quadctl: error: --bogus: quadctl has no such "
                                                                  "option; its options: --debug"),
    # a config named without its option: the line said only "got unexpected extra argument(s) (hover)"
    "a config without -c": (["run", "hover"], "quadctl: error: quadctl run: got an extra argument, hover: a config "
                                              "goes after -c, as `quadctl run -c hover`"),
    "a config without --show": (["configs", "hover"], "quadctl: error: quadctl configs: got an extra argument, "
                                                      "hover: a config goes after --show, as `quadctl configs --show "
                                                      "hover`"),
    # the line keeps the options given, and reads a word as a config only when it names one
    "a config without -c after options": (["export", "--to", "c", "hover"], "quadctl: error: quadctl export: got an "
                                          "extra argument, hover: a config goes after -c, as `quadctl export --to c "
                                          "-c hover`"),
    "a law without --law": (["compare", "pid:px4"], "quadctl: error: quadctl compare: got unexpected extra "
                                                    "argument(s) (pid:px4); see `quadctl compare --help`"),
    "an extra word beside -c": (["trim", "-c", "hover", "x"], "quadctl: error: quadctl trim: got unexpected extra "
                                                              "argument(s) (x); see `quadctl trim --help`"),
    # empty values: --show '' listed the bundled configs, -s '' read the current folder as the sweep file
    "an empty --show": (["configs", "--show", ""], "quadctl: error: '': an empty config name; give a config file's "
                                                   "path or a bundled config's name"),
    "an empty --sweep": (["sweep", "-s", ""], "quadctl: error: --sweep '': an empty path; give the sweep file, as "
                                              "`quadctl sweep -s examples/ci-sweep.yaml`"),
}


@pytest.mark.parametrize("case", sorted(USAGE_ERRORS))
def test_usage_errors_are_one_line_with_the_fix_exit_2(case):
    """click's usage block and boxed error became one stderr line naming the option, the value and the fix."""
    args, start = USAGE_ERRORS[case]
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(start), res.stderr


def test_help_still_answers_and_no_arguments_still_print_it():
    for args in (["check", "--help"], ["-h"], []):
        res = runner.invoke(app, args)
        assert "Usage: quadctl" in res.output and "quadctl: error" not in res.output
    assert runner.invoke(app, ["check", "--help"]).exit_code == 0


def test_help_options_show_a_metavar_not_a_python_type():
    """compare --help showed `--law <list[str]>`, the option's Python annotation, where every other option
    shows what to type (LAW, KEY=VALUE, T0:T1)."""
    from quadctl.cli.commands import COMMANDS

    for module in COMMANDS:
        text = runner.invoke(app, [module.NAME, "--help"], env={"COLUMNS": "200"}).output
        options = text[text.index("Options"):]
        assert "<list[" not in options, module.NAME
    assert "--law" in runner.invoke(app, ["compare", "--help"], env={"COLUMNS": "200"}).output


def test_help_texts_show_no_rst_quotes_and_sweep_states_the_uncertainty_rule():
    """check --help showed ``estimator:`` literally; sweep --help said a noise-seed sweep alone is a
    Monte Carlo, though every plant-side sweep (uncertainty.plant_side) writes montecarlo.png/.npz."""
    from quadctl.cli.commands import COMMANDS
    from quadctl.sweep.uncertainty import plant_side

    for module in COMMANDS:
        res = runner.invoke(app, [module.NAME, "--help"], env={"COLUMNS": "200"})
        assert res.exit_code == 0 and "``" not in res.output, module.NAME
    text = " ".join(runner.invoke(app, ["sweep", "--help"], env={"COLUMNS": "200"}).output.split())
    assert "alone is a Monte Carlo" not in text
    assert "is an uncertainty study: one design flies every case; it also writes montecarlo.png and montecarlo.npz" \
        in text
    named = [("simulation", "noise", "seed"), ("simulation", "plant", "mass"), ("simulation", "plant", "inertia", 0),
             ("simulation", "initial_offset", "pD"), ("simulation", "wind", "gusts"), ("controller", "delay"),
             ("motors", "time_constant")]
    assert all(plant_side(keys) for keys in named)


def test_help_wraps_at_the_terminal_not_at_the_docstring_line_breaks():
    """The help's rich markup kept each docstring's line breaks: on an 80-column terminal a sentence
    broke where the source did ("controller rate can" / "realize"), and the command list showed
    "write" alone on a line. Each paragraph is now one line, which only the terminal wraps."""
    import inspect

    from quadctl.cli.commands import COMMANDS

    listing = " ".join(runner.invoke(app, ["--help"], env={"COLUMNS": "1000"}).output.split("\n"))
    for module in COMMANDS:
        paragraphs = [" ".join(p.split()) for p in inspect.cleandoc(module.command.__doc__).split("\n\n")]
        lines = [line.strip(" │") for line in
                 runner.invoke(app, [module.NAME, "--help"], env={"COLUMNS": "1000"}).output.splitlines()]
        for paragraph in paragraphs:
            assert paragraph in lines, (module.NAME, paragraph)
        assert paragraphs[0] in listing, module.NAME


def test_help_loses_no_bracketed_text_to_rich_markup():
    """The help is rich markup: `allow: [saturation]` showed as `allow: ` (the bracket read as a
    style tag). Every help text of every command and option renders whole (an escaped \\[ as [)."""
    import typer
    from rich.text import Text

    root = typer.main.get_command(app)
    for command in (root, *root.commands.values()):
        for text in (command.help or "", *(getattr(p, "help", None) or "" for p in command.params)):
            assert Text.from_markup(text).plain == text.replace("\\[", "["), (command.name, text)
    res = runner.invoke(app, ["simulate", "--help"], env={"COLUMNS": "1000"})
    assert "the config's `allow: [saturation]` does the same" in res.output


def _warnings(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("quadctl: warning:")]


def test_run_warns_as_the_stages_do(tmp_path):
    """``run`` prints the warnings ``simulate`` and ``check`` print on the same config: a design at a
    rotor limit for a part of the run (a small vehicle's default rotors) and loops a rate cannot realize."""
    sets = ["--set", "controller.rate=20000", "--set", "controller.design=continuous"]
    ran = invoke("run", "-c", "docs/configs/report-on-mambo.yaml", "-o", tmp_path / "run", *sets)
    assert ran.exit_code == 0, ran.output
    alone = [invoke(stage, "-c", "docs/configs/report-on-mambo.yaml", "-o", tmp_path / stage, *sets)
             for stage in ("check", "simulate")]
    expected = _warnings(alone[0].stderr) + _warnings(alone[1].stderr)
    assert any("realizes" in w for w in expected) and any("saturates" in w for w in expected)
    assert _warnings(ran.stderr) == expected


def test_run_marks_no_stage_that_fails_its_gate(tmp_path):
    res = invoke("run", "-o", tmp_path, "--set", "limits={R: [-1.0e-7, 1.0e-7]}")
    assert res.exit_code == 1
    assert "✓ design" in res.stdout and "simulate" not in res.stdout
    assert "the design saturates: R is at a limit 100 % of the run" in res.stderr
    assert (tmp_path / "sim.npz").exists()  # what was computed is saved


def test_run_and_report_stop_at_the_same_check(tmp_path):
    """One chain of stages (quadctl.stages): a flight at its limits fails ``report`` as it fails ``run``,
    at the same stage, for the same reason, in the same line."""
    sets = ["--set", "limits={R: [-1.0e-7, 1.0e-7]}"]
    ran, reported = (invoke(cmd, "-o", tmp_path / cmd, *sets) for cmd in ("run", "report"))
    assert ran.exit_code == reported.exit_code == 1
    failed = [line for line in ran.stderr.splitlines() if line.startswith("quadctl: check failed:")]
    assert failed == [line for line in reported.stderr.splitlines() if line.startswith("quadctl: check failed:")]
    assert failed[0].startswith("quadctl: check failed: simulate: the design saturates: R is at a limit 100 %")


def test_flags_show_no_value_placeholder_in_help():
    """typer 0.29 showed `--plot <bool>`, `--json <bool>`, `--help -h <bool>`, as if the flag took a value
    (`--plot true` is refused); options that take one keep theirs (`--out DIR`, `--set KEY=VALUE`)."""
    import re

    from quadctl.cli.commands import COMMANDS

    rows = {re.split(r"\s{2,}", line.strip(" │"))[0]: line
            for line in runner.invoke(app, ["simulate", "--help"], env={"COLUMNS": "200"}).output.splitlines()
            if line.strip(" │").startswith("--")}
    assert re.search(r"--plot\s+Also write PNG figures", rows["--plot"])
    assert re.search(r"--help\s+-h\s+Show this message", rows["--help"])
    assert re.search(r"--out\s+-o\s+DIR\s+Run directory", rows["--out"])
    assert "KEY=VALUE" in rows["--set"]
    for args in (["--help"], *([m.NAME, "--help"] for m in COMMANDS)):
        res = runner.invoke(app, args, env={"COLUMNS": "200"})
        assert res.exit_code == 0 and "<bool>" not in res.output, args


def test_the_set_help_of_configs_names_what_it_changes_not_a_run_directory():
    """configs --help said --set is "recorded in DIR/config.yaml", but configs writes no run directory."""
    text = " ".join(runner.invoke(app, ["configs", "--help"], env={"COLUMNS": "200"}).output.split())
    assert "DIR" not in text
    assert "validated as the file is; put into the config --show prints (give --show with it)." in text
    trim = " ".join(runner.invoke(app, ["trim", "--help"], env={"COLUMNS": "200"}).output.split())
    assert "validated as the file is; recorded in DIR/config.yaml." in trim


def test_a_monte_carlo_with_no_case_simulated_says_why_it_has_no_bands(tmp_path):
    """Every case of a plant-side sweep refused (a delay of half a controller sample): the gates fail
    (exit 1) and stderr says why montecarlo.png and montecarlo.npz are missing, not silence."""
    sweep_file = tmp_path / "s.yaml"
    sweep_file.write_text("mode: grid\nparameters:\n  controller.delay: [0.0025, 0.0075]\n"
                          "set:\n  simulation.duration: 0.5\ngates:\n  peak.T: {max: 10}\n")
    res = invoke("sweep", "-c", "mambo-200hz", "-s", sweep_file, "-o", tmp_path / "out", "--jobs", "1", "--no-plot")
    assert res.exit_code == 1, res.output
    assert "no montecarlo.png or montecarlo.npz: no case of this Monte Carlo simulated to the end" in res.output
    assert not (tmp_path / "out" / "montecarlo.npz").exists()
    summary = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert summary["montecarlo"]["cases"] == 0 and summary["montecarlo"]["left_out"] == [0, 1]
