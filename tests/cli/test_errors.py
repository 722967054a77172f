"""The bad-input catalogue: every case is one stderr line with the key, the value and the fix.

Each case runs the real command through typer's CliRunner and pins its message and exit code.
"""

from __future__ import annotations

import os
import re

import pytest
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app

runner = CliRunner()
FORWARD = config.locate("forward")[1]


def _edit(old: str, new: str) -> str:
    assert old in FORWARD, old
    return FORWARD.replace(old, new)


CONSTANT_NAME = re.compile(r"\b(?!QUADCTL_|SWEEP_FILE\b)[A-Z][A-Z0-9]*_[A-Z0-9_]*[A-Z0-9]\b")
"""An UPPER_CASE name (MAX_BYTES) in a message: the code's, not the reader's. The environment variables
(QUADCTL_MAX_DURATION) and the command line's placeholder SWEEP_FILE are the reader's."""

CONFIG_CASES = {
    "yaml syntax": ("name: [forward\n", r"c\.yaml: YAML syntax error at line 1, column 7: .*fix the YAML"),
    "not a mapping": ("- 1\n- 2\n", r"the config is a list, not a mapping of keys"),
    "empty file": ("", r"the config is empty, not a mapping of keys"),
    "a number": ("42\n", r"the config is a number, not a mapping of keys"),  # it said "is a int"
    "text": ("forward\n", r"the config is text, not a mapping of keys"),
    "yaw far past a turn": (_edit("yaw: 0.0", "yaw: 1e300"),  # 300 digits of degrees, in one line
                            r"trim\.yaw = 1e\+300: that is 5\.73e\+301 deg, beyond 360 deg; angles are in rad: "),
    "wrong type": (_edit("mass: 0.068", "mass: heavy"), r'vehicle\.mass = "heavy": must be a number \(kg\)'),
    "unknown key": (_edit("vehicle:", "vehicel:"), r"vehicel: unknown key; did you mean `vehicle`\?"),
    "unknown nested key": (_edit("dt: auto", "dtt: auto"), r"simulation\.dtt: unknown key; did you mean `dt`\?"),
    "missing key": (_edit("name: forward\n", ""),
                    r"name: required key is missing; add it \(names the run directory runs/<name>\)$"),
    "nan": (_edit("gravity: 9.81", "gravity: .nan"), r"vehicle\.gravity = nan: must be a finite number"),
    "infinite": (_edit("duration: 10.0", "duration: .inf"), r"simulation\.duration = inf: must be a finite"),
    "mass not positive": (_edit("mass: 0.068", "mass: 0"), r"vehicle\.mass = 0: must be at least 0\.0001 \(kg\)$"),
    "inertia not positive": (_edit("inertia: [6.9e-5,", "inertia: [-6.9e-5,"),
                             r"vehicle\.inertia\[0\] = -6\.9e-05: must be greater than 0"),
    "negative drag": (_edit("drag: [0.22, 0.22, 0.0]", "drag: [0.22, -0.1, 0.0]"),
                      r"vehicle\.drag\[1\] = -0\.1: must be at least 0"),
    "vector length": (_edit("velocity_ned: [1.0, 0.0, 0.0]", "velocity_ned: [1.0, 0.0]"),
                      r"trim\.velocity_ned = \[1, 0\]: must be a list of exactly 3 items"),
    "empty state list": (_edit("states: [v, phi, p]", "states: []"),
                         r"subsystems\.roll\.states = \[\]: must be a list of at least 1 item \("),
    "unknown state": (_edit("states: [v, phi, p]", "states: [v, phi, pp]"),
                      r"subsystems\.roll\.states\[2\] = \"pp\": unknown state; did you mean `p`\?"),
    "unknown input": (_edit("inputs: [E]", "inputs: [El]"),
                      r"subsystems\.pitch\.inputs\[0\] = \"El\": unknown input; did you mean `E`\?"),
    "repeated state": (_edit("states: [psi, r]", "states: [psi, r, p]"),
                       r"subsystems\.yaw\.states\[2\] = \"p\": state already in subsystem `roll`"),
    "input unassigned": (_edit("inputs: [R]}", "inputs: [A]}"),
                         r"subsystems\.yaw\.inputs\[0\] = \"A\": input already drives subsystem `roll`"),
    "input left out": (_edit("  yaw:      {states: [psi, r], inputs: [R]}\n", "").replace(
        "  yaw:      {Q: [50, 1], R: [1]}\n", ""),
        r"input `R` is not assigned to any regulated subsystem; add it to one subsystem's inputs"),
    "Q wrong size": (_edit("roll:     {Q: [1, 50, 1]", "roll:     {Q: [1, 50]"),
                     r"lqr\.roll\.Q = \[1, 50\]: expected 3 values \(one per v, phi, p\) or a 3x3 matrix, got 2"),
    "Q rows of different lengths": (_edit("altitude: {Q: [50, 1]", "altitude: {Q: [[50, 0], [0]]"),
                                    r"lqr\.altitude\.Q = \[\[50, 0\], \[0\]\]: expected 2 values \(one per pD, w\) "
                                    r"or a 2x2 matrix, got rows of 2, 1 values$"),
    "Q not symmetric": (_edit("altitude: {Q: [50, 1]", "altitude: {Q: [[50, 1], [0, 1]]"),
                        r"lqr\.altitude\.Q = .*: not symmetric; make it equal to its transpose"),
    "Q not PSD": (_edit("yaw:      {Q: [50, 1]", "yaw:      {Q: [50, -1]"),
                  r"lqr\.yaw\.Q = \[50, -1\]: must be positive semidefinite \(smallest eigenvalue -1\)"),
    "R not PD": (_edit("altitude: {Q: [50, 1], R: [1]}", "altitude: {Q: [50, 1], R: [0]}"),
                 r"lqr\.altitude\.R = \[0\]: must be positive definite"),
    "R wrong size": (_edit("yaw:      {Q: [50, 1], R: [1]}", "yaw:      {Q: [50, 1], R: [1, 1]}"),
                     r"lqr\.yaw\.R = \[1, 1\]: expected 1 value \(one per R\) or a 1x1 matrix, got 2 values"),
    "weights missing": (_edit("  yaw:      {Q: [50, 1], R: [1]}\n", ""),
                        r"regulated subsystem `yaw` has no weights; add lqr\.yaw with Q \(2 values\) and R \(1\)"),
    "weights for unknown": (_edit("  yaw:      {Q: [50, 1], R: [1]}\n",
                                  "  yaw:      {Q: [50, 1], R: [1]}\n  yw: {Q: [1], R: [1]}\n"),
                            r"c\.yaml: lqr\.yw: unknown regulated subsystem; did you mean `yaw`\?$"),
    "weights for an unregulated subsystem": (
        _edit("  yaw:      {Q: [50, 1], R: [1]}\n",
              "  yaw:      {Q: [50, 1], R: [1]}\n  guidance: {Q: [1, 1], R: [1]}\n"),
        r"c\.yaml: lqr\.guidance: this subsystem has regulate: false; remove its weights or regulate it$"),
    "misspelt design mode": (_edit("name: forward\n", "name: forward\ncontroller: {rate: 200, design: discreet}\n"),
                             r'c\.yaml: controller\.design = "discreet": must be one of discrete, continuous; '
                             r"did you mean `discrete`\?$"),
    "unknown turbulence intensity": (_edit("  dt: auto", "  dt: auto\n  wind: {turbulence: {intensity: extreme}}"),
                                     r'c\.yaml: simulation\.wind\.turbulence\.intensity = "extreme": must be one of '
                                     r"light, moderate, severe$"),
    "duration not positive": (_edit("duration: 10.0", "duration: -1"),
                              r"simulation\.duration = -1: must be greater than 0"),
    "dt not positive": (_edit("dt: auto", "dt: 0"),
                        r"simulation\.dt = 0: must be a positive number of seconds, or auto"),
    "offset unknown state": (_edit("{pD: 0.5,", "{pd: 0.5,"),
                             r"simulation\.initial_offset\.pd = 0\.5: unknown state; did you mean `pD`\?"),
}


