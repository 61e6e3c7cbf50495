"""gonio's Laplace evidence of model comparison against nested sampling and quadrature.

:func:`gonio.fitting.evidence.laplace_evidence` approximates the Bayesian evidence
Z = integral of likelihood x prior by a Gaussian around the posterior mode (Laplace's
formula) and corrects it for the supports' truncation of that Gaussian and for a profile
that is not Gaussian near a bound. This benchmark measures how far the raw formula and the
corrected evidence are from independent estimates, on synthetic data
(``gonio.fitting.Dataset``, seeded Gaussian noise of the stated relative sigma) chosen to
cover the regimes a fit meets:

* well-determined, Gaussian-like posteriors far from the bounds (``gaussian-*``);
* posteriors piled against a physical bound (``bound-*``): the unconstrained optimum
  exactly on one bound, one standard error beyond it, on two bounds at once, and the
  Oren-Nayar roughness fitted to Lambertian data, on and just off sigma = 0, where the
  BRDF is stationary in sigma;
* skewed or poorly determined posteriors (``skewed-*``, ``weak-*``);
* relative radiance with a free ``scale`` and a Gaussian calibration prior on it, as a
  calibrated recording gives (``calibrated-radiance``, the case ``gonio demo`` fits).

For every case the same ``FitProblem`` likelihood and the same priors
(``gonio.fitting.mcmc.resolve_priors``) are integrated three ways:

1. **Laplace**, as ``compare_models`` computes it: the raw formula
   (``laplace_log_evidence(..., corrected=False)``, :attr:`LaplaceEvidence.raw`) and the
   corrected evidence (``corrected=True``, the ``log_evidence`` of a comparison row), with
   the two correction terms, the least-squares fits the profile correction made, and wall
   times; as a cross-check of the truncation term, the script's own truncation-only
   estimate, raw + ln(mass of the least-squares Gaussian inside the priors' support)
   (:func:`gaussian_mass_inside`);
2. **nested sampling** with dynesty (Speagle 2020), from a prior transform that maps the
   unit cube onto exactly those priors (uniform, log-uniform, truncated normal), run to
   ``dlogz = 0.05``, with its own error estimate; ``NESTED_REPEATS`` independent runs
   per case, averaged, their scatter recorded as a check on the stated error;
3. **grid quadrature** (trapezoid rule over the region where the nested samples put the
   posterior: log posterior within ``GRID_NATS`` of its maximum), a reference far more
   precise than the sampler for these one- to three-parameter problems; the change from
   a grid with 2/3 the points per axis is recorded as its error.

Also recorded per case: the posterior's mean, standard deviation and skewness from the
nested samples, and wall times. For two pairs of candidate models (``lambert`` against
``oren-nayar`` on slightly rough data, sigma = 5 deg) the difference of log evidences,
and the model ``compare_models``' rule would choose from it, is computed each way (raw
and corrected Laplace, nested, grid), and ``compare_models`` itself is run on the pair. A
survey of ``SURVEY_SEEDS`` noise draws of Lambertian data fitted with ``oren-nayar``
compares raw and corrected Laplace with a grid only (no sampler), as does a survey of the
same data fitted with ``lambert`` and a free relative extra-noise term (``jitter``), which
the data do not need; each kind of prior transform is checked against the prior's own
density before the runs.

Writes docs/benchmarks/evidence.json and docs/benchmarks/evidence.png.
Needs the optional dependency dynesty (``pip install gonio[nested]``).
Run: ``python benchmarks/bench_evidence.py`` (about six minutes on two cores).
"""
from __future__ import annotations

import math
import sys
import time
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats
from scipy.special import logsumexp, ndtr

import gonio
from gonio.fitting import (
    Dataset,
    FitProblem,
    LogUniform,
    Normal,
    Prior,
    Uniform,
    compare_models,
    fit_least_squares,
)
import gonio.fitting.evidence as evidence_module
import gonio.fitting.least_squares as least_squares_module
from gonio.fitting.evidence import laplace_evidence
from gonio.fitting.mcmc import resolve_priors
from gonio.fitting.problem import predict_quantity
from gonio.geometry import in_plane_angles

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, machine, write_json

COMMAND = "python benchmarks/bench_evidence.py"
#: Live points of each nested-sampling run.
NLIVE = 500
#: dynesty's stopping criterion: estimated evidence left in the live points [ln units].
DLOGZ = 0.05
#: dynesty's sampling method: slice sampling along random directions, which copes with the
#: thin correlated ridge of rho x scale better than rejection sampling from ellipsoids.
SAMPLE = "rslice"
#: Independent nested runs per case (seeds 0, 1, ...).
NESTED_REPEATS = 2
#: The quadrature covers the samples whose log posterior is within this of the maximum.
GRID_NATS = 30.0
#: A support limit inside the region within this of the best log posterior is followed by
#: the grid's edge (see :func:`grid_frame`).
CUT_NATS = 12.0
#: Grid points per axis for 1, 2 and 3 free parameters (the coarse check uses 2/3 of them).
GRID_POINTS = {1: 4001, 2: 241, 3: 45}
#: Seeds of the survey of oren-nayar on Lambertian data (Laplace against a grid only).
SURVEY_SEEDS = range(100, 120)
#: The survey's grid: points per axis, and the largest sigma [deg] it covers.
SURVEY_GRID_POINTS = 121
SURVEY_SIGMA_MAX = 5.0
#: The extra-noise survey's grid: the largest rel_jitter it covers, and the coarse check's points per axis.
JITTER_MAX = 0.03
JITTER_COARSE_POINTS = 81
#: compare_models' threshold [ln units].
THRESHOLD = 1.0

VIEWS_20 = np.linspace(-76.0, 76.0, 20)  # every 8 deg
VIEWS_FIG16 = np.arange(-80.0, 81.0, 5.0)  # every 5 deg, as Oren & Nayar Fig 16
FOUR_VIEWS = np.array([-60.0, -20.0, 20.0, 60.0])
ROUGH_PLASTER = {"rho": 0.9, "sigma": 30.0, "ir_weight": 1.0}


@dataclass
class Case:
    """One evidence integral: a model, its data, its fixed parameters and prior overrides."""

    key: str
    regime: str
    title: str
    model: str
    dataset: Dataset
    truth: dict[str, float]
    fixed: dict[str, float] = field(default_factory=dict)
    priors: dict[str, Prior] = field(default_factory=dict)
    data: str = ""
    #: For data built on a bound: standard errors by which the unconstrained optimum lies beyond it.
    beyond: float = 0.0

    def problem(self) -> FitProblem:
        """The fit problem every estimate integrates."""
        return FitProblem(self.model, self.dataset, self.fixed)


# ---------------------------------------------------------------------------- data
def in_plane(incidences: Sequence[float], views: np.ndarray) -> tuple[np.ndarray, ...]:
    """(theta_i, phi_i, theta_r, phi_r) [deg] of every signed in-plane view at every incidence."""
    theta_i = np.repeat(np.asarray(incidences, float), views.size)
    return in_plane_angles(theta_i, np.tile(views, len(incidences)))


