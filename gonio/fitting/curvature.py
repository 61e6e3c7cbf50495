"""The curvature of a log density at its mode: the covariance of its Laplace approximation.

One finite-difference rule, used where the least-squares covariance (from the residuals'
Jacobian) cannot give the posterior's: a free extra-noise term, which the residuals do not
carry, or a parameter the Jacobian leaves undetermined. The Laplace evidence
(:mod:`gonio.fitting.evidence`) and the MCMC's Laplace move (:mod:`gonio.fitting.mcmc`)
both take it from here.
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np

__all__ = ["inverse_hessian", "range_steps", "steps_at_mode"]

#: Finite-difference step of each parameter, as a fraction of its physical range (of its
#: magnitude when the range is unbounded).
STEP_FRACTION = 1e-4


def range_steps(x: Sequence[float], bounds: Sequence[tuple[float, float]]) -> list[float]:
    """The default finite-difference steps: :data:`STEP_FRACTION` of each parameter's
    range (of its magnitude when the range is unbounded)."""
    return [STEP_FRACTION * ((hi - lo) if math.isfinite(hi - lo) else max(abs(value), 1e-12))
            for value, (lo, hi) in zip(x, bounds)]


def steps_at_mode(mode: Sequence[float], stderr: Sequence[float], bounds: Sequence[tuple[float, float]]) -> list[float]:
    """Finite-difference steps about a least-squares optimum: a hundredth of each
    parameter's standard error where it is known, else a thousandth of its value (1e-9
    of its range's width at 0; of 1 where the range is unbounded).

    A step of the range (:data:`STEP_FRACTION`) is no step for a parameter whose posterior
    is narrow against its range: an extra noise of 3.4e-4 on a range of 10 was differenced
    about 2e-3, beyond its peak, and the curvature came out negative (the evidence of every
    candidate compared with an extra-noise term then fell to sampling).

    Examples
    --------
    >>> steps = steps_at_mode([0.9, 3.4e-4, 0.0], [0.004, float("nan"), float("nan")], [(0, 1), (0, 10), (0, 90)])
    >>> [float(f"{step:.3g}") for step in steps]
    [4e-05, 3.4e-07, 9e-08]
    """
    steps = []
    for value, error, (lo, hi) in zip(mode, stderr, bounds):
        width = hi - lo if math.isfinite(hi - lo) else 1.0
        steps.append(0.01 * error if error > 0 else max(1e-3 * abs(value), 1e-9 * width))
    return steps


def inverse_hessian(negative_log_density: Callable[[np.ndarray], float], x: np.ndarray,
                    bounds: Sequence[tuple[float, float]], steps: Sequence[float] | None = None) -> np.ndarray:
    """Inverse Hessian of ``negative_log_density`` at ``x`` by central differences.

    Steps of :data:`STEP_FRACTION` of each parameter's range (of its magnitude when the
    range is unbounded) unless ``steps`` are given; a parameter within two steps of a
    bound is differenced about a point two steps inside it. 2 k^2 + 1 evaluations for k
    parameters.

    Parameters
    ----------
    negative_log_density : callable
        ``f(vector) -> float``, -ln of the density (up to a constant).
    x : numpy.ndarray, shape (k,)
        The mode.
    bounds : sequence of (float, float)
        The physical range of every parameter.
    steps : sequence of float, optional
        The finite-difference step of every parameter (a small fraction of its posterior
        sd where that is known: a step of the range would move a parameter near its
        bound, an extra noise of 4e-4 on a range of 10, far from the mode).

    Returns
    -------
    numpy.ndarray, shape (k, k)
        The covariance of the Laplace approximation; all NaN where the Hessian is singular.
        It is not checked for positive definiteness (the caller decides what an indefinite
        curvature means).
    """
    x = np.asarray(x, float)
    k = x.size
    centre = x.copy()
    steps = np.array(range_steps(x, bounds) if steps is None else steps, float)
    for i, (lo, hi) in enumerate(bounds):
        if math.isfinite(hi - lo):
            centre[i] = min(max(x[i], lo + 2 * steps[i]), hi - 2 * steps[i])
    hessian = np.empty((k, k))
    f0 = negative_log_density(centre)
    for i in range(k):
        for j in range(i, k):
            ei, ej = np.eye(k)[i] * steps[i], np.eye(k)[j] * steps[j]
            if i == j:
                value = (negative_log_density(centre + ei) - 2 * f0 + negative_log_density(centre - ei)) / steps[i] ** 2
            else:
                value = (negative_log_density(centre + ei + ej) - negative_log_density(centre + ei - ej)
                         - negative_log_density(centre - ei + ej) + negative_log_density(centre - ei - ej)) / (
                    4 * steps[i] * steps[j])
            hessian[i, j] = hessian[j, i] = value
    try:
        return np.linalg.inv(hessian)
    except np.linalg.LinAlgError:
        return np.full((k, k), np.nan)
