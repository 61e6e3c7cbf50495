"""The ``gonio`` command line.

Each sub-command lives in its own module of this package and provides
``register(subparsers)``, which adds its parser and sets ``func`` (a function of the
parsed arguments returning an exit code).  ``main`` wires them together and turns every
error into one line on stderr instead of a traceback:

* bad input (:class:`CLIError`, ``ValueError``, a file that cannot be read or written,
  a rig that cannot be reached): ``gonio: error: <message>``, exit code 2;
* Ctrl-C: exit code 130;
* anything else is an internal error: ``gonio: error: <Type>: <message> (run with --debug
  for the traceback)``, exit code 1.

``gonio --debug COMMAND ...`` (or ``--debug`` anywhere on the line) lets every exception
propagate, traceback included.
"""
from __future__ import annotations

import argparse
import gc
import importlib
import os
import sys
from typing import NoReturn

import gonio

#: Sub-command modules in the order ``gonio --help`` lists them.
SUBCOMMANDS = ("demo", "models", "figures", "plan", "design", "run", "reduce", "fit", "fit_batch", "report", "render",
               "stereo", "emulator", "textons", "curet", "tables", "export")

#: Exit codes: bad input, internal error, interrupted (128 + SIGINT).
EXIT_BAD_INPUT = 2
EXIT_INTERNAL_ERROR = 1
EXIT_INTERRUPTED = 130
#: Exit status when the reader of the output closed it early: 128 + SIGPIPE, as shell tools give.
EXIT_BROKEN_PIPE = 141


class CLIError(ValueError):
    """An error the user can fix; printed as ``gonio: error: ...`` with exit code 2."""


class _VersionAction(argparse.Action):
    """``--version``: print ``gonio VERSION`` and exit, as argparse's ``version`` action does,
    reading the installed version only when asked (:mod:`importlib.metadata` costs about
    0.02 s, which every other command would pay at start-up)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help="show program's version number and exit"):
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None) -> NoReturn:
        print(f"gonio {gonio.__version__}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The top-level argument parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="gonio",
        description="gonio: a virtual gonioreflectometer and measurement-analysis suite.",
    )
    parser.add_argument("--version", action=_VersionAction)
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback of an error instead of a one-line message")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the ``gonio`` command line; returns the process exit code."""
    arguments = sys.argv[1:] if argv is None else list(argv)
    try:
        parser = build_parser()
    except Exception as error:  # a sub-command that cannot even be imported
        if "--debug" in arguments:
            raise
        print(f"gonio: error: {describe_error(error)[0]}", file=sys.stderr)
        return EXIT_INTERNAL_ERROR
    debug = "--debug" in arguments[:arguments.index("--")] if "--" in arguments else "--debug" in arguments
    args = parser.parse_args([a for a in arguments if a != "--debug"] if debug else arguments)
    args.debug = debug  # anywhere on the line: before or after the subcommand
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 0 if args.command is None else EXIT_BAD_INPUT
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("gonio: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # the reader of the output left (``gonio plan ... | head``): no error to report; the
        # rest of the output goes nowhere, so that the interpreter's last flush does not fail
        # again (Python documentation, "Note on SIGPIPE")
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except Exception as error:
        if args.debug:
            raise
        message, code = describe_error(error)
        print(f"gonio: error: {message}", file=sys.stderr)
        return code


def run() -> NoReturn:
    """The ``gonio`` program (the console script and ``python -m gonio``): :func:`main`,
    then exit with its code.

    Before exiting, every object left is frozen (:func:`gc.freeze`) so that the
    interpreter's last garbage collection skips them: with scipy.stats, emcee and ArviZ's
    core loaded that collection takes 0.17-0.23 s of the exit against 0.02-0.03 s frozen,
    about a tenth of a ``gonio fit`` (benchmarks/bench_report.py). Everything the command wrote is closed by
    then, ``atexit`` handlers still run and the standard streams are still flushed; the
    objects are released with the process. ``main`` itself leaves the garbage collector
    alone, for callers that go on running.
    """
    code = main()
    gc.freeze()
    sys.exit(code)


def describe_error(error: Exception) -> tuple[str, int]:
    """The one-line message and the exit code ``main`` gives for an exception.

    Parameters
    ----------
    error : Exception
        What a sub-command raised.

    Returns
    -------
    message : str
        One line (newlines in the exception's text are folded).
    code : int
        2 for bad input (CLIError, ValueError, OSError, a driver error), 1 otherwise.
    """
    if isinstance(error, ValueError):
        text, code = str(error), EXIT_BAD_INPUT
    elif isinstance(error, OSError):
        text, code = os_error_text(error), EXIT_BAD_INPUT
    elif _is_driver_error(error):
        text, code = f"rig: {type(error).__name__}: {error}", EXIT_BAD_INPUT
    else:
        text = f"{type(error).__name__}: {error} (run with --debug for the traceback)"
        code = EXIT_INTERNAL_ERROR
    return " ".join(text.split()), code


def os_error_text(error: OSError) -> str:
    """``FILE: reason`` for an operating-system error (permission, no space, a directory...).

    Errors raised with a message of their own (no errno) keep it.
    """
    if error.strerror is None:
        return str(error) or type(error).__name__
    names = [str(name) for name in (error.filename, error.filename2) if name is not None]
    where = " -> ".join(names)
    return f"{where}: {error.strerror}" if where else error.strerror


def _is_driver_error(error: Exception) -> bool:
    """Whether ``error`` comes from the drivers (never imports them: if they were not
    imported, the error cannot be theirs)."""
    errors = sys.modules.get("drivers.errors")
    return errors is not None and isinstance(error, errors.DriverError)


if __name__ == "__main__":  # pragma: no cover
    run()
