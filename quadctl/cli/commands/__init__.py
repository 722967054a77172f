"""One module per command; :func:`register` adds them all to the app."""

from __future__ import annotations

import inspect

import typer

from quadctl.cli.commands import (
    check,
    compare,
    configs,
    decouple,
    design,
    export,
    identify,
    init,
    linearize,
    margins,
    report,
    run,
    schedule,
    simulate,
    sweep,
    trim,
)
from quadctl.cli.errors import handled
from quadctl.cli.options import flags_without_placeholder, help_into_a_closed_pipe

COMMAND_CLASS = help_into_a_closed_pipe(flags_without_placeholder(typer.core.TyperCommand))
"""Every command's class: its flags show no value placeholder in ``--help``."""

COMMANDS = (init, trim, linearize, decouple, check, design, schedule, simulate, compare, margins, export, sweep, run,
            report, identify, configs)


def register(app: typer.Typer) -> None:
    """Add every command, each wrapped by the one error handler."""
    for module in COMMANDS:
        app.command(module.NAME, cls=COMMAND_CLASS, help=reflowed(module.command.__doc__))(handled(module.command))


def reflowed(doc: str) -> str:
    """``doc`` with each paragraph on one line, paragraphs still apart: the help's rich markup keeps
    a docstring's line breaks, so an 80-column terminal broke its lines mid-sentence where the source
    did, after wrapping them where it had to. One line per paragraph lets the terminal wrap alone."""
    paragraphs = inspect.cleandoc(doc).split("\n\n")
    return "\n\n".join(" ".join(p.split()) for p in paragraphs)