CONFIG_CASES.update({
    "pitch offset in degrees": (_edit("theta: 0.1", "theta: 10"),
                                r"simulation\.initial_offset\.theta = 10: that is 573 deg, beyond 85 deg; "
                                r"angles are in rad: for 10 deg write 0\.1745"),
    "yaw in degrees": (_edit("yaw: 0.0", "yaw: 90"), r"trim\.yaw = 90: that is 5157 deg.* for 90 deg write 1\.571"),
    "case of a key": (_edit("altitude: {Q: [50, 1], R: [1]}", "altitude: {q: [50, 1], R: [1]}"),
                      r"lqr\.altitude\.q: unknown key; did you mean `Q`\?$"),  # Q missing is not a second error:
                      # Q and R are optional beside lqr.<name>.bryson (a missing pair is the checks' one line)
})
MAMBO = config.locate("mambo-200hz")[1]
CONFIG_CASES["not a whole number"] = (MAMBO.replace("seed: 1", "seed: 1.5"),
                                      r"simulation\.noise\.seed = 1\.5: must be a whole number")
CONFIG_CASES["whole number written as a float"] = (_edit("dt: auto", "dt: auto\n  max_samples: 20000.0"),
                                                  r"simulation\.max_samples = 20000\.0: must be a whole number; "
                                                  r"write 20000$")
