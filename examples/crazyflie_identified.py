"""Identification from flight logs: the Crazyflie's thrust and torques.

Two Crazyflie flight logs of tests/data/crazyflie-flights (log10 from 35 to 65 s: climbs and drops;
log15 from 55 to 90 s: rolls and pitches) fitted against the bundled crazyflie config: measured and
predicted thrust and roll and pitch torques over time, and the residuals.

Run from a clone: ``python examples/crazyflie_identified.py [FOLDER]`` writes crazyflie-identified.png
into FOLDER (default: docs/figures/) and prints the identified values with their 95 % intervals.
"""

import sys
from pathlib import Path

import quadctl as qc
from quadctl.identify import readers, results
from quadctl.plots.identify import fit_figure
from quadctl.present.identify import sentences

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "figures"

flights = ROOT / "tests" / "data" / "crazyflie-flights"
logs = [readers.read_log(flights / name) for name in ("log10", "log15")]
ident = results.identify(logs, qc.load_config("crazyflie"), results.windows_per_log(["8.67:38.67", "15.755:50.755"], 2))
identified = results.payload(ident, "crazyflie")  # what identified.json holds
for stage in identified["stages"].values():
    for name, p in stage["parameters"].items():
        low, high = p["interval95"]
        print(f"{name} = {p['value']:.4g} {p['unit']} (95 %: {low:.4g} .. {high:.4g})")
print("\n".join(sentences(identified)))

OUT.mkdir(parents=True, exist_ok=True)
(OUT / "crazyflie-identified.png").write_bytes(fit_figure(ident))  # the PNG the run folder's plot is
print(f"wrote {OUT / 'crazyflie-identified.png'}")
