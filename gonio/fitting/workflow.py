"""One call from data to a complete fit result: :func:`fit`."""
from __future__ import annotations

from typing import Any, Callable, Mapping, Sequence

from gonio.models import Model

from .dataset import Dataset
from .least_squares import fit_least_squares
from .mcmc import resolve_priors, sample_posterior
from .priors import Prior
from .problem import FitProblem
from .results import FitResult

__all__ = ["fit"]


def fit(
    dataset: Dataset,
    model: str | Model,
    fixed: Mapping[str, float] | None = None,
    priors: Mapping[str, Prior] | None = None,
    mcmc: bool = True,
    jitter: bool | str = False,
    options: Mapping[str, Any] | None = None,
    start: Mapping[str, float] | None = None,
    n_walkers: int | None = None,
    max_steps: int = 20000,
    tau_multiple: float = 50.0,
    rhat_limit: float = 1.01,
    seed: int | None = 0,
    progress: Callable[[int, int, float], None] | None = None,
    alignment: str | Sequence[str] | None = None,
    stray_light: bool = False,
) -> FitResult:
    """Fit a registered model to a dataset: least squares, then (optionally) MCMC.

    Parameters
    ----------
    dataset : Dataset
        The measurements (:class:`gonio.fitting.Dataset`).
    model : str or Model
        Registered model name (``gonio.models.available()``).
    fixed : mapping, optional
        Parameters held fixed, by name (model parameters, ``scale``, ``jitter``).
    priors : mapping of Prior, optional
        Overrides of the default priors (uniform over the physical bounds).
    mcmc : bool
        Sample the posterior with emcee after the least-squares fit.
    jitter : bool or {"absolute", "relative"}
        Fit an extra noise term added in quadrature to the uncertainties: ``jitter`` (True
        or "absolute") or ``rel_jitter`` ("relative", proportional to the prediction).
    options : mapping, optional
        Discrete model options.
    start : mapping, optional
        Least-squares starting values.
    n_walkers, max_steps, tau_multiple, rhat_limit, seed, progress
        Passed to :func:`gonio.fitting.mcmc.sample_posterior`.
    alignment : str or sequence of str, optional
        Alignment nuisance parameters to fit (``"all"`` or names such as
        ``"view_offset"``, ``"tilt_y"``; :mod:`gonio.fitting.rig_errors`), with their
        default normal priors unless ``priors`` overrides them.
    stray_light : bool
        Fit the rig's stray light (``stray_light``, :mod:`gonio.fitting.rig_errors`).

    Returns
    -------
    FitResult

    Examples
    --------
    >>> import numpy as np, gonio
    >>> tr = np.arange(0.0, 80.0, 10.0)
    >>> data = Dataset(45, 0, tr, 0, gonio.brdf("lambert", 45, 0, tr, 0, rho=0.5), 0.005)
    >>> result = fit(data, "lambert", mcmc=False)
    >>> round(result.best_values()["rho"], 3)
    0.5
    """
    problem = FitProblem(model, dataset, fixed, options, jitter, alignment, stray_light)
    priors = problem.priors_with_defaults(priors)
    least_squares = fit_least_squares(problem, start=start, seed=seed, priors=priors)
    if not mcmc:
        return FitResult.build(problem, least_squares, None, resolve_priors(problem, least_squares.values, priors))
    chain, used_priors = sample_posterior(
        problem,
        least_squares,
        priors=priors,
        n_walkers=n_walkers,
        max_steps=max_steps,
        tau_multiple=tau_multiple,
        rhat_limit=rhat_limit,
        seed=seed,
        progress=progress,
    )
    return FitResult.build(problem, least_squares, chain, used_priors)
