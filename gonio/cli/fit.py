"""``gonio fit``: fit a registered model to measured data (least squares, then MCMC)."""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .arguments import name_value_pairs, number

if TYPE_CHECKING:  # loaded on use: the command line starts without the fitting stack
    from gonio.fitting import Prior


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio fit``."""
    parser = subparsers.add_parser(
        "fit",
        help="fit a reflectance model to measured data (least squares + MCMC)",
        description=(
            "Fit a registered model to a CSV of measurements with the columns "
            "theta_i,phi_i,theta_r,phi_r,value[,sigma] (angles in degrees; --columns maps your names), or to "
            "recording folders written by 'gonio run' (several are fitted jointly). Several --model: every "
            "candidate is fitted by least squares and compared, and the chosen one is fitted and saved with the "
            "comparison (comparison.json, comparison.txt). Weighted, bounded least squares, "
            "then Bayesian sampling with emcee until the chain is 50 autocorrelation times long. The result "
            "(result.json, chain.npz, posterior.nc, summary.txt) is written to a folder next to the data; "
            "'gonio report FOLDER' turns it into an HTML report. Every fit is tested for goodness of fit. "
            "Exit status: 0 converged and adequate, 2 bad input, 3 chain not converged, "
            "4 model inadequate, 5 noise understated (docs/fitting.md, 'Exit codes')."
        ),
    )
    parser.add_argument("data", nargs="+",
                        help="CSV file(s) (theta_i,phi_i,theta_r,phi_r,value[,sigma]) or recording folder(s) of 'gonio "
                             "run' (relative radiance with the reference standard's prior when calibrated, else "
                             "normalised radiance); several are fitted jointly")
    parser.add_argument("--model", required=True, action="append", metavar="NAME[:p=v,...]",
                        help="registered model name (see 'gonio models'), with values after ':' fixed for that "
                             "model alone (e.g. oren-nayar:ir_weight=1, as in gonio curet fit); repeat to compare "
                             "models")
    parser.add_argument("--quantity", choices=["brdf", "normalised_radiance", "radiance"],
                        help="what the values are (default: the file's '# quantity:' line, else brdf)")
    parser.add_argument("--columns", action="append", default=[], metavar="NAME=COLUMN",
                        help="CSV: your column names for gonio's (theta_i, phi_i, theta_r, phi_r, value, sigma), e.g. "
                             "--columns theta_i=incidence,value=brdf")
    parser.add_argument("--angle-unit", choices=["deg", "rad"],
                        help="CSV: the angles' unit (default: the file's '# angle_unit:' line, else degrees; angles "
                             "that all lie within [0, pi/2] are refused as probable radians unless this is given)")
    parser.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                        help="hold a parameter fixed (repeatable, or comma-separated)")
    parser.add_argument("--prior", action="append", default=[], metavar="NAME=KIND:A:B",
                        help="prior override: uniform:LO:HI, loguniform:LO:HI or normal:MEAN:SD")
    parser.add_argument("--option", action="append", default=[], metavar="NAME=VALUE", help="model option")
    parser.add_argument("--mcmc", action=argparse.BooleanOptionalAction, default=True,
                        help="sample the posterior with emcee after least squares (default: yes)")
    parser.add_argument("--jitter", nargs="?", const="absolute", default="auto",
                        choices=["auto", "none", "absolute", "relative"],
                        help="an extra noise term added in quadrature to the uncertainties: 'auto' (the default: "
                             "a relative one only when the verdict is 'noise understated', the model following "
                             "data that scatter more than stated), 'none', 'absolute' (the default when given "
                             "alone; parameter jitter, in data units) or 'relative' (rel_jitter, a fraction of "
                             "the prediction)")
    parser.add_argument("--alignment", action="append", default=[], metavar="NAMES",
                        help="fit the rig's alignment as nuisance parameters: 'all' or comma-separated names from "
                             "view_offset, theta_i_offset, phi_i_offset (axis zero offsets), tilt_x, tilt_y (holder "
                             "tilt), sample_tilt_x, sample_tilt_y (the sample's own tilt) [deg], with normal priors "
                             "N(0, 0.5 deg) unless --prior overrides them; and texture_slope, the rms of the sample's "
                             "mesoscale slope [deg] (uniform prior on [0, 3]; not part of 'all'); for recordings of "
                             "this rig (docs/fitting.md, 'The rig's errors as parameters')")
    parser.add_argument("--stray-light", action="store_true",
                        help="fit the rig's stray light as a nuisance parameter: stray_light, the stray radiance as a "
                             "fraction of a white Lambertian's at normal incidence (uniform prior on [0, 0.05])")
    parser.add_argument("--calibration", choices=["common", "per-incidence"], default="common",
                        help="a recording's calibration by its reference standard: one lamp irradiance for every "
                             "value ('common', the default: a uniform beam) or the irradiance the standard gave at "
                             "each value's lamp polar angle ('per-incidence': a beam whose irradiance changes with "
                             "the lamp's angle; needs the standard measured at every polar angle of the sample)")
    parser.add_argument("--linearity-correction", action=argparse.BooleanOptionalAction, default=True,
                        help="correct a recording's readings by its camera linearity series (default: yes)")
    parser.add_argument("--walkers", type=int, default=None,
                        help="number of emcee walkers (default 24, for every model with up to 11 free parameters, 2 k + 2 for k above: gonio.fitting.mcmc.default_walkers, chosen by measurement)")
    parser.add_argument("--max-steps", type=int, default=20000, help="step limit of the chain (default 20000)")
    parser.add_argument("--rhat-limit", type=float, default=1.01,
                        help="largest rank-normalised split R-hat accepted for convergence (default 1.01)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--out", help="result folder (default: DATA_STEM.fit-MODEL next to the first data path, "
                                      "DATA_STEM.fit-comparison with several models); "
                                      "refused if it already holds files, unless --overwrite")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an earlier gonio fit result in --out (only its result and report files; "
                             "other files are left alone)")
    parser.add_argument("--report", action=argparse.BooleanOptionalAction, default=False,
                        help="also write the HTML report into the result folder (default: no; 'gonio report FOLDER' "
                             "writes it later)")
    parser.add_argument("--quiet", action="store_true", help="no progress messages")
    parser.set_defaults(func=_run)


def check_result_folder(out: Path, overwrite: bool, argument: str = "--out") -> bool:
    """Refuse a result folder that would overwrite files gonio did not write.

    Parameters
    ----------
    out : Path
        The folder a fit result will be saved into.
    overwrite : bool
        Whether the user allows replacing an earlier gonio fit result there.
    argument : str
        The command-line argument named in messages.

    Returns
    -------
    bool
        True when an earlier fit result will be replaced (see :func:`remove_stale_results`).

    Raises
    ------
    CLIError
        ``out`` is an existing file or device; or it holds files and ``overwrite`` is not
        given; or it holds files but no gonio fit result (result.json of FitResult.save).
    """
    from gonio.cli import CLIError
    from gonio.fitting.results import RESULT_FILE, is_fit_result

    if out.exists() and not out.is_dir():
        kind = "an existing file" if out.is_file() else "a device or special file"
        raise CLIError(f"{argument} {out}: is {kind}, expected a folder for the fit result")
    if not out.exists() or not any(out.iterdir()):
        return False
    if not overwrite:
        raise CLIError(f"{argument} {out}: the folder already holds files; choose a new folder, or give --overwrite "
                       "to replace the gonio fit result in it")
    if not is_fit_result(out):
        raise CLIError(f"{argument} {out}: holds files but no gonio fit result ({RESULT_FILE}); --overwrite only "
                       "replaces a fit result (gonio never overwrites files it did not write)")
    return True


def result_file_names() -> tuple[str, ...]:
    """Every file name a fit result folder may hold from FitResult.save and write_report."""
    from gonio.fitting.results import CHAIN_FILE, COVARIANCE_FILE, INFERENCE_DATA_FILE, RESULT_FILE, SUMMARY_FILE
    from gonio.fitting.selection import COMPARISON_FILE, COMPARISON_TEXT
    from gonio.report.fit_html import REPORT_FILES  # the names without matplotlib

    return (RESULT_FILE, CHAIN_FILE, COVARIANCE_FILE, INFERENCE_DATA_FILE, SUMMARY_FILE, COMPARISON_FILE,
            COMPARISON_TEXT) + REPORT_FILES


def remove_stale_results(out: Path, written: tuple[str, ...]) -> list[Path]:
    """Delete the result and report files of an earlier fit that the new one did not rewrite.

    Only the names FitResult.save and write_report write are considered (a chain left
    from an earlier MCMC run, a report of an earlier fit); every other file stays. Called
    right after the new result is saved, before its report is drawn (with
    ``written = result.saved_files()``): a report that then fails leaves no report of the
    earlier fit beside the new result.

    Parameters
    ----------
    out : Path
        The result folder.
    written : tuple of str
        Names the new fit wrote.

    Returns
    -------
    list of Path
        The files deleted.
    """
    removed = []
    for name in result_file_names():
        path = out / name
        if name not in written and (path.is_file() or path.is_symlink()):
            path.unlink()
            removed.append(path)
    return removed


def _option_value(text: str) -> Any:
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


class _Progress:
    """Prints the chain's progress toward convergence to stderr, at most every two seconds.

    The chain stops when it is ``tau_multiple`` (50) autocorrelation times long (and R-hat
    passes), so the fraction shown is the steps over 50 times the current largest tau
    estimate; the step cap is only the limit. The estimate of tau grows as the chain
    explores, so the fraction can step back.
    """

    def __init__(self, quiet: bool, tau_multiple: float = 50.0):
        self.quiet = quiet
        self.tau_multiple = tau_multiple
        self.last = 0.0

    def __call__(self, steps: int, max_steps: int, tau: float) -> None:
        now = time.monotonic()
        if self.quiet or now - self.last < 2.0:
            return
        self.last = now
        print(f"  mcmc: {convergence_text(steps, max_steps, tau, self.tau_multiple)}", file=sys.stderr, flush=True)


def convergence_text(steps: int, max_steps: int, tau: float, tau_multiple: float = 50.0) -> str:
    """One progress line of a chain: steps against the length convergence needs.

    >>> convergence_text(600, 20000, 20.0)
    'step 600 of ~1000 needed for convergence (60 %; 50 tau, tau = 20); limit 20000'
    >>> convergence_text(50, 20000, float("nan"))
    'step 50, estimating the autocorrelation time; limit 20000'
    """
    if not (tau == tau and 0 < tau < float("inf")):
        return f"step {steps}, estimating the autocorrelation time; limit {max_steps}"
    needed = min(max_steps, tau_multiple * tau)
    return (f"step {steps} of ~{needed:.0f} needed for convergence ({min(100.0, 100 * steps / needed):.0f} %; "
            f"{tau_multiple:g} tau, tau = {tau:.3g}); limit {max_steps}")


def _alignment(items: list[str]) -> tuple[str, ...]:
    """The ``--alignment`` names (repeatable, comma-separated, or 'all')."""
    from gonio.cli import CLIError
    from gonio.fitting.rig_errors import parse_alignment

    try:
        return parse_alignment(",".join(items))
    except ValueError as error:
        raise CLIError(f"--alignment: {error}") from None


def _run(args: argparse.Namespace) -> int:
    from gonio.analysis import fit_dataset, load_data, model_candidates
    from gonio.cli.progress import fitting_progress
    from gonio.cli import CLIError
    from gonio.fitting import ConvergenceWarning

    paths = [Path(p) for p in args.data]
    fixed = {k: number(k, v, "--fix") for k, v in name_value_pairs(args.fix, "--fix").items()}
    try:  # known models; each fixed value names a parameter of one of them
        names = [name for name, _ in model_candidates(args.model, fixed)]
    except (ValueError, KeyError) as error:
        raise CLIError(f"--model/--fix: {error}") from None
    options = {k: _option_value(v) for k, v in name_value_pairs(args.option, "--option").items()}
    priors = _priors(args.prior, names)
    out = _out_folder(args.out, paths, names)
    replacing = check_result_folder(out, args.overwrite)
    try:
        dataset, data_priors = load_data(paths, args.quantity, args.calibration, args.linearity_correction,
                                         name_value_pairs(args.columns, "--columns") or None, args.angle_unit)
    except (ValueError, FileNotFoundError) as error:
        raise CLIError(str(error)) from None
    say = (lambda text: None) if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True))
    with warnings.catch_warnings(), fitting_progress(args.quiet):
        warnings.simplefilter("ignore", ConvergenceWarning)  # reported below, loudly
        result = fit_dataset(
            dataset, args.model, data_priors=data_priors, fixed=fixed, priors=priors, mcmc=args.mcmc,
            jitter=_jitter(args.jitter), options=options, n_walkers=args.walkers, max_steps=args.max_steps,
            rhat_limit=args.rhat_limit, seed=args.seed, progress=_Progress(args.quiet),
            alignment=_alignment(args.alignment), stray_light=args.stray_light, announce=say)
    path = result.save(out)
    if replacing:
        remove_stale_results(out, result.saved_files())  # the earlier fit's report too, before writing it
    print(result.summary())
    if args.report:
        from gonio.report.fit_report import write_report

        print(f"report: {write_report(result, out)}")
    print(f"result: {path}")
    if result.converged is False:
        print("gonio: WARNING: the MCMC chain did NOT converge (step limit reached); "
              "posterior numbers are unreliable. Increase --max-steps or simplify the model.", file=sys.stderr)
    for flag in result.flags:
        if not flag.startswith(("CHAIN NOT CONVERGED", "MODEL INADEQUATE", "NOISE UNDERSTATED")):  # said below
            print(f"gonio: warning: {flag}", file=sys.stderr)
    if result.adequate is False:
        print(f"gonio: {result.adequacy.headline()}", file=sys.stderr)
    return result.exit_code()


def _priors(items: list[str], names: list[str]) -> dict[str, Prior]:
    """The ``--prior`` overrides, each checked against the bounds of the parameter it names
    (in the first model that has it, or the rig's errors)."""
    from gonio import models
    from gonio.cli import CLIError
    from gonio.fitting import parse_prior
    from gonio.fitting.rig_errors import ALIGNMENT_BOUND_DEG, RIG_ERROR_NAMES, STRAY_LIGHT, TEXTURE_SLOPE

    priors = {}
    for key, text in name_value_pairs(items, "--prior").items():
        bounds = next((models.get(n).param(key).bounds for n in names if key in models.get(n).param_names),
                      (-float("inf"), float("inf")))
        if key in RIG_ERROR_NAMES:
            own = {STRAY_LIGHT.name: STRAY_LIGHT.bounds, TEXTURE_SLOPE.name: TEXTURE_SLOPE.bounds}
            bounds = own.get(key, (-ALIGNMENT_BOUND_DEG, ALIGNMENT_BOUND_DEG))
        try:
            priors[key] = parse_prior(text, bounds)
        except ValueError as error:
            raise CLIError(f"--prior {key}={text}: {error}; {key}'s physical range is "
                           f"[{bounds[0]:g}, {bounds[1]:g}]") from None
    return priors


def _out_folder(out: str | None, paths: list[Path], names: list[str]) -> Path:
    """``--out``, or next to the first data path: STEM.fit-MODEL (STEM.fit-comparison for several models)."""
    from gonio.cli import CLIError

    if out is not None:
        if not out.strip():
            raise CLIError(f"--out {out!r}: expected the name of a result folder (an empty name would write "
                           "into the current folder)")
        return Path(out)
    stem = "+".join(p.stem for p in paths[:3]) + ("+..." if len(paths) > 3 else "")
    return paths[0].with_name(f"{stem}.fit-{names[0] if len(names) == 1 else 'comparison'}")


def _jitter(option: str) -> str | bool:
    """The ``jitter`` argument of :func:`gonio.fitting.fit` for a ``--jitter`` choice."""
    return False if option == "none" else option
