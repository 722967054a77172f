"""The one place that maps exceptions to exit codes and one-line messages."""

from __future__ import annotations

import contextlib
import contextvars
import functools
import inspect
import os
import re
import shlex
import sys
import warnings

import typer

from quadctl.cli.stops import EXIT_INTERRUPTED, EXIT_TERMINATED, Terminated, stop_of, stops_recorded

EXIT_OK = 0
EXIT_CHECK_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERNAL = 3

EXIT_CODES_HELP = (
    "Exit codes: 0 success; 1 a check failed (rank, stability, divergence, a mission not flown, a sweep gate, "
    "a unit slip, saturation, an identified value not physically possible); 2 bad input (config, options, files); "
    "3 internal error (a bug: please report it); "
    "130 interrupted (Ctrl-C); 143 terminated (SIGTERM)."
)


def debug_enabled(ctx: typer.Context | None) -> bool:
    """``--debug`` on the command line (the root context's ``obj``) or ``QUADCTL_DEBUG=1``."""
    if os.environ.get("QUADCTL_DEBUG") == "1":
        return True
    root = ctx.find_root() if ctx is not None else None
    return bool(root is not None and isinstance(root.obj, dict) and root.obj.get("debug"))


class FailedChecks(Exception):
    """What a command raises when its checks fail (valid input, a design that fails a check).

    The command decides *that* they failed and why; :func:`handled` prints one
    ``quadctl: check failed: <reason>`` line per reason on stderr and exits
    :data:`EXIT_CHECK_FAILED`: the exit code is decided here, not in each command.
    """

    def __init__(self, *reasons: str):
        super().__init__(*reasons)
        self.reasons = reasons


def fail(message: str, code: int) -> typer.Exit:
    """Print the one stderr line of a failure and return the Exit to raise: ``quadctl: check failed:``
    for a check that failed (exit 1, as ``check`` and ``run`` print it), else ``quadctl: error:``."""
    from quadctl.text.messages import one_line

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


def remember_session(session) -> None:
    """Note the session of the run folder this command writes (:class:`quadctl.artifacts.Session`, a
    :class:`~quadctl.workspace.Workspace`), so that :func:`handled` can put the folder back when the command
    refuses its input (exit 2) after it wrote there (:meth:`~quadctl.artifacts.Session.roll_back`), and
    release it when the command ends."""
    state = _COMMAND.get(None)
    if state is not None:
        state["session"] = session
        session.defer_notes()  # said when the command ends, and not at all of what a refusal puts back


def remember_interrupt_hint(hint: str) -> None:
    """Note what a user can do after Ctrl-C (or SIGTERM) stops this command with its work kept: ``handled``
    adds it to the ``interrupted`` line (a sweep's ``--resume``); not when the folder was put back."""
    state = _COMMAND.get(None)
    if state is not None:
        state["interrupt_hint"] = hint


def _roll_back() -> None:
    session = (_COMMAND.get(None) or {}).get("session")
    if session is not None:
        session.roll_back()


def _put_back_a_replaced_run() -> bool:
    """A command stopped (Ctrl-C, SIGTERM, a bug) after it removed another config's artifacts and before it
    wrote each of them again for its own (:attr:`~quadctl.artifacts.Session.unreplaced`): put the folder back as
    the earlier run left it (:meth:`~quadctl.artifacts.Session.roll_back`), which is whole, rather than leave half
    of each. True if it did."""
    state = _COMMAND.get(None) or {}
    session = state.get("session")
    if session is None or not session.unreplaced:
        return False
    from quadctl.artifacts import SWEEP_PARTS

    chunks = sum(1 for path in session.written if path.parent.name == SWEEP_PARTS)  # a sweep's finished work
    if not session.roll_back():
        return False
    state["put_back"] = True
    state["chunks_gone"] = chunks
    return True


