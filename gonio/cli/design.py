"""``gonio design``: a protocol whose geometries carry the most information per second."""
from __future__ import annotations

import argparse
import math
from pathlib import Path

from . import CLIError
from .arguments import name_value_pairs, number, parse_duration, prior_ranges


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio design``."""
    parser = subparsers.add_parser(
        "design",
        help="design a protocol: the geometries with the most information per second of instrument time",
        description=(
            "Choose, among the geometries the rig accepts, those that add the most expected information about "
            "the model's parameters (Bayesian D-optimality over the prior ranges) per second of instrument time "
            "(moves, settling, exposures, the reference standard), until the budget; write them as a protocol "
            "that 'gonio plan' and 'gonio run' accept, with a comment block saying how it was chosen, the "
            "expected 95 %% interval widths and the estimated time (docs/design.md)."
        ),
    )
    target = parser.add_mutually_exclusive_group(required=True)
    target.add_argument("--model", help="registered model whose parameters the design is for (see 'gonio models')")
    target.add_argument("--discriminate", metavar="MODEL,MODEL[,...]",
                        help="models to tell apart instead: geometries that best separate them per second "
                             "(each uses the --prior ranges of its own parameters)")
    parser.add_argument("--prior", action="append", default=[], metavar="NAME=LOW:HIGH",
                        help="a parameter to design for and its prior range (uniform); repeatable or comma-separated")
    parser.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                        help="value of a parameter not designed for (others: the model's defaults)")
    parser.add_argument("--budget", required=True, metavar="SECONDS|Nmin|Nh",
                        help="instrument time the protocol may take, as gonio plan estimates it (e.g. 300s, 5min)")
    parser.add_argument("--out", required=True, help="protocol file to write (.toml)")
    parser.add_argument("--overwrite", action="store_true", help="replace a protocol 'gonio design' wrote at --out")
    parser.add_argument("--noise", type=float, default=None, metavar="FRACTION",
                        help="relative noise of one value (default 0.0025, the realistic rig's budget)")
    parser.add_argument("--calibration", type=float, default=None, metavar="FRACTION",
                        help="relative uncertainty of the calibration common to every value (default 0.005)")
    parser.add_argument("--no-reference", action="store_true",
                        help="no reference standard (relative values; saves its two swaps)")
    parser.add_argument("--azimuth", action="append", type=float, default=None, metavar="DEG",
                        help="lamp azimuths considered (default 0: the plane of incidence); repeat for out-of-plane")
    parser.add_argument("--alignment-sd", type=float, default=None, metavar="DEG",
                        help="prior standard deviation of the rig's alignment errors the design stays robust to "
                             "(zero offsets of camera and lamp, the sample's tilt; default 0.5, the fit's prior; "
                             "0: a perfectly aligned rig)")
    parser.add_argument("--max-angle", type=float, default=90.0, metavar="DEG",
                        help="largest lamp and camera angle from the normal considered (default 90: the rig's "
                             "limits; 75-80 keeps clear of grazing angles, where a real sample's texture shows)")
    parser.add_argument("--reference-at", default=None, metavar="DEG[,DEG...]",
                        help="lamp polar angles to read the reference standard at besides the design's own: those "
                             "an adaptive run from this protocol may add points at (gonio run --adaptive)")
    parser.add_argument("--label", default="designed sample", help="the protocol's sample label")
    parser.add_argument("--seed", type=int, default=0, help="seed of the prior draws (default 0)")
    parser.set_defaults(func=_run)


def _angles(text: str | None, what: str) -> tuple[float, ...]:
    """``"0,55,75"`` as angles [deg]; a :class:`CLIError` naming ``what``."""
    if text is None:
        return ()
    try:
        return tuple(float(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise CLIError(f"{what} {text!r}: expected angles in degrees separated by commas, e.g. 0,55,75,85") from None


def _fixed(items: list[str]) -> dict[str, float]:
    return {name: number(name, value, "--fix") for name, value in name_value_pairs(items, "--fix").items()}


def _discrimination(names: str, priors: dict[str, tuple[float, float]], budget: float, common: dict) -> tuple[str, str]:
    """The protocol text and the printed summary of ``gonio design --discriminate``."""
    from gonio import discrimination

    result = discrimination.discriminate([n.strip() for n in names.split(",") if n.strip()], priors, budget, **common)
    hardest = min(result.separations.items(), key=lambda item: item[1])
    summary = (f"{len(result.points)} points at {len(result.blocks)} lamp direction(s), estimated instrument time "
               f"{result.seconds:.0f} s (budget {budget:.0f} s)\n"
               f"hardest pair: {hardest[0].replace('|', ' true, rival ')}, expected chi-square excess {hardest[1]:.3g} "
               "(median over the prior; 0: the rival contains the truth)")
    return discrimination.discrimination_protocol_text(result), summary


def _check_out(out: Path, overwrite: bool) -> None:
    if out.suffix != ".toml":
        raise CLIError(f"--out {out}: expected a protocol file name ending in .toml")
    if out.is_dir():
        raise CLIError(f"--out {out}: is a folder; expected a protocol file name")
    if out.exists():
        if not overwrite:
            raise CLIError(f"--out {out}: exists; choose another name or give --overwrite")
        if not out.read_text(errors="replace").startswith("# Designed by gonio design"):
            raise CLIError(f"--out {out}: not a protocol gonio design wrote; gonio never overwrites files it did "
                           "not write")


def _run(args: argparse.Namespace) -> int:
    from gonio import design as designing
    from gonio.files import write_atomic

    out = Path(args.out)
    _check_out(out, args.overwrite)
    budget = parse_duration(args.budget)
    options = {"noise": args.noise, "calibration": args.calibration}
    for name, value in options.items():
        if value is not None and not (0 < value < 1 and math.isfinite(value)):
            raise CLIError(f"--{name} {value!r}: expected a fraction in (0, 1)")
    alignment_sd = designing.DEFAULT_ALIGNMENT_SD if args.alignment_sd is None else args.alignment_sd
    if not (0 <= alignment_sd <= 5 and math.isfinite(alignment_sd)):
        raise CLIError(f"--alignment-sd {args.alignment_sd!r}: expected degrees in [0, 5] (0: an aligned rig)")
    common = dict(fixed=_fixed(args.fix), noise=args.noise or designing.DEFAULT_NOISE,
                  calibration=args.calibration or designing.DEFAULT_CALIBRATION,
                  azimuths=tuple(args.azimuth or (0.0,)), seed=args.seed, label=args.label,
                  reference=not args.no_reference, alignment_sd=alignment_sd, max_angle=args.max_angle)
    if not (0 < args.max_angle <= 90):
        raise CLIError(f"--max-angle {args.max_angle!r}: expected degrees in (0, 90]")
    try:
        if args.discriminate:
            text, summary = _discrimination(args.discriminate, prior_ranges(args.prior), budget, common)
        else:
            result = designing.design(args.model, prior_ranges(args.prior), budget, **common,
                                      reference_at=_angles(args.reference_at, "--reference-at"))
            text = designing.design_protocol_text(result)
            widths = ", ".join(f"{n} {w:.3g}" for n, w in result.widths.items())
            summary = (f"{len(result.points)} points at {len(result.blocks)} lamp direction(s), estimated instrument "
                       f"time {result.seconds:.0f} s (budget {budget:.0f} s)\n"
                       f"expected 95 % interval widths at the prior's centre: {widths}")
    except (ValueError, KeyError) as error:
        raise CLIError(str(error).strip("'\"")) from None
    write_atomic(out, text)
    print(summary)
    print(f"protocol: {out}  (check it with 'gonio plan {out}', measure it with 'gonio run {out} --out FOLDER')")
    return 0
