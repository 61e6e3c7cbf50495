"""Weighted, bounded least squares with covariance and degeneracy diagnostics.

:func:`fit_least_squares` minimises chi^2 = sum(((model - value) / sigma)^2) with
:func:`scipy.optimize.least_squares` (trust-region reflective, bounded by the parameters'
physical ranges), from several starting points so that a local minimum is not mistaken
for the answer.  The covariance of the free parameters is (J^T J)^-1 from the Jacobian of
the weighted residuals at the optimum; it is *not* rescaled by the reduced chi-square,
since the uncertainties are taken as measured (compare ``redchi`` with 1 to judge them;
use the ``jitter`` parameter of the Bayesian fit when they are too small).

Diagnostics, all reported as plain-language warnings in the result:

* **insensitive** parameters: the data do not change when the parameter changes (e.g.
  ``rho`` of a Lambertian sample fitted to normalised radiance, where it cancels; the
  Oren-Nayar ``sigma`` at 0, where the BRDF is stationary in sigma);
* **degenerate** combinations: the Jacobian has a (near-)null direction (``rho`` and the
  free ``scale`` of relative radiance, which enter only as their product);
* parameters **at a bound** of their physical range;
* parameters **not constrained**: standard error larger than the physical range.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from .problem import FitProblem

__all__ = ["LeastSquaresResult", "fit_least_squares", "jacobian_diagnostics"]

# A singular value of the column-scaled Jacobian below this fraction of the largest one is
# a degenerate direction.  Two-point finite differences are accurate to ~1e-8 relative, so
# an exact degeneracy shows up below ~1e-7; genuine but weak constraints (strong
# correlations) stay well above 1e-6.
_log = logging.getLogger("gonio.fitting")
#: Seconds between the progress lines of a slow least-squares fit.
HEARTBEAT_SECONDS = 5.0

_DEGENERATE_RCOND = 1e-6
# A parameter takes part in a degenerate direction when its component in the null vector
# exceeds this (the vector has unit length; 0.1 leaves out round-off contributions).
_NULL_COMPONENT = 0.1
# Relative distance to a bound (fraction of the range, or of |value| for infinite ranges)
# below which a solution counts as "at the bound".
_AT_BOUND = 1e-6


@dataclass
class LeastSquaresResult:
    """Outcome of :func:`fit_least_squares`.

    Attributes
    ----------
    values : dict
        Best-fit value of every parameter (fixed ones included).
    free : tuple of str
        Names of the fitted parameters (order of ``covariance``).
    stderr : dict
        Standard error of each free parameter (NaN where undetermined).
    covariance, correlation : ndarray
        Of the free parameters (NaN rows for undetermined ones).
    chi2, dof, redchi : float
        Chi-square, degrees of freedom (n - free), reduced chi-square.
    log_likelihood : float
        Maximum Gaussian log-likelihood (jitter included when fitted).
    success : bool
        Whether the optimiser reported convergence.
    message : str
        The optimiser's message.
    nfev : int
        Number of residual evaluations (all starts).
    at_bound : dict
        ``name -> 'lower' | 'upper'`` for parameters at a physical bound.
    insensitive : list of str
        Parameters the data do not depend on.
    degenerate : list of list of str
        Groups of parameters that are degenerate with each other.
    warnings : list of str
        Plain-language diagnostics.
    gaussian_priors : tuple of str
        Parameters whose Gaussian prior entered the fit (a maximum a posteriori fit: the
        values are the posterior mode and the covariance its Laplace approximation;
        ``chi2`` and ``log_likelihood`` remain those of the data alone).
    table_error : float
        For a tabulated model: rms of (table - exact) / sigma at ``values``
        (:func:`gonio.fitting.polish.table_error`), once measured (NaN before); a later
        polish of the same fit (:func:`gonio.fitting.fit` given a comparison's least
        squares) reuses it instead of evaluating the exact model again.
    """

    values: dict[str, float]
    free: tuple[str, ...]
    stderr: dict[str, float]
    covariance: np.ndarray
    correlation: np.ndarray
    chi2: float
    dof: int
    redchi: float
    log_likelihood: float
    success: bool
    message: str
    nfev: int
    at_bound: dict[str, str] = field(default_factory=dict)
    insensitive: list[str] = field(default_factory=list)
    degenerate: list[list[str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    gaussian_priors: tuple[str, ...] = ()
    table_error: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """JSON form (NaN written as null by the caller)."""
        return {
            "values": self.values,
            "free": list(self.free),
            "stderr": self.stderr,
            "covariance": self.covariance.tolist(),
            "correlation": self.correlation.tolist(),
            "chi2": self.chi2,
            "dof": self.dof,
            "redchi": self.redchi,
            "log_likelihood": self.log_likelihood,
            "success": self.success,
            "message": self.message,
            "nfev": self.nfev,
            "at_bound": self.at_bound,
            "insensitive": self.insensitive,
            "degenerate": self.degenerate,
            "warnings": self.warnings,
            "gaussian_priors": list(self.gaussian_priors),
            "table_error": self.table_error,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "LeastSquaresResult":
        """Inverse of :meth:`to_dict`."""
        kwargs = dict(data)
        kwargs["free"] = tuple(kwargs["free"])
        for key in ("covariance", "correlation"):
            kwargs[key] = np.array(
                [[np.nan if x is None else x for x in row] for row in kwargs[key]], dtype=float
            ).reshape(len(kwargs["free"]), len(kwargs["free"]))
        kwargs["stderr"] = {k: (math.nan if v is None else v) for k, v in kwargs["stderr"].items()}
        kwargs["gaussian_priors"] = tuple(kwargs.get("gaussian_priors", ()))
        kwargs["table_error"] = math.nan if kwargs.get("table_error") is None else float(kwargs["table_error"])
        return cls(**kwargs)


def _optimiser_bounds(problem: FitProblem, names: Sequence[str],
                      priors: Mapping[str, Any] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`optimiser_bounds` narrowed to each prior's support: a fit given
    ``sigma ~ uniform(10, 45)`` looks for its optimum there, as the sampler does.

    Raises
    ------
    ValueError
        A prior's support outside the parameter's physical range.
    """
    lower, upper = optimiser_bounds([problem.spec(name) for name in names])
    for k, name in enumerate(names):
        prior = (priors or {}).get(name)
        if prior is None:
            continue
        lower[k], upper[k] = max(lower[k], prior.lower), min(upper[k], prior.upper)
        if not lower[k] < upper[k]:
            lo, hi = problem.spec(name).bounds
            raise ValueError(f"the prior of {name}, {prior}, leaves nothing of its physical range [{lo:g}, {hi:g}]")
    return lower, upper


