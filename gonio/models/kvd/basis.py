"""The isotropic reciprocal basis I_nml of Koenderink & van Doorn (1998).

A BRDF of an isotropic surface depends on the two polar angles and on the azimuth
difference only, and is symmetric under exchange of source and viewer.  KvD build an
orthonormal basis for exactly these functions from products of the hemisphere Zernike
functions (:mod:`gonio.zernike`): the symmetrised products H_nmkl (eq 20-23) and, for
isotropic surfaces, the functions

    I_nml(theta_i, theta_r, dphi) = 1/(2 pi) sqrt((n+1)(m+1)/A_nml)
        [R_n^l(rho_i) R_m^l(rho_r) + R_m^l(rho_i) R_n^l(rho_r)] cos(l dphi)      (eq 26)

with rho = sqrt(2) sin(theta/2), the normalisation A_nml of eq 27 and the index rules of
eq 30-31: 0 <= l <= m <= n, n - l and m - l even.  They are orthonormal under
dOmega_i dOmega_r on the product of two hemispheres, have units 1/sr, and the Lambertian
BRDF rho/pi is the lowest mode alone: rho/pi = 2 rho I_000 because I_000 = 1/(2 pi).

References
----------
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998, eq 17-31 and Tables 1-2.
"""
from __future__ import annotations

import functools
import math
from typing import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from gonio.zernike import (
    _check_order,
    check_zernike_indices,
    hemisphere_basis,
    operator_index,
    zernike_radial_table,
)

__all__ = [
    "Mode",
    "isotropic_indices",
    "check_isotropic_index",
    "isotropic_normalisation",
    "isotropic_basis",
    "reciprocal_product",
    "design_matrix",
]

#: An isotropic mode (n, m, l).
Mode = tuple[int, int, int]


def check_isotropic_index(n: int, m: int, l: int) -> Mode:
    """Validate an isotropic mode index (KvD eq 30-31) and return it as ints.

    Parameters
    ----------
    n, m, l : int
        Radial order of the first factor, radial order of the second factor and the
        azimuthal order [-].

    Returns
    -------
    tuple of int
        ``(n, m, l)``.

    Raises
    ------
    ValueError
        Unless ``0 <= l <= m <= n`` and ``n - l``, ``m - l`` are even.
    """
    try:
        n, m, l = (operator_index(v) for v in (n, m, l))
    except TypeError:
        raise ValueError(f"mode indices must be integers, got (n, m, l) = ({n!r}, {m!r}, {l!r})") from None
    if not 0 <= l <= m <= n or (n - l) % 2 or (m - l) % 2:
        raise ValueError(
            f"(n, m, l) = ({n}, {m}, {l}) is not an isotropic mode: need 0 <= l <= m <= n "
            "with n - l and m - l even (Koenderink & van Doorn 1998, eq 30-31)"
        )
    return n, m, l


def isotropic_indices(order: int) -> list[Mode]:
    """All isotropic modes (n, m, l) with n <= order, in the order of KvD Table 2.

    Parameters
    ----------
    order : int
        Highest radial order n [-], ``>= 0``.

    Returns
    -------
    list of tuple of int
        Modes sorted by n, then m, then l.

    Raises
    ------
    ValueError
        If ``order`` is negative or not an integer.

    Notes
    -----
    KvD eq 30-31 (Table 2 lists the 14 modes up to order 4).

    Examples
    --------
    >>> isotropic_indices(2)
    [(0, 0, 0), (1, 1, 1), (2, 0, 0), (2, 2, 0), (2, 2, 2)]
    """
    order = _check_order(order)
    return [
        (n, m, l)
        for n in range(order + 1)
        for m in range(n + 1)
        for l in range(m + 1)
        if (n - l) % 2 == 0 and (m - l) % 2 == 0
    ]


def isotropic_normalisation(n: int, m: int, l: int) -> int:
    """Normalisation A_nml of the isotropic basis (KvD eq 27).

    Parameters
    ----------
    n, m, l : int
        Mode indices (see :func:`check_isotropic_index`).

    Returns
    -------
    int
        4 if n = 0 or (n = m and l = 0); 2 if n = m or l = 0 (but not both); 1 otherwise.

    Notes
    -----
    The three cases follow from the squared norm of the bracket in eq 26: the two products
    coincide when n = m (factor 2 in amplitude, 4 in power, of which the radial
    orthogonality returns 2), and cos^2(l dphi) averages to 1/2 unless l = 0.  The tests
    check orthonormality by quadrature.

    Examples
    --------
    >>> [isotropic_normalisation(*mode) for mode in [(0, 0, 0), (2, 2, 2), (2, 0, 0), (3, 1, 1)]]
    [4, 2, 2, 1]
    """
    n, m, l = check_isotropic_index(n, m, l)
    if n == 0 or (n == m and l == 0):
        return 4
    if n == m or l == 0:
        return 2
    return 1


@functools.lru_cache(maxsize=None)
def _mode_scale(n: int, m: int, l: int) -> float:
    return math.sqrt((n + 1) * (m + 1) / isotropic_normalisation(n, m, l)) / (2.0 * math.pi)


def _check_hemisphere(theta: np.ndarray, label: str) -> None:
    outside = (theta < 0.0) | (theta > 90.0)
    if np.any(outside):
        bad = float(theta[outside].flat[0])
        raise ValueError(f"{label} = {bad:g} deg is outside the hemisphere [0, 90] deg")


