"""Options shared by the commands, and the workspace they open."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

ConfigOpt = Annotated[Optional[str], typer.Option(
    "--config", "-c", metavar="PATH|NAME",
    help="Config file, or the name of a bundled config (see `quadctl configs`). "
         "Default: forward, the report's case.")]


def nonempty_path(way_out: str):
    """A typer ``parser`` taking an option's value as a path and refusing an empty one (a path of '' would
    be the current folder): ``an empty path; <way_out>``."""
    def parsed(text: str) -> Path:
        if not text.strip():
            raise typer.BadParameter(f"an empty path; {way_out}")
        return Path(text)

    return parsed


out_folder = nonempty_path("give the run directory, or leave -o out for runs/<config name>")
"""``--out``'s parser."""

OutOpt = Annotated[Optional[Path], typer.Option(
    "--out", "-o", metavar="DIR", parser=out_folder,
    help="Run directory for artifacts. Default: runs/<config name>.")]
JsonOpt = Annotated[bool, typer.Option(
    "--json", help="Print machine-readable JSON to stdout instead of tables.")]
FreshOpt = Annotated[bool, typer.Option(
    "--fresh", help="Recompute every stage; ignore artifacts already in the run directory.")]
AllowSaturationOpt = Annotated[bool, typer.Option(
    "--allow-saturation", help="Accept a design at an actuator limit more than half the run (else exit 1); "
                               "the config's `allow: \\[saturation]` does the same.")]  # \\[: not rich markup
PlotOpt = Annotated[bool, typer.Option("--plot", help="Also write PNG figures to DIR/plots/.")]
SET_HELP = ("Change one config value without editing the file: a key path and a YAML value "
            "(--set simulation.duration=30, --set vehicle.inertia=[0.02,0.02,0.04]); repeatable, "
            "validated as the file is")


def set_option(after: str):
    """``--set KEY=VALUE`` (repeatable), its help ending with ``after``: what becomes of the values."""
    return Annotated[Optional[list[str]], typer.Option("--set", metavar="KEY=VALUE", help=f"{SET_HELP}; {after}")]


SetOpt = set_option("recorded in DIR/config.yaml.")
"""``--set`` of a command that writes a run directory (DIR): the values are recorded there."""


def force_option(what: str):
    """``--force``: write over ``what``, a file of the user's that the command otherwise refuses to replace
    (one line, exit 2, naming ``--force``)."""
    return Annotated[bool, typer.Option("--force", help=f"Write over {what}.")]


def flags_without_placeholder(command_cls):
    """A typer command (or group) class whose boolean flags show no value placeholder in ``--help``.

    typer 0.29 writes the type of every option beside it, a flag's too (``--plot <bool>``,
    ``--help -h <bool>``), which reads as if the flag took a value (``--plot true`` is refused): an
    empty metavar, given here to every flag of every command and of the app, shows nothing there.
    """

    class FlagsWithoutPlaceholder(command_cls):
        def get_params(self, ctx):
            params = super().get_params(ctx)
            for param in params:
                if getattr(param, "is_flag", False) and param.metavar is None:
                    param.metavar = ""
            return params

    return FlagsWithoutPlaceholder


def help_into_a_closed_pipe(command_cls):
    """A typer command (or group) class whose ``--help`` into a pipe the reader has closed
    (``quadctl --help | head -1``) ends the output and exits 0, as a command's own output does
    (:meth:`quadctl.cli.render._Stdout.on_broken_pipe`). rich, which prints typer's help, answers the
    ``BrokenPipeError`` by sending stdout to the null device and raising ``SystemExit(1)``: a failure
    under ``set -o pipefail`` in a CI job. That exit, and only that one, is dropped here."""

    class HelpIntoAClosedPipe(command_cls):
        def format_help(self, ctx, formatter):
            try:
                return super().format_help(ctx, formatter)
            except SystemExit as exc:
                if not isinstance(exc.__context__, BrokenPipeError):
                    raise

    return HelpIntoAClosedPipe


