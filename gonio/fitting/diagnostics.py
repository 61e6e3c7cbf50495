"""Convergence diagnostics of today's standard, computed by ArviZ.

The rank-normalised split R-hat and the bulk and tail effective sample sizes of Vehtari
et al. (2021) are computed with ArviZ (``arviz.rhat``, ``arviz.ess``) from the chain after
burn-in, each emcee walker taken as one chain (the usual reading of an ensemble: every
walker samples the posterior after burn-in; a stuck walker makes R-hat large). They
complement emcee's integrated autocorrelation time: a fit has converged when the chain is
50 autocorrelation times long *and* every R-hat is below :data:`RHAT_LIMIT`.

ArviZ is imported on first use (it takes about two seconds), never at ``import gonio``.

References
----------
A. Vehtari, A. Gelman, D. Simpson, B. Carpenter, P.-C. Buerkner, "Rank-normalization,
folding, and localization: an improved R-hat for assessing convergence of MCMC",
Bayesian Analysis 16(2), 667 (2021). R. Kumar, C. Carroll, A. Hartikainen, O. Martin,
"ArviZ a unified library for exploratory analysis of Bayesian models in Python", JOSS 4,
1143 (2019).
"""
from __future__ import annotations

import math
import warnings
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["RHAT_LIMIT", "arviz", "convergence_diagnostics", "inference_data"]

#: Largest R-hat accepted for convergence (Vehtari et al. 2021, section 4.2).
RHAT_LIMIT = 1.01


def arviz():
    """The ``arviz`` module, imported quietly on first use."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # the package announces its refactor on import
        import arviz as az
    return az


def convergence_diagnostics(chain: np.ndarray, names: Sequence[str], ess: bool = True) -> dict[str, dict[str, float]]:
    """R-hat, bulk and tail ESS of each parameter of an emcee chain after burn-in.

    Parameters
    ----------
    chain : numpy.ndarray, shape (steps, walkers, parameters)
        Positions after burn-in (thinned or not: the ESS counts the steps given).
    names : sequence of str
        Parameter names, in the chain's last-axis order.
    ess : bool
        Also compute the effective sample sizes (else only R-hat).

    Returns
    -------
    dict
        ``{name: {"r_hat", "ess_bulk", "ess_tail"}}``; NaN where the chain is too short
        (fewer than 4 steps) or constant.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> d = convergence_diagnostics(rng.normal(size=(400, 16, 1)), ["x"])
    >>> d["x"]["r_hat"] < 1.01, d["x"]["ess_bulk"] > 3000
    (True, True)
    """
    chain = np.asarray(chain, float)
    if chain.shape[0] < 4:
        return {n: {"r_hat": math.nan, "ess_bulk": math.nan, "ess_tail": math.nan} for n in names}
    az = arviz()
    with warnings.catch_warnings():
        # an ensemble has more walkers (chains) than thinned draws; ArviZ suspects a transpose
        warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
        data = az.convert_to_dataset({n: chain[:, :, k].T for k, n in enumerate(names)})
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)  # a constant parameter gives NaN
        r_hat = az.rhat(data, method="rank")
        bulk = az.ess(data, method="bulk") if ess else None
        tail = az.ess(data, method="tail") if ess else None
    return {n: {"r_hat": float(r_hat[n]),
                "ess_bulk": float(bulk[n]) if ess else math.nan,
                "ess_tail": float(tail[n]) if ess else math.nan} for n in names}


def inference_data(chain: np.ndarray, log_prob: np.ndarray, names: Sequence[str],
                   log_likelihood: np.ndarray | None = None, observed: np.ndarray | None = None,
                   attributes: Mapping[str, Any] | None = None):
    """An ArviZ ``InferenceData`` of a chain after burn-in (walkers as chains).

    Parameters
    ----------
    chain : numpy.ndarray, shape (steps, walkers, parameters)
    log_prob : numpy.ndarray, shape (steps, walkers)
        Log posterior.
    names : sequence of str
    log_likelihood : numpy.ndarray, shape (steps, walkers, n), optional
        Pointwise log-likelihood (for PSIS-LOO).
    observed : numpy.ndarray, optional
        The measured values.
    attributes : mapping, optional
        Stored as attributes of the posterior group.
    """
    az = arviz()
    posterior = {n: chain[:, :, k].T for k, n in enumerate(names)}
    groups: dict[str, Any] = {"posterior": posterior, "sample_stats": {"lp": np.asarray(log_prob).T}}
    if log_likelihood is not None:
        groups["log_likelihood"] = {"y": np.transpose(log_likelihood, (1, 0, 2))}
    if observed is not None:
        groups["observed_data"] = {"y": np.asarray(observed, float)}
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
        data = az.from_dict(**groups)
    for key, value in dict(attributes or {}).items():
        data.posterior.attrs[key] = value
    return data