def synthetic(model: str, truth: Mapping[str, float], quantity: str, geometry: tuple[np.ndarray, ...],
              noise: float, seed: int, label: str) -> Dataset:
    """Model values with Gaussian noise of relative sigma ``noise`` [-] (seeded).

    Parameters
    ----------
    model : str
        Model generating the data.
    truth : mapping
        Its parameters (and ``scale`` for relative radiance).
    quantity : str
        Dataset quantity.
    geometry : tuple of ndarray
        (theta_i, phi_i, theta_r, phi_r) [deg].
    noise : float
        One-sigma noise as a fraction of each value [-].
    seed : int
        Seed of the numpy Generator.
    label : str
        Dataset label.
    """
    exact = predict_quantity(model, quantity, *geometry, truth)
    sigma = noise * np.abs(exact)
    rng = np.random.default_rng(seed)
    return Dataset(*geometry, exact + sigma * rng.standard_normal(exact.shape), sigma, quantity=quantity, label=label)


def _jacobian_at(model: str, truth: Mapping[str, float], quantity: str, geometry: tuple[np.ndarray, ...],
                 free: Sequence[str]) -> np.ndarray:
    """d(prediction)/d(parameter) at ``truth`` by one-sided differences into the range."""
    base = predict_quantity(model, quantity, *geometry, truth)
    columns = []
    for name in free:
        step = 1e-6 if truth[name] < 0.5 else -1e-6  # the parameters used here live in [0, 1]
        shifted = predict_quantity(model, quantity, *geometry, {**truth, name: truth[name] + step})
        columns.append((shifted - base) / step)
    return np.column_stack(columns)


def on_bound(model: str, truth: Mapping[str, float], quantity: str, geometry: tuple[np.ndarray, ...],
             noise: float, seed: int, label: str, beyond: float = 0.0) -> Dataset:
    """Like :func:`synthetic`, with the noise component along the model's gradient removed.

    The seeded Gaussian noise is projected (in whitened units) onto the complement of the
    Jacobian's columns, so that, to first order, the unconstrained least-squares optimum is
    ``truth`` itself; with ``truth`` on a bound this is the configuration in which the
    Laplace Gaussian puts exactly half its mass (per parameter) outside the prior.  With
    ``beyond`` > 0 the data are then moved along the gradient so that the unconstrained
    optimum lies ``beyond`` standard errors outside the bound (the parameters here have
    their bound at 1): the constrained optimum stays on the bound, now with a slope.
    """
    exact = predict_quantity(model, quantity, *geometry, truth)
    sigma = noise * np.abs(exact)
    free = [n for n in truth if n != "ir_weight"]
    jacobian = _jacobian_at(model, truth, quantity, geometry, free) / sigma[:, None]
    eps = np.random.default_rng(seed).standard_normal(exact.shape)
    eps -= jacobian @ np.linalg.lstsq(jacobian, eps, rcond=None)[0]
    if beyond:
        stderr = np.sqrt(np.diag(np.linalg.inv(jacobian.T @ jacobian)))
        eps += jacobian @ (beyond * stderr)
    return Dataset(*geometry, exact + sigma * eps, sigma, quantity=quantity, label=label)


MATTE = ("lambert rho = 0.5 fitted with oren-nayar (ir_weight = 1): sigma's posterior piles at 0, where the BRDF "
         "is stationary in sigma; BRDF, theta_i = 30/45/60 deg, in-plane views every 5 deg, 1 % noise")


def matte(seed: int) -> Dataset:
    """Lambertian (rho = 0.5) BRDF data on the Fig 16 geometries, 1 % noise: :data:`MATTE`."""
    return synthetic("lambert", {"rho": 0.5}, "brdf", in_plane([30.0, 45.0, 60.0], VIEWS_FIG16), 0.01, seed, "matte")


def cases() -> list[Case]:
    """The benchmark's cases, one per regime of posterior shape."""
    twenty = in_plane([30.0], VIEWS_20)
    fig16 = in_plane([30.0, 45.0, 60.0], VIEWS_FIG16)
    three_by_twenty = in_plane([30.0, 45.0, 60.0], VIEWS_20)
    lambert = {"rho": 0.5}
    calibration = 0.02  # relative one-sigma uncertainty of the reference-standard scale
    true_scale = 100.0
    prior_mean = true_scale * (1.0 + calibration * np.random.default_rng(8).standard_normal())
    out = [
        Case("gaussian-lambert", "gaussian", "lambert, 20 views, 1 %", "lambert",
             synthetic("lambert", lambert, "brdf", twenty, 0.01, 1, "lambert"), lambert,
             data="lambert rho = 0.5, BRDF, theta_i = 30 deg, 20 in-plane views -76..76 deg, 1 % noise, seed 1"),
        Case("gaussian-oren-nayar", "gaussian", "oren-nayar, 99 views, 0.5 %", "oren-nayar",
             synthetic("oren-nayar", ROUGH_PLASTER, "brdf", fig16, 0.005, 2, "plaster"),
             ROUGH_PLASTER, fixed={"ir_weight": 1.0},
             data="oren-nayar rho = 0.9, sigma = 30 deg, ir_weight = 1 (fixed), BRDF, theta_i = 30/45/60 deg, "
                  "in-plane views every 5 deg, 0.5 % noise, seed 2"),
        Case("bound-lambert-rho", "bound", "lambert, rho on 1", "lambert",
             on_bound("lambert", {"rho": 1.0}, "brdf", twenty, 0.01, 3, "white"), {"rho": 1.0},
             data="lambert rho = 1, BRDF, theta_i = 30 deg, 20 views, 1 % noise projected so the unconstrained "
                  "optimum is rho = 1, seed 3"),
        Case("bound-lambert-rho-beyond", "bound", "lambert, rho on 1, data beyond", "lambert",
             on_bound("lambert", {"rho": 1.0}, "brdf", twenty, 0.01, 3, "white", beyond=1.0), {"rho": 1.0},
             beyond=1.0,
             data="as bound-lambert-rho, with the data moved so that the unconstrained optimum is one standard "
                  "error above rho = 1"),
        Case("bound-minnaert-rho-k", "bound", "minnaert, rho and k on 1", "minnaert",
             on_bound("minnaert", {"rho": 1.0, "k": 1.0}, "brdf", three_by_twenty, 0.01, 4, "white"),
             {"rho": 1.0, "k": 1.0},
             data="Lambertian white (minnaert rho = 1, k = 1), BRDF, theta_i = 30/45/60 deg x 20 views, 1 % noise "
                  "projected so the unconstrained optimum is (1, 1), seed 4"),
        Case("bound-oren-nayar-sigma-0", "bound", "oren-nayar on Lambertian data, sigma on 0", "oren-nayar",
             matte(SURVEY_SEEDS.start), {"rho": 0.5, "sigma": 0.0}, fixed={"ir_weight": 1.0},
             data=f"{MATTE}, seed {SURVEY_SEEDS.start} (the first survey seed: optimum on sigma = 0)"),
        Case("bound-oren-nayar-sigma-small", "bound", "oren-nayar on Lambertian data, sigma near 0", "oren-nayar",
             matte(SURVEY_SEEDS.start + 3), {"rho": 0.5, "sigma": 0.0}, fixed={"ir_weight": 1.0},
             data=f"{MATTE}, seed {SURVEY_SEEDS.start + 3} (the first survey seed with the optimum off sigma = 0)"),
        Case("skewed-minnaert", "skewed", "minnaert, 4 views, 15 %", "minnaert",
             synthetic("minnaert", {"rho": 0.6, "k": 0.7}, "brdf", in_plane([30.0], FOUR_VIEWS), 0.15, 3, "dark"),
             {"rho": 0.6, "k": 0.7},
             data="minnaert rho = 0.6, k = 0.7, BRDF, theta_i = 30 deg, views -60/-20/20/60 deg, 15 % noise, seed 3"),
        Case("weak-oren-nayar-normalised", "skewed", "oren-nayar, normalised radiance", "oren-nayar",
             synthetic("oren-nayar", ROUGH_PLASTER, "normalised_radiance", fig16, 0.005, 2, "plaster"),
             ROUGH_PLASTER, fixed={"ir_weight": 1.0},
             data="as gaussian-oren-nayar but normalised radiance: rho enters only through the interreflection "
                  "term, so it is poorly determined"),
        Case("calibrated-radiance", "calibrated", "oren-nayar, radiance, scale prior", "oren-nayar",
             synthetic("oren-nayar", {**ROUGH_PLASTER, "scale": true_scale}, "radiance", fig16, 0.005, 6, "plaster"),
             {**ROUGH_PLASTER, "scale": true_scale}, fixed={"ir_weight": 1.0},
             priors={"scale": Normal(prior_mean, calibration * true_scale, 0.0, math.inf)},
             data=f"oren-nayar (rho = 0.9, sigma = 30 deg, ir_weight = 1 fixed), relative radiance with scale = 100, "
                  f"theta_i = 30/45/60 deg, views every 5 deg, 0.5 % noise, seed 6; calibration prior on scale "
                  f"normal({prior_mean:.3f}, 2) on (0, inf), its mean drawn with 2 % error (seed 8)"),
    ]
    return out


