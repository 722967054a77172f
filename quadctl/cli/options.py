"""Options shared by the commands, and the workspace they open."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

ConfigOpt = Annotated[Optional[str], typer.Option(
    "--config", "-c", metavar="PATH|NAME",
    help="Config file, or the name of a bundled config (see `quadctl configs`). "
         "Default: forward, the report's case.")]
OutOpt = Annotated[Optional[Path], typer.Option(
    "--out", "-o", metavar="DIR", help="Run directory for artifacts. Default: runs/<config name>.")]
JsonOpt = Annotated[bool, typer.Option(
    "--json", help="Print machine-readable JSON to stdout instead of tables.")]
FreshOpt = Annotated[bool, typer.Option(
    "--fresh", help="Recompute every stage; ignore artifacts already in the run directory.")]
PlotOpt = Annotated[bool, typer.Option("--plot", help="Also write PNG figures to DIR/plots/.")]


def load_config(config: str | None):
    """Resolve and load ``--config``; print its notes and warnings on stderr, one line each.

    Returns
    -------
    (Config, str) : the validated config and the file to name in messages.
    """
    cfg, source = load_source(config)
    return cfg, source.label


def load_source(config: str | None):
    """:func:`load_config`, returning the config and its :class:`quadctl.config.Source` (label, text)."""
    from quadctl import config as config_mod
    from quadctl import notices
    from quadctl.cli import render
    from quadctl.cli.errors import remember_config

    source = config_mod.locate(config)
    if source.note:
        render.note(source.note)
    cfg = config_mod.parse(source.text, source.label)
    remember_config(source.label)
    for notice in notices.notices(cfg, source.label):
        (render.note if notice.level == "note" else render.warning)(notice.message)
    return cfg, source


def open_workspace(config: str | None, out: Path | None, fresh: bool = False):
    """Load the config and open its run directory."""
    from quadctl.workspace import Workspace

    cfg, source = load_source(config)
    return Workspace(cfg, out, fresh=fresh, source_text=source.text)
