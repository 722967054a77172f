"""One module per command; :func:`register` adds them all to the app."""

from __future__ import annotations

import typer

from quadctl.cli.commands import (
    check,
    configs,
    decouple,
    design,
    export,
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

COMMANDS = (init, trim, linearize, decouple, check, design, schedule, simulate, margins, export, sweep, run, report,
            configs)


def register(app: typer.Typer) -> None:
    """Add every command, each wrapped by the one error handler."""
    for module in COMMANDS:
        app.command(module.NAME, help=module.command.__doc__)(handled(module.command))