def comparison_pairs() -> list[tuple[str, str, list[Case]]]:
    """(key, description, [lambert case, oren-nayar case]) on slightly rough data."""
    rough = {"rho": 0.5, "sigma": 5.0, "ir_weight": 1.0}
    pairs = []
    for key, incidences, views, noise in (("marginal", [30.0], VIEWS_20, 0.02),
                                          ("decisive", [30.0, 45.0, 60.0], VIEWS_FIG16, 0.05)):
        geometry = in_plane(incidences, views)
        data = synthetic("oren-nayar", rough, "brdf", geometry, noise, 5, "slightly rough")
        angles = "/".join(f"{t:g}" for t in incidences)
        text = (f"oren-nayar rho = 0.5, sigma = 5 deg, ir_weight = 1, BRDF, theta_i = {angles} deg, "
                f"{views.size} views each, {100 * noise:g} % noise, seed 5")
        pairs.append((key, text, [
            Case(f"pair-{key}-lambert", "pair", "lambert", "lambert", data, {"rho": 0.5}, data=text),
            Case(f"pair-{key}-oren-nayar", "pair", "oren-nayar", "oren-nayar", data, rough, fixed={"ir_weight": 1.0},
                 data=text),
        ]))
    return pairs


# ---------------------------------------------------------------------------- Laplace
@contextmanager
def counting_fits() -> Iterator[list[int]]:
    """Count the calls of ``fit_least_squares`` made inside the block (the profile fits of
    the shape correction, which :mod:`gonio.fitting.evidence` imports at call time)."""
    original = least_squares_module.fit_least_squares
    count = [0]

    def counted(*args: Any, **kwargs: Any) -> Any:
        count[0] += 1
        return original(*args, **kwargs)

    least_squares_module.fit_least_squares = counted
    try:
        yield count
    finally:
        least_squares_module.fit_least_squares = original


def laplace(problem: FitProblem, overrides: Mapping[str, Prior]) -> dict[str, Any]:
    """Least squares and the Laplace evidence exactly as ``compare_models`` computes them.

    Parameters
    ----------
    problem : FitProblem
        Model, data and fixed parameters.
    overrides : mapping of Prior
        Priors replacing the defaults (a Gaussian one enters the fit: the posterior mode).

    Returns
    -------
    dict
        ``log_evidence`` (corrected: what ``laplace_log_evidence(..., corrected=True)`` and
        ``compare_models`` return) and ``log_evidence_raw`` (Laplace's formula,
        ``corrected=False``) [ln units], the ``truncation`` and ``shape`` terms, the
        least-squares fits the shape correction made (``profile_fits``), the optimum and
        its standard errors and correlations, the least-squares diagnostics, the script's
        own Gaussian mass inside the priors' support and the truncation-only evidence
        raw + ln(mass), wall ``seconds`` (least squares, evidence, both), and the priors
        used (``_priors``).
    """
    start = time.perf_counter()
    ls = fit_least_squares(problem, priors=overrides)
    fit_seconds = time.perf_counter() - start
    priors = resolve_priors(problem, ls.values, overrides)
    error = None
    with counting_fits() as fits:
        start = time.perf_counter()
        try:
            evidence = laplace_evidence(problem, ls, priors)
        except Exception as exc:  # recorded, so that one failing case does not end the benchmark
            evidence, error = None, f"{type(exc).__name__}: {exc}"
        evidence_seconds = time.perf_counter() - start
    if evidence is not None:
        raw, corrected, truncation, shape = evidence.raw, evidence.log_evidence, evidence.truncation, evidence.shape
    else:
        raw, corrected, truncation, shape = raw_formula(problem, ls, priors), math.nan, math.nan, {}
    mass = gaussian_mass_inside(ls, problem.free, priors)
    return {
        "log_evidence": corrected,
        "log_evidence_raw": raw,
        "raw_from": "gonio" if evidence is not None else "this script (gonio raised)",
        "error": error,
        "truncation": truncation,
        "shape": dict(shape),
        "profile_fits": fits[0],
        "seconds": fit_seconds + evidence_seconds,
        "seconds_least_squares": fit_seconds,
        "seconds_evidence": evidence_seconds,
        "values": {n: ls.values[n] for n in problem.free},
        "stderr": {n: ls.stderr[n] for n in problem.free},
        "correlation": ls.correlation.tolist(),
        "at_bound": ls.at_bound,
        "insensitive": ls.insensitive,
        "log_likelihood": ls.log_likelihood,
        "gaussian_mass_inside_prior": mass,
        "log_evidence_truncated": raw + math.log(mass) if mass > 0 and math.isfinite(raw) else math.nan,
        "priors": {n: str(p) for n, p in priors.items()},
        "_priors": priors,
    }


def raw_formula(problem: FitProblem, ls: Any, priors: Mapping[str, Prior]) -> float:
    """Laplace's formula with the least-squares covariance, computed here (used only where
    gonio's evidence raised): ln L + ln prior + (k/2) ln(2 pi) + (1/2) ln det C at the optimum."""
    covariance = np.asarray(ls.covariance, float)
    if not np.all(np.isfinite(covariance)):
        return math.nan
    sign, log_det = np.linalg.slogdet(covariance)
    vector = np.array([ls.values[n] for n in problem.free], float)
    log_prior = sum(priors[n].logpdf(float(v)) for n, v in zip(problem.free, vector))
    if sign <= 0 or not math.isfinite(log_prior):
        return math.nan
    return problem.log_likelihood(vector) + log_prior + 0.5 * vector.size * math.log(2 * math.pi) + 0.5 * log_det


