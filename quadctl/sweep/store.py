"""The run directory of a sweep: the chunk journal ``--resume`` reads, and the final outputs written atomically."""

from __future__ import annotations

import base64
import contextlib
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadctl import artifacts
from quadctl.errors import ArgumentError, ArtifactError, QuadctlNotice, SweepError
from quadctl.layout import unit_of
from quadctl.sweep.config_tree import value_at
from quadctl.sweep.gates import regulated_states
from quadctl.sweep.outputs import (
    MC_FILES,
    MonteCarloBands,
    montecarlo_bands,
    montecarlo_png,
    summarize,
    to_csv,
    tradeoff_png,
)
from quadctl.sweep.rows import MC_PERCENTILES, MC_POINTS
from quadctl.sweep.runner import SweepResult, base_of, run
from quadctl.sweep.spec import SweepSpec

PARTS = artifacts.SWEEP_PARTS
"""Folder of the run directory holding the finished chunks (the journal ``--resume`` reads)."""

class SweepStore:
    """The sweep's files in a run directory.

    Finished chunks go to ``DIR/sweep.parts/`` one file each, atomically, as they land; a
    stopped sweep keeps them and ``--resume`` reads them back instead of recomputing. At the
    end: ``sweep.csv`` (one row per case), ``sweep.json`` (summary, gates, worst and best cases,
    config hash) and ``sweep.png`` (the trade-off plot). A Monte Carlo's chunks also hold their
    cases' trajectories (float32, base64), so a resumed one has the bands of every case, and it
    ends with ``montecarlo.png`` and ``montecarlo.npz`` (:func:`montecarlo_bands`).

    Parameters
    ----------
    out : path
        The run directory.
    cfg : Config
    spec : SweepSpec
    plot : bool
        Draw the figures (``sweep.png``, ``montecarlo.png``); without, an earlier run's in this
        folder go, so none is mistaken for this one's.
    session : quadctl.artifacts.Session, optional
        The run folder's session (of ``out``) every file is written and removed through: the config beside
        them, another config's run removed, each change undoable. Default: :mod:`quadctl.artifacts`, each
        file written as it is.
    """

    def __init__(self, out: Path | str, cfg, spec: SweepSpec, *, plot: bool = True,
                 session: artifacts.Session | None = None):
        self.out = Path(out)
        self.cfg = cfg
        self.spec = spec
        self.plot = plot
        self.files = artifacts if session is None else session
        """What writes and removes the files (``write_bytes``, ``write_json``, ``write_npz``, ``remove``)."""
        self.parts = self.out / PARTS
        self.digest = spec.digest(cfg)
        self.trace = tuple(regulated_states(cfg)) if spec.monte_carlo else ()
        self.traces: dict[int, np.ndarray] = {}
        """Monte Carlo trajectories journaled so far (read back on resume, added per chunk)."""

    def start(self, resume: bool) -> dict[int, dict]:
        """Rows of finished chunks when resuming (checked to be of this very sweep), else none:
        a fresh sweep first clears the journal of an earlier one."""

        artifacts.remove_stale_temporaries(self.out)  # what a killed run was writing
        artifacts.check_folder(self.parts)
        ours = artifacts.SUBFOLDER_NAMES[PARTS]
        files = sorted(p for p in self.parts.glob("chunk-*.json") if ours.fullmatch(p.name)) \
            if self.parts.is_dir() else []
        if not resume:
            for path in files:
                self.files.remove(path)
            return {}
        if not files:  # asked to resume, told so rather than silently starting over
            warnings.warn(QuadctlNotice(f"--resume: no finished chunks in {self.parts}, so nothing to resume: "
                                        f"computing all {self.spec.count()} cases"), stacklevel=2)
            return {}
        done: dict[int, dict] = {}
        for path in files:
            try:
                data = artifacts.read_json(path)
            except ArtifactError as exc:  # its advice (--fresh) is for the stage commands, not sweep
                why = str(exc).rsplit(";", 1)[0]  # the file and what is wrong; the fix is the last clause
                raise SweepError(f"{why}; delete it, or run without --resume to start over") from None
            if data.get("sweep_digest") != self.digest:
                raise SweepError(
                    f"{path}: rows of another sweep (the config, the sweep file or quadctl changed "
                    "since); run without --resume to start over, or use another -o folder")
            for row in data["rows"]:
                done[int(row["case"])] = artifacts.decode_floats(row)  # "inf" back to a float
            if self.trace:
                self.traces.update(self._decode(path, data.get("traces")))
        return done

    def save_chunk(self, rows: list[dict], traces: dict | None = None) -> Path:
        """Write a finished chunk atomically (``chunk-<first case>.json``), with its cases'
        trajectories in a Monte Carlo."""

        first = min(int(r["case"]) for r in rows)
        payload = {**artifacts.metadata(self.cfg, "sweep-chunk"), "sweep_digest": self.digest,
                   "cases": [r["case"] for r in rows], "rows": rows}
        if self.trace:
            traces = traces or {}
            self.traces.update(traces)
            payload["traces"] = {"states": list(self.trace), "points": MC_POINTS, "dtype": "<f4",
                                 "cases": {str(k): base64.b64encode(np.ascontiguousarray(v, "<f4").tobytes())
                                           .decode("ascii") for k, v in traces.items()}}
        # compact: a journal read back by --resume, not a file to read (1000 rows: 0.2 s indented)
        path = self.files.write_json(self.parts / f"chunk-{first:07d}.json", payload, indent=None)
        if self.files is not artifacts and not self.files.replaced:
            # finished work --resume takes up, in a folder of this config's: kept whatever follows (a refusal,
            # a full disk at sweep.json). A sweep that replaced another config's run keeps its undo: refused,
            # it puts that run back whole
            self.files.keep()
        return path

    def _decode(self, path: Path, block) -> dict[int, np.ndarray]:
        """A chunk's trajectories, checked to have this sweep's layout."""
        if not isinstance(block, dict) or block.get("states") != list(self.trace) \
                or block.get("points") != MC_POINTS or block.get("dtype") != "<f4":
            raise SweepError(f"{path}: a Monte Carlo chunk without trajectories of this layout "
                             f"({MC_POINTS} times of {', '.join(self.trace)}); run without --resume "
                             "to start over")
        shape = (MC_POINTS, len(self.trace))
        return {int(k): np.frombuffer(base64.b64decode(v), dtype="<f4").reshape(shape)
                for k, v in block["cases"].items()}

    def finish(self, result: SweepResult) -> dict:
        """Write sweep.csv, sweep.json and sweep.png (and a Monte Carlo's files); return the
        summary (sweep.json's content)."""

        csv_path = self.files.write_bytes(self.out / "sweep.csv", to_csv(result).encode())
        summary = summarize(result, self.cfg, self.spec)
        summary["files"] = {"table": csv_path.name, **({"plot": "sweep.png"} if self.plot else {}), "chunks": PARTS}
        bands = self.finish_montecarlo(result)
        if self.trace:
            summary["montecarlo"] = {
                "cases": 0 if bands is None else len(bands.cases), "points": MC_POINTS,
                "percentiles": list(MC_PERCENTILES), "states": list(self.trace), "parameters": list(self.spec.names),
                "left_out": [r["case"] for r in result.rows] if bands is None else list(bands.left_out)}
        if bands is not None:
            summary["files"]["montecarlo"] = [name for name in MC_FILES if self.plot or not name.endswith(".png")]
        backends = result.stats.get("backend", ())
        payload = artifacts.jsonable({**artifacts.metadata(self.cfg, "sweep", backends), **summary,
                                      "sweep_digest": self.digest})
        self.files.write_json(self.out / "sweep.json", payload)
        if self.plot:
            self.files.write_bytes(self.out / "sweep.png", tradeoff_png(result, self.cfg))
        else:
            self.files.remove(self.out / "sweep.png")
        return payload

    def finish_montecarlo(self, result: SweepResult) -> MonteCarloBands | None:
        """A Monte Carlo: write montecarlo.npz and montecarlo.png from every trajectory (journaled
        and computed now). None if the sweep is no Monte Carlo or no case simulated to the end:
        then those files of an earlier run in this folder go, so none is mistaken for this one's."""

        traces = {**self.traces, **result.traces} if self.trace else {}
        if not traces:
            for name in MC_FILES:
                self.files.remove(self.out / name)
            return None
        duration = value_at(base_of(self.cfg, self.spec), ("simulation", "duration"))
        bands = montecarlo_bands(traces, self.trace, duration, [r["case"] for r in result.rows])
        meta = {**artifacts.metadata(self.cfg, "montecarlo", result.stats.get("backend", ())),
                "sweep_digest": self.digest,
                "quantity": "deviation from the reference, x - x_ref, in state units (m, m/s, rad, rad/s)",
                "units": {s: unit_of(s) for s in bands.states}, "left_out": list(bands.left_out),
                "t_unit": "s", "parameters": list(self.spec.names)}
        self.files.write_npz(self.out / "montecarlo.npz",
                            {"t": bands.t, "percentiles": np.asarray(bands.percentiles, dtype=float),
                             "bands": bands.bands, "states": np.array(bands.states),
                             "units": np.array([unit_of(s) for s in bands.states]), "cases": bands.cases,
                             "traces": bands.traces, "parameters": np.array(self.spec.names)}, meta)
        if self.plot:
            self.files.write_bytes(self.out / "montecarlo.png", montecarlo_png(bands, self.cfg, self.spec.names))
        else:
            self.files.remove(self.out / "montecarlo.png")
        return bands



