"""Model comparison: use no more model than the data need.

Two families of criteria, both computed from the weighted least-squares optimum:

* information criteria from the maximum log-likelihood ln L, with k free parameters and n
  measurements: AIC = -2 ln L + 2k (Akaike 1974), AICc = AIC + 2k(k+1)/(n-k-1) (small-sample
  correction), BIC = -2 ln L + k ln n (Schwarz 1978);
* the Bayesian evidence Z = integral of likelihood x prior, in the Laplace approximation
  around the optimum: ln Z ~ ln L + ln prior(theta*) + (k/2) ln(2 pi) + (1/2) ln det C,
  with C the least-squares covariance.  Unlike the information criteria it charges each
  parameter for the prior range it could have taken (Occam factor).  It is NaN when a
  parameter is undetermined (degenerate), and overestimates Z by up to a factor 2 per
  parameter sitting on a bound of a uniform prior (half the Gaussian falls outside).

:func:`compare_models` fits each candidate and picks the simplest model whose evidence is
within ``threshold`` (natural-log units; default 1, "not worth more than a bare mention" on
the scale of Kass & Raftery 1995, 2 ln B < 2) of the best; where an evidence is undefined it
uses Delta BIC / 2, which approximates -Delta ln Z for large n.

References
----------
R. E. Kass, A. E. Raftery, "Bayes factors", J. Am. Stat. Assoc. 90, 773 (1995), section 3
(interpretation scale) and 4.1.1 (Laplace's method).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from .dataset import Dataset

__all__ = ["information_criteria", "laplace_log_evidence", "ModelComparison", "compare_models", "candidate_label"]


def information_criteria(log_likelihood: float, k: int, n: int) -> dict[str, float]:
    """AIC, AICc and BIC from the maximum log-likelihood.

    Examples
    --------
    >>> information_criteria(-10.0, 2, 20)["bic"] == 20.0 + 2 * math.log(20)
    True
    """
    aic = -2.0 * log_likelihood + 2.0 * k
    aicc = aic + 2.0 * k * (k + 1) / (n - k - 1) if n - k - 1 > 0 else math.inf
    bic = -2.0 * log_likelihood + k * math.log(n)
    return {"aic": aic, "aicc": aicc, "bic": bic}


def laplace_log_evidence(problem, least_squares, priors) -> float:
    """Laplace approximation of ln Z (module docstring); NaN if the covariance is undetermined.

    Parameters
    ----------
    problem : FitProblem
    least_squares : LeastSquaresResult
    priors : mapping of Prior
        Prior of every free parameter.
    """
    names = list(problem.free)
    if "jitter" in names:
        return math.nan  # the least-squares covariance does not cover the jitter
    covariance = np.asarray(least_squares.covariance, float)
    if not np.all(np.isfinite(covariance)):
        return math.nan
    sign, log_det = np.linalg.slogdet(covariance)
    if sign <= 0:
        return math.nan
    log_prior = sum(priors[n].logpdf(least_squares.values[n]) for n in names)
    if not math.isfinite(log_prior):
        return math.nan
    k = len(names)
    return least_squares.log_likelihood + log_prior + 0.5 * k * math.log(2.0 * math.pi) + 0.5 * log_det


@dataclass
class ModelComparison:
    """Result of :func:`compare_models`.

    Attributes
    ----------
    rows : list of dict
        Per candidate: ``model``, ``fixed``, ``k``, ``chi2``, ``redchi``, ``aic``, ``aicc``,
        ``bic``, ``delta_bic``, ``log_evidence``, ``delta_log_evidence``, ``values``,
        ``warnings``.
    chosen : str
        The selected model.
    reason : str
        Why.
    """

    rows: list[dict[str, Any]]
    chosen: str
    reason: str
    threshold: float = 1.0
    fits: dict[str, Any] = field(default_factory=dict, repr=False)

    def summary(self) -> str:
        """A plain-text table, best first."""
        header = f"{'model':<28} {'k':>2} {'chi2':>10} {'redchi':>8} {'AIC':>10} {'BIC':>10} {'dBIC':>8} {'lnZ':>10} {'dlnZ':>7}"
        lines = [header, "-" * len(header)]
        for row in self.rows:
            mark = " <- chosen" if row["label"] == self.chosen else ""
            lines.append(
                f"{row['label']:<28} {row['k']:>2} {row['chi2']:>10.4g} {row['redchi']:>8.3g} {row['aic']:>10.4g} "
                f"{row['bic']:>10.4g} {row['delta_bic']:>8.3g} {row['log_evidence']:>10.4g} "
                f"{row['delta_log_evidence']:>7.3g}{mark}"
            )
        lines.append(f"chosen: {self.chosen} ({self.reason})")
        return "\n".join(lines)


def candidate_label(name: str, fixed: Mapping[str, float]) -> str:
    """The label of a candidate model in a comparison: ``name`` or ``name (k=v, ...)``.

    Examples
    --------
    >>> candidate_label("oren-nayar", {"ir_weight": 1.0})
    'oren-nayar (ir_weight=1)'
    """
    return name + ("" if not fixed else " (" + ", ".join(f"{k}={v:g}" for k, v in fixed.items()) + ")")


def compare_models(
    dataset: Dataset,
    candidates: Sequence[str | tuple[str, Mapping[str, float]]],
    threshold: float = 1.0,
    n_starts: int = 6,
    priors: Mapping[str, Any] | None = None,
) -> ModelComparison:
    """Fit several models by least squares and choose the simplest adequate one.

    Parameters
    ----------
    dataset : Dataset
    candidates : sequence
        Model names, or ``(name, fixed)`` pairs.
    threshold : float
        Evidence margin [natural log units] within which the model with fewer free
        parameters is preferred.
    n_starts : int
        Starting points per least-squares fit.
    priors : mapping of Prior, optional
        Priors overriding the defaults, by parameter name (e.g. the calibration's prior on
        ``scale`` from :meth:`gonio.reduction.Reduced.fit_inputs`); each applies to the
        candidates that have that free parameter. They enter the least-squares fits (a
        Gaussian prior makes them posterior modes) and the Laplace evidence, as in
        :func:`gonio.fitting.fit`.

    Returns
    -------
    ModelComparison

    Examples
    --------
    >>> import numpy as np, gonio
    >>> tr = np.arange(0.0, 80.0, 5.0)
    >>> values = gonio.brdf("lambert", 30, 0, tr, 0, rho=0.5) * (1 + 0.01 * np.sin(tr))
    >>> comparison = compare_models(Dataset(30, 0, tr, 0, values, 0.003), ["lambert", "minnaert"])
    >>> comparison.chosen
    'lambert'
    """
    from .least_squares import fit_least_squares
    from .mcmc import resolve_priors
    from .problem import FitProblem

    if not candidates:
        raise ValueError("compare_models needs at least one candidate model")
    rows = []
    fits = {}
    for candidate in candidates:
        name, fixed = (candidate, {}) if isinstance(candidate, str) else (candidate[0], dict(candidate[1]))
        problem = FitProblem(name, dataset, fixed)
        given = {k: v for k, v in (priors or {}).items() if k in problem.free}
        ls = fit_least_squares(problem, n_starts=n_starts, priors=given)
        candidate_priors = resolve_priors(problem, ls.values, given)
        label = candidate_label(name, fixed)
        info = information_criteria(ls.log_likelihood, len(problem.free), problem.n_informative)
        rows.append(
            {
                "label": label,
                "model": name,
                "fixed": fixed,
                "k": len(problem.free),
                "chi2": ls.chi2,
                "redchi": ls.redchi,
                **info,
                "log_evidence": laplace_log_evidence(problem, ls, candidate_priors),
                "values": ls.values,
                "warnings": ls.warnings,
            }
        )
        fits[label] = ls
    best_bic = min(r["bic"] for r in rows)
    evidences = [r["log_evidence"] for r in rows]
    use_evidence = all(math.isfinite(z) for z in evidences)
    best_z = max(evidences) if use_evidence else math.nan
    for row in rows:
        row["delta_bic"] = row["bic"] - best_bic
        row["delta_log_evidence"] = row["log_evidence"] - best_z if use_evidence else math.nan
    # Support of each model relative to the best, in ln units (>= 0, 0 for the best).
    deficit = [(-r["delta_log_evidence"] if use_evidence else 0.5 * r["delta_bic"]) for r in rows]
    adequate = [r for r, d in zip(rows, deficit) if d <= threshold]
    chosen = min(adequate, key=lambda r: (r["k"], -r["log_evidence"] if use_evidence else r["bic"]))
    criterion = "Laplace evidence" if use_evidence else "BIC (an evidence was undefined)"
    reason = (
        f"fewest free parameters among the models within {threshold:g} ln-units of the best by {criterion}"
    )
    rows.sort(key=lambda r: -r["log_evidence"] if use_evidence else r["bic"])
    return ModelComparison(rows=rows, chosen=chosen["label"], reason=reason, threshold=threshold, fits=fits)
