"""The state and input layout: names, units and index maps, declared once.

Every other module takes names, units and indices from here; no module hard-codes
a size or an index (docs/model.md, "States and inputs").
"""

from __future__ import annotations

STATE_NAMES: tuple[str, ...] = (
    "pN", "pE", "pD",
    "u", "v", "w",
    "phi", "theta", "psi",
    "p", "q", "r",
)
"""The 12 states: NED position, FRD body velocity, 3-2-1 Euler angles, body rates."""

INPUT_NAMES: tuple[str, ...] = ("T", "A", "E", "R")
"""The 4 inputs: thrust along body -z, and the body torques about x, y, z."""

STATE_UNITS: dict[str, str] = {
    "pN": "m", "pE": "m", "pD": "m",
    "u": "m/s", "v": "m/s", "w": "m/s",
    "phi": "rad", "theta": "rad", "psi": "rad",
    "p": "rad/s", "q": "rad/s", "r": "rad/s",
}
INPUT_UNITS: dict[str, str] = {"T": "N", "A": "N m", "E": "N m", "R": "N m"}

SENSOR_GROUPS: dict[str, tuple[str, ...]] = {
    "imu": ("phi", "theta", "psi", "p", "q", "r"),  # attitude (AHRS) and gyro rates
    "baro": ("pD",),                                # barometric altitude
    "mocap": ("pN", "pE", "pD"),                    # motion-capture position
    "gps": ("pN", "pE", "pD"),                      # satellite position
    "flow": ("u", "v"),                             # optical flow: horizontal body velocity
}
"""Sensor groups ``estimator.measure`` accepts, each the states it measures (a state name measures itself)."""

STATE_INDEX: dict[str, int] = {name: i for i, name in enumerate(STATE_NAMES)}
INPUT_INDEX: dict[str, int] = {name: i for i, name in enumerate(INPUT_NAMES)}

N_STATES = len(STATE_NAMES)
N_INPUTS = len(INPUT_NAMES)

def _block(first: str, size: int, names: tuple[str, ...]) -> slice:
    start = names.index(first)
    return slice(start, start + size)


POSITION = _block("pN", 3, STATE_NAMES)
"""``x[POSITION]``: pN, pE, pD (m)."""
VELOCITY = _block("u", 3, STATE_NAMES)
"""``x[VELOCITY]``: u, v, w (m/s, body frame)."""
ATTITUDE = _block("phi", 3, STATE_NAMES)
"""``x[ATTITUDE]``: phi, theta, psi (rad)."""
BODY_RATES = _block("p", 3, STATE_NAMES)
"""``x[BODY_RATES]``: p, q, r (rad/s)."""
THRUST = INPUT_NAMES.index("T")
"""``u[THRUST]``: T (N)."""
TORQUES = _block("A", 3, INPUT_NAMES)
"""``u[TORQUES]``: A, E, R (N m)."""

POSITION_STATES: tuple[str, ...] = ("pN", "pE", "pD")
"""States the dynamics never read (translation invariance): their columns of A are zero."""

PARAMETER_NAMES: tuple[str, ...] = ("mass", "gravity", "Jxx", "Jyy", "Jzz", "Kx", "Ky", "Kz", "Jxy", "Jxz", "Jyz")
"""Order of the vehicle parameter vector the CasADi model takes: the products of inertia (entries of
the tensor J, zero for a diagonal J) come last, so the first eight keep their places."""
MASS = PARAMETER_NAMES.index("mass")
GRAVITY = PARAMETER_NAMES.index("gravity")
INERTIA = _block("Jxx", 3, PARAMETER_NAMES)
DRAG = _block("Kx", 3, PARAMETER_NAMES)
PRODUCTS = _block("Jxy", 3, PARAMETER_NAMES)


def unit_of(name: str) -> str:
    """Unit of a state or input name (``"m"``, ``"N m"``, ...)."""
    return STATE_UNITS.get(name) or INPUT_UNITS[name]


REPORT_PARTITION: dict[str, dict] = {
    "altitude": {"states": ["pD", "w"], "inputs": ["T"], "regulate": True},
    "roll": {"states": ["v", "phi", "p"], "inputs": ["A"], "regulate": True},
    "pitch": {"states": ["u", "theta", "q"], "inputs": ["E"], "regulate": True},
    "yaw": {"states": ["psi", "r"], "inputs": ["R"], "regulate": True},
    "guidance": {"states": ["pN", "pE"], "inputs": ["u", "psi"], "regulate": False},
}
"""The report's five subsystems (docs/model.md, "Decoupling"); ``guidance`` takes states as inputs."""
