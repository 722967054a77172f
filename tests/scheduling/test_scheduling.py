"""The gain schedule stage: each point's gain is the one-point design at its trim, the frozen-point
checks judge the interpolated gains on the models trimmed in between, the artifacts hold them, and
bad input is one line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.interpolate import PPoly, interp1d
from typer.testing import CliRunner

from quadctl import config, pipeline
from quadctl.cli.app import app
from quadctl.design.gain_table import OUTSIDE, GainTable, scheduling_value
from quadctl.errors import ScheduleError
from quadctl.layout import STATE_INDEX
from quadctl.linear import stability
from quadctl.present.schedule import frozen_failures
from quadctl.schedule.envelope import fine_values, frozen_checks, heading_of, own_value, schedule_of
from quadctl.setup import setup_of
from quadctl.workspace import Workspace

runner = CliRunner()
SAME_DESIGN = 1e-9
"""A point's gain against the one-point design at its trim (the issue's bound; both solve the same
Riccati equations to the solvers' residual check, one batched, one alone)."""


def with_schedule(name: str, schedule: dict, **trim) -> config.Config:
    """Bundled config ``name`` with ``schedule`` and the trim keys given replaced."""
    data = config.load(name).model_dump()
    data["trim"].update(trim)
    data["schedule"] = schedule
    return config.from_dict(data, f"{name} with a schedule")


def one_point_design(cfg: config.Config, velocity_ned, yaw):
    """``quadctl design`` of the config with its trim replaced by a point's (no schedule)."""
    data = cfg.model_dump()
    data["trim"].update(velocity_ned=list(velocity_ned), yaw=yaw)
    data.pop("schedule")
    stages = pipeline.Stages(setup_of(config.from_dict(data, "one point")))
    return stages.trim, stages.design


CASES = {
    # continuous design, speed along a heading 30 deg east of north (a climb kept)
    "forward speed": ("forward", {"variable": "speed", "values": [0.0, 0.5, 2.0, 4.0], "interpolation": "cubic"},
                      {"velocity_ned": [np.cos(0.5), np.sin(0.5), -0.2]}),
    # discrete design at 200 Hz with an integrator, climb rate
    "mambo climb": ("mambo-200hz", {"variable": "climb", "values": [-1.0, 0.0, 1.5]}, {}),
    # yaw in forward flight: the velocity stays north while the nose turns
    "forward yaw": ("forward", {"variable": "yaw", "values": [-0.6, 0.0, 0.4], "interpolation": "nearest"}, {}),
}


@pytest.fixture(scope="module")
def schedules():
    out = {}
    for case, (name, sched, trim) in CASES.items():
        cfg = with_schedule(name, sched, **trim)
        out[case] = cfg, schedule_of(setup_of(cfg))
    return out


