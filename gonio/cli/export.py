"""``gonio export``: a model spec's or a fit's BRDF as a MERL binary, a tidy CSV table or
ASTM E1392 rows, and a recording's measured rows as ASTM E1392 rows, with their
uncertainty (:mod:`gonio.export`, docs/export.md)."""
from __future__ import annotations

import argparse
import sys
import time

from gonio.export import CSV_DRAWS, FORMATS, MERL_DRAWS, MERL_WARN_SECONDS

from .arguments import name_value_pairs


class _StderrProgress:
    """Progress lines on stderr, shown once the work has taken more than ``delay`` [s]
    (the stages before that are printed then, so none is lost)."""

    def __init__(self, delay: float = 2.0):
        self.start = time.monotonic()
        self.delay = delay
        self.pending: list[str] = []

    def __call__(self, message: str) -> None:
        elapsed = time.monotonic() - self.start
        self.pending.append(f"gonio export: {message} ({elapsed:.1f} s)")
        if elapsed > self.delay:
            print("\n".join(self.pending), file=sys.stderr, flush=True)
            self.pending.clear()


def _warn(message: str) -> None:
    """A warning on stderr at once (not delayed like progress, not silenced by --quiet)."""
    print(f"gonio export: warning: {message}", file=sys.stderr, flush=True)


def _run(args: argparse.Namespace) -> int:
    from gonio.export import export

    grid = name_value_pairs(args.grid, "--grid") if args.grid else None
    paths = export(args.source, args.format, args.out, grid=grid, draws=args.draws, overwrite=args.overwrite,
                   seed=args.seed, progress=None if args.quiet else _StderrProgress(), warn=_warn)
    for path in paths:
        print(f"wrote {path}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio export``."""
    parser = subparsers.add_parser(
        "export", help="write a model's or a fit's BRDF as a MERL binary, a CSV table or ASTM E1392 rows, and a "
                       "recording's measured BRDF as ASTM E1392 rows, with their uncertainty",
        description=(
            "Write the BRDF [1/sr] of a model spec NAME[:key=value,...] (e.g. oren-nayar:sigma=30,rho=0.9) or of "
            "a fit folder (its model at the posterior medians) as a MERL BRDF binary (plus FILE.uncertainty.npz: "
            "posterior standard deviation per cell and validity masks), as a tidy CSV table (posterior median, "
            "95 % interval, standard deviation and whether the geometry lies within the data's angles) or as "
            "ASTM E1392 rows (incident and scatter angles, BRDF and cosine-corrected BRDF with their standard "
            "uncertainty under a header naming sample, source, receiver, wavelength, polarization and dates, plus "
            "FILE.uncertainty.npz). A recording folder of 'gonio run' exports its measured rows as ASTM E1392 "
            "rows (calibrated BRDF, as 'gonio reduce --brdf'). A MERL export estimated to take more than "
            f"{MERL_WARN_SECONDS:g} s warns first. See docs/export.md."
        ),
    )
    parser.add_argument("source", metavar="MODEL_SPEC|FIT_FOLDER|RECORDING",
                        help="model spec, fit result folder, or (astm) recording folder")
    parser.add_argument("--format", required=True, choices=FORMATS, help="merl, csv or astm")
    parser.add_argument("--out", required=True, help="file to write (its folder must exist)")
    parser.add_argument("--grid", action="append", default=[], metavar="AXIS=START:STOP:STEP",
                        help="csv and astm of a spec or a fit: replace an axis of the grid (theta_i, theta_r, dphi; "
                             "deg, STOP included); default theta_i=0:85:5, theta_r=0:85:5, dphi=0:180:15")
    parser.add_argument("--draws", type=int, default=None,
                        help=f"most posterior draws used (default {MERL_DRAWS} for merl, {CSV_DRAWS} for csv and "
                             "astm)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the choice of posterior draws (default 0)")
    parser.add_argument("--overwrite", action="store_true", help="replace files that exist")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    parser.set_defaults(func=_run)
