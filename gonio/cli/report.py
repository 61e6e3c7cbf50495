"""``gonio report``: turn a fit result folder into a self-contained HTML report."""
from __future__ import annotations

import argparse
from pathlib import Path

from .paths import check_output_folder


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio report``."""
    parser = subparsers.add_parser(
        "report",
        help="write the HTML report (figures embedded) of a fit result folder",
        description=(
            "Read a folder written by 'gonio fit' (result.json, chain.npz) and write report.html, a single "
            "self-contained file with every figure embedded, plus the figures as PNG files."
        ),
    )
    parser.add_argument("result_dir", metavar="RESULT_DIR", help="folder written by 'gonio fit'")
    parser.add_argument("--out", help="output folder (default: RESULT_DIR)")
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    source = Path(args.result_dir)
    if not (source / "result.json").exists() and not source.is_file():
        raise FileNotFoundError(f"{source}: no result.json here; give a folder written by 'gonio fit'")
    if args.out is not None:
        check_output_folder(args.out, "report")
    from gonio.report.fit_report import write_report  # matplotlib: once the arguments are checked

    path = write_report(source, args.out)
    print(f"report written to {path.resolve()}")
    return 0
