"""The ``quadctl`` application: composes the commands; ``main`` is the console script."""

from __future__ import annotations

import sys
from typing import Annotated, Optional

import typer

from quadctl.cli import commands
from quadctl.cli.columns import NARROWEST
from quadctl.cli.errors import EXIT_CODES_HELP, one_line_usage_errors
from quadctl.cli.options import flags_without_placeholder, help_into_a_closed_pipe
from quadctl.version import __version__

app = typer.Typer(
    name="quadctl",
    cls=one_line_usage_errors(help_into_a_closed_pipe(flags_without_placeholder(typer.core.TyperGroup))),
    help="Design and verify LQR controllers for quadcopters: trim, linearize, decouple, check, "
         f"design, simulate; schedule the gains across an envelope; sweep many designs at once.\n\n{EXIT_CODES_HELP}",
    no_args_is_help=True,
    add_completion=True,
    rich_markup_mode="rich",
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"quadctl {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    ctx: typer.Context,
    debug: Annotated[bool, typer.Option("--debug", help="Show the traceback of an error.")] = False,
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                          help="Print the version and exit.")] = False,
    width: Annotated[Optional[int], typer.Option(
        "--width", metavar="COLUMNS", min=NARROWEST,
        help="Width of the tables on stdout. Default: the terminal's; in a pipe or a file, COLUMNS if set, "
             "else wide enough that nothing is cut.")] = None,
) -> None:
    ctx.obj = {"debug": debug}
    if width is not None or "quadctl.cli.render" in sys.modules:  # (not imported for --help: it takes numpy)
        from quadctl.cli import render

        render.set_width(width)  # None: the default again, for a second call of the app in one process


commands.register(app)


def main() -> None:
    """Run the app (the console script goes through :func:`quadctl.cli.entry.main`)."""
    app(prog_name="quadctl")
