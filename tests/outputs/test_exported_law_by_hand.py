"""The exported C against the law written out by hand in NumPy, not generated from quadctl's loop.

``tests/outputs/test_export.py`` shows that the C is ``simulate``'s law to the last bit; both are
emitted from the same CasADi function, so a slip in that function would be in both. Here the law is
written again from its documented form (the header's THE LAW, docs/guide/export.md) with the numbers
of the JSON export (``K``, ``Ki``, ``x_trim``, ``x_rate``, ``u_trim``, ``Ts``) and a mixer built from
the config's rotor geometry, and the C must give its commands for states the test chooses: around the
drifting reference, past the yaw wrap, and far enough off that the rotors clip.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from _solve import cfg_dict
from test_export import FLOAT_INPUT_RTOL, Controller

from quadctl import config, export
from quadctl.export import data
from quadctl.layout import N_INPUTS, N_STATES, STATE_INDEX
from quadctl.setup import setup_of

DOUBLE_RTOL = 1e-12
"""Of the size of the terms each input is summed from: the C and NumPy add the same terms in other orders
(and the clip mixes through another inverse), a few ulps of double."""
ANTIWINDUP_TOL = 1e-10
"""The header's: in double an input counts as changed by saturation when it moves by more than this."""
SAMPLES = 60


def _mixer(motors: dict) -> np.ndarray:
    """``[T, A, E, R]' = M f`` for an x layout numbered as quadctl numbers it (docs/internals.md, "Rotors:
    mixing and saturation"): rotor 1 front right, then clockwise seen from above; 1 and 3 counter-clockwise."""
    d = motors["arm_length"] / math.sqrt(2.0)
    xy = [(d, d), (-d, d), (-d, -d), (d, -d)]
    spin = [1.0, -1.0, 1.0, -1.0]
    km = motors["torque_coefficient"]
    return np.array([[1.0] * 4, [-y for _, y in xy], [x for x, _ in xy], [s * km for s in spin]])


def _wrap(a: float) -> float:
    """``a`` into (-pi, pi]."""
    return a - 2.0 * math.pi * math.ceil((a - math.pi) / (2.0 * math.pi))


class HandLaw:
    """``u = sat(u_trim - K (x - x_ref(t)) - Ki z)``, ``x_ref(t) = x_trim + x_rate t``, ``t = k Ts``, the yaw
    error wrapped; ``sat``: mixed to the rotors, each clipped to its limits, mixed back; ``z <- z - Ts (x_i -
    x_ref_i(t))`` unless saturation changed an input that Ki drives."""

    def __init__(self, fields: dict, motors: dict):
        self.K, self.Ki = np.asarray(fields["K"]), np.asarray(fields["Ki"]).reshape(N_INPUTS, -1)
        self.x_trim, self.x_rate = np.asarray(fields["x_trim"]), np.asarray(fields["x_rate"])
        self.u_trim, self.Ts = np.asarray(fields["u_trim"]), float(fields["Ts"])
        self.integrated = [STATE_INDEX[s] for s in fields["integral_states"]]
        self.M = _mixer(motors)
        self.lo, self.hi = motors["min_thrust"], motors["max_thrust"]
        self.z, self.k = np.zeros(len(self.integrated)), 0

    def step(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """(u, the size of the terms it is summed from, whether a rotor clipped) at this sample; advances z
        and k."""
        x_ref = self.x_trim + self.x_rate * (self.k * self.Ts)
        e = x - x_ref
        e[STATE_INDEX["psi"]] = _wrap(e[STATE_INDEX["psi"]])
        u = self.u_trim - self.K @ e - self.Ki @ self.z
        terms = np.abs(self.u_trim) + np.abs(self.K) @ (np.abs(x) + np.abs(x_ref)) + np.abs(self.Ki) @ np.abs(self.z)
        f = np.linalg.solve(self.M, u)
        clipped = bool(np.any(f < self.lo) or np.any(f > self.hi))
        sat = self.M @ np.clip(f, self.lo, self.hi)
        terms = np.maximum(terms, np.abs(self.M) @ np.abs(f))  # mixed back from the rotor thrusts
        changed = np.abs(sat - u) > ANTIWINDUP_TOL
        if not np.any(changed[np.any(self.Ki != 0.0, axis=1)]):
            self.z = self.z - self.Ts * e[self.integrated]
        self.k += 1
        return sat, terms, clipped


def _exported(name: str, **changes):
    """(the export, its JSON fields as values, the config's motors) of a bundled config with ``changes``."""
    cfg_data = cfg_dict(name, **changes)
    cfg_data["motors"]["saturation"] = "clip"
    exp = export.prepare(setup_of(config.from_dict(cfg_data, f"{name}.yaml")))
    fields = {k: v["value"] for k, v in data.json_payload(exp)["fields"].items()}
    return exp, fields, cfg_data["motors"]


def _states(fields: dict, rng: np.random.Generator) -> list[np.ndarray]:
    """States about the drifting reference: small and large offsets (the large ones clip rotors), and yaw
    errors past +-pi (the wrap)."""
    scale = np.array([0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.2, 0.2, 0.3, 1.0, 1.0, 1.0])
    x_trim, x_rate, Ts = np.asarray(fields["x_trim"]), np.asarray(fields["x_rate"]), float(fields["Ts"])
    states = []
    for k in range(SAMPLES):
        x = x_trim + x_rate * (k * Ts) + rng.normal(size=N_STATES) * scale * (4.0 if k % 3 == 2 else 0.05)
        if k % 5 == 4:
            x[STATE_INDEX["psi"]] = (x_trim[STATE_INDEX["psi"]] + math.pi - 0.01) * (1 if k % 2 else -1) + 0.02
        states.append(x)
    return states


@pytest.mark.parametrize("name", ["mambo-200hz", "crazyflie"])  # altitude LQI, drifting at 1 m/s; no integrator
@pytest.mark.parametrize("single", [False, True], ids=["double", "float"])
@pytest.mark.parametrize("flags", [(), ("-ffast-math",)], ids=["ieee", "fast-math"])
def test_the_exported_c_applies_the_law_written_out_by_hand(name, single, flags, tmp_path):
    """Also built with -ffast-math, as flight code often is: the law has no NaN or infinity to keep, and its
    sums reassociated stay within the tolerances."""
    exp, fields, motors = _exported(name)
    hand, ctl = HandLaw(fields, motors), Controller(exp, tmp_path / name, single, flags)
    clipped, worst = 0, 0.0
    for x in _states(fields, np.random.default_rng(7)):
        c_u = ctl.step(x.astype(np.float32).astype(float) if single else x)
        want, terms, hit = hand.step(x)
        clipped += hit
        worst = max(worst, float((np.abs(c_u - want) / terms).max()))
    assert clipped >= SAMPLES // 4, f"only {clipped} of {SAMPLES} samples clipped a rotor"
    assert worst <= (FLOAT_INPUT_RTOL if single else DOUBLE_RTOL), \
        f"max |u_C - u_hand| = {worst:.3e} of the terms' size"
