"""Loading a config through the CLI: which file `-c NAME` means, the bounds on its numbers, the
notes and warnings it earns, and errors that name the file even when a later stage raises them.

Every case runs the real command (typer's CliRunner) and pins the exit code and the one line.
"""

from __future__ import annotations

import re

import pytest
from typer.testing import CliRunner

from quadctl import config
from quadctl.cli.app import app
from quadctl.config import notices
from quadctl.errors import ConfigError

runner = CliRunner()
FORWARD = config.bundled("forward").text
HOVER = config.bundled("hover").text
VEHICLE = FORWARD[FORWARD.index("vehicle:"):FORWARD.index("trim:")]


def edit(old: str, new: str, text: str = FORWARD) -> str:
    assert old in text, old
    return text.replace(old, new)


def stderr_lines(res) -> list[str]:
    return res.stderr.strip().splitlines()


def run(tmp_path, text: str, command: str = "trim", name: str = "c.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return runner.invoke(app, [command, "-c", str(path), "-o", str(tmp_path / "out")])


def one_error(res, pattern: str, code: int = 2) -> str:
    assert res.exit_code == code, (res.exit_code, res.output)
    lines = stderr_lines(res)
    assert len(lines) == 1 and lines[0].startswith("quadctl: error: "), res.stderr
    assert re.search(pattern, lines[0]), lines[0]
    return lines[0]


# ---------------------------------------------------------------------------------------
# -c NAME: a file, else a bundled config; never a folder


def test_a_folder_named_like_a_bundled_config_is_not_a_config(tmp_path, monkeypatch):
    """`quadctl run -c forward -o forward` makes a folder `forward`; the next command still means
    the bundled config, silently."""
    monkeypatch.chdir(tmp_path)
    assert runner.invoke(app, ["trim", "-c", "forward", "-o", "forward"]).exit_code == 0
    res = runner.invoke(app, ["linearize", "-c", "forward", "-o", "forward"])
    assert res.exit_code == 0, res.stderr
    assert res.stderr == ""


def test_a_folder_that_is_no_bundled_name_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine").mkdir()
    one_error(runner.invoke(app, ["trim", "-c", "mine"]), r"^quadctl: error: mine: is a folder, not a config file; "
                                                          r"give a \.yaml file$")


@pytest.mark.parametrize("file,spec,taken", [
    ("forward", "forward", "file"),            # a file of exactly that name wins
    ("forward.yaml", "forward.yaml", "file"),
    ("forward.yaml", "forward", "bundled"),    # the bare name is the bundled config
])
def test_when_a_file_and_a_bundled_config_could_be_meant_a_note_says_which(tmp_path, monkeypatch, file, spec, taken):
    monkeypatch.chdir(tmp_path)
    (tmp_path / file).write_text(HOVER)  # hover: trim at rest, so the two are told apart
    res = runner.invoke(app, ["trim", "-c", spec, "-o", "out", "--json"])
    assert res.exit_code == 0, res.stderr
    velocity = __import__("json").loads(res.stdout)["velocity_ned"]
    assert velocity == ([0, 0, 0] if taken == "file" else [1, 0, 0])
    lines = stderr_lines(res)
    assert len(lines) == 1, res.stderr
    if taken == "file":
        assert lines[0] == (f"quadctl: note: -c {spec}: using the file {file}, not the bundled config `forward` "
                            "(`quadctl configs --show forward` prints that one)")
    else:
        assert lines[0] == ("quadctl: note: -c forward: using the bundled config `forward`, not the file "
                            "forward.yaml in this folder (give -c ./forward.yaml for the file)")


def test_a_path_to_a_file_takes_no_note(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "forward.yaml").write_text(HOVER)
    res = runner.invoke(app, ["trim", "-c", "./forward.yaml", "-o", "out"])
    assert res.exit_code == 0 and res.stderr == ""


def test_configs_lists_the_bundled_configs_whatever_files_are_here(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "hover").write_text("not: a config\n")
    res = runner.invoke(app, ["configs"])
    assert res.exit_code == 0 and "Hover at 1 m altitude" in res.stdout


# ---------------------------------------------------------------------------------------
# The name is one folder inside runs/


@pytest.mark.parametrize("name", ["..", ".", "'../../etc'", "a/b", "'a\\\\b'", ".hidden", "-x", "''", "\"abc\\n\"",
                                  "a" * (config.MAX_NAME_LENGTH + 1), "a" * 300, "b" * 256])
def test_a_name_that_is_not_one_folder_name_is_refused(tmp_path, monkeypatch, name):
    """Not a folder name, or longer than a file name may be (300 characters ended in an internal error)."""
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "c.yaml"
    path.write_text(edit("name: forward", f"name: {name}"))
    res = runner.invoke(app, ["trim", "-c", str(path)])  # no -o: the default would be runs/<name>
    line = one_error(res, r"c\.yaml: name = ")
    assert ("must not be empty" in line) if name == "''" else line.endswith(
        "must start with a letter, digit or '_', use only letters, digits, '_', '.' and '-', and have at most 128 "
        "characters (it names the folder runs/<name>)")
    assert list(tmp_path.iterdir()) == [path]  # nothing written, inside runs/ or out of it


@pytest.mark.parametrize("name", ["forward", "my_quad.v2", "x-1", "_tmp", "a" * config.MAX_NAME_LENGTH])
def test_folder_names_are_fine(name):
    assert config.parse(edit("name: forward", f"name: {name}"), "c.yaml").name == name


# ---------------------------------------------------------------------------------------
# Bounds on numbers: a refusal naming the key, the value and the bound


@pytest.mark.parametrize("old,new,pattern", [
    ("duration: 10.0", "duration: 1e300",
     r"simulation\.duration = 1e\+300: must be at most 86400 s \(one day; set QUADCTL_MAX_DURATION "
     r"to allow longer\)$"),
    ("yaw:      {Q: [50, 1]", "yaw:      {Q: [1e300, 1]",
     r"lqr\.yaw\.Q\[0\] = 1e\+300: a weight must be 0 or between 1e-15 and 1e\+15 in magnitude; "
     r"the gains depend only on the ratios of the weights: scale Q and R together$"),
    ("R: [1]}\n  roll", "R: [1e-300]}\n  roll", r"lqr\.altitude\.R\[0\] = 1e-300: a weight must be 0 or between"),
    ("altitude: {Q: [50, 1]", "altitude: {Q: [[50, 0], [0, 1e16]]", r"lqr\.altitude\.Q\[1\]\[1\] = 1e\+16: a weight"),
    ("{pD: 0.5,", "{pD: 1e308,",
     r"simulation\.initial_offset\.pD = 1e\+308: must be at most 10000 m from the trim$"),
    ("{pD: 0.5,", "{r: -1e3, pD: 0.5,", r"simulation\.initial_offset\.r = -1000: must be at most 100 rad/s"),
    ("{pD: 0.5,", "{w: 1e200, pD: 0.5,", r"simulation\.initial_offset\.w = 1e\+200: must be at most 100 m/s"),
    ("position_ned: [0.0, 0.0, -1.0]", "position_ned: [0.0, 0.0, -1e308]",
     r"trim\.position_ned\[2\] = -1e\+308: must be at most 1e\+06 m in magnitude$"),
    ("velocity_ned: [1.0, 0.0, 0.0]", "velocity_ned: [1e300, 0.0, 0.0]",
     r"trim\.velocity_ned\[0\] = 1e\+300: must be at most 1000 m/s in magnitude$"),
])
def test_extreme_numbers_are_refused_by_the_schema(tmp_path, old, new, pattern):
    one_error(run(tmp_path, edit(old, new), "simulate"), r"^quadctl: error: .*c\.yaml: " + pattern)


MAMBO = config.bundled("mambo-200hz").text


@pytest.mark.parametrize("old,new,pattern", [
    ("mass: 0.068", "mass: 1e300", r"vehicle\.mass = 1e\+300: must be at most 10000 \(kg\)$"),
    ("mass: 0.068", "mass: 1e-300", r"vehicle\.mass = 1e-300: must be at least 0\.0001 \(kg\)$"),
    ("gravity: 9.81", "gravity: 1e300", r"vehicle\.gravity = 1e\+300: must be at most 100 \(m/s\^2\)$"),
    ("drag: [0.22, 0.22, 0.0]", "drag: [0.22, 1e300, 0.0]", r"vehicle\.drag\[1\] = 1e\+300: must be at most 100 "),
    ("rate: 200", "rate: 1e300", r"controller\.rate = 1e\+300: must be at most 100000 \(Hz"),
    ("force: [0.005,", "force: [1e300,", r"simulation\.noise\.force\[0\] = 1e\+300: must be at most 10000 \(N,"),
    ("torque: [2.0e-5,", "torque: [1e300,", r"simulation\.noise\.torque\[0\] = 1e\+300: must be at most 1000 \(N m,"),
])
def test_physical_bounds_the_pipeline_needs(tmp_path, old, new, pattern):
    """Found by setting every number of the bundled configs to +-1e300 and 1e-300: these gave an
    internal error (gravity, drag: the controllability test overflowed), numpy overflow warnings
    (noise) or a false "not stabilizable" (mass, rate); every other number gives a result or a
    refusal."""
    one_error(run(tmp_path, edit(old, new, MAMBO), "simulate"), r"^quadctl: error: .*c\.yaml: " + pattern)


def test_the_duration_bound_can_be_raised(tmp_path, monkeypatch):
    text = edit("duration: 10.0", "duration: 100000")
    one_error(run(tmp_path, text), r"simulation\.duration = 100000: must be at most 86400 s")
    monkeypatch.setenv("QUADCTL_MAX_DURATION", "2e5")
    assert config.parse(text, "c.yaml").simulation.duration == 1e5
    monkeypatch.setenv("QUADCTL_MAX_DURATION", "a week")
    one_error(run(tmp_path, text), r"^quadctl: error: QUADCTL_MAX_DURATION=a week: must be a positive number of "
                                   r"seconds; unset it for the default 86400 s$")


def test_weights_at_the_edges_of_the_range_design(tmp_path):
    """Not a refusal of everything large: a 1e9 weight designs and simulates."""
    res = run(tmp_path, edit("yaw:      {Q: [50, 1]", "yaw:      {Q: [1e9, 1]").replace("duration: 10.0",
                                                                                          "duration: 0.5"), "run")
    assert res.exit_code == 0, res.stderr
    assert "Warning" not in res.stderr


# ---------------------------------------------------------------------------------------
# The vehicle: impossible inertia refused, defaults and implausible values said


def test_an_inertia_no_rigid_body_has_is_refused(tmp_path):
    one_error(run(tmp_path, edit("1.5e-4]", "3e-4]")),
              r"^quadctl: error: .*c\.yaml: vehicle\.inertia = \[6\.9e-05, 7\.75e-05, 0\.0003\]: no rigid body has "
              r"Jxx \+ Jyy = 0\.0001465 below Jzz = 0\.0003 kg m\^2 \(the moments of inertia obey Jxx \+ Jyy >= Jzz\); "
              r"check the order \[Jxx, Jyy, Jzz\] and that all three are in kg m\^2$")


def test_the_plant_inertia_is_held_to_the_same_law(tmp_path):
    text = edit("  dt: auto", "  dt: auto\n  plant: {inertia: [1e-4, 1e-4, 1e-3]}")
    one_error(run(tmp_path, text), r"simulation\.plant\.inertia = \[0\.0001, 0\.0001, 0\.001\]: no rigid body has")


def test_the_reports_own_inertia_is_within_the_tolerance():
    """The Mambo's published Jxx + Jyy is 2.3 % under Jzz: measurement, not physics."""
    jxx, jyy, jzz = config.load("forward").vehicle.inertia
    assert 1 - config.INERTIA_TRIANGLE_RTOL < (jxx + jyy) / jzz < 1


@pytest.mark.parametrize("name", config.bundled_names())
def test_bundled_configs_earn_no_notice(name):
    assert notices.notices(config.load(name), name) == []


def notice_lines(res) -> list[str]:
    return [line for line in stderr_lines(res) if line.startswith(("quadctl: note: ", "quadctl: warning: "))]


def test_a_vehicle_given_in_part_says_what_it_took_from_the_mambo(tmp_path):
    """`vehicle: {mass: 0.027}` used to fly a 27 g vehicle with the 68 g Mambo's inertia and drag."""
    res = run(tmp_path, FORWARD.replace(VEHICLE, "vehicle:\n  mass: 0.027\n"))
    assert res.exit_code == 0, res.stderr
    assert notice_lines(res) == [
        f"quadctl: note: {tmp_path / 'c.yaml'}: vehicle.inertia, vehicle.drag not given: using the report's Parrot "
        "Mambo values (vehicle.inertia = [6.9e-05, 7.75e-05, 0.00015], vehicle.drag = [0.22, 0.22, 0]); give your "
        "vehicle's own values"]


def test_empty_motors_say_they_are_the_mambos(tmp_path):
    res = run(tmp_path, FORWARD + "motors: {}\n")
    assert res.exit_code == 0, res.stderr
    (line,) = notice_lines(res)
    assert line.startswith(f"quadctl: note: {tmp_path / 'c.yaml'}: motors.arm_length, motors.thrust_coefficient, "
                           "motors.torque_coefficient, motors.max_thrust not given: using the report's Parrot Mambo "
                           "values (motors.arm_length = 0.0624,")


def test_a_vehicle_left_out_whole_is_the_reports_without_a_word():
    text = FORWARD.replace(VEHICLE, "")
    assert notices.notices(config.parse(text, "c.yaml"), "c.yaml") == []


@pytest.mark.parametrize("old,new,key,pattern", [
    # the Crazyflie: inertia in kg mm^2 (1.657e-5 kg m^2 written as 16.57)
    (VEHICLE, "vehicle:\n  mass: 0.027\n  inertia: [16.57, 16.66, 29.26]\n  drag: [0.1, 0.1, 0]\n", "vehicle.inertia",
     r"vehicle\.inertia = \[16\.57, 16\.66, 29\.26\] kg m\^2 with vehicle\.mass = 0\.027 kg gives a radius of gyration "
     r"sqrt\(Jzz/m\) = 32\.9 m, but a 0\.027 kg quadcopter's is 0\.006 to 0\.18 m \(0\.02 to 0\.6 m times "
     r"the cube root of the mass in kg\); "
     r"is it in kg mm\^2\? that is \[1\.657e-05, 1\.666e-05, 2\.926e-05\] kg m\^2$"),
    ("mass: 0.068", "mass: 68", "vehicle.mass",
     r"vehicle\.mass = 68 kg with vehicle\.inertia = .* gives a radius of gyration sqrt\(Jzz/m\) = 0\.00149 m, .*; "
     r"is vehicle\.mass in grams\? "
     r"68 g is 0\.068 kg$"),
    ("inertia: [6.9e-5, 7.75e-5, 1.5e-4]", "inertia: [690, 775, 1500]", "vehicle.inertia",
     r"vehicle\.inertia = .* radius of gyration sqrt\(Jzz/m\) = 149 m, .*; is it in g cm\^2\? "
     r"that is \[6\.9e-05, 7\.75e-05, 0\.00015\] "
     r"kg m\^2$"),
    ("inertia: [6.9e-5, 7.75e-5, 1.5e-4]", "inertia: [1.5e-4, 6.9e-5, 7.75e-5]", "vehicle.inertia",
     r"vehicle\.inertia = \[0\.00015, 6\.9e-05, 7\.75e-05\]: Jzz is below Jxx or Jyy, but a flat quadcopter has Jzz "
     r"about Jxx \+ Jyy = 0\.000219 kg m\^2; is the order \[Jxx, Jyy, Jzz\]\?$"),
])
def test_an_implausible_vehicle_is_warned_about_with_the_likely_slip(tmp_path, old, new, key, pattern):
    cfg = config.parse(edit(old, new), "c.yaml")
    found = notices.notices(cfg, "c.yaml")
    assert [(n.level, n.key) for n in found] == [("warning", key)]
    assert re.search(r"^c\.yaml: " + pattern, found[0].message), found[0].message
    res = run(tmp_path, edit(old, new), "linearize")
    assert res.exit_code == 1, res.stderr  # a check failed: a design for a unit slip is for no vehicle
    assert notice_lines(res) == [f"quadctl: warning: {str(tmp_path / 'c.yaml')}: {found[0].message[8:]}"]
    assert stderr_lines(res)[-1] == (
        f"quadctl: check failed: {tmp_path / 'c.yaml'}: {key} implausible (the warning above gives the likely slip "
        "and the fix); correct the value, or add `allow: [implausible]` to the config if the vehicle really is so")
    res = run(tmp_path, edit(old, new) + "allow: [implausible]\n", "linearize")
    assert res.exit_code == 0, res.stderr  # unusual vehicles exist: the config says so
    assert notice_lines(res) == [f"quadctl: warning: {str(tmp_path / 'c.yaml')}: {found[0].message[8:]}"]


@pytest.mark.parametrize("motors,mass,key,pattern", [
    ("{max_thrust: 33.6}", 0.068, "motors.max_thrust",
     r"motors\.max_thrust = 33\.6 N per rotor with vehicle\.mass = 0\.068 kg is a thrust-to-weight ratio of 201 "
     r"\(4 rotors\); a quadcopter's is 1 to 30, a racing quadcopter's about 10; is motors\.max_thrust in "
     r"grams-force\? 33\.6 gf is 0\.33 N$"),
    ("{max_thrust: 0.034}", 0.068, "motors.max_thrust",
     r"thrust-to-weight ratio of 0\.204 \(4 rotors\); the vehicle cannot hover; is motors\.max_thrust in "
     r"kilograms-force\? 0\.034 kgf is 0\.333 N$"),
    ("{max_thrust: 0.33}", 0.2, "motors.max_thrust",  # just underpowered: no unit slip guessed
     r"ratio of 0\.673 .* cannot hover; check motors\.max_thrust \(N per rotor\) and vehicle\.mass \(kg\)$"),
])
def test_thrust_to_weight(motors, mass, key, pattern):
    text = edit("mass: 0.068", f"mass: {mass}") + f"motors: {motors}\n"
    found = [n for n in notices.notices(config.parse(text, "c.yaml"), "c.yaml") if n.level == "warning"]
    assert [n.key for n in found] == [key]
    assert re.search(pattern, found[0].message), found[0].message


def test_with_motors_the_radius_of_gyration_is_held_to_the_arm():
    text = edit("mass: 0.068", "mass: 68") + "motors: {arm_length: 0.0624, thrust_coefficient: 4.72e-8, " \
                                             "torque_coefficient: 0.00241, max_thrust: 0.33}\n"
    found = notices.notices(config.parse(text, "c.yaml"), "c.yaml")
    assert [n.key for n in found] == ["vehicle.mass", "vehicle.mass"]  # the radius, and the thrust-to-weight
    assert "0.0238 times motors.arm_length = 0.0624 m (a quadcopter's radius of gyration is 0.1 to 2 times its " \
           "arm length); " \
           "is vehicle.mass in grams? 68 g is 0.068 kg" in found[0].message
    assert "thrust-to-weight ratio of 0.00198 (4 rotors); the vehicle cannot hover; is vehicle.mass in grams?" \
           in found[1].message


@pytest.mark.parametrize("mass,inertia", [
    (0.027, [1.657e-5, 1.666e-5, 2.926e-5]),   # Crazyflie 2.0
    (1.5, [0.0075, 0.0075, 0.013]),            # a 450 mm frame
    (25.0, [1.2, 1.2, 2.2]),                   # a heavy-lift octo-class vehicle
])
def test_real_vehicles_earn_no_warning(mass, inertia):
    text = edit("mass: 0.068", f"mass: {mass}").replace("[6.9e-5, 7.75e-5, 1.5e-4]", str(inertia))
    assert notices.notices(config.parse(text, "c.yaml"), "c.yaml") == []


# ---------------------------------------------------------------------------------------
# Errors of later stages name the config file


@pytest.mark.parametrize("old,new,command,pattern", [
    ("velocity_ned: [1.0, 0.0, 0.0]", "velocity_ned: [0.0, 0.0, -10.0]", "trim",
     r"c\.yaml: no equilibrium at velocity_ned \[0, 0, -10\] m/s: it needs thrust"),
    ("dt: auto", "dt: 0.001", "simulate",
     r"c\.yaml: simulation\.dt = 0\.001 s is unstable for RK4: .* use dt: auto or a step of at most 0\.00019 s$"),
])
def test_errors_from_the_configs_values_name_the_file(tmp_path, old, new, command, pattern):
    text = edit(old, new).replace("drag: [0.22, 0.22, 0.0]", "drag: [0.2, 0.2, 0.2]")
    line = one_error(run(tmp_path, text, command), pattern)
    assert line.startswith(f"quadctl: error: {tmp_path / 'c.yaml'}: ")
    assert line.count("c.yaml") == 1


SWAPPED = edit("roll:     {states: [v, phi, p], inputs: [A]}", "roll:     {states: [v, phi, p], inputs: [R]}").replace(
    "yaw:      {states: [psi, r], inputs: [R]}", "yaw:      {states: [psi, r], inputs: [A]}")
"""Roll driven by the yaw torque: valid, but not stabilizable (a check failure, exit 1)."""


@pytest.mark.parametrize("debug", [[], ["--debug"]])
@pytest.mark.parametrize("text,code,pattern", [
    (edit("mass: 0.068", "mass: -1"), 2, r"vehicle\.mass = -1: must be at least 0\.0001"),       # ConfigError
    (edit("dt: auto", "dt: 0.001"), 2, r"simulation\.dt = 0\.001 s is unstable for RK4"),      # StepSizeError
    (SWAPPED, 1, r"subsystem roll: not stabilizable"),                                       # DesignError
])
def test_the_exit_code_does_not_depend_on_debug(tmp_path, debug, text, code, pattern):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    res = runner.invoke(app, [*debug, "simulate", "-c", str(path), "-o", str(tmp_path / "out")])
    assert res.exit_code == code, res.output
    last = stderr_lines(res)[-1]
    kind = "check failed" if code == 1 else "error"  # exit 1 is a failed check, and says so
    assert last.startswith(f"quadctl: {kind}: {path}: ") and re.search(pattern, last), last
    assert ("Traceback (most recent call last)" in res.stderr) == bool(debug)


def test_an_internal_error_is_exit_3_with_or_without_debug(tmp_path, monkeypatch):
    from quadctl import pipeline

    def broken(*args, **kwargs):
        raise IndexError("list index out of range")

    monkeypatch.setattr(pipeline, "trim_of", broken)
    for debug in ([], ["--debug"]):
        res = runner.invoke(app, [*debug, "trim", "-o", str(tmp_path)])
        assert res.exit_code == 3, res.output
        assert stderr_lines(res)[-1].startswith("quadctl: error: internal error IndexError: list index out of range")
        assert ("Traceback (most recent call last)" in res.stderr) == bool(debug)


def test_a_fifth_rotor_position_is_refused_as_a_list_of_exactly_four():
    """The length rule of a list inside Optional[...] (motors.positions) is read from the list, not said as
    'None to 4'."""
    res = CliRunner().invoke(app, ["trim", "-c", "crazyflie", "--set", "motors.spin=[ccw,cw,ccw,cw]", "--set",
                                   "motors.positions=[[0.03,0.04],[-0.03,0.04],[-0.03,-0.04],[0.03,-0.04],[0.05,0]]"])
    assert res.exit_code == 2 and "motors.positions" in res.stderr
    assert "must be a list of exactly 4 items (m, each rotor's" in res.stderr and "None" not in res.stderr


def test_a_config_with_several_errors_names_where_each_of_the_others_is():
    """The line says the first error and names every other failing key (the rest counted past three), so
    one run shows where each fix goes."""
    data = {"name": "x", "vehicle": {"mass": "heavy", "inertia": "big"}}
    with pytest.raises(ConfigError) as err:
        config.from_dict(data, "two.yaml")
    assert str(err.value) == ('two.yaml: vehicle.mass = "heavy": must be a number (kg) '
                              "(and 2 more errors, at vehicle.inertia and lqr)")
    data = {"name": "x", "vehicle": {"mass": 1.0, "inertia": [1, 1, 1], "drag": "a", "gravity": "b"},
            "trim": {"speed": "c"}, "simulation": {"duration": "d", "dt": -1}, "lqr": {}}
    with pytest.raises(ConfigError) as err:
        config.from_dict(data, "many.yaml")
    assert str(err.value).endswith("(and 4 more errors, at vehicle.gravity, vehicle.drag, simulation.duration "
                                   "and 1 more)"), str(err.value)


@pytest.mark.parametrize("spec, fix", [
    ({"vehicle": {"mass": 0.068}}, r"validate a mapping with quadctl.config.from_dict\(data\)"),
    (42, r"give a YAML file's path or a bundled config's name"),
])
def test_load_config_given_no_path_or_name_says_what_to_pass(spec, fix):
    """A dict read as a file name was 'no such file and no bundled config of that name'."""
    import quadctl as qc

    with pytest.raises(TypeError, match=rf"^load_config takes a file path or a bundled config's name, got "
                                        rf"{type(spec).__name__}; {fix}"):
        qc.load_config(spec)


@pytest.mark.parametrize("name", ["", "  "])
def test_an_empty_config_name_is_refused_as_empty(name):
    """'' resolved to the working folder and was refused as ': is a folder, not a config file' (no name)."""
    import quadctl as qc

    with pytest.raises(qc.ConfigError, match=r"^load_config: the config's name is empty \(.*\); give a YAML file's "
                                             r"path or a bundled config's name"):
        qc.load_config(name)
