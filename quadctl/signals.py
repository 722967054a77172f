"""Ctrl-C and SIGTERM held back while a block runs that must not be cut short (a folder put back, a
compiled module's initialization), then taken. Imports nothing of quadctl and nothing heavy: the
console script's guard uses it before the commands load."""

from __future__ import annotations

import contextlib
import signal
import threading


@contextlib.contextmanager
def signals_held():
    """Ctrl-C and SIGTERM wait until the block is done (in the main thread; Python takes signals there
    only): each is recorded by a handler of this block meanwhile, then raised again under the handler
    it had (one ignored stays ignored), so a signal leaves no folder half put back and no
    compiled module half made. (Masking them would not do: a
    thread BLAS started, not masked, takes the signal, and Python still runs its handler.)"""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    held = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        try:
            held[signum] = signal.signal(signum, lambda s, _: caught.append(s))
        except (OSError, ValueError):
            continue
    try:
        yield
    finally:
        for signum, handler in held.items():
            signal.signal(signum, handler if handler is not None else signal.SIG_DFL)
        for signum in dict.fromkeys(caught):
            signal.raise_signal(signum)