def gaussian_mass_inside(ls: Any, free: Sequence[str], priors: Mapping[str, Prior]) -> float:
    """Probability that the Laplace Gaussian N(mode, covariance) falls inside the prior's support.

    Laplace's formula integrates its Gaussian over all of R^k; where the support cuts it (a
    mode on or near a bound) the evidence is overstated by -ln of this mass.  Computed here
    from the least-squares covariance and the priors' limits, independently of gonio's
    truncation term, as a check on it.  NaN when the covariance is undetermined.
    """
    covariance = np.asarray(ls.covariance, float)
    if not np.all(np.isfinite(covariance)):
        return math.nan
    mean = np.array([ls.values[n] for n in free])
    lower = np.array([priors[n].lower for n in free])
    upper = np.array([priors[n].upper for n in free])
    if mean.size == 1:
        sd = math.sqrt(covariance[0, 0])
        return float(ndtr((upper[0] - mean[0]) / sd) - ndtr((lower[0] - mean[0]) / sd))
    sd = np.sqrt(np.diag(covariance))
    # Standardise and replace infinite limits by far ones (the CDF routine wants finite numbers).
    lo = np.maximum((lower - mean) / sd, -40.0)
    hi = np.minimum((upper - mean) / sd, 40.0)
    correlation = covariance / np.outer(sd, sd)
    distribution = stats.multivariate_normal(np.zeros(mean.size), correlation)
    return float(distribution.cdf(hi, lower_limit=lo, rng=np.random.default_rng(0)))


# ---------------------------------------------------------------------------- nested sampling
def unit_to_prior(prior: Prior) -> Callable[[float], float]:
    """The inverse CDF of ``prior`` (:meth:`gonio.fitting.priors.Prior.quantile`): maps u in
    [0, 1] to a draw from it."""
    return lambda u: float(prior.quantile(u))


def prior_transform(priors: Sequence[Prior]) -> Callable[[np.ndarray], np.ndarray]:
    """dynesty's prior transform: unit cube -> parameter vector, one independent prior per axis."""
    inverse = [unit_to_prior(p) for p in priors]

    def transform(u: np.ndarray) -> np.ndarray:
        return np.array([f(x) for f, x in zip(inverse, u)])

    return transform


def check_transforms() -> list[dict[str, Any]]:
    """Each kind of prior transform against the prior's own density.

    For u on a grid in (0, 1), the probability the prior's ``logpdf`` puts below the
    transformed point (adaptive quadrature) must equal u; the largest difference is
    recorded. The priors are those of the cases (uniform, the truncated-normal calibration
    prior), the default log-uniform prior of a free ``scale``, and a normal truncated
    entirely above its mean (the mirrored branch).
    """
    from scipy.integrate import quad

    priors = [Uniform(0.0, 90.0), LogUniform(0.1, 1.0e5), Normal(100.0, 2.0, 0.0, math.inf),
              Normal(0.5, 0.1, 0.6, 1.0)]
    out = []
    for prior in priors:
        inverse = unit_to_prior(prior)
        worst = 0.0
        for u in np.linspace(0.01, 0.99, 99):
            x = inverse(float(u))
            below = quad(lambda t, p=prior: math.exp(p.logpdf(t)), prior.lower, x, limit=200, epsabs=1e-12,
                         epsrel=1e-10)[0]
            worst = max(worst, abs(below - u))
        out.append({"prior": str(prior), "max_cdf_error": worst})
        print(f"prior transform {prior}: largest |CDF(x(u)) - u| = {worst:.1e}", flush=True)
    return out


def log_likelihood_in_support(problem: FitProblem, priors: Sequence[Prior]) -> Callable[[np.ndarray], float]:
    """``problem.log_likelihood``, -inf outside the physical range or the priors' support."""

    def log_likelihood(vector: np.ndarray) -> float:
        if not problem.in_bounds(vector) or not all(p.contains(float(x)) for p, x in zip(priors, vector)):
            return -math.inf
        return problem.log_likelihood(vector)

    return log_likelihood


def nested_run(problem: FitProblem, priors: Mapping[str, Prior], seed: int) -> dict[str, Any]:
    """One dynesty run to ``DLOGZ``.

    Parameters
    ----------
    problem : FitProblem
        Whose ``log_likelihood`` is integrated.
    priors : mapping of Prior
        The prior of every free parameter (as :func:`laplace` resolved them).
    seed : int
        Seed of the sampler's numpy Generator.

    Returns
    -------
    dict
        ``log_evidence`` and its ``error`` [ln units], wall ``seconds``, likelihood
        ``calls``, ``iterations``, the ``information`` H [nats], the sampler's warnings, and
        the samples, their importance weights and log-likelihoods (``_``-prefixed).
    """
    import dynesty

    ordered = [priors[n] for n in problem.free]
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sampler = dynesty.NestedSampler(
            log_likelihood_in_support(problem, ordered), prior_transform(ordered), problem.ndim,
            nlive=NLIVE, sample=SAMPLE, rstate=np.random.default_rng(seed))
        sampler.run_nested(dlogz=DLOGZ, print_progress=False)
    results = sampler.results
    return {
        "log_evidence": float(results.logz[-1]),
        "error": float(results.logzerr[-1]),
        "seconds": time.perf_counter() - start,
        "calls": int(np.sum(results.ncall)),
        "iterations": int(results.niter),
        "information": float(results.information[-1]),
        "warnings": sorted({str(w.message).split(".")[0] for w in caught}),
        "_samples": np.asarray(results.samples),
        "_weights": np.asarray(results.importance_weights()),
        "_log_likelihood": np.asarray(results.logl),
    }


def nested(problem: FitProblem, priors: Mapping[str, Prior]) -> dict[str, Any]:
    """``NESTED_REPEATS`` independent runs, their mean, its error and the runs' scatter."""
    runs = [nested_run(problem, priors, seed) for seed in range(NESTED_REPEATS)]
    values = np.array([r["log_evidence"] for r in runs])
    errors = np.array([r["error"] for r in runs])
    samples = np.concatenate([r["_samples"] for r in runs])
    weights = np.concatenate([r["_weights"] for r in runs]) / len(runs)
    log_like = np.concatenate([r["_log_likelihood"] for r in runs])
    return {
        "log_evidence": float(values.mean()),
        "error": float(math.sqrt(np.sum(errors**2)) / len(runs)),
        "runs": [{k: v for k, v in r.items() if not k.startswith("_")} for r in runs],
        "scatter_of_runs": float(values.std(ddof=1)) if len(runs) > 1 else math.nan,
        "mean_stated_error": float(errors.mean()),
        "seconds": float(sum(r["seconds"] for r in runs)),
        "posterior": posterior_moments(problem.free, samples, weights),
        "_samples": samples,
        "_log_likelihood": log_like,
    }


def posterior_moments(free: Sequence[str], samples: np.ndarray, weights: np.ndarray) -> dict[str, dict[str, float]]:
    """Weighted mean, standard deviation, skewness and 2.5/97.5 percentiles per parameter."""
    out = {}
    weights = weights / weights.sum()
    for j, name in enumerate(free):
        x = samples[:, j]
        mean = float(np.sum(weights * x))
        sd = float(math.sqrt(np.sum(weights * (x - mean) ** 2)))
        order = np.argsort(x)
        cumulative = np.cumsum(weights[order])
        out[name] = {
            "mean": mean,
            "sd": sd,
            "skewness": float(np.sum(weights * ((x - mean) / sd) ** 3)) if sd > 0 else math.nan,
            "p2_5": float(x[order][np.searchsorted(cumulative, 0.025)]),
            "p97_5": float(x[order][min(np.searchsorted(cumulative, 0.975), x.size - 1)]),
        }
    return out


# ---------------------------------------------------------------------------- quadrature
@dataclass
class GridFrame:
    """An affine grid frame x = centre + matrix z over the box [low, high] in z."""

    centre: np.ndarray
    matrix: np.ndarray
    low: np.ndarray
    high: np.ndarray
    rotated: bool


