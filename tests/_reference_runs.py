"""Every bundled config's run folder reduced to its numbers, and compared with a stored reference.

The reference (``tests/data/reference_runs.json``) holds what quadctl wrote before a change that
must not move any number: each JSON artifact with its volatile fields (times, versions, compiler,
speeds, paths) left out, and each ``.npz`` array (whole when it has few rows, else 33 evenly spaced
rows, the first and the last among them). Remake it only when a change is meant to move numbers,
and say which in the commit (``python tests/_reference_runs.py --write``).

The comparison holds on any CPU: each number to a tolerance from its own conditioning (see
:func:`differences`), so another BLAS kernel's rounding passes and a gain moved by 1e-9 of
itself does not.
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
"""Relative and absolute floor: the same code path on the same BLAS kernel gives the same bits."""
EPS = float(np.finfo(float).eps)
EIGEN_KAPPA = 100.0
"""The largest eigenvalue condition number allowed for: an LQR closed loop is mildly non-normal."""
ARGMAX_RTOL = 1e-4
"""Relative tolerance of a frequency that maximizes a function (``disk_margin_freq``): on a flat peak
the maximizer is fixed only to ``sqrt(eps f / f'')``, so another BLAS kernel's rounding moves it
(5e-6 seen); the peak's value is well conditioned and keeps :data:`TOLERANCE`."""
EIGENVALUE_KEYS = ("eigenvalues", "eigenvalues_z")
SINGULAR_VALUE_KEYS = ("ctrb_singular_values", "obsv_singular_values")
TRAJECTORY_KEYS = ("x", "u", "x_hat", "x_ref", "z", "rotor_thrust", "wind")


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


def tolerance(reference: dict) -> float:
    """The relative tolerance of one config's numbers, from the conditioning of its closed loop.

    Another BLAS kernel rounds differently: a backward-stable solve (Riccati, Lyapunov, eigenvalues)
    of a loop whose eigenvalues span ``|lambda|_max / |lambda|_min`` (its stiffness, a lower bound
    of its condition number) returns numbers that agree to about ``n eps`` times that ratio. Zero
    eigenvalues (free positions) have no dynamics to solve and are left out. Never below :data:`TOLERANCE`.
    """
    eig = _complex(reference["design_full.json"]["closed_loop_eigenvalues"])
    size = np.abs(eig)
    moving = size[size > 1e-9 * size.max()]
    return max(TOLERANCE, len(eig) * EPS * float(moving.max() / moving.min()))


def differences(reference: dict, new: dict, where: str = "", rtol: float = TOLERANCE, steps: int = 1) -> list[str]:
    """Every place ``new`` differs from ``reference`` beyond its tolerance (keys only in ``new`` are
    additions, not differences).

    Numbers agree to ``rtol`` (relative, with :data:`TOLERANCE` absolute). Eigenvalues are compared as
    multisets (each matched to its nearest, the order a solver returns them in is not a number), to
    ``EIGEN_KAPPA n eps |lambda|_max`` (Bauer-Fike for a backward-stable solver); a matrix's entries
    to ``rtol`` of its largest (a backward-stable solve's error is norm-wise); singular values to
    ``n eps sigma_max`` (Weyl); a simulated trajectory column to ``steps eps max|column|`` (the
    rounding one step adds, accumulated; another CPU may fuse multiply-adds differently); a peak's
    frequency to :data:`ARGMAX_RTOL`.
    """
    key = where.rsplit(".", 1)[-1]
    if isinstance(reference, dict) and isinstance(new, dict):
        return [d for k in reference
                for d in (differences(reference[k], new[k], f"{where}.{k}", rtol, steps) if k in new
                          else [f"{where}.{k}: missing"])]
    if isinstance(reference, list) and isinstance(new, list):
        if len(reference) != len(new):
            return [f"{where}: {len(reference)} items, now {len(new)}"]
        if key.endswith(EIGENVALUE_KEYS) and reference and _pairs(reference) and _pairs(new):
            return _eigenvalue_differences(reference, new, where, rtol)
        if key in SINGULAR_VALUE_KEYS and reference:
            atol = max(TOLERANCE, len(reference) * EPS * max(abs(v) for v in reference))
            return _number_differences(reference, new, where, rtol, atol)
        if key in TRAJECTORY_KEYS and np.ndim(reference) == 2 and np.size(reference):
            return _trajectory_differences(np.asarray(reference, float), np.asarray(new, float), where, rtol,
                                           steps)
        if _matrix(reference) and _matrix(new) and np.shape(reference) == np.shape(new):
            # a backward-stable solve (Riccati, Lyapunov) errs by rtol of the matrix's norm, in every
            # entry alike: an entry that is round-off (a structural zero) moves by that much, not by
            # rtol of itself
            atol = max(TOLERANCE, rtol * float(np.abs(np.asarray(reference, float)).max()))
            return [d for i, (a, b) in enumerate(zip(reference, new))
                    for d in _number_differences(a, b, f"{where}[{i}]", rtol, atol)]
        return [d for i, (a, b) in enumerate(zip(reference, new))
                for d in differences(a, b, f"{where}[{i}]", rtol, steps)]
    if _number(reference) and _number(new):
        return _number_differences([reference], [new], where, ARGMAX_RTOL if key == "disk_margin_freq" else rtol,
                                   TOLERANCE, single=True)
    return [] if reference == new else [f"{where}: {str(reference)[:60]!r}, now {str(new)[:60]!r}"]


