"""Chandrasekhar's H-function for isotropic scattering in a semi-infinite medium.

The H-function describes diffuse reflection from a semi-infinite, plane-parallel medium
of isotropic scatterers with single-scattering albedo omega.  It enters the physical
albedo factor of the Wolff smooth-dielectric model (Wolff, Nayar & Oren 1998, eq 8).

Functions
---------
discrete_ordinates
    Positive zeros mu_j of the Legendre polynomial P_2N and their Gauss weights a_j.
characteristic_roots
    Positive roots k_alpha of the characteristic equation 1 = omega sum a_j/(1 - k^2 mu_j^2).
h_function
    The N-th order approximation of H (the closed form quoted after eq 8).
h_function_numerical
    An independent solution of the nonlinear integral equation for H on a fine Gauss grid
    (the reference the approximation is validated against).

References
----------
S. Chandrasekhar, *Radiative Transfer*, Oxford 1950 / Dover 1960, ch. III (discrete
ordinates, the characteristic equation) and ch. V (the H-function, its integral
equations and moments).
L. B. Wolff, S. K. Nayar, M. Oren, "Improved diffuse reflection models for computer
vision", IJCV 30(1), 1998, text after eq 8 (N-th order H-function).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "DEFAULT_ORDER",
    "discrete_ordinates",
    "characteristic_roots",
    "h_function",
    "h_function_numerical",
]

#: Order N of the approximation used by default.  The error of the N-th approximation
#: falls only like 1/N (it is worst near mu = 0, where the exact H has a mu log mu term
#: no rational function follows): at N = 32 the largest relative error over mu in [0, 1]
#: is 1.9e-3 (omega = 1, mu ~ 0.03) and below 1e-3 for mu >= 0.5; the Wolff albedo
#: factor (eq 8) built on it is within 7e-4 of the one built on the exact H.
#: docs/wolff.md and benchmarks/bench_wolff.py record the error against N.
DEFAULT_ORDER = 32


def _check_omega(omega: float) -> float:
    try:
        value = float(omega)
    except (TypeError, ValueError):
        raise ValueError(f"omega must be a real number in [0, 1], got {omega!r}") from None
    if not 0.0 <= value <= 1.0:
        raise ValueError(
            f"omega = {value:g} (single-scattering albedo) is outside its valid range [0, 1]"
        )
    return value


def _check_order(order: int) -> int:
    if int(order) != order or order < 1:
        raise ValueError(f"order = {order!r} must be a positive integer (N >= 1)")
    return int(order)


@lru_cache(maxsize=64)
def _ordinates(order: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(2 * order)
    positive = x > 0
    mu, a = x[positive], w[positive]
    sort = np.argsort(mu)[::-1]
    return mu[sort], a[sort]


def discrete_ordinates(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Positive zeros of the even Legendre polynomial P_2N and their Gauss weights.

    Parameters
    ----------
    order : int
        N >= 1.

    Returns
    -------
    mu : numpy.ndarray
        The N positive zeros mu_j of P_2N, decreasing [-].
    a : numpy.ndarray
        Their Gauss-Legendre weights a_j on [-1, 1] [-]; sum(a) = 1.

    Notes
    -----
    Chandrasekhar (1960) ch. III: the Gauss quadrature on [-1, 1] of order 2N, whose
    nodes come in pairs +-mu_j.

    References
    ----------
    S. Chandrasekhar, *Radiative Transfer*, Dover 1960, ch. III (Gauss quadrature, discrete ordinates).

    Examples
    --------
    >>> mu, a = discrete_ordinates(1)
    >>> round(float(mu[0]), 6), float(a[0])
    (0.57735, 1.0)
    """
    mu, a = _ordinates(_check_order(order))
    return mu.copy(), a.copy()


