"""One symmetric V-cavity of Lambertian facets: Oren & Nayar (1995) section 4.1.

A V-cavity is two long planar facets of equal slope ``theta_a`` facing opposite azimuths:
the facet considered has normal ``a = (theta_a, phi_a)`` and its neighbour
``a' = (theta_a, phi_a + pi)``, so that ``a + a' = 2 cos(theta_a) n`` (n the mean surface
normal).  Everything here is a pure function of angles in **radians** (this is the facet
level that the surface models integrate over; the registered models take degrees).

Quantities returned
-------------------
* :func:`projected_radiance` -- eq 10, a fully lit and fully visible facet;
* :func:`geometric_attenuation` -- eq 14-16 and Table 1 (GAF in [0, 1]);
* :func:`direct_projected_radiance` -- Table 1: GAF times eq 10;
* :func:`masked_width`, :func:`shadowed_width` -- eq 20-21;
* :func:`interreflection_kernel` -- eq 19; :func:`interreflection_factor` -- eq 24-25;
* :func:`interreflected_projected_radiance` -- eq 23/26, the two-bounce term;
* :func:`facet_brdf_terms` -- the two terms above as BRDF contributions (coefficients of
  rho and rho^2), written without divisions that can fail; this is what the surface
  models integrate.

Conventions
-----------
Projected radiance is the flux reflected by a facet divided by the *projected* (surface
plane) area of the facet, the viewing solid angle and cos(theta_r) (eq 7).  Radiances are
returned for a source of irradiance ``e0`` (E_0 of the paper, measured perpendicular to
the source direction) and facet albedo ``rho``.  The BRDF of a surface follows as
L / (E_0 cos theta_i).

References
----------
M. Oren, S. K. Nayar, "Generalization of the Lambertian model and implications for machine
vision", IJCV 14(3), 1995; tech. report CUCS-057-92 (rev. 1996), section 4.1, eq 7-26,
Table 1, Figures 5-9.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "projected_radiance",
    "geometric_attenuation",
    "direct_projected_radiance",
    "masked_width",
    "shadowed_width",
    "interreflection_kernel",
    "interreflection_factor",
    "interreflected_projected_radiance",
    "facet_brdf_terms",
    "facet_direct_term",
    "facet_interreflected_term",
]


def _dot_with_facet(theta: ArrayLike, phi: ArrayLike, theta_a: ArrayLike, phi_a: ArrayLike) -> np.ndarray:
    """<d, a> for the direction d = (theta, phi) and the facet normal a = (theta_a, phi_a)."""
    theta, phi, theta_a, phi_a = (np.asarray(x, dtype=float) for x in (theta, phi, theta_a, phi_a))
    return np.cos(theta) * np.cos(theta_a) + np.sin(theta) * np.sin(theta_a) * np.cos(phi - phi_a)


def _safe_ratio(numerator: np.ndarray, denominator: np.ndarray, where: np.ndarray, fill: float) -> np.ndarray:
    """numerator / denominator where ``where`` holds, ``fill`` elsewhere, without warnings."""
    numerator, denominator, where = np.broadcast_arrays(numerator, denominator, where)
    out = np.full(numerator.shape, fill, dtype=float)
    np.divide(numerator, denominator, out=out, where=where)
    return out


def projected_radiance(
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_r: ArrayLike,
    phi_r: ArrayLike,
    theta_a: ArrayLike,
    phi_a: ArrayLike,
    rho: float = 1.0,
    e0: float = 1.0,
) -> np.ndarray:
    """Projected radiance of a tilted Lambertian facet with no masking or shadowing.

    Parameters
    ----------
    theta_i, phi_i : array_like
        Source direction [rad].
    theta_r, phi_r : array_like
        Viewing direction [rad], theta_r < pi/2.
    theta_a, phi_a : array_like
        Facet normal [rad], theta_a < pi/2.
    rho : float, optional
        Facet albedo [-].
    e0 : float, optional
        Source irradiance perpendicular to the source direction [W/m^2].

    Returns
    -------
    numpy.ndarray
        L_rp [W/(m^2 sr)] (same unit as ``e0`` per sr).  Negative values mean the facet
        faces away from the source or the viewer; callers apply the GAF (Table 1).

    Notes
    -----
    Oren & Nayar eq 10: L_rp = rho/pi E_0 <s,a><v,a> / (<a,n><v,n>)
    = rho/pi E_0 cos(theta_i) cos(theta_a) (1 + tan(theta_i) tan(theta_a) cos(phi_i - phi_a))
    (1 + tan(theta_r) tan(theta_a) cos(phi_r - phi_a)).  It depends on the viewing direction
    even without masking and shadowing: a rough surface of Lambertian facets is not
    Lambertian.

    References
    ----------
    Oren & Nayar (1995), section 4.1, eq 9-10.

    Examples
    --------
    >>> float(projected_radiance(0.3, 0.0, 0.2, 1.0, 0.0, 0.0, rho=np.pi))  # flat facet
    0.955336489125606
    """
    s_a = _dot_with_facet(theta_i, phi_i, theta_a, phi_a)
    v_a = _dot_with_facet(theta_r, phi_r, theta_a, phi_a)
    return rho / np.pi * e0 * s_a * v_a / (np.cos(theta_a) * np.cos(theta_r))


def geometric_attenuation(
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_r: ArrayLike,
    phi_r: ArrayLike,
    theta_a: ArrayLike,
    phi_a: ArrayLike,
) -> np.ndarray:
    """Geometric attenuation factor (GAF) of a facet in a symmetric V-cavity.

    The fraction of the facet area that is both lit and visible.

    Parameters
    ----------
    theta_i, phi_i : array_like
        Source direction [rad], theta_i in [0, pi/2].
    theta_r, phi_r : array_like
        Viewing direction [rad], theta_r in [0, pi/2].
    theta_a, phi_a : array_like
        Facet normal [rad], theta_a in [0, pi/2]; the neighbouring facet is
        (theta_a, phi_a + pi).

    Returns
    -------
    numpy.ndarray
        GAF in [0, 1], broadcast shape of the inputs.

    Notes
    -----
    Oren & Nayar eq 15-16 (the long-cavity projection of eq 14):
    GAF = Max[0, Min[1, 2<s,n><a,n>/<s,a>, 2<v,n><a,n>/<v,a>]].  The order Max-outside,
    Min-inside is the corrected one (their footnote 6).  A facet turned away from the
    source (<s,a> <= 0) or from the viewer (<v,a> <= 0) gets GAF = 0: eq 15's ratios
    are negative there, and at exactly <s,a> = 0 (edge-on, where eq 15 divides by zero)
    the lit area is zero.  The cases of Table 1 are: 1 (neither), masking term, shadowing
    term.  The expression is symmetric in source and viewer.  At theta_i = pi/2 (or
    theta_r) every lit facet is fully shadowed (masked): GAF = 0.

    References
    ----------
    Oren & Nayar (1995), section 4.1.1, eq 11-16, Table 1, Figures 7-8; Torrance &
    Sparrow (1967) for the V-cavity geometry.

    Examples
    --------
    >>> float(geometric_attenuation(0.0, 0.0, 0.0, 0.0, 0.5, 0.0))  # normal view and light
    1.0
    >>> round(float(geometric_attenuation(np.radians(80), 0.0, 0.0, 0.0, np.radians(30), 0.0)), 4)
    0.4679
    """
    s_a = _dot_with_facet(theta_i, phi_i, theta_a, phi_a)
    v_a = _dot_with_facet(theta_r, phi_r, theta_a, phi_a)
    cos_a = np.cos(np.asarray(theta_a, dtype=float))
    lit = s_a > 0
    seen = v_a > 0
    shadowing = _safe_ratio(2.0 * np.cos(theta_i) * cos_a, s_a, lit, 0.0)
    masking = _safe_ratio(2.0 * np.cos(theta_r) * cos_a, v_a, seen, 0.0)
    gaf = np.minimum(1.0, np.minimum(shadowing, masking))
    return np.where(lit & seen, np.clip(gaf, 0.0, 1.0), 0.0)


def direct_projected_radiance(
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_r: ArrayLike,
    phi_r: ArrayLike,
    theta_a: ArrayLike,
    phi_a: ArrayLike,
    rho: float = 1.0,
    e0: float = 1.0,
) -> np.ndarray:
    """Projected radiance of a facet due to direct illumination, masking and shadowing included.

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad] (theta_r < pi/2).
    theta_a, phi_a : array_like
        Facet normal [rad] (theta_a < pi/2).
    rho : float, optional
        Facet albedo [-].
    e0 : float, optional
        Source irradiance [W/m^2].

    Returns
    -------
    numpy.ndarray
        L_rp^1 [W/(m^2 sr)], non-negative.

    Notes
    -----
    Oren & Nayar Table 1: L_rp^1 = GAF x eq 10, i.e. rho/pi E_0 <s,a><v,a>/(<a,n><v,n>)
    with no masking or shadowing, rho/pi E_0 2<s,a> under masking and
    rho/pi E_0 2<s,n><v,a>/<v,n> under shadowing.

    References
    ----------
    Oren & Nayar (1995), section 4.1.1, Table 1.

    Examples
    --------
    >>> l1 = direct_projected_radiance(1.3, 0.0, 0.2, 0.0, 0.6, 0.0, rho=np.pi)
    >>> round(float(l1), 6)
    0.502788
    """
    cos_i = np.cos(np.asarray(theta_i, dtype=float))
    cos_r = np.cos(np.asarray(theta_r, dtype=float))
    terms = facet_brdf_terms(
        cos_i, np.sin(theta_i), cos_r, np.sin(theta_r),
        np.cos(theta_a), np.sin(theta_a), np.cos(np.subtract(phi_a, phi_i)),
        np.cos(np.subtract(phi_a, phi_r)),
    )
    return rho * e0 * cos_i * terms[0]


def masked_width(theta_r: ArrayLike, phi_r: ArrayLike, theta_a: ArrayLike, phi_a: ArrayLike) -> np.ndarray:
    """Masked fraction m_v / w of a facet (measured from the bottom of the cavity).

    Parameters
    ----------
    theta_r, phi_r : array_like
        Viewing direction [rad].
    theta_a, phi_a : array_like
        Facet normal [rad]; the neighbour (theta_a, phi_a + pi) is the one that masks.

    Returns
    -------
    numpy.ndarray
        m_v / w in [0, 1]: the part of the facet next to the cavity bottom that the
        neighbouring facet hides from the viewer.  1 when the facet faces away from the
        viewer.

    Notes
    -----
    Oren & Nayar eq 20: m_v/w = Max[0, Min[1, -<a',v>/<a,v>]].  The paper calls m_v "the
    width visible to the viewer", but its integration limits (eq 22, x from m_v to w) and
    this expression both make m_v the *masked* width; gonio uses it that way.  Where
    <a,v> <= 0 (facet turned away) the ratio is not defined and the whole facet is hidden:
    1.

    References
    ----------
    Oren & Nayar (1995), section 4.1.2, eq 20, Figure 9.

    Examples
    --------
    >>> float(masked_width(0.0, 0.0, 0.4, 0.0))   # normal viewing: nothing is masked
    0.0
    """
    v_a = _dot_with_facet(theta_r, phi_r, theta_a, phi_a)
    v_a_neighbour = _dot_with_facet(theta_r, np.add(phi_r, np.pi), theta_a, phi_a)
    ratio = _safe_ratio(-v_a_neighbour, v_a, v_a > 0, 1.0)
    return np.clip(ratio, 0.0, 1.0)


def shadowed_width(theta_i: ArrayLike, phi_i: ArrayLike, theta_a: ArrayLike, phi_a: ArrayLike) -> np.ndarray:
    """Shadowed fraction m^s / w of the *neighbouring* facet (theta_a, phi_a + pi).

    Parameters
    ----------
    theta_i, phi_i : array_like
        Source direction [rad].
    theta_a, phi_a : array_like
        Normal of the facet considered [rad]; it casts the shadow on its neighbour.

    Returns
    -------
    numpy.ndarray
        m^s / w in [0, 1]: the part of the neighbouring facet, next to the cavity bottom,
        that lies in the shadow of the facet considered.  1 when the neighbour faces away
        from the source.

    Notes
    -----
    Oren & Nayar eq 21: m^s/w = Max[0, Min[1, -<a,s>/<a',s>]] (the paper's wording calls
    it the illuminated width; as for eq 20 the limits of eq 22 make it the shadowed one).

    References
    ----------
    Oren & Nayar (1995), section 4.1.2, eq 21, Figure 9.

    Examples
    --------
    >>> float(shadowed_width(0.0, 0.0, 0.4, 0.0))
    0.0
    """
    s_a = _dot_with_facet(theta_i, phi_i, theta_a, phi_a)
    s_a_neighbour = _dot_with_facet(theta_i, np.add(phi_i, np.pi), theta_a, phi_a)
    ratio = _safe_ratio(-s_a, s_a_neighbour, s_a_neighbour > 0, 1.0)
    return np.clip(ratio, 0.0, 1.0)


def interreflection_kernel(t: ArrayLike, r: ArrayLike, theta_a: ArrayLike) -> np.ndarray:
    """Two-dimensional radiative transfer kernel between the two facets of a V-cavity.

    Parameters
    ----------
    t, r : array_like
        Distances from the cavity bottom of the receiving and emitting points, in units of
        the facet width [-].
    theta_a : array_like
        Facet slope [rad].

    Returns
    -------
    numpy.ndarray
        K'(t, r) [1/width] such that L^2(t) = rho/pi integral K'(t, r) L^1(r) dr.

    Notes
    -----
    Oren & Nayar eq 19 (from Jakob 1957 / Forsyth & Zisserman 1989):
    K'(x, y) = pi sin^2(2 theta_a)/2 xy / (x^2 + 2 x y cos(2 theta_a) + y^2)^{3/2}; it is pi
    times the differential view factor between two infinitely long strips.  The
    denominator vanishes only at t = r = 0 (the cavity bottom), which is excluded.

    References
    ----------
    Oren & Nayar (1995), section 4.1.2, eq 18-19.

    Examples
    --------
    >>> round(float(interreflection_kernel(0.5, 0.5, np.pi / 4)), 6)
    1.110721
    """
    t, r, theta_a = (np.asarray(x, dtype=float) for x in (t, r, theta_a))
    distance_sq = t * t + 2.0 * t * r * np.cos(2.0 * theta_a) + r * r
    return np.pi * np.sin(2.0 * theta_a) ** 2 / 2.0 * t * r / distance_sq**1.5


def _cavity_distance(x: np.ndarray, y: np.ndarray, cos_2a: np.ndarray) -> np.ndarray:
    """d(x, y) of eq 25: distance between points x and y (facet widths) across the cavity."""
    return np.sqrt(np.maximum(x * x + 2.0 * x * y * cos_2a + y * y, 0.0))


def interreflection_factor(masked: ArrayLike, shadowed: ArrayLike, theta_a: ArrayLike) -> np.ndarray:
    """Interreflection factor IF of a V-cavity facet (closed form of the kernel integral).

    Parameters
    ----------
    masked : array_like
        m_v / w, masked fraction of the facet (eq 20) [-].
    shadowed : array_like
        m^s / w, shadowed fraction of the neighbouring facet (eq 21) [-].
    theta_a : array_like
        Facet slope [rad].

    Returns
    -------
    numpy.ndarray
        IF = integral over t in [m_v, 1], r in [m^s, 1] of K'(t, r) [-].

    Notes
    -----
    Oren & Nayar eq 24-25: IF = pi/2 [d(1, m_v) + d(1, m^s) - d(m^s, m_v) - d(1, 1)] with
    d(x, y) = sqrt(x^2 + 2 x y cos(2 theta_a) + y^2).  It follows from
    d^2 d(x, y)/dx dy = -xy sin^2(2 theta_a)/d^3.  With nothing masked or shadowed
    IF = pi (1 - cos theta_a), the first-order term of the approximation eq 48.

    References
    ----------
    Oren & Nayar (1995), section 4.1.2, eq 24-25.

    Examples
    --------
    >>> round(float(interreflection_factor(0.0, 0.0, np.radians(30))), 6)
    0.420894
    """
    m_v, m_s, theta_a = (np.asarray(x, dtype=float) for x in (masked, shadowed, theta_a))
    return _interreflection_factor(m_v, m_s, np.cos(2.0 * theta_a))


def _interreflection_factor(m_v: np.ndarray, m_s: np.ndarray, cos_2a: np.ndarray) -> np.ndarray:
    """Eq 24 from the two widths and cos(2 theta_a); d(1, 1) = sqrt(2 + 2 cos 2 theta_a)."""
    value = (
        _cavity_distance(1.0, m_v, cos_2a)
        + _cavity_distance(1.0, m_s, cos_2a)
        - _cavity_distance(m_s, m_v, cos_2a)
        - np.sqrt(np.maximum(2.0 + 2.0 * cos_2a, 0.0))
    )
    return np.maximum(np.pi / 2.0 * value, 0.0)


def interreflected_projected_radiance(
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_r: ArrayLike,
    phi_r: ArrayLike,
    theta_a: ArrayLike,
    phi_a: ArrayLike,
    rho: float = 1.0,
    e0: float = 1.0,
) -> np.ndarray:
    """Projected radiance of a facet due to two-bounce interreflection in its V-cavity.

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad] (theta_r < pi/2).
    theta_a, phi_a : array_like
        Facet normal [rad] (theta_a < pi/2).
    rho : float, optional
        Facet albedo [-].
    e0 : float, optional
        Source irradiance [W/m^2].

    Returns
    -------
    numpy.ndarray
        L_rp^2 [W/(m^2 sr)], non-negative.

    Notes
    -----
    Oren & Nayar eq 23 and 26: L_rp^2 = (rho/pi)^2 E_0 <a',s><a,v>/(<a,n><v,n>) IF, with
    IF of eq 24 evaluated at the masked width of the facet (eq 20) and the shadowed width
    of its neighbour (eq 21).  Zero when the neighbour is unlit or the facet unseen.  Only
    the light that the neighbour reflects once is counted (two bounces in total), as in
    the paper.

    References
    ----------
    Oren & Nayar (1995), section 4.1.2, eq 17-26.

    Examples
    --------
    >>> l2 = interreflected_projected_radiance(1.3, 0.0, 1.2, np.pi, 0.6, np.pi, rho=np.pi)
    >>> round(float(l2), 6)
    0.381863
    """
    cos_i = np.cos(np.asarray(theta_i, dtype=float))
    cos_r = np.cos(np.asarray(theta_r, dtype=float))
    terms = facet_brdf_terms(
        cos_i, np.sin(theta_i), cos_r, np.sin(theta_r),
        np.cos(theta_a), np.sin(theta_a), np.cos(np.subtract(phi_a, phi_i)),
        np.cos(np.subtract(phi_a, phi_r)),
    )
    return rho**2 * e0 * cos_i * terms[1]


def facet_brdf_terms(
    cos_i: ArrayLike,
    sin_i: ArrayLike,
    cos_r: ArrayLike,
    sin_r: ArrayLike,
    cos_a: ArrayLike,
    sin_a: ArrayLike,
    cos_dphi_i: ArrayLike,
    cos_dphi_r: ArrayLike,
) -> tuple[np.ndarray, np.ndarray]:
    """BRDF contributions of one V-cavity facet per unit projected area, from cosines.

    Parameters
    ----------
    cos_i, sin_i : array_like
        cos and sin of the source polar angle [-]; cos_i > 0.
    cos_r, sin_r : array_like
        cos and sin of the viewing polar angle [-]; cos_r > 0.
    cos_a, sin_a : array_like
        cos and sin of the facet slope theta_a [-]; cos_a > 0.
    cos_dphi_i, cos_dphi_r : array_like
        cos(phi_a - phi_i) and cos(phi_a - phi_r) [-].

    Returns
    -------
    direct, interreflected : numpy.ndarray
        g1 and g2 [1/sr] such that the facet's projected radiance is
        E_0 cos(theta_i) (rho g1 + rho^2 g2).

    Notes
    -----
    g1 = GAF <s,a><v,a> / (pi <a,n><s,n><v,n>) (Table 1, eq 10, 15), written as
    Min[<s,a><v,a>/<a,n>, 2<s,n><v,a>, 2<v,n><s,a>] / (pi <s,n><v,n>) for a facet facing
    both source and viewer, which needs no division by <s,a> or <v,a>;
    g2 = <a',s><a,v> IF / (pi^2 <a,n><s,n><v,n>) (eq 23, 26), zero where the neighbour is
    unlit or the facet unseen.  Uses <s,a> + <s,a'> = 2 <s,n><a,n>.  This is the integrand
    of the surface models (eq 8, 29, 46); gonio keeps it in one place.

    References
    ----------
    Oren & Nayar (1995), Table 1, eq 10, 15, 20-26.

    Examples
    --------
    >>> g1, g2 = facet_brdf_terms(1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 1.0)  # flat facet
    >>> float(g1) * np.pi, float(g2)
    (1.0, 0.0)
    """
    args = (cos_i, sin_i, cos_r, sin_r, cos_a, sin_a, cos_dphi_i, cos_dphi_r)
    return facet_direct_term(*args), facet_interreflected_term(*args)


def _facet_dots(cos_i, sin_i, cos_r, sin_r, cos_a, sin_a, cos_dphi_i, cos_dphi_r):
    """<s,a>, <s,a'>, <v,a>, <v,a'> from cosines (a' = (theta_a, phi_a + pi))."""
    cos_i, sin_i, cos_r, sin_r, cos_a, sin_a, cdi, cdr = (
        np.asarray(x, dtype=float)
        for x in (cos_i, sin_i, cos_r, sin_r, cos_a, sin_a, cos_dphi_i, cos_dphi_r)
    )
    flat_i = cos_i * cos_a
    flat_r = cos_r * cos_a
    tilt_i = sin_i * sin_a * cdi
    tilt_r = sin_r * sin_a * cdr
    return flat_i + tilt_i, flat_i - tilt_i, flat_r + tilt_r, flat_r - tilt_r


def facet_direct_term(cos_i, sin_i, cos_r, sin_r, cos_a, sin_a, cos_dphi_i, cos_dphi_r) -> np.ndarray:
    """g1 of :func:`facet_brdf_terms` alone (direct light, Table 1) [1/sr]."""
    s_a, _, v_a, _ = _facet_dots(cos_i, sin_i, cos_r, sin_r, cos_a, sin_a, cos_dphi_i, cos_dphi_r)
    lit_seen = (s_a > 0) & (v_a > 0)
    smallest = np.minimum(s_a * v_a / cos_a, np.minimum(2.0 * cos_i * v_a, 2.0 * cos_r * s_a))
    return np.where(lit_seen, smallest, 0.0) / (np.pi * cos_i * cos_r)


def facet_interreflected_term(cos_i, sin_i, cos_r, sin_r, cos_a, sin_a, cos_dphi_i, cos_dphi_r) -> np.ndarray:
    """g2 of :func:`facet_brdf_terms` alone (two-bounce light, eq 23-26) [1/sr]."""
    s_a, s_b, v_a, v_b = _facet_dots(cos_i, sin_i, cos_r, sin_r, cos_a, sin_a, cos_dphi_i, cos_dphi_r)
    neighbour_lit_seen = (s_b > 0) & (v_a > 0)
    masked = np.clip(_safe_ratio(-v_b, v_a, v_a > 0, 1.0), 0.0, 1.0)
    shadowed = np.clip(_safe_ratio(-s_a, s_b, s_b > 0, 1.0), 0.0, 1.0)
    factor = _interreflection_factor(masked, shadowed, np.multiply(cos_a, cos_a) - np.multiply(sin_a, sin_a))
    value = np.where(neighbour_lit_seen, s_b * v_a / cos_a * factor, 0.0)
    return value / (np.pi**2 * np.multiply(cos_i, cos_r))
