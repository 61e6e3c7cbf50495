"""From measured files to a fit, as ``gonio fit`` does it: the analysis API.

::

    import gonio
    result = gonio.fit_recording(["plaster/fig16", "plaster/fig19"], models="oren-nayar")
    result                              # a short summary; in a notebook, an HTML table
    result.save("plaster.fit")          # result.json, chain.npz, posterior.nc, summary.txt
    gonio.report.write_report(result, "plaster.fit")

    result = gonio.fit_recording("data.csv", models=["lambert", "oren-nayar", "torrance-sparrow"],
                                 columns={"theta_i": "incidence"})
    result.comparison                   # the comparison that chose the model (JSON form)

:func:`load_data` reads what a user has: recording folders of ``gonio run`` (reduced and
joined, one sample measured by several protocols), or CSV tables of values
(:meth:`gonio.fitting.Dataset.from_csv`; several are joined). :func:`fit_recording` fits
one model, or compares several (:func:`gonio.fitting.compare_models`) and fits the chosen
one, with the comparison kept in the result. The command line calls these functions
(docs/api.md).
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

import numpy as np

if TYPE_CHECKING:
    from .fitting import Dataset, FitResult, Prior

__all__ = ["load_data", "fit_recording", "fit_dataset", "recording_notes", "model_candidates", "joined"]

def _paths(paths: str | Path | Sequence[str | Path]) -> list[Path]:
    items = [paths] if isinstance(paths, (str, Path)) else list(paths)
    if not items:
        raise ValueError("no data given: expected a recording folder or a CSV file (or several)")
    return [Path(p) for p in items]


def load_data(paths: str | Path | Sequence[str | Path], quantity: str | None = None, calibration: str = "common",
              linearity: bool = True, columns: Mapping[str, str] | None = None,
              angle_unit: str | None = None) -> tuple[Dataset, dict[str, Prior]]:
    """The dataset and priors a fit of ``paths`` uses.

    Parameters
    ----------
    paths : path or sequence of paths
        Recording folders of ``gonio run`` (one sample: reduced, then joined with
        :func:`gonio.reduction.combine_reduced`), or CSV files (joined). Mixing the two is
        refused.
    quantity : {"brdf", "normalised_radiance", "radiance"}, optional
        What to fit. Recordings: by default relative radiance with the reference
        standard's prior on ``scale`` (:meth:`gonio.reduction.Reduced.fit_inputs`), or
        normalised radiance without a standard. CSV: the file's ``# quantity:`` line, else
        ``brdf``.
    calibration : {"common", "per-incidence"}
        A recording's calibration by its reference standard.
    linearity : bool
        Correct a recording's readings by its camera linearity series.
    columns, angle_unit
        CSV only: column names and angle unit (:meth:`gonio.fitting.Dataset.from_csv`).

    Returns
    -------
    dataset : gonio.fitting.Dataset
        Its metadata carries notes on what is missing (an incomplete recording, rows left
        out), which the fit's flags repeat.
    priors : dict of name -> gonio.fitting.Prior

    Raises
    ------
    ValueError, FileNotFoundError
        Naming the path and what is wrong.
    """
    items = _paths(paths)
    folders = [p.is_dir() for p in items]
    if any(folders) and not all(folders):
        raise ValueError(f"{', '.join(map(str, items))}: recording folders and CSV files cannot be fitted together; "
                         "reduce the recordings (gonio reduce --brdf) and fit the CSV files, or fit the folders")
    for path in items:
        if not path.exists():
            raise FileNotFoundError(f"{path}: no such file or recording folder")
    if all(folders):
        if columns or angle_unit:
            raise ValueError("columns and angle_unit apply to CSV files, not to recording folders")
        return _recording_inputs(items, quantity, calibration, linearity)
    if calibration != "common" or not linearity:
        raise ValueError("calibration and the linearity correction apply to recording folders, not to CSV files")
    from .fitting import Dataset

    datasets = [Dataset.from_csv(p, quantity=quantity, columns=columns, angle_unit=angle_unit) for p in items]
    return (datasets[0] if len(datasets) == 1 else joined(datasets)), {}


def _recording_inputs(folders: list[Path], quantity: str | None, calibration: str,
                      linearity: bool) -> tuple[Dataset, dict[str, Prior]]:
    from dataclasses import replace

    from .fitting.csv_table import DATA_NOTES
    from .reduction import combine_reduced, reduce_recording

    parts = [reduce_recording(folder, linearity=linearity) for folder in folders]
    try:
        reduced = parts[0] if len(parts) == 1 else combine_reduced(parts, label=parts[0].label)
        dataset, priors = _quantity_of(reduced, quantity, calibration)
    except ValueError as error:
        raise ValueError(f"{', '.join(map(str, folders))}: {error}") from None
    notes = [note for folder in folders for note in recording_notes(folder, dataset.quantity)]
    if notes:
        dataset = replace(dataset, metadata={**dataset.metadata, DATA_NOTES: notes})
    return dataset, priors


def _quantity_of(reduced, quantity: str | None, calibration: str) -> tuple[Dataset, dict[str, Prior]]:
    """The dataset of ``quantity`` of a reduced recording and the priors it implies."""
    if quantity is None:
        return reduced.fit_inputs(calibration)
    if quantity == "normalised_radiance":
        if calibration != "common":
            raise ValueError("calibration per incidence does not apply to normalised radiance (each incidence's "
                             "level is divided out, the calibration with it)")
        return reduced.normalised_radiance(), {}
    return {"brdf": reduced.brdf, "radiance": reduced.relative_radiance}[quantity](calibration), {}


def joined(datasets: Sequence[Dataset]) -> Dataset:
    """Several datasets of one quantity as one (covariances block-diagonal: independent files).

    Raises
    ------
    ValueError
        The quantities differ.
    """
    from .fitting import Dataset, LowRankCovariance
    from .fitting.covariance import block_diagonal

    quantities = {d.quantity for d in datasets}
    if len(quantities) > 1:
        raise ValueError(f"the files hold different quantities {sorted(quantities)}; fit them separately")
    covariance = None
    if any(d.covariance is not None for d in datasets):
        covariance = block_diagonal([d.covariance if d.covariance is not None
                                     else LowRankCovariance(d.sigma**2, np.zeros((d.n, 0))) for d in datasets])
    cat = lambda name: np.concatenate([getattr(d, name) for d in datasets])  # noqa: E731
    metadata = {k: v for d in reversed(datasets) for k, v in d.metadata.items()}
    metadata["joined"] = [d.label for d in datasets]
    return Dataset(cat("theta_i"), cat("phi_i"), cat("theta_r"), cat("phi_r"), cat("value"), cat("sigma"),
                   quantity=datasets[0].quantity, label=" + ".join(d.label for d in datasets), metadata=metadata,
                   covariance=covariance)


def recording_notes(folder: str | Path, quantity: str) -> list[str]:
    """What a recording lacks, and what that changes for a fit of ``quantity``: a run that
    did not complete (points measured of those planned), a reference standard planned but
    not measured (the values are relative, not BRDF). Empty for a whole recording.
    """
    from .data import read_metadata, read_points
    from .protocols import loads, plan
    from .reduction import CHECK_BLOCK, REFERENCE_BLOCK

    folder = Path(folder)
    metadata = read_metadata(folder)
    status = metadata.get("status", "unknown")
    protocol = loads(metadata["protocol"]["text"], source=str(metadata["protocol"].get("source") or "PROTOCOL"))
    rows = read_points(folder, as_arrays=False)
    measured = [r for r in rows if r.get("status") == "ok"]
    sample = sum(1 for r in measured if r.get("block") not in (REFERENCE_BLOCK, CHECK_BLOCK))
    planned = len(plan(protocol).points)
    notes = []
    if status != "complete" or sample < planned:
        notes.append(f"{folder}: the recording is {status}: {sample} of {planned} planned sample points measured "
                     f"(resume it with 'gonio run {protocol.source} --out {folder} --resume' to measure the rest)")
    if protocol.reference is not None and not any(r.get("block") == REFERENCE_BLOCK for r in measured):
        what = ("the values are relative radiance normalised per incidence (L/L(0)), not calibrated BRDF, and "
                "carry no absolute level" if quantity != "brdf" else "no calibration")
        notes.append(f"{folder}: its reference standard was planned but not measured: {what}")
    return notes


def model_candidates(models: str | Sequence[str], fixed: Mapping[str, float] | None = None
                     ) -> list[tuple[str, dict[str, float]]]:
    """Each model with the fixed values that belong to it, as ``gonio fit --model`` and
    ``gonio curet fit --model`` take them: ``NAME`` or ``NAME:p=v,...`` (values fixed for that
    candidate alone, ``oren-nayar:ir_weight=1``), plus the ``fixed`` values of every
    candidate that has the parameter, and the rig's (alignment, stray light, scale), which
    every candidate shares.

    >>> model_candidates(["lambert", "oren-nayar:ir_weight=1"], {"rho": 0.5})
    [('lambert', {'rho': 0.5}), ('oren-nayar', {'ir_weight': 1.0, 'rho': 0.5})]

    Raises
    ------
    ValueError
        An unknown model, a spec value that is not a number (model options go in
        ``options``), or a fixed value that belongs to no candidate.
    """
    from . import models as registry
    from .fitting.rig_errors import RIG_ERROR_NAMES
    from .sample_specs import split_model_spec

    specs = [models] if isinstance(models, str) else list(models)
    if not specs:
        raise ValueError("models: expected at least one registered model name")
    fixed = dict(fixed or {})
    parsed = []
    for spec in specs:
        name, values, options = split_model_spec(spec)
        if options:
            raise ValueError(f"model {spec!r}: {sorted(options)} are not numbers; a value after ':' fixes a parameter "
                             "(model options go in --option)")
        parsed.append((name, values))
    shared = set(RIG_ERROR_NAMES) | {"scale", "jitter", "rel_jitter"}
    unknown = sorted(set(fixed) - shared - {p for name, _ in parsed for p in registry.get(name).param_names})
    if unknown:
        raise ValueError(f"fixed parameter(s) {unknown} belong to none of the models {specs}")
    return [(name, {**values, **{k: v for k, v in fixed.items()
                                 if k in registry.get(name).param_names or k in shared}})
            for name, values in parsed]


def fit_recording(paths: str | Path | Sequence[str | Path], models: str | Sequence[str] = "oren-nayar", *,
                  fixed: Mapping[str, float] | None = None, priors: Mapping[str, Prior] | None = None,
                  mcmc: bool = True, jitter: bool | str = "auto", options: Mapping[str, Any] | None = None,
                  alignment: str | Sequence[str] | None = None, stray_light: bool = False, seed: int | None = 0,
                  n_walkers: int | None = None, max_steps: int = 20000, rhat_limit: float = 1.01,
                  quantity: str | None = None, calibration: str = "common", linearity: bool = True,
                  columns: Mapping[str, str] | None = None, angle_unit: str | None = None,
                  progress: Callable[[int, int, float], None] | None = None,
                  announce: Callable[[str], None] | None = None) -> FitResult:
    """Fit measured data as ``gonio fit`` does: one model, or the best of several.

    Parameters
    ----------
    paths : path or sequence of paths
        Recording folders or CSV files (:func:`load_data`); several are fitted jointly.
    models : str or sequence of str
        One registered model, or several candidates (each ``NAME`` or ``NAME:p=v,...``,
        :func:`model_candidates`): then every candidate is fitted by
        least squares and compared (:func:`gonio.fitting.compare_models`), and the chosen
        one is fitted (with MCMC when ``mcmc``); the comparison is kept in the result
        (``result.comparison``) and saved with it (``comparison.json``, ``comparison.txt``).
    fixed, priors, mcmc, jitter, options, alignment, stray_light, seed, n_walkers, max_steps, rhat_limit, progress
        As :func:`gonio.fitting.fit`. Priors given here override the data's (a reference
        standard's prior on ``scale``).
    quantity, calibration, linearity, columns, angle_unit
        As :func:`load_data`.
    announce : callable, optional
        Called with a line of text at each stage (the command line prints them).

    Returns
    -------
    gonio.fitting.FitResult
    """
    dataset, data_priors = load_data(paths, quantity, calibration, linearity, columns, angle_unit)
    return fit_dataset(dataset, models, data_priors=data_priors, fixed=fixed, priors=priors, mcmc=mcmc, jitter=jitter,
                       options=options, alignment=alignment, stray_light=stray_light, seed=seed, n_walkers=n_walkers,
                       max_steps=max_steps, rhat_limit=rhat_limit, progress=progress, announce=announce)


def fit_dataset(dataset: Dataset, models: str | Sequence[str], *, data_priors: Mapping[str, Prior] | None = None,
                fixed: Mapping[str, float] | None = None, priors: Mapping[str, Prior] | None = None,
                mcmc: bool = True, jitter: bool | str = "auto", options: Mapping[str, Any] | None = None,
                alignment: str | Sequence[str] | None = None, stray_light: bool = False, seed: int | None = 0,
                n_walkers: int | None = None, max_steps: int = 20000, rhat_limit: float = 1.01,
                progress: Callable[[int, int, float], None] | None = None,
                announce: Callable[[str], None] | None = None) -> FitResult:
    """:func:`fit_recording` of a loaded dataset and its priors (:func:`load_data`)."""
    from .fitting import compare_models, fit

    candidates = model_candidates(models, fixed)
    say = announce or (lambda text: None)
    all_priors = {**dict(data_priors or {}), **dict(priors or {})}
    comparison = least_squares = None
    name, fixed = candidates[0]
    if len(candidates) > 1:
        say(f"comparing {len(candidates)} models on {dataset.n} {dataset.quantity} values (least squares)")
        comparison = compare_models(dataset, candidates, priors=all_priors, jitter=jitter, alignment=alignment,
                                    stray_light=stray_light)
        say(comparison.summary())
        chosen = comparison.row(comparison.chosen)
        name, fixed = chosen["model"], dict(chosen["fixed"])
        jitter = comparison.jitter or jitter  # the noise the candidates were compared with, as gonio demo
        if not options:  # the comparison's fit, made without options, is this fit's least squares
            least_squares = comparison.fits[comparison.chosen]
    say(f"fitting {name} to {dataset.n} {dataset.quantity} values" + (" (least squares, then MCMC)" if mcmc else ""))
    result = fit(dataset, name, fixed=fixed, priors=all_priors, mcmc=mcmc, jitter=jitter, options=options,
                 n_walkers=n_walkers, max_steps=max_steps, rhat_limit=rhat_limit, seed=seed, progress=progress,
                 alignment=alignment, stray_light=stray_light, least_squares=least_squares)
    if comparison is not None:
        result.comparison = comparison.to_dict()
    return result
