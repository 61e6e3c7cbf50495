"""Many independent least-squares fits at once: one model, one geometry, M datasets.

Imaging data give one dataset per pixel (or per sample): the same N lighting and viewing
geometries, M sets of values. :func:`least_squares_many` fits a registered model to all of
them together, a batched Levenberg-Marquardt whose every step evaluates the model for all
M parameter vectors in one call of the fixed-geometry path (:meth:`gonio.models.Model.at`,
parameters as (M, 1) columns).

What it computes for every fit is what :func:`gonio.fitting.fit_least_squares` computes for
one dataset of BRDF values with independent errors: the minimum of
chi^2 = sum(((model - value) / sigma)^2) within the parameters' physical bounds, and the
covariance (J^T J)^-1 of the weighted Jacobian J at the optimum, *not* rescaled by the
reduced chi-square (the uncertainties are taken as measured), with the same rule for
undetermined directions (:func:`gonio.fitting.least_squares.jacobian_diagnostics`: NaN for
insensitive or degenerate parameters). tests/fitting/test_least_squares_many.py checks the
two against each other.

Algorithm
---------
* **Variable projection.** When exactly one free parameter is one the model is linear in
  (``Model.linear_in``: ``rho`` of ``lambert``, ``oren-nayar-qualitative``, ``minnaert``),
  it is solved for exactly at every step: with the model affine in it,
  f = f0 + p g, the best p for the other parameters is
  clip(sum(w^2 g (y - f0)) / sum(w^2 g^2), bounds) (exact for one bounded parameter,
  since chi^2 is a parabola in p). The iteration then runs over the other parameters
  only; a model with no other free parameter is solved in one step.
* **Levenberg-Marquardt** on the remaining parameters, all fits at once: a damping
  factor per fit (times 0.3 after a step that lowers chi^2, times 10 after one that does
  not), Marquardt's scaling by the largest diagonal of J^T J seen so far (MINPACK), the
  Jacobian by forward differences (step sqrt(eps) max(1, |x|), as scipy's ``2-point``,
  taken backwards at an upper bound). Fits that have converged drop out of the batch.
* **Bounds** by step-back: a step that would cross a bound of the physical range (open
  bounds 1e-9 of the range inside, as in the single fit) goes 99.5 % of the way to it
  (scipy's trust-region-reflective step back), so the iterates stay strictly inside and
  approach a bound geometrically. A parameter stationary at its bound (the Oren-Nayar
  ``sigma`` at 0, where the BRDF goes as sigma^2) is thus never stranded there by a
  clipped step. The projected linear parameter is clipped exactly (its optimum under a
  bound is the clipped value).
* **Convergence** of each fit, with scipy's meanings of the tolerances: a step that lowers
  chi^2/2 by less than ``ftol`` of itself, a step shorter than ``xtol`` (relative, in
  units of each parameter's range), or every Jacobian column at a cosine below ``gtol`` with
  the residual vector (MINPACK's test). A fit that reaches ``max_iterations`` first is
  flagged ``converged=False`` with the reason; the batch goes on.
* **Starts**: ``n_starts`` starting points per fit (the given start, then points drawn
  as the single fit draws them, :func:`gonio.fitting.least_squares._random_start`); the
  lowest chi^2 wins.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from gonio import models
from gonio.models import Model, Param

from .least_squares import _AT_BOUND, _DEGENERATE_RCOND, _random_start, jacobian_diagnostics, optimiser_bounds
from .problem import BATCH_ELEMENTS

__all__ = ["ManyLeastSquaresResult", "least_squares_many"]

#: Initial damping factor of every fit [-] (relative to the scaled diagonal of J^T J).
_INITIAL_DAMPING = 1e-3
#: A fit whose damping exceeds this has no step left that lowers chi^2.
_MAX_DAMPING = 1e16
_EPS_STEP = math.sqrt(np.finfo(float).eps)
#: Fraction of the way to a bound a step that would cross it goes (scipy's trust-region
#: reflective step back, theta = 0.995).
_STEP_BACK = 0.995


@dataclass
class ManyLeastSquaresResult:
    """Outcome of :func:`least_squares_many`: M fits of P free parameters.

    Attributes
    ----------
    model : str
        Registered model name.
    free : tuple of str
        Names of the fitted parameters (columns of ``values``, ``stderr``).
    values : numpy.ndarray, shape (M, P)
        Best-fit value of each free parameter, in its unit (``Model.params``).
    stderr : numpy.ndarray, shape (M, P)
        Standard error of each free parameter: sqrt of the diagonal of (J^T J)^-1 of the
        weighted Jacobian (gonio's convention: not rescaled by the reduced chi-square),
        NaN where undetermined. With ``sigma=None`` (no stated uncertainties) rescaled by
        ``sqrt(redchi)``, see ``noise_from_scatter``.
    covariance : numpy.ndarray, shape (M, P, P)
        Of the free parameters (NaN rows for undetermined ones).
    chi2 : numpy.ndarray, shape (M,)
        Chi-square at the best fit [-].
    dof : int
        Degrees of freedom N - P.
    converged : numpy.ndarray of bool, shape (M,)
        Whether the fit met a convergence criterion.
    reason : numpy.ndarray of str, shape (M,)
        Why a fit did not converge ("" where it did).
    iterations : numpy.ndarray of int, shape (M,)
        Levenberg-Marquardt iterations of the winning start.
    at_bound : numpy.ndarray of int, shape (M, P)
        -1 at the lower bound of the physical range, +1 at the upper one, 0 inside (within
        1e-6 of the range, as :class:`~gonio.fitting.LeastSquaresResult` ``at_bound``).
    fixed : dict
        The fixed parameters: floats, or arrays of shape (M,).
    noise_from_scatter : bool
        True when no uncertainties were given: unit weights, and ``stderr`` and
        ``covariance`` scaled by the reduced chi-square (the residual scatter estimates the
        noise, as scipy's ``curve_fit`` does without ``sigma``).
    """

    model: str
    free: tuple[str, ...]
    values: np.ndarray
    stderr: np.ndarray
    covariance: np.ndarray
    chi2: np.ndarray
    dof: int
    converged: np.ndarray
    reason: np.ndarray
    iterations: np.ndarray
    at_bound: np.ndarray
    fixed: dict[str, Any]
    noise_from_scatter: bool = False

    @property
    def redchi(self) -> np.ndarray:
        """Reduced chi-square chi2 / dof, shape (M,) (NaN without degrees of freedom)."""
        return self.chi2 / self.dof if self.dof > 0 else np.full(self.chi2.shape, np.nan)

    def value(self, name: str) -> np.ndarray:
        """Best-fit values of parameter ``name``, shape (M,) (fixed ones broadcast)."""
        if name in self.free:
            return self.values[:, self.free.index(name)]
        if name in self.fixed:
            return np.broadcast_to(np.asarray(self.fixed[name], float), self.chi2.shape)
        raise ValueError(f"{name!r} is neither a free parameter {list(self.free)} nor fixed {list(self.fixed)}")


@dataclass
class _Setup:
    """Checked inputs: the frozen model, the data, free and fixed parameters."""

    model: Model
    frozen: Any
    free: tuple[str, ...]
    specs: tuple[Param, ...]
    lower: np.ndarray
    upper: np.ndarray
    fixed: dict[str, Any]
    value: np.ndarray
    weight: np.ndarray
    linear: str | None
    affine: bool

    def weights(self, rows: np.ndarray) -> np.ndarray:
        """1 / sigma of the data rows ``rows``, broadcasting to (len(rows), N)."""
        return self.weight if self.weight.shape[0] == 1 else self.weight[rows]


def _scales(specs: tuple[Param, ...], values: np.ndarray) -> np.ndarray:
    """Characteristic scale of each parameter: its range, or |value| when unbounded; shape
    of ``values`` (M, P)."""
    out = np.empty(values.shape)
    for k, spec in enumerate(specs):
        lo, hi = spec.bounds
        out[:, k] = hi - lo if math.isfinite(hi - lo) else np.maximum(np.abs(values[:, k]), 1e-12)
    return out


def _finite_array(name: str, value: Any, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """``value`` as a finite float array (broadcast to ``shape``), or ``ValueError`` naming it."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers, got {value!r}") from None
    if shape is not None:
        try:
            array = np.broadcast_to(array, shape)
        except ValueError:
            raise ValueError(f"{name} has shape {array.shape}, which does not broadcast to {shape}") from None
    bad = ~np.isfinite(array)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"{name}{list(index)} = {float(array[index])} is not finite; {int(bad.sum())} of "
                         f"{array.size} values are not (mask them out before fitting)")
    return array