def _release_session() -> None:
    """The command is over: its run folder is released (its lock, the files it set aside) and its held-back
    notices said, not left to the garbage collector of a process that goes on."""
    session = (_COMMAND.get(None) or {}).get("session")
    if session is not None:
        session.close()


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
            with notices_printed(), stops_recorded() as stops:
                try:
                    try:
                        result = fn(*args, **kwargs)
                    except Exception as exc:  # whatever a stop caused where a library took it for its own
                        if stops:  # error (CasADi's wrapper): the stop
                            raise stop_of(stops) from exc
                        raise
                    if stops:  # a stop a library took for its own and the command outlived: it ends stopped
                        raise stop_of(stops)
                    return result
                except QuadctlError as exc:
                    if exc.exit_code == EXIT_BAD_INPUT:  # refused: the run folder as it was
                        _roll_back()
                    raise
                except KeyboardInterrupt:
                    _put_back_a_replaced_run()
                    raise
                except (typer.Exit, typer.Abort, FailedChecks, BrokenPipeError):
                    raise
                except Exception:  # a bug (exit 3): the run folder as Ctrl-C would leave it
                    _put_back_a_replaced_run()
                    raise
                finally:  # within the notices: those the session held back are said (before the error)
                    _release_session()
        except (typer.Exit, typer.Abort, SystemExit):
            raise
        except FailedChecks as verdict:  # a verdict, not an error: no traceback with --debug
            exits = [fail(reason, EXIT_CHECK_FAILED) for reason in verdict.reasons]
            raise exits[-1] from None
        except QuadctlError as exc:  # the class decides the exit code, with or without --debug
            if debug_enabled(ctx):
                _traceback()
            raise fail(message_of(exc), exc.exit_code) from None
        except BrokenPipeError:  # `quadctl ... --json | head`: the reader left; the work is saved
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            raise typer.Exit(EXIT_OK) from None
        except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM (quadctl.cli.stops.Terminated)
            stopped, code = ("terminated", EXIT_TERMINATED) if isinstance(exc, Terminated) else \
                ("interrupted", EXIT_INTERRUPTED)
            if (_COMMAND.get(None) or {}).get("put_back"):
                chunks = (_COMMAND.get(None) or {}).get("chunks_gone", 0)
                lost = (f"; the {chunks} chunk{'s' * (chunks != 1)} this sweep finished went with them, so "
                        "--resume cannot take them up" if chunks else "")
                raise fail(f"{stopped}; the run folder is as the earlier config's run left it (this one's "
                           f"artifacts were not all written{lost})", code) from None
            hint = (_COMMAND.get(None) or {}).get("interrupt_hint")
            raise fail(f"{stopped}; artifacts written before this point are complete"
                       + (f"; {hint}" if hint else ""), code) from None
        except Exception as exc:  # a bug: say so in one line, traceback on --debug
            if debug_enabled(ctx):
                _traceback()
            where = ""
            tb = sys.exc_info()[2]
            while tb and tb.tb_next:
                tb = tb.tb_next
            if tb:
                where = f" at {os.path.basename(tb.tb_frame.f_code.co_filename)}:{tb.tb_lineno}"
            put_back = ("; the run folder is as the earlier config's run left it"
                        if (_COMMAND.get(None) or {}).get("put_back") else "")
            raise fail(f"internal error {type(exc).__name__}: {exc}{where}{put_back}; "
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


def _click_exceptions():
    """The click exceptions module typer raises from (its own vendored copy in newer typers)."""
    import importlib

    return importlib.import_module(typer.BadParameter.__module__)


def _number(text: str) -> str:
    """``0.000000001`` -> ``1e-09``: every decimal number in ``text`` in its shortest form."""
    import re

    def short(m):
        shown = f"{float(m.group()):g}"
        return shown if len(shown) < len(m.group()) else m.group()

    return re.sub(r"(?<![\w.])\d+\.\d+(?![\w.])", short, text)


def _given(args, opts) -> str | None:
    """The value the command line gave an option (``--rate -5``, ``--rate=-5``, ``-j0``), or None."""
    found = None
    args = list(args)
    for i, tok in enumerate(args):
        for opt in opts:
            if tok == opt and i + 1 < len(args):
                found = args[i + 1]
            elif opt.startswith("--") and tok.startswith(opt + "="):
                found = tok[len(opt) + 1:]
            elif not opt.startswith("--") and tok.startswith(opt) and len(tok) > len(opt):
                found = tok[len(opt):]
    return found


def _range_of(param) -> tuple:
    """(min, max) of a numeric option (typer's own attributes, or click's range type), else Nones."""
    for holder in (param, getattr(param, "type", None)):
        lo, hi = getattr(holder, "min", None), getattr(holder, "max", None)
        if lo is not None or hi is not None:
            return lo, hi
    return None, None


def _is_numeric(param) -> bool:
    """Whether an option takes a number (click's FLOAT or INT type, or typer's type descriptor)."""
    kind = getattr(getattr(param, "type", None), "name", "")
    annotation = getattr(getattr(param, "type_descriptor", None), "annotation", None)
    return kind in ("float", "integer") or annotation in (float, int)


def _is_integer(param) -> bool:
    """Whether an option takes a whole number (click's INT type, or typer's type descriptor)."""
    kind = getattr(getattr(param, "type", None), "name", "")
    return kind == "integer" or getattr(getattr(param, "type_descriptor", None), "annotation", None) is int


def _choices_of(param) -> list[str]:
    """The values a choice option takes (click's Choice type, or typer's type descriptor)."""
    for holder in (getattr(param, "type", None), getattr(param, "type_descriptor", None)):
        choices = getattr(holder, "choices", None)
        if choices:
            return [str(getattr(c, "value", c)) for c in choices]
    return []


def usage_message(exc, args, command: str = "quadctl") -> str:
    """One line for a click usage error (an unknown option, a value out of range or not a choice, a
    missing option): what was given, what is allowed, and where the full usage is.

    ``args`` are the command-line words the failing command parsed (to quote the value given);
    ``command`` names it when the error carries no context.
    """
    import difflib

    from quadctl.text.messages import hint, one_line

    exc_mod = _click_exceptions()
    ctx = getattr(exc, "ctx", None)
    if ctx is not None:
        command = ctx.command_path
    if isinstance(exc, exc_mod.NoSuchOption):
        root = ctx.find_root() if ctx is not None and ctx.parent is not None else None
        own = next((p for p in (root.command.get_params(root) if root else []) if exc.option_name in p.opts), None)
        if own is not None and getattr(own, "is_eager", False):  # --version: it answers alone
            return f"{exc.option_name}: an option of quadctl itself, not of {command}: run `{root.command_path} " \
                   f"{exc.option_name}`"
        if own is not None:  # quadctl's own option (--debug, --width) after the command's name
            value = "" if getattr(own, "is_flag", False) else f" {own.metavar or 'VALUE'}"
            return (f"{exc.option_name}: an option of quadctl itself, not of {command}: give it before the "
                    f"command, as `{root.command_path} {exc.option_name}{value} {ctx.info_name} ...`")
        later = _command_option_first(exc.option_name, args, ctx) if ctx is not None and ctx.parent is None else None
        if later is not None:
            return later
        options = [o for p in (ctx.command.get_params(ctx) if ctx else []) for o in (*p.opts, *p.secondary_opts)
                   if o.startswith("--")]
        near = difflib.get_close_matches(exc.option_name, options, n=1, cutoff=0.7)
        fix = f"did you mean `{near[0]}`?" if near else f"its options: {', '.join(options)}"
        return f"{exc.option_name}: {command} has no such option; {fix}"
    param = getattr(exc, "param", None)
    key = (getattr(param, "opts", None) or [getattr(param, "name", "")])[0]
    choices = _choices_of(param) if param is not None else []
    if isinstance(exc, exc_mod.MissingParameter) and getattr(param, "param_type_name", "") == "argument":
        meta = (param.metavar or param.name or "ARGUMENT").strip("{}").upper()  # init's NAME, identify's LOG
        many = ", one or more" if param.nargs == -1 else ""
        return (f"{command} needs {meta}{many}; give it, as `{command} {meta}{' ...' if many else ''}` "
                f"(`{command} --help` describes it)")
    if isinstance(exc, exc_mod.MissingParameter) and param is not None:
        what = f" {' | '.join(choices)}" if choices else ""
        return f"{command} needs {key}{what}; add it (`{command} --help` describes it)"
    if isinstance(exc, exc_mod.BadParameter) and param is not None:
        value = _given(args, getattr(param, "opts", ()))
        given = key if value is None else f"{key} {value!r}" if not value.strip() else f"{key} {value}"  # '' shown
        lo, hi = _range_of(param)
        if choices:
            near = hint(value, choices) if value is not None else ""
            fix = f"; {near}" if near.startswith("did you mean") else ""
            return f"{given}: must be one of {', '.join(choices)}{fix}"
        numeric = _is_numeric(param)
        if numeric or lo is not None or hi is not None:
            try:
                float(value)
            except (TypeError, ValueError):
                return f"{given}: not a number; give {key} a number"
        if lo is not None or hi is not None:
            bound = (f"between {lo:g} and {hi:g}" if lo is not None and hi is not None
                     else f"of at least {lo:g}" if lo is not None else f"of at most {hi:g}")
            if _is_integer(param) and not re.fullmatch(r"\s*[+-]?[0-9]+\s*", value):  # -j 2.5, --width 1e3
                return f"{given}: not a whole number; give {key} one in digits, {bound.removeprefix('of ')}"
            return f"{given}: out of range; give {key} a value {bound}"
        return f"{given}: {_number(one_line(exc.message)).rstrip('.')}; see `{command} --help`"
    extra = re.fullmatch(r"Got unexpected extra argument\(s\) \((\S+)\)", getattr(exc, "message", "") or "")
    taken = next((o for key, o in (("config", "-c"), ("show", "--show")) if ctx is not None and key in ctx.params
                  and ctx.params[key] is None), None) if extra else None
    if taken is not None and _names_a_config(extra[1]):  # quadctl run hover, quadctl configs hover
        words = list(args)
        at = len(words) - 1 - words[::-1].index(extra[1]) if extra[1] in words else len(words)
        fixed = shlex.join([*words[:at], taken, extra[1], *words[at + 1:]])
        return f"{command}: got an extra argument, {extra[1]}: a config goes after {taken}, as " \
               f"`{command.split()[0]} {fixed}`"
    text = _number(one_line(exc.format_message())).rstrip(".")
    return f"{command}: {text[:1].lower()}{text[1:]}; see `{command} --help`"


def _names_a_config(word: str) -> bool:
    """Whether a stray word names a config: a file, or a bundled config's name (with or without ``.yaml``);
    another word (``quadctl compare pid:px4``, a law) is not read as one."""
    from quadctl.config.loading import bundled_names

    return os.path.isfile(word) or re.sub(r"\.ya?ml$", "", word) in bundled_names()


def _command_option_first(option: str, args, ctx) -> str | None:
    """The line for a command's option given before the command's name (``quadctl -c hover trim``), naming
    where it goes; None when ``option`` is not an option of the command named later in ``args`` (nor, with no
    command named, of any)."""
    group = ctx.command
    if not hasattr(group, "list_commands"):
        return None
    names = group.list_commands(ctx)
    takes_value = {o for name in names for p in group.get_command(ctx, name).get_params(ctx)
                   if not getattr(p, "is_flag", False) for o in p.opts}
    words, named = iter(args), None
    for word in words:
        if word.startswith("-"):
            if word in takes_value:
                next(words, None)  # its value, which may read like a command (-c schedule)
        elif word in names:
            named = word
            break
    for name in [named] if named is not None else names:
        command = group.get_command(ctx, name)
        if command is not None and any(option in p.opts for p in command.get_params(ctx)):
            where = f"`{ctx.command_path} {name} {option} ...`" if named is not None else \
                f"`{ctx.command_path} COMMAND {option} ...` (`{ctx.command_path} {name} --help` lists it)"
            return f"{option}: an option of a command, not of quadctl itself: give it after the command, as {where}"
    return None


def unknown_command(name: str, commands, program: str = "quadctl") -> str:
    """The line for a mistyped command: the nearest command, else the list of them.

    >>> unknown_command("simulte", ["trim", "simulate"])
    "no such command 'simulte'; did you mean 'simulate'? (quadctl --help lists the commands)"
    >>> unknown_command("zz", ["trim", "simulate"])
    "no such command 'zz'; the commands: trim, simulate (quadctl --help describes them)"
    """
    import difflib

    near = difflib.get_close_matches(name, list(commands), n=1)
    if near:
        return f"no such command {name!r}; did you mean {near[0]!r}? ({program} --help lists the commands)"
    return f"no such command {name!r}; the commands: {', '.join(commands)} ({program} --help describes them)"


def one_line_usage_errors(group_cls):
    """A typer group class whose usage errors (bad options and values) print one line,
    ``quadctl: error: ...``, and exit 2 (click prints a usage block and a boxed error)."""
    exc_mod = _click_exceptions()
    passed = tuple(getattr(exc_mod, name) for name in ("NoArgsIsHelpError",) if hasattr(exc_mod, name))

    def refused(exc, args, command):
        if isinstance(exc, passed) or not isinstance(exc, exc_mod.UsageError):
            return None
        return fail(usage_message(exc, args, command), EXIT_BAD_INPUT)

    class OneLineUsageErrors(group_cls):
        def make_context(self, info_name, args, parent=None, **extra):
            words = list(args)
            try:
                return super().make_context(info_name, args, parent=parent, **extra)
            except exc_mod.UsageError as exc:
                out = refused(exc, words, "quadctl")
                if out is None:
                    raise
                raise out from None

        def resolve_command(self, ctx, args):
            try:
                return super().resolve_command(ctx, args)
            except exc_mod.UsageError:
                if not args or args[0].startswith("-") or self.get_command(ctx, args[0]) is not None:
                    raise
                raise fail(unknown_command(args[0], self.list_commands(ctx), ctx.command_path),
                           EXIT_BAD_INPUT) from None

        def invoke(self, ctx):
            words = [*getattr(ctx, "_protected_args", ()), *ctx.args]
            try:
                return super().invoke(ctx)
            except exc_mod.UsageError as exc:
                out = refused(exc, words, " ".join([ctx.command_path, *words[:1]]))
                if out is None:
                    raise
                raise out from None

    return OneLineUsageErrors
