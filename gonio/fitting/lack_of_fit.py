"""Lack of fit that does not depend on the noise budget being complete.

A chi-square test asks whether the residuals are as small as the *stated* uncertainties
say. When it fails there are two explanations it cannot tell apart: the model cannot
follow the data, or the budget left a noise source out (a real sample's texture). This
module asks a question whose answer does not depend on the size of the stated noise:
**is there structure in the residuals that a flexible, model-free description of the
same data would pick up?**

The test is the classical lack-of-fit F test of a regression against an augmented one
(Draper & Smith 1998, section 2.1; Seber & Wild 2003, section 5.9 for its nonlinear,
locally linear form). At the least-squares optimum, with whitened residuals ``r`` (the
stated covariance's Cholesky factor, so only the *shape* of the budget is used, never its
size), the whitened Jacobian ``J`` of the model and a whitened flexible basis ``X``:

1. the part of ``X`` the model can already follow is removed: ``X_perp = (1 - P_J) X``
   with ``q`` its rank;
2. the residual sum of squares is split into what ``X_perp`` explains, ``S_lof``, and the
   rest, ``S_pure`` (``n - rank J - q`` degrees of freedom);
3. ``F = (S_lof / q) / (S_pure / (n - rank J - q))``; under an adequate model with any
   noise level of the stated shape, ``F`` follows ``F(q, n - rank J - q)`` to first order.

An understated noise scales ``S_lof`` and ``S_pure`` alike and leaves ``F`` unchanged; a
model that misses a smooth structure raises ``S_lof`` only.

The flexible description is the reciprocal series of Koenderink & van Doorn (1998, eq
26-31; :mod:`gonio.models.kvd`) at radial orders 2, 4 and 6 (5, 14 and 30 modes), times
``cos(theta_i)`` for relative radiance; the orders a dataset can afford (``q`` at most
half the degrees of freedom, at least :data:`MIN_PURE_DOF` left) are each tested and the
smallest p-value is multiplied by their number (Bonferroni), so the false-alarm rate
stays at most the nominal one. The same split gives the **noise factor**
``sqrt(S_pure / dof)``: the scatter about model and flexible description together over
the stated uncertainty, the factor by which the budget understates the noise when the
model is adequate. ``benchmarks/bench_lack_of_fit.py`` measures the false-alarm rate and
the power (docs/fitting.md, "Three verdicts").

References
----------
N. R. Draper, H. Smith, "Applied Regression Analysis", 3rd ed., Wiley 1998, section 2.1.
G. A. F. Seber, C. J. Wild, "Nonlinear Regression", Wiley 2003, section 5.9.
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Mapping

import numpy as np

__all__ = ["LackOfFit", "LACK_OF_FIT_ORDERS", "MIN_PURE_DOF", "lack_of_fit", "split_residuals"]

#: Radial orders of the flexible (Koenderink-van Doorn) description that are tested.
LACK_OF_FIT_ORDERS = (2, 4, 6)
#: Fewest degrees of freedom left for the scatter estimate of a test.
MIN_PURE_DOF = 10


@dataclass(frozen=True)
class LackOfFit:
    """Result of :func:`lack_of_fit` (module docstring).

    Attributes
    ----------
    p : float
        Bonferroni-corrected p-value of the most significant order [-].
    order : int
        The series order of that test.
    statistic : float
        Its F statistic [-].
    dof : tuple of int
        Its degrees of freedom ``(q, n - rank J - q)``.
    noise_factor : float
        ``sqrt(S_pure / dof)`` of the highest order tested: the data's scatter over the
        stated uncertainties [-] (1 when the budget is complete).
    orders : tuple of int
        Every order tested.
    """

    p: float
    order: int
    statistic: float
    dof: tuple[int, int]
    noise_factor: float
    orders: tuple[int, ...]

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["dof"], out["orders"] = list(self.dof), list(self.orders)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "LackOfFit":
        return cls(float(data["p"]), int(data["order"]), float(data["statistic"]), tuple(data["dof"]),
                   float(data["noise_factor"]), tuple(data["orders"]))


def split_residuals(residuals: np.ndarray, jacobian: np.ndarray, basis: np.ndarray) -> tuple[float, int, float, int]:
    """Split whitened residuals into what ``basis`` explains beyond ``jacobian``, and the rest.

    Parameters
    ----------
    residuals : numpy.ndarray, shape (n,)
        Whitened residuals at the optimum [-].
    jacobian : numpy.ndarray, shape (n, k)
        Whitened derivatives of the prediction with respect to the free parameters.
    basis : numpy.ndarray, shape (n, m)
        Whitened flexible description.

    Returns
    -------
    (lack_of_fit_ss, q, pure_ss, pure_dof)
        The sum of squares along the part of ``basis`` outside the span of ``jacobian``,
        its dimension, the rest of the sum of squares and its degrees of freedom.

    Examples
    --------
    >>> x = np.linspace(-1, 1, 21)
    >>> r = x**2 - np.mean(x**2)                      # a parabola a constant model missed
    >>> s_lof, q, s_pure, dof = split_residuals(r, np.ones((21, 1)), np.c_[x, x**2])
    >>> q, dof, round(s_pure, 12)
    (2, 18, 0.0)
    """
    tangent = _orthonormal_columns(jacobian)
    outside = basis - tangent @ (tangent.T @ basis)
    direction = _orthonormal_columns(outside)
    free_residuals = residuals - tangent @ (tangent.T @ residuals)
    lack = float(np.sum((direction.T @ free_residuals) ** 2))
    total = float(free_residuals @ free_residuals)
    return lack, direction.shape[1], max(total - lack, 0.0), len(residuals) - tangent.shape[1] - direction.shape[1]


def _orthonormal_columns(matrix: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the column space of ``matrix`` (rank by SVD)."""
    if matrix.size == 0:
        return np.zeros((matrix.shape[0], 0))
    u, s, _ = np.linalg.svd(matrix, full_matrices=False)
    keep = s > s.max(initial=0.0) * max(matrix.shape) * 1e-10
    return u[:, keep]


