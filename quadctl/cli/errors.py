"""The one place that maps exceptions to exit codes and one-line messages."""

from __future__ import annotations

import contextlib
import contextvars
import functools
import inspect
import os
import sys
import warnings

import typer

EXIT_OK = 0
EXIT_CHECK_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERNAL = 3
EXIT_INTERRUPTED = 130

EXIT_CODES_HELP = (
    "Exit codes: 0 success; 1 a check failed (rank, stability, divergence, a sweep gate); "
    "2 bad input (config, options, files); 3 internal error (a bug: please report it); "
    "130 interrupted."
)


def debug_enabled(ctx: typer.Context | None) -> bool:
    """``--debug`` on the command line (the root context's ``obj``) or ``QUADCTL_DEBUG=1``."""
    if os.environ.get("QUADCTL_DEBUG") == "1":
        return True
    root = ctx.find_root() if ctx is not None else None
    return bool(root is not None and isinstance(root.obj, dict) and root.obj.get("debug"))


def fail(message: str, code: int) -> typer.Exit:
    """Print the one stderr line of a failure and return the Exit to raise: ``quadctl: check failed:``
    for a check that failed (exit 1, as ``check`` and ``run`` print it), else ``quadctl: error:``."""
    from quadctl.messages import one_line

    kind = "check failed" if code == EXIT_CHECK_FAILED else "error"
    typer.echo(f"quadctl: {kind}: {one_line(message)}", err=True)
    return typer.Exit(code)


@contextlib.contextmanager
def notices_printed():
    """Print each :class:`quadctl.errors.QuadctlNotice` the library issues as one ``note`` line, once."""
    from quadctl.errors import QuadctlNotice

    seen: set[str] = set()
    original = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, QuadctlNotice):
            return original(message, category, filename, lineno, file, line)
        text = " ".join(str(message).split())
        if text not in seen:
            seen.add(text)
            from quadctl.cli import render

            render.note(text)

    with warnings.catch_warnings():
        warnings.simplefilter("always", QuadctlNotice)
        warnings.showwarning = show
        yield
_COMMAND: contextvars.ContextVar[dict] = contextvars.ContextVar("quadctl_command")
"""What the running command has learnt that its error message needs (the config file); set by
:func:`handled` for the length of one command."""


def remember_config(label: str) -> None:
    """Note the config file this command reads, so that :func:`handled` can name it in an error
    that comes from the config's values but not from the file's text (no trim, an RK4 step)."""
    state = _COMMAND.get(None)
    if state is not None:
        state["config"] = label


def message_of(exc) -> str:
    """The error's message, with the config file in front when the config caused it."""
    text = str(exc)
    label = (_COMMAND.get(None) or {}).get("config")
    if label and getattr(exc, "from_config", False) and not text.startswith(f"{label}:"):
        text = f"{label}: {text}"
    return text


def _traceback() -> None:
    """``--debug``: the traceback of the error being handled, on stderr, before its one line."""
    import traceback

    traceback.print_exc(file=sys.stderr)


def handled(fn):
    """Decorate a command: QuadctlError -> its exit code and one line on stderr, no traceback."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from quadctl.errors import QuadctlError

        ctx = kwargs.pop(_CTX, None)
        token = _COMMAND.set({})
        try:
            with notices_printed():
                return fn(*args, **kwargs)
        except (typer.Exit, typer.Abort, SystemExit):
            raise
        except QuadctlError as exc:  # the class decides the exit code, with or without --debug
            if debug_enabled(ctx):
                _traceback()
            raise fail(message_of(exc), exc.exit_code) from None
        except BrokenPipeError:  # `quadctl ... --json | head`: the reader left; the work is saved
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            raise typer.Exit(EXIT_OK) from None
        except KeyboardInterrupt:
            raise fail("interrupted; artifacts written before this point are complete",
                       EXIT_INTERRUPTED) from None
        except Exception as exc:  # a bug: say so in one line, traceback on --debug
            if debug_enabled(ctx):
                _traceback()
            where = ""
            tb = sys.exc_info()[2]
            while tb and tb.tb_next:
                tb = tb.tb_next
            if tb:
                where = f" at {os.path.basename(tb.tb_frame.f_code.co_filename)}:{tb.tb_lineno}"
            raise fail(f"internal error {type(exc).__name__}: {exc}{where}; "
                       "rerun with --debug for the traceback and please report it",
                       EXIT_INTERNAL) from None
        finally:
            _COMMAND.reset(token)

    # typer hands the context to a parameter annotated typer.Context: add one to the signature
    sig = inspect.signature(fn)
    ctx_param = inspect.Parameter(_CTX, inspect.Parameter.KEYWORD_ONLY, annotation=typer.Context)
    wrapper.__signature__ = sig.replace(parameters=[*sig.parameters.values(), ctx_param])
    return wrapper


_CTX = "quadctl_context"