def _setup(model, geometry, values, sigma, fixed, options) -> _Setup:
    """Check every input and freeze the model at the geometry."""
    model = models.get(model) if isinstance(model, str) else model
    if not isinstance(model, Model):
        raise ValueError(f"model must be a registered model name or a gonio Model, got {model!r}")
    angles = [_finite_array(name, a) for name, a in zip(("theta_i", "phi_i", "theta_r", "phi_r"), geometry)]
    try:
        angles = [np.ravel(a) for a in np.broadcast_arrays(*angles)]
    except ValueError:
        raise ValueError(f"the four angles do not broadcast together: shapes {[np.shape(a) for a in geometry]}") from None
    value = np.asarray(values, dtype=float)
    if value.ndim != 2:
        raise ValueError(f"values must have shape (M fits, N geometries), got shape {value.shape} "
                         "(one dataset: values[None, :])")
    if value.shape[1] != angles[0].size:
        raise ValueError(f"values has {value.shape[1]} columns (geometries) but the angles give "
                         f"{angles[0].size} geometries; they must match")
    value = _finite_array("values", value)
    weight = np.ones((1, 1))
    if sigma is not None:
        _finite_array("sigma", sigma, value.shape)  # names a bad shape or value
        uncertainty = np.asarray(sigma, float)
        uncertainty = uncertainty.reshape((1,) * (2 - uncertainty.ndim) + uncertainty.shape)  # kept unbroadcast
        if not np.all(uncertainty > 0):
            index = tuple(int(i) for i in np.argwhere(np.broadcast_to(uncertainty, value.shape) <= 0)[0])
            raise ValueError(f"sigma{list(index)} = {float(np.broadcast_to(uncertainty, value.shape)[index]):g}: "
                             "uncertainties must be > 0 (one standard deviation, in the unit of values)")
        weight = 1.0 / uncertainty
    checked_fixed = _checked_fixed(model, fixed, value.shape[0])
    free = tuple(n for n in model.param_names if n not in checked_fixed)
    if not free:
        raise ValueError(f"every parameter of {model.name!r} is fixed; nothing to fit")
    specs = tuple(model.param(n) for n in free)
    lower, upper = optimiser_bounds(specs)
    frozen = model.at(*angles, **dict(options or {}))
    linear_free = [n for n in free if n in model.linear_in]
    linear = linear_free[0] if len(linear_free) == 1 else None
    affine = linear is not None and any(n != linear for n in model.linear_in)
    return _Setup(model, frozen, free, specs, lower, upper, checked_fixed, value, weight, linear, affine)


