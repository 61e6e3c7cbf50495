"""``gonio fit``: fit a registered model to measured data (least squares, then MCMC)."""
from __future__ import annotations

import argparse
import contextlib
import sys
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator

if TYPE_CHECKING:  # loaded on use: the command line starts without the fitting stack
    from gonio.fitting import Dataset, Prior


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio fit``."""
    parser = subparsers.add_parser(
        "fit",
        help="fit a reflectance model to measured data (least squares + MCMC)",
        description=(
            "Fit a registered model to a CSV of measurements with the columns "
            "theta_i,phi_i,theta_r,phi_r,value,sigma (angles in degrees), or to a recording folder written "
            "by 'gonio run'. Weighted, bounded least squares, "
            "then Bayesian sampling with emcee until the chain is 50 autocorrelation times long. The result "
            "(result.json, chain.npz, posterior.nc, summary.txt) is written to a folder next to the data; "
            "'gonio report FOLDER' turns it into an HTML report. Every fit is tested for goodness of fit. "
            "Exit status: 0 converged and adequate, 2 bad input, 3 chain not converged, "
            "4 model inadequate, 5 noise understated (docs/fitting.md, 'Exit codes')."
        ),
    )
    parser.add_argument("data", help="CSV file (theta_i,phi_i,theta_r,phi_r,value,sigma) or a recording folder of "
                                     "'gonio run' (absolute BRDF when calibrated, else normalised radiance)")
    parser.add_argument("--model", required=True, action="append",
                        help="registered model name (see 'gonio models'); repeat to compare models")
    parser.add_argument("--quantity", choices=["brdf", "normalised_radiance", "radiance"],
                        help="what the values are (default: the file's '# quantity:' line, else brdf)")
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
                             "view_offset, theta_i_offset, phi_i_offset (axis zero offsets), tilt_x, tilt_y (sample "
                             "tilt) [deg], with normal priors N(0, 0.5 deg) unless --prior overrides them; for "
                             "recordings of this rig (docs/fitting.md, 'The rig's errors as parameters')")
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
                        help="number of emcee walkers (default 32, for every model: gonio.fitting.mcmc.default_walkers, chosen by measurement)")
    parser.add_argument("--max-steps", type=int, default=20000, help="step limit of the chain (default 20000)")
    parser.add_argument("--rhat-limit", type=float, default=1.01,
                        help="largest rank-normalised split R-hat accepted for convergence (default 1.01)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--out", help="result folder (default: DATA_STEM.fit-MODEL next to the data); "
                                      "refused if it already holds files, unless --overwrite")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an earlier gonio fit result in --out (only its result and report files; "
                             "other files are left alone)")
    parser.add_argument("--report", action="store_true", help="also write the HTML report into the result folder")
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
    from gonio.fitting.results import CHAIN_FILE, INFERENCE_DATA_FILE, RESULT_FILE, SUMMARY_FILE
    from gonio.report.fit_html import REPORT_FILES  # the names without matplotlib

    return (RESULT_FILE, CHAIN_FILE, INFERENCE_DATA_FILE, SUMMARY_FILE) + REPORT_FILES


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


def _pairs(items: list[str], what: str) -> dict[str, str]:
    pairs = {}
    for item in items:
        for part in item.split(","):
            if not part.strip():
                continue
            name, sep, value = part.partition("=")
            if not sep or not name.strip() or not value.strip():
                from gonio.cli import CLIError

                raise CLIError(f"{what} {part!r}: expected NAME=VALUE")
            pairs[name.strip()] = value.strip()
    return pairs


def _number(name: str, text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        from gonio.cli import CLIError

        raise CLIError(f"{what} {name}={text!r}: the value must be a number") from None


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
    """Prints the chain's progress to stderr at most every two seconds."""

    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.last = 0.0

    def __call__(self, steps: int, max_steps: int, tau: float) -> None:
        now = time.monotonic()
        if self.quiet or now - self.last < 2.0:
            return
        self.last = now
        need = f", needs >= {50 * tau:.0f} steps" if tau == tau and tau != float("inf") else ""
        print(f"  mcmc: step {steps}/{max_steps}, max tau = {tau:.1f}{need}", file=sys.stderr, flush=True)


def _load(path: Path, quantity: str | None, calibration: str = "common",
          linearity: bool = True) -> tuple[Dataset, dict[str, Prior]]:
    """A CSV file, or a recording folder written by 'gonio run' (reduced here).

    Returns the dataset and the priors it implies: for a calibrated recording fitted as
    it comes, relative radiance with the reference-standard prior on ``scale``
    (gonio.acquisition.Reduced.fit_inputs), calibrated as ``calibration`` says.
    """
    from gonio.cli import CLIError
    from gonio.fitting import Dataset

    if not path.is_dir():
        if calibration != "common" or not linearity:
            raise CLIError(f"{path}: --calibration and --no-linearity-correction apply to recording folders, not "
                           "to a CSV file of values")
        return Dataset.from_csv(path, quantity=quantity), {}
    from gonio.acquisition import reduce_recording

    reduced = reduce_recording(path, linearity=linearity)
    try:
        if quantity is None:
            return reduced.fit_inputs(calibration)
        if quantity == "normalised_radiance":
            if calibration != "common":
                raise ValueError("--calibration does not apply to normalised radiance (each incidence's level is "
                                 "divided out, the calibration with it)")
            return reduced.normalised_radiance(), {}
        return {"brdf": reduced.brdf, "radiance": reduced.relative_radiance}[quantity](calibration), {}
    except ValueError as error:
        raise CLIError(f"{path}: {error}") from None


