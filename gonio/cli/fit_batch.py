"""``gonio fit-batch``: fit every input x every model in parallel, resumably (:mod:`gonio.batch`)."""
from __future__ import annotations

import argparse
import functools
import os
import sys
import time
from pathlib import Path
from typing import Any, Mapping

from .arguments import name_value_pairs, number

#: Exit status when at least one fit of the batch failed (the table gives each reason).
EXIT_FAILED_FITS = 6


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio fit-batch``."""
    parser = subparsers.add_parser(
        "fit-batch",
        help="fit many inputs x models in parallel (joblib or Dask), resumably, into one table",
        description=(
            "Fit every input (CSV files and recording folders, as 'gonio fit' takes them; a folder that is not a "
            "recording stands for the CSV files and recordings inside it), or every CUReT sample (--curet), with "
            "every --model. The fits run on --workers processes (or a Dask cluster), each with one BLAS thread and a "
            "seed derived from --seed and its task id; each is saved in OUT/INPUT--MODEL/, a re-run skips finished "
            "fits, and a failed fit is recorded with its reason. Writes OUT/fits.csv, OUT/fits.nc and OUT/overview.md (docs/batch.md). "
            f"Exit status 0 when every fit finished (verdicts are in the table), {EXIT_FAILED_FITS} when some "
            "failed, 2 bad input."
        ),
    )
    parser.add_argument("data", nargs="*", help="CSV files, recording folders, or folders holding them")
    parser.add_argument("--curet", metavar="SAMPLES",
                        help="fit CUReT samples instead: 'all' or numbers and ranges, e.g. 6,10-12")
    parser.add_argument("--data-dir", metavar="DIR",
                        help="--curet: folder with abrdf.dat and table.txt (default as 'gonio curet')")
    parser.add_argument("--noise", default="kvd", metavar="kvd|relative:S",
                        help="--curet: the uncertainty model, as 'gonio curet fit' (default kvd)")
    parser.add_argument("--model", action="append", metavar="NAME[:p=v,...]",
                        help="model to fit to every input, repeatable (required for files; with --curet the "
                             "default is gonio curet fit's candidates)")
    parser.add_argument("--out", required=True, help="batch folder (an existing batch folder is resumed)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                        help="joblib worker processes (default: the number of cores)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run on a Dask distributed cluster at ADDRESS (e.g. tcp://host:8786) instead of "
                             "joblib; needs the 'dask' extra, and workers that see the inputs and --out")
    parser.add_argument("--seed", type=int, default=0, help="base seed of the batch (default 0)")
    parser.add_argument("--mcmc", action=argparse.BooleanOptionalAction, default=True,
                        help="sample each posterior with emcee (default: yes)")
    parser.add_argument("--jitter", choices=["auto", "none", "absolute", "relative"],
                        help="extra noise term, as gonio fit (default auto; absolute with --curet)")
    parser.add_argument("--walkers", type=int, default=None, help="emcee walkers (default 32)")
    parser.add_argument("--max-steps", type=int, default=20000, help="step limit of each chain (default 20000)")
    parser.add_argument("--tau-multiple", type=float, default=50.0,
                        help="chain length required, in autocorrelation times (default 50)")
    parser.add_argument("--rhat-limit", type=float, default=1.01, help="largest R-hat accepted (default 1.01)")
    parser.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                        help="hold a parameter fixed in every model that has it (repeatable)")
    parser.add_argument("--option", action="append", default=[], metavar="NAME=VALUE", help="model option")
    parser.add_argument("--quantity", choices=["brdf", "normalised_radiance", "radiance"],
                        help="what the values are, as gonio fit")
    parser.add_argument("--columns", action="append", default=[], metavar="NAME=COLUMN",
                        help="CSV column names, as gonio fit")
    parser.add_argument("--angle-unit", choices=["deg", "rad"], help="CSV angle unit, as gonio fit")
    parser.add_argument("--overview", action=argparse.BooleanOptionalAction, default=True,
                        help="write overview.md with its chart (default: yes)")
    parser.add_argument("--quiet", action="store_true", help="no progress display")
    parser.set_defaults(func=_run)


def curet_samples(text: str, available: list[int]) -> list[int]:
    """The sample numbers of ``--curet``: 'all', or numbers and ranges (``6,10-12``).

    >>> curet_samples("6,10-12", list(range(1, 62)))
    [6, 10, 11, 12]
    """
    from . import CLIError

    if text.strip() == "all":
        return list(available)
    numbers: list[int] = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        low, _, high = part.partition("-")
        try:
            numbers += list(range(int(low), int(high or low) + 1))
        except ValueError:
            raise CLIError(f"--curet {text!r}: expected 'all' or numbers and ranges such as 6,10-12") from None
    unknown = sorted(set(numbers) - set(available))
    if unknown or not numbers:
        raise CLIError(f"--curet {text!r}: samples {unknown or '(none)'} are not in the data "
                       f"({min(available)}-{max(available)})")
    return list(dict.fromkeys(numbers))


def curet_input(folder: str | None, number: int, noise: float | None):
    """The dataset of CUReT sample ``number`` with gonio curet's noise model (run in a worker)."""
    from .curet import curet_dataset, load_curet

    return curet_dataset(load_curet(folder), number, noise)[0]


