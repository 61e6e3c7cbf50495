"""``gonio curet``: list, export and fit the CUReT BRDF measurements.

Three actions on the measured samples of the Columbia-Utrecht Reflectance and Texture
database (Dana, van Ginneken, Nayar & Koenderink, ACM TOG 18(1), 1999; credit them
whenever the data is used or shown):

``gonio curet list``
    Every sample with its number, name and a few statistics.
``gonio curet export SAMPLE --out FILE.csv``
    A fitting CSV (``gonio fit`` format) of one sample: the 205 geometries [deg], the BRDF
    [1/sr] and the uncertainty of the noise model below.
``gonio curet fit SAMPLE --out DIR``
    Fits one or more models (default ``lambert``, ``oren-nayar-qualitative``,
    ``oren-nayar`` with ``ir_weight`` fixed at 1 and free), each by least squares and MCMC,
    writes a report per model and a model comparison.

Noise model (the decision, and why)
-----------------------------------
The files give one number per geometry, with no uncertainty.  The values are quantised to
0.001 sr^-1, and the scatter that matters is not the camera noise but the variation of the
sample (texture in the averaged image region, re-positioning of the sample for each of the
205 poses) and the calibration: effects proportional to the signal.  gonio therefore uses
a *relative* uncertainty whose size is estimated from the data themselves, independently
of the physical models under test:

1. a smooth, reciprocal description of the sample is fitted: the Koenderink-van Doorn
   isotropic series of order 6 (30 amplitudes, Tikhonov weight 1e-5 sr^-2;
   :func:`gonio.models.kvd.fit_series`), flexible enough to follow every matte sample
   (docs/kvd.md) yet far smoother than the point-to-point scatter;
2. the relative scatter of the data about it is
   ``s^2 = sum(residual^2) / (n - 30) / mean(smooth^2)`` (residual variance corrected for
   the 30 fitted amplitudes, over the mean square signal);
3. each value gets ``sigma_i = sqrt((s * |smooth_i|)^2 + q^2)`` with ``smooth_i`` the
   series fitted to all geometries (not the noisy value itself, which would bias a fit
   towards low values) and ``q = 0.001 / sqrt(12)`` sr^-1 the rounding of the files.

``s`` includes the series' own interpolation error, so it over- rather than
under-estimates the noise (by 0-12 % for Oren-Nayar surfaces with 4 % noise): a physical model that reaches a reduced chi-square near 1 fits
as well as the best smooth description the data support, and a larger value measures
systematic misfit.  ``--noise relative:0.05`` replaces the estimate by a fixed relative
uncertainty.  By default every fit also has ``jitter`` (extra noise in quadrature,
:mod:`gonio.fitting.problem`) so that posterior intervals widen when the model misfits,
and the model comparison uses the same likelihood (one likelihood for fitting and
selection, :mod:`gonio.fitting.selection`). The verdict (:mod:`gonio.fitting.adequacy`)
tells structure the model cannot follow (lack of fit against a flexible description:
inadequate) from a scatter larger than the estimate (noise understated).

Exit status of ``gonio curet fit``: 0 when every chain converged and the chosen model (or,
without a comparison, at least one candidate) is adequate; 3 when a chain did not
converge; 5 when the best verdict is "noise understated"; 4 when no model is adequate; 2
for bad input.

Geometry selection: every value is kept by default (negative values are legitimate
noisy measurements of a dark sample; dropping them would bias the fit upwards).
``--drop-negative`` removes them, ``--exclude-specular DEG`` removes the geometries whose
viewing direction lies within DEG of the mirror direction of the source (for shiny samples,
whose near-specular values the database notes may be clipped; the files do not mark them).

Data folder: ``--data DIR``, else the environment variable ``GONIO_CURET_DIR``, else
``shared/data/curet`` beside the repository checkout (see :func:`default_curet_dir`).
"""
from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from gonio.curet import ENVIRONMENT_VARIABLE, default_directory

from . import CLIError

