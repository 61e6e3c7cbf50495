"""Surfaces of V-cavities that all have one facet slope: Oren & Nayar (1995) 4.1, 4.2, App. A.

* :func:`unidirectional_radiance` -- all cavities aligned (azimuth phi_a), eq 28;
  anisotropic.
* Isotropic single-slope surface (cavity azimuths uniform in [0, 2 pi)), eq 29:

  - :func:`isotropic_brdf_terms` -- the phi_a-average of the facet terms of Table 1 and
    eq 26 by Gauss-Legendre panels between the critical azimuths (no approximation);
  - :func:`critical_azimuth` (eq 39), :func:`in_plane_direct_radiance` (eq 40-41),
    :func:`perpendicular_direct_radiance` (eq 42-43), the coefficients
    :func:`coefficient_a1`, :func:`coefficient_a2`, :func:`coefficient_a3` and
    :func:`isotropic_direct_radiance` (eq 45): the paper's closed form;
  - :func:`weighted_sum_radiance` -- the azimuthal interpolation of eq 44;
  - :func:`isotropic_interreflected_radiance` -- the approximation eq 48-49.

All angles in radians (facet-level functions); polar angles in [0, pi/2).

References
----------
M. Oren, S. K. Nayar, "Generalization of the Lambertian model and implications for machine
vision", IJCV 14(3), 1995; tech. report CUCS-057-92 (rev. 1996), section 4.1-4.2,
Appendix A (eq 28-30, 39-49, Table 2).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from .vcavity import (
    direct_projected_radiance,
    facet_direct_term,
    facet_interreflected_term,
    interreflected_projected_radiance,
)

__all__ = [
    "unidirectional_radiance",
    "critical_azimuth",
    "in_plane_direct_radiance",
    "perpendicular_direct_radiance",
    "coefficient_a1",
    "coefficient_a2",
    "coefficient_a3",
    "isotropic_direct_radiance",
    "weighted_sum_radiance",
    "isotropic_interreflected_radiance",
    "isotropic_brdf_terms",
    "azimuth_breakpoints",
]

_TWO_PI = 2.0 * np.pi


def _arrays(*values: ArrayLike) -> list[np.ndarray]:
    return [np.asarray(v, dtype=float) for v in values]


def unidirectional_radiance(
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_r: ArrayLike,
    phi_r: ArrayLike,
    theta_a: ArrayLike,
    phi_a: ArrayLike,
    rho: float = 1.0,
    e0: float = 1.0,
    interreflection: bool = True,
) -> np.ndarray:
    """Radiance of a surface of parallel V-cavities of one slope (anisotropic).

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad].
    theta_a : array_like
        Facet slope [rad].
    phi_a : array_like
        Azimuth of one facet normal [rad]; the cavity's other facet faces phi_a + pi, so
        the result is periodic in phi_a with period pi.
    rho : float, optional
        Facet albedo [-].
    e0 : float, optional
        Source irradiance [W/m^2].
    interreflection : bool, optional
        Include the two-bounce term of eq 26 (default) or only direct light.

    Returns
    -------
    numpy.ndarray
        L_r [W/(m^2 sr)].

    Notes
    -----
    Oren & Nayar eq 28: the two facet types have equal projected area, so the radiance is
    the mean of their projected radiances L_rp = L_rp^1 + L_rp^2 (Table 1, eq 26-27).

    References
    ----------
    Oren & Nayar (1995), section 4.1, eq 27-28.

    Examples
    --------
    >>> round(float(unidirectional_radiance(0.0, 0.0, 0.0, 0.0, 0.3, 0.0, rho=np.pi, interreflection=False)), 6)
    0.955336
    """
    total = 0.0
    for azimuth in (np.asarray(phi_a, dtype=float), np.add(phi_a, np.pi)):
        total = total + direct_projected_radiance(theta_i, phi_i, theta_r, phi_r, theta_a, azimuth, rho, e0)
        if interreflection:
            total = total + interreflected_projected_radiance(
                theta_i, phi_i, theta_r, phi_r, theta_a, azimuth, rho, e0
            )
    return total / 2.0


def critical_azimuth(theta: ArrayLike, theta_a: ArrayLike) -> np.ndarray:
    """Critical azimuth phi_c of shadowing (theta = theta_i) or masking (theta = theta_r).

    Parameters
    ----------
    theta : array_like
        Polar angle of the source or the viewer [rad].
    theta_a : array_like
        Facet slope [rad].

    Returns
    -------
    numpy.ndarray
        phi_c in [0, pi/2] [rad]: facets whose azimuth lies within phi_c of the source
        (viewer) azimuth are partly shadowed (masked), those within phi_c of the opposite
        azimuth are turned away (Table 2).

    Notes
    -----
    Oren & Nayar eq 39: phi_c = arccos(1 / (tan theta_a tan theta)) if
    tan theta_a tan theta > 1, else 0.  Computed as arccos(cos theta_a cos theta /
    Max[sin theta_a sin theta, cos theta_a cos theta]) so that grazing angles do not
    overflow.

    References
    ----------
    Oren & Nayar (1995), Appendix A.1, eq 39, Table 2.

    Examples
    --------
    >>> float(critical_azimuth(np.radians(30), np.radians(30)))
    0.0
    >>> round(float(np.degrees(critical_azimuth(np.radians(75), np.radians(40)))), 4)
    71.3776
    """
    theta, theta_a = _arrays(theta, theta_a)
    flat = np.cos(theta) * np.cos(theta_a)
    tilt = np.sin(theta) * np.sin(theta_a)
    scale = np.maximum(tilt, flat)
    cosine = np.ones(np.broadcast(flat, scale).shape)
    np.divide(flat, scale, out=cosine, where=scale > 0)
    return np.arccos(np.clip(cosine, 0.0, 1.0))


def coefficient_a1(alpha: ArrayLike, theta_a: ArrayLike) -> np.ndarray:
    """Coefficient A_1(alpha; theta_a) of eq 45 [-].

    Parameters
    ----------
    alpha : array_like
        Max[theta_i, theta_r] [rad].
    theta_a : array_like
        Facet slope [rad].

    Notes
    -----
    Oren & Nayar Appendix A.1: A_1 = tan(theta_a) 2 sin(phi_c^alpha)/pi +
    1/2 tan^2(theta_a) tan(alpha) (1 - (2 phi_c^alpha + sin(2 phi_c^alpha))/pi).

    Examples
    --------
    >>> round(float(coefficient_a1(0.5, 0.2)), 6)
    0.011224
    """
    alpha, theta_a = _arrays(alpha, theta_a)
    phi_c = critical_azimuth(alpha, theta_a)
    t_a = np.tan(theta_a)
    return t_a * 2.0 * np.sin(phi_c) / np.pi + 0.5 * t_a**2 * np.tan(alpha) * (
        1.0 - (2.0 * phi_c + np.sin(2.0 * phi_c)) / np.pi
    )


def coefficient_a2(beta: ArrayLike, delta_phi: ArrayLike, theta_a: ArrayLike) -> np.ndarray:
    """Coefficient A_2(beta, phi_r - phi_i; theta_a) of eq 45 [-].

    Notes
    -----
    Oren & Nayar Appendix A.1: A_2 = 2 phi_c^beta/pi - tan(theta_a) tan(beta)
    2 sin(phi_c^beta)/pi when cos(phi_r - phi_i) < 0, else 0.

    Examples
    --------
    >>> float(coefficient_a2(0.5, 0.0, 0.2))
    0.0
    """
    beta, delta_phi, theta_a = _arrays(beta, delta_phi, theta_a)
    phi_c = critical_azimuth(beta, theta_a)
    value = 2.0 * phi_c / np.pi - np.tan(theta_a) * np.tan(beta) * 2.0 * np.sin(phi_c) / np.pi
    return np.where(np.cos(delta_phi) < 0, value, 0.0)


def coefficient_a3(theta_r: ArrayLike, theta_i: ArrayLike, theta_a: ArrayLike) -> np.ndarray:
    """Coefficient A_3(theta_r, theta_i; theta_a) of eq 45 (overlap of shadow and mask) [-].

    Notes
    -----
    Oren & Nayar Appendix A.1 (from eq 43): 0 when phi_c^i + phi_c^r <= pi/2, else
    1/2 - (phi_c^i + phi_c^r)/pi + (sqrt(tan^2 theta_r tan^2 theta_a - 1) +
    sqrt(tan^2 theta_i tan^2 theta_a - 1) - tan theta_a sqrt(tan^2 theta_i + tan^2 theta_r))/pi.

    Examples
    --------
    >>> float(coefficient_a3(0.3, 0.3, 0.3))
    0.0
    """
    theta_r, theta_i, theta_a = _arrays(theta_r, theta_i, theta_a)
    phi_ci = critical_azimuth(theta_i, theta_a)
    phi_cr = critical_azimuth(theta_r, theta_a)
    t_a, t_i, t_r = np.tan(theta_a), np.tan(theta_i), np.tan(theta_r)
    root_r = np.sqrt(np.maximum(t_r**2 * t_a**2 - 1.0, 0.0))
    root_i = np.sqrt(np.maximum(t_i**2 * t_a**2 - 1.0, 0.0))
    value = 0.5 - (phi_ci + phi_cr) / np.pi + (root_r + root_i - t_a * np.sqrt(t_i**2 + t_r**2)) / np.pi
    return np.where(phi_ci + phi_cr > np.pi / 2.0, value, 0.0)


def in_plane_direct_radiance(
    theta_i: ArrayLike,
    theta_r: ArrayLike,
    theta_a: ArrayLike,
    same_side: bool,
    rho: float = 1.0,
    e0: float = 1.0,
) -> np.ndarray:
    """Direct radiance of the isotropic single-slope surface in the plane of incidence.

    Parameters
    ----------
    theta_i, theta_r : array_like
        Source and viewing polar angles [rad].
    theta_a : array_like
        Facet slope [rad].
    same_side : bool
        True for phi_r = phi_i (viewer on the source side, backward), False for
        phi_r = phi_i + pi (forward).
    rho, e0 : float, optional
        Facet albedo [-] and source irradiance [W/m^2].

    Returns
    -------
    numpy.ndarray
        L_rp||^1(theta_a) [W/(m^2 sr)].

    Notes
    -----
    Oren & Nayar eq 40 (phi_r = phi_i) and eq 41 (phi_r = phi_i + pi), written for
    theta_i >= theta_r; for theta_r > theta_i the paper swaps source and viewer inside the
    bracket, i.e. the bracket is a function of alpha = Max, beta = Min.  These are exact
    evaluations of eq 29 (tested against :func:`isotropic_brdf_terms`).

    References
    ----------
    Oren & Nayar (1995), Appendix A.1, eq 40-41.

    Examples
    --------
    >>> round(float(in_plane_direct_radiance(0.0, 0.0, 0.4, True, rho=np.pi)), 6)  # cos(theta_a)
    0.921061
    """
    theta_i, theta_r, theta_a = _arrays(theta_i, theta_r, theta_a)
    alpha, beta = np.maximum(theta_i, theta_r), np.minimum(theta_i, theta_r)
    phi_ca = critical_azimuth(alpha, theta_a)
    phi_cb = critical_azimuth(beta, theta_a)
    t_a = np.tan(theta_a)
    half_overlap = 0.5 * t_a**2 * np.tan(alpha) * np.tan(beta) * (1.0 - (2.0 * phi_ca + np.sin(2.0 * phi_ca)) / np.pi)
    if same_side:
        bracket = 1.0 + 2.0 * t_a * np.tan(beta) * np.sin(phi_ca) / np.pi + half_overlap
    else:
        bracket = (
            1.0
            - 2.0 * phi_cb / np.pi
            + 2.0 * t_a * np.tan(beta) * (np.sin(phi_cb) - np.sin(phi_ca)) / np.pi
            - half_overlap
        )
    return rho / np.pi * e0 * np.cos(theta_i) * np.cos(theta_a) * bracket


def perpendicular_direct_radiance(
    theta_i: ArrayLike, theta_r: ArrayLike, theta_a: ArrayLike, rho: float = 1.0, e0: float = 1.0
) -> np.ndarray:
    """Direct radiance of the isotropic single-slope surface for phi_r = phi_i +- pi/2.

    Parameters
    ----------
    theta_i, theta_r : array_like
        Source and viewing polar angles [rad].
    theta_a : array_like
        Facet slope [rad].
    rho, e0 : float, optional
        Facet albedo [-] and source irradiance [W/m^2].

    Returns
    -------
    numpy.ndarray
        L_rp-perp^1(theta_a) [W/(m^2 sr)].

    Notes
    -----
    Oren & Nayar eq 42 (shadowed and masked azimuth ranges disjoint,
    phi_c^i + phi_c^r <= pi/2) and eq 43 (overlapping): rho/pi E_0 cos theta_i
    cos theta_a (1 + A_3).

    References
    ----------
    Oren & Nayar (1995), Appendix A.1, eq 42-43.

    Examples
    --------
    >>> round(float(perpendicular_direct_radiance(0.2, 0.3, 0.4, rho=np.pi)), 6)
    0.902701
    """
    theta_i, theta_r, theta_a = _arrays(theta_i, theta_r, theta_a)
    bracket = 1.0 + coefficient_a3(theta_r, theta_i, theta_a)
    return rho / np.pi * e0 * np.cos(theta_i) * np.cos(theta_a) * bracket


def weighted_sum_radiance(in_plane: ArrayLike, perpendicular: ArrayLike, delta_phi: ArrayLike) -> np.ndarray:
    """Interpolate between the plane of incidence and the perpendicular plane.

    Parameters
    ----------
    in_plane : array_like
        Radiance in the plane of incidence on the side selected by the sign of
        cos(delta_phi) (eq 40 if cos >= 0, eq 41 otherwise).
    perpendicular : array_like
        Radiance in the perpendicular plane (eq 42-43).
    delta_phi : array_like
        phi_r - phi_i [rad].

    Returns
    -------
    numpy.ndarray
        |cos dphi| L|| + (1 - |cos dphi|) L-perp.

    Notes
    -----
    Oren & Nayar eq 44.  It is exact at dphi = 0, pi/2, pi; elsewhere an approximation
    (the paper reports a slight over-estimate near theta_r = theta_i at grazing; gonio
    measures it in tests/models/test_oren_nayar_single_slope.py).

    Examples
    --------
    >>> float(weighted_sum_radiance(2.0, 1.0, np.pi / 3))
    1.5
    """
    weight = np.abs(np.cos(np.asarray(delta_phi, dtype=float)))
    return weight * np.asarray(in_plane, dtype=float) + (1.0 - weight) * np.asarray(perpendicular, dtype=float)


def isotropic_direct_radiance(
    theta_i: ArrayLike,
    theta_r: ArrayLike,
    delta_phi: ArrayLike,
    theta_a: ArrayLike,
    rho: float = 1.0,
    e0: float = 1.0,
) -> np.ndarray:
    """Direct radiance of the isotropic single-slope surface, closed form of eq 45.

    Parameters
    ----------
    theta_i, theta_r : array_like
        Source and viewing polar angles [rad].
    delta_phi : array_like
        phi_r - phi_i [rad].
    theta_a : array_like
        Facet slope [rad].
    rho, e0 : float, optional
        Facet albedo [-] and source irradiance [W/m^2].

    Returns
    -------
    numpy.ndarray
        L_rp^1(theta_a) [W/(m^2 sr)].

    Notes
    -----
    Oren & Nayar eq 30 = eq 45: rho/pi E_0 cos theta_i cos theta_a [1 + cos(dphi)
    (A_1(alpha) tan beta + A_2(beta, dphi)) + (1 - |cos dphi|) A_3], the weighted sum
    eq 44 of eq 40-43 written with the coefficients A_1..A_3.  Exact in and perpendicular
    to the plane of incidence, approximate in between.

    References
    ----------
    Oren & Nayar (1995), eq 30, Appendix A.1, eq 44-45.

    Examples
    --------
    >>> round(float(isotropic_direct_radiance(0.0, 0.0, 0.0, 0.4, rho=np.pi)), 6)
    0.921061
    """
    theta_i, theta_r, delta_phi, theta_a = _arrays(theta_i, theta_r, delta_phi, theta_a)
    alpha, beta = np.maximum(theta_i, theta_r), np.minimum(theta_i, theta_r)
    cos_dphi = np.cos(delta_phi)
    bracket = (
        1.0
        + cos_dphi * (coefficient_a1(alpha, theta_a) * np.tan(beta) + coefficient_a2(beta, delta_phi, theta_a))
        + (1.0 - np.abs(cos_dphi)) * coefficient_a3(theta_r, theta_i, theta_a)
    )
    return rho / np.pi * e0 * np.cos(theta_i) * np.cos(theta_a) * bracket


def isotropic_interreflected_radiance(
    theta_i: ArrayLike,
    theta_r: ArrayLike,
    delta_phi: ArrayLike,
    theta_a: ArrayLike,
    rho: float = 1.0,
    e0: float = 1.0,
) -> np.ndarray:
    """Interreflected radiance of the isotropic single-slope surface, approximation eq 49.

    Parameters
    ----------
    theta_i, theta_r : array_like
        Source and viewing polar angles [rad].
    delta_phi : array_like
        phi_r - phi_i [rad].
    theta_a : array_like
        Facet slope [rad].
    rho, e0 : float, optional
        Facet albedo [-] and source irradiance [W/m^2].

    Returns
    -------
    numpy.ndarray
        L_rp^2(theta_a) [W/(m^2 sr)].

    Notes
    -----
    Oren & Nayar eq 49, which results from the approximation eq 48
    IF ~ pi (1 - cos theta_a)(1 - m^s)(1 - m_v) integrated over phi_a (eq 46):
    rho^2/pi E_0 cos theta_i cos theta_a (1 - cos theta_a) [1 - cos(dphi)
    (2 phi_c^beta/pi + 2 tan theta_a tan beta (sin phi_c^alpha - sin phi_c^beta)/pi
    + 1/2 tan^2 theta_a tan alpha tan beta (1 - (2 phi_c^alpha + sin 2 phi_c^alpha)/pi))].
    The paper gives no azimuthal rule other than the factor cos(dphi); gonio uses the
    expression as printed for every dphi.

    References
    ----------
    Oren & Nayar (1995), Appendix A.2, eq 46-49.

    Examples
    --------
    >>> round(float(isotropic_interreflected_radiance(0.0, 0.0, 0.0, 0.4, rho=np.pi) / np.pi), 6)
    0.072708
    """
    theta_i, theta_r, delta_phi, theta_a = _arrays(theta_i, theta_r, delta_phi, theta_a)
    alpha, beta = np.maximum(theta_i, theta_r), np.minimum(theta_i, theta_r)
    phi_ca = critical_azimuth(alpha, theta_a)
    phi_cb = critical_azimuth(beta, theta_a)
    t_a, t_b = np.tan(theta_a), np.tan(beta)
    inner = (
        2.0 * phi_cb / np.pi
        + 2.0 * t_a * t_b * (np.sin(phi_ca) - np.sin(phi_cb)) / np.pi
        + 0.5 * t_a**2 * np.tan(alpha) * t_b * (1.0 - (2.0 * phi_ca + np.sin(2.0 * phi_ca)) / np.pi)
    )
    cos_a = np.cos(theta_a)
    return rho**2 / np.pi * e0 * np.cos(theta_i) * cos_a * (1.0 - cos_a) * (1.0 - np.cos(delta_phi) * inner)


# --------------------------------------------------------------------------- exact eq 29
@lru_cache(maxsize=None)
def _unit_gauss_legendre(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(order)
    return (x + 1.0) / 2.0, w / 2.0


def _azimuth_kinks(cos_i, sin_i, cos_r, sin_r, delta_phi, cos_a, sin_a) -> tuple[np.ndarray, np.ndarray]:
    """The twelve kink azimuths phi_a - phi_i [rad] (unsorted) and their sharpness scales.

    Returns ``(kinks, scale)``, both of shape (..., 12).  ``scale`` is infinite except at
    the two azimuths where m^s = m_v: there d(m^s, m_v) of eq 25 behaves like
    sqrt((m^s - m_v)^2 + 4 m^s m_v cos^2 theta_a), a near-kink of half-width
    2 m cos(theta_a) / |d(m^s - m_v)/d phi_a|, which is returned (when 0 < m < 1).
    """
    theta_a = np.arctan2(sin_a, cos_a)
    phi_ci = critical_azimuth(np.arctan2(sin_i, cos_i), theta_a)
    phi_cr = critical_azimuth(np.arctan2(sin_r, cos_r), theta_a)
    # tan_i cos x = tan_r cos(x - d)  <=>  (s_i c_r - s_r c_i cos d) cos x - s_r c_i sin d sin x = 0
    a_coef = sin_i * cos_r - sin_r * cos_i * np.cos(delta_phi)
    b_coef = -sin_r * cos_i * np.sin(delta_phi)
    equal = np.arctan2(-a_coef, b_coef)
    # masked width of the facet = shadowed width of its neighbour (eq 20 = eq 21):
    # tan_i cos x = -tan_r cos(x - d)
    a_coef = sin_i * cos_r + sin_r * cos_i * np.cos(delta_phi)
    b_coef = sin_r * cos_i * np.sin(delta_phi)
    widths_equal = np.arctan2(-a_coef, b_coef)
    shape = np.broadcast_shapes(np.shape(phi_ci), np.shape(phi_cr), np.shape(equal))
    kinks = np.stack(
        [np.broadcast_to(k, shape) for k in (
            phi_ci, -phi_ci, np.pi + phi_ci, np.pi - phi_ci,
            delta_phi + phi_cr, delta_phi - phi_cr, delta_phi + np.pi + phi_cr, delta_phi + np.pi - phi_cr,
            equal, equal + np.pi, widths_equal, widths_equal + np.pi,
        )],
        axis=-1,
    )
    scale = np.full(kinks.shape, np.inf)
    x = kinks[..., 10:]
    flat_i, tilt_i = (cos_i * cos_a)[..., None], (sin_i * sin_a)[..., None]
    flat_r, tilt_r = (cos_r * cos_a)[..., None], (sin_r * sin_a)[..., None]
    s_a, s_b = flat_i + tilt_i * np.cos(x), flat_i - tilt_i * np.cos(x)
    v_a, v_b = flat_r + tilt_r * np.cos(x - delta_phi[..., None]), flat_r - tilt_r * np.cos(x - delta_phi[..., None])
    partial = (s_a < 0) & (s_b > 0) & (v_b < 0) & (v_a > 0)
    s_b_safe, v_a_safe = np.where(partial, s_b, 1.0), np.where(partial, v_a, 1.0)
    width = -s_a / s_b_safe
    slope = (2.0 * flat_i * tilt_i * np.sin(x) / s_b_safe**2
             + 2.0 * flat_r * tilt_r * np.sin(x - delta_phi[..., None]) / v_a_safe**2)
    half_width = np.full(x.shape, np.inf)
    np.divide(2.0 * width * cos_a[..., None], np.abs(slope), out=half_width, where=partial & (slope != 0))
    scale[..., 10:] = half_width
    return kinks, scale


def azimuth_breakpoints(
    cos_i: np.ndarray, sin_i: np.ndarray, cos_r: np.ndarray, sin_r: np.ndarray,
    delta_phi: np.ndarray, cos_a: np.ndarray, sin_a: np.ndarray,
) -> np.ndarray:
    """Azimuths phi_a - phi_i [rad] where the facet integrand of eq 29 has kinks.

    Parameters
    ----------
    cos_i, sin_i, cos_r, sin_r : numpy.ndarray
        cos/sin of the source and viewing polar angles.
    delta_phi : numpy.ndarray
        phi_r - phi_i [rad].
    cos_a, sin_a : numpy.ndarray
        cos/sin of the facet slope.

    Returns
    -------
    numpy.ndarray
        Shape (..., 13): the twelve kinks reduced to [0, 2 pi) and sorted, then the first
        one plus 2 pi (so the panels between them cover one period).

    Notes
    -----
    The kinks are the edges of the ranges of Table 2 (+-phi_c^i and pi +- phi_c^i around
    the source azimuth, the same with phi_c^r around the viewer's, eq 39); the two
    azimuths where shadowing and masking are equally strong,
    tan theta_i cos(phi_a - phi_i) = tan theta_r cos(phi_a - phi_r) (the angle gamma of
    eq 43, generalised to any dphi); and the two where the masked width equals the
    shadowed width of the neighbour (eq 20 = eq 21),
    tan theta_i cos(phi_a - phi_i) = -tan theta_r cos(phi_a - phi_r), near which
    d(m^s, m_v) of eq 25 is sharp for steep facets.  None depends on theta_a except
    through phi_c.  Between consecutive kinks the integrand is analytic.
    """
    kinks, _ = _azimuth_kinks(cos_i, sin_i, cos_r, sin_r, delta_phi, cos_a, sin_a)
    kinks = np.sort(np.mod(kinks, _TWO_PI), axis=-1)
    return np.concatenate([kinks, kinks[..., :1] + _TWO_PI], axis=-1)


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angle reduced to [-pi, pi)."""
    return np.mod(angle + np.pi, _TWO_PI) - np.pi


def _pole_distances(lo: np.ndarray, hi: np.ndarray, centre: np.ndarray, phi_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances from a panel's ends to the poles of a width ratio (eq 20 or 21).

    The shadowed width m^s/w = -<a,s>/<a',s> lies strictly between 0 and 1 for
    |phi_a - phi_i - pi| < phi_c^i and has poles at phi_a - phi_i = +-phi_c^i, i.e. at
    +-(pi - phi_c^i) from the centre of that range (likewise for m_v around phi_r).  For
    a panel inside the range the poles lie outside it, at the returned distances; for
    other panels the ratio is clipped to a constant and the distance is infinite.
    """
    mid = _wrap(0.5 * (lo + hi) - centre)
    inside = np.abs(mid) < phi_c
    start = mid - 0.5 * (hi - lo)
    end = mid + 0.5 * (hi - lo)
    reach = np.pi - phi_c
    left = np.where(inside, start + reach, np.inf)
    right = np.where(inside, reach - end, np.inf)
    return left, right


def _graded_nodes(lo, hi, left_gap, right_gap, order):
    """Nodes and weights on [lo, hi] graded towards poles just outside either end.

    The panel is halved; each half is mapped by the sinh transformation
    x = end +- gap sinh(mu u), mu = asinh(half-width / gap), u in [0, 1] (Johnston &
    Elliott, "Sinh transformation for evaluating nearly singular boundary element
    integrals", 2005), which removes the near-singularity of a pole at distance ``gap``
    beyond the end; far poles (gap >> width) give the plain Gauss-Legendre rule.
    """
    u, w = _unit_gauss_legendre(order)
    half = 0.5 * (hi - lo)
    nodes, weights = [], []
    for end, gap, sign in ((lo, left_gap, 1.0), (hi, right_gap, -1.0)):
        gap = np.clip(gap, 1e-12 * np.maximum(half, 1e-300), 1e3 * half + 1e-300)
        mu = np.arcsinh(half / gap)[..., None]
        gap = gap[..., None]
        grow = np.exp(mu * u)
        shrink = 1.0 / grow
        nodes.append(end[..., None] + sign * gap * 0.5 * (grow - shrink))
        weights.append(gap * mu * 0.5 * (grow + shrink) * w)
    return np.concatenate(nodes, axis=-1), np.concatenate(weights, axis=-1)


def isotropic_brdf_terms(
    cos_i: ArrayLike, sin_i: ArrayLike, cos_r: ArrayLike, sin_r: ArrayLike,
    delta_phi: ArrayLike, cos_a: ArrayLike, sin_a: ArrayLike, order: int = 8,
    interreflection_order: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Exact azimuthal average (eq 29, 46) of the facet BRDF terms of one slope.

    Parameters
    ----------
    cos_i, sin_i, cos_r, sin_r : array_like
        cos/sin of the source and viewing polar angles (cos > 0).
    delta_phi : array_like
        phi_r - phi_i [rad].
    cos_a, sin_a : array_like
        cos/sin of the facet slope theta_a (cos_a > 0).
    order : int, optional
        Gauss-Legendre nodes on each of the 12 panels between the kinks (direct term).
    interreflection_order : int, optional
        Nodes on each half panel for the interreflection term (default: ``order``).

    Returns
    -------
    direct, interreflected : numpy.ndarray
        h1, h2 [1/sr]: the isotropic single-slope surface has radiance
        E_0 cos(theta_i) (rho h1 + rho^2 h2).

    Notes
    -----
    h_k = 1/(2 pi) integral_0^{2 pi} g_k(phi_a) d phi_a with g_k of
    :func:`~gonio.models.oren_nayar.vcavity.facet_brdf_terms` (Table 1 with the exact GAF
    of eq 15 and the exact interreflection of eq 23-24), integrated by Gauss-Legendre on
    the panels of :func:`azimuth_breakpoints`; panels where a term vanishes (facet unseen,
    facet or neighbour unlit: the signs of <s,a>, <s,a'>, <v,a> are constant on a panel)
    are skipped.  The direct term is analytic on each panel (exponential convergence:
    order 6 gives ~1e-11).  The interreflection term contains the width ratios of eq 20-21,
    whose poles lie just outside some panels when the critical azimuths crowd (steep
    facets, grazing angles), and d(m^s, m_v) of eq 25 is nearly a kink where m^s = m_v for
    steep facets; such panels are halved and graded towards the pole by a sinh change of
    variable (see ``_graded_nodes``); convergence is then fast down to ~1e-8 and
    algebraic below.  This is the reference for the closed form eq 40-45 and for the
    approximation eq 49.

    References
    ----------
    Oren & Nayar (1995), eq 29, 46, Table 1-2.

    Examples
    --------
    >>> h1, h2 = isotropic_brdf_terms(1.0, 0.0, 1.0, 0.0, 0.0, np.cos(0.4), np.sin(0.4))
    >>> round(float(h1 * np.pi), 6)   # normal light and view: cos(theta_a)
    0.921061
    """
    arrays = np.broadcast_arrays(*_arrays(cos_i, sin_i, cos_r, sin_r, delta_phi, cos_a, sin_a))
    shape = arrays[0].shape
    cos_i, sin_i, cos_r, sin_r, delta_phi, cos_a, sin_a = (a.ravel() for a in arrays)
    kinks, scale = _azimuth_kinks(cos_i, sin_i, cos_r, sin_r, delta_phi, cos_a, sin_a)
    kinks = np.mod(kinks, _TWO_PI)
    order_idx = np.argsort(kinks, axis=-1)
    kinks = np.take_along_axis(kinks, order_idx, axis=-1)
    scale = np.take_along_axis(scale, order_idx, axis=-1)
    edges = np.concatenate([kinks, kinks[:, :1] + _TWO_PI], axis=-1)
    scale = np.concatenate([scale, scale[:, :1]], axis=-1)
    lo, hi = edges[:, :-1], edges[:, 1:]
    column = (lambda a: a[:, None])

    # Which panels contribute: the signs of <s,a>, <s,a'>, <v,a> are constant on a panel.
    mid = 0.5 * (lo + hi)
    flat_i, tilt_i = column(cos_i * cos_a), column(sin_i * sin_a) * np.cos(mid)
    flat_r, tilt_r = column(cos_r * cos_a), column(sin_r * sin_a) * np.cos(mid - column(delta_phi))
    nonempty = hi > lo
    seen = flat_r + tilt_r > 0
    direct_panels = np.nonzero(nonempty & seen & (flat_i + tilt_i > 0))
    bounce_panels = np.nonzero(nonempty & seen & (flat_i - tilt_i > 0))

    # direct term: analytic between kinks, plain Gauss-Legendre
    row = direct_panels[0]
    unit_x, unit_w = _unit_gauss_legendre(order)
    p_lo, p_width = lo[direct_panels][:, None], (hi - lo)[direct_panels][:, None]
    x = p_lo + p_width * unit_x
    g1 = facet_direct_term(
        column(cos_i[row]), column(sin_i[row]), column(cos_r[row]), column(sin_r[row]),
        column(cos_a[row]), column(sin_a[row]), np.cos(x), np.cos(x - column(delta_phi[row])),
    )
    direct = np.bincount(row, weights=(g1 * (p_width * unit_w)).sum(axis=-1), minlength=cos_i.size)

    # interreflection: poles of the width ratios (eq 20-21) and the m^s = m_v near-kink
    # lie just outside some panels; grade the nodes towards them
    row = bounce_panels[0]
    theta_a = np.arctan2(sin_a[row], cos_a[row])
    phi_ci = critical_azimuth(np.arctan2(sin_i[row], cos_i[row]), theta_a)
    phi_cr = critical_azimuth(np.arctan2(sin_r[row], cos_r[row]), theta_a)
    p_lo, p_hi = lo[bounce_panels], hi[bounce_panels]
    shadow_left, shadow_right = _pole_distances(p_lo, p_hi, np.pi, phi_ci)
    mask_left, mask_right = _pole_distances(p_lo, p_hi, delta_phi[row], phi_cr)
    left = np.minimum(np.minimum(shadow_left, mask_left), scale[:, :-1][bounce_panels])
    right = np.minimum(np.minimum(shadow_right, mask_right), scale[:, 1:][bounce_panels])
    n2 = order if interreflection_order is None else interreflection_order
    bounce = np.zeros(cos_i.size)
    width = p_hi - p_lo
    near = (left < width) | (right < width)
    for part, graded in ((np.nonzero(near)[0], True), (np.nonzero(~near)[0], False)):
        if part.size == 0:
            continue
        if graded:  # a pole within a panel width of an end: sinh-graded halves
            x2, w2 = _graded_nodes(p_lo[part], p_hi[part], left[part], right[part], n2)
        else:  # analytic well beyond the panel: plain Gauss-Legendre
            unit_x, unit_w = _unit_gauss_legendre(n2)
            x2 = p_lo[part][:, None] + width[part][:, None] * unit_x
            w2 = width[part][:, None] * unit_w
        r = row[part]
        g2 = facet_interreflected_term(
            column(cos_i[r]), column(sin_i[r]), column(cos_r[r]), column(sin_r[r]),
            column(cos_a[r]), column(sin_a[r]), np.cos(x2), np.cos(x2 - column(delta_phi[r])),
        )
        bounce += np.bincount(r, weights=(g2 * w2).sum(axis=-1), minlength=cos_i.size)
    return (direct / _TWO_PI).reshape(shape), (bounce / _TWO_PI).reshape(shape)
