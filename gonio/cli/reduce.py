"""``gonio reduce``: a recording's radiance per geometry with its uncertainty budget."""
from __future__ import annotations

import argparse
import os
from pathlib import Path

from . import CLIError
from .paths import check_output_folder

def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio reduce``."""
    parser = subparsers.add_parser(
        "reduce",
        help="reduce a recording: radiance per geometry with its uncertainty budget by component",
        description=(
            "Reduce a recording written by 'gonio run': every measured geometry (repeats combined, at the "
            "geometry the stage read back) with its uncertainty split into components (shot and read noise, "
            "dark, PRNU, lamp, angle, linearity correction) and the reference standard's calibration (with its "
            "irradiance at each lamp polar angle). Prints the budget table and "
            "writes reduced.csv and budget.json (docs/acquisition.md); with --brdf also the absolute BRDF "
            "calibrated by the reference standard, brdf.csv with its covariance brdf_covariance.npy "
            "(docs/data-format.md)."
        ),
    )
    parser.add_argument("recording", help="recording folder of 'gonio run'")
    parser.add_argument("--out", help="output folder (default: RECORDING.reduced next to the recording)")
    parser.add_argument("--lamp", choices=["auto", "monitor", "checks", "repeats", "none"], default="auto",
                        help="how lamp flicker and drift are handled (default: the monitor if recorded, "
                             "else the lamp checks, else the scatter of repeats)")
    parser.add_argument("--linearity-correction", action=argparse.BooleanOptionalAction, default=True,
                        help="correct the readings by the camera's linearity series of the recording (default: yes)")
    parser.add_argument("--brdf", action="store_true",
                        help="also write the absolute BRDF [1/sr] with its uncertainty by component (brdf.csv) and "
                             "the values' covariance (brdf_covariance.npy); needs the reference standard")
    parser.add_argument("--calibration", choices=["common", "per-incidence"], default="common",
                        help="the BRDF's calibration: one lamp irradiance for every value ('common', the default) or "
                             "the standard's at each lamp polar angle ('per-incidence')")
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier 'gonio reduce' output in --out")
    parser.set_defaults(func=_run)


def _check_earlier_output(out: Path, overwrite: bool) -> None:
    from gonio.reduction import BRDF_COVARIANCE, BRDF_TABLE, REDUCED_BUDGET, REDUCED_TABLE, is_whole_reduction

    files = (REDUCED_TABLE, BRDF_TABLE, BRDF_COVARIANCE, REDUCED_BUDGET)
    present = [name for name in files if os.path.lexists(out / name)]
    if not present:
        return
    if not is_whole_reduction(out):
        raise CLIError(f"--out {out}: holds {', '.join(present)} that are not one reduction 'gonio reduce' wrote "
                       f"(its {REDUCED_BUDGET} must list the {REDUCED_TABLE} beside it); choose another --out (gonio "
                       "never overwrites files it did not write)")
    if not overwrite:
        raise CLIError(f"--out {out}: holds an earlier reduction; add --overwrite to replace it")
    for name in files:  # the earlier reduction goes whole: no brdf.csv of it beside the new one
        if os.path.lexists(out / name):
            (out / name).unlink()


def _run(args: argparse.Namespace) -> int:
    from gonio.reduction import reduce_recording

    recording = Path(args.recording)
    if not recording.is_dir():
        raise CLIError(f"{recording}: not a recording folder (expected the folder 'gonio run --out' wrote)")
    out = check_output_folder(args.out, "reduction") if args.out else recording.with_name(f"{recording.name}.reduced")
    _check_earlier_output(out, args.overwrite)
    reduced = reduce_recording(recording, lamp=args.lamp, linearity=args.linearity_correction)
    print(reduced.budget_table())
    if reduced.reference_irradiance is not None:
        print(f"reference irradiance E_0 = {reduced.reference_irradiance:.7g} +/- "
              f"{reduced.reference_irradiance_sigma:.2g} ({reduced.unit} per sr)")
    if args.brdf and reduced.reference_irradiance is None:
        raise CLIError(f"{recording}: --brdf needs the reference standard, and this recording has none (its protocol "
                       "has no [reference] table, or the reference points were not measured); the radiance is "
                       "relative only (reduced.csv)")
    try:
        paths = reduced.write(out, brdf=args.calibration if args.brdf else None)
    except ValueError as error:
        raise CLIError(f"{recording}: {error}") from None
    for path in paths:
        print(f"wrote {path}")
    return 0
