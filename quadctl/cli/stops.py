"""How a command is stopped from outside: Ctrl-C (SIGINT) and SIGTERM, answered alike, and their exit
codes. Imports nothing of quadctl: the console script's guard (:mod:`quadctl.cli.entry`) and the
commands' error handling (:mod:`quadctl.cli.errors`) both read it."""

from __future__ import annotations

import contextlib
import signal
import threading

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




@contextlib.contextmanager
def stops_recorded():
    """Record each Ctrl-C and SIGTERM that reaches the block (its handler still runs: the stop is raised
    as before) and yield the list of their signal numbers. A stop can land where a library takes it for
    its own error: CasADi's Python wrapper, interrupted while it converts a call's arguments, raises
    ``NotImplementedError: Wrong number or type of arguments`` (or returns None), and the command went
    on to fail with that error, or finished, rather than stop. With the record, the command ends as
    stopped either way (:func:`quadctl.cli.errors.handled`). Only in the main thread (Python runs
    handlers there only), and only over a handler Python can call (not one ignored or the default)."""
    received: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return
    chained = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        previous = signal.getsignal(signum)
        if not callable(previous):
            continue

        def recorded(signum, frame, previous=previous):
            received.append(signum)
            previous(signum, frame)

        try:
            signal.signal(signum, recorded)
        except (OSError, ValueError):
            continue
        chained[signum] = previous
    try:
        yield received
    finally:
        for signum, previous in chained.items():
            signal.signal(signum, previous)


def stop_of(received: list[int]) -> KeyboardInterrupt:
    """The stop to raise for the signals ``received`` (:func:`stops_recorded`): :class:`Terminated`
    when a SIGTERM came, else a Ctrl-C's KeyboardInterrupt."""
    return Terminated() if signal.SIGTERM in received else KeyboardInterrupt()