def grid_frame(problem: FitProblem, priors: Sequence[Prior], samples: np.ndarray,
               log_likelihood: np.ndarray) -> GridFrame:
    """The region to integrate: every nested sample within ``GRID_NATS`` of the best log posterior.

    Where the bulk of the posterior (log posterior within ``CUT_NATS`` of the best) stays
    clear of the priors' support limits, the grid is laid along the principal axes of the
    region (whitened by the samples' covariance), so that a thin correlated ridge (rho x
    scale) is resolved, and a support limit cutting the far tail costs nothing; where the
    bulk reaches a limit, the grid is aligned with the parameter axes and clipped to the
    support, so that the cut falls on the grid's edge. Each box is widened by a tenth of
    its span on each side.
    """
    log_prior = np.array([sum(p.logpdf(float(x)) for p, x in zip(priors, row)) for row in samples])
    log_post = log_likelihood + log_prior
    keep = samples[log_post >= np.max(log_post) - GRID_NATS]
    bulk = samples[log_post >= np.max(log_post) - CUT_NATS]
    low, high = keep.min(axis=0), keep.max(axis=0)
    span = np.maximum(high - low, 1e-12)
    support_low = np.array([max(p.lower, problem.spec(n).bounds[0]) for p, n in zip(priors, problem.free)])
    support_high = np.array([min(p.upper, problem.spec(n).bounds[1]) for p, n in zip(priors, problem.free)])
    touches = bool(np.any(bulk.min(axis=0) - 0.1 * span <= support_low)
                   or np.any(bulk.max(axis=0) + 0.1 * span >= support_high))
    if touches or problem.ndim == 1:
        lo = np.maximum(low - 0.1 * span, support_low)
        hi = np.minimum(high + 0.1 * span, support_high)
        return GridFrame(np.zeros(problem.ndim), np.eye(problem.ndim), lo, hi, rotated=False)
    centre = keep.mean(axis=0)
    matrix = np.linalg.cholesky(np.cov(keep.T))
    z = np.linalg.solve(matrix, (keep - centre).T).T
    z_low, z_high = z.min(axis=0), z.max(axis=0)
    z_span = z_high - z_low
    return GridFrame(centre, matrix, z_low - 0.1 * z_span, z_high + 0.1 * z_span, rotated=True)


def trapezoid_log_evidence(problem: FitProblem, priors: Sequence[Prior], frame: GridFrame, points: int) -> float:
    """ln of the trapezoid-rule integral of likelihood x prior over ``frame``.

    Parameters
    ----------
    problem : FitProblem
        Whose ``log_likelihood`` is integrated.
    priors : sequence of Prior
        In ``problem.free`` order; the integrand is zero outside their support.
    frame : GridFrame
        The box, in the frame's coordinates z (x = centre + matrix z).
    points : int
        Grid points per axis.

    Returns
    -------
    float
        ln Z [ln units].
    """
    axes, log_weights = [], []
    for lo, hi in zip(frame.low, frame.high):
        w = np.full(points, (hi - lo) / (points - 1))
        w[[0, -1]] *= 0.5
        axes.append(np.linspace(lo, hi, points))
        log_weights.append(np.log(w))
    k = len(axes)
    z = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, k)
    log_w = np.stack(np.meshgrid(*log_weights, indexing="ij"), axis=-1).reshape(-1, k).sum(axis=1)
    x = frame.centre + z @ frame.matrix.T
    log_like = log_likelihood_in_support(problem, priors)
    terms = np.array([log_like(v) + sum(p.logpdf(float(c)) for p, c in zip(priors, v)) for v in x])
    log_jacobian = float(np.linalg.slogdet(frame.matrix)[1])
    return float(logsumexp(terms + log_w)) + log_jacobian


def quadrature(problem: FitProblem, priors: Mapping[str, Prior], samples: np.ndarray,
               log_likelihood: np.ndarray) -> dict[str, Any]:
    """Grid reference of ln Z and its error (change from a grid with 2/3 the points per axis)."""
    ordered = [priors[n] for n in problem.free]
    start = time.perf_counter()
    frame = grid_frame(problem, ordered, samples, log_likelihood)
    points = GRID_POINTS[problem.ndim]
    fine = trapezoid_log_evidence(problem, ordered, frame, points)
    coarse = trapezoid_log_evidence(problem, ordered, frame, int(2 * points / 3) | 1)
    return {
        "log_evidence": fine,
        "error": abs(fine - coarse),
        "points_per_axis": points,
        "grid": "principal axes of the posterior region" if frame.rotated else "parameter axes, clipped to the support",
        "seconds": time.perf_counter() - start,
    }


# ---------------------------------------------------------------------------- per case
def expected_bound_offset(case: Case, lap: Mapping[str, Any]) -> dict[str, Any] | None:
    """The offset ln Z(Laplace) - ln Z the Gaussian likelihood predicts for the data built on a bound.

    One parameter whose unconstrained optimum lies d standard errors beyond its bound: the
    likelihood is exp(-(x - x0)^2 / (2 s^2)) cut at the bound, the constrained optimum is
    the bound, and the integral is Phi(-d) exp(d^2/2) of Laplace's, so the offset is
    -ln(Phi(-d)) - d^2/2: ln 2 for d = 0, more for d > 0.  Two parameters both on their
    upper bound with correlation r (d = 0): the quadrant below both bounds holds
    1/4 + arcsin(r)/(2 pi) of a bivariate Gaussian, so the offset is -ln of that (2 ln 2
    for r = 0).
    """
    if case.key.startswith("bound-lambert-rho"):
        d = case.beyond
        return {"value": -math.log(ndtr(-d)) - 0.5 * d * d, "formula": f"-ln Phi(-{d:g}) - {d:g}^2/2"}
    if case.key == "bound-minnaert-rho-k":
        correlation = float(lap["correlation"][0][1])
        quadrant = 0.25 + math.asin(correlation) / (2.0 * math.pi)
        return {"value": -math.log(quadrant), "formula": f"-ln(1/4 + asin({correlation:.3f})/(2 pi))",
                "correlation": correlation}
    return None


def difference(a: float, b: float, error: float) -> dict[str, float]:
    """a - b with its error and the difference in units of that error."""
    d = a - b
    return {"value": d, "error": error, "in_errors": d / error if error > 0 else math.nan}


