"""Can the model explain the data? Goodness-of-fit tests and the verdict every fit reports.

Three numbers test the fit against its own likelihood (the stated uncertainties and their
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

They fail both when the model is wrong and when the noise budget misses a source (a real
sample's texture), so a fourth test decides between the two without using the size of the
stated noise: the **lack-of-fit F test** against a flexible description of the same data
(:mod:`gonio.fitting.lack_of_fit`). The verdict has three answers (:data:`VERDICTS`):

``"adequate"``
    every test passes: p-values at least :data:`ALPHA`, extra noise at most the stated;
``"noise understated"``
    the model explains the data (no lack of fit) but the scatter exceeds the stated
    uncertainties, by the factor the test measures: the fit must carry an extra-noise
    term (``gonio fit`` adds a relative one, ``jitter="auto"``) and its intervals are
    those of the data's real scatter;
``"inadequate"``
    the residuals hold structure the model cannot follow (lack-of-fit p below
    :data:`ALPHA`), or the budget's tests fail where the dataset is too small for a
    lack-of-fit test (the two causes cannot be told apart; the headline says so).

``ALPHA = 1e-3`` flags a fit of an adequate model by chance about once in five hundred
(two tests); the customary 0.05 would flag one adequate fit in ten, while model errors
large enough to matter drive p far below 1e-3. The verdict opens the summary, the report
and the JSON, and sets the exit status of ``gonio fit`` (0, 5 noise understated, 4
inadequate).

References
----------
A. Gelman, X.-L. Meng, H. Stern, "Posterior predictive assessment of model fitness via
realized discrepancies", Statistica Sinica 6, 733 (1996), section 2.
N. R. Draper, H. Smith, "Applied Regression Analysis", 3rd ed., Wiley 1998, section 2.1
(lack of fit against pure error).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping

import numpy as np

from .csv_table import ASSUMED_SIGMA
from .lack_of_fit import LackOfFit, lack_of_fit

__all__ = ["ALPHA", "VERDICTS", "Adequacy", "assess", "chi2_pvalue", "posterior_predictive_pvalue",
           "extra_noise_ratio"]

#: p-value below which a test fails.
ALPHA = 1e-3
#: The three answers of a verdict (module docstring).
VERDICTS = ("adequate", "noise understated", "inadequate")


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
    """The goodness-of-fit verdict of a fit (module docstring).

    Attributes
    ----------
    chi2_p, ppc_p : float
        The chi-square and posterior predictive p-values (NaN when not computed).
    extra_noise_ratio : float
        The fitted extra noise over the stated uncertainties (NaN without the term).
    alpha : float
        The p-value limit.
    reasons : tuple of str
        The budget's tests that failed, in words.
    lack_of_fit : LackOfFit or None
        The budget-independent test (None where the dataset is too small for it).
    """

    chi2_p: float
    ppc_p: float
    extra_noise_ratio: float
    alpha: float = ALPHA
    reasons: tuple[str, ...] = field(default_factory=tuple)
    lack_of_fit: LackOfFit | None = None

    @property
    def verdict(self) -> str:
        """One of :data:`VERDICTS`."""
        if self.lack_of_fit is not None and self.lack_of_fit.p < self.alpha:
            return "inadequate"
        if not self.reasons:
            return "adequate"
        return "inadequate" if self.lack_of_fit is None else "noise understated"

    @property
    def adequate(self) -> bool:
        """True when every test passed."""
        return self.verdict == "adequate"

    @property
    def noise_factor(self) -> float:
        """The data's scatter over the stated uncertainties, from the lack-of-fit split (NaN without it)."""
        return self.lack_of_fit.noise_factor if self.lack_of_fit is not None else math.nan

    def headline(self) -> str:
        """One line: ``MODEL INADEQUATE: ...``, ``NOISE UNDERSTATED: ...`` or ``model adequate (...)``."""
        numbers = f"chi-square p = {_p(self.chi2_p)}, posterior predictive p = {_p(self.ppc_p)}"
        if math.isfinite(self.extra_noise_ratio):
            numbers += f", extra noise = {self.extra_noise_ratio:.3g} x the stated uncertainties"
        lof = self.lack_of_fit
        if lof is not None:
            numbers += f", lack of fit p = {_p(lof.p)} (series order {lof.order})"
        verdict = self.verdict
        if verdict == "adequate":
            return f"model adequate ({numbers})"
        if verdict == "noise understated":
            return (f"NOISE UNDERSTATED: the model follows the data (no lack of fit) but they scatter "
                    f"{lof.noise_factor:.3g} times the stated uncertainties; " + "; ".join(self.reasons)
                    + f" ({numbers})")
        if lof is not None and lof.p < self.alpha:
            reasons = [f"the residuals hold structure the model cannot follow (lack-of-fit p = {_p(lof.p)} < "
                       f"{self.alpha:g} against a flexible description of order {lof.order})", *self.reasons]
        else:
            reasons = [*self.reasons, "too few values for a lack-of-fit test, so a wrong model cannot be told from "
                       "an understated noise"]
        return "MODEL INADEQUATE: " + "; ".join(reasons) + f" ({numbers})"

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["reasons"] = list(self.reasons)
        out["adequate"] = self.adequate
        out["verdict"] = self.verdict
        out["lack_of_fit"] = self.lack_of_fit.to_dict() if self.lack_of_fit is not None else None
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Adequacy":
        nan = lambda v: math.nan if v is None else float(v)  # noqa: E731
        lof = LackOfFit.from_dict(data["lack_of_fit"]) if data.get("lack_of_fit") else None
        return cls(nan(data["chi2_p"]), nan(data["ppc_p"]), nan(data["extra_noise_ratio"]),
                   float(data.get("alpha", ALPHA)), tuple(data.get("reasons", ())), lof)


