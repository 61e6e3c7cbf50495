"""One call from data to a complete fit result: :func:`fit`."""
from __future__ import annotations

import contextlib
import importlib
from typing import Any, Callable, Mapping, Sequence

from gonio.models import Model

from .csv_table import ASSUMED_SIGMA, data_notes
from .dataset import Dataset
from .adequacy import assess
from .least_squares import LeastSquaresResult, fit_least_squares
from .mcmc import resolve_priors, sample_posterior
from .polish import polish, shifted_chain
from .priors import Prior
from .problem import FitProblem
from .results import FitResult
from .validity import check as check_validity
from .validity import regime_flags

__all__ = ["fit", "AUTO", "BLAS_THREADS"]

#: ``jitter`` value that adds an extra-noise term only where the verdict asks for it.
AUTO = "auto"
#: BLAS threads during a fit (:func:`fit`'s ``blas_threads``).
BLAS_THREADS = 1


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
    polish_table: bool = True,
    blas_threads: int | None = BLAS_THREADS,
    least_squares: LeastSquaresResult | None = None,
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
    jitter : bool or {"absolute", "relative", "auto"}
        Fit an extra noise term added in quadrature to the uncertainties: ``jitter`` (True
        or "absolute") or ``rel_jitter`` ("relative", proportional to the prediction).
        ``"auto"``: none, unless the least-squares verdict is "noise understated"
        (:mod:`gonio.fitting.adequacy`: the model follows the data, which scatter more than
        stated); then the fit is redone with ``rel_jitter`` before the MCMC, and a flag
        says so.
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

    polish_table : bool
        Polish a tabulated model's fit with its exact model where the table's error at the
        data's geometries exceeds a tenth of their uncertainties (:mod:`gonio.fitting.polish`:
        the optimum and the posterior move to the exact model's, and a flag says by how
        much). False keeps the table's fit: the same widths, a slightly different optimum,
        in a fraction of the time (the exact model at grazing geometries takes a minute or
        more); an adaptive run's decisions use it (:mod:`gonio.adaptive`).
    blas_threads : int or None
        Threads the BLAS library (OpenBLAS, MKL) may use during the fit
        (:func:`threadpoolctl.threadpool_limits`; default 1, None: as the process has it).
        A fit's matrix products (the whitening of correlated data, a few hundred to a few
        thousand values) gain nothing from threads, a threaded BLAS spins between calls
        and takes the cores other work needs, and a product's rounding, so the chain,
        depends on the thread count; with one thread the same seed and data give the same
        chain on any machine (docs/fitting.md, "Performance").
    least_squares : LeastSquaresResult, optional
        This fit's least squares, already made on the same dataset with the same priors
        (a comparison's, :attr:`gonio.fitting.ModelComparison.fits`): used as it is
        instead of fitting again, with its measured table error (:mod:`gonio.fitting.polish`).
        Its free parameters must be the fit's (with ``jitter="auto"``, those of the fit
        without or with ``rel_jitter``).

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
    from threadpoolctl import threadpool_limits

    importlib.import_module("scipy.linalg")  # loads scipy's own BLAS now, so that the limit reaches it too

    with threadpool_limits(limits=blas_threads, user_api="blas") if blas_threads else contextlib.nullcontext():
        return _fit(dataset, model, fixed=fixed, priors=priors, mcmc=mcmc, jitter=jitter, options=options, start=start,
                    n_walkers=n_walkers, max_steps=max_steps, tau_multiple=tau_multiple, rhat_limit=rhat_limit,
                    seed=seed, progress=progress, alignment=alignment, stray_light=stray_light,
                    polish_table=polish_table, given=least_squares)


