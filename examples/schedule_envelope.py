"""A gain schedule's envelope: the bundled schedule.

The bundled schedule config: LQR designs at 11 speeds from hover to 10 m/s, interpolated between
them; the gains, the frozen-point closed-loop poles on a grid finer than the schedule's, the trim
attitude and the rotor thrust against speed.

Run from a clone: ``python examples/schedule_envelope.py [FOLDER]`` writes schedule-envelope.png into
FOLDER (default: docs/figures/) and prints the envelope and the frozen-point checks.
"""

import sys
from pathlib import Path

import numpy as np

import quadctl as qc
from quadctl import plots
from quadctl.schedule.envelope import schedule_of

OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "docs" / "figures"

setup = qc.setup_of(qc.load_config("schedule"))
schedule = schedule_of(setup)
print(f"schedule: envelope {schedule.envelope} m/s, frozen-point checks passed {schedule.checks.passed}, "
      f"least damping {np.nanmin(schedule.checks.least_damping):.3g}")

fig = plots.schedule_figure(schedule, setup.actuators, title="schedule")
fig.set_size_inches(9.2, 7.0)  # 736 pixels at 80 dpi: the pages' width, so it shows unscaled and its legend reads
OUT.mkdir(parents=True, exist_ok=True)
fig.savefig(OUT / "schedule-envelope.png", dpi=80)
print(f"wrote {OUT / 'schedule-envelope.png'}")