CONFIG_CASES["too few samples"] = (_edit("dt: auto", "dt: auto\n  max_samples: 1"),
                                   r"simulation\.max_samples = 1: must be at least 2")


def billion_laughs() -> str:
    """1.6 kB of YAML that stands for 9^9 strings."""
    lines = ['lol0: &lol0 "lol"']
    lines += [f"lol{i}: &lol{i} [" + ", ".join([f"*lol{i - 1}"] * 9) + "]" for i in range(1, 10)]
    return "\n".join(lines) + "\n"


def _line(text: str) -> int:
    """The line of the bundled forward.yaml that ``text`` starts on (the file's comments move them)."""
    return FORWARD[:FORWARD.index(text)].count("\n") + 1


CONFIG_CASES.update({
    "duplicate key": (_edit("mass: 0.068", "mass: 0.068\n  mass: 0.5"),
                      rf"c\.yaml: vehicle\.mass: duplicate key at lines {_line('mass: 0.068')} and "
                      rf"{_line('mass: 0.068') + 1}; keep one \(YAML would silently take the last\)$"),
    "alias bomb": (FORWARD + billion_laughs(), rf"c\.yaml: lol6: at line {FORWARD.count(chr(10)) + 7} the aliases "
                                               r"\(\*name\) expand the document past 2,000,000 values and characters: "
                                               r"a YAML alias bomb\? write the values out$"),
    "nested 5000 deep": (_edit("description:", "deep: " + "[" * 5000 + "]" * 5000 + "\ndescription:"),
                         rf"c\.yaml: deep\[0\]\[0\]\.\.\.: nested more than 32 levels deep at line "
                         rf"{_line('description:')}; a config nests about 5: check the brackets$"),
    "name outside runs/": (_edit("name: forward", "name: .."), r'c\.yaml: name = "\.\.": must start with a letter'),
    "duration of 1e300 s": (_edit("duration: 10.0", "duration: 1e300"),
                            r"simulation\.duration = 1e\+300: must be at most 86400 s \(one day; set "
                            r"QUADCTL_MAX_DURATION to allow longer\)$"),
    "weight of 1e300": (_edit("yaw:      {Q: [50, 1]", "yaw:      {Q: [1e300, 1]"),
                        r"lqr\.yaw\.Q\[0\] = 1e\+300: a weight must be 0 or between 1e-15 and 1e\+15"),
    "offset of 1e308": (_edit("{pD: 0.5,", "{pD: 1e308,"),
                        r"simulation\.initial_offset\.pD = 1e\+308: must be at most 10000 m from the trim"),
    "impossible inertia": (_edit("1.5e-4]", "3e-4]"), r"c\.yaml: vehicle\.inertia = .*: no rigid body has Jxx \+ Jyy"),
})


@pytest.mark.parametrize("path,pattern", [
    ("/dev/zero", r"^quadctl: error: /dev/zero: more than 1,000,000 bytes, the most quadctl reads for a config file; "
                  r"a config file is a few kB: check the path$"),
    ("big.yaml", r"big\.yaml: more than 1,000,000 bytes, the most quadctl reads for a config file; a config file is "
                 r"a few kB"),
])
def test_a_config_too_large_to_be_one_is_refused_unread(tmp_path, path, pattern):
    if path == "big.yaml":
        path = tmp_path / path
        with open(path, "wb") as f:
            f.truncate(50_000_000)
    elif not os.path.exists(path):
        pytest.skip("needs /dev/zero")
    res = runner.invoke(app, ["trim", "-c", str(path), "-o", str(tmp_path / "out")])
    assert res.exit_code == 2
    assert len(res.stderr.strip().splitlines()) == 1 and re.search(pattern, res.stderr.strip()), res.stderr


