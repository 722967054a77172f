"""The run report: every stage of a config in one HTML page a student can hand in, and a Markdown twin.

:func:`run_stages` runs the stages through a :class:`~quadctl.workspace.Workspace` (reusing its
fresh artifacts) in ``quadctl run``'s order, plus the margins, and stops where ``run`` stops;
:func:`build` turns what was computed into a :class:`~quadctl.report.document.Document`;
:func:`write` writes ``report.html`` (self-contained: CSS inline, figures as ``data:`` URIs, no
script, nothing fetched), ``report.md`` and the figures it shows, into ``<run folder>/report/``.

Examples
--------
>>> from quadctl import config
>>> from quadctl.workspace import Workspace
>>> ws = Workspace(config.load("hover"), "runs/hover")              # doctest: +SKIP
>>> outcome = run_stages(ws)                                         # doctest: +SKIP
>>> write(build(ws, outcome), ws.out / "report")                    # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from quadctl.errors import QuadctlError
from quadctl.present.loops import thin_sentence
from quadctl.present.mission import mission_text
from quadctl.present.stages import UNSTABLE_DESIGN
from quadctl.report import content
from quadctl.report.document import Document, Section, Table, Text, to_html, to_markdown

STAGES = ("trim", "linearize", "decouple", "check", "design", "margins", "simulate")
"""The stages a report runs, in order: ``quadctl run``'s, with the margins before the flight."""
FOLDER = "report"
"""Where :func:`write` puts the report inside the run folder."""
HTML, MARKDOWN = "report.html", "report.md"


@dataclass(frozen=True)
class Outcome:
    """How far the stages went.

    Attributes
    ----------
    done : tuple of str
        The stages computed, in order (a simulation that diverged is computed).
    failed : str or None
        Why a check failed (``"check: subsystem roll is not stabilizable: mode 0 in phi, p"``): what
        ``quadctl run`` exits 1 for.
    error : QuadctlError or None
        An error a stage raised (its ``exit_code`` says what kind); the stages after it did not run.
    """

    done: tuple[str, ...]
    failed: str | None = None
    error: QuadctlError | None = None

    @property
    def stopped_at(self) -> str | None:
        """The stage that failed a check or raised; None when every stage passed."""
        if self.failed is not None:
            return self.done[-1]
        return None if self.error is None else STAGES[len(self.done)]


def run_stages(ws) -> Outcome:
    """Run the stages in order until one fails a check or raises; what ``quadctl run`` checks, plus margins.

    A check fails when a regulated subsystem is not stabilizable, a continuous design is unstable
    sampled at the controller's rate, or the rotors' lag and the delay make the design's loop unstable
    (the verdicts ``check`` and ``run`` give), the assembled design is unstable
    on the coupled model, the simulation does not finish (diverged, left the valid range), or its
    mission misses a waypoint or ends farther than the tolerance from it, or (after the flight) a loop has a thin
    margin (:func:`quadctl.design.margins.thin_loops`) the config does not accept (``allow: [thin-margins]``); a
    :class:`~quadctl.errors.QuadctlError` a stage raises stops the stages too. Neither is raised:
    both are in the returned :class:`Outcome`, so that what was computed can still be reported.
    """
    done: list[str] = []

    def step(name, compute, verdict=lambda: None):
        try:
            compute()
        except QuadctlError as exc:
            return Outcome(tuple(done), error=exc)
        done.append(name)
        why = verdict()
        return None if why is None else Outcome(tuple(done), failed=f"{name}: {why}")

    plan = (
        ("trim", lambda: ws.trim, None),
        ("linearize", lambda: ws.linear, None),
        ("decouple", lambda: ws.decoupled, None),
        ("check", lambda: ws.checks, lambda: ws.checks.verdict()),
        ("design", lambda: ws.design, lambda: (
            None if ws.design.stable else UNSTABLE_DESIGN)),
        ("margins", lambda: ws.margins, None),
        ("simulate", lambda: ws.simulation, lambda: (
            mission_text(ws.simulation.flight.get("reference")) if ws.simulation.sim.status == "ok"
            else ws.simulation.sim.message)),
    )
    for name, compute, verdict in plan:
        stop = step(name, compute, verdict or (lambda: None))
        if stop is not None:
            return stop
    thin = thin_sentence(ws.margins) if "thin-margins" not in ws.cfg.allow else None
    if thin is not None:  # after the flight: thin margins fail the check, the flight is still worth reporting
        return Outcome(tuple(done), failed=f"margins: {thin}")
    return Outcome(tuple(done))


