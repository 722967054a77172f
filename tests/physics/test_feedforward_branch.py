"""The flatness feedforward flies the physical branch: positive thrust, roll and pitch continuous along
the path, equal to an independent Newton solve of the force balance (written here from the model's
equations, continued from hover), and a one-line refusal where no attitude within the model's valid
range flies the reference.

The balance: along a path of earth-frame velocity ``v`` and acceleration ``a`` at heading ``psi``,
``m a = R_b^E (F_T + F_A) + m g e_3`` with ``F_T = [0, 0, -T]`` and the rotor drag
``F_A = -T Kc R_E^b v`` (the body rate drops out of the earth-frame balance).
"""

from __future__ import annotations

import numpy as np
import pytest

from quadctl.errors import TrimError
from quadctl.physics import trajectory
from quadctl.physics.flatness import feedforward
from quadctl.physics.model import MAX_TILT, Vehicle

VEHICLE = Vehicle()  # the report's vehicle: the bundled forward and schedule configs fly it
AGREE = 1e-9
"""rad and N: the feedforward against the independent solve. Both are Newton roots of the same
balance to 1e-12 m/s^2; the Jacobian's condition (below 1e3 on these paths) keeps the roots within
1e-9 of each other."""


def _rotation(phi, theta, psi) -> np.ndarray:
    """R_E^b = R(phi) R(theta) R(psi), the elementary rotations of the report."""
    c, s = np.cos, np.sin
    R1 = np.array([[1, 0, 0], [0, c(phi), s(phi)], [0, -s(phi), c(phi)]])
    R2 = np.array([[c(theta), 0, -s(theta)], [0, 1, 0], [s(theta), 0, c(theta)]])
    R3 = np.array([[c(psi), s(psi), 0], [-s(psi), c(psi), 0], [0, 0, 1]])
    return R1 @ R2 @ R3


def _balance(z, v, a, psi) -> np.ndarray:
    """Earth-frame acceleration of attitude and thrust ``z = [phi, theta, T]`` less the one asked."""
    m, g, Kc = VEHICLE.mass, VEHICLE.gravity, np.diag(VEHICLE.drag)
    R = _rotation(z[0], z[1], psi)
    force = np.array([0.0, 0.0, -z[2]]) - z[2] * Kc @ (R @ v) + R @ np.array([0.0, 0.0, m * g])
    return R.T @ force / m - a


def _independent(v, a, psi) -> np.ndarray:
    """``[phi, theta, T]`` by Newton (central-difference Jacobian) continued from hover, the flight
    condition scaled from zero to ``(v, a)`` in twenty steps: the root hover's branch reaches."""
    z = np.array([0.0, 0.0, VEHICLE.mass * VEHICLE.gravity])
    for lam in np.linspace(0.05, 1.0, 20):
        for _ in range(30):
            G = _balance(z, lam * v, lam * a, psi)
            if np.abs(G).max() < 1e-13:
                break
            J = np.column_stack([(_balance(z + d, lam * v, lam * a, psi) - _balance(z - d, lam * v, lam * a, psi))
                                 / (2 * 1e-7) for d in np.eye(3) * 1e-7])
            z = z - np.linalg.solve(J, G)
        assert np.abs(_balance(z, lam * v, lam * a, psi)).max() < 1e-12 and z[2] > 0
    return z


def _fast_setpoints():
    """The report's vehicle stepped from 10 to 10.5 m/s north, then a turn to a 0.4 rad heading."""
    return trajectory.setpoint_reference([{"t": 0.0, "velocity": [10.0, 0.0, 0.0]},
                                          {"t": 0.2, "velocity": [10.5, 0.0, 0.0]},
                                          {"t": 0.4, "velocity": [9.0, 4.0, -0.5], "yaw": 0.4}],
                                         [0, 0, -1], [1.0, 0.0, 0.0], 0.0)


def _fast_leg():
    """A 9 m/s minimum-jerk leg of 12 m north-east and up (peak pitch about 70 deg), then a hold."""
    return trajectory.mission_reference([{"position": [10.0, 6.6, -2.0], "yaw": 0.6, "hold": 0.5}],
                                        [0, 0, -1], 0.0, 9.0, 0.05, "minimum-jerk")


@pytest.mark.parametrize("reference, times", [
    (_fast_setpoints, [0.0, 0.1, 0.205, 0.3, 0.45, 0.6]),
    (_fast_leg, np.linspace(0.0, 3.0, 31)),
], ids=["setpoints 10 to 10.5 m/s", "9 m/s leg"])
def test_the_feedforward_is_the_independent_solve_from_hover(reference, times):
    ref = reference()
    flat = ref.flat(times)
    x, u = feedforward(flat, VEHICLE.vector())
    want = np.array([_independent(v, a, psi) for v, a, psi in zip(flat.position[1], flat.position[2], flat.yaw[0])])
    got = np.column_stack([x[:, 6], x[:, 7], u[:, 0]])
    assert np.abs(got - want).max() < AGREE, np.abs(got - want).max()
    assert np.all(u[:, 0] > 0)
    np.testing.assert_array_equal(x[:, 8], flat.yaw[0])


