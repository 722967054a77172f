from typing import Annotated, Optional

import typer

NAME = "configs"


def command(show: Annotated[Optional[str], typer.Option(
        "--show", metavar="PATH|NAME",
        help="Print this config, validated, with every default filled in.")] = None) -> None:
    """List the bundled configs, or print one with --show (a starting point for your own)."""
    from quadctl import config
    from quadctl.cli import render

    if show:
        typer.echo(config.load(show).to_yaml(), nl=False)  # raw: rich would wrap long lines
        return
    from rich.table import Table

    table = Table(title="Bundled configs (use with --config NAME)", title_justify="left")
    table.add_column("name")
    table.add_column("description")
    for name in config.bundled_names():
        table.add_row(name, config.load(name).description)
    render.out.print(table)