@dataclass
class SweepOutcome:
    """What :func:`execute` did: the result, the summary written, the files, and what was reused."""

    result: SweepResult
    summary: dict
    out: Path
    reused: int = 0
    files: list = field(default_factory=list)


def execute(cfg, spec: SweepSpec, out: Path | str | artifacts.Session, *, label: str | None = None,
            jobs: int | None = None, scheduler: str | None = None, resume: bool = False,
            progress: Callable[[int, int], None] | None = None, plot: bool = True) -> SweepOutcome:
    """Run a sweep into a run directory: journal each chunk, resume, write the outputs.

    Parameters
    ----------
    cfg : Config
    spec : SweepSpec
    out : path or quadctl.artifacts.Session
        Run directory (``sweep.csv``, ``sweep.json``, ``sweep.png``, ``sweep.parts/``; a Monte
        Carlo also ``montecarlo.png`` and ``montecarlo.npz``), or the session of one the files are
        written through (``quadctl sweep``'s, which puts the folder back when the command fails).
        Given a path, the sweep opens a session of its own, closed when it ends. Either writes the
        config beside the sweep at its first write and removes the run of another config there.
    label, jobs, scheduler, progress
        As :func:`run`.
    resume : bool
        Keep the rows of an earlier, interrupted run of this same sweep and compute only the rest.
    plot : bool
        Draw ``sweep.png`` (and a Monte Carlo's ``montecarlo.png``); False: no figure (an earlier
        run's in ``out`` goes).

    Returns
    -------
    SweepOutcome

    Raises
    ------
    SweepError
        ``resume`` finds rows of a different sweep, or the scheduler cannot be reached.
    ArgumentError
        ``out`` is a session of another config.
    """

    with contextlib.ExitStack() as own:
        if isinstance(out, artifacts.Session):
            session = out
            if session.cfg.digest() != cfg.digest():  # its config.yaml, stamps and clean-up are its config's
                raise ArgumentError(f"the session of {session.out} is of config {session.cfg.name!r} "
                                    f"({session.cfg.digest()[:12]}), the sweep of {cfg.name!r} ({cfg.digest()[:12]}): "
                                    "give the run folder's path, or a session of the sweep's config")
        else:
            session = own.enter_context(artifacts.Session(cfg, out))  # one run writes a folder at a time
            session.defer_notes()  # what it removed is said at the end: not at all if it is put back
        store = SweepStore(session.out, cfg, spec, plot=plot, session=session)
        done = store.start(resume)
        result = run(cfg, spec, label=label, jobs=jobs, scheduler=scheduler, done=done,
                     on_chunk=store.save_chunk, progress=progress)
        summary = store.finish(result)
    files = [store.out / "sweep.csv", store.out / "sweep.json"] + ([store.out / "sweep.png"] if plot else [])
    files += [store.out / name for name in summary["files"].get("montecarlo", [])]
    return SweepOutcome(result=result, summary=summary, out=store.out, reused=len(done), files=files)
