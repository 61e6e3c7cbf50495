"""The ``gonio`` command line.

Each sub-command lives in its own module of this package and provides
``register(subparsers)``, which adds its parser and sets ``func`` (a function of the
parsed arguments returning an exit code).  ``main`` wires them together and turns
expected errors (bad input, interrupted runs) into a one-line message instead of a
traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys

import gonio

#: Sub-command modules in the order ``gonio --help`` lists them.
SUBCOMMANDS = ("demo", "models", "figures", "plan", "run", "fit", "report", "emulator", "textons", "curet", "tables")


class CLIError(ValueError):
    """An error the user can fix; printed as ``gonio: error: ...`` with exit code 2."""


def build_parser() -> argparse.ArgumentParser:
    """The top-level argument parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="gonio",
        description="gonio: a virtual gonioreflectometer and measurement-analysis suite.",
    )
    parser.add_argument("--version", action="version", version=f"gonio {gonio.__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the ``gonio`` command line; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 0 if args.command is None else 2
    try:
        return int(args.func(args) or 0)
    except (CLIError, ValueError, FileNotFoundError) as error:
        print(f"gonio: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gonio: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