def _fit(dataset, model, *, fixed, priors, mcmc, jitter, options, start, n_walkers, max_steps, tau_multiple,
         rhat_limit, seed, progress, alignment, stray_light, polish_table, given) -> FitResult:
    """:func:`fit`'s work, with its BLAS threads set."""
    def problem_of(name: str | Model, noise: str | None) -> FitProblem:
        return FitProblem(name, dataset, fixed, options, noise, alignment, stray_light)

    problem, least_squares, all_priors, flags = _least_squares(problem_of, model, jitter, priors, start, seed, given)
    validity = check_validity(problem, least_squares, _other_problem(problem, fixed, alignment, stray_light))
    flags += regime_flags(problem, all_priors)
    polished = polish(problem, least_squares, all_priors, lambda name: problem_of(name, problem.jitter)) \
        if polish_table else None
    judge = None
    if polished is not None:
        flags.append(polished.flag())
        judge = polished.problem
    if not mcmc:
        result = FitResult.build(problem, polished.least_squares if polished else least_squares, None,
                                 resolve_priors(problem, least_squares.values, all_priors), judge=judge)
    else:
        chain, used_priors = sample_posterior(problem, least_squares, priors=all_priors, n_walkers=n_walkers,
                                              max_steps=max_steps, tau_multiple=tau_multiple, rhat_limit=rhat_limit,
                                              seed=seed, progress=progress)
        if polished is not None:
            chain, least_squares = shifted_chain(chain, problem, polished.shift), polished.least_squares
        result = FitResult.build(problem, least_squares, chain, used_priors, judge=judge)
    result.flags[:0] = data_notes(dataset.metadata) + flags
    result.validity = validity
    if validity is not None and validity.exceeded:
        result.flags.append(validity.flag(dataset.geometry))
    return result


def _other_problem(problem: FitProblem, fixed, alignment, stray_light) -> Callable[..., FitProblem]:
    """``build(model_name, options, dataset)``: ``problem``'s fit with another model or dataset,
    the fixed values kept where that model has the parameter (:mod:`gonio.fitting.validity`)."""
    def build(name: str, options: Mapping[str, Any], dataset: Dataset) -> FitProblem:
        base = FitProblem(name, dataset, None, options, problem.jitter, alignment, stray_light)
        known = {spec.name for spec in base.specs}
        return FitProblem(name, dataset, {k: v for k, v in (fixed or {}).items() if k in known}, options,
                          problem.jitter, alignment, stray_light)
    return build


def _least_squares(problem_of, model, jitter, priors, start, seed, given=None):
    """The least-squares fit, redone with ``rel_jitter`` when ``jitter="auto"`` and the verdict
    is "noise understated": (problem, least squares, priors, flags). ``given`` (:func:`fit`'s
    ``least_squares``) stands in for the fit of the problem whose free parameters it has."""
    built: dict[str | None, FitProblem] = {}

    def problem_with(name, noise: str | None) -> FitProblem:  # each noise's problem built once
        if noise not in built:
            built[noise] = problem_of(name, noise)
        return built[noise]

    if given is not None:
        noises = (None, "relative") if jitter == AUTO else (jitter,)
        expected = [list(problem_with(model, noise).free) for noise in noises]
        if list(given.free) not in expected:
            raise ValueError(f"least_squares: its free parameters {list(given.free)} are not those of this fit "
                             f"({' or '.join(map(str, expected))}); pass the least squares of the same model, fixed "
                             "parameters, rig errors and noise term")

    def solve(problem: FitProblem, all_priors) -> LeastSquaresResult:
        if given is not None and tuple(given.free) == tuple(problem.free):
            return given
        return fit_least_squares(problem, start=start, seed=seed, priors=all_priors)

    return _noise_and_fit(problem_with, model, jitter, priors, solve)


def _noise_and_fit(problem_of, model, jitter, priors, solve):
    """:func:`_least_squares` with ``solve(problem, priors)`` making each least-squares fit."""
    if jitter == AUTO and problem_of(model, None).dataset.metadata.get(ASSUMED_SIGMA):  # nothing stated to judge
        problem = problem_of(model, "relative")
        all_priors = problem.priors_with_defaults(priors)
        return problem, solve(problem, all_priors), all_priors, []
    problem = problem_of(model, None if jitter == AUTO else jitter)
    all_priors = problem.priors_with_defaults(priors)
    least_squares = solve(problem, all_priors)
    if jitter != AUTO:
        return problem, least_squares, all_priors, []
    verdict = assess(problem, least_squares)
    if verdict.verdict != "noise understated":
        return problem, least_squares, all_priors, []
    flag = (f"noise understated: the data scatter {verdict.noise_factor:.3g} times the stated uncertainties about a "
            "model that follows them, so the fit adds a relative extra-noise term (rel_jitter); its intervals are "
            "those of the data's real scatter")
    problem = problem_of(model, "relative")
    all_priors = problem.priors_with_defaults(priors)
    return problem, solve(problem, all_priors), all_priors, [flag]
