from pathlib import Path
from typing import Annotated

import typer

NAME = "init"


def command(
    name: Annotated[str, typer.Argument(metavar="NAME", help="Your vehicle's config name: writes NAME.yaml here.")],
    vehicle: Annotated[str, typer.Option(
        "--from", metavar="crazyflie|mambo|iris",
        help="The vehicle whose published values fill vehicle:, motors: and the controller rate.")] = "crazyflie",
    flight: Annotated[str, typer.Option(
        "--flight", metavar="hover|forward", help="The flight condition: its trim and the partition that fits it.")]
        = "hover",
    force: Annotated[bool, typer.Option("--force", help="Overwrite NAME.yaml if it exists.")] = False,
) -> None:
    """Start a config for your own vehicle: NAME.yaml, every key with its unit, a named vehicle's values
    (with their sources) to replace with yours. Then: quadctl run -c NAME.yaml."""
    from quadctl import artifacts, starter
    from quadctl.cli import render
    from quadctl.errors import ConfigError

    text = starter.config_text(name, vehicle, flight)
    path = Path(f"{name}.yaml")
    if path.exists() and not force:
        raise ConfigError(f"{path}: already exists; pass --force to overwrite it, or choose another NAME")
    artifacts.write_bytes(path, text.encode())
    render.out.print(f"wrote {path}: {starter.PRESETS[vehicle].title}, {flight}; replace its numbers with your "
                     f"vehicle's, then: quadctl run -c {path}", markup=False, soft_wrap=True)
