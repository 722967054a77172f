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
FORWARD = config.resolve("forward")[1]


def _edit(old: str, new: str) -> str:
    assert old in FORWARD, old
    return FORWARD.replace(old, new)


CONFIG_CASES = {
    "yaml syntax": ("name: [forward\n", r"c\.yaml: YAML syntax error at line 2, column 1: .*fix the YAML"),
    "not a mapping": ("- 1\n- 2\n", r"the config is a list, not a mapping of keys"),
    "empty file": ("", r"the config is empty, not a mapping of keys"),
    "wrong type": (_edit("mass: 0.068", "mass: heavy"), r'vehicle\.mass = "heavy": must be a number \(kg\)'),
    "unknown key": (_edit("vehicle:", "vehicel:"), r"vehicel: unknown key; did you mean `vehicle`\?"),
    "unknown nested key": (_edit("dt: auto", "dtt: auto"), r"simulation\.dtt: unknown key; did you mean `dt`\?"),
    "missing key": (_edit("name: forward\n", ""), r"name: required key is missing; add it"),
    "nan": (_edit("gravity: 9.81", "gravity: .nan"), r"vehicle\.gravity = nan: must be a finite number"),
    "infinite": (_edit("duration: 10.0", "duration: .inf"), r"simulation\.duration = inf: must be a finite"),
    "mass not positive": (_edit("mass: 0.068", "mass: 0"), r"vehicle\.mass = 0: must be greater than 0"),
    "inertia not positive": (_edit("inertia: [6.9e-5,", "inertia: [-6.9e-5,"),
                             r"vehicle\.inertia\[0\] = -6\.9e-05: must be greater than 0"),
    "negative drag": (_edit("drag: [0.22, 0.22, 0.0]", "drag: [0.22, -0.1, 0.0]"),
                      r"vehicle\.drag\[1\] = -0\.1: must be at least 0"),
    "vector length": (_edit("velocity_ned: [1.0, 0.0, 0.0]", "velocity_ned: [1.0, 0.0]"),
                      r"trim\.velocity_ned = \[1, 0\]: must be a list of exactly 3 items"),
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
                            r"lqr\.yw = \"yw\": unknown regulated subsystem; did you mean `yaw`\?"),
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
                      r"lqr\.altitude\.q: unknown key; did you mean `Q`\? \(and 1 more error\)"),
})
MAMBO = config.resolve("mambo-200hz")[1]
CONFIG_CASES["not a whole number"] = (MAMBO.replace("seed: 1", "seed: 1.5"),
                                      r"simulation\.noise\.seed = 1\.5: must be a whole number")
CONFIG_CASES["whole number written as a float"] = (_edit("dt: auto", "dt: auto\n  max_samples: 20000.0"),
                                                  r"simulation\.max_samples = 20000\.0: must be a whole number; "
                                                  r"write 20000$")
CONFIG_CASES["too few samples"] = (_edit("dt: auto", "dt: auto\n  max_samples: 1"),
                                   r"simulation\.max_samples = 1: must be at least 2")


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
    assert not (tmp_path / "out").exists()  # bad input writes nothing


@pytest.mark.parametrize("args,pattern", [
    (["-c", "no/such.yaml"], r"no/such\.yaml: no such file and no bundled config of that name; bundled: forward"),
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
    assert config.resolve(spec)[0] == label


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
    assert res.exit_code == 2 and "cannot read the config (Permission denied)" in res.stderr


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