__all__ = [
    "CREDIT",
    "DEFAULT_CANDIDATES",
    "NoiseEstimate",
    "default_curet_dir",
    "load_curet",
    "parse_sample",
    "parse_noise",
    "estimate_relative_noise",
    "select_geometries",
    "curet_dataset",
    "candidate_label",
    "candidate_slug",
    "register",
]

#: Credit line for anything that uses or shows the CUReT data.
CREDIT = (
    "CUReT data: K. J. Dana, B. van Ginneken, S. K. Nayar, J. J. Koenderink, "
    '"Reflectance and texture of real-world surfaces", ACM Transactions on Graphics 18(1), 1999'
)

#: Models fitted by ``gonio curet fit`` when no ``--model`` is given (model-spec syntax of
#: ``gonio models plot``: ``NAME[:param=value,...]``, values held fixed).
DEFAULT_CANDIDATES = ("lambert", "oren-nayar-qualitative", "oren-nayar:ir_weight=1", "oren-nayar")


# The files print each BRDF value with three decimals [1/sr]; the rounding error is uniform
# over one step, standard deviation step / sqrt(12).
QUANTISATION_STEP = 0.001
# Smooth reference of the noise estimate: KvD order and Tikhonov weight [sr^-2].  Order 6
# had the smallest 5-fold cross-validated error of orders 2-8 on samples 6, 10, 11 and 30
# (0.029, 0.034, 0.050, 0.038 relative rms; order 8 overfits without the penalty), and the
# weight 1e-5 keeps it from ringing.
SMOOTH_ORDER = 6
SMOOTH_REGULARIZATION = 1e-5


# ---------------------------------------------------------------------- data location
def default_curet_dir() -> Path:
    """The CUReT folder used when none is given (:func:`gonio.curet.default_directory`)."""
    return default_directory()


def load_curet(directory: str | Path | None = None, angle_order: str = "view-first"):
    """Read the CUReT files from ``directory`` (default :func:`default_curet_dir`).

    Raises
    ------
    CLIError
        The folder lacks ``abrdf.dat`` or ``table.txt`` (naming the folder and the ways to
        point gonio at the data).
    """
    from gonio.curet import read_curet

    folder = Path(directory) if directory is not None else default_curet_dir()
    missing = [name for name in ("abrdf.dat", "table.txt") if not (folder / name).is_file()]
    if missing:
        how = "" if directory is not None else f" (default location; set --data DIR or ${ENVIRONMENT_VARIABLE})"
        raise CLIError(f"CUReT folder {folder}{how} lacks {' and '.join(missing)}; "
                       "it must hold abrdf.dat and table.txt of the CUReT BRDF database")
    return read_curet(folder, angle_order=angle_order)


def parse_sample(text: str | int) -> int | str:
    """A sample key: a number (``"11"``) or a name (``"plaster_b"``)."""
    text = str(text).strip()
    return int(text) if text.isdigit() else text


# ---------------------------------------------------------------------- noise model
@dataclass(frozen=True)
class NoiseEstimate:
    """Uncertainties of one sample's values (module notes, "Noise model").

    Attributes
    ----------
    sigma : numpy.ndarray
        One-standard-deviation uncertainty of each value [1/sr].
    relative : float
        Relative uncertainty s [-].
    method : str
        ``"kvd-scatter"`` or ``"fixed"``.
    description : str
        One line for metadata and reports.
    smooth : numpy.ndarray
        The smooth reference each sigma is proportional to [1/sr].
    """

    sigma: np.ndarray
    relative: float
    method: str
    description: str
    smooth: np.ndarray


def parse_noise(text: str) -> float | None:
    """``"kvd"`` -> None (estimate), ``"relative:S"`` -> S (fixed relative uncertainty).

    Raises
    ------
    CLIError
        Anything else, or S outside (0, 1].
    """
    text = text.strip()
    if text == "kvd":
        return None
    kind, _, value = text.partition(":")
    if kind == "relative":
        try:
            relative = float(value)
        except ValueError:
            relative = math.nan
        if 0.0 < relative <= 1.0:
            return relative
        raise CLIError(f"--noise {text!r}: the relative uncertainty must be a number in (0, 1], e.g. relative:0.05")
    raise CLIError(f"--noise {text!r}: expected 'kvd' (estimated from the data) or 'relative:S' (e.g. relative:0.05)")