def run_case(case: Case) -> dict[str, Any]:
    """Laplace (raw and corrected), nested sampling and quadrature for one case, and their differences.

    Parameters
    ----------
    case : Case
        The problem and its priors.

    Returns
    -------
    dict
        The case's description, the three estimates (:func:`laplace`, :func:`nested`,
        :func:`quadrature`), the differences raw - grid, corrected - grid, raw - nested,
        corrected - nested, truncation-only - grid and nested - grid with their errors, and
        the offset of the raw formula the bound construction predicts
        (:func:`expected_bound_offset`).
    """
    problem = case.problem()
    lap = laplace(problem, case.priors)
    priors = lap.pop("_priors")
    ns = nested(problem, priors)
    quad = quadrature(problem, priors, ns.pop("_samples"), ns.pop("_log_likelihood"))
    z_r, z_c, z_n, z_q = lap["log_evidence_raw"], lap["log_evidence"], ns["log_evidence"], quad["log_evidence"]
    record = {
        "key": case.key,
        "regime": case.regime,
        "title": case.title,
        "model": case.model,
        "fixed": case.fixed,
        "free": list(problem.free),
        "n_data": case.dataset.n,
        "quantity": case.dataset.quantity,
        "data": case.data,
        "truth": case.truth,
        "laplace": lap,
        "nested": ns,
        "quadrature": quad,
        "raw_minus_quadrature": difference(z_r, z_q, quad["error"]),
        "corrected_minus_quadrature": difference(z_c, z_q, quad["error"]),
        "raw_minus_nested": difference(z_r, z_n, ns["error"]),
        "corrected_minus_nested": difference(z_c, z_n, ns["error"]),
        "truncated_minus_quadrature": difference(lap["log_evidence_truncated"], z_q, quad["error"]),
        "nested_minus_quadrature": difference(z_n, z_q, math.hypot(ns["error"], quad["error"])),
        "expected_offset": expected_bound_offset(case, lap),
    }
    shape = ", ".join(f"{k} {v:+.3f}" for k, v in lap["shape"].items()) or "none"
    print(f"{case.key:<28} raw {z_r:10.4f}  corrected {z_c:10.4f}  nested {z_n:10.4f} +- {ns['error']:.4f}  "
          f"grid {z_q:10.4f}  raw-grid {z_r - z_q:+.4f}  corr-grid {z_c - z_q:+.4f}  corr-N {z_c - z_n:+.3f}  "
          f"[trunc {lap['truncation']:+.4f}, shape {shape}, {lap['profile_fits']} fits]  "
          f"({lap['seconds_least_squares']:.2f} + {lap['seconds_evidence']:.2f} s / {ns['seconds']:.0f} s / "
          f"{quad['seconds']:.0f} s)", flush=True)
    return record


def choose(delta: float) -> str:
    """compare_models' rule for lambert against oren-nayar (both adequate) from
    ln Z(oren-nayar) - ln Z(lambert): the fewer parameters unless the other is better by
    more than ``THRESHOLD``."""
    return "oren-nayar" if delta > THRESHOLD else "lambert"


#: The estimates of a case compared in the pairs: (name in the report, getter of ln Z and its error).
ESTIMATES: dict[str, Callable[[Mapping[str, Any]], tuple[float, float]]] = {
    "laplace_raw": lambda r: (r["laplace"]["log_evidence_raw"], 0.0),
    "laplace": lambda r: (r["laplace"]["log_evidence"], 0.0),
    "nested": lambda r: (r["nested"]["log_evidence"], r["nested"]["error"]),
    "quadrature": lambda r: (r["quadrature"]["log_evidence"], r["quadrature"]["error"]),
}


def run_pair(key: str, text: str, pair: Sequence[Case]) -> dict[str, Any]:
    """ln Z(oren-nayar) - ln Z(lambert), and compare_models' choice, from each estimate."""
    simple, rough = (run_case(c) for c in pair)
    out: dict[str, Any] = {"key": key, "data": text, "candidates": [simple["key"], rough["key"]]}
    for method, get in ESTIMATES.items():
        (z_s, e_s), (z_r, e_r) = get(simple), get(rough)
        delta = z_r - z_s
        out[method] = {"delta_log_evidence": delta, "error": math.hypot(e_s, e_r), "chosen": choose(delta)}
    start = time.perf_counter()
    comparison = compare_models(pair[0].dataset, [simple["model"], (rough["model"], rough["fixed"])])
    seconds = time.perf_counter() - start
    rows = {row["label"]: {k: row[k] for k in ("log_evidence", "log_evidence_laplace", "evidence_truncation",
                                               "evidence_shape")} for row in comparison.rows}
    benchmark = [simple["laplace"]["log_evidence"], rough["laplace"]["log_evidence"]]
    out["compare_models"] = {
        "chosen": comparison.chosen, "reason": comparison.reason, "rows": rows, "seconds": seconds,
        "largest_difference_from_benchmark": max(abs(row["log_evidence"] - z) for row, z in zip(
            sorted(comparison.rows, key=lambda r: r["k"]), benchmark)),
    }
    out["cases"] = [simple, rough]
    print(f"pair {key}: dlnZ(oren-nayar - lambert) raw {out['laplace_raw']['delta_log_evidence']:+.3f}, corrected "
          f"{out['laplace']['delta_log_evidence']:+.3f}, nested {out['nested']['delta_log_evidence']:+.3f} +- "
          f"{out['nested']['error']:.3f}, grid {out['quadrature']['delta_log_evidence']:+.3f}; chosen "
          + " / ".join(out[m]["chosen"] for m in ESTIMATES)
          + f"; compare_models chose {comparison.chosen} ({seconds:.1f} s)", flush=True)
    return out


def sigma_survey() -> dict[str, Any]:
    """Raw and corrected Laplace against grid quadrature for oren-nayar on Lambertian data, over many noise draws.

    The data of :data:`MATTE` for every seed of :data:`SURVEY_SEEDS`; the grid covers rho
    within ten least-squares standard errors of the optimum and sigma in [0, SURVEY_SIGMA_MAX]
    deg (the log posterior falls by more than ``GRID_NATS`` before its edge).
    """
    on_zero, off_zero = [], []
    start = time.perf_counter()
    for seed in SURVEY_SEEDS:
        problem = FitProblem("oren-nayar", matte(seed), {"ir_weight": 1.0})
        lap = laplace(problem, {})
        priors = [lap["_priors"][n] for n in problem.free]
        rho, sd = lap["values"]["rho"], lap["stderr"]["rho"]
        frame = GridFrame(np.zeros(2), np.eye(2), np.array([rho - 10 * sd, 0.0]),
                          np.array([rho + 10 * sd, SURVEY_SIGMA_MAX]), rotated=False)
        reference = trapezoid_log_evidence(problem, priors, frame, SURVEY_GRID_POINTS)
        # Lambert is linear in rho and far from its bounds: its Laplace evidence is exact
        # (the gaussian-lambert case) and uncorrected.
        simple = laplace(FitProblem("lambert", problem.dataset), {})
        lambert = simple["log_evidence"]
        raw, corrected = lap["log_evidence_raw"], lap["log_evidence"]
        row = {"seed": seed, "sigma": lap["values"]["sigma"], "sigma_stderr": lap["stderr"]["sigma"],
               "laplace_raw": raw, "laplace": corrected, "truncation": lap["truncation"],
               "shape": lap["shape"].get("sigma", 0.0), "profile_fits": lap["profile_fits"],
               "seconds_evidence": lap["seconds_evidence"], "quadrature": reference,
               "raw_minus_quadrature": raw - reference, "corrected_minus_quadrature": corrected - reference,
               "lambert_laplace": lambert, "lambert_correction": lambert - simple["log_evidence_raw"],
               "delta_raw": raw - simple["log_evidence_raw"], "delta_corrected": corrected - lambert,
               "delta_quadrature": reference - lambert,
               "chosen_by_raw": choose(raw - simple["log_evidence_raw"]),
               "chosen_by_corrected": choose(corrected - lambert),
               "chosen_by_quadrature": choose(reference - lambert)}
        (on_zero if "sigma" in lap["at_bound"] else off_zero).append(row)

    def stats_of(values: list[float]) -> dict[str, Any]:
        d = np.array(values, float)
        finite = d[np.isfinite(d)]
        return {"undefined": int(d.size - finite.size),
                "mean": float(finite.mean()) if finite.size else math.nan,
                "min": float(finite.min()) if finite.size else math.nan,
                "max": float(finite.max()) if finite.size else math.nan,
                "largest_abs": float(np.abs(finite).max()) if finite.size else math.nan}

    def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {"count": len(rows)}
        for name in ("raw", "corrected"):
            out[f"{name}_minus_quadrature"] = stats_of([r[f"{name}_minus_quadrature"] for r in rows])
            out[f"delta_{name}"] = stats_of([r[f"delta_{name}"] for r in rows])
            out[f"decisions_differ_{name}"] = sum(r[f"chosen_by_{name}"] != r["chosen_by_quadrature"] for r in rows)
            out[f"oren_nayar_chosen_by_{name}"] = sum(r[f"chosen_by_{name}"] == "oren-nayar" for r in rows)
        out["delta_quadrature"] = stats_of([r["delta_quadrature"] for r in rows])
        out["oren_nayar_chosen_by_quadrature"] = sum(r["chosen_by_quadrature"] == "oren-nayar" for r in rows)
        out["corrected_with_shape"] = sum(r["shape"] != 0.0 for r in rows)
        out["seconds_evidence"] = stats_of([r["seconds_evidence"] for r in rows])
        out["profile_fits"] = stats_of([r["profile_fits"] for r in rows])
        out["rows"] = rows
        return out

    out = {"what": MATTE, "seeds": [SURVEY_SEEDS.start, SURVEY_SEEDS.stop - 1],
           "grid_points_per_axis": SURVEY_GRID_POINTS, "sigma_max": SURVEY_SIGMA_MAX,
           "optimum_on_sigma_0": summary(on_zero), "optimum_off_sigma_0": summary(off_zero),
           "seconds": time.perf_counter() - start}
    for key in ("optimum_on_sigma_0", "optimum_off_sigma_0"):
        s = out[key]
        r, c = s["raw_minus_quadrature"], s["corrected_minus_quadrature"]
        print(f"survey, {key.replace('_', ' ')}: {s['count']} seeds; raw - grid mean {r['mean']:+.3f} "
              f"({r['min']:+.3f} .. {r['max']:+.3f}); corrected - grid mean {c['mean']:+.4f} "
              f"({c['min']:+.4f} .. {c['max']:+.4f}), undefined {c['undefined']}; oren-nayar chosen "
              f"{s['oren_nayar_chosen_by_raw']} / {s['oren_nayar_chosen_by_corrected']} / "
              f"{s['oren_nayar_chosen_by_quadrature']} times (raw / corrected / grid)", flush=True)
    return out


