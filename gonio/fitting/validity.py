"""Whether an approximate model holds at a fit's own data: its error against the exact model.

Each approximation of the papers has an exact reference in gonio: the functional and
qualitative Oren-Nayar models (eq 30-33, eq 36 and its footnote 11) and the paper's own
numerical evaluation (eq 44, 48-49) approximate the V-cavity model integrated exactly
(``oren-nayar-exact``); Wolff's polynomial Fresnel factor (after eq 7) approximates the
exact Fresnel transmission (eq 2). Where they fail is mapped in docs/validity.md: at
grazing angles the functional model is several times the exact value, and at a real lab's
noise (0.15-0.6 %) its error of a few percent is several standard deviations of the data.

:func:`check` measures the approximation's error at the fit's geometries and optimum,
and what it does to the fit: the linearised shift of the optimum that the difference
``d = approximation - exact`` causes,

    delta = -C J_w^T d_w,

with ``J_w`` the whitened Jacobian of the approximation's predictions, ``d_w`` the
whitened difference and ``C`` the least-squares covariance: the amount by which the
parameters describe the formula's error instead of the sample, in units of their standard
errors. A fit whose parameter moves by more than :data:`BIAS_LIMIT` standard errors, or
that has a value where the formula alone is off by more than :data:`POINT_LIMIT` of its
uncertainties, is flagged with the model to use instead.

Decisions: the functional model is compared with its interreflection weight at the
paper's value 1 (``ir_weight`` scales eq 33's interreflection term; another value is no
longer the paper's approximation), and the qualitative model, which leaves the
interreflection out by design, against the full exact model with it, as
docs/oren-nayar-accuracy.md does. Models whose reference has other parameters (the
Torrance-Sparrow shadowing, the pitted surface's Monte Carlo, the KvD series) are mapped in
docs/validity.md but not checked here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

__all__ = ["BIAS_LIMIT", "POINT_LIMIT", "Reference", "REFERENCES", "ModelValidity", "reference_for", "check",
           "regime_flags"]

#: Largest shift of a parameter, in its standard errors, that an approximation's own error
#: may cause before the fit is flagged [-].
BIAS_LIMIT = 0.5
#: Largest error of the approximation at one value, in that value's uncertainties, before
#: the fit is flagged [-].
POINT_LIMIT = 3.0
#: At most this many values are compared (the most grazing ones and an even sample of the
#: rest), so that a fit of 1e5 values does not evaluate the exact model 1e5 times.
MAX_CHECKED = 4000


@dataclass(frozen=True)
class Reference:
    """The exact model an approximation is checked against.

    Attributes
    ----------
    model : str
        The exact model's registered name.
    options : dict
        Options of the exact model (the approximation's options of the same name carry
        over, :attr:`carried`).
    carried : tuple of str
        Options passed on from the approximation.
    approximation_values : dict
        Parameters of the approximation set for the comparison (e.g. ``ir_weight = 1``).
    advice : str
        What to fit instead.
    """

    model: str
    options: dict[str, Any] = field(default_factory=dict)
    carried: tuple[str, ...] = ()
    approximation_values: dict[str, float] = field(default_factory=dict)
    advice: str = ""


_EXACT_OREN_NAYAR = ("fit oren-nayar-exact (the exact V-cavity model) or oren-nayar-tabulated (its table, "
                     "1e-4 from it), or leave out the values where the formula fails (docs/validity.md)")
#: Approximations and their exact references, by model name and the option that selects the
#: approximation (None: the model itself is the approximation).
REFERENCES: dict[tuple[str, tuple[str, Any] | None], Reference] = {
    ("oren-nayar", None): Reference("oren-nayar-exact", approximation_values={"ir_weight": 1.0},
                                    advice=_EXACT_OREN_NAYAR),
    ("oren-nayar-qualitative", None): Reference("oren-nayar-exact", advice=_EXACT_OREN_NAYAR),
    ("oren-nayar-numerical", None): Reference("oren-nayar-exact", carried=("interreflection",),
                                              advice=_EXACT_OREN_NAYAR),
    ("wolff", ("fresnel", "polynomial")): Reference("wolff", {"fresnel": "exact"}, carried=("scale",),
                                                    advice="fit with the exact Fresnel factor (--option fresnel=exact)"),
    ("wolff-oren-nayar", ("fresnel", "polynomial")): Reference(
        "wolff-oren-nayar", {"fresnel": "exact"}, advice="fit with the exact Fresnel factor (--option fresnel=exact)"),
}


def reference_for(model: str, options: Mapping[str, Any]) -> Reference | None:
    """The exact reference of ``model`` with ``options``, or None when it is not an
    approximation gonio can check (module notes)."""
    for (name, selector), reference in REFERENCES.items():
        if name == model and (selector is None or options.get(selector[0]) == selector[1]):
            return reference
    return None


@dataclass(frozen=True)
class ModelValidity:
    """An approximation's error at a fit's data and the shift it causes (module notes).

    Attributes
    ----------
    model, reference : str
        The approximation and its exact reference.
    bias_sd : dict
        Linearised shift of each free parameter caused by the approximation's error, in its
        standard errors [-] (signed: the approximation's fit minus the exact model's).
    bias : dict
        The same shifts in the parameters' units.
    error_sd : list of float
        ``(approximation - exact) / uncertainty`` at each checked value [-].
    relative_error : list of float
        ``approximation / exact - 1`` at each checked value [-].
    checked : list of int
        Indices of the checked values in the dataset.
    advice : str
        What to fit instead.
    """

    model: str
    reference: str
    bias_sd: dict[str, float]
    bias: dict[str, float]
    error_sd: list[float]
    relative_error: list[float]
    checked: list[int]
    advice: str

    @property
    def exceeded(self) -> bool:
        """Whether a parameter moves by more than :data:`BIAS_LIMIT` or a value is off by more
        than :data:`POINT_LIMIT`."""
        worst_bias = max((abs(b) for b in self.bias_sd.values() if math.isfinite(b)), default=0.0)
        return worst_bias > BIAS_LIMIT or self.worst_point() > POINT_LIMIT

    def worst_point(self) -> float:
        """Largest ``|approximation - exact| / uncertainty`` over the checked values [-]."""
        errors = np.abs(np.asarray(self.error_sd, float))
        return float(np.nanmax(errors)) if errors.size else 0.0

    def flag(self, geometry: tuple[np.ndarray, ...]) -> str:
        """The fit's flag: how far the parameters moved, how many values the formula misses
        and where the worst is, and what to fit instead. ``geometry``: the dataset's
        (theta_i, phi_i, theta_r, phi_r) [deg]."""
        moved = ", ".join(f"{name} {self.bias_sd[name]:+.2g} sd ({value:+.3g})"
                          for name, value in self.bias.items() if abs(self.bias_sd[name]) > BIAS_LIMIT)
        errors = np.abs(np.asarray(self.error_sd, float))
        over = int(np.sum(errors > 1.0))
        worst = int(np.nanargmax(errors))
        index = self.checked[worst]
        ti, pi_, tr, pr = (float(np.asarray(a)[index]) for a in geometry)
        dphi = abs((pr - pi_ + 180.0) % 360.0 - 180.0)
        text = (f"{self.model} departs from {self.reference} at these geometries by more than the data's "
                f"uncertainty at {over} of {len(self.checked)} values (worst {self.relative_error[worst]:+.1%}, "
                f"{errors[worst]:.2g} x the uncertainty, at theta_i {ti:.4g}, theta_r {tr:.4g}, "
                f"dphi {dphi:.4g} deg)")
        if moved:
            text += f"; the formula's own error moves {moved}"
        return text + f": {self.advice}"

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.model, "reference": self.reference, "bias_sd": self.bias_sd, "bias": self.bias,
                "error_sd": self.error_sd, "relative_error": self.relative_error, "checked": self.checked,
                "advice": self.advice, "bias_limit": BIAS_LIMIT, "point_limit": POINT_LIMIT}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "ModelValidity":
        return cls(data["model"], data["reference"], dict(data["bias_sd"]), dict(data["bias"]),
                   [float(x) for x in data["error_sd"]], [float(x) for x in data["relative_error"]],
                   [int(i) for i in data["checked"]], data["advice"])


def checked_values(theta_i: np.ndarray, theta_r: np.ndarray, limit: int = MAX_CHECKED) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the values to compare and the number of values each stands for: all of
    them (weight 1) up to ``limit``; beyond, the quarter of ``limit`` most grazing (largest
    ``max(theta_i, theta_r)``, weight 1) and an even sample of the rest (each weighted by
    the values of the rest it stands for).

    >>> checked_values(np.zeros(5), np.arange(5.0))[0].tolist()
    [0, 1, 2, 3, 4]
    >>> index, weight = checked_values(np.zeros(10), np.arange(10.0), limit=4)
    >>> index.tolist(), weight.tolist()
    ([0, 4, 8, 9], [3.0, 3.0, 3.0, 1.0])
    """
    n = len(theta_i)
    if n <= limit:
        return np.arange(n), np.ones(n)
    grazing = np.argsort(-np.maximum(theta_i, theta_r), kind="stable")[: limit // 4]
    rest = np.setdiff1d(np.arange(n), grazing)
    sample = rest[np.linspace(0, len(rest) - 1, limit - len(grazing)).round().astype(int)]
    index = np.union1d(grazing, sample)
    return index, np.where(np.isin(index, grazing), 1.0, len(rest) / len(sample))


def check(problem, least_squares, build_problem: Callable[..., Any]) -> ModelValidity | None:
    """The approximation's error at ``problem``'s data and optimum (module notes).

    Parameters
    ----------
    problem : FitProblem
        The approximation's problem.
    least_squares : LeastSquaresResult
        Its fit (values and covariance).
    build_problem : callable
        ``build_problem(model_name, options, dataset)`` -> the same problem with another
        model or dataset.

    Returns
    -------
    ModelValidity or None
        None for a model that is not a checked approximation, or a fit none of whose
        parameters is determined (the shifts are given for the determined ones).

    Notes
    -----
    A dataset of more than :data:`MAX_CHECKED` independent values is compared on the
    values :func:`checked_values` selects, the evenly sampled ones weighted by the number of
    values each stands for in ``J_w^T d_w``. So is one whose covariance is a diagonal plus
    low rank (:class:`~gonio.fitting.LowRankCovariance`), through the Woodbury form of
    ``J^T C^-1 d`` whose three sums over values are taken on the same weighted sample
    (:func:`_sampled_gradient`); a dense covariance is compared on every value.
    """
    reference = reference_for(problem.base_model.name, problem.options)
    free = list(least_squares.free)
    determined = np.isfinite(np.diag(np.asarray(least_squares.covariance, float))) if free else np.zeros(0, bool)
    if reference is None or not determined.any():
        return None
    covariance = np.asarray(least_squares.covariance, float)[np.ix_(determined, determined)]
    free = [name for name, known in zip(free, determined) if known]  # undetermined ones: no shift to give
    data = problem.dataset
    whole = problem
    checked, weights = _checked_with_weights(data)
    if len(checked) < data.n:
        data = data.subset(checked)
        problem = build_problem(problem.base_model.name, problem.options, data)
    options = dict(reference.options) | {k: problem.options[k] for k in reference.carried if k in problem.options}
    exact_problem = build_problem(reference.model, options, data)
    values = dict(least_squares.values)
    approximation = values | reference.approximation_values
    predicted = problem.predict(approximation)
    exact = exact_problem.predict(values)
    difference = predicted - exact
    extra = problem.extra_variance(values, predicted) if problem.jitter else 0.0
    columns = _prediction_jacobian(problem, approximation, free)
    if len(checked) < whole.dataset.n and whole.dataset.covariance is not None:
        gradient = _sampled_gradient(whole, values, approximation, checked, weights, difference,
                                     np.column_stack(columns))
    else:
        whitened, _ = problem.whiten(difference, extra)
        jacobian = np.column_stack([problem.whiten(column, extra)[0] for column in columns])
        gradient = jacobian.T @ (weights * whitened)
    shift = -covariance @ gradient
    sd = np.sqrt(np.diag(covariance))
    sigma = np.sqrt(data.sigma ** 2 + extra)
    return ModelValidity(
        model=problem.base_model.name, reference=reference.model,
        bias_sd={name: float(shift[k] / sd[k]) if sd[k] > 0 else math.nan for k, name in enumerate(free)},
        bias={name: float(shift[k]) for k, name in enumerate(free)},
        error_sd=[float(x) for x in difference / sigma],
        relative_error=[float(x) for x in difference / exact],
        checked=[int(i) for i in checked],
        advice=reference.advice,
    )


def _checked_with_weights(data) -> tuple[np.ndarray, np.ndarray]:
    """The values to compare and the number of values each stands for (module notes): a
    dense covariance's all together, independent values and a diagonal plus low rank
    covariance's by :func:`checked_values`."""
    from .covariance import LowRankCovariance

    n = data.n
    if data.covariance is not None and not isinstance(data.covariance, LowRankCovariance):
        return np.arange(n), np.ones(n)
    theta_i, theta_r = (np.broadcast_to(np.asarray(a, float), (n,)) for a in (data.theta_i, data.theta_r))
    return checked_values(theta_i, theta_r, MAX_CHECKED)


def _sampled_gradient(whole, values: Mapping[str, float], approximation: Mapping[str, float], checked: np.ndarray,
                      weights: np.ndarray, difference: np.ndarray, jacobian: np.ndarray) -> np.ndarray:
    """``J^T C^-1 d`` for a diagonal plus low rank ``C = D + U U^T`` of ``whole``'s data
    (the extra noise on ``D``) from the values ``checked`` standing for ``weights`` values
    each: ``J^T D^-1 d - (U^T D^-1 J)^T (I + U^T D^-1 U)^-1 U^T D^-1 d`` (Woodbury), the
    sums over values of its first, second and last factors estimated on the sample, the
    middle one exact (it needs no exact model). ``difference`` (m,) and ``jacobian`` (m, p)
    are at the checked values."""
    covariance = whole.dataset.covariance
    extra = 0.0
    if whole.jitter:
        extra = whole.extra_variance(values, whole.predict(approximation) if whole.jitter == "relative" else None)
    independent = covariance.independent + np.broadcast_to(np.asarray(extra, float), (covariance.n,))
    factors = covariance.factors
    inner = np.eye(covariance.rank) + factors.T @ (factors / independent[:, None])
    weight = weights / independent[checked]
    sampled = factors[checked]
    shared = np.linalg.solve(inner, sampled.T @ (weight * difference))
    return jacobian.T @ (weight * difference) - (sampled.T @ (weight[:, None] * jacobian)).T @ shared


def _prediction_jacobian(problem, values: Mapping[str, float], free: list[str]) -> list[np.ndarray]:
    """Central (one-sided at a bound) differences of the predictions in each free parameter."""
    columns = []
    for name in free:
        value = float(values[name])
        low, high = problem.spec(name).bounds
        step = 1e-6 * max(1.0, abs(value))
        up, down = min(value + step, high), max(value - step, low)
        if up == down:
            columns.append(np.zeros(problem.dataset.n))
            continue
        columns.append((problem.predict(dict(values, **{name: up}))
                        - problem.predict(dict(values, **{name: down}))) / (up - down))
    return columns


def regime_flags(problem, priors: Mapping[str, Any]) -> list[str]:
    """Warnings for a fit set up where docs/validity.md measured its methods to fail.

    Relative radiance with ``scale`` and ``rho`` both free and no reference standard (no
    normal prior on ``scale``): rho and scale enter the prediction as their product apart
    from the interreflection's rho^2, and the atlas measured rho's interval 54 times the
    calibrated fit's and 19 of 20 chains not converging within 10000 steps
    (benchmarks/validity_fits.py, the scale axis).
    """
    from .priors import Normal

    free = set(problem.free)
    calibrated = isinstance(priors.get("scale"), Normal)
    if problem.dataset.quantity == "radiance" and {"scale", "rho"} <= free and not calibrated:
        return ["rho and scale are both free without a reference standard: the data fix mainly their product "
                "(measured, docs/validity.md: rho's interval 54 times a calibrated fit's, 19 of 20 chains not "
                "converged); measure a reference standard ([reference] in the protocol) for a prior on scale, "
                "fix scale, or quote rho x scale"]
    return []
