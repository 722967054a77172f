"""Every bundled config's run folder reduced to its numbers, and compared with a stored reference.

The reference (``tests/data/reference_runs.json``) holds what quadctl wrote before a change that
must not move any number: each JSON artifact with its volatile fields (times, versions, compiler,
speeds, paths) left out, and each ``.npz`` array (whole when it has few rows, else 33 evenly spaced rows,
the first and the last among them). Remake it only when a change is meant to move numbers, and say which in the commit::

    python tests/_reference_runs.py --write
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

CONFIGS = ("forward", "forward-script-q", "hover", "mambo-200hz", "crazyflie", "crazyflie-wind")
"""The bundled configs (``quadctl configs``)."""
REFERENCE = Path(__file__).parent / "data" / "reference_runs.json"
VOLATILE = frozenset({"created", "software", "quadctl_version", "compiler", "backend", "steps_per_second",
                      "elapsed", "out", "host"})
"""Keys whose values differ from run to run or machine to machine, never compared."""
WHOLE = 64
"""Arrays with at most this many rows are kept whole; longer ones (time series) by :data:`ROWS` rows."""
ROWS = 33
TOLERANCE = 1e-12
"""Relative and absolute: the same code path gives the same bits; a reordered sum stays within this."""


def run_folder(name: str, out: Path) -> Path:
    """Every stage of bundled config ``name`` (the coupled design and the margins too) written into ``out``."""
    from quadctl import config
    from quadctl.workspace import Workspace

    with Workspace(config.load(name), out) as ws:
        for stage in ("trim", "linear", "decoupled", "checks", "design", "full", "margins", "simulation"):
            getattr(ws, stage)
    return out


def digest(folder: Path) -> dict:
    """The numbers of a run folder: ``{artifact: content}`` (see the module docstring)."""
    out = {}
    for path in sorted(folder.iterdir()):
        if path.suffix == ".json":
            out[path.name] = _strip(json.loads(path.read_text()))
        elif path.suffix == ".npz":
            with np.load(path, allow_pickle=False) as z:
                out[path.name] = {k: _array(z[k]) for k in z.files if k != "meta"}
    return out


def differences(reference: dict, new: dict, where: str = "") -> list[str]:
    """Every place ``new`` differs from ``reference`` beyond :data:`TOLERANCE` (keys only in ``new``
    are additions, not differences)."""
    if isinstance(reference, dict) and isinstance(new, dict):
        return [d for k in reference for d in (differences(reference[k], new[k], f"{where}.{k}") if k in new
                                               else [f"{where}.{k}: missing"])]
    if isinstance(reference, list) and isinstance(new, list):
        if len(reference) != len(new):
            return [f"{where}: {len(reference)} items, now {len(new)}"]
        return [d for i, (a, b) in enumerate(zip(reference, new)) for d in differences(a, b, f"{where}[{i}]")]
    if _number(reference) and _number(new):
        a, b = float(reference), float(new)
        same = a == b or (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=TOLERANCE,
                                                                            abs_tol=TOLERANCE)
        return [] if same else [f"{where}: {a!r}, now {b!r} (diff {abs(a - b):.3e})"]
    return [] if reference == new else [f"{where}: {str(reference)[:60]!r}, now {str(new)[:60]!r}"]


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _strip(v):
    if isinstance(v, dict):
        return {k: _strip(x) for k, x in v.items() if k not in VOLATILE}
    if isinstance(v, list):
        return [_strip(x) for x in v]
    return v


def _array(a: np.ndarray):
    if a.dtype.kind == "c":
        return {"real": _array(a.real), "imag": _array(a.imag)}
    if a.ndim >= 1 and len(a) > WHOLE:
        rows = sorted(set(np.linspace(0, len(a) - 1, ROWS).round().astype(int).tolist()))
        a = a[rows]
    return a.tolist()


def main(argv: list[str]) -> int:
    if argv[1:] != ["--write"]:
        print(__doc__)
        return 2
    refs = {}
    for name in CONFIGS:
        with tempfile.TemporaryDirectory() as tmp:
            refs[name] = digest(run_folder(name, Path(tmp)))
    REFERENCE.parent.mkdir(exist_ok=True)
    REFERENCE.write_text(json.dumps(refs, sort_keys=True, separators=(",", ":")) + "\n")
    print(f"wrote {REFERENCE} ({REFERENCE.stat().st_size / 1e3:.0f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