def _p(value: float) -> str:
    return "n/a" if not math.isfinite(value) else (f"{value:.2g}" if value >= 1e-4 else f"{value:.1e}")


def assess(problem, least_squares, samples: np.ndarray | None = None, alpha: float = ALPHA,
           max_draws: int = 1000) -> Adequacy:
    """The verdict of a fit: both p-values and the extra-noise ratio against their limits, and
    the lack-of-fit test that tells a wrong model from an understated noise. ``max_draws``
    posterior samples enter the posterior predictive p-value (fewer for a slow model)."""
    vector = np.array([least_squares.values[n] for n in problem.free])
    chi2_p = chi2_pvalue(float(problem.chi_square_batch(vector)[0]), least_squares.dof)
    ppc_p = posterior_predictive_pvalue(problem, samples, max_draws) if samples is not None else math.nan
    values = samples_median(problem, samples) if samples is not None else least_squares.values
    ratio = extra_noise_ratio(problem, values)
    reasons = []
    if math.isfinite(chi2_p) and chi2_p < alpha:
        reasons.append(f"the least-squares chi-square has p = {_p(chi2_p)} < {alpha:g}: the residuals exceed "
                       "the uncertainties")
    if math.isfinite(ppc_p) and ppc_p < alpha:
        reasons.append(f"posterior predictive p = {_p(ppc_p)} < {alpha:g}")
    if math.isfinite(ratio) and ratio > 1.0 and not problem.dataset.metadata.get(ASSUMED_SIGMA):  # else none stated
        reasons.append(f"the fitted extra noise is {ratio:.3g} times the stated uncertainties")
    return Adequacy(chi2_p, ppc_p, ratio, alpha, tuple(reasons), lack_of_fit(problem, vector))


def samples_median(problem, samples: np.ndarray) -> dict[str, float]:
    """Median of each free parameter over the samples, with the fixed values."""
    out = dict(problem.fixed)
    out.update(zip(problem.free, np.median(samples, axis=0)))
    return out
