"""``gonio figures``: reproduce the model figures of Oren & Nayar (1995) as PNG files."""
from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio figures``."""
    parser = subparsers.add_parser(
        "figures",
        help="reproduce the model figures of the papers (Oren & Nayar Figs 10-14) as PNG",
        description="Draw the model figures of Oren & Nayar (1995), Figs 10-14, into a folder.",
    )
    parser.add_argument("--out", default="gonio-figures", help="output folder (default gonio-figures)")
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from gonio.report.paper_figures import write_paper_figures

    out = Path(args.out)
    paths = write_paper_figures(out, progress=print)
    print(f"\n{len(paths)} figures written to {out.resolve()}")
    return 0