def _curet_inputs(args: argparse.Namespace) -> dict[str, Any]:
    """One loader per CUReT sample of ``--curet``, by name ``curet-NN``."""
    from .curet import load_curet, parse_noise

    data = load_curet(args.data_dir)
    noise = parse_noise(args.noise)
    samples = curet_samples(args.curet, [int(n) for n in data.sample_numbers])
    return {f"curet-{n:02d}": functools.partial(curet_input, args.data_dir, n, noise) for n in samples}


def _settings(args: argparse.Namespace):
    from gonio.batch import BatchSettings

    from .fit import _option_value

    jitter = args.jitter or ("absolute" if args.curet else "auto")
    fixed = {k: number(k, v, "--fix") for k, v in name_value_pairs(args.fix, "--fix").items()}
    return BatchSettings(
        mcmc=args.mcmc, jitter=False if jitter == "none" else jitter, n_walkers=args.walkers,
        max_steps=args.max_steps, tau_multiple=args.tau_multiple, rhat_limit=args.rhat_limit, fixed=fixed,
        options={k: _option_value(v) for k, v in name_value_pairs(args.option, "--option").items()},
        quantity=args.quantity, columns=name_value_pairs(args.columns, "--columns") or None,
        angle_unit=args.angle_unit)


class _BatchProgress:
    """The batch's progress line (:class:`gonio.cli.progress.ProgressLine`): fits done of
    all, the estimated time left, the last fit finished and its verdict."""

    def __init__(self, quiet: bool):
        from .progress import ProgressLine

        self.line = None if quiet else ProgressLine("fits")
        self.start = time.monotonic()
        self.skipped = 0

    def __call__(self, done: int, total: int, row: Mapping[str, Any]) -> None:
        if self.line is None:
            return
        if row.get("status") == "skipped":
            self.skipped = done
            self.start = time.monotonic()
        fitted = done - self.skipped
        eta = (time.monotonic() - self.start) / fitted * (total - done) if fitted > 0 else None
        what = "skipped" if row.get("status") == "skipped" else (row.get("verdict") or "FAILED")
        self.line.update(done, total, eta, f"{row['task_id']}: {what}")


def _run(args: argparse.Namespace) -> int:
    from gonio.batch import fit_many

    from . import CLIError

    if bool(args.data) == bool(args.curet):
        raise CLIError("give either input paths or --curet SAMPLES (not both, not neither)")
    if not args.model and not args.curet:
        raise CLIError("--model is required for file inputs (repeat it to fit several models)")
    if args.workers < 1:
        raise CLIError(f"--workers {args.workers}: expected at least 1")
    if args.curet:
        from .curet import DEFAULT_CANDIDATES
    inputs = _curet_inputs(args) if args.curet else [Path(p) for p in args.data]
    models = args.model or list(DEFAULT_CANDIDATES)
    say = (lambda text: None) if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True))
    try:
        batch = fit_many(inputs, models, args.out, workers=args.workers, scheduler=args.scheduler, seed=args.seed,
                         settings=_settings(args), overview=args.overview, progress=_BatchProgress(args.quiet),
                         announce=say)
    except FileNotFoundError as error:
        raise CLIError(str(error)) from None
    fitted = len(batch.rows) - len(batch.skipped)
    print(f"{len(batch.rows)} fits: {fitted - len(batch.failed)} fitted, {len(batch.skipped)} skipped (finished "
          f"earlier), {len(batch.failed)} failed")
    for name, path in batch.files.items():
        print(f"{name}: {path}")
    return EXIT_FAILED_FITS if batch.failed else 0
