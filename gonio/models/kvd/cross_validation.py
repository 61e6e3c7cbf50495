"""Series order by leave-one-out cross-validation of the regularised least-squares fit.

:func:`gonio.models.kvd.fit_series` fits the isotropic KvD series of a given order to
scattered samples.  Which order a data set supports is a model-selection question: too
low and the series misses real structure, too high and it follows the noise and rings
between the samples.  Leave-one-out cross-validation answers it without randomness: each
sample is predicted by the series fitted to the other N - 1, and the order with the
smallest prediction error (or, by the one-standard-error rule, the lowest order within one
standard error of it) is chosen.

For a linear smoother the leave-one-out residual is exact in closed form,
``e_j = r_j / (1 - h_jj)``, with ``r`` the residuals of the full fit and ``h_jj`` the
diagonal of its hat matrix (Hastie, Tibshirani & Friedman 2009, eq 7.64 / section 7.10);
no refit is needed.

References
----------
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998, eq 26-31 (the series).  T. Hastie, R. Tibshirani,
J. Friedman, "The Elements of Statistical Learning", 2nd ed., Springer 2009, section 7.10
(cross-validation, the one-standard-error rule) and eq 7.64 (leave-one-out shortcut).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import numpy as np
from numpy.typing import ArrayLike

from gonio.zernike import _check_order

from .basis import design_matrix, isotropic_indices
from .least_squares import _geometry, penalty_weights

__all__ = ["SELECTION_RULES", "OrderSelection", "leave_one_out_residuals", "select_order"]

#: Rules understood by :func:`select_order`.
SELECTION_RULES = ("one-standard-error", "minimum")


def _augmented_svd(matrix: np.ndarray, regularization: float, modes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin SVD of ``[X / sqrt(N) ; sqrt(lam P)]`` restricted to its numerical rank."""
    n = matrix.shape[0]
    rows = [matrix / np.sqrt(n)]
    if regularization > 0.0:
        rows.append(np.diag(np.sqrt(regularization * penalty_weights(modes))))
    u, s, vt = np.linalg.svd(np.vstack(rows), full_matrices=False)
    keep = s > s.max(initial=0.0) * max(u.shape) * np.finfo(float).eps
    return u[:, keep], s[keep], vt[keep]


def leave_one_out_residuals(
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_r: ArrayLike,
    phi_r: ArrayLike,
    brdf: ArrayLike,
    order: int,
    regularization: float = 0.0,
) -> np.ndarray:
    """Leave-one-out prediction residuals of the KvD series fit [1/sr].

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Sample geometries [deg] (polar angles in [0, 90]); broadcast together.
    brdf : array_like
        Measured BRDF [1/sr].
    order : int
        Radial order of the series [-], ``>= 0``.
    regularization : float
        Penalty weight ``lam >= 0`` [sr^-2] of :func:`gonio.models.kvd.fit_series`.

    Returns
    -------
    numpy.ndarray
        ``e_j = f_j - s_(-j)(x_j)``, the value minus the prediction of the series fitted
        without sample j [1/sr], flat; ``inf`` where a sample alone determines a mode
        (leverage 1, only possible with ``lam = 0``).

    Notes
    -----
    ``e_j = r_j / (1 - h_jj)`` with ``r`` the residuals and ``h_jj`` the leverages of the
    fit to all N samples, computed from the SVD of the augmented system of
    :func:`gonio.models.kvd.fit_series`.  It equals a refit without sample j whose
    objective keeps the penalty of the full fit, ``sum_{i != j} r_i^2 + N lam P``, i.e.
    ``fit_series`` on the N - 1 samples with ``regularization = lam N / (N - 1)`` (tested).

    Examples
    --------
    >>> theta = np.array([10.0, 30.0, 50.0, 70.0])
    >>> e = leave_one_out_residuals(theta, 0.0, theta[::-1], 180.0, np.full(4, 0.3), order=0)
    >>> bool(np.allclose(e, 0.0))
    True
    """
    order = _check_order(order)
    regularization = float(regularization)
    if not regularization >= 0.0:
        raise ValueError(f"regularization = {regularization:g} must be >= 0 (sr^-2)")
    ti, pi_, tr, pr, f = _geometry(theta_i, phi_i, theta_r, phi_r, brdf)
    modes = isotropic_indices(order)
    matrix = design_matrix(modes, np.cos(np.radians(ti)), np.cos(np.radians(tr)), np.radians(pr - pi_))
    u, s, vt = _augmented_svd(matrix, regularization, modes)
    n = f.size
    top = u[:n]
    amplitudes = vt.T @ ((top.T @ (f / np.sqrt(n))) / s)
    residuals = f - matrix @ amplitudes
    leverage = np.sum(top**2, axis=1)
    free = 1.0 - leverage
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(free > 1e-10, residuals / np.where(free > 1e-10, free, 1.0), np.inf)


