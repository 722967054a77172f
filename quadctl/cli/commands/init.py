from pathlib import Path
from typing import Annotated

import typer

from quadctl.cli.options import JsonOpt, force_option

NAME = "init"


def command(
    name: Annotated[str, typer.Argument(metavar="NAME", help="Your vehicle's config name: writes NAME.yaml here.")],
    vehicle: Annotated[str, typer.Option(
        "--from", metavar="crazyflie|mambo|iris",
        help="The vehicle whose published values fill vehicle:, motors: and the controller rate.")] = "crazyflie",
    flight: Annotated[str, typer.Option(
        "--flight", metavar="hold|hover|forward",
        help="The flight condition: its trim and the partition that fits it (hold: hover holding position; "
             "hover: the position left free; forward: 1 m/s north).")]
        = "hold",
    force: force_option("NAME.yaml if it exists") = False,
    json: JsonOpt = False,
) -> None:
    """Start a config for your own vehicle: NAME.yaml, every key with its unit, a named vehicle's values
    (with their sources) to replace with yours. Then: quadctl run -c NAME.yaml."""
    from quadctl.cli import render
    from quadctl.config import template
    from quadctl.errors import ConfigError

    text = template.config_text(name, vehicle, flight)
    path = Path(f"{name}.yaml")
    if path.exists() and not force:
        raise ConfigError(f"{path}: already exists; pass --force to overwrite it, or choose another NAME")
    _write_atomically(path, text)
    if json:
        render.emit_json({"file": str(path), "vehicle": vehicle, "flight": flight})
        return
    render.out.print(f"wrote {path}: {template.PRESETS[vehicle].title}, {flight}; replace its numbers with your "
                     f"vehicle's, then: quadctl run -c {path}", markup=False, soft_wrap=True)


def _write_atomically(path: Path, text: str) -> None:
    """A temporary beside ``path``, renamed over it: never a half-written config."""
    import os
    import tempfile

    from quadctl.errors import ArtifactError

    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except OSError as exc:
        if "tmp" in locals():
            Path(tmp).unlink(missing_ok=True)
        raise ArtifactError(f"{path}: cannot write it ({exc.strerror or exc}); run quadctl init in a folder you "
                            "can write to") from None
