"""The ``agent`` command line: one typer app, one module per command in agent/commands/.

Each command module defines a typer-annotated function; this file only registers them
and turns project errors, usage errors included, into one-line messages (exit 2 for bad
input, 1 otherwise).
"""

from __future__ import annotations

import os

# The model fits work on tiny matrices (3x3 to 9x9); a multi-threaded BLAS turns each
# call into a thread hand-off costing ~20 ms on a loaded 2-core machine.  Set before
# numpy is first imported; a user's explicit setting wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import functools
import sys
import warnings
from typing import Callable

import typer

from core.errors import InputError, RapidIdentError, RapidIdentWarning

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="rapid-ident: identify virtual models of CNC feed drives from a short G-code run.",
)


def _one_line_warnings(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
    print(f"warning: {message}", file=sys.stderr)


def _quiet_library_loggers() -> None:
    """Keep third-party loggers (canopen, pymodbus, can) off the terminal.

    Without a handler, Python's last-resort handler prints their warnings, so a failure
    the library reports as one ``error:`` line would come with a second line from the
    library below it.  ``RAPID_IDENT_DEBUG=1`` lets them through.
    """
    import logging

    root = logging.getLogger()
    if os.environ.get("RAPID_IDENT_DEBUG"):
        logging.basicConfig(level=logging.DEBUG)
    elif not root.handlers:
        root.addHandler(logging.NullHandler())


#: library argument (RapidIdentError.parameter) -> the option that sets it, where the
#: option is not simply ``--`` + the argument with ``-`` for ``_``.
FLAGS = {"options": "--opt", "programs": "PROGRAM", "out": "--out", "center": "--centre"}


def error_line(exc: RapidIdentError) -> str:
    """The one line a command prints for ``exc``: the library's message, with the option named.

    A message about argument ``port`` becomes ``--port: <message>``; one that starts with
    the argument's own name (``duration must be > 0 s``) has that name replaced by the
    option (``--duration must be > 0 s``).
    """
    message = str(exc)
    if not exc.parameter:
        return message
    flag = FLAGS.get(exc.parameter, "--" + exc.parameter.replace("_", "-"))
    words = exc.parameter.replace("_", " ")
    if message.startswith(words + " "):
        return flag + message[len(words):]
    return f"{flag}: {message}"


#: Exit status when stdout's reader went away (``agent simulate … | head -1``): a shell tool's
#: 128 + SIGPIPE, without a message — the reader asked for no more.
EXIT_BROKEN_PIPE = 141


def _leave_quietly() -> None:
    """Point stdout at /dev/null so the interpreter's final flush cannot fail a second time."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def reports_errors(func: Callable) -> Callable:
    """Run a command, printing a RapidIdentError as one line instead of a traceback."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        warnings.showwarning = _one_line_warnings
        _quiet_library_loggers()
        warnings.simplefilter("always", RapidIdentWarning)
        try:
            value = func(*args, **kwargs)
            sys.stdout.flush()  # a reader that went away shows here, not at interpreter exit
            return value
        except BrokenPipeError:
            _leave_quietly()
            raise typer.Exit(EXIT_BROKEN_PIPE) from None
        except RapidIdentError as exc:
            print(f"error: {error_line(exc)}", file=sys.stderr)
            raise typer.Exit(2 if isinstance(exc, InputError) else 1) from None
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
            raise typer.Exit(130) from None
        except (typer.Exit, typer.Abort, SystemExit):
            raise
        except OSError as exc:  # a file or device the user named cannot be used
            print(f"error: {exc.filename or ''}{': ' if exc.filename else ''}{exc.strerror or exc}", file=sys.stderr)
            raise typer.Exit(2) from None
        except Exception as exc:  # a bug: still one line, the traceback on request
            if os.environ.get("RAPID_IDENT_DEBUG"):
                raise
            print(f"error: internal error {type(exc).__name__}: {exc} "
                  f"(set RAPID_IDENT_DEBUG=1 for the traceback)", file=sys.stderr)
            raise typer.Exit(1) from None

    return wrapper


def _register() -> None:
    # Imported here so `agent --help` stays fast and a broken optional transport
    # cannot stop unrelated commands.
    from agent.commands import registered_commands

    for name, func in registered_commands():
        app.command(name)(reports_errors(func))


def usage_error_line(exc: typer.TyperException) -> str:
    """The one line a command-line usage error prints: typer's message (a missing argument, an
    unknown option, an option without its value) and where the usage is told."""
    ctx = getattr(exc, "ctx", None)
    where = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
    return f"error: {exc.format_message().rstrip('.')}{where}"


def main() -> None:
    """The ``agent`` console script: the app outside typer's standalone mode, so that a usage
    error is one ``error:`` line like every other bad input (typer's own is a boxed panel
    with the usage above it), with the exit status typer gives it (2)."""
    _register()
    try:
        status = app(standalone_mode=False)
    except typer.TyperException as exc:
        message = exc.format_message()
        if message:  # empty: ``agent`` alone, whose help typer has already printed
            print(usage_error_line(exc), file=sys.stderr)
        sys.exit(exc.exit_code)
    except typer.Abort:  # end of input at a prompt
        print("aborted", file=sys.stderr)
        sys.exit(1)
    # an int where a command raised typer.Exit (``--help``: 0); None where it returned
    sys.exit(status if isinstance(status, int) else 0)


if __name__ == "__main__":
    main()
