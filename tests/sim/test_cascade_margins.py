"""Margins of the PID cascade's loops against what they must equal.

The lifted loop (:mod:`quadctl.sim.cascade_lift`) must have the poles of the loop the simulation
flies: the eigenvalues of the Jacobian of one frame of the compiled law and RK4 plant, as sets. A
single-rate P loop on an integrator has phase, gain and disk margins in closed form; the same loop
written as a frame of three or four identical samples must keep them. A loop at one rate (a PD loop on a
double integrator, the Crazyflie's cascade with every loop at its rate) must have the margins
:func:`quadctl.design.margin_search.loop_margins` reads from its transfer function; on the multi-rate cascade
each margin's perturbation must put a pole of the lifted loop on the unit circle, and a little less not.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.optimize

from quadctl.design.broken_loops import broken_loop
from quadctl.design.margin_search import loop_margins
from quadctl.sim.cascade_lift import Lifted
from quadctl.sim.cascade_margins import exact_delay_margin, exact_gain_margins, loci_margins

J, KP, TS = 1.4e-5, 0.004, 0.002  # kg m^2 (a Crazyflie's roll inertia), N m s/rad, s (500 Hz): kp Ts / J = 0.57


ON_CIRCLE_TOL = 1e-9
"""A pole put on the unit circle by a margin's perturbation: the margins are refined to ~1e-12 (root finding,
bisection), each pole moves with the perturbation at a rate of order one; the stability test's own margin."""
SAME_LOOP_TOL = 1e-8
"""The loci's margins against :func:`loop_margins` on the same single-rate loop: both refined to ~1e-10 or better
(crossings by root finding to 1e-14, least values by bounded minimization to 1e-10 in log frequency, where the
value moves by its square)."""


def p_rate_loop(frame: int) -> Lifted:
    """``J w' = u``, ``u = -kp w`` sampled with a ZOH, written as ``frame`` identical samples."""
    plant = (np.array([[1.0]]), np.array([[TS / J, 0.0, 0.0, 0.0]]))
    law_state = [np.eye(1)] * frame
    command = np.zeros((4, 1))
    command[0, 0] = -KP
    rates = (np.zeros((1, 1)), np.array([[1 / J, 0.0, 0.0, 0.0]]))
    return Lifted(plant=plant, law_state=law_state, law_command=[command] * frame, sample_time=TS, plant_rates=rates)


def pd_attitude_loop(frame: int) -> Lifted:
    """``J theta'' = u``, ``u = -kp theta - kd theta'`` sampled with a ZOH (crossover near 60 rad/s), written as
    ``frame`` identical samples."""
    kp, kd = J * 60.0 ** 2, 2 * 0.7 * J * 60.0
    Ad = np.array([[1.0, TS], [0.0, 1.0]])
    Bd = np.zeros((2, 4))
    Bd[:, 0] = TS ** 2 / (2 * J), TS / J
    command = np.zeros((4, 2))
    command[0] = -kp, -kd
    B = np.zeros((2, 4))
    B[1, 0] = 1 / J
    return Lifted(plant=(Ad, Bd), law_state=[np.eye(2)] * frame, law_command=[command] * frame, sample_time=TS,
                  plant_rates=(np.array([[0.0, 1.0], [0.0, 0.0]]), B))