def estimate_relative_noise(
    theta_i: np.ndarray,
    phi_i: np.ndarray,
    theta_r: np.ndarray,
    phi_r: np.ndarray,
    brdf: np.ndarray,
    relative: float | None = None,
) -> NoiseEstimate:
    """Relative uncertainties of measured BRDF values from the scatter about a smooth fit.

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : numpy.ndarray
        Geometries [deg].
    brdf : numpy.ndarray
        Measured BRDF [1/sr].
    relative : float, optional
        Use this relative uncertainty [-] instead of estimating it (the smooth reference
        is still fitted).

    Returns
    -------
    NoiseEstimate

    Raises
    ------
    ValueError
        Fewer geometries than twice the number of series amplitudes (60) when estimating.

    Notes
    -----
    The smooth reference is the isotropic Koenderink-van Doorn series (KvD 1998, eq 26-31)
    of order 6 (p = 30 amplitudes) fitted by Tikhonov-regularised least squares; the
    relative scatter is ``s^2 = sum(residual^2) / (n - p) / mean(smooth^2)``, the residual
    variance corrected for the p fitted amplitudes over the mean square signal: a
    consistent estimate when the scatter is proportional to the signal.  Checked on
    Oren-Nayar BRDFs at the CUReT geometries with 4 % Gaussian relative noise (20 seeds):
    s = 0.040-0.045 on average (the excess is the series' interpolation error, 0.002-0.022
    without noise), so s errs on the large side.

    Examples
    --------
    >>> import numpy as np, gonio
    >>> rng = np.random.default_rng(1)
    >>> ti, tr = rng.uniform(0, 80, 200), rng.uniform(0, 80, 200)
    >>> pi_, pr = rng.uniform(-180, 180, 200), rng.uniform(-180, 180, 200)
    >>> f = gonio.brdf("oren-nayar", ti, pi_, tr, pr, rho=0.8, sigma=20)
    >>> noisy = f * (1 + 0.04 * rng.standard_normal(200))
    >>> 0.03 < estimate_relative_noise(ti, pi_, tr, pr, noisy).relative < 0.05
    True
    """
    from gonio.models import kvd

    n_modes = len(kvd.isotropic_indices(SMOOTH_ORDER))
    n = brdf.size
    if relative is None and n < 2 * n_modes:
        raise ValueError(
            f"{n} geometries are too few to estimate the noise with the order-{SMOOTH_ORDER} series "
            f"({n_modes} amplitudes need >= {2 * n_modes} values); give a fixed relative uncertainty "
            "(--noise relative:S)"
        )
    fitted = kvd.fit_series(theta_i, phi_i, theta_r, phi_r, brdf, order=SMOOTH_ORDER,
                            regularization=SMOOTH_REGULARIZATION)
    smooth = fitted.fitted
    if relative is None:
        relative = float(np.sqrt(np.sum(fitted.residuals**2) / (n - n_modes) / np.mean(smooth**2)))
        method = "kvd-scatter"
        description = (
            f"sigma = sqrt((s f_smooth)^2 + q^2), s = {relative:.4f} the relative scatter about a KvD "
            f"order-{SMOOTH_ORDER} series f_smooth ({n_modes} amplitudes), q = {QUANTISATION_STEP:g}/sqrt(12) sr^-1 "
            "(rounding)"
        )
    else:
        relative = float(relative)
        method = "fixed"
        description = (
            f"sigma = sqrt((s f_smooth)^2 + q^2), fixed s = {relative:g}, f_smooth a KvD order-{SMOOTH_ORDER} "
            f"series, q = {QUANTISATION_STEP:g}/sqrt(12) sr^-1 (rounding)"
        )
    quantisation = QUANTISATION_STEP / math.sqrt(12.0)
    sigma = np.sqrt((relative * np.abs(smooth)) ** 2 + quantisation**2)
    return NoiseEstimate(sigma, relative, method, description, smooth)


