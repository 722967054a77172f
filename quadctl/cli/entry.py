"""The console script: the app imported inside a guard, so Ctrl-C at any moment ends with one line.

A Ctrl-C that lands while Python imports typer and the commands (the first ~0.2 s) would otherwise
print a traceback from deep inside an import.
"""

from __future__ import annotations

import gc
import sys


def main() -> None:
    """Console-script entry point (``quadctl``, ``python -m quadctl``).

    However the command ends, the objects still alive are then left out of the garbage collections
    Python runs as it exits (``gc.freeze``): the process ends anyway, and those collections walked
    every object the imports made (NumPy, pydantic's schemas, rich, typer). Exit handlers still run,
    files still close.
    """
    try:
        from quadctl.cli.app import app

        app(prog_name="quadctl")
    except KeyboardInterrupt:
        sys.stderr.write("quadctl: error: interrupted\n")
        sys.exit(130)
    finally:
        gc.freeze()