@pytest.mark.parametrize("frame", [1, 3, 4])
def test_the_characteristic_loci_of_a_sampled_p_rate_loop_have_its_closed_form_margins(frame):
    # L(z) = a / (z - 1): PM = 90 - asin(a / 2) deg at w Ts = 2 asin(a / 2), upper gain margin 2 / a at z = -1;
    # the balanced disk alpha = 2 |1 + L| / |1 - L| = 2 |z - 1 + a| / |z - 1 - a| is least at z = -1 (the ratio of
    # the distances to 1 - a and 1 + a grows with Re z on the circle): 2 (2 - a) / (2 + a), where |1 + L| = 1 - a/2
    a = KP * TS / J
    m = loci_margins(p_rate_loop(frame).broken(0))
    assert m.phase_margin_deg == pytest.approx(90 - math.degrees(math.asin(a / 2)), abs=1e-9)
    assert m.gain_crossover_freq == pytest.approx(2 * math.asin(a / 2) / TS, rel=1e-9)
    assert m.gain_margin_db == (-math.inf, pytest.approx(20 * math.log10(2 / a), abs=1e-9))
    assert m.phase_crossover_freqs[1] == pytest.approx(math.pi / TS, rel=1e-12)
    assert m.disk_alpha == pytest.approx(2 * (2 - a) / (2 + a), rel=1e-9)
    assert m.disk_freq == pytest.approx(math.pi / TS, rel=1e-4)  # a flat minimum: its place to sqrt of the value's
    assert m.min_return_difference == pytest.approx(1 - a / 2, rel=1e-9)


def held_late_roots(a: float, delay: float) -> np.ndarray:
    """Roots of ``z^(d+2) - z^(d+1) + a (1 - f) z + a f``: ``w(k+1) = w(k) - a ((1 - f) w(k-d) + f w(k-d-1))``, the
    P rate loop whose command reaches the plant ``delay = d + f`` samples late (the hold shifted: the command
    of ``d + 1`` samples ago for the first ``f`` of a sample, that of ``d`` ago for the rest)."""
    d = int(math.floor(delay))
    f = delay - d
    c = np.zeros(d + 3)
    c[0], c[1] = 1.0, -1.0
    c[d + 1] += a * (1 - f)
    c[d + 2] += a * f
    return np.roots(c)


@pytest.mark.parametrize("frame", [1, 3])
def test_the_delay_margin_of_a_p_rate_loop_is_where_its_recurrence_leaves_the_unit_circle(frame):
    a = KP * TS / J
    radius = lambda s: float(np.max(np.abs(held_late_roots(a, s)))) - 1  # noqa: E731
    grid = np.arange(0.0, 5.0, 1e-2)  # samples: the first root out, from the recurrence alone
    first = int(np.argmax([radius(s) >= 0 for s in grid]))
    want = scipy.optimize.brentq(radius, grid[first - 1], grid[first], xtol=1e-15)
    got = exact_delay_margin(p_rate_loop(frame), 0) / TS
    assert got == pytest.approx(want, rel=1e-9)


@pytest.mark.parametrize("frame", [1, 4])
def test_the_loci_of_a_pd_loop_at_one_rate_are_its_transfer_functions_margins(frame):
    """The independent reference: :func:`loop_margins` on ``L(z) = K (zI - Ad)^-1 Bd`` of the same loop."""
    lift = pd_attitude_loop(frame)
    want = loop_margins(broken_loop(lift.plant[0], lift.plant[1], -lift.law_command[0], 0, TS))
    got = loci_margins(lift.broken(0))
    assert want.stable and math.isfinite(want.phase_margin_deg)
    assert got.phase_margin_deg == pytest.approx(want.phase_margin_deg, abs=SAME_LOOP_TOL)
    assert got.gain_crossover_freq == pytest.approx(want.gain_crossover_freq, rel=SAME_LOOP_TOL)
    assert got.gain_margin_db == pytest.approx(want.gain_margin_db, abs=SAME_LOOP_TOL)
    assert got.disk_alpha == pytest.approx(want.disk_alpha, rel=SAME_LOOP_TOL)
    assert got.min_return_difference == pytest.approx(want.min_return_difference, rel=SAME_LOOP_TOL)