def _number_differences(reference, new, where, rtol, atol, single=False) -> list[str]:
    out = []
    for i, (a, b) in enumerate(zip(reference, new)):
        a, b = float(a), float(b)
        same = a == b or (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=rtol, abs_tol=atol)
        if not same:
            out.append(f"{where if single else f'{where}[{i}]'}: {a!r}, now {b!r} (diff {abs(a - b):.3e}, "
                       f"tolerance {max(rtol * max(abs(a), abs(b)), atol):.1e})")
    return out


def _eigenvalue_differences(reference, new, where, rtol) -> list[str]:
    from scipy.optimize import linear_sum_assignment

    a, b = _complex(reference), _complex(new)
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return [] if np.array_equal(a, b, equal_nan=True) else [f"{where}: {a}, now {b}"]
    rows, cols = linear_sum_assignment(np.abs(a[:, None] - b[None, :]))
    atol = max(TOLERANCE, EIGEN_KAPPA * len(a) * EPS * float(np.abs(a).max()))
    return [f"{where}: eigenvalue {a[i]:.15g} nearest {b[j]:.15g} (diff {abs(a[i] - b[j]):.3e}, tolerance "
            f"{atol + rtol * abs(a[i]):.1e})"
            for i, j in zip(rows, cols) if abs(a[i] - b[j]) > atol + rtol * abs(a[i])]


def _trajectory_differences(reference: np.ndarray, new: np.ndarray, where: str, rtol: float,
                            steps: int) -> list[str]:
    if reference.shape != new.shape:
        return [f"{where}: shape {reference.shape}, now {new.shape}"]
    scale = np.nan_to_num(np.abs(reference), posinf=0.0).max(axis=0)
    atol = np.maximum(TOLERANCE, max(rtol, steps * EPS) * scale)
    bad = ~((np.abs(new - reference) <= atol) | (reference == new) | (np.isnan(reference) & np.isnan(new)))
    return [f"{where}[{i}][{j}]: {reference[i, j]!r}, now {new[i, j]!r} (diff {abs(new[i, j] - reference[i, j]):.3e}, "
            f"tolerance {atol[j]:.1e})" for i, j in zip(*np.nonzero(bad))]


def compare(reference: dict, new: dict, name: str = "") -> list[str]:
    """:func:`differences` of one config's digest, at that config's :func:`tolerance` and its run's steps."""
    steps = int(reference.get("sim.json", {}).get("steps") or 1)
    return differences(reference, new, name, tolerance(reference), steps)


def _pairs(v) -> bool:
    return all(isinstance(x, list) and len(x) == 2 and all(_number(c) or c is None for c in x) for x in v)


def _complex(pairs) -> np.ndarray:
    a = np.asarray(pairs, dtype=float)
    return a[:, 0] + 1j * a[:, 1]


def _matrix(v) -> bool:
    """A list of equal rows of numbers."""
    return (isinstance(v, list) and len(v) > 0 and all(isinstance(r, list) and r and len(r) == len(v[0])
                                                       and all(_number(x) for x in r) for r in v))


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
