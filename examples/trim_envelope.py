"""Trim across the flight envelope: pitch and thrust against speed.

The report's vehicle trimmed in level flight from hover to 12 m/s, flying north, north-east and
east: the pitch it holds and the thrust it needs (with the report's drag, the heading changes
neither). The trim at 1 m/s north is the report's.

Run from a clone: ``python examples/trim_envelope.py [FOLDER]`` writes trim-envelope.png into FOLDER
(default: docs/figures/) and prints the trim at 1 m/s north.
"""

import math
import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from quadctl.errors import TrimError
from quadctl.linear.trim import solve_trim
from quadctl.physics.model import Vehicle

OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "docs" / "figures"

vehicle = Vehicle()
speeds = np.linspace(0.0, 12.0, 49)
fig = Figure(figsize=(7, 5), layout="constrained")
ax_pitch, ax_thrust = fig.subplots(2, 1, sharex=True)
# the three headings trim alike (the drag is the same along x and y), so their curves coincide: a wide
# light line, a dashed one and a dotted one on top show all three
STYLES = {0: dict(lw=5.0, alpha=0.35), 45: dict(lw=2.0, ls="--"), 90: dict(lw=1.5, ls=":", color="black")}
for heading_deg in (0, 45, 90):
    psi = math.radians(heading_deg)
    tilt, thrust = [], []
    for s in speeds:
        try:
            t = solve_trim([s * math.cos(psi), s * math.sin(psi), 0.0], psi, [0, 0, -1], vehicle)
        except TrimError as exc:
            print(f"{s:.2f} m/s: {exc}")
            break
        tilt.append(math.degrees(t.x[7]))
        thrust.append(t.u[0])
    ax_pitch.plot(speeds[:len(tilt)], tilt, label=f"heading {heading_deg} deg, flying along it", **STYLES[heading_deg])
    ax_thrust.plot(speeds[:len(thrust)], thrust, **STYLES[heading_deg])
ax_pitch.set_ylabel("pitch theta [deg]")
ax_thrust.set_ylabel("thrust T [N]")
ax_thrust.set_xlabel("speed [m/s]")
ax_pitch.legend(frameon=False)
fig.suptitle("The report's vehicle in level flight: its trim against speed, alike at every heading", fontsize=11)
for ax in (ax_pitch, ax_thrust):
    ax.grid(alpha=0.3)
OUT.mkdir(parents=True, exist_ok=True)
fig.savefig(OUT / "trim-envelope.png", dpi=100)
print(f"wrote {OUT / 'trim-envelope.png'}")
t1 = solve_trim([1, 0, 0], 0.0, [0, 0, -1], vehicle)
print(f"1 m/s north: theta = {t1.x[7]:.4f} rad, T = {t1.u[0]:.4f} N (the report: -0.2119, 0.6522)")