def jitter_survey() -> dict[str, Any]:
    """Raw and corrected Laplace against a grid for a free relative extra-noise term that is not needed.

    The data of :data:`MATTE` (Lambertian, the stated 1 % noise is the true one) for every
    seed of :data:`SURVEY_SEEDS`, fitted with ``lambert`` and ``jitter="relative"``: the
    likelihood depends on ``rel_jitter`` through its square, so, like sigma of Oren-Nayar,
    its posterior piles at 0 where the likelihood is stationary (least squares does not list
    the extra-noise term in ``at_bound``, so "on 0" is its value being 0). The grid covers rho within
    ten least-squares standard errors and rel_jitter in [0, JITTER_MAX] with
    ``SURVEY_GRID_POINTS`` per axis; its error is the change from ``JITTER_COARSE_POINTS``.
    """
    rows = []
    start = time.perf_counter()
    for seed in SURVEY_SEEDS:
        problem = FitProblem("lambert", matte(seed), jitter="relative")
        lap = laplace(problem, {})
        priors = [lap["_priors"][n] for n in problem.free]
        rho, sd = lap["values"]["rho"], lap["stderr"]["rho"]
        frame = GridFrame(np.zeros(2), np.eye(2), np.array([rho - 10 * sd, 0.0]),
                          np.array([rho + 10 * sd, JITTER_MAX]), rotated=False)
        reference = trapezoid_log_evidence(problem, priors, frame, SURVEY_GRID_POINTS)
        coarse = trapezoid_log_evidence(problem, priors, frame, JITTER_COARSE_POINTS)
        raw, corrected = lap["log_evidence_raw"], lap["log_evidence"]
        rows.append({"seed": seed, "rel_jitter": lap["values"]["rel_jitter"], "at_bound": lap["values"]["rel_jitter"] <= 1e-9,
                     "laplace_raw": raw, "laplace": corrected, "truncation": lap["truncation"], "shape": lap["shape"],
                     "profile_fits": lap["profile_fits"], "seconds_evidence": lap["seconds_evidence"],
                     "quadrature": reference, "quadrature_error": abs(reference - coarse),
                     "raw_minus_quadrature": raw - reference, "corrected_minus_quadrature": corrected - reference})
    out: dict[str, Any] = {"what": "lambert with a free relative extra-noise term (jitter='relative') on the data of "
                                   f"the sigma survey: {MATTE}",
                           "seeds": [SURVEY_SEEDS.start, SURVEY_SEEDS.stop - 1], "rel_jitter_max": JITTER_MAX,
                           "grid_points_per_axis": SURVEY_GRID_POINTS}
    for key, subset in (("jitter_on_0", [r for r in rows if r["at_bound"]]),
                        ("jitter_off_0", [r for r in rows if not r["at_bound"]])):
        summary: dict[str, Any] = {"count": len(subset)}
        for name in ("raw_minus_quadrature", "corrected_minus_quadrature"):
            d = np.array([r[name] for r in subset], float)
            summary[name] = {"mean": float(d.mean()), "min": float(d.min()), "max": float(d.max())} if d.size else None
        out[key] = summary
    out["corrected_with_shape"] = sum(bool(r["shape"]) for r in rows)
    for name in ("profile_fits", "seconds_evidence"):
        d = np.array([r[name] for r in rows], float)
        out[name] = {"mean": float(d.mean()), "min": float(d.min()), "max": float(d.max())}
    out["largest_grid_error"] = max(r["quadrature_error"] for r in rows)
    out["rows"] = rows
    out["seconds"] = time.perf_counter() - start
    for key in ("jitter_on_0", "jitter_off_0"):
        sm = out[key]
        if sm["count"]:
            r, c = sm["raw_minus_quadrature"], sm["corrected_minus_quadrature"]
            print(f"jitter survey, {key.replace('_', ' ')}: {sm['count']} seeds; raw - grid {r['min']:+.3f} .. "
                  f"{r['max']:+.3f}; corrected - grid {c['min']:+.4f} .. {c['max']:+.4f} (mean {c['mean']:+.4f})",
                  flush=True)
    return out


# ---------------------------------------------------------------------------- output
def real(value: Any) -> float:
    """A JSON number, NaN for null (undefined values are written as null)."""
    return math.nan if value is None else float(value)


