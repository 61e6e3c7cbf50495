"""Can the model explain the data? Goodness-of-fit tests and the verdict every fit reports.

Three numbers, all under the fit's own likelihood (the stated uncertainties and their
covariance, plus the fitted extra noise when there is one):

- the **chi-square p-value** of the least-squares optimum: ``P(chi2_dof >= chi2)`` with
  ``dof`` = informative measurements minus free parameters;
- the **posterior predictive p-value** of the chi-square discrepancy (Gelman, Meng & Stern
  1996): ``P(T(y_rep, theta) >= T(y, theta) | y)``. For Gaussian replicates
  ``T(y_rep, theta)`` is chi-square with n degrees of freedom whatever theta, so the
  p-value is the posterior mean of ``P(chi2_n >= T(y, theta))``, computed exactly on the
  posterior samples (no simulation noise);
- the **extra noise relative to the stated uncertainties**: the fitted ``jitter`` over the
  median stated uncertainty, or ``rel_jitter`` over the median relative one.

The model is **inadequate** when either p-value is below :data:`ALPHA` or when the extra
noise exceeds the stated uncertainties (ratio > 1: the model needs more noise than was
measured to explain the data). ``ALPHA = 1e-3`` flags a fit of an adequate model by chance
about once in five hundred (two tests); the customary 0.05 would flag one adequate fit in
ten, while model errors large enough to matter drive p far below 1e-3. The verdict opens
the summary, the report and the JSON, and sets the exit status of ``gonio fit``.

References
----------
A. Gelman, X.-L. Meng, H. Stern, "Posterior predictive assessment of model fitness via
realized discrepancies", Statistica Sinica 6, 733 (1996), section 2.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping

import numpy as np

__all__ = ["ALPHA", "Adequacy", "assess", "chi2_pvalue", "posterior_predictive_pvalue", "extra_noise_ratio"]

#: p-value below which a fit's model is called inadequate.
ALPHA = 1e-3


def chi2_pvalue(chi2: float, dof: int) -> float:
    """``P(chi2_dof >= chi2)`` (NaN without degrees of freedom).

    Examples
    --------
    >>> round(chi2_pvalue(10.0, 10), 3)
    0.44

    Notes
    -----
    ``scipy.special.chdtrc``, the function ``scipy.stats.chi2.sf`` evaluates (equal to it,
    tests/fitting/test_adequacy.py), without importing scipy.stats (0.4 s of CPU here), which a
    least-squares-only fit needs for nothing else.
    """
    from scipy.special import chdtrc

    if dof <= 0 or not math.isfinite(chi2):
        return math.nan
    return float(chdtrc(dof, chi2))


def posterior_predictive_pvalue(problem, samples: np.ndarray, max_draws: int = 1000) -> float:
    """Posterior predictive p-value of the chi-square discrepancy (module docstring).

    Parameters
    ----------
    problem : FitProblem
    samples : numpy.ndarray, shape (draws, free parameters)
        Posterior samples; at most ``max_draws`` evenly spaced ones are used.
    """
    from scipy.special import chdtrc  # chi2.sf, see chi2_pvalue

    if len(samples) == 0:
        return math.nan
    pick = np.linspace(0, len(samples) - 1, min(max_draws, len(samples))).astype(int)
    n = problem.n_informative
    discrepancies = problem.chi_square_batch(samples[pick])
    return float(np.mean(chdtrc(n, discrepancies)))


def extra_noise_ratio(problem, values: Mapping[str, float]) -> float:
    """Fitted extra noise over the typical stated uncertainty (NaN without an extra-noise term)."""
    data = problem.dataset
    if problem.jitter == "absolute":
        return float(values["jitter"] / np.median(data.sigma))
    if problem.jitter == "relative":
        relative = data.sigma / np.maximum(np.abs(data.value), 1e-300)
        return float(values["rel_jitter"] / np.median(relative))
    return math.nan


@dataclass(frozen=True)
class Adequacy:
    """The goodness-of-fit verdict of a fit (module docstring)."""

    chi2_p: float
    ppc_p: float
    extra_noise_ratio: float
    alpha: float = ALPHA
    reasons: tuple[str, ...] = field(default_factory=tuple)

    @property
    def adequate(self) -> bool:
        """True unless a test failed."""
        return not self.reasons

    def headline(self) -> str:
        """One line: ``MODEL INADEQUATE: ...`` or ``model adequate: ...``."""
        numbers = f"chi-square p = {_p(self.chi2_p)}, posterior predictive p = {_p(self.ppc_p)}"
        if math.isfinite(self.extra_noise_ratio):
            numbers += f", extra noise = {self.extra_noise_ratio:.3g} x the stated uncertainties"
        if self.adequate:
            return f"model adequate ({numbers})"
        return "MODEL INADEQUATE: " + "; ".join(self.reasons) + f" ({numbers})"

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["reasons"] = list(self.reasons)
        out["adequate"] = self.adequate
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Adequacy":
        nan = lambda v: math.nan if v is None else float(v)  # noqa: E731
        return cls(nan(data["chi2_p"]), nan(data["ppc_p"]), nan(data["extra_noise_ratio"]),
                   float(data.get("alpha", ALPHA)), tuple(data.get("reasons", ())))


def _p(value: float) -> str:
    return "n/a" if not math.isfinite(value) else (f"{value:.2g}" if value >= 1e-4 else f"{value:.1e}")


def assess(problem, least_squares, samples: np.ndarray | None = None, alpha: float = ALPHA) -> Adequacy:
    """The verdict of a fit: both p-values and the extra-noise ratio against their limits."""
    vector = np.array([least_squares.values[n] for n in problem.free])
    chi2_p = chi2_pvalue(float(problem.chi_square_batch(vector)[0]), least_squares.dof)
    ppc_p = posterior_predictive_pvalue(problem, samples) if samples is not None else math.nan
    values = samples_median(problem, samples) if samples is not None else least_squares.values
    ratio = extra_noise_ratio(problem, values)
    reasons = []
    if math.isfinite(chi2_p) and chi2_p < alpha:
        reasons.append(f"the least-squares chi-square has p = {_p(chi2_p)} < {alpha:g}: the model does not explain "
                       "the data within their uncertainties")
    if math.isfinite(ppc_p) and ppc_p < alpha:
        reasons.append(f"posterior predictive p = {_p(ppc_p)} < {alpha:g}")
    if math.isfinite(ratio) and ratio > 1.0:
        reasons.append(f"the fitted extra noise is {ratio:.3g} times the stated uncertainties: the misfit is "
                       "larger than the measurement noise")
    return Adequacy(chi2_p, ppc_p, ratio, alpha, tuple(reasons))


def samples_median(problem, samples: np.ndarray) -> dict[str, float]:
    """Median of each free parameter over the samples, with the fixed values."""
    out = dict(problem.fixed)
    out.update(zip(problem.free, np.median(samples, axis=0)))
    return out
