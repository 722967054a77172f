"""The gain schedule's table: its interpolation against SciPy's, its ends held, the scheduling variables."""

import casadi as ca
import numpy as np
import pytest
from scipy.interpolate import interp1d

from quadctl.design.gain_table import INTERPOLATIONS, GainTable, scheduling_value
from quadctl.layout import STATE_NAMES

VALUES = np.array([0.0, 1.0, 2.5, 4.0, 5.0])
GAINS = np.random.default_rng(3).normal(size=(5, 4, 14))


@pytest.mark.parametrize("kind", INTERPOLATIONS)
def test_table_interpolates_as_scipy_interp1d(kind):
    table = GainTable.of("speed", VALUES, GAINS, kind)
    v = np.linspace(0.0, 5.0, 203)
    np.testing.assert_allclose(table.at(v), interp1d(VALUES, GAINS, kind=kind, axis=0)(v), rtol=0, atol=1e-13)
    np.testing.assert_array_equal(table.at(VALUES[2]), GAINS[2])


@pytest.mark.parametrize("kind", INTERPOLATIONS)
def test_table_holds_the_end_gains_outside_the_grid(kind):
    table = GainTable.of("climb", VALUES, GAINS, kind)
    np.testing.assert_allclose(table.at([-3.0, 9.0]), GAINS[[0, -1]], rtol=0, atol=1e-13)


def test_cubic_of_two_and_three_points_is_the_line_and_the_parabola():
    v = np.array([0.0, 1.0, 3.0])
    g = (1 + 2 * v - 0.5 * v**2)[:, None, None] * np.ones((1, 4, 12))
    assert abs(GainTable.of("yaw", v, g, "cubic").at(2.0)[0, 0] - (1 + 4 - 2)) < 1e-12
    assert abs(GainTable.of("yaw", v[:2], g[:2], "cubic").at(0.25)[0, 0] - (1 + 0.25 * 1.5)) < 1e-12


@pytest.mark.parametrize(("values", "gains", "match"), [
    ([0.0], GAINS[:1], "at least two"),
    ([0.0, 2.0, 1.0], GAINS[:3], "increase strictly"),
    ([0.0, 1.0], GAINS[:3], r"\(2, 4, m\)"),
])
def test_table_refuses_a_bad_grid(values, gains, match):
    with pytest.raises(ValueError, match=match):
        GainTable.of("speed", values, gains)


def _state(**values):
    x = np.zeros(12)
    for name, value in values.items():
        x[STATE_NAMES.index(name)] = value
    return x


def test_speed_is_the_ground_velocity_along_the_heading():
    # level flight at body speed 3 m/s, nose at psi = 0.7: ground speed 3 along the nose
    x = _state(u=3.0, psi=0.7)
    assert scheduling_value("speed", x, 0.7) == pytest.approx(3.0, abs=1e-14)
    assert scheduling_value("speed", x, 0.2) == pytest.approx(3.0 * np.cos(0.5), abs=1e-14)
    assert scheduling_value("yaw", x, 0.0) == 0.7


def test_climb_is_up_positive():
    # nose up by theta, flying along the body x axis at 2 m/s: climbs at 2 sin(theta)
    x = _state(u=2.0, theta=0.3)
    assert scheduling_value("climb", x, 0.0) == pytest.approx(2 * np.sin(0.3), abs=1e-14)
    # rolled by phi, body w = 1 (down the body z axis): sinks at cos(phi)
    assert scheduling_value("climb", _state(w=1.0, phi=0.4), 0.0) == pytest.approx(-np.cos(0.4), abs=1e-14)


@pytest.mark.parametrize("variable", ["speed", "climb", "yaw"])
def test_symbolic_value_equals_the_numeric(variable):
    x = np.random.default_rng(1).normal(size=12)
    sym = ca.SX.sym("x", 12)
    f = ca.Function("f", [sym], [scheduling_value(variable, sym, 0.3, lib=ca)])
    assert float(f(x)) == pytest.approx(float(scheduling_value(variable, x, 0.3)), abs=1e-14)


def test_config_schedule_section_refuses_values_out_of_order():
    import yaml

    from quadctl.config import bundled, from_dict
    from quadctl.errors import ConfigError

    cfg = yaml.safe_load(bundled("hover").text)
    cfg["schedule"] = {"variable": "speed", "values": [0.0, 2.0, 1.0]}
    with pytest.raises(ConfigError, match=r"schedule.values\[2\] = 1: not above values\[1\] = 2"):
        from_dict(cfg)