def _alignment(items: list[str]) -> tuple[str, ...]:
    """The ``--alignment`` names (repeatable, comma-separated, or 'all')."""
    from gonio.cli import CLIError
    from gonio.fitting.rig_errors import parse_alignment

    try:
        return parse_alignment(",".join(items))
    except ValueError as error:
        raise CLIError(f"--alignment: {error}") from None


def _run(args: argparse.Namespace) -> int:
    from gonio import models
    from gonio.fitting import ConvergenceWarning, compare_models, fit, parse_prior
    from gonio.fitting.rig_errors import ALIGNMENT_BOUND_DEG, RIG_ERROR_NAMES, STRAY_LIGHT
    from gonio.fitting.results import verdict_exit_code

    data_path = Path(args.data)
    dataset, priors = _load(data_path, args.quantity, args.calibration, args.linearity_correction)
    fixed = {k: _number(k, v, "--fix") for k, v in _pairs(args.fix, "--fix").items()}
    options = {k: _option_value(v) for k, v in _pairs(args.option, "--option").items()}
    alignment = _alignment(args.alignment)
    if len(args.model) > 1:
        rig = {k: v for k, v in fixed.items() if k in RIG_ERROR_NAMES}  # the rig's errors: every candidate's
        candidates = [(name, {**{k: v for k, v in fixed.items() if k in models.get(name).param_names}, **rig})
                      for name in args.model]
        comparison = compare_models(dataset, candidates, priors=priors, jitter=_jitter(args.jitter),
                                    alignment=alignment, stray_light=args.stray_light)
        print(comparison.summary())
        return verdict_exit_code(comparison.row(comparison.chosen)["verdict"])
    name = args.model[0]
    model = models.get(name)
    for key, text in _pairs(args.prior, "--prior").items():
        bounds = model.param(key).bounds if key in model.param_names else (-float("inf"), float("inf"))
        if key in RIG_ERROR_NAMES:
            bounds = STRAY_LIGHT.bounds if key == STRAY_LIGHT.name else (-ALIGNMENT_BOUND_DEG, ALIGNMENT_BOUND_DEG)
        priors[key] = parse_prior(text, bounds)
    if args.out is not None and not args.out.strip():
        from gonio.cli import CLIError

        raise CLIError(f"--out {args.out!r}: expected the name of a result folder (an empty name would write "
                       "into the current folder)")
    out = Path(args.out) if args.out else data_path.with_name(f"{data_path.stem}.fit-{name}")
    replacing = check_result_folder(out, args.overwrite)
    if not args.quiet:
        print(f"fitting {name} to {dataset.n} {dataset.quantity} values from {data_path}", file=sys.stderr)
    with _report_workers(args.report) as pool:  # they import matplotlib while this process fits
        drawing = _report_drawing(pool, dataset) if args.report else None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)  # reported below, loudly
            result = fit(
                dataset, name, fixed=fixed, priors=priors, mcmc=args.mcmc, jitter=_jitter(args.jitter),
                options=options, n_walkers=args.walkers, max_steps=args.max_steps, rhat_limit=args.rhat_limit,
                seed=args.seed, progress=_Progress(args.quiet), alignment=alignment, stray_light=args.stray_light,
            )
        if drawing is not None:
            drawing.draw_fit(result)  # the workers draw while this process saves
        path = result.save(out)
        if replacing:
            remove_stale_results(out, result.saved_files())  # the earlier fit's report too, before writing it
        print(result.summary())
        if drawing is not None:
            from gonio.report.workers import finish_report

            print(f"report: {finish_report(pool, result, out, drawing)}")
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


def _jitter(option: str) -> str | bool:
    """The ``jitter`` argument of :func:`gonio.fitting.fit` for a ``--jitter`` choice."""
    return False if option == "none" else option


def _report_drawing(pool, dataset: Dataset):
    """The report's figures (gonio.report.workers.ReportDrawing), those of the measurements
    alone given to the workers now."""
    from gonio.report.workers import ReportDrawing, print_warning

    drawing = ReportDrawing(pool, print_warning)
    drawing.draw_measurements(dataset)
    return drawing


@contextlib.contextmanager
def _report_workers(report: bool) -> Iterator[Any]:
    """The report's worker pool (gonio.report.workers.report_pool) for ``gonio fit``, or
    None: none without ``--report`` or with one report process.

    While the workers run, this process keeps its BLAS to one thread
    (:func:`threadpoolctl.threadpool_limits`): a fit's matrix products (a few hundred
    values) gain nothing from threads, and OpenBLAS's threads, which spin between calls,
    took 0.4 s of CPU from the cores the fork server and the workers draw on
    (docs/fitting.md "Performance").
    """
    if not report:
        yield None
        return
    from threadpoolctl import threadpool_limits

    from gonio.report.workers import print_warning, report_pool, report_processes

    processes = report_processes(while_fitting=True)
    with report_pool(processes if processes > 1 else 0, warn=print_warning) as pool:
        with threadpool_limits(limits=1, user_api="blas") if pool is not None else contextlib.nullcontext():
            yield pool