@pytest.mark.parametrize("case", sorted(CONFIG_CASES))
def test_config_error_is_one_line_exit_2(tmp_path, case):
    text, pattern = CONFIG_CASES[case]
    path = tmp_path / "c.yaml"
    path.write_text(text)
    res = runner.invoke(app, ["design", "-c", str(path), "-o", str(tmp_path / "out")])
    assert res.exit_code == 2, res.output
    assert res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("quadctl: error: "), res.stderr
    assert re.search(pattern, lines[0]), lines[0]
    assert not CONSTANT_NAME.search(lines[0]), lines[0]  # bounds in numbers and words
    assert not (tmp_path / "out").exists()  # bad input writes nothing


@pytest.mark.parametrize("args,pattern", [
    (["-c", "no/such.yaml"],
     r"no/such\.yaml: no such file and no bundled config of that name; "
     r"bundled: crazyflie, crazyflie-speed-schedule, crazyflie-wind, drake-hover, forward"),
    (["-c", "."], r"\.: is a folder, not a config file"),
])
def test_config_file_errors(args, pattern):
    res = runner.invoke(app, ["trim", *args])
    assert res.exit_code == 2 and re.search(pattern, res.stderr), res.stderr


def test_exponent_without_a_dot_is_a_number():
    """YAML 1.1 reads 1e5 as text; quadctl's loader reads it as the number a user means."""
    cfg = config.parse(_edit("mass: 0.068", "mass: 68e-3").replace(
        "altitude: {Q: [50, 1], R: [1]}", "altitude: {Q: [5e1, 1], R: [1E0]}"), "c.yaml")
    assert cfg.vehicle.mass == 0.068 and cfg.lqr["altitude"].Q == [50.0, 1.0]


@pytest.mark.parametrize("spec,label", [("forward.yml", "forward.yaml"), ("hover.yaml", "hover.yaml")])
def test_bundled_names_with_an_extension(spec, label):
    assert config.locate(spec)[0] == label


@pytest.mark.parametrize("args", [["trim", "-c", ""], ["configs", "--show", " "]])
def test_an_empty_config_name_is_named_as_empty(args):
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert re.fullmatch(r"quadctl: error: '\s*': an empty config name; give a config file's path or a bundled "
                        r"config's name \(`quadctl configs` lists them\)\n", res.stderr), res.stderr


def test_misspelt_bundled_name_gets_a_suggestion():
    res = runner.invoke(app, ["trim", "-c", "forwad"])
    assert res.exit_code == 2 and "did you mean `forward`?" in res.stderr


