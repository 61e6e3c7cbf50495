"""Zernike polynomials carried from the unit disk to the hemisphere of directions.

Koenderink & van Doorn (1998) build their reflectance series from the Zernike
polynomials of the unit disk.  The map ``rho = sqrt(2) sin(theta / 2)`` takes the
hemisphere of directions (polar angle theta in [0, 90] deg) onto the unit disk so that
area on the disk is proportional to solid angle, ``rho d rho d phi = dOmega / 2``; the
Zernike functions therefore stay orthogonal on the hemisphere and only need a new
normalisation, which gives the orthonormal basis ``K_n^l(theta, phi)``.

Conventions
-----------
* ``n >= 0`` is the radial order and ``l`` (or ``m``) the signed azimuthal order with
  ``|l| <= n`` and ``n - |l|`` even.
* The azimuthal factor ``az_l`` is ``cos(l phi)`` for ``l > 0``, ``1/sqrt(2)`` for
  ``l = 0`` and ``sin(|l| phi)`` for ``l < 0`` (KvD eq 5-7); with it
  ``integral az_k az_l dphi = pi delta_kl`` over one turn (eq 8).
* Angles are in degrees at the public interface.  ``rho**2 = 1 - cos(theta)``, so
  ``R_n^l`` is evaluated through the Jacobi polynomial of ``cos(theta)``, which avoids the
  cancellation of the explicit factorial sum at high order.

References
----------
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998: Zernike functions eq 1-4, azimuthal factors eq 5-9,
hemisphere map eq 10-14, basis K_n^l eq 15-16, Figs 1-2.
M. Born, E. Wolf, *Principles of Optics*, appendix VII (Zernike circle polynomials and
their Jacobi-polynomial form).
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "check_zernike_indices",
    "zernike_radial",
    "zernike_radial_of_cos",
    "hemisphere_radius",
    "azimuthal_factor",
    "hemisphere_basis",
    "hemisphere_basis_indices",
    "zernike_radial_table",
]


def check_zernike_indices(n: int, m: int, name: str = "n") -> tuple[int, int]:
    """Validate a Zernike index pair and return it as Python ints.

    Parameters
    ----------
    n : int
        Radial order [-], ``n >= 0``.
    m : int
        Azimuthal order [-], ``|m| <= n`` with ``n - |m|`` even.
    name : str
        How the radial order is called in error messages.

    Returns
    -------
    tuple of int
        ``(n, m)``.

    Raises
    ------
    ValueError
        If an index is not an integer, ``n < 0``, ``|m| > n`` or ``n - |m|`` is odd.
    """
    try:
        n_int, m_int = operator_index(n), operator_index(m)
    except TypeError:
        raise ValueError(f"Zernike indices must be integers, got {name} = {n!r}, m = {m!r}") from None
    if n_int < 0:
        raise ValueError(f"Zernike order {name} = {n_int} is negative; valid orders are 0, 1, 2, ...")
    if abs(m_int) > n_int or (n_int - abs(m_int)) % 2:
        raise ValueError(
            f"Zernike index m = {m_int} is invalid for {name} = {n_int}: need |m| <= {name} "
            f"and {name} - |m| even"
        )
    return n_int, m_int


def operator_index(value: object) -> int:
    """``value`` as an int if it is integral (numpy integers and integral floats included)."""
    if isinstance(value, (bool, np.bool_)):
        raise TypeError("booleans are not indices")
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)) and float(value).is_integer():
        return int(value)
    raise TypeError(f"{value!r} is not an integer")


def zernike_radial_of_cos(n: int, m: int, cos_theta: ArrayLike) -> np.ndarray:
    """Zernike radial polynomial on the hemisphere, as a function of cos(theta).

    Parameters
    ----------
    n, m : int
        Radial and azimuthal orders (``|m| <= n``, ``n - |m|`` even).
    cos_theta : array_like
        Cosine of the polar angle [-], in [0, 1] on the hemisphere.

    Returns
    -------
    numpy.ndarray
        ``R_n^|m|(sqrt(2) sin(theta/2))`` [-].

    Notes
    -----
    With ``rho**2 = 1 - cos(theta)`` (KvD eq 10) the radial polynomial of KvD eq 3 equals
    ``(-1)**k rho**|m| P_k^(|m|, 0)(1 - 2 rho**2)`` with ``k = (n - |m|)/2`` and
    ``P^(a, b)`` the Jacobi polynomial (Born & Wolf appendix VII); ``1 - 2 rho**2`` is
    ``2 cos(theta) - 1``.  This is the single implementation used by every basis in gonio;
    the tests compare it with the explicit factorial sum of eq 3.

    Examples
    --------
    >>> float(zernike_radial_of_cos(2, 0, 1.0))   # centre of the disk: R_2^0(0) = -1
    -1.0
    """
    from scipy.special import eval_jacobi  # scipy loads on first use, not at import gonio

    n, m = check_zernike_indices(n, m)
    m = abs(m)
    k = (n - m) // 2
    c = np.asarray(cos_theta, dtype=float)
    one_minus_cos = np.maximum(1.0 - c, 0.0)  # rho**2 >= 0; rounding can make it -0.0
    rho_power = one_minus_cos ** (0.5 * m) if m else np.where(np.isnan(c), np.nan, 1.0)
    sign = -1.0 if k % 2 else 1.0
    return sign * rho_power * eval_jacobi(k, m, 0, 2.0 * c - 1.0)


def zernike_radial(n: int, m: int, rho: ArrayLike) -> np.ndarray:
    """Zernike radial polynomial R_n^m(rho) on the unit disk.

    Parameters
    ----------
    n, m : int
        Radial and azimuthal orders (``|m| <= n``, ``n - |m|`` even); the polynomial
        depends on ``|m|`` only.
    rho : array_like
        Radius on the unit disk [-], in [0, 1].

    Returns
    -------
    numpy.ndarray
        ``R_n^m(rho)`` [-]; ``R_n^m(1) = 1``.

    Raises
    ------
    ValueError
        For invalid indices or ``rho`` outside [0, 1] (NaN passes through).

    Notes
    -----
    KvD eq 3: ``R_n^m(rho) = sum_s (-1)^s (n-s)! / (s! ((n+m)/2-s)! ((n-m)/2-s)!)
    rho^(n-2s)``, evaluated through :func:`zernike_radial_of_cos` with
    ``cos(theta) = 1 - rho**2``.

    Examples
    --------
    >>> float(zernike_radial(2, 0, 0.5))   # 2 rho^2 - 1
    -0.5
    """
    r = np.asarray(rho, dtype=float)
    if np.any((r < 0.0) | (r > 1.0)):
        bad = float(r[(r < 0.0) | (r > 1.0)].flat[0])
        raise ValueError(f"rho = {bad:g} is outside the unit disk [0, 1]")
    return zernike_radial_of_cos(n, m, 1.0 - r * r)


def _check_polar(theta: np.ndarray, label: str) -> None:
    outside = (theta < 0.0) | (theta > 90.0)
    if np.any(outside):
        bad = float(theta[outside].flat[0])
        raise ValueError(f"{label} = {bad:g} deg is outside the hemisphere [0, 90] deg")


def hemisphere_radius(theta: ArrayLike) -> np.ndarray:
    """Radius on the unit disk of the direction with polar angle theta.

    Parameters
    ----------
    theta : array_like
        Polar angle [deg], in [0, 90].

    Returns
    -------
    numpy.ndarray
        ``rho = sqrt(2) sin(theta / 2)`` [-]: 0 at the normal, 1 at the horizon.

    Notes
    -----
    KvD eq 10-13: the map is area preserving up to the constant factor 2,
    ``rho d rho = sin(theta) d theta / 2``.

    Examples
    --------
    >>> float(hemisphere_radius(90.0))
    1.0
    """
    t = np.asarray(theta, dtype=float)
    _check_polar(t, "theta")
    return math.sqrt(2.0) * np.sin(np.radians(t) / 2.0)


def azimuthal_factor(l: int, phi: ArrayLike) -> np.ndarray:
    """Azimuthal factor az_l(phi) of KvD eq 5-7.

    Parameters
    ----------
    l : int
        Signed azimuthal order [-].
    phi : array_like
        Azimuth [deg].

    Returns
    -------
    numpy.ndarray
        ``cos(l phi)`` for l > 0, ``1/sqrt(2)`` for l = 0, ``sin(|l| phi)`` for l < 0.

    Notes
    -----
    The extracted text writes the l < 0 case as ``-sin(l phi)``, which is
    ``sin(|l| phi)``.  Normalisation (eq 8): the integral of ``az_k az_l`` over one turn is
    ``pi`` when k = l and 0 otherwise.  Parity (eq 9): ``az_l(phi + 180 deg) =
    (-1)^l az_l(phi)``.

    Examples
    --------
    >>> float(azimuthal_factor(-1, 90.0))
    1.0
    """
    l = operator_index(l)
    p = np.radians(np.asarray(phi, dtype=float))
    return _azimuthal_factor_rad(l, p)


def _azimuthal_factor_rad(l: int, phi: np.ndarray) -> np.ndarray:
    if l > 0:
        return np.cos(l * phi)
    if l < 0:
        return np.sin(-l * phi)
    return np.where(np.isnan(phi), np.nan, 1.0 / math.sqrt(2.0))


def hemisphere_basis(n: int, l: int, theta: ArrayLike, phi: ArrayLike) -> np.ndarray:
    """Orthonormal basis function K_n^l(theta, phi) on the hemisphere [1/sqrt(sr)].

    Parameters
    ----------
    n : int
        Radial order [-], ``n >= 0``.
    l : int
        Signed azimuthal order [-], ``|l| <= n``, ``n - |l|`` even.
    theta : array_like
        Polar angle [deg], in [0, 90].
    phi : array_like
        Azimuth [deg].

    Returns
    -------
    numpy.ndarray
        ``sqrt((n + 1) / pi) R_n^l(sqrt(2) sin(theta / 2)) az_l(phi)``.

    Notes
    -----
    KvD eq 15; orthonormal under the solid-angle measure (eq 16):
    ``integral K_n^k K_m^l dOmega = delta_nm delta_kl`` over the hemisphere, which the tests
    check by Gauss-Legendre quadrature in cos(theta) (exact for these polynomials).
    Figs 1 and 2 of the paper draw the functions up to n = 4.

    Examples
    --------
    >>> round(float(hemisphere_basis(0, 0, 10.0, 0.0)) ** 2 * 2 * np.pi, 12)   # 1/(2 pi) sr^-1
    1.0
    """
    n, l = check_zernike_indices(n, l, "n")
    t = np.asarray(theta, dtype=float)
    _check_polar(t, "theta")
    t_rad = np.radians(t)
    radial = zernike_radial_of_cos(n, l, np.cos(t_rad))
    return math.sqrt((n + 1) / math.pi) * radial * _azimuthal_factor_rad(l, np.radians(np.asarray(phi, float)))


def hemisphere_basis_indices(order: int) -> list[tuple[int, int]]:
    """All index pairs (n, l) of the basis K_n^l with n <= order.

    Parameters
    ----------
    order : int
        Highest radial order [-], ``>= 0``.

    Returns
    -------
    list of tuple of int
        ``(n, l)`` sorted by n then l; there are ``(order + 1)(order + 2)/2`` of them.

    Examples
    --------
    >>> hemisphere_basis_indices(2)
    [(0, 0), (1, -1), (1, 1), (2, -2), (2, 0), (2, 2)]
    """
    order = _check_order(order)
    return [(n, l) for n in range(order + 1) for l in range(-n, n + 1, 2)]


def _check_order(order: int) -> int:
    try:
        value = operator_index(order)
    except TypeError:
        raise ValueError(f"order = {order!r} must be a non-negative integer") from None
    if value < 0:
        raise ValueError(f"order = {value} is negative; valid orders are 0, 1, 2, ...")
    return value


def zernike_radial_table(order: int, cos_theta: ArrayLike) -> dict[tuple[int, int], np.ndarray]:
    """All radial polynomials R_n^l (0 <= l <= n <= order, n - l even) at once.

    Parameters
    ----------
    order : int
        Highest radial order [-], ``>= 0``.
    cos_theta : array_like
        Cosine of the polar angle [-].

    Returns
    -------
    dict
        ``{(n, l): R_n^l(sqrt(2) sin(theta/2))}``, the same values as
        :func:`zernike_radial_of_cos` (the tests require agreement to 1e-12).

    Notes
    -----
    The fast path of the series evaluations: for each l the Jacobi polynomials
    P_k^(l, 0)(2 cos(theta) - 1), k = 0, 1, ..., follow from the classical three-term
    recurrence (Abramowitz & Stegun 22.7.1 with alpha = l, beta = 0), so the whole table
    costs a few array operations per entry instead of one special-function call each.
    """
    order = _check_order(order)
    c = np.asarray(cos_theta, dtype=float)
    x = 2.0 * c - 1.0
    rho_squared = np.maximum(1.0 - c, 0.0)
    table: dict[tuple[int, int], np.ndarray] = {}
    rho_power = np.ones_like(c) + 0.0 * c  # rho**l, NaN where cos_theta is NaN
    for l in range(order + 1):
        if l:
            rho_power = rho_power * np.sqrt(rho_squared)
        previous, current = None, np.ones_like(c)
        for k in range((order - l) // 2 + 1):
            if k == 1:
                previous, current = current, 0.5 * ((l + 2) * x + l)
            elif k > 1:
                j = k - 1  # P_{j+1} from P_j and P_{j-1}
                s = 2 * j + l
                following = ((s + 1) * (s * (s + 2) * x + l * l) * current - 2 * j * (j + l) * (s + 2) * previous) / (
                    2 * (j + 1) * (j + l + 1) * s
                )
                previous, current = current, following
            table[(l + 2 * k, l)] = (-1.0 if k % 2 else 1.0) * rho_power * current
    return table