@pytest.mark.parametrize("frame", [1, 3])
def test_a_sampled_p_rate_loop_has_its_closed_form_margins(frame):
    # L(z) = a / (z - 1), a = kp Ts / J: |L| = 1 where 2 sin(w Ts / 2) = a, and there angle L = -(90 + w Ts / 2)
    # deg, so PM = 90 - asin(a / 2) (deg); L(-1) = -a / 2: upper gain margin 2 / a, no lower one.
    a = KP * TS / J
    loop = p_rate_loop(frame).broken(0)
    m = loop_margins(loop, grid=loop.grid(200))
    assert m.stable
    assert m.phase_margin_deg == pytest.approx(90 - math.degrees(math.asin(a / 2)), abs=1e-7)
    assert m.gain_crossover_freq == pytest.approx(2 * math.asin(a / 2) / TS, rel=1e-9)
    assert m.gain_margin_db[1] == pytest.approx(20 * math.log10(2 / a), abs=1e-7)
    lower, upper = exact_gain_margins(loop)  # from the lifted loop's poles: bisected to ~1e-12 in the gain
    assert upper == pytest.approx(20 * math.log10(2 / a), abs=1e-6) and lower == -math.inf


@pytest.fixture(scope="module")
def crazyflie_cascade():
    import quadctl as qc
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim.cascade_lift import lifted

    stages = qc.Stages(qc.setup_of(qc.load_config("crazyflie")))
    loop = pid_loop_of(stages.setup, stages.linear)
    return loop, lifted(loop)


def test_a_ctrl_c_during_the_cascades_linearization_is_taken_after_it(crazyflie_cascade, monkeypatch):
    """The lifted loop's trim evaluates the CasADi law from Python, step by step: a Ctrl-C that landed in one
    of those calls was swallowed by CasADi's argument conversion and `quadctl compare` ran on to exit 0.
    It is held until the linearization is done, then raised: the law's evaluations go on after it."""
    import signal

    from quadctl.sim import cascade_lift

    real = cascade_lift.evaluated
    calls, interrupt = [], []

    def evaluated(fn, *args):
        if interrupt and not calls:
            signal.raise_signal(signal.SIGINT)  # the Ctrl-C lands in the first evaluation
        calls.append(1)
        return real(fn, *args)

    monkeypatch.setattr(cascade_lift, "evaluated", evaluated)
    cascade_lift.lifted(crazyflie_cascade[0])
    whole, calls[:] = len(calls), []
    interrupt.append(1)
    with pytest.raises(KeyboardInterrupt):
        cascade_lift.lifted(crazyflie_cascade[0])
    assert len(calls) == whole > 1  # the trim's search and the frame's linearization ran whole


@pytest.fixture(scope="module")
def iris():
    """PX4's Iris (``quadctl init``'s iris preset), at hover."""
    import yaml

    import quadctl as qc
    from quadctl.config import Config
    from quadctl.config import template as starter

    return qc.Stages(qc.setup_of(Config(**yaml.safe_load(starter.config_text("iris-px4", "iris", "hover")))))


@pytest.fixture(scope="module")
def px4_cascade(iris):
    """PX4's cascade (its quaternion attitude stage, 400/200/100 Hz) on PX4's Iris."""
    from quadctl.config.pid import resolve
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim.cascade_lift import lifted

    loop = pid_loop_of(iris.setup, iris.linear, resolve("px4"))
    assert loop.law.attitude == "px4"
    return loop, lifted(loop)


def test_the_px4_cascade_on_the_iris_has_margins_on_every_input(px4_cascade, iris):
    """The lifted margins through the quaternion attitude stage: every input's loop stable, its upper gain
    margin exact (just inside stable, just outside not); and the lifted loop the Euler stage's with the
    same gains (about hover the quaternion error is the Euler error, the yaw's weighted and its gain
    divided by the weight: the same linearization, to the Jacobians' round-off)."""
    from quadctl.config.pid import resolve
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim.cascade_lift import lifted
    from quadctl.sim.cascade_margins import cascade_margins

    loop, lift = px4_cascade
    euler = lifted(pid_loop_of(iris.setup, iris.linear, resolve("px4", attitude="euler")))
    assert list(euler.states) == list(lift.states)
    gap = np.linalg.norm(lift.frame_map - euler.frame_map, 2)
    assert gap < 1e-10 * np.linalg.norm(lift.frame_map, 2), f"max diff {gap:.4E}"
    margins = cascade_margins(loop, lift=lift)
    assert [m.input for m in margins] == ["T", "A", "E", "R"]
    for j, m in enumerate(margins):
        assert m.stable, m
        upper = m.gain_margin_db[1]
        assert upper > 0
        if math.isfinite(upper):
            assert lift.broken(j).is_stable(10 ** (upper / 20) * (1 - 1e-6))
            assert not lift.broken(j).is_stable(10 ** (upper / 20) * (1 + 1e-6))