def isotropic_basis(n: int, m: int, l: int, theta_i: ArrayLike, theta_r: ArrayLike, dphi: ArrayLike) -> np.ndarray:
    """Isotropic reciprocal basis function I_nml [1/sr] (KvD eq 26).

    Parameters
    ----------
    n, m, l : int
        Mode indices, ``0 <= l <= m <= n`` with ``n - l`` and ``m - l`` even.
    theta_i, theta_r : array_like
        Polar angles of source and viewer [deg], in [0, 90].
    dphi : array_like
        Azimuth difference phi_r - phi_i [deg]; only cos(l dphi) enters.

    Returns
    -------
    numpy.ndarray
        ``I_nml`` with the broadcast shape of the angles [1/sr].

    Notes
    -----
    KvD eq 26 with A_nml of eq 27.  Orthonormal under dOmega_i dOmega_r (eq 28-29),
    symmetric in (theta_i, theta_r) by construction.

    Examples
    --------
    >>> round(float(isotropic_basis(0, 0, 0, 30.0, 60.0, 90.0)) * 2 * np.pi, 12)
    1.0
    """
    n, m, l = check_isotropic_index(n, m, l)
    ti, tr, dp = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (theta_i, theta_r, dphi)))
    _check_hemisphere(ti, "theta_i")
    _check_hemisphere(tr, "theta_r")
    matrix = design_matrix([(n, m, l)], np.cos(np.radians(ti)).ravel(), np.cos(np.radians(tr)).ravel(), np.radians(dp).ravel())
    return matrix[:, 0].reshape(ti.shape)


def reciprocal_product(
    n: int, m: int, k: int, l: int, theta_i: ArrayLike, phi_i: ArrayLike, theta_r: ArrayLike, phi_r: ArrayLike
) -> np.ndarray:
    """Reciprocal (symmetrised) product basis H_nmkl [1/sr] (KvD eq 20-21).

    Parameters
    ----------
    n, k : int
        Radial and signed azimuthal order of the first hemisphere factor K_n^k.
    m, l : int
        Radial and signed azimuthal order of the second factor K_m^l.
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [deg].

    Returns
    -------
    numpy.ndarray
        ``[K_n^k(i) K_m^l(r) + K_n^k(r) K_m^l(i)] / sqrt(2 + 2 delta_nm delta_kl)``.

    Notes
    -----
    KvD eq 20-23: orthonormal under dOmega_i dOmega_r over the product of hemispheres and
    invariant under exchange of i and r.  The isotropic modes I_nml are combinations of
    H_nm(+-l)(+-l); for instance sum_k K_n^k(i) K_n^k(r) over k = +-l equals
    ``c_l I_nnl`` with c_0 = 1 and c_l = sqrt(2) for l > 0 (used for the mirror and the
    retroreflector, eq 32-39).

    Examples
    --------
    >>> round(float(reciprocal_product(0, 0, 0, 0, 10.0, 0.0, 20.0, 0.0)) * 2 * np.pi, 12)
    1.0
    """
    check_zernike_indices(n, k, "n")
    check_zernike_indices(m, l, "m")
    same = n == m and k == l
    forward = hemisphere_basis(n, k, theta_i, phi_i) * hemisphere_basis(m, l, theta_r, phi_r)
    backward = hemisphere_basis(n, k, theta_r, phi_r) * hemisphere_basis(m, l, theta_i, phi_i)
    return (forward + backward) / math.sqrt(2.0 + 2.0 * same)


def radial_table(orders: Iterable[tuple[int, int]], cos_theta: np.ndarray) -> dict[tuple[int, int], np.ndarray]:
    """R_n^l at the given cosines for every (n, l) in ``orders`` (one recurrence pass,
    :func:`gonio.zernike.zernike_radial_table`)."""
    orders = set(orders)
    highest = max((n for n, _ in orders), default=0)
    table = zernike_radial_table(highest, cos_theta)
    return {key: table[key] for key in orders}


def _cosines_of_multiples(x: np.ndarray, largest: int) -> dict[int, np.ndarray]:
    """cos(l x) for l = 0 .. ``largest`` by the Chebyshev recurrence
    cos(l x) = 2 cos(x) cos((l-1) x) - cos((l-2) x): one cosine instead of one per l (the
    recurrence is stable for |cos x| <= 1; its rounding grows like l ulp)."""
    x = np.asarray(x, float)
    out = {0: np.ones_like(x)}
    if largest >= 1:
        out[1] = np.cos(x)
    for l in range(2, largest + 1):
        out[l] = 2.0 * out[1] * out[l - 1] - out[l - 2]
    return out


def design_matrix(
    modes: Sequence[Mode], cos_i: np.ndarray, cos_r: np.ndarray, dphi_rad: np.ndarray
) -> np.ndarray:
    """Values of the modes at many geometries: one column per mode [1/sr].

    Parameters
    ----------
    modes : sequence of (n, m, l)
        Isotropic modes (already validated).
    cos_i, cos_r : numpy.ndarray
        Cosines of the source and viewing polar angles [-], 1-d, same length.
    dphi_rad : numpy.ndarray
        Azimuth difference [rad], same length.

    Returns
    -------
    numpy.ndarray
        Shape ``(len(cos_i), len(modes))``; column j is I_modes[j] (KvD eq 26).  The series
        value at the geometries is ``design_matrix(...) @ coefficients``: this is the one
        implementation of the series used by the model, the fits and the projections.
    """
    needed = [(n, l) for n, _, l in modes] + [(m, l) for _, m, l in modes]
    r_i = radial_table(needed, cos_i)
    r_r = radial_table(needed, cos_r)
    azimuthal = _cosines_of_multiples(dphi_rad, max(mode[2] for mode in modes))
    out = np.empty((np.size(cos_i), len(modes)))
    for j, (n, m, l) in enumerate(modes):
        bracket = r_i[(n, l)] * r_r[(m, l)] + r_i[(m, l)] * r_r[(n, l)]
        out[:, j] = _mode_scale(n, m, l) * bracket * azimuthal[l]
    return out
