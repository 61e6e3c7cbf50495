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

__all__ = ["inverse_hessian"]

#: Finite-difference step of each parameter, as a fraction of its physical range (of its
#: magnitude when the range is unbounded).
STEP_FRACTION = 1e-4


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
    given = steps
    steps = np.empty(k)
    for i, (lo, hi) in enumerate(bounds):
        steps[i] = given[i] if given is not None else \
            STEP_FRACTION * ((hi - lo) if math.isfinite(hi - lo) else max(abs(x[i]), 1e-12))
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