# ---------------------------------------------------------------------- data selection
def select_geometries(sample, exclude_specular: float = 0.0, drop_negative: bool = False) -> tuple[np.ndarray, dict[str, int]]:
    """Mask of the geometries to fit, and how many each rule dropped.

    Parameters
    ----------
    sample : gonio.curet.CuretSample
    exclude_specular : float
        Drop geometries whose viewing direction lies within this angle [deg] of the mirror
        direction of the source (0 keeps all).
    drop_negative : bool
        Drop negative values.

    Raises
    ------
    ValueError
        ``exclude_specular`` outside [0, 90] deg, or nothing left.
    """
    from gonio.geometry import angle_between

    if not 0.0 <= exclude_specular <= 90.0:
        raise ValueError(f"exclude_specular = {exclude_specular:g} deg is outside [0, 90] deg")
    keep = np.ones(sample.brdf.size, bool)
    dropped = {"near_specular": 0, "negative": 0}
    if exclude_specular > 0.0:
        off_mirror = angle_between(sample.theta_i, sample.phi_i + 180.0, sample.theta_r, sample.phi_r)
        near = off_mirror < exclude_specular
        dropped["near_specular"] = int(np.count_nonzero(near))
        keep &= ~near
    if drop_negative:
        negative = sample.negative & keep
        dropped["negative"] = int(np.count_nonzero(negative))
        keep &= ~negative
    if not keep.any():
        raise ValueError(f"no geometry of CUReT sample {sample.number} is left after the selection")
    return keep, dropped


def curet_dataset(
    data,
    key: int | str,
    noise: float | None = None,
    exclude_specular: float = 0.0,
    drop_negative: bool = False,
):
    """A :class:`gonio.fitting.Dataset` of one CUReT sample with the noise model.

    Parameters
    ----------
    data : gonio.curet.CuretData
        From :func:`load_curet` or :func:`gonio.curet.read_curet`.
    key : int or str
        Sample number (1-61) or name.
    noise : float, optional
        Fixed relative uncertainty; None estimates it (module notes).
    exclude_specular, drop_negative
        Geometry selection (:func:`select_geometries`).

    Returns
    -------
    dataset : Dataset
        Absolute BRDF [1/sr]; ``metadata`` records the sample, the selection, the noise
        model and the credit.
    noise : NoiseEstimate
        For the selected geometries.

    Examples
    --------
    >>> dataset, noise = curet_dataset(load_curet(), "plaster_a")     # doctest: +SKIP
    >>> dataset.n, round(noise.relative, 3)                          # doctest: +SKIP
    (205, 0.036)
    """
    from gonio.fitting import Dataset

    sample = data.sample(key)
    keep, dropped = select_geometries(sample, exclude_specular, drop_negative)
    geometry = tuple(g[keep] for g in (sample.theta_i, sample.phi_i, sample.theta_r, sample.phi_r))
    values = sample.brdf[keep]
    estimate = estimate_relative_noise(*geometry, values, relative=noise)
    metadata = {
        "source": CREDIT,
        "curet_sample": sample.number,
        "curet_name": sample.name,
        "angle_order": data.angle_order,
        "geometries_used": int(keep.sum()),
        "dropped_near_specular": dropped["near_specular"],
        "dropped_negative": dropped["negative"],
        "exclude_specular_deg": float(exclude_specular),
        "noise_model": estimate.description,
        "noise_relative": round(estimate.relative, 6),
    }
    dataset = Dataset(*geometry, values, estimate.sigma, quantity="brdf",
                      label=f"CUReT {sample.number} {sample.name}", metadata=metadata)
    return dataset, estimate


# ---------------------------------------------------------------------- candidates
def candidate_label(name: str, fixed: dict[str, Any]) -> str:
    """``name`` or ``name (k=v, ...)`` as :func:`gonio.fitting.compare_models` labels it."""
    from gonio.fitting.selection import candidate_label as comparison_label  # imported on use: fast CLI start

    return comparison_label(name, fixed)


