"""Fit results: posterior summaries, flags, JSON persistence and a plain-text report.

A :class:`FitResult` bundles the dataset, the least-squares result, the MCMC chain (when
sampled) and the numbers computed from them:

* posterior median, 16/84 and 2.5/97.5 percentiles, MAP (highest posterior density among
  the least-squares optimum and every chain position), correlation matrix;
* flags for parameters piled at a bound of their range, strongly correlated pairs,
  degenerate or insensitive parameters, a chain that did not converge;
* chi-square and reduced chi-square, AIC and BIC.

It is saved as ``result.json`` (everything but the chain) plus ``chain.npz`` (chain and log
posterior) in one folder, and read back with :meth:`FitResult.load`.
"""
from __future__ import annotations

import datetime as _dt
import io
import json
import math
import textwrap
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

import gonio
from gonio import models
from gonio.files import write_atomic

from .adequacy import Adequacy, assess
from .discrepancy import discrepancy_statement
from .diagnostics import RHAT_LIMIT
from .covariance import LowRankCovariance
from .dataset import Dataset
from .least_squares import LeastSquaresResult, _with_unit
from .mcmc import LogPosterior, McmcResult
from .priors import Prior, prior_from_dict
from .rig_errors import RIG_ERROR_NAMES, RigPrediction
from .evaluation import combine_prediction, evaluated_model
from .problem import FitProblem, jitter_mode, predict_quantity
from .validity import ModelValidity
from .text import digits_to_resolve
from .truth import known_truth, truth_lines
from .selection import COMPARISON_FILE, COMPARISON_TEXT, comparison_text, information_criteria

__all__ = ["FitResult", "RESULT_FILE", "CHAIN_FILE", "COVARIANCE_FILE", "SUMMARY_FILE", "INFERENCE_DATA_FILE",
           "RESULT_FORMAT",
           "is_fit_result", "EXIT_BAD_INPUT", "EXIT_NOT_CONVERGED", "EXIT_INADEQUATE",
           "EXIT_NOISE_UNDERSTATED", "verdict_exit_code"]

RESULT_FILE = "result.json"
CHAIN_FILE = "chain.npz"
#: The data's covariance matrix (N x N doubles), beside result.json rather than in it: as
#: JSON text it made result.json 554 MB for 4708 values.
COVARIANCE_FILE = "covariance.npz"
#: The version of result.json: 2 keeps the covariance in :data:`COVARIANCE_FILE`.
RESULT_FORMAT_VERSION = 2
#: Largest number of posterior draws (walkers x steps) in an InferenceData / posterior.nc:
#: Stan's default (4 chains x 1000 draws), enough for PSIS-LOO, whose Pareto-k threshold
#: min(1 - 1/log10(S), 0.7) is 0.7 for any S above 2,200 draws (Vehtari et al. 2024,
#: "Pareto smoothed importance sampling", JMLR 25); every further draw costs one
#: prediction of every value when the result is saved.
INFERENCE_DRAWS = 4000
#: Most replicated datasets in posterior.nc's posterior_predictive group (the last steps of
#: the chain, every walker).
PREDICTIVE_DRAWS = 1000
#: Most values (draws x data values) of each pointwise group of posterior.nc
#: (log_likelihood, posterior_predictive): 128 MB of doubles. With many values the draws
#: are thinned further, down to one step of every walker, so the file and the memory that
#: writes it grow linearly with the data, not with draws x data.
POINTWISE_ELEMENTS = 2**24
SUMMARY_FILE = "summary.txt"
#: Draws x geometries evaluated at once by FitResult.posterior_predictive.
_PREDICTIVE_ELEMENTS = 2**16
#: The posterior as ArviZ InferenceData (netCDF), written with MCMC.
INFERENCE_DATA_FILE = "posterior.nc"
#: Exit status of ``gonio fit`` / ``gonio demo`` / ``gonio curet fit`` (docs/fitting.md).
EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3
EXIT_INADEQUATE = 4
EXIT_NOISE_UNDERSTATED = 5
#: Posterior draws of the predictive check under a slow (exact) model.
SLOW_MODEL_DRAWS = 50


def verdict_exit_code(verdict: str | None) -> int:
    """The exit status of a goodness-of-fit verdict (docs/fitting.md, "Exit codes"): 0 adequate
    (or no verdict), 5 noise understated, 4 inadequate."""
    return {"inadequate": EXIT_INADEQUATE, "noise understated": EXIT_NOISE_UNDERSTATED}.get(verdict or "", 0)
#: The ``format`` field of every result.json gonio writes.
RESULT_FORMAT = "gonio-fit-result"

# A posterior is "piled at a bound" when its 95 % interval reaches to within 5 % of its own
# width of the bound: the data are then consistent with the bound value itself.  For a
# Gaussian posterior centred mu away from the bound with standard deviation s this flags
# mu < 2.2 s; a half-normal against the bound gives 0.014 < 0.05.
_PILE_FRACTION = 0.05
# Pairs with |correlation| above this are reported as nearly degenerate.
_STRONG_CORRELATION = 0.95
# What to do about a strong correlation whose cause is known (docs/validity.md).
_DEGENERACY_ADVICE = {
    frozenset(("rho", "scale")): (
        ": relative radiance without a reference standard fixes rho x scale, and rho only through the "
        "interreflection's rho^2; measure a reference standard ([reference] in the protocol, docs/acquisition.md) "
        "for a prior on scale, or quote rho x scale"),
}
# The plain-text summary lists correlations above this (as lmfit does, at 0.1).
_REPORTED_CORRELATION = 0.1