def chart(report: Mapping[str, Any], path: Path) -> None:
    """Raw and corrected Laplace, and nested sampling, minus the grid per case; the pairs'
    decisions; the survey."""
    from matplotlib.figure import Figure

    from matplotlib.lines import Line2D

    fig = Figure(figsize=(19.0, 5.6), layout="constrained")
    left, right, survey, jitter = fig.subplots(1, 4, width_ratios=[2.2, 1.0, 1.3, 1.3])
    records = report["cases"]
    colours = {"gaussian": "C0", "bound": "C3", "skewed": "C1", "calibrated": "C2"}
    for y, r in enumerate(records):
        colour = colours[r["regime"]]
        n = r["nested_minus_quadrature"]
        left.errorbar(n["value"], y + 0.22, xerr=n["error"], fmt="s", ms=4, color="0.55", capsize=2)
        raw, corrected = real(r["raw_minus_quadrature"]["value"]), real(r["corrected_minus_quadrature"]["value"])
        if math.isfinite(raw):
            left.plot(raw, y, "o", mfc="none", mec=colour, ms=7, mew=1.5)
        if math.isfinite(corrected):
            left.plot(corrected, y, "o", color=colour, ms=5)
            if math.isfinite(raw) and abs(raw - corrected) > 0.02:
                left.annotate("", (corrected, y), (raw, y), arrowprops={"arrowstyle": "->", "color": colour,
                                                                        "lw": 0.8})
        else:
            reason = (r["laplace"].get("error") or "NaN").split(":")[0]
            left.text(max(raw, 0.0) if math.isfinite(raw) else 0.0, y - 0.3, f"   corrected: {reason}", va="center",
                      fontsize=8, color=colour)
        expected = r["expected_offset"]
        if expected:
            left.plot(expected["value"], y, "|", color="C3", ms=14, mew=2)
    left.axvline(0.0, color="k", lw=0.8)
    left.axvline(math.log(2.0), color="C3", lw=0.8, ls=":")
    left.text(math.log(2.0), len(records) - 0.6, " ln 2", color="C3", fontsize=8, va="center")
    left.set_yticks(range(len(records)), [r["key"] for r in records], fontsize=8)
    left.invert_yaxis()
    left.set_xlabel("ln Z (estimate) - ln Z (grid quadrature) [natural-log units]")
    left.set_title("open: Laplace's formula (raw); filled: corrected, as compare_models; grey: nested sampling\n"
                   f"(dynesty, {NESTED_REPEATS} x {NLIVE} live points, 1 sigma); bars: raw offset the truncated "
                   "Gaussian predicts", fontsize=9)
    handles = [Line2D([], [], ls="none", marker="o", mfc="none", mec="k", mew=1.5, label="raw formula"),
               Line2D([], [], ls="none", marker="o", color="k", ms=5, label="corrected (gonio)"),
               Line2D([], [], ls="none", marker="s", color="0.55", ms=4, label="nested sampling"),
               Line2D([], [], ls="none", marker="|", color="C3", ms=12, mew=2, label="raw offset predicted")]
    left.legend(handles=handles, fontsize=7, loc="lower right")
    left.grid(axis="x", alpha=0.3)
    pairs = report["pairs"]
    styles = {"laplace_raw": ("o", "raw"), "laplace": ("D", "corrected"), "nested": ("s", "nested"),
              "quadrature": ("^", "grid")}
    for j, (method, (marker, label)) in enumerate(styles.items()):
        for i, p in enumerate(pairs):
            m = p[method]
            right.errorbar(i + 0.18 * (j - 1.5), m["delta_log_evidence"], yerr=m["error"] or None, fmt=marker,
                           color=f"C{j + 4}", capsize=3, label=label if i == 0 else None,
                           mfc="none" if method == "laplace_raw" else None)
    right.axhline(THRESHOLD, color="k", lw=0.8, ls=":")
    right.axhline(0.0, color="k", lw=0.8)
    right.text(-0.55, THRESHOLD, " threshold: above it oren-nayar is chosen", fontsize=7, va="bottom")
    right.set_xticks(range(len(pairs)), [p["key"] for p in pairs])
    right.set_xlim(-0.6, len(pairs) - 0.4)
    right.set_ylabel("ln Z(oren-nayar) - ln Z(lambert)")
    right.set_title("lambert vs oren-nayar on sigma = 5 deg data", fontsize=9)
    right.legend(fontsize=8)
    right.grid(alpha=0.3)
    survey_panel(survey, report["sigma_survey"])
    jitter_panel(jitter, report["jitter_survey"])
    fig.savefig(path, dpi=110)


def survey_panel(ax: Any, survey: Mapping[str, Any]) -> None:
    """Raw and corrected Laplace minus grid against the least-squares sigma, for oren-nayar on Lambertian data."""
    for key, marker, label in (("optimum_on_sigma_0", "v", "on sigma = 0"),
                               ("optimum_off_sigma_0", "o", "off sigma = 0")):
        rows = survey[key]["rows"]
        sigma = [r["sigma"] for r in rows]
        n = len(rows)
        ax.plot(sigma, [real(r["raw_minus_quadrature"]) for r in rows], marker, ls="none", mfc="none", color="C3",
                label=f"raw, optimum {label} ({n})")
        ax.plot(sigma, [real(r["corrected_minus_quadrature"]) for r in rows], marker, ls="none", color="C0",
                label=f"corrected, optimum {label} ({n})")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.axhline(math.log(2.0), color="C3", lw=0.8, ls=":")
    ax.set_xlabel("least-squares sigma [deg]")
    ax.set_ylabel("ln Z (Laplace) - ln Z (grid)")
    ax.set_title(f"oren-nayar on Lambertian data, {survey['seeds'][1] - survey['seeds'][0] + 1} noise draws",
                 fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)


def jitter_panel(ax: Any, survey: Mapping[str, Any]) -> None:
    """Raw and corrected Laplace minus grid against the least-squares rel_jitter, for lambert with a free jitter."""
    rows = survey["rows"]
    x = [100.0 * r["rel_jitter"] for r in rows]
    ax.plot(x, [real(r["raw_minus_quadrature"]) for r in rows], "o", mfc="none", color="C3", label="raw")
    ax.plot(x, [real(r["corrected_minus_quadrature"]) for r in rows], "o", color="C0", label="corrected")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.axhline(math.log(2.0), color="C3", lw=0.8, ls=":")
    ax.set_xlabel("least-squares rel_jitter [% of the value]")
    ax.set_ylabel("ln Z (Laplace) - ln Z (grid)")
    ax.set_title(f"lambert with a free relative jitter, same data ({len(rows)} draws)", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)


def strip_private(value: Any) -> Any:
    """Drop keys starting with '_' and turn NaN/inf into None (strict JSON)."""
    if isinstance(value, dict):
        return {k: strip_private(v) for k, v in value.items() if not str(k).startswith("_")}
    if isinstance(value, (list, tuple)):
        return [strip_private(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def main() -> int:
    try:
        import dynesty
    except ImportError:
        raise SystemExit("bench_evidence needs dynesty: pip install 'gonio[nested]'") from None
    began = time.perf_counter()
    transforms = check_transforms()
    records = [run_case(case) for case in cases()]
    pairs = [run_pair(*pair) for pair in comparison_pairs()]
    survey = sigma_survey()
    jitter = jitter_survey()
    wall = time.perf_counter() - began
    report = {
        "benchmark": "evidence",
        "command": COMMAND,
        "machine": machine() | {"gonio": gonio.__version__, "dynesty": dynesty.__version__},
        "settings": {"nlive": NLIVE, "dlogz": DLOGZ, "sample": SAMPLE, "nested_repeats": NESTED_REPEATS,
                     "grid_points_per_axis": GRID_POINTS, "grid_nats": GRID_NATS, "threshold": THRESHOLD,
                     "evidence": {name: getattr(evidence_module, name) for name in
                                  ("TRUNCATION_SDS", "SHAPE_SDS", "SHAPE_TOLERANCE", "PROFILE_DEPTH")}
                     | {"profile_nodes_per_side": int(evidence_module._NODES.size)}},
        "prior_transforms": transforms,
        "cases": records,
        "pairs": pairs,
        "sigma_survey": survey,
        "jitter_survey": jitter,
        "wall_seconds": wall,
    }
    report = strip_private(report)
    path = write_json("evidence", report)
    chart(report, OUT / "evidence.png")
    print(f"wall time {wall:.0f} s; wrote {path} and {OUT / 'evidence.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