def _checked_fixed(model: Model, fixed: Mapping[str, Any] | None, m: int) -> dict[str, Any]:
    """Fixed values checked against their ranges: floats, or arrays of shape (M,)."""
    out: dict[str, Any] = {}
    for name, value in dict(fixed or {}).items():
        spec = model.param(name)  # ValueError naming the model's parameters
        checked = spec.check(value, model.name)
        if isinstance(checked, np.ndarray):
            if checked.shape != (m,):
                raise ValueError(f"fixed {name!r} has shape {checked.shape}; give one value or one per fit, ({m},)")
            checked = checked.copy()
        out[name] = checked
    return out


def _starts(setup: _Setup, start: Mapping[str, Any] | None, n_starts: int, seed: int | None) -> np.ndarray:
    """Starting points, shape (n_starts, M, P): the given start (default: the defaults),
    kept 1e-3 of the range inside the bounds, then random points drawn as the single fit
    draws them."""
    m = setup.value.shape[0]
    unknown = [n for n in (start or {}) if n not in setup.free]
    if unknown:
        raise ValueError(f"start names {unknown} that are not free parameters of {setup.model.name!r}: "
                         f"{list(setup.free)}")
    first = np.empty((m, len(setup.free)))
    for k, spec in enumerate(setup.specs):
        given = spec.check((start or {}).get(spec.name, spec.default), setup.model.name)
        lo, hi = setup.lower[k], setup.upper[k]
        width = hi - lo if math.isfinite(hi - lo) else np.maximum(np.abs(given), 1.0)
        first[:, k] = np.clip(np.broadcast_to(given, (m,)), lo + 1e-3 * width, hi - 1e-3 * width)
    rng = np.random.default_rng(seed)
    points = [first]
    for _ in range(max(n_starts - 1, 0)):
        drawn = [_random_start(lo, hi, float(np.mean(first[:, k])), rng)
                 for k, (lo, hi) in enumerate(zip(setup.lower, setup.upper))]
        points.append(np.broadcast_to(np.array(drawn), first.shape).copy())
    return np.stack(points)


