from typing import Annotated, Optional

import typer

from quadctl.cli.options import set_option

NAME = "configs"


def command(
    show: Annotated[Optional[str], typer.Option(
        "--show", metavar="PATH|NAME",
        help="Print this config, validated, with every default filled in.")] = None,
    sets: set_option("put into the config --show prints (give --show with it).") = None,
    schema: Annotated[bool, typer.Option(
        "--schema", help="Print the config's JSON Schema (units and defaults in the descriptions), for "
                         "editors: put `# yaml-language-server: $schema=<file>` atop a config.")] = False,
) -> None:
    """List the bundled configs, print one with --show (every default filled in), or the schema. For a
    vehicle of your own, `quadctl init NAME` writes a commented config to start from."""
    from quadctl import config
    from quadctl.cli import render
    from quadctl.cli.options import load_config
    from quadctl.errors import ConfigError

    if schema and show is not None:
        raise ConfigError(f"--schema with --show {show or repr(show)}: one prints the schema of every config, the "
                          "other one config; give one of the two")
    if sets and show is None:
        raise ConfigError("--set changes the config --show prints; give --show NAME with it")
    if schema:
        import json

        typer.echo(json.dumps(config.json_schema(), indent=2))
        return
    if show is not None:  # '' too: refused by name, not taken for no --show
        cfg, label = load_config(show, sets, plausible=False)
        typer.echo(config.shown_yaml(cfg, label), nl=False)  # raw: rich would wrap long lines
        return
    from rich.table import Table

    table = Table(title="Bundled configs (use with --config NAME)", title_justify="left")
    table.add_column("name")
    table.add_column("description")
    for name in config.bundled_names():
        source = config.bundled(name)  # the bundled one, whatever files of that name are here
        table.add_row(name, config.parse(source.text, source.label).description)
    render.out.print(table)
