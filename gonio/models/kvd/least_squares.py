"""KvD series coefficients from scattered measurements by regularised least squares.

Measured BRDFs (a gonioreflectometer sweep, the 205 geometries of a CUReT sample) sample
the four-dimensional domain sparsely and unevenly, so the quadrature of
:mod:`gonio.models.kvd.projection` does not apply.  Instead the amplitudes minimise

    (1/N) sum_j w_j (sum_k a_k I_k(x_j) - f_j)^2  +  lam sum_k (n_k^2 + m_k^2) a_k^2

over the modes up to the requested order (KvD suggest the series for summarising,
smoothing and interpolating data; the fitting recipe is gonio's).  The penalty grows with
the radial orders, so it damps the high orders that ring or are poorly constrained by the
samples, and it leaves the Lambertian mode I_000 (the albedo) unpenalised.  With
``lam = 0`` this is ordinary (minimum-norm) least squares.

References
----------
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998, eq 26-31 and section 1 (summarising and interpolating
BRDF data); A. N. Tikhonov's regularisation as in scipy.linalg.lstsq on an augmented
system.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from gonio.zernike import _check_order

from .basis import design_matrix, isotropic_indices
from .series import KvdCoefficients

__all__ = ["SeriesFit", "fit_series", "penalty_weights"]


@dataclass(frozen=True)
class SeriesFit:
    """Result of :func:`fit_series`.

    Attributes
    ----------
    coefficients : KvdCoefficients
        Fitted amplitudes.
    fitted : numpy.ndarray
        Series values at the samples [1/sr].
    residuals : numpy.ndarray
        ``data - fitted`` [1/sr].
    rms_residual : float
        Root mean square of the residuals [1/sr] (unweighted).
    relative_rms_residual : float
        ``rms_residual / rms(data)`` [-].
    regularization : float
        The penalty weight used [sr^-2].
    """

    coefficients: KvdCoefficients
    fitted: np.ndarray
    residuals: np.ndarray
    rms_residual: float
    relative_rms_residual: float
    regularization: float


def penalty_weights(modes) -> np.ndarray:
    """Per-mode penalty ``n^2 + m^2`` of the regularised fit [-] (0 for the Lambert mode)."""
    return np.array([float(n * n + m * m) for n, m, _ in modes])


def _geometry(theta_i, phi_i, theta_r, phi_r, brdf):
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (theta_i, phi_i, theta_r, phi_r, brdf)))
    ti, pi_, tr, pr, f = (a.ravel() for a in arrays)
    for label, values in (("theta_i", ti), ("phi_i", pi_), ("theta_r", tr), ("phi_r", pr), ("brdf", f)):
        if not np.all(np.isfinite(values)):
            index = int(np.flatnonzero(~np.isfinite(values))[0])
            raise ValueError(f"{label}[{index}] = {values[index]} is not finite; remove the sample before fitting")
    for label, theta in (("theta_i", ti), ("theta_r", tr)):
        outside = (theta < 0.0) | (theta > 90.0)
        if np.any(outside):
            index = int(np.flatnonzero(outside)[0])
            raise ValueError(f"{label}[{index}] = {theta[index]:g} deg is outside the hemisphere [0, 90] deg")
    return ti, pi_, tr, pr, f


def fit_series(
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_r: ArrayLike,
    phi_r: ArrayLike,
    brdf: ArrayLike,
    order: int,
    regularization: float = 0.0,
    weights: ArrayLike | None = None,
) -> SeriesFit:
    """Fit the isotropic KvD series of ``order`` to scattered BRDF samples.

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Sample geometries [deg] (polar angles in [0, 90]); broadcast together.
    brdf : array_like
        Measured BRDF [1/sr]; negative values (noise) are used as they are.
    order : int
        Highest radial order of the series [-], ``>= 0``.
    regularization : float
        Penalty weight ``lam >= 0`` [sr^-2] of the objective in the module notes.
    weights : array_like, optional
        Non-negative sample weights [-] (e.g. 0 for saturated samples); default 1.

    Returns
    -------
    SeriesFit

    Raises
    ------
    ValueError
        Negative order or regularisation, non-finite samples, polar angles outside
        [0, 90] deg, negative weights.

    Notes
    -----
    Solved as one linear least-squares problem on the system ``[sqrt(w/N) X ;
    sqrt(lam P)] a = [sqrt(w/N) f ; 0]`` with X the design matrix of KvD eq 26 and P the
    diagonal penalty (``scipy.linalg.lstsq``, SVD based; minimum-norm when the samples do
    not determine every mode).  Reciprocity is exact whatever the data.

    Examples
    --------
    >>> theta = np.array([10.0, 30.0, 50.0, 70.0])
    >>> fit = fit_series(theta, 0.0, theta[::-1], 180.0, np.full(4, 0.5 / np.pi), order=0)
    >>> round(fit.coefficients[(0, 0, 0)], 12)
    1.0
    """
    order = _check_order(order)
    regularization = float(regularization)
    if not regularization >= 0.0:
        raise ValueError(f"regularization = {regularization:g} must be >= 0 (sr^-2)")
    ti, pi_, tr, pr, f = _geometry(theta_i, phi_i, theta_r, phi_r, brdf)
    if weights is None:
        w = np.ones_like(f)
    else:
        w = np.broadcast_to(np.asarray(weights, dtype=float), np.broadcast_shapes(np.shape(weights), np.shape(brdf))).ravel()
        if w.shape != f.shape:
            raise ValueError(f"weights must be one per sample: {w.size} weights for {f.size} samples")
        if not np.all(np.isfinite(w) & (w >= 0.0)):
            bad = w[~(np.isfinite(w) & (w >= 0.0))][0]
            raise ValueError(f"weights must be finite and non-negative, got {bad:g}")
    modes = isotropic_indices(order)
    matrix = design_matrix(modes, np.cos(np.radians(ti)), np.cos(np.radians(tr)), np.radians(pr - pi_))
    scale = np.sqrt(w / f.size)
    rows = [scale[:, None] * matrix]
    rhs = [scale * f]
    if regularization > 0.0:
        rows.append(np.diag(np.sqrt(regularization * penalty_weights(modes))))
        rhs.append(np.zeros(len(modes)))
    import scipy.linalg  # scipy loads on first use, not at import gonio

    amplitudes, *_ = scipy.linalg.lstsq(np.vstack(rows), np.concatenate(rhs))
    coefficients = KvdCoefficients(tuple(modes), amplitudes)
    fitted = matrix @ amplitudes
    residuals = f - fitted
    rms = math.sqrt(float(np.mean(residuals**2)))
    data_rms = math.sqrt(float(np.mean(f**2)))
    return SeriesFit(coefficients, fitted, residuals, rms, rms / data_rms if data_rms > 0 else math.inf, regularization)
