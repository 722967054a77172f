"""The console script: the app imported inside a guard, so Ctrl-C at any moment ends with one line;
SIGTERM (``timeout``, a cancelled CI job, ``docker stop``) is answered as Ctrl-C is.

A Ctrl-C that lands while Python imports typer and the commands (the first ~0.2 s) would otherwise
print a traceback from deep inside an import; one inside a compiled module's initialization would
leave it half made (:func:`extensions_initialize_whole`).
"""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import sys
import threading

from quadctl.cli.columns import usable_columns
from quadctl.cli.stops import EXIT_INTERRUPTED, EXIT_TERMINATED, Terminated, raise_terminated
from quadctl.signals import signals_held


def main() -> None:
    """Console-script entry point (``quadctl``, ``python -m quadctl``).

    However the command ends, the objects still alive are then left out of the garbage collections
    Python runs as it exits (``gc.freeze``): the process ends anyway, and those collections walked
    every object the imports made (NumPy, pydantic's schemas, rich, typer). Exit handlers still run,
    files still close; but after a Ctrl-C that cut an import short
    (:data:`quadctl.cli.progress.IMPORTS_CUT_SHORT`), once the command's own cleanup is done, the
    process leaves at once.
    """
    usable_columns()
    _unencodable_replaced()
    _drawing_into_files()
    try:
        with extensions_initialize_whole():
            _terminate_as_interrupt()
            from quadctl.cli.app import app

            app(prog_name="quadctl")
    except KeyboardInterrupt as exc:
        sys.stderr.write(f"quadctl: error: {'terminated' if isinstance(exc, Terminated) else 'interrupted'}\n")
        _leave(EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED)
    except SystemExit as exc:
        if _cut_short():
            _leave(exc.code)
        raise
    finally:
        gc.freeze()


def _drawing_into_files() -> None:
    """``MPLBACKEND=agg`` before matplotlib is imported. quadctl draws every figure into a file through Agg
    and never opens a window, so the backend an environment names is never used; but matplotlib checks it
    on import, and one it does not know (``MPLBACKEND=bogus``, a backend of another environment) made every
    command that draws an internal error (exit 3)."""
    os.environ["MPLBACKEND"] = "agg"


def _unencodable_replaced() -> None:
    """A character stdout's encoding cannot carry is printed as ``?``, where Python would raise in the
    middle of a table: a stdout in ASCII or Latin-1 (``PYTHONIOENCODING``, a Latin-1 locale) or cp1252
    (Windows, redirected to a file) has no ``✓`` of ``run``, no ``·`` of ``design``, no ``±`` of
    ``margins``, no ``ö`` of ``configs``. A UTF-8 stdout carries every character but the bytes of a path
    that are not UTF-8 (``runs/\xff``, read from the command line as surrogates): those are written back
    as they were given, as Python does in the C locale. stdout only, and only when it would raise: stderr's
    own default (``backslashreplace``) already never raises, and ``--json`` output is ASCII."""
    import codecs
    import io

    if isinstance(sys.stdout, io.TextIOWrapper) and sys.stdout.errors == "strict":
        utf8 = codecs.lookup(sys.stdout.encoding).name == "utf-8"
        sys.stdout.reconfigure(errors="surrogateescape" if utf8 else "replace")


def _terminate_as_interrupt() -> None:
    """Answer SIGTERM as Ctrl-C, in the main thread, unless SIGTERM is ignored or already handled
    (a process that set its own handler keeps it). A process forked from here (a sweep's worker, a
    figure drawer) takes SIGTERM's default back at once, before any of its own code runs: the pool
    stops a worker with SIGTERM, which must end it, not raise in it."""
    if threading.current_thread() is threading.main_thread() and \
            signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        signal.signal(signal.SIGTERM, raise_terminated)
        if hasattr(os, "register_at_fork"):
            os.register_at_fork(after_in_child=_default_sigterm)


def _default_sigterm() -> None:
    if signal.getsignal(signal.SIGTERM) is raise_terminated:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _cut_short() -> list[str]:
    """The imports a Ctrl-C cut short in this process (:data:`quadctl.cli.progress.IMPORTS_CUT_SHORT`;
    none where that module never loaded)."""
    progress = sys.modules.get("quadctl.cli.progress")
    return progress.IMPORTS_CUT_SHORT if progress is not None else []


def _leave(code) -> None:
    """Exit with ``code`` (as ``sys.exit`` takes it): after an import cut short, at once
    (:func:`_cut_short`)."""
    if not _cut_short():
        sys.exit(code)
    if code is not None and not isinstance(code, int):  # a message: sys.exit prints it and exits 1
        sys.stderr.write(f"{code}\n")
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(0 if code is None else code if isinstance(code, int) else 1)


@contextlib.contextmanager
def extensions_initialize_whole():
    """Compiled extension modules imported in the block initialize whole: a Ctrl-C that lands in one's
    initialization is taken when it ends, one that lands elsewhere at once.

    The commands import much late (a sweep imports matplotlib while its workers compute). Interrupted
    inside the initialization of a compiled module (pybind11's, matplotlib's: it runs Python, where the
    KeyboardInterrupt lands), the module was left half made: the command ended in "internal error
    ImportError: initialization failed" instead of "interrupted". An initialization takes
    milliseconds; the Python around it stays interruptible, so a Ctrl-C is still answered at once.
    In the main thread (:func:`quadctl.signals.signals_held`); a signal ignored stays ignored (a sweep's
    worker ignores Ctrl-C).
    """
    from importlib.machinery import ExtensionFileLoader

    create, execute = ExtensionFileLoader.create_module, ExtensionFileLoader.exec_module

    def create_whole(self, spec):
        with signals_held():
            return create(self, spec)

    def execute_whole(self, module):
        with signals_held():
            return execute(self, module)

    ExtensionFileLoader.create_module, ExtensionFileLoader.exec_module = create_whole, execute_whole
    try:
        yield
    finally:
        ExtensionFileLoader.create_module, ExtensionFileLoader.exec_module = create, execute