def lack_of_fit(problem, vector: np.ndarray, orders: tuple[int, ...] = LACK_OF_FIT_ORDERS) -> LackOfFit | None:
    """The lack-of-fit test of a fit at its least-squares optimum (module docstring).

    Parameters
    ----------
    problem : FitProblem
    vector : numpy.ndarray
        The free parameters at the optimum.
    orders : tuple of int
        Series orders to test.

    Returns
    -------
    LackOfFit or None
        None when the dataset is too small for any order (fewer than about
        ``2 * 5 + MIN_PURE_DOF`` informative values beyond the free parameters) or the
        residuals are undefined.
    """
    from scipy.special import fdtrc  # scipy.stats.f.sf without importing scipy.stats

    residuals = problem.residuals(vector)
    if not np.all(np.isfinite(residuals)):
        return None
    jacobian = _whitened_jacobian(problem, np.asarray(vector, float), residuals)
    n = problem.n_informative
    tests = []
    for order in orders:
        basis = _whitened_basis(problem, order)
        lack, q, pure, dof = split_residuals(residuals, jacobian, basis)
        dof -= problem.dataset.n - n  # normalised radiance: the references carry nothing
        if q == 0 or dof < MIN_PURE_DOF or q > (n - jacobian.shape[1]) / 2 or pure <= 0.0:
            continue
        statistic = (lack / q) / (pure / dof)
        tests.append((float(fdtrc(q, dof, statistic)), order, statistic, (q, dof), math.sqrt(pure / dof)))
    if not tests:
        return None
    p, order, statistic, dof, _ = min(tests)
    return LackOfFit(min(1.0, p * len(tests)), order, statistic, dof, tests[-1][4], tuple(t[1] for t in tests))


def _whitened_jacobian(problem, vector: np.ndarray, residuals: np.ndarray) -> np.ndarray:
    """Derivatives of the whitened residuals by finite differences stepping into the bounds."""
    columns = []
    for j, name in enumerate(problem.free):
        spec = problem.spec(name)
        step = 1e-6 * max(abs(vector[j]), _typical(spec))
        moved = vector.copy()
        moved[j] += step
        if not problem.in_bounds(moved):
            step = -step
            moved[j] = vector[j] + step
        columns.append((problem.residuals(moved) - residuals) / step)
    jacobian = np.column_stack(columns) if columns else np.zeros((len(residuals), 0))
    return np.where(np.isfinite(jacobian), jacobian, 0.0)


def _typical(spec) -> float:
    """A parameter's typical size: its range when finite, else 1."""
    width = spec.bounds[1] - spec.bounds[0]
    return float(width) if math.isfinite(width) and width > 0 else 1.0


def _whitened_basis(problem, order: int) -> np.ndarray:
    """The flexible description at the data's geometries, as the data's quantity, whitened."""
    from gonio.models.kvd import design_matrix, isotropic_indices

    data = problem.dataset
    theta_i, phi_i, theta_r, phi_r = data.geometry
    basis = design_matrix(isotropic_indices(order), np.cos(np.radians(theta_i)), np.cos(np.radians(theta_r)),
                          np.radians(data.azimuth_difference))
    if data.quantity == "radiance":
        basis = basis * np.cos(np.radians(theta_i))[:, None]
    if data.quantity == "normalised_radiance":
        basis[(data.theta_r == 0.0) & (data.value == 1.0)] = 0.0
    if data.covariance is None:
        return basis / data.sigma[:, None]
    return problem.whiten(basis)[0]
