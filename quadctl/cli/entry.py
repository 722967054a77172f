"""The console script: the app imported inside a guard, so Ctrl-C at any moment ends with one line.

A Ctrl-C that lands while Python imports typer and the commands (the first ~0.2 s) would otherwise
print a traceback from deep inside an import.
"""

from __future__ import annotations

import sys


def main() -> None:
    """Console-script entry point (``quadctl``, ``python -m quadctl``)."""
    try:
        from quadctl.cli.app import app

        app(prog_name="quadctl")
    except KeyboardInterrupt:
        sys.stderr.write("quadctl: error: interrupted\n")
        sys.exit(130)