def optimiser_bounds(specs: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """The optimiser's bounds of parameters ``specs``: their physical range, an open end
    1e-9 of the range inside (the one rule of the single and the batched least squares)."""
    lower, upper = [], []
    for spec in specs:
        lo, hi = spec.bounds
        width = hi - lo if math.isfinite(hi - lo) else 1.0
        # Open bounds are excluded from the physical range: stay a hair inside them.
        lower.append(lo + 1e-9 * width if spec.open_lower and math.isfinite(lo) else lo)
        upper.append(hi - 1e-9 * width if spec.open_upper and math.isfinite(hi) else hi)
    return np.array(lower), np.array(upper)


def _characteristic_scale(problem: FitProblem, name: str, value: float) -> float:
    lo, hi = problem.spec(name).bounds
    if math.isfinite(hi - lo):
        return hi - lo
    return max(abs(value), 1e-12)


def jacobian_diagnostics(
    jacobian: np.ndarray, names: Sequence[str], scales: Sequence[float]
) -> tuple[np.ndarray, list[str], list[list[str]]]:
    """Covariance, insensitive parameters and degenerate groups from a weighted Jacobian.

    Parameters
    ----------
    jacobian : ndarray, shape (n, k)
        d(weighted residual)/d(parameter).
    names : sequence of str
        Parameter names (columns).
    scales : sequence of float
        Characteristic scale of each parameter (its physical range), used to compare
        columns on an equal footing.

    Returns
    -------
    covariance : ndarray, shape (k, k)
        (J^T J)^-1 on the well-determined subspace; NaN rows/columns for parameters that
        are insensitive or part of a degenerate group.
    insensitive : list of str
    degenerate : list of list of str
    """
    scales = np.asarray(scales, float)
    scaled = jacobian * scales
    norms = np.linalg.norm(scaled, axis=0)
    largest = float(norms.max()) if norms.size else 0.0
    insensitive_mask = norms <= _DEGENERATE_RCOND * largest if largest > 0 else np.ones(len(names), bool)
    insensitive = [n for n, bad in zip(names, insensitive_mask) if bad]
    keep = ~insensitive_mask
    covariance = np.full((len(names), len(names)), np.nan)
    degenerate: list[list[str]] = []
    undetermined = insensitive_mask.copy()
    if keep.any():
        sub = scaled[:, keep]
        _, singular, vt = np.linalg.svd(sub, full_matrices=False)
        null = singular <= _DEGENERATE_RCOND * singular[0]
        kept_names = [n for n, k in zip(names, keep) if k]
        kept_index = np.flatnonzero(keep)
        for vector in vt[null]:
            group = [kept_names[j] for j in np.flatnonzero(np.abs(vector) > _NULL_COMPONENT)]
            if group:
                degenerate.append(group)
                undetermined[kept_index[np.abs(vector) > _NULL_COMPONENT]] = True
        inverse = (vt[~null].T / singular[~null] ** 2) @ vt[~null]
        scaled_cov = inverse * np.outer(scales[keep], scales[keep])  # J = J_scaled / s
        covariance[np.ix_(kept_index, kept_index)] = scaled_cov
    covariance[undetermined, :] = np.nan
    covariance[:, undetermined] = np.nan
    return covariance, insensitive, degenerate


def _correlation(covariance: np.ndarray) -> np.ndarray:
    sd = np.sqrt(np.abs(np.diag(covariance)))
    with np.errstate(invalid="ignore", divide="ignore"):  # NaN rows of undetermined parameters
        return covariance / np.outer(sd, sd)


def _start_points(problem: FitProblem, start: Mapping[str, float] | None, n_starts: int, rng,
                  priors: Mapping[str, Any] | None = None) -> list[np.ndarray]:
    names = [n for n in problem.free if n not in (problem.noise_parameter, "scale")]
    lower, upper = _optimiser_bounds(problem, names, priors)
    first = []
    for name, lo, hi in zip(names, lower, upper):
        value = float((start or {}).get(name, problem.spec(name).default))
        width = hi - lo if math.isfinite(hi - lo) else max(abs(value), 1.0)
        # least_squares needs a strictly feasible start: keep 1e-3 of the range inside.
        first.append(min(max(value, lo + 1e-3 * width), hi - 1e-3 * width))
    points = [np.array(first)]
    for _ in range(max(n_starts - 1, 0)):
        points.append(np.array([_random_start(lo, hi, centre, rng) for lo, hi, centre in zip(lower, upper, first)]))
    return [_with_nuisances(problem, names, p, start) for p in points]


def _random_start(lo: float, hi: float, centre: float, rng) -> float:
    """A random starting value strictly inside (lo, hi), given a first start ``centre`` inside.

    Uniform over a finite range (1e-3 of it kept clear of each bound). Over a half-open
    range the first start's distance from the finite bound is scaled by a log-normal
    factor, so that a start never crosses the bound (a refractive index on (1, inf) starts
    above 1, not at 1.5 times a random factor); over the whole line, log-normal about a
    positive start, normal about another.

    >>> rng = np.random.default_rng(0)
    >>> all(_random_start(1.0, math.inf, 1.5, rng) > 1.0 for _ in range(1000))
    True
    """
    if math.isfinite(lo) and math.isfinite(hi):
        return float(rng.uniform(lo + 1e-3 * (hi - lo), hi - 1e-3 * (hi - lo)))
    z = float(rng.normal(0.0, 1.0))
    if math.isfinite(lo):
        return lo + (centre - lo) * math.exp(z)
    if math.isfinite(hi):
        return hi - (hi - centre) * math.exp(z)
    return centre * math.exp(z) if centre > 0 else centre + z


def _with_nuisances(problem: FitProblem, names, point, start) -> np.ndarray:
    values = dict(problem.fixed)
    values.update(zip(names, point))
    if "scale" in problem.free:
        given = (start or {}).get("scale")
        values["scale"] = float(given) if given is not None else problem.optimal_scale(values)
    if problem.noise_parameter in problem.free:
        values[problem.noise_parameter] = 0.0
    return np.array([values[n] for n in problem.free])


def _best_jitter(problem: FitProblem, vector: np.ndarray) -> float:
    """Maximum-likelihood extra noise (``jitter`` or ``rel_jitter``) with the other
    parameters held at ``vector``."""
    j = problem.free.index(problem.noise_parameter)
    upper = problem.spec(problem.noise_parameter).bounds[1]

    def negative_log_likelihood(jitter: float) -> float:
        trial = vector.copy()
        trial[j] = jitter
        return -problem.log_likelihood(trial)

    from scipy import optimize  # loaded where a fit runs, not with the results

    found = optimize.minimize_scalar(negative_log_likelihood, bounds=(0.0, upper), method="bounded")
    return float(found.x) if negative_log_likelihood(found.x) < negative_log_likelihood(0.0) else 0.0


def _finite(residuals: np.ndarray) -> np.ndarray:
    """Residuals with undefined values (normalised data of a black sample) replaced by a
    large finite one, which least squares moves away from (it cannot take NaN)."""
    return np.where(np.isfinite(residuals), residuals, 1e10)


def _forward_steps(x: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Forward-difference steps of a least-squares Jacobian at ``x`` inside [lower, upper].

    scipy's ``2-point`` rule (``least_squares``' default): ``sqrt(eps) max(1, |x|)`` with
    the sign of ``x`` (+ at 0), turned back where it would leave the bounds and the other
    side has room, else the larger room; each step is the representable difference
    ``(x + h) - x``.
    """
    h = np.sqrt(np.finfo(float).eps) * np.where(x >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))
    h = (x + h) - x
    outside = (x + h < lower) | (x + h > upper)
    room_below, room_above = x - lower, upper - x
    fits = np.abs(h) <= np.maximum(room_below, room_above)
    h = np.where(outside & fits, -h, h)
    h = np.where(~fits, np.where(room_above >= room_below, room_above, -room_below), h)
    return h


def _whitened(problem: FitProblem, vector: np.ndarray) -> np.ndarray:
    """Residuals whitened by the total uncertainty (the extra noise at its value in ``vector``,
    or held fixed)."""
    if not problem.jitter:
        return problem.residuals(vector)
    values, predicted = problem._predict_vector(vector)
    difference = predicted - problem.dataset.value
    if not np.all(np.isfinite(difference)):
        return np.full(difference.shape, np.nan)
    return problem.whiten(difference, problem.extra_variance(values, predicted))[0]


def _with_extra_noise(problem: FitProblem, solve, found, vector: np.ndarray, index: list[int], rounds: int = 8):
    """Alternate the extra noise's maximum-likelihood value and the model parameters' least
    squares under the total uncertainty, until the noise changes by < 0.1 %: the joint
    maximum of the likelihood (for relative noise, up to its log-determinant's slope in the
    model parameters).

    Returns
    -------
    found : scipy OptimizeResult
        The last least-squares solution (its Jacobian is that of the total uncertainty).
    vector : numpy.ndarray
        Every free parameter.
    calls : int
        Model evaluations spent.
    """
    j = problem.free.index(problem.noise_parameter)
    calls = 0
    vector = vector.copy()
    vector[j] = _best_jitter(problem, vector)
    for _ in range(rounds):
        previous = vector[j]
        refined = solve(vector, vector[index])
        if refined is None:
            break
        calls += int(refined.nfev)
        found = refined
        vector[index] = refined.x
        vector[j] = _best_jitter(problem, vector)
        if abs(vector[j] - previous) <= 1e-3 * max(abs(previous), 1e-300):
            break
    return found, vector, calls


class _Heartbeat:
    """Logs a slow least-squares fit's progress (logger ``gonio.fitting``, INFO) every
    :data:`HEARTBEAT_SECONDS`: the start, the model evaluations and the time so far. A fit
    of the exact models can take minutes; ``gonio fit`` prints these lines."""

    def __init__(self, model: str, starts: int):
        self.model, self.starts, self.start, self.calls = model, starts, 0, 0
        self.begun = self.last = time.monotonic()

    def beat(self) -> None:
        self.calls += 1
        now = time.monotonic()
        if now - self.last >= HEARTBEAT_SECONDS:
            self.last = now
            _log.info("least squares of %s: start %d of %d, %d model evaluations, %.0f s", self.model,
                      self.start, self.starts, self.calls, now - self.begun)


def fit_least_squares(
    problem: FitProblem,
    start: Mapping[str, float] | None = None,
    n_starts: int = 6,
    seed: int | None = 0,
    priors: Mapping[str, Any] | None = None,
) -> LeastSquaresResult:
    """Weighted least-squares fit within the physical bounds.

    Parameters
    ----------
    problem : FitProblem
        Model, data and fixed parameters.
    start : mapping, optional
        Starting values (default: the parameters' defaults).
    n_starts : int
        Number of starting points: ``start`` plus ``n_starts - 1`` drawn uniformly within the
        bounds (for a bound on one side only, the start's distance from it scaled
        log-normally; log-normally around the start for unbounded parameters).  The lowest
        chi-square wins.
    seed : int, optional
        Seed of the random starting points.
    priors : mapping of Prior, optional
        Priors of free parameters. Gaussian ones (:class:`~gonio.fitting.priors.Normal`,
        e.g. the calibration's prior on ``scale``) add the residual ``(x - mean) / sd``, so
        the fit is the posterior mode under the same likelihood and priors the sampler
        uses; every prior restricts the range to its support, as the physical bounds do
        (``sigma ~ uniform(10, 45)``: the optimum is sought between 10 and 45 deg).

    Returns
    -------
    LeastSquaresResult

    Examples
    --------
    >>> import numpy as np, gonio
    >>> from gonio.fitting import Dataset, FitProblem
    >>> tr = np.arange(0, 80, 10.0)
    >>> truth = gonio.brdf("minnaert", 30, 0, tr, 0, rho=0.6, k=0.7)
    >>> data = Dataset(30, 0, tr, 0, truth, 0.001)
    >>> fit = fit_least_squares(FitProblem("minnaert", data))
    >>> round(fit.values["k"], 3), round(fit.values["rho"], 3)
    (0.7, 0.6)
    """
    from .priors import Normal

    rng = np.random.default_rng(seed)
    free = problem.free
    optimised = [n for n in free if n != problem.noise_parameter]
    lower, upper = _optimiser_bounds(problem, optimised, priors)
    index = [free.index(n) for n in optimised]
    gaussian = [(optimised.index(n), p.mean, p.sd) for n, p in (priors or {}).items()
                if isinstance(p, Normal) and n in optimised]
    prior_at = np.array([k for k, _, _ in gaussian], int)
    prior_mean = np.array([m for _, m, _ in gaussian], float)
    prior_sd = np.array([s for _, _, s in gaussian], float)
    best = None
    nfev = 0
    heartbeat = _Heartbeat(problem.base_model.name, n_starts)

    def solve(template: np.ndarray, x0: np.ndarray):
        """Least squares of the model parameters, the others held at ``template``."""

        def with_priors(r: np.ndarray, x: np.ndarray) -> np.ndarray:
            """The Gaussian priors' residuals (x - mean) / sd appended (rows: one per x row)."""
            return np.concatenate([r, (x[..., prior_at] - prior_mean) / prior_sd], axis=-1) if gaussian else r

        def residuals(x: np.ndarray) -> np.ndarray:
            heartbeat.beat()
            vector = template.copy()
            vector[index] = x
            return _finite(with_priors(_whitened(problem, vector), x))

        def jacobian(x: np.ndarray) -> np.ndarray:
            """Forward differences of :func:`residuals`, the point and every step in one
            batch (all through the same whitening, so that its rounding cancels)."""
            heartbeat.beat()
            x = np.asarray(x, float)
            steps = _forward_steps(x, lower, upper)
            vectors = np.repeat(template[None, :], len(x) + 1, axis=0)
            vectors[:, index] = x
            vectors[1:, index] += np.diag(steps)
            rows = _finite(with_priors(problem.residuals_batch(vectors), vectors[:, index]))
            return ((rows[1:] - rows[0]) / steps[:, None]).T

        if not np.all(np.isfinite(residuals(x0))):
            return None
        from scipy import optimize

        jac = jacobian if not problem.jitter else "2-point"
        return optimize.least_squares(residuals, x0, jac=jac, bounds=(lower, upper), x_scale="jac", method="trf")

    for point in _start_points(problem, start, n_starts, rng, priors):
        heartbeat.start += 1
        found = solve(point, np.clip(point[index], lower, upper))
        if found is None:
            continue
        nfev += int(found.nfev)
        if best is None or found.cost < best[0].cost:
            best = (found, point)
    if best is None:  # pragma: no cover - every start invalid
        raise ValueError(f"model {problem.base_model.name!r}: no valid starting point for the least-squares fit")
    found, template = best
    vector = template.copy()
    vector[index] = found.x
    if problem.noise_parameter in free:
        found, vector, calls = _with_extra_noise(problem, solve, found, vector, index)
        nfev += calls
    values = problem.values(vector)

    scales = [_characteristic_scale(problem, n, values[n]) for n in optimised]
    covariance_opt, insensitive, degenerate = jacobian_diagnostics(found.jac, optimised, scales)
    covariance = np.full((len(free), len(free)), np.nan)
    covariance[np.ix_(index, index)] = covariance_opt
    stderr = {n: float(math.sqrt(covariance[i, i])) if np.isfinite(covariance[i, i]) else math.nan for i, n in enumerate(free)}

    at_bound: dict[str, str] = {}
    for n in optimised:
        lo, hi = problem.spec(n).bounds
        scale = _characteristic_scale(problem, n, values[n])
        if math.isfinite(lo) and values[n] - lo <= _AT_BOUND * scale:
            at_bound[n] = "lower"
        elif math.isfinite(hi) and hi - values[n] <= _AT_BOUND * scale:
            at_bound[n] = "upper"

    chi2 = problem.chi_square(values)
    dof = problem.n_informative - len(free)
    warnings = _describe(problem, values, stderr, at_bound, insensitive, degenerate, dof)
    return LeastSquaresResult(
        values=values,
        free=free,
        stderr=stderr,
        covariance=covariance,
        correlation=_correlation(covariance),
        chi2=chi2,
        dof=dof,
        redchi=chi2 / dof if dof > 0 else math.nan,
        log_likelihood=problem.log_likelihood(vector),
        success=bool(found.success),
        message=str(found.message),
        nfev=nfev,
        at_bound=at_bound,
        insensitive=insensitive,
        degenerate=degenerate,
        warnings=warnings,
        gaussian_priors=tuple(optimised[k] for k, _, _ in gaussian),
    )


def _with_unit(value: str, unit: str) -> str:
    """``value unit``, leaving out the dimensionless unit '-'."""
    return value if unit in ("-", "") else f"{value} {unit}"


def _describe(problem, values, stderr, at_bound, insensitive, degenerate, dof) -> list[str]:
    quantity = problem.dataset.quantity
    notes = []
    for name in insensitive:
        why = ""
        if quantity == "normalised_radiance" and name in problem.model.linear_in:
            why = " (normalised radiance divides out the overall level, so an albedo-like factor cancels)"
        notes.append(
            f"{name}: the data do not depend on this parameter at the best fit{why}; "
            f"fix it (--fix {name}=VALUE) or measure a quantity that constrains it"
        )
    for group in degenerate:
        if len(group) == 1:  # a null direction along one parameter, the others' parts below _NULL_COMPONENT
            notes.append(
                f"{group[0]} is not determined: at the best fit its effect is matched by small changes of the "
                f"other parameters; fix it (--fix {group[0]}=VALUE) or measure where it matters"
            )
            continue
        why = ""
        if "scale" in group:
            why = " (relative radiance has a free scale, and an albedo-like factor only multiplies it)"
        notes.append(
            f"{' and '.join(group)} are degenerate: only a combination of them is determined by the "
            f"data{why}; fix all but one of them"
        )
    for name, side in at_bound.items():
        lo, hi = problem.spec(name).bounds
        notes.append(
            f"{name} = {values[name]:g} lies at the {side} bound of its physical range "
            f"{_with_unit(f'[{lo:g}, {hi:g}]', problem.spec(name).unit)}; its uncertainty is one-sided "
            "(quote a limit, see the posterior percentiles)"
        )
    for name, error in stderr.items():
        lo, hi = problem.spec(name).bounds
        if math.isfinite(error) and math.isfinite(hi - lo) and error > (hi - lo):
            notes.append(
                f"{name} is not constrained by the data: its standard error {error:.3g} exceeds "
                f"its physical range [{lo:g}, {hi:g}] (low signal or too few geometries)"
            )
    if dof <= 0:
        notes.append(f"{problem.n_informative} informative measurements for {len(problem.free)} free parameters: "
                     "no degrees of freedom left")
    return notes
