"""The run report: every stage of a config in one HTML page a student can hand in, and a Markdown twin.

:func:`quadctl.stages.run_stages` runs the stages through a :class:`~quadctl.workspace.Workspace` (reusing its
fresh artifacts) in ``quadctl run``'s order, plus the margins, and stops where ``run`` stops;
:func:`build` turns what was computed into a :class:`~quadctl.report.document.Document`;
:func:`write` writes ``report.html`` (self-contained: CSS inline, figures as ``data:`` URIs, no
script, nothing fetched), ``report.md`` and the figures it shows, into ``<run folder>/report/``.

Examples
--------
>>> from quadctl import config
>>> from quadctl import stages
>>> from quadctl.workspace import Workspace
>>> ws = Workspace(config.load("hover"), "runs/hover")              # doctest: +SKIP
>>> outcome = stages.run_stages(ws)                                  # doctest: +SKIP
>>> write(build(ws, outcome), ws.out / "report")                    # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path

from quadctl import artifacts
from quadctl.present.stages import stage_summary
from quadctl.report import content
from quadctl.report.document import Document, Section, Table, Text, to_html, to_markdown
from quadctl.stages import NAMES, Outcome

FOLDER = "report"
"""Where :func:`write` puts the report inside the run folder."""
HTML, MARKDOWN = "report.html", "report.md"


def build(ws, outcome: Outcome, *, command_line: str = "", label: str | None = None) -> Document:
    """The report of what ``outcome`` says was computed in ``ws``.

    Parameters
    ----------
    ws : Workspace
        The stages' results (cached on it by :func:`quadctl.stages.run_stages`).
    outcome : Outcome
    command_line : str
        The command that made the report, shown in it.
    label : str, optional
        Where the config came from (a file, a bundled name); default its name.
    """

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
    left = [s for s in NAMES if s not in outcome.done]
    after = f" Not run: {', '.join(left)}." if left else ""
    return Text(f"Stopped at {outcome.stopped_at}: {why}.{after} This report shows what was computed.", "fail")


def _summary(ws, outcome: Outcome) -> Section:
    done = set(outcome.done)
    rows = []
    for stage in NAMES:
        if stage not in done:
            verdict = "failed" if stage == outcome.stopped_at else "not run"
            rows.append((stage, verdict, str(outcome.error) if stage == outcome.stopped_at and outcome.error else ""))
            continue
        ok = not (outcome.failed and outcome.failed.startswith(stage + ":"))
        result = stage_summary(ws, stage) if ok else outcome.failed.split(": ", 1)[1]
        rows.append((stage, "ok" if ok else "failed", result))
    return Section("summary", "Summary", (
        Table("summary-table", "Stages", ("stage", "verdict", "result"), tuple(rows), align="llw"),))


def write(doc: Document, folder: Path | str, store=None) -> list[Path]:
    """Write ``report.html``, ``report.md`` and the figures into ``folder``, atomically; the paths.

    The figures of an earlier report that this one does not show go: those the earlier
    ``report.md`` names (:func:`~quadctl.report.document.figure_files`), never another file.

    ``store`` writes and removes the files (``write_bytes(path, data)``, ``remove(path)``): the run folder's
    :class:`~quadctl.workspace.Workspace`, so that a command that fails on the way (a full disk) puts
    every file back as its stages' artifacts (:meth:`~quadctl.workspace.Workspace.roll_back`); default
    :mod:`quadctl.artifacts` (each file atomic, nothing put back).
    """

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


__all__ = ["FOLDER", "HTML", "MARKDOWN", "Document", "Section", "Table", "build",
           "write"]
