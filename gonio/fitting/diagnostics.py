"""Convergence diagnostics of today's standard, computed by ArviZ.

The rank-normalised split R-hat and the bulk and tail effective sample sizes of Vehtari
et al. (2021) are computed by ArviZ from the chain after burn-in, each emcee walker taken
as one chain (the usual reading of an ensemble: every walker samples the posterior after
burn-in; a stuck walker makes R-hat large). They complement emcee's integrated
autocorrelation time: a fit has converged when the chain is 50 autocorrelation times long
*and* every R-hat is below :data:`RHAT_LIMIT`.

The numbers come from ``arviz_stats.base.array_stats``, ArviZ's computational core on
numpy arrays (the package ``arviz`` 0.x re-exports the same functions as ``arviz.rhat``
and ``arviz.ess``; tests/fitting/test_diagnostics.py checks that they agree to the last
bit). It is imported without xarray (:func:`array_stats`): ``import arviz`` takes 1 to
3 s (it loads xarray, pandas, matplotlib.pyplot and compiles a numba function of its ECDF
code every time), which is most of what a ``gonio fit`` of a small recording would
otherwise cost; ``arviz_stats.base`` needs numpy and scipy only. ``arviz`` itself is
imported only for the in-memory ``InferenceData`` and PSIS-LOO (:func:`arviz`), never at
``import gonio``.

References
----------
A. Vehtari, A. Gelman, D. Simpson, B. Carpenter, P.-C. Buerkner, "Rank-normalization,
folding, and localization: an improved R-hat for assessing convergence of MCMC",
Bayesian Analysis 16(2), 667 (2021). R. Kumar, C. Carroll, A. Hartikainen, O. Martin,
"ArviZ a unified library for exploratory analysis of Bayesian models in Python", JOSS 4,
1143 (2019).
"""
from __future__ import annotations

import functools
import math
import sys
import warnings
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["RHAT_LIMIT", "TAIL_PROBABILITIES", "arviz", "array_stats", "convergence_diagnostics", "inference_data"]

#: Largest R-hat accepted for convergence (Vehtari et al. 2021, section 4.2).
RHAT_LIMIT = 1.01
#: Quantiles whose effective sample size is the tail ESS (ArviZ's default, Vehtari et al. 2021).
TAIL_PROBABILITIES = (0.05, 0.95)


def arviz():
    """The ``arviz`` module, imported quietly on first use."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # the package announces its refactor on import
        import arviz as az
    return az


@functools.cache
def array_stats():
    """ArviZ's diagnostics on numpy arrays (``arviz_stats.base.array_stats``), imported
    without xarray and without leaving a trace in ``sys.modules``.

    ``import arviz_stats`` loads its xarray interface whenever xarray is importable
    (arviz-stats 0.8: about 1 s for xarray and pandas) even where that interface cannot
    work (without arviz-base); its numpy core needs neither. So xarray is made
    unimportable for the duration of the import (``sys.modules["xarray"] = None``, which
    makes ``import xarray`` raise ``ModuleNotFoundError``, the case arviz-stats handles by
    skipping that interface), then ``sys.modules`` gets back its ``xarray`` entry, or
    none, as it was, and the arviz-stats modules this import added are taken out again
    (the returned object keeps what it needs), so that a later ``import arviz_stats``
    anywhere in the process gets the whole package. Where arviz-stats was imported before,
    its own ``array_stats`` is returned untouched.
    """
    if "arviz_stats" in sys.modules:
        from arviz_stats.base import array_stats as stats

        return stats
    before = set(sys.modules)
    xarray = sys.modules.get("xarray", _ABSENT)
    sys.modules["xarray"] = None  # type: ignore[assignment]
    try:
        from arviz_stats.base import array_stats as stats
    finally:
        if xarray is _ABSENT:
            del sys.modules["xarray"]
        else:
            sys.modules["xarray"] = xarray
        for name in set(sys.modules) - before:
            if name == "arviz_stats" or name.startswith("arviz_stats."):
                del sys.modules[name]
    return stats


_ABSENT = object()


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
    stats = array_stats()
    by_parameter = np.transpose(chain, (2, 1, 0))  # (parameter, chain = walker, draw = step)
    nan = np.full(len(names), math.nan)
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)  # a constant parameter gives NaN
        r_hat = stats.rhat(by_parameter, method="rank")
        bulk = stats.ess(by_parameter, method="bulk") if ess else nan
        tail = stats.ess(by_parameter, method="tail", prob=TAIL_PROBABILITIES) if ess else nan
    return {n: {"r_hat": float(r_hat[k]), "ess_bulk": float(bulk[k]), "ess_tail": float(tail[k])}
            for k, n in enumerate(names)}


def inference_data(chain: np.ndarray, log_prob: np.ndarray, names: Sequence[str],
                   log_likelihood: np.ndarray | None = None, observed: np.ndarray | None = None,
                   attributes: Mapping[str, Any] | None = None, predictive: np.ndarray | None = None,
                   geometry: Mapping[str, np.ndarray] | None = None):
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
    predictive : numpy.ndarray, shape (steps', walkers, n), optional
        Replicated data (the ``posterior_predictive`` group).
    geometry : mapping of str to numpy.ndarray, optional
        The measurement geometry [deg] (the ``constant_data`` group).
    """
    from .inference_file import DATA_DIMENSION, inference_groups

    az = arviz()
    groups = {group: {name: values for name, (_, values) in variables.items()}
              for group, variables in inference_groups(chain, log_prob, names, log_likelihood, observed, predictive,
                                                       geometry).items()}
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
        data = az.from_dict(**groups, dims={name: [DATA_DIMENSION] for name in (geometry or {})})
    for key, value in dict(attributes or {}).items():
        data.posterior.attrs[key] = value
    return data