def simulated_frame_jacobian(loop, lift: Lifted, substeps: int = 8) -> np.ndarray:
    """d(X after one frame)/dX of the compiled loop's law and RK4 plant, at the lift's equilibrium."""
    import casadi as ca

    from quadctl.sim.builder import build

    spec = loop.spec()
    funcs = build(spec)
    c, e = loop.constants(lift.sample_time), np.zeros(spec.n_exo)
    X = ca.MX.sym("X", spec.nx)
    Y = X
    for _ in range(lift.frame):
        u, Y = funcs.law(Y, 0.0, c, e)
        for _ in range(substeps):
            Y = funcs.plant(Y, u, lift.sample_time / substeps, c, e)
    return np.asarray(ca.Function("frame", [X], [ca.jacobian(Y, X)])(lift.equilibrium))


@pytest.mark.parametrize("cascade", ["crazyflie_cascade", "px4_cascade"])
def test_the_lifted_cascade_has_the_poles_of_the_simulated_multirate_loop(cascade, request):
    loop, lift = request.getfixturevalue(cascade)
    assert lift.frame == loop.law.ratios[1] > 1  # a multi-rate loop: the outer loops held over the frame
    keep = lift.states
    J_sim = simulated_frame_jacobian(loop, lift)[np.ix_(keep, keep)]
    Phi = lift.frame_map
    # first-order perturbation theory: each eigenvalue moves at most its condition number 1/|y^H x| times the
    # size of the difference of the two maps (RK4 against expm: ~1e-11 here, the maps ~6e4); twice that, as sets
    got, right = np.linalg.eig(Phi)
    left = np.linalg.inv(right).conj().T
    kappa = np.linalg.norm(left, axis=0) * np.linalg.norm(right, axis=0) / np.abs(np.sum(left.conj() * right, axis=0))
    gap = np.linalg.norm(J_sim - Phi, 2)
    assert gap < 1e-6 * np.linalg.norm(Phi, 2)  # the maps themselves agree: the lifting is the simulated loop's
    want = np.linalg.eigvals(J_sim)
    for g, k in zip(got, kappa):
        i = int(np.argmin(np.abs(want - g)))
        diff = abs(want[i] - g)
        assert diff <= 2 * k * gap + 1e-12, f"pole {g} vs {want[i]}: diff {diff:.4E}, bound {2 * k * gap:.4E}"
        want = np.delete(want, i)
    assert max(abs(got)) < 1  # and the cascade holds hover


@pytest.fixture(scope="module")
def crazyflie_margins(crazyflie_cascade):
    from quadctl.sim.cascade_margins import cascade_margins

    loop, lift = crazyflie_cascade
    return cascade_margins(loop, lift=lift)


def test_cascade_margins_are_one_loop_per_input_with_exact_gain_margins(crazyflie_cascade, crazyflie_margins):
    loop, lift = crazyflie_cascade
    assert [m.input for m in crazyflie_margins] == ["T", "A", "E", "R"]
    for j, m in enumerate(crazyflie_margins):
        assert m.stable and m.model == "cascade"
        lower, upper = m.gain_margin_db
        broken = lift.broken(j)
        if math.isfinite(upper):  # just inside the margin stable, just outside not
            assert broken.is_stable(10 ** (upper / 20) * (1 - 1e-6))
            assert not broken.is_stable(10 ** (upper / 20) * (1 + 1e-6))


def nearest_to_circle(eigenvalues) -> float:
    return float(np.min(np.abs(np.abs(eigenvalues) - 1)))