@dataclass(frozen=True)
class OrderSelection:
    """Cross-validation curve of the KvD series order and the order it chooses.

    Attributes
    ----------
    orders : tuple of int
        Radial orders tried [-].
    modes : tuple of int
        Number of amplitudes of each order [-].
    cv_rms : numpy.ndarray
        Relative leave-one-out error per order, ``sqrt(mean(e^2) / mean(f^2))`` [-].
    cv_rms_se : numpy.ndarray
        Its standard error [-] (from the standard error of ``mean(e^2)`` over the samples,
        propagated through the square root).
    chosen : int
        The chosen order [-].
    rule : str
        ``"one-standard-error"`` or ``"minimum"`` (:data:`SELECTION_RULES`).
    regularization : float
        Penalty weight of every fit [sr^-2].
    """

    orders: tuple[int, ...]
    modes: tuple[int, ...]
    cv_rms: np.ndarray
    cv_rms_se: np.ndarray
    chosen: int
    rule: str
    regularization: float

    @property
    def best(self) -> int:
        """The order with the smallest leave-one-out error [-]."""
        return self.orders[int(np.argmin(self.cv_rms))]

    def curve(self) -> dict[int, float]:
        """``{order: relative leave-one-out error}``."""
        return {o: float(v) for o, v in zip(self.orders, self.cv_rms)}


def select_order(
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_r: ArrayLike,
    phi_r: ArrayLike,
    brdf: ArrayLike,
    orders: Iterable[int] = range(0, 11),
    regularization: float = 0.0,
    rule: str = "one-standard-error",
) -> OrderSelection:
    """Choose the KvD series order by leave-one-out cross-validation.

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Sample geometries [deg]; broadcast together.
    brdf : array_like
        Measured BRDF [1/sr].
    orders : iterable of int
        Candidate radial orders [-] (default 0-10).
    regularization : float
        Penalty weight ``lam >= 0`` [sr^-2] of every fit.
    rule : {"one-standard-error", "minimum"}
        ``"minimum"``: the order of smallest leave-one-out mean square error;
        ``"one-standard-error"``: the lowest order whose mean square error is within one
        standard error of that minimum (Hastie et al. 2009, section 7.10), the smoothest
        series the data cannot tell apart from the best one.

    Returns
    -------
    OrderSelection

    Raises
    ------
    ValueError
        No candidate order, an unknown rule, or the fitting errors of
        :func:`leave_one_out_residuals`.

    Notes
    -----
    Deterministic: the leave-one-out residuals are exact (no random folds), and ties go
    to the lower order.  The standard error of ``mean(e^2)`` is
    ``std(e^2, ddof=1) / sqrt(N)``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> ti, tr = rng.uniform(0, 80, 150), rng.uniform(0, 80, 150)
    >>> f = np.full(150, 0.25) * (1 + 0.01 * rng.standard_normal(150))
    >>> select_order(ti, 0.0, tr, 180.0, f, orders=range(0, 5)).chosen
    0
    """
    if rule not in SELECTION_RULES:
        raise ValueError(f"rule = {rule!r} is not one of {list(SELECTION_RULES)}")
    orders = tuple(sorted({_check_order(o) for o in orders}))
    if not orders:
        raise ValueError("orders is empty: give at least one radial order to cross-validate")
    signal = float(np.mean(_geometry(theta_i, phi_i, theta_r, phi_r, brdf)[4] ** 2))
    mse, mse_se = [], []
    for order in orders:
        e2 = leave_one_out_residuals(theta_i, phi_i, theta_r, phi_r, brdf, order, regularization) ** 2
        mse.append(float(np.mean(e2)))
        mse_se.append(float(np.std(e2, ddof=1) / np.sqrt(e2.size)) if e2.size > 1 and np.all(np.isfinite(e2)) else np.inf)
    mse_arr, se_arr = np.array(mse), np.array(mse_se)
    best = int(np.argmin(mse_arr))
    if rule == "minimum":
        chosen = orders[best]
    else:
        chosen = orders[int(np.flatnonzero(mse_arr <= mse_arr[best] + se_arr[best])[0])]
    scale = signal if signal > 0.0 else 1.0
    cv_rms = np.sqrt(mse_arr / scale)
    with np.errstate(divide="ignore", invalid="ignore"):
        cv_se = np.where(cv_rms > 0, se_arr / scale / (2.0 * cv_rms), 0.0)
    return OrderSelection(orders, tuple(len(isotropic_indices(o)) for o in orders), cv_rms, cv_se, chosen, rule,
                          float(regularization))