def _clean(value: Any) -> Any:
    """JSON-safe copy: NaN/inf -> None, numpy -> Python."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        if value.dtype.kind == "f" and np.isfinite(value).all():
            return value.tolist()  # Python floats already (a 90 x 90 covariance: 8,100 of them)
        return _clean(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def _nan(value: Any) -> float:
    return math.nan if value is None else float(value)


def is_fit_result(folder: str | Path) -> bool:
    """Whether ``folder`` holds a fit result written by :meth:`FitResult.save`: one that
    :meth:`FitResult.load` reads whole (its dataset, parameters and chain, of one save),
    not a ``result.json`` that merely claims the format (``--overwrite`` replaces only
    what gonio wrote)."""
    path = Path(folder) / RESULT_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    if not (isinstance(data, dict) and data.get("format") == RESULT_FORMAT):
        return False
    try:
        FitResult.load(path)
    except Exception:  # noqa: BLE001 - any failure to read it whole: not a result gonio wrote
        return False
    return True


@dataclass
class FitResult:
    """Everything a fit produced (see the module docstring).

    Attributes
    ----------
    model : str
        Registered model name.
    dataset : Dataset
    fixed : dict
        Fixed parameter values.
    free : tuple of str
        Fitted parameters.
    options : dict
        Model options used.
    least_squares : LeastSquaresResult
    mcmc : McmcResult or None
    priors : dict of Prior
    jitter : str or None
        The extra-noise term fitted: None, ``"absolute"`` (``jitter``) or ``"relative"``
        (``rel_jitter``).
    posterior : dict
        ``median``, ``p16``, ``p84``, ``p2_5``, ``p97_5``, ``map`` (dicts by name),
        ``correlation`` (matrix over ``free``), ``tau``, ``ess`` (dicts by name),
        ``acceptance_fraction`` (mean) and the run's bookkeeping; empty without MCMC.
    flags : list of str
        Every warning, least squares and MCMC.
    adequacy : Adequacy or None
        The goodness-of-fit verdict (:mod:`gonio.fitting.adequacy`): chi-square and
        posterior predictive p-values, extra noise relative to the stated uncertainties.
    alignment : tuple of str
        The alignment parameters of the fit, free or fixed (:mod:`gonio.fitting.rig_errors`).
    stray_light : bool
        Whether the rig's stray light is a parameter of the fit.
    comparison : dict or None
        The model comparison that chose this model, in its JSON form
        (:meth:`gonio.fitting.ModelComparison.to_dict`), when the fit followed one.
    validity : ModelValidity or None
        For an approximate model, its error against the exact model at the data and the
        shift of the optimum it causes (:mod:`gonio.fitting.validity`); None otherwise.
    """

    model: str
    dataset: Dataset
    fixed: dict[str, float]
    free: tuple[str, ...]
    options: dict[str, Any]
    least_squares: LeastSquaresResult
    mcmc: McmcResult | None = None
    priors: dict[str, Prior] = field(default_factory=dict)
    jitter: str | None = None
    posterior: dict[str, Any] = field(default_factory=dict)
    flags: list[str] = field(default_factory=list)
    created: str = ""
    gonio_version: str = ""
    result_id: str = ""
    adequacy: Adequacy | None = None
    alignment: tuple[str, ...] = ()
    stray_light: bool = False
    comparison: dict[str, Any] | None = None
    validity: ModelValidity | None = None

    # ------------------------------------------------------------------ construction
    @classmethod
    def build(
        cls,
        problem: FitProblem,
        least_squares: LeastSquaresResult,
        mcmc: McmcResult | None = None,
        priors: Mapping[str, Prior] | None = None,
        judge: FitProblem | None = None,
    ) -> "FitResult":
        """Assemble a result and compute the posterior summaries and flags.

        ``judge``: the problem whose likelihood the goodness of fit is assessed under (the
        exact model of a polished tabulated fit, :mod:`gonio.fitting.polish`; its posterior
        predictive p-value on :data:`SLOW_MODEL_DRAWS` draws); default ``problem``.
        """
        result = cls(
            model=problem.base_model.name,
            dataset=problem.dataset,
            fixed=dict(problem.fixed),
            free=problem.free,
            options=dict(problem.options),
            least_squares=least_squares,
            mcmc=mcmc,
            priors=dict(priors or {}),
            jitter=problem.jitter,
            alignment=problem.alignment,
            stray_light=problem.stray_light,
            created=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            gonio_version=gonio.__version__,
            result_id=uuid.uuid4().hex,
        )
        result.flags = list(least_squares.warnings)
        if mcmc is not None:
            result.posterior = _summarise(problem, least_squares, mcmc, result.priors)
            result.flags += mcmc.warnings + _posterior_flags(problem, result.posterior)
        samples = mcmc.samples() if mcmc is not None else None
        result.adequacy = (assess(problem, least_squares, samples) if judge is None
                           else assess(judge, least_squares, samples, max_draws=SLOW_MODEL_DRAWS))
        if not result.adequacy.adequate:
            result.flags.insert(0, result.adequacy.headline())
        return result

    @property
    def discrepancy(self) -> str:
        """What the model leaves out of a real surface, and how far its parameters were
        measured to fall from a rendered surface's (:mod:`gonio.fitting.discrepancy`)."""
        return discrepancy_statement(self.model)

    @property
    def adequate(self) -> bool | None:
        """Whether the model explains the data (None for a result saved without a verdict)."""
        return None if self.adequacy is None else self.adequacy.adequate

    def exit_code(self) -> int:
        """The command line's exit status for this fit (docs/fitting.md, "Exit codes")."""
        if self.converged is False:
            return EXIT_NOT_CONVERGED
        return verdict_exit_code(self.adequacy.verdict if self.adequacy is not None else None)

    # ------------------------------------------------------------------ access
    @property
    def specs(self) -> dict[str, models.Param]:
        """Parameter specifications (model parameters and nuisances), by name."""
        problem = self.problem()
        return {p.name: p for p in problem.specs}

    def problem(self) -> FitProblem:
        """The :class:`FitProblem` of this fit, rebuilt once and kept while the model, the
        dataset, the fixed values, the options, the extra noise and the rig-error parameters
        stay the same (building one prepares the model's geometry terms: a report would
        otherwise build it a dozen times)."""
        key = (self.model, id(self.dataset), tuple(sorted(self.fixed.items())),
               tuple(sorted(self.options.items())), self.jitter, tuple(self.alignment), self.stray_light)
        cached = self.__dict__.get("_problem")
        if cached is None or cached[0] != key:
            cached = (key, FitProblem(self.model, self.dataset, self.fixed, self.options, self.jitter,
                                      self.alignment, self.stray_light))
            self.__dict__["_problem"] = cached
        return cached[1]

    def __getstate__(self) -> dict[str, Any]:
        """The result for pickling (to another process), without the cached
        FitProblem of :meth:`problem`: it holds the model's prepared functions, which do
        not pickle, and is rebuilt on demand."""
        state = self.__dict__.copy()
        state.pop("_problem", None)
        return state

    def truth_comparison(self, cause: str | None = None) -> tuple[str, list[str], list[str]] | None:
        """The fit against the emulated sample's truth (:mod:`gonio.fitting.truth`): the
        sample's spec, the table's lines and the BIAS lines; None for data of a real rig."""
        known = known_truth(self.dataset.metadata)
        if known is None or not known[1]:
            return None
        lines, bias = truth_lines(self.parameter_rows(), known[1], self.model, cause)
        return known[0], lines, bias

    def __repr__(self) -> str:
        """One line: model, data, verdict and the best values (``summary()`` has everything)."""
        values = self.best_values()
        shown = ", ".join(f"{name}={_fmt(values[name], 4)}" for name in self.free[:6])
        verdict = self.adequacy.verdict if self.adequacy is not None else "no verdict"
        chain = "least squares" if self.mcmc is None else ("MCMC converged" if self.converged else "MCMC NOT converged")
        return (f"<FitResult {self.model} to {self.dataset.n} {self.dataset.quantity} values: {verdict}, {chain}; "
                f"{shown}{', ...' if len(self.free) > 6 else ''}>")

    def _repr_html_(self) -> str:
        """A notebook's view: the verdict, the parameters with their intervals, the comparison."""
        from html import escape

        from .selection import comparison_html

        rows = []
        for r in self.parameter_rows():
            if r["fixed"]:
                cells = (r["name"], _fmt(r["value"], 6), "fixed", "", r["unit"])
            elif "median" in r:
                digits = max(4, digits_to_resolve(r["median"], (r["p84"] - r["p16"]) / 2))
                cells = (r["name"], _fmt(r["median"], digits), f"-{_fmt(r['median'] - r['p16'], 3)} "
                         f"+{_fmt(r['p84'] - r['median'], 3)}", f"[{_fmt(r['p2_5'], digits)}, "
                         f"{_fmt(r['p97_5'], digits)}]", r["unit"])
            else:
                cells = (r["name"], _fmt(r["value"], digits_to_resolve(r["value"], r["stderr"])),
                         f"+/- {_fmt(r['stderr'], 3)}", "", r["unit"])
            rows.append("<tr>" + "".join(f"<td>{escape(str(c))}</td>" for c in cells) + "</tr>")
        head = "<tr><th>parameter</th><th>value</th><th>1 sigma</th><th>95 %</th><th>unit</th></tr>"
        verdict = escape(self.adequacy.headline()) if self.adequacy is not None else "no verdict"
        comparison = comparison_html(self.comparison) if self.comparison is not None else ""
        return (f"<p><b>{escape(self.model)}</b> fitted to {self.dataset.n} {escape(self.dataset.quantity)} values "
                f"of {escape(self.dataset.label or 'data')}: {verdict}</p><table>{head}{''.join(rows)}</table>"
                + comparison)

    @property
    def converged(self) -> bool | None:
        """Whether the chain converged (None without MCMC)."""
        return None if self.mcmc is None else self.mcmc.converged

    def best_values(self) -> dict[str, float]:
        """Posterior medians when sampled, else the least-squares values (fixed included)."""
        values = dict(self.least_squares.values)
        if self.posterior:
            values.update(self.posterior["median"])
        return values

    def samples(self) -> np.ndarray:
        """Posterior samples (n, len(free)); empty without MCMC."""
        if self.mcmc is None:
            return np.empty((0, len(self.free)))
        return self.mcmc.samples()

    def predict(self, theta_i, phi_i, theta_r, phi_r, values: Mapping[str, float] | None = None) -> np.ndarray:
        """The fitted quantity at arbitrary geometries [deg] (best values by default)."""
        values = dict(self.best_values() if values is None else values)
        model = evaluated_model(self.model, self.dataset)  # through the apertures, as fitted
        return predict_quantity(model, self.dataset.quantity, theta_i, phi_i, theta_r, phi_r, values, self.options,
                                self.dataset.metadata)

    def posterior_predictive(
        self, theta_i, phi_i, theta_r, phi_r, n_draws: int = 200, seed: int = 0, percentiles=(2.5, 16, 50, 84, 97.5)
    ) -> np.ndarray:
        """Percentiles of the model prediction over posterior draws (the model band).

        Returns an array of shape ``(len(percentiles),) + broadcast shape``.  Without a
        chain, the least-squares prediction repeated.
        """
        samples = self.samples()
        if samples.shape[0] == 0:
            one = self.predict(theta_i, phi_i, theta_r, phi_r)
            return np.repeat(one[None], len(percentiles), axis=0)
        rng = np.random.default_rng(seed)
        rows = rng.choice(samples.shape[0], size=min(n_draws, samples.shape[0]), replace=False)
        geometry = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))
        draws = self._predict_draws(samples[rows], [a.reshape(-1) for a in geometry])
        # numpy's nanpercentile sorts column by column; without NaN percentile gives the
        # same numbers in one vectorised sort
        quantiles = np.nanpercentile if np.isnan(draws).any() else np.percentile
        return quantiles(draws, percentiles, axis=0).reshape((len(percentiles),) + geometry[0].shape)

    def _predict_draws(self, draws: np.ndarray, geometry: list[np.ndarray]) -> np.ndarray:
        """The fitted quantity for every row of ``draws`` (free parameters, shape (D, k)) at
        the flat ``geometry`` (four arrays of M angles [deg]): shape (D, M).

        The geometry is frozen once (``Model.at``, through the apertures as fitted) and the
        parameters broadcast as columns, so the draws cost a few model evaluations instead
        of one each; the result equals :meth:`predict` row by row to rounding.
        """
        model = evaluated_model(self.model, self.dataset)
        ti, pi_, tr, pr = geometry
        if any(name in self.free or self.fixed.get(name, 0.0) != 0.0 for name in RIG_ERROR_NAMES):
            return self._predict_rig_draws(model, draws, geometry)
        at_views = model.at(ti, pi_, tr, pr, **self.options)
        at_normal = model.at(ti, pi_, np.zeros_like(tr), pi_, **self.options) \
            if self.dataset.quantity == "normalised_radiance" else None
        # Draws per evaluation: temporaries of (draws x geometries x aperture rays) stay
        # within a few tens of megabytes.
        chunk = max(1, _PREDICTIVE_ELEMENTS // max(ti.size, 1))
        base = dict(self.least_squares.values)
        out = np.empty((draws.shape[0], ti.size))
        for start in range(0, draws.shape[0], chunk):
            block = draws[start:start + chunk]
            values = dict(base, **{name: block[:, [k]] for k, name in enumerate(self.free)})
            params = {name: values[name] for name in model.param_names if name in values}
            brdf = at_views(**params)
            normal = at_normal(**params) if at_normal is not None else None
            scale = np.asarray(values.get("scale", 1.0), float)
            out[start:start + chunk] = combine_prediction(self.dataset.quantity, brdf, normal, np.cos(np.radians(ti)),
                                                          scale)
        return out

    def _predict_rig_draws(self, model, draws: np.ndarray, geometry: list[np.ndarray]) -> np.ndarray:
        """:meth:`_predict_draws` of a fit with rig errors (alignment, stray light): the draws
        as columns of one prediction of that rig per chunk (RigPrediction, as predict_quantity)."""
        rig = RigPrediction(model, self.dataset.quantity, geometry, self.options, self.dataset.metadata, compiled=True)
        # the numpy path holds every value's 49 aperture sub-rays per draw, the compiled loop none
        rays = 1 if rig.compiled else 49
        chunk = max(1, _PREDICTIVE_ELEMENTS // max(geometry[0].size * rays, 1))
        base = dict(self.least_squares.values)
        out = np.empty((draws.shape[0], geometry[0].size))
        for start in range(0, draws.shape[0], chunk):
            block = draws[start:start + chunk]
            out[start:start + chunk] = rig.of_values(dict(base, **{name: block[:, [k]] for k, name in enumerate(self.free)}))
        return out

    def information(self) -> dict[str, float]:
        """AIC, AICc and BIC of the maximum-likelihood fit (:mod:`gonio.fitting.selection`)."""
        return information_criteria(self.least_squares.log_likelihood, len(self.free), self.least_squares.dof + len(self.free))

    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        """JSON form of everything but the chain."""
        problem = self.problem()
        out: dict[str, Any] = {
            "format": "gonio-fit-result",
            "format_version": RESULT_FORMAT_VERSION,
            "gonio_version": self.gonio_version,
            "created": self.created,
            "result_id": self.result_id,
            "comparison": self.comparison,
            "validity": self.validity.to_dict() if self.validity is not None else None,
            "model": self.model,
            "model_reference": problem.model.reference,
            "quantity": self.dataset.quantity,
            "parameters": [
                {
                    "name": p.name,
                    "unit": p.unit,
                    "bounds": list(p.bounds),
                    "description": p.description,
                    "fixed": self.fixed.get(p.name),
                }
                for p in problem.specs
            ],
            "fixed": self.fixed,
            "free": list(self.free),
            "options": self.options,
            "jitter": self.jitter,
            "alignment": list(self.alignment),
            "stray_light": self.stray_light,
            "priors": {name: prior.to_dict() for name, prior in self.priors.items()},
            "least_squares": self.least_squares.to_dict(),
            "information_criteria": self.information(),
            "posterior": self.posterior,
            "flags": self.flags,
            "adequacy": self.adequacy.to_dict() if self.adequacy is not None else None,
            "discrepancy": self.discrepancy,
            "dataset": self._dataset_record(),
        }
        if self.mcmc is not None:
            m = self.mcmc
            out["mcmc"] = {
                "n_walkers": m.n_walkers,
                "n_steps": m.n_steps,
                "burn_in": m.burn_in,
                "thin": m.thin,
                "converged": m.converged,
                "tau": m.tau.tolist(),
                "acceptance_fraction": m.acceptance_fraction.tolist(),
                "tau_multiple": m.tau_multiple,
                "rhat_limit": m.rhat_limit,
                "moves": m.moves,
                "tau_rtol": m.tau_rtol,
                "max_steps": m.max_steps,
                "wall_seconds": m.wall_seconds,
                "model_seconds": m.model_seconds,
                "evaluations": m.evaluations,
                "tau_history": [list(h) for h in m.tau_history],
                "warnings": m.warnings,
                "diagnostics": m.diagnostics,
                "chain_file": CHAIN_FILE,
                "inference_data_file": INFERENCE_DATA_FILE,
            }
        return _clean(out)

    def saved_files(self) -> tuple[str, ...]:
        """Names of the files :meth:`save` writes for this result (chain only with MCMC, the
        comparison's files only after a comparison)."""
        return ((RESULT_FILE, SUMMARY_FILE) + ((CHAIN_FILE, INFERENCE_DATA_FILE) if self.mcmc is not None else ())
                + ((COVARIANCE_FILE,) if self.dataset.covariance is not None else ())
                + ((COMPARISON_FILE, COMPARISON_TEXT) if self.comparison is not None else ()))

    def _dataset_record(self) -> dict[str, Any]:
        """The dataset for result.json: its covariance named by file, not written out."""
        record = self.dataset.to_dict(covariance=False)
        if self.dataset.covariance is not None:
            record["covariance_file"] = COVARIANCE_FILE
        return record

    def save(self, directory: str | Path) -> Path:
        """Write ``chain.npz`` and ``posterior.nc`` (with MCMC), ``covariance.npz`` (data with a
        covariance), ``comparison.json`` and
        ``comparison.txt`` (after a model comparison), ``summary.txt`` and, last,
        ``result.json`` into a folder.

        Each file is written to a temporary file in the same folder and renamed over the
        target (:func:`gonio.files.write_atomic`, with the permissions a normally created
        file gets), so an interrupted or failed write (a full disk) leaves the earlier file,
        never a truncated one, and no temporary file. Every file carries the result's
        ``result_id``, and ``result.json``, which says what the others are, is written last:
        a save interrupted between files leaves files of two saves, which :meth:`load`
        refuses, naming them, instead of reading the mix as one result.

        Parameters
        ----------
        directory : str or Path
            The folder (created if missing).

        Returns
        -------
        pathlib.Path
            The path of ``result.json``.
        """
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        if not self.result_id:
            self.result_id = uuid.uuid4().hex
        if self.mcmc is not None:
            buffer = io.BytesIO()
            # uncompressed: zlib gains ~25 % on a chain's random doubles at ten times the
            # time (2 s for a 256-walker Fig 16 chain)
            np.savez(buffer, chain=self.mcmc.chain, log_prob=self.mcmc.log_prob, result_id=np.array(self.result_id),
                     names=np.array(self.free), burn_in=np.array(self.mcmc.burn_in), thin=np.array(self.mcmc.thin))
            write_atomic(directory / CHAIN_FILE, buffer.getvalue())
            self._write_inference_data(directory / INFERENCE_DATA_FILE)
        if self.dataset.covariance is not None:
            buffer = io.BytesIO()
            np.savez(buffer, **_covariance_arrays(self.dataset.covariance), result_id=np.array(self.result_id))
            write_atomic(directory / COVARIANCE_FILE, buffer.getvalue())
        if self.comparison is not None:
            comparison = {**_clean(self.comparison), "result_id": self.result_id}
            write_atomic(directory / COMPARISON_FILE, json.dumps(comparison, indent=1, allow_nan=False))
            write_atomic(directory / COMPARISON_TEXT, comparison_text(self.comparison) + "\n")
        write_atomic(directory / SUMMARY_FILE, self.summary() + "\n")
        path = directory / RESULT_FILE
        write_atomic(path, json.dumps(self.to_dict(), indent=1, allow_nan=False))
        return path

    def inference_data(self):
        """The posterior as an ArviZ ``InferenceData`` (walkers as chains, after burn-in and
        thinning), with the pointwise log-likelihood for PSIS-LOO and the observed values.

        At most :data:`INFERENCE_DRAWS` draws in all, and at most
        :data:`POINTWISE_ELEMENTS` draws x values in each pointwise group: a large ensemble
        or a large dataset is thinned further (every k-th step, at least one step), so that
        ``posterior.nc`` stays within a few hundred megabytes for any number of values.
        """
        from .diagnostics import inference_data

        return inference_data(**self._inference_arrays())

    def _inference_arrays(self) -> dict[str, Any]:
        """The arguments of :func:`~gonio.fitting.diagnostics.inference_data` for this fit."""
        if self.mcmc is None:
            raise ValueError("no posterior: the fit ran without MCMC")
        m = self.mcmc
        most = min(INFERENCE_DRAWS, POINTWISE_ELEMENTS // max(self.dataset.n, 1))
        thin = max(m.thin, math.ceil((m.n_steps - m.burn_in) / max(1, most // m.n_walkers)))
        chain = m.chain[m.burn_in :: thin]
        problem = self.problem()
        pointwise = problem.pointwise_log_likelihood_batch(chain.reshape(-1, len(self.free))).reshape(
            chain.shape[:2] + (self.dataset.n,))
        # replicated data of the last steps, at most PREDICTIVE_DRAWS in all (arviz.plot_ppc)
        predictive_draws = min(PREDICTIVE_DRAWS, POINTWISE_ELEMENTS // max(self.dataset.n, 1))
        steps = max(1, min(chain.shape[0], predictive_draws // chain.shape[1]))
        recent = chain[-steps:]
        rng = np.random.default_rng(0 if not self.result_id else int(self.result_id[:8], 16))
        predictive = problem.replicated_data(recent.reshape(-1, len(self.free)), rng).reshape(
            recent.shape[:2] + (self.dataset.n,))
        data = self.dataset
        return {"chain": chain, "log_prob": m.log_prob[m.burn_in :: thin], "names": self.free,
                "log_likelihood": pointwise, "observed": data.value, "predictive": predictive,
                "geometry": {"theta_i": data.theta_i, "phi_i": data.phi_i, "theta_r": data.theta_r,
                             "phi_r": data.phi_r, "sigma": data.sigma},
                "attributes": {"model": self.model, "quantity": data.quantity, "gonio_version": self.gonio_version,
                               "result_id": self.result_id}}

    def _write_inference_data(self, path: Path) -> None:
        # written with h5netcdf, read back by arviz.from_netcdf equal to inference_data()
        # (importing ArviZ for the file would cost 1-3 s: gonio.fitting.inference_file)
        from .inference_file import write_inference_data

        write_atomic(path, write_inference_data(**self._inference_arrays()))

    def loo(self):
        """PSIS-LOO of the fit (ArviZ ``loo``): expected log predictive density, its error
        and the Pareto k diagnostics (Vehtari, Gelman & Gabry 2017)."""
        from .diagnostics import arviz

        return arviz().loo(self.inference_data(), pointwise=True)

    @classmethod
    def load(cls, path: str | Path) -> "FitResult":
        """Read a result saved by :meth:`save` (a folder or its ``result.json``).

        Raises
        ------
        FileNotFoundError, ValueError
            Missing file, or a file that is not a gonio fit result (naming the field).
        """
        path = Path(path)
        if path.is_dir():
            path = path / RESULT_FILE
        data = json.loads(path.read_text())
        if data.get("format") != "gonio-fit-result":
            raise ValueError(f"{path}: field 'format' is {data.get('format')!r}, expected 'gonio-fit-result'")
        mcmc = None
        if "mcmc" in data:
            chain_path = path.parent / data["mcmc"]["chain_file"]
            with np.load(chain_path) as arrays:
                chain, log_prob = arrays["chain"], arrays["log_prob"]
                _check_same_save(path, data.get("result_id"), chain_path,
                                 str(arrays["result_id"]) if "result_id" in arrays else None)
            m = data["mcmc"]
            mcmc = McmcResult(
                free=tuple(data["free"]),
                chain=chain,
                log_prob=log_prob,
                tau=np.array([_nan(t) for t in m["tau"]]),
                acceptance_fraction=np.array(m["acceptance_fraction"], float),
                burn_in=int(m["burn_in"]),
                thin=int(m["thin"]),
                converged=bool(m["converged"]),
                tau_multiple=float(m["tau_multiple"]),
                tau_rtol=float(m["tau_rtol"]),
                max_steps=int(m["max_steps"]),
                wall_seconds=float(m["wall_seconds"]),
                model_seconds=float(m["model_seconds"]),
                evaluations=int(m["evaluations"]),
                tau_history=[(int(s), _nan(t)) for s, t in m["tau_history"]],
                warnings=list(m["warnings"]),
                diagnostics={k: {kk: _nan(vv) for kk, vv in v.items()} for k, v in m.get("diagnostics", {}).items()},
                rhat_limit=float(m.get("rhat_limit", RHAT_LIMIT)),
                moves=str(m.get("moves", "stretch")),  # results written before the moves were recorded
            )
        posterior = data["posterior"]
        for key, value in list(posterior.items()):
            if isinstance(value, dict):
                posterior[key] = {k: _nan(v) for k, v in value.items()}
            elif key == "correlation":
                posterior[key] = [[_nan(x) for x in row] for row in value]
        ls = dict(data["least_squares"])
        ls["values"] = {k: _nan(v) for k, v in ls["values"].items()}
        for key in ("chi2", "redchi", "log_likelihood"):
            ls[key] = _nan(ls[key])
        return cls(
            model=data["model"],
            dataset=_load_dataset(path, data),
            fixed={k: float(v) for k, v in data["fixed"].items()},
            free=tuple(data["free"]),
            options=dict(data["options"]),
            least_squares=LeastSquaresResult.from_dict(ls),
            mcmc=mcmc,
            priors={k: prior_from_dict(v) for k, v in data["priors"].items()},
            jitter=jitter_mode(data["jitter"]),
            alignment=tuple(data.get("alignment", ())),
            stray_light=bool(data.get("stray_light", False)),
            posterior=posterior,
            flags=list(data["flags"]),
            created=data.get("created", ""),
            result_id=str(data.get("result_id", "")),
            gonio_version=data.get("gonio_version", ""),
            adequacy=Adequacy.from_dict(data["adequacy"]) if data.get("adequacy") else None,
            comparison=data.get("comparison"),
            validity=ModelValidity.from_dict(data["validity"]) if data.get("validity") else None,
        )

    # ------------------------------------------------------------------ text
    def parameter_rows(self) -> list[dict[str, Any]]:
        """One dict per parameter (fixed included) with every number of the summary."""
        rows = []
        specs = self.specs
        ls = self.least_squares
        post = self.posterior
        for name, spec in specs.items():
            row: dict[str, Any] = {"name": name, "unit": spec.unit, "bounds": spec.bounds, "fixed": name in self.fixed}
            row["value"] = self.fixed.get(name, ls.values.get(name))
            row["stderr"] = ls.stderr.get(name, math.nan)
            if post and name in post["median"]:
                for key in ("median", "p16", "p84", "p2_5", "p97_5", "map", "tau", "ess", "r_hat", "ess_bulk",
                            "ess_tail"):
                    row[key] = post.get(key, {}).get(name, math.nan)
            row["prior"] = str(self.priors[name]) if name in self.priors else ""
            rows.append(row)
        return rows

    def summary(self) -> str:
        """A plain-text fit report in the style of lmfit's ``fit_report``."""
        return _summary_text(self)


# ---------------------------------------------------------------------- computations
def _summarise(
    problem: FitProblem, ls: LeastSquaresResult, mcmc: McmcResult, priors: Mapping[str, Prior]
) -> dict[str, Any]:
    samples = mcmc.samples()
    log_prob = mcmc.sample_log_prob()
    names = problem.free
    q = np.percentile(samples, [2.5, 16, 50, 84, 97.5], axis=0)
    everything = mcmc.chain.reshape(-1, len(names))
    all_log_prob = mcmc.log_prob.reshape(-1)
    best = int(np.argmax(all_log_prob))
    map_vector = everything[best]
    map_log_prob = float(all_log_prob[best])
    # The least-squares optimum is the MAP itself for flat priors: keep whichever is higher.
    ls_vector = np.array([ls.values[n] for n in names])
    ls_log_prob = LogPosterior(problem, priors)(ls_vector) if len(priors) == len(names) else -math.inf
    if ls_log_prob > map_log_prob:
        map_vector, map_log_prob = ls_vector, ls_log_prob
    if samples.shape[0] > 1 and len(names) > 1:
        with np.errstate(invalid="ignore", divide="ignore"):  # a constant column gives NaN
            correlation = np.corrcoef(samples, rowvar=False)
    else:
        correlation = np.ones((len(names), len(names)))
    ess = mcmc.ess
    return {
        "median": dict(zip(names, q[2].tolist())),
        "p16": dict(zip(names, q[1].tolist())),
        "p84": dict(zip(names, q[3].tolist())),
        "p2_5": dict(zip(names, q[0].tolist())),
        "p97_5": dict(zip(names, q[4].tolist())),
        "map": dict(zip(names, map_vector.tolist())),
        "map_log_posterior": map_log_prob,
        "correlation": np.atleast_2d(correlation).tolist(),
        "tau": dict(zip(names, mcmc.tau.tolist())),
        "ess": dict(zip(names, ess.tolist())),
        "r_hat": {n: mcmc.diagnostics.get(n, {}).get("r_hat", math.nan) for n in names},
        "ess_bulk": {n: mcmc.diagnostics.get(n, {}).get("ess_bulk", math.nan) for n in names},
        "ess_tail": {n: mcmc.diagnostics.get(n, {}).get("ess_tail", math.nan) for n in names},
        "acceptance_fraction": float(mcmc.acceptance_fraction.mean()),
        "n_samples": int(samples.shape[0]),
        "median_log_posterior": float(np.median(log_prob)) if log_prob.size else math.nan,
    }


def _limit_text(limit: float, bound: float) -> str:
    """A one-sided limit with digits enough to differ from the bound it lies near
    (``rho > 0.9996``, never ``rho > 1`` for a parameter bounded at 1).

    >>> _limit_text(0.99962, 1.0), _limit_text(12.3456, 0.0)
    ('0.9996', '12.3')
    """
    return format(limit, f".{digits_to_resolve(limit, abs(bound - limit) * 10)}g")


def _posterior_flags(problem: FitProblem, posterior: Mapping[str, Any]) -> list[str]:
    notes = []
    for name in problem.free:
        lo, hi = problem.spec(name).bounds
        low, high = posterior["p2_5"][name], posterior["p97_5"][name]
        width = high - low
        unit = problem.spec(name).unit
        if math.isfinite(lo) and low - lo < _PILE_FRACTION * width:
            notes.append(
                f"{name}: the posterior piles up at the lower bound {_with_unit(f'{lo:g}', unit)}; quote the upper "
                f"limit {name} < {_with_unit(_limit_text(high, lo), unit)} (97.5 %) rather than "
                "median +/- error"
            )
        elif math.isfinite(hi) and hi - high < _PILE_FRACTION * width:
            notes.append(
                f"{name}: the posterior piles up at the upper bound {_with_unit(f'{hi:g}', unit)}; quote the lower "
                f"limit {name} > {_with_unit(_limit_text(low, hi), unit)} (2.5 %) rather than "
                "median +/- error"
            )
    correlation = np.asarray(posterior["correlation"], float)
    names = problem.free
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            r = correlation[i, j]
            if math.isfinite(r) and abs(r) > _STRONG_CORRELATION:
                notes.append(
                    f"{names[i]} and {names[j]} are strongly correlated in the posterior (r = {r:+.3f}): "
                    "the data constrain mainly a combination of them" + _DEGENERACY_ADVICE.get(
                        frozenset((names[i], names[j])), "")
                )
    return notes


# ---------------------------------------------------------------------- summary text
def _covariance_arrays(covariance: Any) -> dict[str, np.ndarray]:
    """What ``covariance.npz`` holds: ``covariance`` (n, n), or for a diagonal plus low rank
    its ``independent`` variances (n,) and shared ``factors`` (n, k), never the n x n matrix."""
    if isinstance(covariance, LowRankCovariance):
        return covariance.arrays()
    return {"covariance": np.asarray(covariance)}


def _load_dataset(path: Path, data: Mapping[str, Any]) -> Dataset:
    """The dataset of a result.json at ``path``, its covariance read from the file it names
    (format 2) or from the record itself (format 1)."""
    record = dict(data["dataset"])
    name = record.pop("covariance_file", None)
    if name is not None:
        covariance_path = path.parent / name
        with np.load(covariance_path) as arrays:
            record["covariance"] = (LowRankCovariance(arrays["independent"], arrays["factors"]) if "factors" in arrays
                                    else arrays["covariance"])
            _check_same_save(path, data.get("result_id"), covariance_path, str(arrays["result_id"]))
    return Dataset.from_dict(record)


def _check_same_save(result_path: Path, result_id: str | None, other: Path, other_id: str | None) -> None:
    """Refuse a file of another save beside ``result.json`` (a save interrupted between files,
    :meth:`FitResult.save`); files written before results carried an id pass."""
    if result_id and other_id and other_id != result_id:
        raise ValueError(f"{other} belongs to another save than {result_path} (result ids {other_id[:12]} and "
                         f"{result_id[:12]}): the folder mixes two fits, probably from a save that was interrupted; "
                         "fit again into this folder (--overwrite) or another")


def _fmt(x: Any, digits: int = 5) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return f"{x:.{digits}g}"


def _adequacy_lines(result: FitResult) -> list[str]:
    """The goodness-of-fit numbers of the summary."""
    a = result.adequacy
    if a is None:
        return []
    lines = [f"    chi-square p-value = {_fmt(a.chi2_p, 3)} (least-squares optimum, fitted noise)",
             f"    post. predictive p = {_fmt(a.ppc_p, 3)}"]
    if math.isfinite(a.extra_noise_ratio):
        lines.append(f"    extra noise / stated uncertainty = {_fmt(a.extra_noise_ratio, 3)}")
    if a.lack_of_fit is not None:
        lof = a.lack_of_fit
        lines.append(f"    lack-of-fit p      = {_fmt(lof.p, 3)} (F = {_fmt(lof.statistic, 3)} on {lof.dof[0]}, "
                     f"{lof.dof[1]} dof against a series of order {lof.order}; scatter / stated = "
                     f"{_fmt(lof.noise_factor, 3)})")
    lines.append(f"    verdict            = {a.verdict.upper() if a.verdict != 'adequate' else a.verdict} (limit p >= "
                 f"{a.alpha:g}, extra noise <= stated)")
    return lines


def _data_notes(metadata: Mapping[str, Any]) -> list[str]:
    """Summary lines on what the reduction left out or could not measure."""
    lines = []
    excluded = metadata.get("excluded") or {}
    if isinstance(excluded, Mapping):
        lines += [f"    excluded           = {count} {reason} point(s) excluded (not fitted)"
                  for reason, count in excluded.items() if count]
    warnings = metadata.get("reduction_warnings") or []
    if isinstance(warnings, (list, tuple)):
        lines += [f"    reduction warning  = {text}" for text in warnings]
    return lines


def _summary_text(result: FitResult) -> str:
    ls = result.least_squares
    data = result.dataset
    model = models.get(result.model)
    info = result.information()
    lines = []
    if result.adequacy is not None:
        lines += [result.adequacy.headline(), ""]
    lines += ["[[Model]]", f"    {result.model}: {model.description}", f"    reference: {model.reference}"]
    if result.comparison is not None:
        lines += [f"    chosen among {len(result.comparison['rows'])} candidates (table: [[Model choice]], "
                  f"{COMPARISON_TEXT})"]
    lines += textwrap.wrap(f"discrepancy: {result.discrepancy}", width=100, initial_indent="    ",
                           subsequent_indent="      ")
    if result.options:
        lines.append("    options: " + ", ".join(f"{k}={v}" for k, v in result.options.items()))
    lines += [
        "[[Data]]",
        f"    label              = {data.label or '(none)'}",
        f"    quantity           = {data.quantity} [{data.unit}]",
        f"    incidences         = {len(data.incidences()[0])}",
        *_data_notes(data.metadata),
        "[[Fit Statistics]]",
        "    # fitting method   = least_squares (trf, bounded"
        + (f"; posterior mode with the Gaussian priors on {', '.join(ls.gaussian_priors)}" if ls.gaussian_priors else "")
        + ")" + (" + emcee" if result.mcmc else ""),
        f"    # function evals   = {ls.nfev}",
        f"    # data points      = {data.n}",
        f"    result id          = {result.result_id or '(none)'} (every file of this fit carries it)",
        f"    # variables        = {len(result.free)}",
        f"    chi-square         = {_fmt(ls.chi2)}",
        f"    reduced chi-square = {_fmt(ls.redchi)}",
        f"    Akaike info crit   = {_fmt(info['aic'])}",
        f"    Bayesian info crit = {_fmt(info['bic'])}",
        *_adequacy_lines(result),
        "[[Variables]]",
    ]
    rows = result.parameter_rows()
    width = max(len(r["name"]) for r in rows) + 1
    for r in rows:
        label = f"    {r['name'] + ':':<{width}}"
        if r["fixed"]:
            lines.append(f"{label} {_fmt(r['value'], 6):>11} (fixed) [{r['unit']}]")
            continue
        error = r["stderr"]
        relative = f" ({100 * abs(error / r['value']):.2f}%)" if math.isfinite(error) and r["value"] else ""
        error_text = f"+/- {_fmt(error, 4)}" if math.isfinite(error) else "+/- (undetermined)"
        lo, hi = r["bounds"]
        lines.append(f"{label} {_fmt(r['value'], 6):>11} {error_text}{relative} [{r['unit']}] range [{lo:g}, {hi:g}]")
    if result.posterior and result.mcmc is not None:
        m = result.mcmc
        status = (
            f"converged: length >= {m.tau_multiple:g} tau and R-hat < {m.rhat_limit:g}"
            if m.converged
            else "!!! NOT CONVERGED: step limit reached, numbers unreliable !!!"
        )
        lines += [
            f"[[Posterior]] (emcee, {m.moves} move: {m.n_walkers} walkers x {m.n_steps} steps, burn-in {m.burn_in}, thin {m.thin}; {status})",
            f"    mean acceptance fraction = {result.posterior['acceptance_fraction']:.3f}; "
            f"samples kept = {result.posterior['n_samples']}",
            f"    {'name':<{width}} {'median':>10} {'-1sig':>9} {'+1sig':>9} {'2.5%':>10} {'97.5%':>10} {'MAP':>10} "
            f"{'tau':>7} {'R-hat':>7} {'ESS bulk':>9} {'ESS tail':>9}  prior",
        ]
        for r in rows:
            if r["fixed"] or "median" not in r:
                continue
            digits = max(5, digits_to_resolve(r["median"], (r["p84"] - r["p16"]) / 2))
            lines.append(
                f"    {r['name']:<{width}} {_fmt(r['median'], digits):>10} {_fmt(r['median'] - r['p16'], 3):>9} "
                f"{_fmt(r['p84'] - r['median'], 3):>9} {_fmt(r['p2_5'], digits):>10} {_fmt(r['p97_5'], digits):>10} "
                f"{_fmt(r['map'], digits):>10} {_fmt(r['tau'], 3):>7} {_fmt(r['r_hat'], 4):>7} {_fmt(r['ess_bulk'], 4):>9} "
                f"{_fmt(r['ess_tail'], 4):>9}  {r['prior']}"
            )
    correlations = []
    matrix = np.asarray(result.posterior["correlation"], float) if result.posterior else ls.correlation
    for i in range(len(result.free)):
        for j in range(i + 1, len(result.free)):
            r = matrix[i, j]
            if math.isfinite(r) and abs(r) > _REPORTED_CORRELATION:
                correlations.append((abs(r), f"    C({result.free[i]}, {result.free[j]}) = {r:+.4f}"))
    source = "posterior" if result.posterior else "least squares"
    lines.append(f"[[Correlations]] ({source}; unreported correlations are < {_REPORTED_CORRELATION:.3f})")
    lines += [text for _, text in sorted(correlations, reverse=True)] or ["    (none)"]
    truth = result.truth_comparison()
    if truth is not None:
        lines.append(f"[[Truth]] (the emulated sample {truth[0]})")
        lines += ["    " + line for line in truth[1] + truth[2]]
    if result.comparison is not None:
        lines.append("[[Model choice]] (least squares of every candidate, same likelihood)")
        lines += ["    " + line for line in comparison_text(result.comparison).splitlines()]
    lines.append("[[Warnings]]")
    lines += [f"    ! {flag}" for flag in result.flags] or ["    (none)"]
    return "\n".join(lines)
