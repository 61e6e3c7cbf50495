"""Fitting reflectance models to measurements: least squares, MCMC, model selection.

>>> import numpy as np, gonio
>>> from gonio.fitting import Dataset, fit
>>> tr = np.arange(0.0, 80.0, 10.0)
>>> data = Dataset(30, 0, tr, 0, gonio.brdf("minnaert", 30, 0, tr, 0, rho=0.6, k=0.7), 0.002)
>>> result = fit(data, "minnaert", mcmc=False)
>>> print(result.summary())          # doctest: +SKIP

Modules: :mod:`~gonio.fitting.dataset` (the data interface), :mod:`~gonio.fitting.problem`
(prediction and likelihood), :mod:`~gonio.fitting.priors`,
:mod:`~gonio.fitting.least_squares`, :mod:`~gonio.fitting.mcmc`,
:mod:`~gonio.fitting.results`, :mod:`~gonio.fitting.selection`.  See docs/fitting.md.
"""
from __future__ import annotations

from .covariance import LowRankCovariance
from .dataset import CSV_COLUMNS, QUANTITIES, Dataset
from .least_squares import LeastSquaresResult, fit_least_squares
from .least_squares_batch import ManyLeastSquaresResult, least_squares_many
from .mcmc import ConvergenceWarning, McmcResult, sample_posterior
from .priors import LogUniform, Normal, Prior, Uniform, parse_prior
from .problem import FitProblem, predict_quantity
from .results import FitResult
from .selection import ModelComparison, compare_loo, compare_models, information_criteria
from .workflow import fit

__all__ = [
    "CSV_COLUMNS",
    "QUANTITIES",
    "Dataset",
    "LowRankCovariance",
    "FitProblem",
    "predict_quantity",
    "Prior",
    "Uniform",
    "LogUniform",
    "Normal",
    "parse_prior",
    "LeastSquaresResult",
    "fit_least_squares",
    "ManyLeastSquaresResult",
    "least_squares_many",
    "McmcResult",
    "ConvergenceWarning",
    "sample_posterior",
    "FitResult",
    "ModelComparison",
    "compare_loo",
    "compare_models",
    "information_criteria",
    "fit",
]