def _bracketed_root(function, left: float, right: float) -> float:
    """Root of an increasing ``function`` on (left, right) with -inf/+inf at the ends."""
    gap = right - left
    lo = left if left == 0.0 else None
    hi = None
    # Steps stop at 1e-12 of the gap: poles are at least 1e-3 of their value apart for
    # N <= 64, so every trial point stays many ulps away from a pole (no division by 0);
    # a root nearer its pole than that changes k by less than 1e-12 relative.
    for step in (1e-2, 1e-4, 1e-7, 1e-10, 1e-12):
        if lo is None and function(left + step * gap) < 0.0:
            lo = left + step * gap
        if hi is None and function(right - step * gap) > 0.0:
            hi = right - step * gap
    if lo is None:
        return left
    if hi is None:
        return right
    from scipy.optimize import brentq  # scipy loads on first use, not at import gonio

    return brentq(function, lo, hi, xtol=1e-300, rtol=1e-15, maxiter=200)


@lru_cache(maxsize=256)
def _roots(omega: float, order: int) -> np.ndarray:
    mu, a = _ordinates(order)
    if omega == 0.0:
        return np.empty(0)

    def characteristic(s: float) -> float:  # s = k^2
        return omega * float(np.sum(a / (1.0 - s * mu**2))) - 1.0

    poles = 1.0 / mu**2  # increasing, since mu decreases
    # The function of s rises monotonically between consecutive poles, from -inf just
    # right of one pole to +inf just left of the next, so each gap holds one root.  For
    # small omega the root crowds a pole: the bracket is tightened until the signs differ,
    # and a root closer to its pole than rounding can resolve is the pole itself.
    gaps = [(0.0, poles[0])] if omega < 1.0 else []  # characteristic(0) = omega - 1 < 0
    gaps += list(zip(poles[:-1], poles[1:]))
    roots = [_bracketed_root(characteristic, left, right) for left, right in gaps]
    return np.sqrt(np.array(roots))


def characteristic_roots(omega: float, order: int = DEFAULT_ORDER) -> np.ndarray:
    """Positive roots k_alpha of the characteristic equation of isotropic scattering.

    Parameters
    ----------
    omega : float
        Single-scattering albedo [-], in [0, 1].
    order : int, optional
        Order N of the discrete-ordinate approximation.

    Returns
    -------
    numpy.ndarray
        The positive roots of 1 = omega sum_j a_j / (1 - k^2 mu_j^2), increasing: N of
        them for omega < 1, N - 1 for omega = 1 (the root k = 0 is excluded), none for
        omega = 0.

    Notes
    -----
    Chandrasekhar (1960) ch. III; Wolff, Nayar & Oren (1998) after eq 8.  The function of
    s = k^2 on the right-hand side has poles at s = 1/mu_j^2 and rises monotonically
    between them, so each interval holds exactly one root; each is found by bracketing
    (``scipy.optimize.brentq``).

    References
    ----------
    S. Chandrasekhar, *Radiative Transfer*, Dover 1960, ch. III (characteristic equation).
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, text after eq 8.

    Examples
    --------
    >>> characteristic_roots(1.0, order=1).size
    0
    >>> round(float(characteristic_roots(0.75, order=1)[0]), 6)   # sqrt(3 (1 - omega))
    0.866025
    """
    return _roots(_check_omega(omega), _check_order(order)).copy()


def h_function(mu: ArrayLike, omega: float, order: int = DEFAULT_ORDER) -> np.ndarray:
    """Chandrasekhar's H-function for isotropic scattering, N-th order approximation [-].

    Parameters
    ----------
    mu : array_like
        Direction cosine, in [0, 1].
    omega : float
        Single-scattering albedo [-], in [0, 1].
    order : int, optional
        Order N of the approximation (default :data:`DEFAULT_ORDER`).

    Returns
    -------
    numpy.ndarray
        H(mu) = prod_j (mu + mu_j) / (prod_j mu_j prod_alpha (1 + k_alpha mu)), with mu_j
        the positive zeros of P_2N and k_alpha the positive characteristic roots.
        H(0) = 1; H = 1 for omega = 0.  NaN in gives NaN out.

    Notes
    -----
    The closed form quoted after eq 8 of Wolff, Nayar & Oren (1998), from Chandrasekhar
    (1960) ch. V.  Its error against the exact H (solution of the integral equation,
    :func:`h_function_numerical`) falls quickly with N: tests/models/test_chandrasekhar.py
    and benchmarks/bench_wolff.py measure it.

    References
    ----------
    S. Chandrasekhar, *Radiative Transfer*, Dover 1960, ch. V (N-th approximation of H).
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, text after eq 8.

    Examples
    --------
    >>> round(float(h_function(1.0, 1.0)), 3)
    2.908
    """
    omega = _check_omega(omega)
    order = _check_order(order)
    mu = np.asarray(mu, float)
    if omega == 0.0:  # no scattering: H = 1 (the limit of the closed form as omega -> 0)
        return 1.0 + 0.0 * mu
    nodes, _ = _ordinates(order)
    roots = _roots(omega, order)
    x = mu[..., None]
    numerator = np.prod((x + nodes) / nodes, axis=-1)
    denominator = np.prod(1.0 + roots * x, axis=-1) if roots.size else 1.0
    return numerator / denominator