def test_the_report_speed_step_flies_upright():
    """10.5 m/s on the report's vehicle: pitch -0.9386 rad with thrust +0.3942 N, not the inverted root
    (-2.2030 rad, -0.3942 N) that also balances."""
    x, u = feedforward(_fast_setpoints().flat([0.205]), VEHICLE.vector())
    assert x[0, 7] == pytest.approx(-0.93856, abs=1e-5) and u[0, 0] == pytest.approx(0.39421, abs=1e-5)
    inverted = np.array([0.0, -2.20303429, -0.394212])
    assert np.abs(_balance(inverted, np.array([10.5, 0, 0]), np.zeros(3), 0.0)).max() < 1e-6  # the other root


@pytest.mark.parametrize("reference", [_fast_setpoints, _fast_leg], ids=["setpoints", "9 m/s leg"])
def test_attitudes_are_continuous_along_the_rows(reference):
    """On the 5 ms rows, solved in any order (reversed here), roll and pitch move between rows by no
    more than their rates allow (away from a setpoint's step), and the thrust stays positive."""
    ref = reference()
    t = np.arange(0.0, 3.0, 0.005)
    x, u = feedforward(ref.flat(t[::-1]), VEHICLE.vector())
    x, u = x[::-1], u[::-1]
    assert np.all(u[:, 0] > 0) and np.abs(x[:, 6:8]).max() < MAX_TILT
    steps = np.abs(np.diff(x[:, 6:8], axis=0)).max(axis=1)
    jumps = np.searchsorted(t, ref.jumps) - 1 if ref.jumps else []
    smooth = np.delete(steps, jumps)
    assert smooth.max() < 0.005 * 1.01 * np.abs(x[:, 9:12]).max() + 1e-12, smooth.max()
    assert np.abs(steps).max() < 0.5  # a step of the reference moves the attitude, never by a turn


@pytest.mark.parametrize("waypoint, needs", [
    ([5.0, 0.0, -1.0], r"needs roll 0\.0 deg and pitch -8[0-9]\.\d deg \(a tilt of 8[0-9]\.\d deg\)"),
    ([0.0, 0.0, 5.0], r"needs a tilt of 90 deg or more \(no attitude with upward thrust flies it\)"),
], ids=["5 m north at 9 m/s", "6 m down at 9 m/s"])
def test_a_reference_no_attitude_flies_is_refused(waypoint, needs):
    ref = trajectory.mission_reference([{"position": waypoint}], [0, 0, -1], 0.0, 9.0, 0.05, "minimum-jerk")
    message = (r"^simulation\.reference: at t = [0-9.]+ s the reference asks an acceleration of \[[-0-9., e]+\] "
               r"m/s\^2 at velocity \[[-0-9., e]+\] m/s, which " + needs
               + r", beyond the 80 deg of roll or pitch the Euler-angle model supports; lower "
               r"simulation\.reference\.speed or space the waypoints further apart$")
    with pytest.raises(TrimError, match=message):
        feedforward(ref.flat(np.arange(0.0, ref.end, 0.005)), VEHICLE.vector())


def test_the_refusal_is_one_line_and_exit_2(tmp_path):
    import yaml
    from typer.testing import CliRunner

    from quadctl import config
    from quadctl.cli.app import app

    data = config.load("hover").model_dump(mode="json", exclude_none=True)
    data["simulation"].update(duration=1.0, reference={"speed": 9.0, "waypoints": [{"position": [5.0, 0.0, -1.0]}]})
    path = tmp_path / "leg.yaml"
    path.write_text(yaml.safe_dump(data))
    got = CliRunner().invoke(app, ["simulate", "--config", str(path), "--out", str(tmp_path / "run")])
    assert got.exit_code == 2, got.output
    lines = got.output.strip().splitlines()
    assert len(lines) == 1 and "the reference asks an acceleration of [24.3, 0, 0] m/s^2" in lines[0], got.output
    assert "Traceback" not in got.output


def test_a_references_rows_do_not_depend_on_how_they_are_tabulated():
    """The runners ask for a reference's rows in chunks of their own (a segment, a chunk of steps):
    each chunk's feedforward starts from hover, so its roots must not keep the trace of where Newton
    started. The rows' curvature, a difference of the model's rates over a 5 ms row, multiplies what
    is left of the force balance by 200: the same rows in one piece and in chunks of 7 agree to
    round-off (with the 1e-12 m/s^2 Newton accepts left in: 4e-10)."""
    from quadctl import config
    from quadctl.setup import setup_of

    flown = setup_of(config.load("square")).flown_reference
    j = np.arange(3000)
    whole = flown.rows(j, 0.005)
    chunked = np.vstack([flown.rows(j[k:k + 7], 0.005) for k in range(0, len(j), 7)])
    assert np.abs(chunked - whole).max() < 1e-11, np.abs(chunked - whole).max()


def _square_at(speed):
    """The bundled square mission flown at ``speed`` m/s (its own feedforward model)."""
    from quadctl import config
    from quadctl.config import overrides
    from quadctl.setup import setup_of

    return setup_of(overrides.load(config.bundled("square"), [f"simulation.reference.speed={speed}"])).flown_reference