@pytest.mark.parametrize("j", range(4))
def test_each_margin_of_the_multirate_cascade_puts_a_pole_on_the_unit_circle(crazyflie_cascade, crazyflie_margins, j):
    """The phase margin's complex gain ``e^(j PM)`` on every sample of the input, the loci's real gains, and the
    delay margin's late input each put a pole of the lifted loop on the unit circle; a little less keeps it
    stable. The loci's gain margins are :func:`exact_gain_margins`' (a scan of the lifted loop's poles)."""
    _, lift = crazyflie_cascade
    m, broken = crazyflie_margins[j], lift.broken(j)
    pm = math.radians(m.phase_margin_deg)
    for sign in (1, -1):  # the loci over (pi, 2 pi) are the conjugates: both phases destabilize
        assert nearest_to_circle(broken.closed_loop_eigenvalues(np.exp(1j * sign * pm))) < ON_CIRCLE_TOL
        assert broken.is_stable(np.exp(1j * sign * 0.99 * pm))
    loci = loci_margins(broken)
    for got, exact in zip(loci.gain_margin_db, m.gain_margin_db):
        if math.isfinite(got):  # the bisection stops within the stability test's 1e-9 of the circle
            assert nearest_to_circle(broken.closed_loop_eigenvalues(10 ** (got / 20))) < ON_CIRCLE_TOL
            assert got == pytest.approx(exact, abs=1e-4)
    assert nearest_to_circle(np.linalg.eigvals(lift.delayed_frame_map(j, m.delay_margin))) < ON_CIRCLE_TOL
    assert max(abs(np.linalg.eigvals(lift.delayed_frame_map(j, 0.99 * m.delay_margin)))) < 1


def test_the_loci_margins_do_not_depend_on_the_frequency_grid(crazyflie_cascade):
    _, lift = crazyflie_cascade
    broken = lift.broken(1)  # roll: thin margins near 90 Hz, folded by the 10 ms frame
    coarse, fine = loci_margins(broken, 10), loci_margins(broken, 60)
    for name in ("phase_margin_deg", "gain_crossover_freq", "disk_alpha", "min_return_difference"):
        assert getattr(coarse, name) == pytest.approx(getattr(fine, name), rel=1e-10), name
    assert coarse.gain_margin_db == pytest.approx(fine.gain_margin_db, abs=1e-10)


def test_the_cascade_at_one_rate_has_the_margins_of_its_transfer_function():
    """Every loop of the Crazyflie's cascade at its 500 Hz (a frame of one sample): the loci are the loop's
    transfer function ``L(z)``, whose margins :func:`loop_margins` reads."""
    import quadctl as qc
    from quadctl.config.pid import resolve
    from quadctl.pipeline import pid_loop_of
    from quadctl.sim.cascade_lift import lifted

    stages = qc.Stages(qc.setup_of(qc.load_config("crazyflie")))
    stock = resolve("crazyflie")
    one_rate = stock.with_values(attitude_hz=stock["rate_hz"], position_hz=stock["rate_hz"])
    lift = lifted(pid_loop_of(stages.setup, stages.linear, one_rate))
    assert lift.frame == 1
    for j in range(4):
        broken = lift.broken(j)
        want, got = loop_margins(broken, grid=broken.grid(200)), loci_margins(broken)
        assert want.stable
        assert got.phase_margin_deg == pytest.approx(want.phase_margin_deg, abs=SAME_LOOP_TOL)
        assert got.disk_alpha == pytest.approx(want.disk_alpha, rel=SAME_LOOP_TOL)
        assert got.min_return_difference == pytest.approx(want.min_return_difference, rel=SAME_LOOP_TOL)
        assert got.gain_margin_db == pytest.approx(want.gain_margin_db, abs=SAME_LOOP_TOL)


