"""Uncertainty bands: one design flown on 64 perturbed vehicles.

The design that includes the rotors' 30 ms lag (docs/configs/mambo-rotor-lag-include.yaml), flown
on the 64 Monte Carlo vehicles of examples/uncertainty-sweep.yaml (mass, roll and pitch inertia,
delay and noise seed drawn): the 5-95 % bands of the altitude and roll states over time. The mass error
shows in the altitude band; the roll band stays a tenth of a degree wide.

Run from a clone: ``python examples/uncertainty_bands.py [FOLDER]`` writes uncertainty-bands.png into
FOLDER (default: docs/figures/) and prints how many cases pass and the roll band's width.
"""

import sys
from pathlib import Path

import numpy as np

import quadctl as qc
from quadctl import plots, sweep
from quadctl.sweep.outputs import montecarlo_bands
from quadctl.sweep.runner import base_of

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "figures"

cfg = qc.load_config(ROOT / "docs" / "configs" / "mambo-rotor-lag-include.yaml")
spec = sweep.load(ROOT / "examples" / "uncertainty-sweep.yaml", cfg)
result = sweep.run(cfg, spec, jobs=1)
duration = base_of(cfg, spec)["simulation"]["duration"]  # with the sweep's set: values
bands = montecarlo_bands(result.traces, sweep.regulated_states(cfg), duration, [r["case"] for r in result.rows])
phi = bands.states.index("phi")
half = bands.t >= bands.t[-1] / 2
spread = np.degrees(bands.bands[-1, half, phi] - bands.bands[0, half, phi]).max()
print(f"uncertainty: {len(bands.cases)} cases, {sum(r['pass'] for r in result.rows)} pass; phi 5-95 % band "
      f"(second half) at most {spread:.3g} deg wide")

groups = {name: list(cfg.partition()[name].states) for name in ("altitude", "roll")}  # the mass and Jxx errors
fig = plots.montecarlo_figure(bands, groups, title=cfg.name, varied=tuple(spec.names))
fig.set_size_inches(9.2, fig.get_figheight())  # 736 pixels at 80 dpi: the pages' width, so it shows unscaled
OUT.mkdir(parents=True, exist_ok=True)
fig.savefig(OUT / "uncertainty-bands.png", dpi=80)
print(f"wrote {OUT / 'uncertainty-bands.png'}")