def _lockstep_cases():
    """(reference, rows, period): missions and setpoints at several speeds, clocks, lengths and vehicles,
    with refusals of both kinds (a point lost to the continuation, the steepest point beyond the
    model's tilt) among them."""
    from quadctl.physics.reference_rows import FlownReference

    heavy = Vehicle(mass=0.09, drag=(0.3, 0.25, 0.05)).vector()
    refused = [FlownReference(trajectory.mission_reference([{"position": p}], [0, 0, -1], 0.0, 9.0, 0.05,
                                                          "minimum-jerk"), VEHICLE.vector())
               for p in ([0.0, 0.0, 5.0], [5.0, 0.0, -1.0], [1.0, 0.0, 4.0], [0.0, 0.0, 3.0])]
    # down at 9 m/s: lost in the first block, each its own way; 5 m north: beyond 80 deg
    return [(_square_at(2.0), np.arange(3000), 0.005),
            (refused[0], np.arange(500), 0.005),
            (_square_at(2.9), np.arange(40, 700), 0.01),
            (FlownReference(_fast_leg(), heavy), np.arange(650), 0.005),
            (refused[1], np.arange(500), 0.005),
            (refused[2], np.arange(400), 0.005),
            (FlownReference(_fast_setpoints(), VEHICLE.vector()), np.arange(130), 0.005),
            (refused[3], np.arange(300), 0.005),
            (FlownReference(_fast_leg(), VEHICLE.vector()), np.arange(0, 600, 3), 0.004)]


def test_references_tabulated_together_are_each_ones_own_rows_to_the_bit():
    """A sweep chunk solves its cases' feedforward in lockstep (block b of every path in one Newton
    continuation, each row from its own path's start root): each point's Newton is its own (its
    iterations, its 3 x 3 solve, the compiled map a point at a time), so every reference's rows are
    those it has alone, bit for bit, and a refused one is refused alone, with its own message."""
    from quadctl.physics.reference_rows import FlownReference

    cases = _lockstep_cases()
    together = FlownReference.rows_of(*zip(*cases))
    refused = 0
    for (ref, j, period), got in zip(cases, together):
        try:
            alone = ref.rows(j, period)
        except TrimError as exc:
            assert isinstance(got, TrimError) and str(got) == str(exc), (got, exc)
            refused += 1
            continue
        assert isinstance(got, np.ndarray) and np.array_equal(got, alone), \
            f"Max diff is {np.abs(got - alone).max():.4E}"
    assert refused == 4


def test_paths_solved_together_are_each_ones_own_feedforward_to_the_bit():
    """:func:`feedforward_of` on paths of any length and time order (one reversed), with their own
    vehicles: each path's state and input are its :func:`feedforward` alone, bit for bit."""
    from quadctl.physics.flatness import feedforward_of

    t = np.arange(0.0, 2.5, 0.005)
    heavy = Vehicle(mass=0.09).vector()
    paths = [_fast_leg().flat(t[::-1]), _fast_setpoints().flat(t[:97]), _fast_leg().flat(t[5:300])]
    params = [VEHICLE.vector(), heavy, heavy]
    for path, p, got in zip(paths, params, feedforward_of(paths, params)):
        for mine, alone in zip(got, feedforward(path, p)):
            assert np.array_equal(mine, alone), f"Max diff is {np.abs(mine - alone).max():.4E}"


def test_a_row_whose_jacobian_is_singular_or_not_finite_fails_alone():
    """Newton's step of each row is its own 3 x 3 solve, in the compiled point: where the Jacobian is
    singular (no thrust at rest: roll and pitch move no force) or not finite, that row's step is not
    finite (it leaves the branch and the continuation retries it); the other rows' steps solve their
    own Jacobian, here by central differences of G."""
    from quadctl.native.mapped import mapped
    from quadctl.physics.flatness import _functions

    balance = mapped(_functions()[0])
    p = VEHICLE.vector()
    rng = np.random.default_rng(3)
    z = np.column_stack([rng.uniform(-0.3, 0.3, (5, 2)), rng.uniform(0.2, 0.5, 5)])
    s = np.column_stack([rng.normal(size=(5, 3)), rng.uniform(-1.0, 1.0, 5), rng.normal(size=(5, 3))])
    z[1], s[1, :3] = 0.0, 0.0  # no thrust, at rest: G does not depend on roll and pitch
    s[3, 0] = np.inf
    G, step = balance(z, s, p)
    assert not np.isfinite(step[1]).all() and not np.isfinite(step[3]).all()
    h = 1e-6
    for k in (0, 2, 4):
        J = np.column_stack([(balance(z[k] + h * e, s[k], p)[0][0] - balance(z[k] - h * e, s[k], p)[0][0]) / (2 * h)
                             for e in np.eye(3)])
        assert np.isfinite(step[k]).all()
        assert np.allclose(J @ step[k], -G[k], rtol=0, atol=1e-7 * (1 + np.abs(J).max() * np.abs(step[k]).max()))