class _Residuals:
    """Weighted residuals of the fits' rows ``rows`` at parameters ``x`` (free order), in one
    model call; with a projected linear parameter, ``x``'s column of it is replaced by its
    best value."""

    def __init__(self, setup: _Setup):
        self.setup = setup
        self.evaluations = 0
        self.linear_column = setup.free.index(setup.linear) if setup.linear else None

    def _params(self, rows: np.ndarray, x: np.ndarray) -> dict[str, Any]:
        params = {p.name: p.default for p in self.setup.model.params}
        for name, value in self.setup.fixed.items():
            params[name] = value[rows, None] if isinstance(value, np.ndarray) else value
        for k, name in enumerate(self.setup.free):
            params[name] = x[:, k:k + 1].copy()  # copies: models may work in place
        return params

    def predict(self, rows: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The model at ``x`` (shape (m, P)) for the data rows ``rows``: shape (m, N)."""
        self.evaluations += 1
        out = self.setup.frozen.unchecked(**self._params(rows, x))
        return np.broadcast_to(out, (len(rows), self.setup.value.shape[1]))

    def __call__(self, rows: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(weighted residuals (m, N), ``x`` with the projected linear column filled in)."""
        weight, value = self.setup.weights(rows), self.setup.value[rows]
        if self.linear_column is None:
            return (self.predict(rows, x) - value) * weight, x
        x = x.copy()
        k = self.linear_column
        x[:, k] = 0.0
        offset = self.predict(rows, x) if self.setup.affine else 0.0
        x[:, k] = 1.0
        shape = self.predict(rows, x) - offset
        target = (value - offset) * weight
        shape *= weight
        numerator = np.einsum("mn,mn->m", shape, target)
        denominator = np.einsum("mn,mn->m", shape, shape)
        with np.errstate(invalid="ignore", divide="ignore"):
            best = np.where(denominator > 0, numerator / denominator, self.setup.specs[k].default)
        x[:, k] = np.clip(best, self.setup.lower[k], self.setup.upper[k])
        return shape * x[:, k:k + 1] - target, x


def _jacobian(residuals: _Residuals, rows: np.ndarray, x: np.ndarray, r: np.ndarray, columns: list[int],
              upper: np.ndarray) -> np.ndarray:
    """Forward-difference Jacobian of the residuals in ``columns``, shape (m, N, len(columns))."""
    out = np.empty(r.shape + (len(columns),))
    for j, k in enumerate(columns):
        step = _EPS_STEP * np.maximum(1.0, np.abs(x[:, k]))
        step = np.where(x[:, k] + step > upper[k], -step, step)  # stay inside the range
        moved = x.copy()
        moved[:, k] += step
        step = moved[:, k] - x[:, k]  # the step actually taken (rounding)
        out[..., j] = (residuals(rows, moved)[0] - r) / step[:, None]
    return out


class _Iterations:
    """The state of a batch of Levenberg-Marquardt fits of the data rows ``rows`` (the same
    row may appear once per start): values, residuals, Jacobians, damping, outcome."""

    def __init__(self, residuals: _Residuals, rows: np.ndarray, x: np.ndarray, tolerances: tuple[float, float, float]):
        setup = residuals.setup
        self.residuals, self.rows, self.tolerances = residuals, rows, tolerances
        self.columns = [k for k in range(len(setup.free)) if k != residuals.linear_column]
        self.lower, self.upper = setup.lower[self.columns], setup.upper[self.columns]
        self.width = np.where(np.isfinite(self.upper - self.lower), self.upper - self.lower, 1.0)
        self.r, self.x = residuals(rows, x)
        self.cost = 0.5 * np.einsum("mn,mn->m", self.r, self.r)
        m = len(rows)
        self.converged = np.zeros(m, bool)
        self.reason = np.full(m, "", dtype=object)
        self.iterations = np.zeros(m, int)
        self.reason[~np.isfinite(self.cost)] = "the model's prediction is not finite at the start"
        self.damping = np.full(m, _INITIAL_DAMPING)
        self.diagonal = np.zeros((m, len(self.columns)))
        self.jac = np.zeros(self.r.shape + (len(self.columns),))

    def jacobian(self, fits: np.ndarray) -> None:
        """Recompute the Jacobians of ``fits`` (indices) at their current values."""
        self.jac[fits] = _jacobian(self.residuals, self.rows[fits], self.x[fits], self.r[fits], self.columns,
                                   self.residuals.setup.upper)

    def step(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One damped Gauss-Newton step of the fits ``active``: (done, accepted) masks."""
        ftol, xtol, gtol = self.tolerances
        self.iterations[active] += 1
        jac, cost = self.jac[active], self.cost[active]
        a = np.einsum("mni,mnj->mij", jac, jac)
        g = np.einsum("mni,mn->mi", jac, self.r[active])
        self.diagonal[active] = np.maximum(self.diagonal[active], np.einsum("mii->mi", a))
        scale = np.maximum(self.diagonal[active], 1e-300)
        flat = np.all(np.abs(g) <= gtol * np.sqrt(scale * 2.0 * cost[:, None]), axis=1)  # cosines <= gtol
        xa = self.x[active][:, self.columns]
        trial = self.x[active].copy()
        trial[:, self.columns] = _inside(xa, xa + _damped_step(a, g, scale, self.damping[active]), self.lower, self.upper)
        moved = trial[:, self.columns] - xa
        r_new, trial = self.residuals(self.rows[active], trial)
        cost_new = 0.5 * np.einsum("mn,mn->m", r_new, r_new)
        better = np.isfinite(cost_new) & (cost_new < cost)
        small = np.linalg.norm(moved / self.width, axis=1) <= xtol * (xtol + np.linalg.norm(xa / self.width, axis=1))
        done = flat | small | (better & (cost - cost_new <= ftol * cost))
        accepted = active[better]
        self.x[accepted], self.r[accepted], self.cost[accepted] = trial[better], r_new[better], cost_new[better]
        self.damping[active] = np.where(better, self.damping[active] * 0.3, self.damping[active] * 10.0)
        self.converged[active[done]] = True
        return done, better


def _levenberg_marquardt(residuals: _Residuals, rows: np.ndarray, x: np.ndarray, tolerances: tuple[float, float, float],
                         max_iterations: int) -> _Iterations:
    """Fits of the data rows ``rows`` from ``x`` (m, P), all at once; fits that converge (or
    whose damping runs out) leave the batch."""
    state = _Iterations(residuals, rows, x, tolerances)
    active = np.flatnonzero(np.isfinite(state.cost))
    if not state.columns:  # only a projected linear parameter: solved exactly
        state.converged[active] = True
        return state
    state.jacobian(active)
    for _ in range(max_iterations):
        if active.size == 0:
            break
        done, better = state.step(active)
        accepted = active[better]
        exhausted = ~done & (state.damping[active] > _MAX_DAMPING)
        state.reason[active[exhausted]] = "no step lowers chi-square (damping exhausted)"
        active = active[~done & ~exhausted]
        refresh = np.intersect1d(active, accepted, assume_unique=True)
        if refresh.size:
            state.jacobian(refresh)
    state.reason[active] = f"maximum of {max_iterations} iterations reached"
    return state


def _damped_step(a: np.ndarray, g: np.ndarray, scale: np.ndarray, damping: np.ndarray) -> np.ndarray:
    """Solve (J^T J + lambda D) s = -J^T r for every fit (D the diagonal ``scale``)."""
    system = a + damping[:, None, None] * (scale[:, :, None] * np.eye(a.shape[1]))
    return np.linalg.solve(system, -g[..., None])[..., 0]


def _inside(x: np.ndarray, trial: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``trial``, with every component that would cross a bound taken 99.5 % of the way
    from ``x`` to it instead: iterates stay strictly inside the range."""
    with np.errstate(invalid="ignore"):
        out = np.where(trial < lower, x + _STEP_BACK * (lower - x), trial)
        return np.where(out > upper, x + _STEP_BACK * (upper - x), out)


def _covariance(residuals: _Residuals, rows: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(J^T J)^-1 of all free parameters at ``x``, shape (m, P, P): the SVD rule of
    :func:`~gonio.fitting.least_squares.jacobian_diagnostics`, batched for the fits with a
    well-conditioned Jacobian, that function itself for the others."""
    setup = residuals.setup
    columns = list(range(len(setup.free)))
    r = (residuals.predict(rows, x) - setup.value[rows]) * setup.weights(rows)
    jac = _jacobian(_Plain(residuals), rows, x, r, columns, setup.upper)
    scales = _scales(setup.specs, x)
    scaled = jac * scales[:, None, :]
    _, singular, vt = np.linalg.svd(scaled, full_matrices=False)
    norms = np.linalg.norm(scaled, axis=1)
    healthy = (singular[:, -1] > _DEGENERATE_RCOND * singular[:, 0]) & np.all(
        norms > _DEGENERATE_RCOND * norms.max(axis=1, keepdims=True), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = np.einsum("mki,mk,mkj->mij", vt, 1.0 / singular**2, vt)
    out = inverse * scales[:, :, None] * scales[:, None, :]
    for i in np.flatnonzero(~healthy):
        out[i] = jacobian_diagnostics(jac[i], setup.free, scales[i])[0]
    return out


class _Plain:
    """The residuals without the projection of a linear parameter (every column free)."""

    def __init__(self, residuals: _Residuals):
        self.residuals = residuals

    def __call__(self, rows: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        setup = self.residuals.setup
        return (self.residuals.predict(rows, x) - setup.value[rows]) * setup.weights(rows), x


def _at_bound(setup: _Setup, values: np.ndarray) -> np.ndarray:
    """-1 / +1 / 0 for values at the lower / upper bound / inside (:data:`_AT_BOUND`)."""
    scales = _scales(setup.specs, values)
    lo = np.array([s.bounds[0] for s in setup.specs])
    hi = np.array([s.bounds[1] for s in setup.specs])
    with np.errstate(invalid="ignore"):
        return np.where(values - lo <= _AT_BOUND * scales, -1, np.where(hi - values <= _AT_BOUND * scales, 1, 0))


def _fit_block(residuals: _Residuals, rows: np.ndarray, starts: np.ndarray, tolerances, max_iterations: int):
    """Every start of the fits ``rows``; the lowest chi^2 of each fit wins."""
    n_starts = starts.shape[0]
    tiled = np.tile(rows, n_starts)
    x0 = starts[:, rows].reshape(-1, starts.shape[2])
    state = _levenberg_marquardt(residuals, tiled, x0, tolerances, max_iterations)
    ranked = np.where(np.isfinite(state.cost), state.cost, np.inf).reshape(n_starts, len(rows))
    best = np.argmin(ranked, axis=0) * len(rows) + np.arange(len(rows))
    return state.x[best], 2.0 * state.cost[best], state.converged[best], state.reason[best], state.iterations[best]


def least_squares_many(
    model: str | Model,
    theta_i: Any,
    phi_i: Any,
    theta_r: Any,
    phi_r: Any,
    values: Any,
    sigma: Any = None,
    fixed: Mapping[str, Any] | None = None,
    start: Mapping[str, Any] | None = None,
    options: Mapping[str, Any] | None = None,
    n_starts: int = 1,
    seed: int | None = 0,
    max_iterations: int = 100,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
    gtol: float = 1e-8,
) -> ManyLeastSquaresResult:
    """Weighted least-squares fits of one model to M datasets sharing one geometry.

    Parameters
    ----------
    model : str or Model
        Registered model name (``gonio.models.available()``) or model.
    theta_i, phi_i, theta_r, phi_r : array_like
        The N geometries [deg] every dataset was measured at (broadcast to shape (N,)).
    values : array_like, shape (M, N)
        BRDF values [1/sr]: one row per fit (pixel, sample), one column per geometry.
    sigma : array_like, optional
        One-standard-deviation uncertainties [1/sr], broadcasting to (M, N) (a scalar, one
        per geometry (N,), or one per value). None: unit weights, and the standard errors
        from the residual scatter (``noise_from_scatter``).
    fixed : mapping, optional
        Parameters held fixed: a float, or one value per fit (shape (M,)).
    start : mapping, optional
        Starting values of free parameters: a float or shape (M,) (default: the defaults).
    options : mapping, optional
        Discrete model options (``Model.options``).
    n_starts : int
        Starting points per fit: ``start`` plus ``n_starts - 1`` random ones (``seed``),
        the lowest chi-square wins (the single fit's default is 6).
    seed : int, optional
        Seed of the random starting points.
    max_iterations : int
        Most Levenberg-Marquardt iterations per fit; a fit still going is flagged.
    ftol, xtol, gtol : float
        Convergence tolerances [-] (module docstring).

    Returns
    -------
    ManyLeastSquaresResult

    Raises
    ------
    ValueError
        Unknown model or parameter, values not of shape (M, N) with N the geometries,
        NaN or infinite values, angles or uncertainties, sigma <= 0, fixed or start values
        outside their physical range, or nothing left to fit.

    Notes
    -----
    Each fit minimises the chi-square of :func:`gonio.fitting.fit_least_squares` for a
    BRDF dataset with independent errors and reports its covariance by the same rule;
    the algorithm (batched Levenberg-Marquardt, variable projection of one linear
    parameter, bounds by step-back) is described in the module docstring. Fits are run
    in blocks of at most :data:`gonio.fitting.problem.BATCH_ELEMENTS` values.

    Examples
    --------
    >>> import numpy as np, gonio
    >>> tr = np.arange(0.0, 80.0, 10.0)
    >>> truth = gonio.brdf("oren-nayar-qualitative", 40.0, 0.0, tr, 0.0, rho=[[0.3], [0.7]], sigma=25.0)
    >>> fits = least_squares_many("oren-nayar-qualitative", 40.0, 0.0, tr, 0.0, truth, sigma=1e-3)
    >>> np.round(fits.values, 4).tolist(), fits.converged.tolist()
    ([[0.3, 25.0], [0.7, 25.0]], [True, True])
    """
    setup = _setup(model, (theta_i, phi_i, theta_r, phi_r), values, sigma, fixed, options)
    starts = _starts(setup, start, int(n_starts), seed)
    residuals = _Residuals(setup)
    m, n = setup.value.shape
    tolerances = (ftol, xtol, gtol)
    out_x = np.empty((m, len(setup.free)))
    chi2, iterations = np.empty(m), np.zeros(m, int)
    converged, reason = np.zeros(m, bool), np.full(m, "", dtype=object)
    covariance = np.empty((m, len(setup.free), len(setup.free)))
    block = max(1, BATCH_ELEMENTS // max(n * starts.shape[0], 1))
    for first in range(0, m, block):
        rows = np.arange(first, min(first + block, m))
        x, c, ok, why, its = _fit_block(residuals, rows, starts, tolerances, max_iterations)
        out_x[rows], chi2[rows], converged[rows], reason[rows], iterations[rows] = x, c, ok, why, its
        covariance[rows] = _covariance(residuals, rows, x)
    dof = n - len(setup.free)
    if sigma is None:  # the scatter estimates the noise; without degrees of freedom, nothing does
        covariance *= (chi2 / dof)[:, None, None] if dof > 0 else np.nan
    with np.errstate(invalid="ignore"):
        stderr = np.sqrt(np.einsum("mii->mi", covariance))
    return ManyLeastSquaresResult(
        model=setup.model.name, free=setup.free, values=out_x, stderr=stderr, covariance=covariance, chi2=chi2,
        dof=dof, converged=converged, reason=reason.astype(str), iterations=iterations,
        at_bound=_at_bound(setup, out_x), fixed=setup.fixed, noise_from_scatter=sigma is None)