@lru_cache(maxsize=32)
def _numerical_solution(omega: float, nodes: int, tolerance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(nodes)
    mu, weight = 0.5 * (x + 1.0), 0.5 * w
    kernel = 0.5 * omega * weight * mu / (mu[:, None] + mu)  # row i: mu_i, column j: mu'_j
    floor = np.sqrt(1.0 - omega)
    h = np.ones_like(mu)
    for _ in range(30):  # fixed-point iteration: a good start for Newton
        h = 1.0 / (floor + kernel @ h)
    # Newton on G(h) = h (floor + K h) - 1 = 0: the plain iteration contracts slowly as
    # omega -> 1, Newton converges quadratically from this start.
    for _ in range(50):
        field_ = floor + kernel @ h
        residual = h * field_ - 1.0
        jacobian = np.diag(field_) + h[:, None] * kernel
        step = np.linalg.solve(jacobian, residual)
        h = h - step
        if np.max(np.abs(step)) < tolerance:
            break
    else:  # pragma: no cover - Newton converges in a handful of steps
        raise RuntimeError("H-function iteration did not converge")
    return mu, weight, h


def h_function_numerical(
    mu: ArrayLike, omega: float, nodes: int = 400, tolerance: float = 1e-14
) -> np.ndarray:
    """H-function from the nonlinear integral equation on a Gauss grid [-].

    Parameters
    ----------
    mu : array_like
        Direction cosine, in [0, 1].
    omega : float
        Single-scattering albedo [-], in [0, 1].
    nodes : int, optional
        Gauss-Legendre nodes on [0, 1].
    tolerance : float, optional
        Stop when successive iterates differ by less than this (absolute).

    Returns
    -------
    numpy.ndarray
        H(mu), accurate to about 1e-7 relative with the defaults (limited by the
        logarithmic end-point behaviour of H near mu = 0, not by the iteration).

    Notes
    -----
    Solves the form 1/H(mu) = sqrt(1 - omega) + (omega/2) int_0^1 mu' H(mu') /
    (mu + mu') dmu' (Chandrasekhar 1960, ch. V), equivalent to the standard equation
    H = 1 + (omega/2) mu H int H(mu')/(mu + mu') dmu'.  A few fixed-point iterations
    start Newton's method, which converges in a handful of steps also for conservative
    scattering (omega = 1), where the plain iteration is slow.  H is first found
    at the Gauss nodes; at other mu the same equation gives H(mu) from the nodal values
    (Nystrom interpolation).  This is a reference implementation for validating
    :func:`h_function` (speed is not its purpose).

    References
    ----------
    S. Chandrasekhar, *Radiative Transfer*, Dover 1960, ch. V (integral equations for H).

    Examples
    --------
    >>> round(float(h_function_numerical(1.0, 1.0)), 4)
    2.9078
    """
    omega = _check_omega(omega)
    nodes_mu, weight, h = _numerical_solution(omega, int(nodes), float(tolerance))
    mu = np.asarray(mu, float)
    x = mu[..., None]
    integral = np.sum(weight * nodes_mu * h / (x + nodes_mu), axis=-1)
    return 1.0 / (np.sqrt(1.0 - omega) + 0.5 * omega * integral)