def build(ws, outcome: Outcome, *, command_line: str = "", label: str | None = None) -> Document:
    """The report of what ``outcome`` says was computed in ``ws``.

    Parameters
    ----------
    ws : Workspace
        The stages' results (cached on it by :func:`run_stages`).
    outcome : Outcome
    command_line : str
        The command that made the report, shown in it.
    label : str, optional
        Where the config came from (a file, a bundled name); default its name.
    """
    from quadctl import artifacts

    done = set(outcome.done)
    label = label or f"{ws.cfg.name} (Python)"
    sections = [_summary(ws, outcome)]
    for stage, make in (("trim", content.trim), ("decouple", content.decoupling), ("check", content.checks),
                        ("design", content.design), ("margins", content.margins),
                        ("simulate", content.simulation), ("simulate", content.mission), ("simulate", content.flight)):
        section = make(ws) if stage in done else None
        if section is not None:  # (a run without a reference has no mission)
            sections.append(section)
        if make is content.design and ws.setup.schedule is not None and "simulate" in done:
            sections.append(content.schedule(ws))  # the schedule the flight flew (computed with it)
    compared = content.comparison(ws)  # what quadctl compare left in the run folder
    if compared is not None:
        sections.append(compared)
    sections.append(content.configuration(ws, label))
    backends = [ws.simulation.sim.backend] if "simulate" in done else []
    meta = artifacts.metadata(ws.cfg, "report", backends)
    sections.append(content.software(meta, command_line or "(library call)", ws.out))
    title = f"quadctl report: {ws.cfg.name}"
    subtitle = ws.cfg.description or f"config {ws.cfg.name}"
    return Document(title=title, subtitle=f"{subtitle} — {meta['created']}", status=_status(outcome),
                    sections=tuple(sections), generator=f"quadctl {meta['quadctl_version']}")


def _status(outcome: Outcome) -> Text:
    if outcome.stopped_at is None:
        return Text("Complete: every stage ran and every check passed (stabilizable, stable on the coupled "
                    "model, simulation finished).", "ok")
    why = outcome.failed.split(": ", 1)[1] if outcome.failed else str(outcome.error)
    left = [s for s in STAGES if s not in outcome.done]
    after = f" Not run: {', '.join(left)}." if left else ""
    return Text(f"Stopped at {outcome.stopped_at}: {why}.{after} This report shows what was computed.", "fail")


def _summary(ws, outcome: Outcome) -> Section:
    done = set(outcome.done)
    rows = []
    for stage in STAGES:
        if stage not in done:
            verdict = "failed" if stage == outcome.stopped_at else "not run"
            rows.append((stage, verdict, str(outcome.error) if stage == outcome.stopped_at and outcome.error else ""))
            continue
        ok = not (outcome.failed and outcome.failed.startswith(stage + ":"))
        rows.append((stage, "ok" if ok else "failed", _detail(ws, stage) if ok else outcome.failed.split(": ", 1)[1]))
    return Section("summary", "Summary", (
        Table("summary-table", "Stages", ("stage", "verdict", "result"), tuple(rows), align="llw"),))


def _detail(ws, stage: str) -> str:
    from quadctl.present import design, loops, stages

    if stage == "trim":
        return stages.trim_summary(ws.trim)
    if stage == "linearize":
        return f"A {ws.linear.A.shape}, B {ws.linear.B.shape}"
    if stage == "decouple":
        return stages.decouple_summary(ws.decoupled)
    if stage == "check":
        return stages.CHECKS_PASSED
    if stage == "design":
        return design.summary(ws.design)
    if stage == "margins":
        return loops.summary(ws.margins, discrete=ws.setup.law == "pid" or ws.design.rate is not None)
    sim = ws.simulation.sim
    return f"{sim.steps} RK4 steps, dt {sim.dt:.3g} s, {sim.backend}: {sim.status}"


def write(doc: Document, folder: Path | str, store=None) -> list[Path]:
    """Write ``report.html``, ``report.md`` and the figures into ``folder``, atomically; the paths.

    The figures of an earlier report that this one does not show go: those the earlier
    ``report.md`` names (:func:`~quadctl.report.document.figure_files`), never another file.

    ``store`` writes and removes the files (``write_bytes(path, data)``, ``remove(path)``): the run folder's
    :class:`~quadctl.workspace.Workspace`, so that a command that fails on the way (a full disk) puts
    every file back as its stages' artifacts (:meth:`~quadctl.workspace.Workspace.roll_back`); default
    :mod:`quadctl.artifacts` (each file atomic, nothing put back).
    """
    from quadctl import artifacts

    store = artifacts if store is None else store
    folder = artifacts.check_folder(Path(folder))
    earlier = _earlier_figures(folder / MARKDOWN)
    paths = [store.write_bytes(folder / fig.file, fig.png) for fig in doc.figures]
    for name in sorted(earlier - {p.name for p in paths}):
        store.remove(folder / name)
    paths.append(store.write_bytes(folder / MARKDOWN, to_markdown(doc).encode("utf-8")))
    paths.append(store.write_bytes(folder / HTML, to_html(doc).encode("utf-8")))
    return paths


def _earlier_figures(markdown: Path) -> set[str]:
    """The figure files an earlier report in this folder wrote (its ``report.md`` names them)."""
    import os

    from quadctl.report.document import figure_files

    if os.path.islink(markdown) or not markdown.is_file():
        return set()
    try:
        return figure_files(markdown.read_text(encoding="utf-8", errors="replace"))
    except OSError:
        return set()


__all__ = ["FOLDER", "HTML", "MARKDOWN", "STAGES", "Document", "Outcome", "Section", "Table", "build",
           "run_stages", "write"]