def rate_option(help: str):
    """``--rate HZ``: stands for ``controller.rate`` (:data:`quadctl.config.OVERRIDES`); its bounds
    are that key's, checked by :func:`override` in the command (not typer's ``min``/``max``)."""
    return Annotated[Optional[float], typer.Option("--rate", metavar="HZ", help=help)]


def override(option: str, value):
    """A command-line ``value`` that stands for a config key, checked against that key's own
    declaration (:func:`quadctl.config.check_override`: the same bounds and words as in a file);
    None stays None.

    Raises
    ------
    ConfigError
        One line naming the option, the value, the bound and the key (exit 2).
    """
    if value is None:
        return None
    from quadctl import config

    return config.check_override(option, value)


def load_config(config: str | None, sets=None, *, plausible: bool = True):
    """Resolve and load ``--config`` with its ``--set`` values; print its notes and warnings on
    stderr, one line each.

    Returns
    -------
    (Config, str) : the validated config and the file to name in messages.
    """
    cfg, source = load_source(config, sets, plausible=plausible)
    return cfg, label_of(source, sets)


def label_of(source, sets=None) -> str:
    """How messages name the config: its file (or bundled name), ``with --set`` when a value named may be one
    ``--set`` gave."""
    return f"{source.label} with --set" if sets else source.label


def load_source(config: str | None, sets=None, *, plausible: bool = True):
    """:func:`load_config`, returning the config and its :class:`quadctl.config.Source` (label, text:
    the file's, with the ``--set`` values after it as comments).

    With ``plausible`` (every command that computes), a warning on the config's values (a likely unit
    slip) stops the command with exit 1 after the warnings, unless the config says ``allow: [implausible]``.
    """
    from quadctl import config as config_mod
    from quadctl.cli.errors import remember_config
    from quadctl.config import overrides

    source = config_mod.locate(config)
    if source.note:
        _render().note(source.note)
    cfg = overrides.load(source, sets or ())
    label = label_of(source, sets)
    remember_config(label)
    noticed(cfg, label, plausible=plausible)
    return cfg, source._replace(text=overrides.recorded(source.text, sets or ()))


def noticed(cfg, label: str, *, plausible: bool = True) -> None:
    """Print the config's notes and warnings on stderr, one line each (:func:`quadctl.config.notices.notices`);
    with ``plausible``, a warning (a likely unit slip) then stops the command with exit 1, unless the config
    says ``allow: [implausible]`` (:func:`quadctl.config.notices.require_plausible`)."""
    from quadctl.config import notices

    found = notices.notices(cfg, label)
    for notice in found:
        (_render().note if notice.level == "note" else _render().warning)(notice.message)
    if plausible:
        notices.require_plausible(cfg, found, label)


def _render():
    """:mod:`quadctl.cli.render`, imported when a note is printed: a sweep's worker processes start
    before it is needed (it takes rich)."""
    from quadctl.cli import render

    return render


def open_workspace(config: str | None, out: Path | None, fresh: bool = False, sets=None):
    """Load the config (with its ``--set`` values) and open its run directory for the stages."""
    from quadctl.workspace import Workspace

    cfg, source = load_source(config, sets)
    return remembered(Workspace(cfg, out, fresh=fresh, source_text=source.text))


def open_session(cfg, source, out: Path | None):
    """Open the run directory of ``cfg`` (loaded from ``source``, :func:`load_source`) for a command that
    writes without the stages (a sweep, an export): its config beside what it writes, another config's run
    there removed, the folder put back when the command fails (:class:`quadctl.artifacts.Session`)."""
    from quadctl.artifacts import Session

    return remembered(Session(cfg, out, source_text=source.text))


def remembered(session):
    """``session``, the command's (:func:`quadctl.cli.errors.remember_session`): put back when the command
    fails, released when it ends."""
    from quadctl.cli.errors import remember_session

    remember_session(session)
    return session
