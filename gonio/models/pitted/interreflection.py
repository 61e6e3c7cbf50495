"""Interreflection inside one spherical pit in closed form (Koenderink et al. 1999, eq 3-13).

Inside a sphere the mutual etendue of two surface elements does not depend on where they
are (eq 3), so the radiative balance of the cavity (eq 4-6) averages to an algebraic
equation (eq 8).  Every point of a pit therefore receives the same *diffuse* irradiance
from the rest of the pit, on top of its primary irradiance.

All irradiances here are per unit irradiance of the mega-scale plane, ``H_perp n.i = 1``;
multiply by ``H_perp cos(theta_i)`` for absolute values.

References
----------
J. J. Koenderink, A. J. van Doorn, K. J. Dana, S. K. Nayar, "Bidirectional reflection
distribution function of thoroughly pitted surfaces", IJCV 31(2/3), 1999, section 2.3.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "cavity_area_ratio",
    "mean_primary_irradiance",
    "mean_irradiance",
    "diffuse_irradiance",
    "diffuse_radiance",
    "diffuse_radiance_series",
    "diffuse_brdf",
    "pit_albedo",
]


def _half_angle_sin2(psi: ArrayLike) -> np.ndarray:
    return np.sin(np.radians(np.asarray(psi, float)) / 2.0) ** 2


def cavity_area_ratio(psi: ArrayLike) -> np.ndarray:
    """Area of the cavity divided by the area of its orifice [-].

    Parameters
    ----------
    psi : array_like
        Pit aperture [deg], 0 < psi <= 90.

    Returns
    -------
    numpy.ndarray
        ``4 sin^2(psi/2) / sin^2(psi)`` = ``1 / cos^2(psi/2)``: 2 for the hemisphere.

    Notes
    -----
    Koenderink et al. (1999) section 2: orifice area pi R^2 sin^2 psi, cavity area
    4 pi R^2 sin^2(psi/2).

    Examples
    --------
    >>> round(float(cavity_area_ratio(90.0)), 12)
    2.0
    """
    return 1.0 / np.cos(np.radians(np.asarray(psi, float)) / 2.0) ** 2


def mean_primary_irradiance(psi: ArrayLike) -> np.ndarray:
    """Average primary irradiance over the cavity, per unit plane irradiance [-].

    Parameters
    ----------
    psi : array_like
        Pit aperture [deg].

    Returns
    -------
    numpy.ndarray
        ``cos^2(psi/2)``.

    Notes
    -----
    Eq 10: the flux entering through the orifice spread over the cavity area.

    Examples
    --------
    >>> round(float(mean_primary_irradiance(90.0)), 12)
    0.5
    """
    return 1.0 - _half_angle_sin2(psi)


def mean_irradiance(rho: ArrayLike, psi: ArrayLike) -> np.ndarray:
    """Average total irradiance over the cavity, per unit plane irradiance [-].

    Parameters
    ----------
    rho : array_like
        Micro-scale Lambertian albedo [-].
    psi : array_like
        Pit aperture [deg].

    Returns
    -------
    numpy.ndarray
        ``cos^2(psi/2) / (1 - rho sin^2(psi/2))``.

    Notes
    -----
    Eq 9 with eq 10 for the mean primary irradiance.

    Examples
    --------
    >>> round(float(mean_irradiance(1.0, 90.0)), 12)
    1.0
    """
    return mean_primary_irradiance(psi) / (1.0 - np.asarray(rho, float) * _half_angle_sin2(psi))


def diffuse_irradiance(rho: ArrayLike, psi: ArrayLike) -> np.ndarray:
    """Diffuse (interreflected) irradiance, the same at every cavity point [-].

    Parameters
    ----------
    rho : array_like
        Micro-scale albedo [-].
    psi : array_like
        Pit aperture [deg].

    Returns
    -------
    numpy.ndarray
        ``rho sin^2(psi) / (4 (1 - rho sin^2(psi/2)))`` per unit plane irradiance.

    Notes
    -----
    Eq 11, the difference between the mean irradiance (eq 9) and the mean primary
    irradiance (eq 10).

    Examples
    --------
    >>> round(float(diffuse_irradiance(1.0, 90.0)), 12)
    0.5
    """
    rho = np.asarray(rho, float)
    psi_rad = np.radians(np.asarray(psi, float))
    return rho * np.sin(psi_rad) ** 2 / (4.0 * (1.0 - rho * _half_angle_sin2(psi)))


def diffuse_radiance(rho: ArrayLike, psi: ArrayLike) -> np.ndarray:
    """Radiance of the interreflected light leaving any cavity point [1/sr].

    Parameters
    ----------
    rho : array_like
        Micro-scale albedo [-].
    psi : array_like
        Pit aperture [deg].

    Returns
    -------
    numpy.ndarray
        ``rho^2 sin^2(psi) / (4 pi (1 - rho sin^2(psi/2)))`` per unit plane irradiance
        ``H_perp n.i`` [1/sr].

    Notes
    -----
    Eq 12 (eq 11 times rho/pi, eq 5).  It is also the radiance of the cast-shadow part
    of a pit, the narrow low mode of the radiance histogram (section 4.2).

    Examples
    --------
    >>> round(float(diffuse_radiance(1.0, 90.0)), 6)   # 1/(2 pi)
    0.159155
    """
    return np.asarray(rho, float) * diffuse_irradiance(rho, psi) / np.pi


def diffuse_radiance_series(rho: ArrayLike, psi: ArrayLike, orders: int = 5) -> np.ndarray:
    """Truncated multiple-scattering series of the diffuse radiance [1/sr].

    Parameters
    ----------
    rho : array_like
        Micro-scale albedo [-].
    psi : array_like
        Pit aperture [deg].
    orders : int
        Number of terms kept: scattering orders 2 .. orders + 1.

    Returns
    -------
    numpy.ndarray
        ``sin^2(psi)/(4 pi) sum_{k=0}^{orders-1} rho^(k+2) sin^(2k)(psi/2)``.

    Notes
    -----
    Eq 13: the geometric series of eq 12 in rho.  The k-th term is the light scattered
    k + 2 times; it starts at rho^2 because light must bounce at least twice to reach a
    point through interreflection.  ``orders=5`` is the five terms printed in eq 13.

    Examples
    --------
    >>> float(diffuse_radiance_series(0.5, 90.0, orders=60) - diffuse_radiance(0.5, 90.0)) < 1e-15
    True
    """
    if int(orders) < 1:
        raise ValueError(f"orders = {orders!r} must be a positive integer (number of series terms)")
    rho = np.asarray(rho, float)
    s2 = _half_angle_sin2(psi)
    k = np.arange(int(orders)).reshape((-1,) + (1,) * np.broadcast(rho, s2).ndim)
    terms = rho ** (k + 2) * s2**k
    psi_rad = np.radians(np.asarray(psi, float))
    return np.sin(psi_rad) ** 2 / (4.0 * np.pi) * terms.sum(axis=0)


def diffuse_brdf(rho: ArrayLike, psi: ArrayLike) -> np.ndarray:
    """Interreflection term of the pit BRDF [1/sr]: eq 12 per unit plane irradiance.

    The diffuse radiance is the same at every cavity point, so it contributes a constant
    (geometry-independent) term to the BRDF of the pit.  For the hemispherical pit this
    is ``rho^2 / (2 pi (2 - rho))``, the D of eq 29 and the forward-scattering limit
    of eq 30.

    Parameters
    ----------
    rho : array_like
        Micro-scale albedo [-].
    psi : array_like
        Pit aperture [deg].

    Returns
    -------
    numpy.ndarray
        [1/sr].

    Examples
    --------
    >>> round(float(diffuse_brdf(1.0, 90.0)), 6)
    0.159155
    """
    return diffuse_radiance(rho, psi)


def pit_albedo(rho: ArrayLike, psi: ArrayLike) -> np.ndarray:
    """Fraction of the flux entering a pit that leaves it again [-].

    Parameters
    ----------
    rho : array_like
        Micro-scale albedo [-].
    psi : array_like
        Pit aperture [deg].

    Returns
    -------
    numpy.ndarray
        ``rho cos^2(psi/2) / (1 - rho sin^2(psi/2))``, independent of the direction of
        incidence; 1 when rho = 1.

    Notes
    -----
    Derived from eq 9-10 (not printed in the paper): the cavity absorbs
    ``(1 - rho) <H> A_cavity`` of the flux ``<H_prim> A_cavity`` that enters, so the
    escaping fraction is ``1 - (1 - rho)/(1 - rho sin^2(psi/2))``.  It is the
    directional-hemispherical reflectance of a fully pitted surface, which the tests
    check against the quadrature of the BRDF.

    Examples
    --------
    >>> float(pit_albedo(1.0, 45.0))
    1.0
    """
    rho = np.asarray(rho, float)
    s2 = _half_angle_sin2(psi)
    return rho * (1.0 - s2) / (1.0 - rho * s2)
