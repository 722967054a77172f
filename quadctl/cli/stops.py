"""How a command is stopped from outside: Ctrl-C (SIGINT) and SIGTERM, answered alike, and their exit
codes. Imports nothing of quadctl: the console script's guard (:mod:`quadctl.cli.entry`) and the
commands' error handling (:mod:`quadctl.cli.errors`) both read it."""

from __future__ import annotations

import signal

EXIT_INTERRUPTED = 130
"""The exit code of a command stopped by Ctrl-C (SIGINT), as a shell reports one the signal ended."""
EXIT_TERMINATED = 128 + signal.SIGTERM
"""The exit code of a command stopped by SIGTERM (143)."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Python takes a Ctrl-C: the command stops as on Ctrl-C (a run folder
    it had changed is put back, a sweep keeps its finished chunks and stops its workers), and says
    ``terminated``."""


def raise_terminated(signum, frame) -> None:
    raise Terminated


