"""How a command is stopped from outside: Ctrl-C (SIGINT) and SIGTERM, answered alike, and their exit
codes. Imports nothing of quadctl: the console script's guard (:mod:`quadctl.cli.entry`) and the
commands' error handling (:mod:`quadctl.cli.errors`) both read it."""

from __future__ import annotations

import contextlib
import os
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


_RECORDING: dict[int, object] = {}
"""The handlers :func:`stops_recorded` stands in front of, by signal, while it records."""


def _handlers_back_in_child() -> None:
    """A process forked while a command records its stops (a sweep's worker) is not that command: it takes
    the handlers back that the recording stood in front of (then SIGTERM's default, :mod:`quadctl.cli.entry`)."""
    for signum, previous in _RECORDING.items():
        signal.signal(signum, previous)
    _RECORDING.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_handlers_back_in_child)


@contextlib.contextmanager
def stops_recorded():
    """Record each Ctrl-C and SIGTERM that reaches the block (its handler still runs: the stop is raised
    as before) and yield the list of their signal numbers. A stop can land where a library takes it for
    its own error: CasADi's Python wrapper, interrupted while it converts a call's arguments, raises
    ``NotImplementedError: Wrong number or type of arguments`` (or returns None), and the command went
    on to fail with that error, or finished, rather than stop. With the record, the command ends as
    stopped either way (:func:`quadctl.cli.errors.handled`). Only in the main thread (Python runs
    handlers there only), and only over a handler Python can call (not one ignored or the default); a
    process forked meanwhile has the handlers from before."""
    received: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return
    chained, owner = {}, os.getpid()
    for signum in (signal.SIGINT, signal.SIGTERM):
        previous = signal.getsignal(signum)
        if not callable(previous) or signum in _RECORDING:
            continue

        def recorded(signum, frame, previous=previous):
            if os.getpid() != owner and signum == signal.SIGTERM:
                # a process forked meanwhile, stopped (a pool ends its workers so) before it took its handlers
                # back: it ends as SIGTERM's default ends it, not with an exception in its fork hooks
                signal.signal(signum, signal.SIG_DFL)
                os.kill(os.getpid(), signum)
                return
            received.append(signum)
            previous(signum, frame)

        try:
            signal.signal(signum, recorded)
        except (OSError, ValueError):
            continue
        chained[signum] = previous
    _RECORDING.update(chained)
    try:
        yield received
    finally:
        for signum, previous in chained.items():
            signal.signal(signum, previous)
            _RECORDING.pop(signum, None)


def stop_of(received: list[int]) -> KeyboardInterrupt:
    """The stop to raise for the signals ``received`` (:func:`stops_recorded`): :class:`Terminated`
    when a SIGTERM came, else a Ctrl-C's KeyboardInterrupt."""
    return Terminated() if signal.SIGTERM in received else KeyboardInterrupt()