@pytest.mark.parametrize("case", CASES)
def test_each_point_gain_is_the_one_point_design_at_its_trim(schedules, case):
    cfg, sched = schedules[case]
    assert len(sched.points) == len(cfg.schedule.values) and all(p.designed for p in sched.points)
    for p, value in zip(sched.points, cfg.schedule.values):
        trim, des = one_point_design(cfg, p.velocity_ned, p.yaw)
        assert p.value == value
        np.testing.assert_allclose(p.trim.x, trim.x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(p.trim.u, trim.u, rtol=0, atol=1e-12)
        scale = np.abs(des.K_block).max()
        assert np.abs(p.K - des.K_block).max() <= SAME_DESIGN * scale, case
        assert p.Ki.shape == des.Ki_block.shape
        if des.Ki_block.size:
            assert np.abs(p.Ki - des.Ki_block).max() <= SAME_DESIGN * np.abs(des.Ki_block).max()
        assert p.stable == des.stable
        # the point flies the value it is at: the variable read back from its trim state
        assert scheduling_value(sched.variable, p.trim.x, sched.heading) == pytest.approx(value, abs=1e-12)
    np.testing.assert_array_equal(sched.table.values, cfg.schedule.values)
    np.testing.assert_array_equal(sched.table.gains[:, :, :12], [p.K for p in sched.points])


def test_speed_keeps_the_heading_and_the_vertical_velocity(schedules):
    _, sched = schedules["forward speed"]
    assert sched.heading == pytest.approx(0.5, abs=1e-15)
    for p in sched.points:
        np.testing.assert_allclose(p.velocity_ned, [p.value * np.cos(0.5), p.value * np.sin(0.5), -0.2], atol=1e-15)
    _, climb = schedules["mambo climb"]
    assert [p.velocity_ned[2] for p in climb.points] == [1.0, -0.0, -1.5]


def test_hover_speed_is_along_the_nose():
    cfg = with_schedule("hover", {"variable": "speed", "values": [0.0, 1.0]}, yaw=-2.0)
    setup = setup_of(cfg)
    assert heading_of(setup) == -2.0
    sched = schedule_of(setup)
    np.testing.assert_allclose(sched.points[1].velocity_ned, [np.cos(-2.0), np.sin(-2.0), 0.0], atol=1e-15)


@pytest.mark.parametrize("check", [1, 3])
def test_the_fine_grid_splits_each_interval(check):
    v = fine_values([0.0, 1.0, 4.0], check)
    expected = np.concatenate([np.linspace(0, 1, check + 1)[:-1], np.linspace(1, 4, check + 1)])
    np.testing.assert_allclose(v, expected, rtol=0, atol=1e-15)


def _frozen_reference(cfg, table, v):
    """The eigenvalues of ``A(v) - B(v) G(v)``, the model trimmed at ``v`` by a one-point config and
    the gain interpolated by SciPy, the free positions (pN, pE: no gain reads them) left out."""
    data = cfg.model_dump()
    data.pop("schedule")
    data["trim"]["velocity_ned"] = [v, 0.0, 0.0]
    linear = pipeline.Stages(setup_of(config.from_dict(data, "frozen"))).linear
    G = interp1d(table.values, table.gains, kind=table.interpolation, axis=0)(v)
    keep = [i for i in range(12) if i not in (STATE_INDEX["pN"], STATE_INDEX["pE"])]
    return np.linalg.eigvals((linear.A - linear.B @ G)[np.ix_(keep, keep)])


def test_the_frozen_checks_name_where_an_interpolated_gain_destabilizes():
    """A hand-made table: the hover design at 0 m/s, the 10 m/s design with its sign flipped at
    10 m/s. Interpolated linearly, the gain fades through zero: stable near hover, unstable beyond.
    The checks flag exactly the fine values an independent computation finds unstable, with its
    eigenvalue."""
    cfg = with_schedule("forward", {"variable": "speed", "values": [0.0, 10.0]}, velocity_ned=[0.0, 0.0, 0.0])
    setup = setup_of(cfg)
    sched = schedule_of(setup)
    assert sched.passed  # the designed table is fine
    table = GainTable.of("speed", [0.0, 10.0], sched.table.gains * np.array([1.0, -1.0])[:, None, None], "linear")
    checks = frozen_checks(setup, table, (), 8, 0.0)
    np.testing.assert_allclose(checks.values, np.linspace(0, 10, 9), rtol=0, atol=1e-14)
    found = []
    for i, v in enumerate(checks.values):
        eig = _frozen_reference(cfg, table, v)
        worst = eig[np.argmax(eig.real)]
        found.append(bool(np.all(stability.is_stable(eig))))
        assert checks.slowest[i] == pytest.approx(worst.real, abs=1e-9)
        assert abs(checks.worst[i] - worst) < 1e-9 * max(1.0, abs(worst)) or abs(checks.worst[i] - worst.conj()) < 1e-9
    assert found == checks.stable.tolist()
    assert found[0] and not found[-1]  # the test sees both verdicts
    fails = frozen_failures(checks, "m/s")
    assert len(fails) == found.count(False)
    assert fails[-1].startswith("at 10 m/s: the interpolated gain's frozen loop is UNSTABLE (eigenvalue ")


@pytest.mark.parametrize("interpolation", ["nearest", "linear", "cubic"])
def test_the_frozen_loops_close_the_interpolated_gain(interpolation):
    """Between the points the check closes the table's gain, not a point's: each fine loop's
    eigenvalues against the independent reference."""
    cfg = with_schedule("forward", {"variable": "speed", "values": [0.0, 3.0, 5.0, 9.0], "check": 3,
                                    "interpolation": interpolation}, velocity_ned=[0.0, 0.0, 0.0])
    sched = schedule_of(setup_of(cfg))
    for i in (1, 4, 8):  # 1 m/s, 4 m/s, 7.67 m/s: between the points
        ref = _frozen_reference(cfg, sched.table, sched.checks.values[i])
        assert sched.checks.slowest[i] == pytest.approx(ref.real.max(), abs=1e-9)


def test_a_discrete_integrating_schedule_checks_its_sampled_loops(schedules):
    """mambo-200hz (lqrd at 200 Hz, an integrator on pD), scheduled on climb: each fine loop is the
    zero-order hold of the model trimmed there (SciPy's expm of the augmented matrix), closed by the
    interpolated ``[K, Ki]`` with the accumulator ``z <- z - Ts pD``; its eigenvalues as ``ln z / Ts``."""
    from scipy.linalg import expm

    cfg, sched = schedules["mambo climb"]
    Ts = 1 / 200
    assert sched.sample_time == Ts and sched.integral_states == ("pD",)
    for i in (1, 3, 6):  # between the points
        v = sched.checks.values[i]
        data = cfg.model_dump()
        data.pop("schedule")
        data["trim"]["velocity_ned"] = [1.0, 0.0, -v]  # the config's 1 m/s north kept
        linear = pipeline.Stages(setup_of(config.from_dict(data, "frozen"))).linear
        M = np.zeros((16, 16))
        M[:12, :12], M[:12, 12:] = linear.A, linear.B
        E = expm(M * Ts)
        Ad, Bd = E[:12, :12], E[:12, 12:]
        G = interp1d(sched.table.values, sched.table.gains, axis=0)(v)
        K, Ki = G[:, :12], G[:, 12:]
        loop = np.zeros((13, 13))
        loop[:12, :12], loop[:12, 12:] = Ad - Bd @ K, -Bd @ Ki
        loop[12, STATE_INDEX["pD"]], loop[12, 12] = -Ts, 1.0
        keep = [k for k in range(13) if k not in (STATE_INDEX["pN"], STATE_INDEX["pE"])]
        s = np.log(np.linalg.eigvals(loop[np.ix_(keep, keep)]).astype(complex)) / Ts
        assert sched.checks.slowest[i] == pytest.approx(s.real.max(), abs=1e-8)
        assert sched.checks.stable[i]


def test_a_design_with_the_rotors_lag_is_refused():
    data = config.load("mambo-200hz").model_dump()
    data["motors"]["time_constant"] = 0.02
    data["controller"]["rotor_lag"] = "include"
    data["schedule"] = {"variable": "speed", "values": [0.0, 1.0]}
    with pytest.raises(ScheduleError, match=r"^controller\.rotor_lag = include: a gain schedule tables the state and "
                                            r"integrator gains only; set controller\.rotor_lag: ignore"):
        schedule_of(setup_of(config.from_dict(data, "lag")))


def test_a_value_outside_the_motor_limits_says_why_and_the_envelope_is_the_rest():
    """Mambo rotors that cannot idle below 0.16 N: the thrust a faster trim needs falls under it."""
    data = config.load("mambo-200hz").model_dump()
    data["motors"]["min_thrust"] = 0.16
    data["schedule"] = {"variable": "speed", "values": [0.0, 1.0, 2.0, 3.0]}
    sched = schedule_of(setup_of(config.from_dict(data, "tight rotors")))
    assert [p.trimmed for p in sched.points] == [True, True, False, False]
    assert "motors.min_thrust = 0.16: the trim needs rotor 1 = 0.15" in sched.points[2].reason
    assert sched.envelope == (0.0, 1.0)
    np.testing.assert_allclose(sched.checks.values, np.linspace(0, 1, 5))
    assert all(np.all(p.actuator_commands >= 0.16) for p in sched.points if p.trimmed)


def test_the_envelope_figure_draws_the_rotor_limits_and_marks_the_values_with_no_trim():
    from quadctl import plots

    data = config.load("mambo-200hz").model_dump()
    data["motors"]["min_thrust"] = 0.16
    data["schedule"] = {"variable": "speed", "values": [0.0, 1.0, 2.0, 3.0]}
    setup = setup_of(config.from_dict(data, "tight rotors"))
    sched = schedule_of(setup)
    fig = plots.schedule_figure(sched, setup.actuators, title="tight")
    _, poles, attitude, thrust = fig.axes[:4]  # (then the damping axis, twin of the poles)
    rotor = thrust.get_lines()[0]
    np.testing.assert_allclose(rotor.get_ydata(), [p.actuator_commands[0] for p in sched.points[:2]])
    levels = {line.get_ydata()[0] for line in thrust.get_lines() if line.get_linestyle() == "-."}
    assert levels == {0.16, 0.33}
    marked = sorted(line.get_xdata()[0] for line in attitude.get_lines() if line.get_linestyle() == ":")
    assert marked == [2.0, 3.0]
    np.testing.assert_allclose(poles.get_lines()[0].get_ydata(), sched.checks.slowest)


def test_the_gain_legend_sits_narrow_beside_the_curves_and_tells_coincident_ones_apart():
    """The bundled `schedule` case: 10 nonzero gains, roll and pitch designed alike (K[A,phi] and
    K[E,theta] on one normalized curve), several constant gains on +1."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from quadctl import plots

    sched = schedule_of(setup_of(config.load("schedule")))
    fig = plots.schedule_figure(sched, title="schedule")
    FigureCanvasAgg(fig).draw()
    gains = fig.axes[0]
    legend, box = gains.get_legend(), gains.get_window_extent()
    beside = legend.get_window_extent()
    assert box.x1 <= beside.x0 and beside.x1 <= fig.axes[1].get_window_extent().x0  # between the two panels
    assert beside.width < 0.4 * box.width  # narrow: a long label breaks, the panels keep the figure's width
    curves = {line.get_label().split(" ")[0]: line for line in gains.get_lines() if line.get_label()[0] == "K"}
    assert len(curves) == 10
    dashes = {}  # input -> the dash patterns (offset, on-off sequence) of its entries' lines
    for name, line in curves.items():
        offset, sequence = line._unscaled_dash_pattern
        dashes.setdefault(name[2], set()).add((offset, tuple(sequence or ())))
    assert sorted(dashes) == ["A", "E", "R", "T"] and all(len(d) == 1 for d in dashes.values())
    assert len({d for ds in dashes.values() for d in ds}) == 4  # one pattern per input, no two alike
    roll, pitch = curves["K[A,phi]"], curves["K[E,theta]"]
    np.testing.assert_allclose(pitch.get_ydata(), roll.get_ydata(), atol=1e-3)  # one curve: two styles
    assert pitch.get_label().endswith(",\non K[A,phi]'s curve")
    assert not curves["K[A,v]"].get_label().endswith("curve")



def test_the_frozen_point_legend_covers_neither_curve_of_its_twin_axes():
    """The poles panel's legend names the slowest pole and, on the twin axis, the least damping: it keeps off
    both curves (matplotlib's "best" sees only the lines of the legend's own axes; the bundled schedule's
    damping curve ends in the lower right corner, where the legend sat)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from quadctl import plots

    sched = schedule_of(setup_of(config.load("schedule")))
    fig = plots.schedule_figure(sched, title="schedule")
    FigureCanvasAgg(fig).draw()
    poles, twin = fig.axes[1], fig.axes[-1]
    box = poles.get_legend().get_window_extent()
    for ax in (poles, twin):
        line = ax.get_lines()[0]
        points = line.get_transform().transform(line.get_xydata())
        assert not any(box.contains(x, y) for x, y in points), f"the legend covers {line.get_label()}"
    assert poles.get_ylim()[1] < 0.5  # the unseen copy of the damping curve leaves the poles' limits alone

def test_a_value_beyond_the_models_tilt_says_why():
    sched = schedule_of(setup_of(with_schedule("hover", {"variable": "speed", "values": [0.0, 1.0, 200.0]})))
    assert sched.envelope == (0.0, 1.0)
    assert "it needs pitch -81.4 deg, beyond the 80 deg" in sched.points[2].reason


@pytest.mark.parametrize(("schedule", "match"), [
    ({"variable": "speed", "values": [200.0, 300.0]},
     r"schedule\.values: 0 of 2 values trim and design, a schedule needs two \(at 200 m/s: no usable equilibrium .*"
     r"narrow schedule\.values to the envelope the vehicle can fly$"),
    ({"variable": "speed", "values": [1.0, 2.0]},
     r"schedule\.values: the config's own flight condition \(trim\.velocity_ned: speed 0 m/s\) is outside the "
     r"envelope that trims, \[1, 2\] m/s; list values around 0 m/s in schedule\.values, or change trim\.velocity_ned$"),
])
def test_a_schedule_that_cannot_be_made_is_refused(schedule, match):
    with pytest.raises(ScheduleError, match=match):
        schedule_of(setup_of(with_schedule("hover", schedule)))


def test_a_config_without_a_schedule_is_refused():
    with pytest.raises(ScheduleError, match=r"^schedule: missing; add a schedule section"):
        schedule_of(setup_of(config.load("hover")))


def test_the_artifacts_hold_the_table_and_the_checks(tmp_path, schedules):
    cfg, _ = schedules["mambo climb"]
    with Workspace(cfg, tmp_path) as ws:
        sched = ws.schedule
    data = json.loads((tmp_path / "schedule.json").read_text())
    assert (data["variable"], data["unit"], data["interpolation"], data["outside"]) == ("climb", "m/s", "linear",
                                                                                        OUTSIDE)
    assert data["artifact"] == "schedule" and data["design"] == "discrete" and data["integral_states"] == ["pD"]
    for p, point in zip(sched.points, data["points"]):
        assert point["value"] == p.value and point["designed"] and point["reason"] is None
        assert point["K"] == p.K.tolist() and point["Ki"] == p.Ki.tolist()
        assert point["state"]["theta"] == p.trim.x[STATE_INDEX["theta"]] and point["input"]["T"] == p.trim.u[0]
        assert point["x"] == p.trim.x.tolist() and len(point["actuator_commands"]) == 4
    assert data["checks"]["refinement"] == 4 and len(data["checks"]["values"]) == 9 and data["checks"]["passed"]
    with np.load(tmp_path / "schedule.npz", allow_pickle=False) as z:
        assert z["K"].shape == (3, 4, 12) and z["Ki"].shape == (3, 4, 1) and z["x_trim"].shape == (3, 12)
        np.testing.assert_array_equal(z["values"], [-1.0, 0.0, 1.5])
        # the table's piecewise cubic, evaluated by SciPy, is the linear interpolation of the points' gains
        v = np.linspace(-1.0, 1.5, 11)
        pp = PPoly(z["coefficients"], z["breaks"])
        np.testing.assert_allclose(pp(v), interp1d(z["values"], z["gains"], axis=0)(v), rtol=0, atol=1e-12)
        assert z["fine_eigenvalues"].shape == (9, 13) and z["fine_stable"].all()
        np.testing.assert_allclose(z["fine_values"], fine_values(z["values"], 4))


def write(tmp_path, schedule: str, base: str = "hover") -> str:
    path = tmp_path / "c.yaml"
    path.write_text(config.bundled(base).text + schedule)
    return str(path)


def test_the_command_prints_the_points_and_writes_the_artifacts(tmp_path):
    res = runner.invoke(app, ["schedule", "-c", "schedule", "-o", str(tmp_path), "--plot"])
    assert res.exit_code == 0, res.output
    assert "Gain schedule over speed (11 values, linear interpolation)" in res.stdout
    assert "Envelope: speed 0 to 10 m/s (11 of 11 values trim and design)" in res.stdout
    assert "Frozen-point checks: the interpolated gains are stable at all 41 values" in res.stdout
    assert (tmp_path / "schedule.json").is_file() and (tmp_path / "schedule.npz").is_file()
    assert (tmp_path / "plots" / "schedule.png").stat().st_size > 10_000


def test_the_command_fails_a_schedule_whose_design_or_check_is_unstable(tmp_path):
    """The report's weights lose the coupled loop beyond 20 m/s."""
    res = runner.invoke(app, ["schedule", "-c", write(tmp_path, "schedule: {variable: speed, values: [0, 22]}\n"),
                              "-o", str(tmp_path / "out")])
    assert res.exit_code == 1, res.output
    assert res.stderr.startswith("quadctl: check failed: the design at 22 m/s is UNSTABLE on the coupled model; ")
    assert "frozen-point checks fail: " in res.stderr
    failing = res.stdout[res.stdout.index("Frozen-point checks that fail"):]
    assert "UNSTABLE" in failing and "right half-plane" in failing


def test_a_value_with_no_trim_exits_2_naming_the_values_and_the_fix_after_writing_the_envelope(tmp_path):
    res = runner.invoke(app, ["schedule", "-c", write(tmp_path, "schedule: {variable: speed, values: [0, 1, 200]}\n"),
                              "-o", str(tmp_path / "out"), "--plot"])
    assert res.exit_code == 2, res.output
    assert res.stderr.startswith(f"quadctl: error: {tmp_path / 'c.yaml'}: schedule.values: 1 of 3 values has no "
                                 "trim or design (200 m/s; the first: no usable equilibrium")
    assert res.stderr.rstrip().endswith("the envelope is [0, 1] m/s: narrow schedule.values to it")
    assert len(res.stderr.strip().splitlines()) == 1
    saved = json.loads((tmp_path / "out" / "schedule.json").read_text())  # nothing lost: the points and why
    assert [p["designed"] for p in saved["points"]] == [True, True, False]
    assert (tmp_path / "out" / "plots" / "schedule.png").is_file()


def test_export_refuses_a_table_that_leaves_values_out(tmp_path):
    """A value with no trim (200 m/s): the table would hold 0 and 1 m/s only, so export writes nothing
    and exits 2 as `quadctl schedule` does (it exported the smaller table silently)."""
    out = tmp_path / "out"
    res = runner.invoke(app, ["export", "--to", "json", "-c", write(tmp_path, "schedule: {variable: speed, values: "
                              "[0, 1, 200]}\n"), "-o", str(out)])
    assert res.exit_code == 2, res.output
    assert res.stderr.startswith(f"quadctl: error: {tmp_path / 'c.yaml'}: schedule.values: 1 of 3 values has no "
                                 "trim or design (200 m/s")
    assert res.stderr.rstrip().endswith("the envelope is [0, 1] m/s: narrow schedule.values to it")
    assert not (out / "quadctl_controller.json").exists()


@pytest.mark.parametrize("command", ["simulate", "run"])
def test_flying_a_schedule_that_fails_its_checks_warns(tmp_path, command):
    """`quadctl schedule` exits 1 on a design unstable at 22 m/s and warns of a value with no trim;
    `simulate` and `run`, which fly the same table, said nothing of either."""
    path = write(tmp_path, "schedule: {variable: speed, values: [0, 22, 200]}\n")
    res = runner.invoke(app, [command, "-c", path, "-o", str(tmp_path / "out"), "--set", "simulation.duration=0.05"])
    assert res.exit_code == 0, res.output
    warnings = [line for line in res.stderr.splitlines() if line.startswith("quadctl: warning: schedule")]
    assert len(warnings) == 2, res.stderr
    assert warnings[0].startswith("quadctl: warning: schedule.values: 1 of 3 values has no trim or design (200 m/s")
    assert warnings[1].startswith("quadctl: warning: schedule: the gains flown fail their checks (the design at "
                                  "22 m/s is UNSTABLE; at 22 m/s: the interpolated gain's frozen loop is UNSTABLE")
    assert warnings[1].endswith("`quadctl schedule` lists them: narrow schedule.values to where they pass, "
                                "or change the weights")


@pytest.mark.parametrize(("schedule", "pattern"), [
    ("", r"c\.yaml: schedule: missing; add a schedule section"),
    ("schedule: {variable: speed, values: [150, 200]}\n",
     r"c\.yaml: schedule\.values: 0 of 2 values trim and design.*narrow schedule\.values"),
    ("schedule: {variable: climb, values: [0.5, 1]}\n",
     r"c\.yaml: schedule\.values: the config's own flight condition \(trim\.velocity_ned: climb 0 m/s\) is outside"),
    ("schedule: {variable: roll, values: [0, 1]}\n", r"c\.yaml: schedule\.variable"),
    ("schedule: {variable: Speed, values: [0, 1]}\n",
     r'c\.yaml: schedule\.variable = "Speed": must be one of speed, climb, yaw; did you mean `speed`\?$'),
    ("schedule: {values: [0, 1]}\n",
     r"c\.yaml: schedule\.variable: required key is missing; add it: speed, climb or yaw \(speed: m/s along"),
    ("schedule: {variable: speed, values: [0, 5, 3]}\n",
     r"c\.yaml: schedule\.values\[2\] = 3: not above values\[1\] = 5; list the values increasing, each once$"),
    ("schedule: {variable: speed, values: [3]}\n",
     r"c\.yaml: schedule\.values = \[3\]: must be a list of 2 to \d+ items \(the scheduling values to trim and design "
     r"at, in increasing order, in the variable's unit\)$"),
    ("schedule: {variable: speed, values: [0, 1], interpolation: linaer}\n",
     r'c\.yaml: schedule\.interpolation = "linaer": must be one of nearest, linear, cubic; did you mean `linear`\?$'),
])
def test_bad_schedules_are_one_line_with_exit_2(tmp_path, schedule, pattern):
    res = runner.invoke(app, ["schedule", "-c", write(tmp_path, schedule), "-o", str(tmp_path / "out")])
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("quadctl: error: "), res.stderr
    import re

    assert re.search(pattern, lines[0]), lines[0]


def test_help_reads_well():
    res = runner.invoke(app, ["schedule", "--help"])
    assert res.exit_code == 0
    assert "Trim and design at each value of the config's schedule" in res.stdout and "--plot" in res.stdout


@pytest.mark.parametrize(("variable", "trim", "expected"), [
    ("speed", {"velocity_ned": [3.0, 4.0, -0.5], "yaw": 2.0}, 5.0),  # along its own horizontal direction
    ("climb", {"velocity_ned": [3.0, 4.0, -0.5], "yaw": 2.0}, 0.5),  # up positive
    ("yaw", {"velocity_ned": [0.0, 0.0, 0.0], "yaw": -1.2}, -1.2),
])
def test_the_configs_own_value_of_the_variable(variable, trim, expected):
    setup = setup_of(with_schedule("forward", {"variable": variable, "values": [0.0, 1.0]}, **trim))
    assert own_value(setup, heading_of(setup)) == pytest.approx(expected, abs=1e-12)


def test_the_report_s_schedule_table_has_a_markdown_rule_cell_per_column(schedules):
    """report.md's gain schedule table had 11 cells in its |---| rule under 10 headers, which GitHub's
    Markdown does not read as a table; a value with no trim keeps the count too."""
    from quadctl.present.schedule import points_table
    from quadctl.report.document import _md_block

    _, sched = schedules["forward speed"]
    table = points_table(sched)
    assert len(table.alignment()) == len(table.columns) == len(table.rows[0])
    header, rule = _md_block(table).splitlines()[2:4]
    assert header.count(" | ") + 1 == rule.strip("|").count("|") + 1 == len(table.columns)
    refused = with_schedule("forward", {"variable": "speed", "values": [0.0, 1.0, 300.0]})  # 300 m/s: no trim
    assert {len(row) for row in points_table(schedule_of(setup_of(refused))).rows} == {len(table.columns)}