def test_margins_command_shows_the_cascade_that_flies_and_fails_its_thin_roll_loop(tmp_path):
    """controller.flies: pid: margins.json holds the cascade's four loops; the stock Crazyflie cascade's roll
    and pitch loops have less than 6 dB (MIL-F-9490D), which fails the check, naming the cascade's values."""
    import json

    from typer.testing import CliRunner

    from quadctl.cli.app import app

    res = CliRunner().invoke(app, ["margins", "-c", "crazyflie", "--set", "controller.flies=pid", "-o", str(tmp_path),
                                   "--plot"])
    assert res.exit_code == 1, res.output
    assert "lifted to its 10 ms frame" in res.output and "controller.pid.values" in res.output
    data = json.loads((tmp_path / "margins.json").read_text())
    assert data["law"] == "pid" and data["closed_loop"]["stable"] is True
    assert [loop["input"] for loop in data["loops"]] == ["T", "A", "E", "R"]
    # a figure per broken loop, none overwriting another, named as the report names them (the test below)
    figures = [tmp_path / "plots" / f"margins-crazyflie-{s}.png" for s in "TAER"]
    assert [line.split("figure -> ")[1] for line in res.output.splitlines() if "figure -> " in line] == [
        str(p) for p in figures]
    assert sorted((tmp_path / "plots").glob("margins-*.png")) == sorted(figures)


def test_an_unstable_cascade_names_each_loop_by_its_input(tmp_path):
    """Without the gyro low-pass the stock cascade is unstable (docs/guide/compare.md): the check said
    "unstable loop(s): crazyflie (cascade), crazyflie (cascade), crazyflie (cascade), crazyflie (cascade)",
    four loops alike; each is named by the input it is broken at, as the thin-margin sentence names them."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    res = CliRunner().invoke(app, ["margins", "-c", "crazyflie", "--set", "controller.flies=pid", "--set",
                                   "controller.pid.values.gyro_lpf_hz=0", "-o", str(tmp_path)])
    assert res.exit_code == 1, res.output
    assert ("unstable loop(s): crazyflie (cascade, T), crazyflie (cascade, A), crazyflie (cascade, E), "
            "crazyflie (cascade, R)") in " ".join(res.output.split())


def test_a_cascade_margins_figure_names_the_cascade_and_the_input_it_is_broken_at(crazyflie_margins):
    import dataclasses

    from quadctl.plots import margins_figure

    m = dataclasses.replace(crazyflie_margins[3], loop="crazyflie")  # as the stage names it: the preset's name
    title = margins_figure(m, title="mambo")._suptitle.get_text()
    assert title == ("mambo: crazyflie PID cascade broken at R (the rest of it closed; lifted, frequencies at its "
                     "2 ms sample)")


@pytest.mark.parametrize("j", [1, 3])
def test_a_cascade_margins_figure_draws_the_magnitude_about_the_crossover(crazyflie_margins, j):
    """The lifted roll and yaw loops reach hundreds of dB at the ends of the grid (integrators at the lowest
    frequency, zeros at Nyquist): the magnitude axis keeps 0 dB and every finite gain margin in view, within
    MAGNITUDE_SPAN_DB of 0 dB (10 dB beyond the farthest margin), not the grid's ends."""
    from quadctl.plots import margins_figure
    from quadctl.plots.frequency import MAGNITUDE_SPAN_DB

    m = crazyflie_margins[j]
    mag = 20 * np.log10(np.abs(m.response))
    assert mag.max() > 2 * MAGNITUDE_SPAN_DB or mag.min() < -2 * MAGNITUDE_SPAN_DB  # what the limits are for
    low, high = margins_figure(m).axes[0].get_ylim()
    finite = [abs(g) for g in m.gain_margin_db if math.isfinite(g)]
    span = max([MAGNITUDE_SPAN_DB] + [g + 10 for g in finite])
    assert -1.1 * span <= low < -max(finite) and max(finite) < high <= 1.1 * span, (low, high, m.gain_margin_db)