def candidate_slug(name: str, fixed: dict[str, Any], options: dict[str, Any] | None = None) -> str:
    """A folder name for a candidate, e.g. ``oren-nayar.ir_weight-1``."""
    parts = [name] + [f"{k}-{v:g}" for k, v in fixed.items()] + [f"{k}-{v}" for k, v in (options or {}).items()]
    return re.sub(r"[^A-Za-z0-9_.+-]", "_", ".".join(parts))


def _parse_candidates(specs: Sequence[str]) -> list[tuple[str, dict[str, float], dict[str, str]]]:
    from gonio.sample_specs import split_model_spec

    return [split_model_spec(spec) for spec in specs]


# ---------------------------------------------------------------------- CLI
def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio curet`` with the actions ``list``, ``export`` and ``fit``."""
    parser = subparsers.add_parser(
        "curet",
        help="list, export and fit the CUReT BRDF measurements (Dana et al. 1999)",
        description=(
            "The measured BRDFs of the Columbia-Utrecht Reflectance and Texture database: 61 samples at 205 "
            "geometries, RGB-averaged absolute BRDF [1/sr]. " + CREDIT + "."
        ),
    )
    actions = parser.add_subparsers(dest="curet_action", metavar="ACTION")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--data", metavar="DIR",
                        help=f"folder with abrdf.dat and table.txt (default: ${ENVIRONMENT_VARIABLE}, else "
                             "shared/data/curet beside the gonio checkout)")
    common.add_argument("--angle-order", choices=["view-first", "illumination-first"], default="view-first",
                        help="column order of table.txt (default view-first; see gonio.curet)")
    selection = argparse.ArgumentParser(add_help=False)
    selection.add_argument("sample", help="sample number (1-61) or name (e.g. plaster_b, 'plaster_b zoomed')")
    selection.add_argument("--noise", default="kvd", metavar="kvd|relative:S",
                           help="uncertainty model: 'kvd' estimates a relative uncertainty from the scatter about a "
                                "smooth KvD series (default), 'relative:S' fixes it")
    selection.add_argument("--exclude-specular", type=float, default=0.0, metavar="DEG",
                           help="drop geometries within DEG of the mirror direction (default 0: keep all)")
    selection.add_argument("--drop-negative", action="store_true", help="drop negative (dark-noise) values")

    listing = actions.add_parser("list", parents=[common], help="list the samples with names and statistics")
    listing.set_defaults(func=_run_list)

    export = actions.add_parser("export", parents=[common, selection],
                                help="write one sample as a fitting CSV (gonio fit format)")
    export.add_argument("--out", required=True, metavar="FILE.csv", help="CSV file to write")
    export.set_defaults(func=_run_export)

    fitting = actions.add_parser(
        "fit", parents=[common, selection],
        help="fit models to one sample (least squares + MCMC), write reports and a comparison",
        description=(
            "Fit each model to one CUReT sample: least squares, then emcee (with a jitter term unless "
            "--no-jitter), a folder with result.json and report.html per model, and comparison.txt/.json "
            "(chi-square and its p-value, AIC, BIC, Laplace evidence under the fits' likelihood). Exit status 0 "
            "all good, 3 a chain did not converge, 4 no adequate model, 5 noise understated, 2 bad input. Models are NAME[:param=value,...] "
            "with the values held fixed, e.g. oren-nayar:ir_weight=1."
        ),
    )
    fitting.add_argument("--model", action="append", metavar="NAME[:p=v,...]",
                         help="model to fit, repeatable (default: " + ", ".join(DEFAULT_CANDIDATES) + ")")
    fitting.add_argument("--out", required=True, metavar="DIR",
                         help="output folder; refused if it already holds files, unless --overwrite")
    fitting.add_argument("--overwrite", action="store_true",
                         help="replace the results of an earlier 'gonio curet fit' in --out (only the files it "
                              "writes; other files are left alone)")
    fitting.add_argument("--mcmc", action=argparse.BooleanOptionalAction, default=True,
                         help="sample the posterior with emcee (default: yes)")
    fitting.add_argument("--jitter", nargs="?", const="absolute", default="absolute",
                         choices=["none", "absolute", "relative"],
                         help="the extra noise term of every fit and of the comparison, as in gonio fit: 'absolute' "
                              "(the default here: CUReT values carry an estimated noise whose size the fit adjusts), "
                              "'relative' or 'none'")
    fitting.add_argument("--no-jitter", dest="jitter", action="store_const", const="none",
                         help="the same as --jitter none")
    fitting.add_argument("--walkers", type=int, default=None,
                         help="emcee walkers (default 24, for every model with up to 11 free parameters, 2 k + 2 for k above: gonio.fitting.mcmc.default_walkers)")
    fitting.add_argument("--max-steps", type=int, default=20000, help="step limit of each chain (default 20000)")
    fitting.add_argument("--tau-multiple", type=float, default=50.0,
                         help="chain length required, in autocorrelation times (default 50)")
    fitting.add_argument("--rhat-limit", type=float, default=1.01,
                         help="largest rank-normalised split R-hat accepted for convergence (default 1.01)")
    fitting.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    fitting.add_argument("--report", action=argparse.BooleanOptionalAction, default=False,
                         help="also write report.html per model (default: no, as gonio fit; 'gonio report FOLDER' "
                              "writes it later)")
    fitting.add_argument("--quiet", action="store_true", help="no progress messages")
    fitting.set_defaults(func=_run_fit)
    parser.set_defaults(func=lambda args: _no_action(parser))


def _no_action(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


def format_sample_table(data) -> str:
    """Plain-text table of every sample: number, name, median BRDF, pi x median, negatives."""
    lines = [f"{'number':>6}  {'name':<18} {'min':>7} {'median':>7} {'max':>7} {'pi*median':>9} {'negative':>8}",
             "-" * 70]
    for number, name, row in zip(data.sample_numbers, data.names, data.brdf):
        lines.append(f"{int(number):>6}  {name:<18} {row.min():>7.3f} {np.median(row):>7.3f} {row.max():>7.3f} "
                     f"{math.pi * np.median(row):>9.3f} {int(np.count_nonzero(row < 0)):>8}")
    return "\n".join(lines)


def _run_list(args: argparse.Namespace) -> int:
    data = load_curet(args.data, args.angle_order)
    print(format_sample_table(data))
    print(f"{len(data.sample_numbers)} samples x {data.theta_i.size} geometries; BRDF [1/sr], RGB average "
          "(pi*median ~ albedo of a matte sample).")
    print(CREDIT + ".")
    return 0


def _dataset_from_args(args: argparse.Namespace):
    data = load_curet(args.data, args.angle_order)
    return curet_dataset(data, parse_sample(args.sample), parse_noise(args.noise), args.exclude_specular,
                         args.drop_negative)


def _describe(dataset, noise) -> str:
    meta = dataset.metadata
    dropped = meta["dropped_near_specular"] + meta["dropped_negative"]
    return (f"{dataset.label}: {dataset.n} geometries ({dropped} dropped), relative uncertainty "
            f"{noise.relative:.4f} ({noise.method})")


def _run_export(args: argparse.Namespace) -> int:
    dataset, noise = _dataset_from_args(args)
    path = dataset.to_csv(args.out)
    print(_describe(dataset, noise))
    print(f"written: {path}")
    return 0


def comparison_record(comparison) -> dict[str, Any]:
    """JSON-safe form of a :class:`gonio.fitting.ModelComparison`."""
    from gonio.fitting.results import _clean  # the fit results' JSON conversion (NaN -> null)

    record = comparison.to_dict()
    for row, full in zip(record["rows"], comparison.rows):
        row["warnings"] = full["warnings"]
    return _clean(record)


#: Files ``gonio curet fit`` writes at the top of its output folder (each candidate gets a
#: fit result folder of its own).
DATA_FILE = "data.csv"
COMPARISON_TEXT = "comparison.txt"
COMPARISON_JSON = "comparison.json"


def check_fit_folder(out: Path, overwrite: bool, folders: Sequence[str]) -> bool:
    """Refuse an output folder that would overwrite files gonio did not write.

    Parameters
    ----------
    out : Path
        The ``--out`` folder.
    overwrite : bool
        Whether the results of an earlier ``gonio curet fit`` may be replaced.
    folders : sequence of str
        The candidate folders this run writes inside ``out``.

    Returns
    -------
    bool
        True when an earlier run's results will be replaced.

    Raises
    ------
    CLIError
        ``out`` is a file; or it holds files and ``overwrite`` is not given; or it is not
        the output of ``gonio curet fit`` (comparison.txt and a gonio fit result in a
        candidate folder); or a candidate folder holds files but no gonio fit result.
    """
    from gonio.fitting.results import is_fit_result

    from .fit import check_result_folder

    if out.exists() and not out.is_dir():
        kind = "an existing file" if out.is_file() else "a device or special file"
        raise CLIError(f"--out {out}: is {kind}, expected an output folder")
    if not out.exists() or not any(out.iterdir()):
        return False
    if not overwrite:
        raise CLIError(f"--out {out}: the folder already holds files; choose a new folder, or give --overwrite to "
                       "replace the results of an earlier 'gonio curet fit' there")
    earlier = (out / COMPARISON_TEXT).is_file() and any(is_fit_result(d) for d in out.iterdir() if d.is_dir())
    if not earlier:
        raise CLIError(f"--out {out}: holds files but no results of 'gonio curet fit' ({COMPARISON_TEXT} and a fit "
                       "result folder); --overwrite only replaces those (gonio never overwrites files it did not "
                       "write)")
    for name in folders:
        check_result_folder(out / name, overwrite=True, argument=f"--out {out}: candidate folder")
    return True


def _run_fit(args: argparse.Namespace) -> int:
    from gonio.fitting import ConvergenceWarning, compare_models, fit

    from .fit import remove_stale_results

    candidates = _parse_candidates(args.model or DEFAULT_CANDIDATES)
    dataset, noise = _dataset_from_args(args)
    if not args.out.strip():
        raise CLIError(f"--out {args.out!r}: expected the name of an output folder (an empty name would write into "
                       "the current folder)")
    out = Path(args.out)
    replacing = check_fit_folder(out, args.overwrite, [candidate_slug(*c) for c in candidates])
    out.mkdir(parents=True, exist_ok=True)
    dataset.to_csv(out / DATA_FILE)
    say = (lambda text: None) if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True))
    say(_describe(dataset, noise))
    summary_rows = []
    for name, fixed, options in candidates:
        label = candidate_label(name, fixed)
        folder = out / candidate_slug(name, fixed, options)
        say(f"fitting {label} ...")
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)  # reported below
            result = fit(dataset, name, fixed=fixed, options=options, mcmc=args.mcmc, jitter=_jitter(args.jitter),
                         n_walkers=args.walkers, max_steps=args.max_steps, tau_multiple=args.tau_multiple,
                         rhat_limit=args.rhat_limit,
                         seed=args.seed)
        result.save(folder)
        if replacing:
            remove_stale_results(folder, result.saved_files())  # the earlier report too, before drawing
        if args.report:
            from gonio.report.fit_report import write_report

            write_report(folder)
        seconds = time.perf_counter() - start
        summary_rows.append((label, folder, result, seconds))
        if result.converged is False:
            print(f"gonio: WARNING: {label}: the MCMC chain did NOT converge; posterior numbers are unreliable "
                  "(increase --max-steps)", file=sys.stderr)
    # The comparison uses the fits' likelihood: the noise model and, when fitted, the jitter.
    with_options = [candidate_label(name, fixed) for name, fixed, options in candidates if options]
    comparison = None if with_options else compare_models(dataset, [(name, fixed) for name, fixed, _ in candidates],
                                                          jitter=_jitter(args.jitter))
    lines = [_describe(dataset, noise), CREDIT + ".", ""]
    for label, folder, result, seconds in summary_rows:
        best = result.best_values()
        values = ", ".join(f"{k} = {best[k]:.4g}" for k in result.free)
        lines.append(f"{label:<34} redchi {result.least_squares.redchi:8.3f}  {values}  [{folder.name}, {seconds:.1f} s]")
    if comparison is not None:
        likelihood = ("the noise model and a fitted jitter" if _jitter(args.jitter) else
                      "the noise model, no jitter")
        lines += ["", f"Model comparison (posterior modes under {likelihood}, as the fits):", comparison.summary()]
        chosen = next(row for row in summary_rows if row[0] == comparison.chosen)
        spread_lines, spread = noise_model_lines(dataset, chosen[2], _jitter(args.jitter))
        lines += spread_lines
        record = {**comparison_record(comparison), "noise_models": {"model": comparison.chosen, **spread.to_dict()}}
        (out / COMPARISON_JSON).write_text(json.dumps(record, indent=1, allow_nan=False))
    else:
        if replacing and (out / COMPARISON_JSON).is_file():
            (out / COMPARISON_JSON).unlink()  # the earlier run's comparison, not this one's
        lines += ["", f"No model comparison: {', '.join(with_options)} set model options, which the comparison "
                      "does not take; fit them in a separate run."]
    lines += _loo_lines(summary_rows)
    text = "\n".join(lines)
    (out / COMPARISON_TEXT).write_text(text + "\n")
    print(text)
    print(f"results: {out}")
    return fit_exit_code([result for _, _, result, _ in summary_rows], comparison)


def _jitter(option: str) -> str | bool:
    """The ``jitter`` argument of the fits for a ``--jitter`` choice (as ``gonio fit``)."""
    return False if option == "none" else option


def noise_model_lines(dataset, result, jitter: bool | str):
    """The chosen fit's dependence on the shape of the estimated noise (lines of
    comparison.txt) and the :class:`gonio.fitting.noise_models.NoiseModelSpread`.

    Each 95 % interval is widened by the noise-model component (half the range of the
    least-squares values over the shapes), added in quadrature to each side's half-width.
    """
    from gonio.fitting.noise_models import noise_model_spread

    spread = noise_model_spread(dataset, result.model, result.fixed, jitter=jitter)
    lines = ["", f"Noise-model dependence of {result.model} (least squares with the estimated noise shaped relative, "
                 "shot-like and absolute, each at its median; docs/curet.md):", *spread.lines()]
    post = result.posterior
    for name, half_range in spread.half_range.items():
        if not post or name not in post.get("median", {}):
            continue
        median, low, high = post["median"][name], post["p2_5"][name], post["p97_5"][name]
        wide_low = median - math.hypot(median - low, half_range)
        wide_high = median + math.hypot(high - median, half_range)
        lines.append(f"    {name}: 95 % interval [{low:.5g}, {high:.5g}]; with the noise-model component "
                     f"[{wide_low:.5g}, {wide_high:.5g}]")
    return lines, spread


def _loo_lines(summary_rows) -> list[str]:
    """The PSIS-LOO comparison of the candidates' MCMC fits, as lines of comparison.txt."""
    from gonio.fitting import compare_loo
    from gonio.fitting.selection import loo_summary

    sampled = {label: result for label, _, result, _ in summary_rows if result.mcmc is not None}
    if len(sampled) < 2:
        return []
    return ["", "Predictive comparison (PSIS-LOO of the MCMC fits, Vehtari, Gelman & Gabry 2017):",
            loo_summary(compare_loo(sampled))]


def fit_exit_code(results: Sequence[Any], comparison) -> int:
    """Exit status of ``gonio curet fit`` (module docstring).

    Parameters
    ----------
    results : sequence of FitResult
        Every candidate's fit.
    comparison : ModelComparison or None
        The comparison, when one was made.
    """
    from gonio.fitting.adequacy import VERDICTS
    from gonio.fitting.results import EXIT_NOT_CONVERGED, verdict_exit_code

    if any(result.converged is False for result in results):
        return EXIT_NOT_CONVERGED
    if comparison is not None:
        return verdict_exit_code(comparison.chosen_verdict)
    verdicts = [r.adequacy.verdict if r.adequacy is not None else "adequate" for r in results]
    return verdict_exit_code(min(verdicts, key=VERDICTS.index))
