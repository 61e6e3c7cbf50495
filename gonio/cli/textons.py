"""``gonio textons``: textons and radiance histograms of a pitted surface (Figs 13-14 of
Koenderink, van Doorn, Dana & Nayar 1999) as PNG files."""
from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio textons``."""
    parser = subparsers.add_parser(
        "textons",
        help="draw the textons and radiance histograms of a pitted surface (Koenderink et al. Figs 13-14)",
        description=(
            "Render the views of one spherical pit ('textons') and their radiance histograms for "
            "the (alpha, beta, epsilon) geometries of Koenderink et al. (1999) Figs 13-14, plus a "
            "tiled texture, as PNG files."
        ),
    )
    parser.add_argument("--out", default="gonio-textons", help="output folder (default gonio-textons)")
    parser.add_argument("--rho", type=float, default=1.0, help="micro-scale albedo [-] (default 1, as in the paper)")
    parser.add_argument("--psi", type=float, default=90.0, help="pit aperture [deg] in (0, 90] (default 90)")
    parser.add_argument("--pixels", type=int, default=128, help="texton image size in pixels (default 128)")
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from gonio.models.pitted.validation import check_pit_parameters
    from gonio.report.texton_plots import write_texton_figures

    from . import CLIError

    check_pit_parameters(rho=args.rho, psi=args.psi)
    if args.pixels < 8:
        raise CLIError(f"--pixels {args.pixels} is too small: use at least 8")
    out = Path(args.out)
    paths = write_texton_figures(out, rho=args.rho, psi=args.psi, pixels=args.pixels, progress=print)
    print(f"\n{len(paths)} figures written to {out.resolve()}")
    return 0
