"""A transition across the envelope: hover to 20 m/s and back.

The bundled crazyflie-speed-schedule config: a Crazyflie commanded from hover to 20 m/s in 2 m/s
steps and back, flown with its speed schedule and with the hover design alone. The schedule flies
the whole transition; the hover design loses damping with speed, reaches its rotors' limits and
pitches past 85 deg near 18 m/s.

Run from a clone: ``python examples/speed_schedule_transition.py [FOLDER]`` writes
speed-schedule-transition.png into FOLDER (default: docs/figures/) and prints both runs' summaries.
"""

import sys
from pathlib import Path

import quadctl as qc
from quadctl import plots
from quadctl.present.schedule import transition_lines
from quadctl.schedule.transition import fly_transition

OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "docs" / "figures"

result = fly_transition(qc.setup_of(qc.load_config("crazyflie-speed-schedule")))
print("\n".join(transition_lines(result.summary)))
print("fixed:", result.fixed.message)

fig = plots.transition_figure(result, title="crazyflie-speed-schedule")
OUT.mkdir(parents=True, exist_ok=True)
fig.savefig(OUT / "speed-schedule-transition.png", dpi=80)
print(f"wrote {OUT / 'speed-schedule-transition.png'}")