@pytest.mark.parametrize("j", [1, 3])
def test_a_cascade_margins_figure_draws_the_phase_about_minus_180(crazyflie_margins, j):
    """The lifted roll loop's phase runs down to -540 deg at the lowest frequency drawn (its integrators): the
    phase axis keeps -180 deg, the phase margin above it at the crossover and the phase at every phase crossover
    in view, within PHASE_SPAN_DEG of -180 deg, not the grid's ends."""
    from quadctl.plots import margins_figure
    from quadctl.plots.frequency import PHASE_SPAN_DEG

    m = crazyflie_margins[j]
    ax = margins_figure(m).axes[1]
    low, high = ax.get_ylim()
    w, phase = ax.get_lines()[0].get_xydata().T
    at = lambda f: phase[int(np.argmin(np.abs(np.log(w / f))))]  # noqa: E731
    seen = [at(m.gain_crossover_freq)] + [at(f) for f in m.phase_crossover_freqs if f is not None]
    assert seen[0] == pytest.approx(-180.0 + m.phase_margin_deg, abs=np.abs(np.diff(phase)).max())
    assert -180.0 - 1.1 * PHASE_SPAN_DEG <= low < min(seen + [-180.0]), (low, seen)
    assert max(seen + [-180.0]) < high <= -180.0 + 1.1 * PHASE_SPAN_DEG, (high, seen)
    if j == 1:
        assert phase.min() < -180.0 - 1.5 * PHASE_SPAN_DEG  # what the limits are for: -540 deg


@pytest.mark.parametrize("j", range(4))
def test_a_cascade_margins_figures_labels_cross_no_curve(crazyflie_margins, j):
    """Each margin's label (GM on the magnitude, PM on the phase) lies inside its panel and clear of the curve
    (the roll loop's GM +0.75 dB sits where |L| is a few dB above 0 just left of its crossover): the curve,
    sampled at 50 points a segment in the figure as drawn, has none inside a label's box."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from quadctl.plots import margins_figure

    fig = margins_figure(crazyflie_margins[j])
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    labels = [(ax, t) for ax in fig.axes[:2] for t in ax.texts if t.get_text()[:2] in ("GM", "PM")]
    assert sorted(t.get_text()[:2] for _, t in labels) == ["GM", "GM", "PM"]
    for ax, text in labels:
        box, frame = text.get_window_extent(renderer), ax.get_window_extent(renderer)
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
        curve = ax.get_lines()[0]
        xy = curve.get_transform().transform(curve.get_xydata())
        s = np.linspace(0.0, 1.0, 50)[:, None, None]
        dense = (xy[:-1] + s * (xy[1:] - xy[:-1])).reshape(-1, 2)
        dense = dense[np.isfinite(dense).all(axis=1)]
        inside = ((box.x0 <= dense[:, 0]) & (dense[:, 0] <= box.x1) & (box.y0 <= dense[:, 1]) & (dense[:, 1] <= box.y1))
        assert not inside.any(), (text.get_text(), dense[inside][:3], box)


def test_the_report_of_a_config_flying_the_cascade_shows_its_loops(tmp_path):
    from quadctl.cli.options import open_workspace
    from quadctl.report import content

    section = content.margins(open_workspace("crazyflie", tmp_path, sets=["controller.flies=pid"]))
    texts = [b.text for b in section.blocks if hasattr(b, "text")]
    assert any("lifted to its 10 ms frame" in t for t in texts)
    assert [b.name for b in section.blocks if hasattr(b, "png")] == [f"margins-crazyflie-{s}" for s in "TAER"]


def test_the_cascades_trim_takes_the_zero_nearest_its_start():
    """:func:`nearest_zero` on an affine residual with more unknowns than equations: the zero nearest the start,
    x0 - pinv(A) (A x0 - b), in closed form; on one the steps do not settle (no zero), the least-squares point."""
    from quadctl.sim.cascade_lift import nearest_zero

    rng = np.random.default_rng(3)
    A, b, x0 = rng.normal(size=(4, 6)), rng.normal(size=4), rng.normal(size=6)
    got = nearest_zero(lambda x: A @ x - b, lambda x: A, x0, scale=1.0)
    want = x0 - np.linalg.pinv(A) @ (A @ x0 - b)
    assert np.allclose(got, want, rtol=0, atol=1e-12 * np.linalg.cond(A))
    # x^2 + 1 has no zero: its least squares are at x = 0
    far = nearest_zero(lambda x: x ** 2 + 1.0, lambda x: np.diag(2 * x), np.array([3.0]), scale=1.0)
    assert abs(far[0]) < 1e-6
