"""A waypoint mission: the bundled square.

The bundled square config: four waypoints joined by minimum-snap legs, flown by the LQR design with
the differential-flatness feedforward; the path in the horizontal plane with each waypoint's
tolerance and the time it was reached, and the altitude.

Run from a clone: ``python examples/square_mission.py [FOLDER]`` writes square-mission.png into FOLDER
(default: docs/figures/) and prints when each waypoint was reached and the tracking error.
"""

import sys
from pathlib import Path

import quadctl as qc
from quadctl import pipeline, plots, run_summary

OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "docs" / "figures"

stages = qc.Stages(qc.setup_of(qc.load_config("square")))
sim = pipeline.simulation_of(stages.setup, stages.loop)
summary = run_summary.tracking_summary(stages.setup, sim)
error = summary["position_error"]
print("square: reached " + ", ".join(f"{w['reached']:.3f} s" for w in summary["waypoints"])
      + f"; tracking error rms {error['rms']:.3g} m, peak {error['peak']:.3g} m")

fig = plots.path_figure(sim, [w["position"] for w in summary["waypoints"]],
                        reached=[w["reached"] for w in summary["waypoints"]], tolerance=summary["tolerance"],
                        title="square")
OUT.mkdir(parents=True, exist_ok=True)
fig.savefig(OUT / "square-mission.png", dpi=80)
print(f"wrote {OUT / 'square-mission.png'}")