def test_undecodable_config_file(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_bytes(b"name: \xff\xfe\n")
    res = runner.invoke(app, ["trim", "-c", str(path)])
    assert res.exit_code == 2 and "cannot read the config" in res.stderr


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads any file")
def test_unreadable_config_file(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text(FORWARD)
    path.chmod(0)
    res = runner.invoke(app, ["trim", "-c", str(path)])
    assert res.exit_code == 2 and "cannot read the config file (Permission denied); check the file" in res.stderr


@pytest.mark.parametrize("velocity,drag,pattern", [
    ("[0.0, 0.0, -10.0]", "[0.2, 0.2, 0.2]", r"no equilibrium at velocity_ned \[0, 0, -10\] m/s: it needs thrust"),
    ("[300.0, 0.0, 0.0]", "[0.22, 0.22, 0.0]", r"needs pitch -8\d\.\d deg, beyond the 80 deg .* choose a lower speed"),
])
def test_no_equilibrium_is_bad_input(tmp_path, velocity, drag, pattern):
    path = tmp_path / "c.yaml"
    path.write_text(_edit("velocity_ned: [1.0, 0.0, 0.0]", f"velocity_ned: {velocity}").replace(
        "drag: [0.22, 0.22, 0.0]", f"drag: {drag}"))
    res = runner.invoke(app, ["trim", "-c", str(path), "-o", str(tmp_path)])
    assert res.exit_code == 2 and re.search(pattern, res.stderr), res.stderr


def test_output_folder_that_cannot_be_written(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    res = runner.invoke(app, ["trim", "-o", str(blocker / "runs")])
    assert res.exit_code == 2
    assert "cannot write artifacts there" in res.stderr and "choose another --out folder" in res.stderr


NAME_TOO_LONG = "a" * 300
"""A file name past every file system's 255 bytes: the system refuses it (ENAMETOOLONG) where it would say
"no such file"; pathlib's tests raise that error, and the commands gave it as an internal error, exit 3."""


@pytest.mark.parametrize("args, message", [
    (["trim", "-c", NAME_TOO_LONG], rf"^quadctl: error: {NAME_TOO_LONG}: no such file and no bundled config"),
    (["configs", "--show", NAME_TOO_LONG + ".yaml"], r": no such file and no bundled config of that name;"),
    (["trim", "-o", NAME_TOO_LONG], r": cannot write artifacts there \(File name too long\); choose another --out"),
    (["trim", "-o", f"x/{NAME_TOO_LONG}/y"], r": cannot write artifacts there \(File name too long\);"),
    (["identify", "-c", "crazyflie", NAME_TOO_LONG], r": no such file; give the path of a flight log$"),
    (["identify", "-c", "crazyflie", "-o", NAME_TOO_LONG, "gone.csv"], r"gone.csv: no such file; give the path of"),
])
def test_a_name_too_long_for_the_file_system_is_bad_input(tmp_path, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and re.search(message, lines[0]), res.stderr
    assert list(tmp_path.iterdir()) == []


def test_corrupt_upstream_artifact(tmp_path):
    assert runner.invoke(app, ["linearize", "-o", str(tmp_path)]).exit_code == 0
    (tmp_path / "linear.npz").write_bytes(b"PK\x03\x04 truncated")
    res = runner.invoke(app, ["design", "-o", str(tmp_path)])
    assert res.exit_code == 2 and "linear.npz: corrupted artifact" in res.stderr
    assert runner.invoke(app, ["design", "-o", str(tmp_path), "--fresh"]).exit_code == 0


def test_artifact_from_another_version(tmp_path):
    assert runner.invoke(app, ["trim", "-o", str(tmp_path)]).exit_code == 0
    path = tmp_path / "trim.json"
    path.write_text(path.read_text().replace('"format_version": 1', '"format_version": 0'))
    res = runner.invoke(app, ["design", "-o", str(tmp_path)])
    assert res.exit_code == 2 and "trim.json: written by quadctl" in res.stderr and "--fresh" in res.stderr


def test_divergence_is_exit_1_and_saves_the_partial_run(tmp_path):
    """Positive-feedback yaw weights cannot be configured, so break the loop through the artifact."""
    assert runner.invoke(app, ["design", "-o", str(tmp_path)]).exit_code == 0
    import json

    path = tmp_path / "design.json"
    data = json.loads(path.read_text())
    data["K_block"] = [[-k for k in row] for row in data["K_block"]]
    path.write_text(json.dumps(data))
    res = runner.invoke(app, ["simulate", "-o", str(tmp_path)])
    assert res.exit_code == 1
    assert "check failed: diverged at t = " in res.stderr or "left the model's valid range" in res.stderr
    assert (tmp_path / "sim.npz").exists() and (tmp_path / "sim.json").exists()


@pytest.mark.parametrize("debug", [[], ["--debug"]])
def test_debug_prints_the_traceback_and_keeps_the_exit_code(debug):
    """--debug adds the traceback; the exit code is still the error class's (2: bad input)."""
    res = runner.invoke(app, [*debug, "trim", "-c", "nope"])
    assert res.exit_code == 2, res.output
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("quadctl: error: nope: no such file and no bundled config"), last
    assert ("Traceback (most recent call last)" in res.stderr) == bool(debug)
    if debug:
        assert "quadctl.errors.ConfigError: nope: no such file" in res.stderr


@pytest.mark.parametrize("debug", [[], ["--debug"]])
def test_a_wrong_argument_reaching_a_command_is_bad_input_not_a_bug(tmp_path, monkeypatch, debug):
    """A library call given a wrong argument inside a command (here the run's duration) is an ArgumentError:
    exit 2 and its one line, as bad input; a plain ValueError there would read as an internal error, exit 3."""
    import quadctl as qc
    from quadctl import pipeline

    monkeypatch.setattr(pipeline, "simulation_of", lambda setup, loop, **_: qc.simulate(loop, loop.x_trim, -1.0))
    res = runner.invoke(app, [*debug, "simulate", "-c", "hover", "-o", str(tmp_path / "run")])
    assert res.exit_code == 2, res.output
    assert res.stderr.strip().splitlines()[-1] == \
        "quadctl: error: duration must be a positive number of seconds, got -1.0"
    assert ("Traceback (most recent call last)" in res.stderr) == bool(debug)
    assert "internal error" not in res.stderr


@pytest.mark.parametrize("debug", [False, True])
def test_failed_checks_are_one_line_each_and_exit_1_decided_in_one_place(monkeypatch, debug):
    """A command says *that* its checks failed and why (FailedChecks); the errors module prints each
    reason as one line and picks the exit code, with no traceback even under --debug (a verdict)."""
    import typer

    from quadctl.cli.errors import EXIT_CHECK_FAILED, FailedChecks, handled

    monkeypatch.setenv("QUADCTL_DEBUG", "1" if debug else "0")
    demo = typer.Typer()

    @demo.command()
    @handled
    def verdict():
        typer.echo("the result, on stdout first")
        raise FailedChecks("roll is not stabilizable", "a loop sampled at 50 Hz is\n unstable")

    res = CliRunner().invoke(demo, [])
    assert res.exit_code == EXIT_CHECK_FAILED == 1
    assert res.stdout == "the result, on stdout first\n"
    assert res.stderr.splitlines() == ["quadctl: check failed: roll is not stabilizable",
                                       "quadctl: check failed: a loop sampled at 50 Hz is unstable"]


def test_only_the_errors_module_decides_exit_codes():
    """No command module raises an exit code of its own: they raise FailedChecks or a QuadctlError."""
    from pathlib import Path

    import quadctl.cli.commands as commands

    offenders = [path.name for path in Path(commands.__file__).parent.glob("*.py")
                 if "EXIT_" in path.read_text() or re.search(r"typer\.Exit\(\w", path.read_text())]
    assert offenders == []

def test_json_stdout_stays_parseable_when_a_check_fails(tmp_path):
    import json

    path = tmp_path / "c.yaml"
    swapped = _edit("roll:     {states: [v, phi, p], inputs: [A]}", "roll:     {states: [v, phi, p], inputs: [R]}")
    path.write_text(swapped.replace("yaw:      {states: [psi, r], inputs: [R]}",
                                    "yaw:      {states: [psi, r], inputs: [A]}"))
    res = runner.invoke(app, ["check", "-c", str(path), "-o", str(tmp_path), "--json"])
    assert res.exit_code == 1
    assert json.loads(res.stdout)["subsystems"]["roll"]["stabilizable"] is False
    assert "roll is not stabilizable" in res.stderr


def test_unknown_option_is_exit_2():
    res = runner.invoke(app, ["trim", "--confg", "x"])
    assert res.exit_code == 2



# ---------------------------------------------------------------------------------------
# Sweep files: the same loader, the same bounds, one line


SWEEP_CASES = {
    "duplicate key": ("parameters:\n  vehicle.mass: [0.06]\n  vehicle.mass: [0.07]\n",
                      r"s\.yaml: parameters\.vehicle\.mass: duplicate key at lines 2 and 3; keep one"),
    "alias bomb": (billion_laughs().replace("lol", "x") + "parameters: {vehicle.mass: [0.07]}\n",
                   r"s\.yaml: x7: at line 8 the aliases \(\*name\) expand the document past 2,000,000 values"),
    "nested 5000 deep": ("parameters: {vehicle.mass: " + "[" * 5000 + "]" * 5000 + "}\n",
                         r"s\.yaml: parameters\.vehicle\.mass\[0\]\.\.\.: nested more than 32 levels deep"),
    "a billion samples": ("mode: random\nsamples: 1000000000\nparameters: {vehicle.mass: [0.07]}\n",
                          r"s\.yaml: samples: 1000000000: more than 1,000,000 cases, the most a sweep "
                          r"runs; run fewer samples"),
    "10**30 samples": (f"mode: random\nsamples: {10 ** 30}\nparameters: {{vehicle.mass: [0.07]}}\n",
                       rf"s\.yaml: samples: {10 ** 30}: more than 1,000,000 cases, the most a sweep runs"),
    "samples as a float": ("mode: random\nsamples: 1e3\nparameters: {vehicle.mass: [0.07]}\n",
                           r"s\.yaml: samples: 1000\.0: must be a whole number >= 1; write 1000$"),
    "a range of 10**12": (f"parameters:\n  vehicle.mass: {{from: 0.06, to: 0.07, num: {10 ** 12}}}\n",
                          r"s\.yaml: parameters\.vehicle\.mass\.num = 1000000000000: more than 1,000,000 values, the "
                          r"most cases a sweep runs; use fewer$"),
    "a grid past the bound": ("parameters:\n  vehicle.mass: {from: 0.06, to: 0.07, num: 1000}\n"
                              "  lqr.roll.Q[1]: {from: 1, to: 100, num: 1001}\n",
                              r"s\.yaml: parameters: the grid has 1000 x 1001 = 1,001,000 cases, more than 1,000,000 "
                              r"\(the most a sweep runs\); use fewer values, or mode: random with samples$"),
    "a set: value its key refuses": ("parameters:\n  vehicle.mass: [0.06, 0.07]\nset:\n  simulation.duration: -1\n",
                                     r"s\.yaml: set\.simulation\.duration = -1: must be greater than 0\.0 \(s\)$"),
    "a range wider than a float": ("parameters:\n  vehicle.mass: {from: -1e308, to: 1e308, num: 3}\n",
                                   r"s\.yaml: parameters\.vehicle\.mass\.from = -1e\+308: must be at most 1e\+300 in "
                                   r"magnitude$"),
}


@pytest.mark.parametrize("case", sorted(SWEEP_CASES))
def test_sweep_file_error_is_one_line_exit_2(tmp_path, case):
    text, pattern = SWEEP_CASES[case]
    (tmp_path / "s.yaml").write_text(text)
    res = runner.invoke(app, ["sweep", "-s", str(tmp_path / "s.yaml"), "-o", str(tmp_path / "out")])
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("quadctl: error: "), res.stderr  # no progress bar: nothing ran
    assert re.search(pattern, lines[0]), lines[0]
    assert not CONSTANT_NAME.search(lines[0]), lines[0]  # bounds in numbers and words
    assert not (tmp_path / "out").exists()


def test_sweep_numbers_read_as_config_numbers(tmp_path):
    """5e0 was refused as "must be a finite number" and 68e-3 made every case invalid_config."""
    import json

    (tmp_path / "s.yaml").write_text("parameters:\n  vehicle.mass: [68e-3, 0.07]\n"
                                     "  lqr.roll.Q[1]: {from: 5e0, to: 5e1, num: 2}\n"
                                     "set: {simulation.duration: 1e-1}\ngates: {peak.T: {max: 5e0}}\n")
    res = runner.invoke(app, ["sweep", "-s", str(tmp_path / "s.yaml"), "-o", str(tmp_path / "out"), "-j", "1",
                              "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    assert summary["statuses"] == {"ok": 4} and summary["failed"] == 0
    assert summary["sweep"]["parameters"]["vehicle.mass"] == [0.068, 0.07]


# ---------------------------------------------------------------------------------------
# One line, always: stderr piped (rich used to wrap at 80 columns when it was not a terminal)


def test_errors_warnings_and_check_failures_stay_on_one_line_when_piped(tmp_path):
    import subprocess
    import sys

    long_name = tmp_path / ("a-config-file-with-a-long-name-" * 3 + ".yaml")
    long_name.write_text(_edit("mass: 0.068", "mass: 68").replace("duration: 10.0", "duration: 0.3")
                         + "motors: {}\n")
    sweep = tmp_path / "s.yaml"
    sweep.write_text("parameters:\n  lqr.roll.Q[1]: [10, 20, 30, 40, 50, 60, 70]\nset: {simulation.duration: 0.1}\n"
                     "gates: {peak.T: {max: 0.001}, peak.A: {max: 0.0000001}}\n")
    runs = [
        ["simulate", "-c", str(long_name), "-o", str(tmp_path / "a")],                  # notes, warnings, exit 1
        ["trim", "-c", str(tmp_path / "nope" / ("x" * 90))],                            # an error, exit 2
        ["sweep", "-s", str(sweep), "-o", str(tmp_path / "b"), "-j", "1", "--json"],    # a check failure, exit 1
    ]
    seen = []
    for args in runs:
        proc = subprocess.run([sys.executable, "-m", "quadctl", *args], capture_output=True, text=True,
                              env={**os.environ, "COLUMNS": "80"})
        assert proc.returncode in (1, 2), proc.stderr
        lines = proc.stderr.splitlines()
        assert all(line.startswith("quadctl: ") for line in lines), proc.stderr
        seen += lines
    kinds = {line.split(":")[1].strip() for line in seen}
    assert kinds >= {"note", "warning", "error", "check failed"}, seen
    assert max(map(len, seen)) > 200
    failed = [line for line in seen if line.startswith("quadctl: check failed: 7 of 7 cases fail")]
    assert failed and "worst cases: " in failed[0], seen


# ---------------------------------------------------------------------------------------
# --scheduler: the address's form is checked at once


@pytest.mark.parametrize("address,why", [
    ("tcp://127.0.0.1:notaport", "the port `notaport` is not a whole number from 1 to 65535"),
    ("tcp://127.0.0.1:0", "the port `0` is not a whole number from 1 to 65535"),
    ("tcp://127.0.0.1:70000", "the port `70000` is not a whole number from 1 to 65535"),
    ("tcp://127.0.0.1", "no port"),
    ("http://127.0.0.1:8786", "`http` is not a Dask protocol (tcp, tls, ws, wss, ucx)"),
    ("tcp://:8786", "no host"),
    ("tcp://my host:8786", "`my host` is not a host name or IP address"),
])
def test_a_malformed_scheduler_address_fails_at_once(tmp_path, address, why):
    import time

    (tmp_path / "s.yaml").write_text("parameters: {vehicle.mass: [0.07]}\n")
    start = time.perf_counter()
    res = runner.invoke(app, ["sweep", "-s", str(tmp_path / "s.yaml"), "--scheduler", address, "-o", str(tmp_path)])
    assert time.perf_counter() - start < 5
    assert res.exit_code == 2
    assert res.stderr == (f"quadctl: error: --scheduler {address}: {why}; give the address as tcp://host:port "
                          "(a Dask scheduler listens on 8786 unless told otherwise)\n")


def test_an_empty_scheduler_address_is_refused_not_run_locally(tmp_path):
    """`--scheduler "$DASK_SCHEDULER"` with the variable unset ran the sweep on this machine without a word."""
    (tmp_path / "s.yaml").write_text("parameters: {vehicle.mass: [0.07]}\n")
    res = runner.invoke(app, ["sweep", "-s", str(tmp_path / "s.yaml"), "--scheduler", "", "-o", str(tmp_path / "o")])
    assert res.exit_code == 2 and not (tmp_path / "o").exists()
    assert res.stderr == ("quadctl: error: --scheduler '': an empty address; give the address as tcp://host:port, "
                          "or leave --scheduler out to run on this machine's cores\n")


@pytest.mark.parametrize("address,normal", [("127.0.0.1:8786", "tcp://127.0.0.1:8786"),
                                            ("TLS://sched.example.org:8786/", "tls://sched.example.org:8786"),
                                            ("tcp://[::1]:8786", "tcp://[::1]:8786")])
def test_well_formed_scheduler_addresses(address, normal):
    from quadctl.sweep.runner import check_scheduler_address

    assert check_scheduler_address(address) == normal


def test_an_unreachable_scheduler_fails_within_the_timeout(monkeypatch):
    import socket
    import time

    pytest.importorskip("distributed")
    from quadctl.errors import SweepError
    from quadctl.sweep import runner as runner_mod

    with socket.socket() as sock:  # a port nobody listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    monkeypatch.setattr(runner_mod, "SCHEDULER_TIMEOUT", "1s")
    start = time.perf_counter()
    with pytest.raises(SweepError, match=rf"^--scheduler tcp://127\.0\.0\.1:{port}: cannot reach the Dask scheduler"):
        runner_mod._dask_client(f"tcp://127.0.0.1:{port}")
    assert time.perf_counter() - start < 8


def test_an_output_folder_that_is_a_file_is_said_to_be_one(tmp_path):
    blocker = tmp_path / "results"
    blocker.write_text("")
    res = runner.invoke(app, ["trim", "-o", str(blocker)])
    assert res.exit_code == 2
    assert f"{blocker}: cannot write artifacts there (a file, not a folder); choose another --out folder" in res.stderr


@pytest.mark.parametrize("args", [["trim", "-c", "hover"], ["sweep", "-c", "hover", "-s", "x.yaml"],
                                  ["identify", "x.csv", "-c", "crazyflie"]], ids=["trim", "sweep", "identify"])
def test_an_empty_out_is_refused_not_taken_for_the_current_folder(tmp_path, monkeypatch, args):
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, [*args, "-o", ""])
    assert res.exit_code == 2
    assert res.stderr.startswith("quadctl: error: --out '': an empty path; give the run directory") \
        and len(res.stderr.splitlines()) == 1
    assert not any(tmp_path.iterdir())
