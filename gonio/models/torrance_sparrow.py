"""Torrance-Sparrow specular reflection from V-cavity mirror facets, and the combined
Oren-Nayar + Torrance-Sparrow model.

Two registered models:

``torrance-sparrow``
    Oren & Nayar (1995) eq 37: mirror facets with a Gaussian slope-area distribution of
    spread ``sigma_s``, the V-cavity geometric attenuation factor and a Fresnel factor
    (F = 1 as the paper fitted, or Fresnel reflectance from ``n``).
``oren-nayar+torrance-sparrow``
    Eq 38: kd times the Oren-Nayar diffuse model (eq 33-35) plus ks times the specular
    lobe.

Normalisation (a decision; the paper leaves the scale of eq 37 to the fitted ks)
---------------------------------------------------------------------------------
Eq 37 is the Torrance-Sparrow radiance written with the slope-area distribution
P(theta_a) = c exp(-theta_a^2 / (2 sigma^2)) of eq 32.  As a BRDF, the specular
reflection of mirror facets whose normal is the half vector h is

    f_s = ks F(<s,h>) GAF c exp(-theta_a^2 / (2 sigma_s^2)) / (4 cos(theta_i) cos(theta_r) cos(theta_a)),

where 4 <s,h> is the Jacobian between the solid angle of facet normals and of reflected
directions, and 1/cos(theta_a) converts the slope-area distribution to the distribution
of facet normals over projected area (section 3, eq 6).  gonio keeps the paper's own
normalisation: c makes P integrate to 1 over the hemisphere of facet normals (eq 32),
i.e. P(theta_a) is the fraction of the surface's projected area covered by facets of
each orientation.  ``ks`` is then the albedo of the mirror facets: with F = 1 the lobe
reflects the fraction ks of the incident power, minus what the V-cavity attenuation and
the horizon remove, so its directional-hemispherical reflectance never exceeds ks
(measured: docs/models.md).  At normal incidence it equals ks c M(sigma_s)
(:func:`normal_incidence_albedo`): ks itself for narrow lobes (0.9999 ks at
sigma_s = 8 deg, 0.998 ks at 10 deg), 0.832 ks at 20 deg, 0.41 ks at 42 deg, as facets
steeper than 45 deg mirror the source below the horizon and the GAF masks more.

The normalisation at normal incidence (dividing by c M instead, so that
rho_dh(0) = ks exactly) was measured and rejected: it makes broad lobes reflect up to
1/(c M) = 4 times ks near grazing incidence.

The paper's ks (eq 37-38) maps to gonio's as ks_gonio = 4 ks_paper with kd unchanged
(:func:`ks_over_kd_from_paper`).

References
----------
M. Oren, S. K. Nayar, "Generalization of the Lambertian model and implications for machine
vision", IJCV 14(3), 1995, section 3 (eq 6), section 4.1.1 (GAF, eq 15-16), eq 32,
section 5 (eq 37-38, Figs 20-22).
K. E. Torrance, E. M. Sparrow, "Theory for off-specular reflection from roughened
surfaces", JOSA 57(9), 1967 (the V-cavity specular model and its 1/(4 cos theta_r) factor).
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from ._core import Model, Option, Param, register
from .fresnel import fresnel_reflectance
from .oren_nayar.exact import _gaussian_slope_integral, slope_normalisation
from .oren_nayar.functional import RHO, SIGMA, _prepare_oren_nayar
from .oren_nayar.vcavity import geometric_attenuation

__all__ = [
    "slope_area_normalisation",
    "normal_incidence_albedo",
    "ks_over_kd_from_paper",
    "torrance_sparrow_brdf",
    "oren_nayar_torrance_sparrow_brdf",
    "TORRANCE_SPARROW",
    "OREN_NAYAR_TORRANCE_SPARROW",
]

KS = Param("ks", "-", 0.1, (0.0, 1.0), "specular weight: albedo of the mirror facets (lobe reflectance <= ks when F = 1)")
KD = Param("kd", "-", 1.0, (0.0, 1.0), "diffuse weight multiplying the Oren-Nayar BRDF")
SIGMA_S = Param(
    "sigma_s", "deg", 10.0, (0.0, 90.0),
    "specular roughness: standard deviation of the mirror-facet slope angle", open_lower=True,
)
N_INDEX = Param(
    "n", "-", 1.5, (1.0, math.inf),
    "refractive index of the surface medium relative to air (used when fresnel='dielectric')",
    open_lower=True,
)
FRESNEL = Option(
    "fresnel", "unity", ("unity", "dielectric"),
    "Fresnel factor of eq 37: F = 1 as in the paper's fits ('unity') or the Fresnel "
    "reflectance of a dielectric of index n ('dielectric')",
)


# ---------------------------------------------------------------- slope integrals
def _normal_incidence_attenuation(t: np.ndarray) -> np.ndarray:
    """GAF (eq 15) at normal incidence for the mirror direction 2t of facets of slope t [rad].

    Its kink is at t = pi/6, where 2 cos 2t = 1.
    """
    return geometric_attenuation(0.0, 0.0, 2.0 * t, 0.0, t, 0.0)


@lru_cache(maxsize=1024)
def _slope_area_normalisation_rad(sigma: float) -> float:
    return 1.0 / (2.0 * math.pi * slope_normalisation(sigma))


def slope_area_normalisation(sigma: float) -> float:
    """Constant c of Oren & Nayar eq 32 for a Gaussian slope-area distribution [1/sr].

    Parameters
    ----------
    sigma : float
        Standard deviation of the facet slope angle [deg], > 0.

    Returns
    -------
    float
        c with 1/c = 2 pi int_0^{pi/2} exp(-theta^2 / (2 sigma^2)) sin(theta) dtheta, so
        that P(theta_a) = c exp(-theta_a^2 / (2 sigma^2)) integrates to 1 over the
        hemisphere of facet normals (eq 32).  For small sigma, c -> 1/(2 pi sigma^2)
        (sigma in radians).

    Examples
    --------
    >>> round(slope_area_normalisation(20.0), 4)
    1.3601
    """
    return _slope_area_normalisation_rad(math.radians(float(sigma)))


def normal_incidence_albedo(sigma_s: float) -> float:
    """Directional-hemispherical reflectance of the unit lobe at normal incidence, F = 1 [-].

    Parameters
    ----------
    sigma_s : float
        Standard deviation of the facet slope angle [deg], > 0.

    Returns
    -------
    float
        c M with c from :func:`slope_area_normalisation` and
        M = 2 pi int_0^{45 deg} exp(-theta^2 / (2 sigma_s^2)) GAF_0(theta) sin(theta) dtheta,
        GAF_0 the V-cavity attenuation (eq 15) at normal incidence for the mirror direction
        2 theta.  The ``torrance-sparrow`` model reflects ks times this at normal
        incidence.

    Notes
    -----
    At normal incidence the reflected direction of a facet of slope theta is 2 theta, so
    facets steeper than 45 deg send light below the horizon (the upper limit), and the
    neighbouring facet masks the reflection when 2 cos(2 theta) < 1 (theta > 30 deg).

    Examples
    --------
    >>> round(normal_incidence_albedo(20.0), 4)
    0.8325
    """
    s = math.radians(float(sigma_s))
    masked = _gaussian_slope_integral(s, math.pi / 4.0, _normal_incidence_attenuation, kinks=(math.pi / 6.0,))
    return _slope_area_normalisation_rad(s) * 2.0 * math.pi * masked


def ks_over_kd_from_paper(ratio: ArrayLike) -> np.ndarray:
    """Convert a ks/kd ratio of Oren & Nayar's radiance formulation (eq 37-38) to gonio's.

    Parameters
    ----------
    ratio : array_like
        ks/kd as reported by the paper (Figs 20-22: foam 0.019, towel 0.085, wood
        shavings 0.043) [-].

    Returns
    -------
    numpy.ndarray
        ks/kd for ``oren-nayar+torrance-sparrow`` (``fresnel='unity'``, ``sigma_s`` equal
        to ``sigma`` as in the paper's fits): 4 times the paper's ratio.

    Notes
    -----
    Eq 38 combines radiances, L = kd L_d + ks L_s, with L_d = (rho/pi) E_0 cos(theta_i)
    [...] (eq 33) and L_s = F GAF c exp(-theta_a^2/(2 sigma^2)) / (cos theta_r cos theta_a)
    (eq 37), which carries no E_0.  Reading eq 37 as radiance per unit source irradiance
    (the only reading in which both weights are dimensionless), the paper's BRDF is
    kd f_ON + ks F GAF c exp(.) / (cos theta_i cos theta_r cos theta_a).  gonio's
    specular BRDF has the Torrance-Sparrow factor 1/4 (module notes), so the two agree
    when ks_gonio = 4 ks_paper and kd_gonio = kd_paper.  The paper's fits thus had
    specular albedos ks = 0.076 kd (foam, Fig. 20), 0.34 kd (towel, Fig. 21) and
    0.172 kd (wood shavings, Fig. 22); their normal-incidence reflectances
    (:func:`normal_incidence_albedo` at sigma = 20, 42, 26 deg) are 0.063, 0.138 and
    0.115 times kd.

    Examples
    --------
    >>> float(ks_over_kd_from_paper(0.019))
    0.076
    """
    return 4.0 * np.asarray(ratio, float)


# ---------------------------------------------------------------- geometry of the lobe
def _specular_geometry(theta_i, phi_i, theta_r, phi_r):
    """Half-vector slope theta_a, <s,h>, and GAF / (4 cos ti cos tr cos theta_a).  [rad]

    All three are symmetric in source and viewer (h = s + v, |s + v| / 2 = <s,h>), so the
    lobe is reciprocal to rounding.  Where the cosine product underflows to 0 the ratio is
    set to 0 (a direction exactly on the horizon given as an exact zero cosine: no
    irradiance and no projected area).
    """
    sin_i, sin_r = np.sin(theta_i), np.sin(theta_r)
    cos_i, cos_r = np.cos(theta_i), np.cos(theta_r)
    hx = sin_i * np.cos(phi_i) + sin_r * np.cos(phi_r)
    hy = sin_i * np.sin(phi_i) + sin_r * np.sin(phi_r)
    hz = cos_i + cos_r
    h_planar = np.hypot(hx, hy)
    theta_a = np.arctan2(h_planar, hz)
    phi_a = np.arctan2(hy, hx)
    cos_d = 0.5 * np.hypot(h_planar, hz)
    gaf = geometric_attenuation(theta_i, phi_i, theta_r, phi_r, theta_a, phi_a)
    denominator = 4.0 * cos_i * cos_r * np.cos(theta_a)
    gaf, denominator = np.broadcast_arrays(gaf, denominator)
    radial = np.zeros(gaf.shape)
    np.divide(gaf, denominator, out=radial, where=denominator > 0.0)
    return theta_a, cos_d, radial


def _prepare_torrance_sparrow(theta_i, phi_i, theta_r, phi_r, fresnel: str = "unity"):
    """Geometry-only terms of eq 37 (angles [rad]); returns f(ks, sigma_s, n)."""
    theta_a, cos_d, radial = _specular_geometry(theta_i, phi_i, theta_r, phi_r)
    slope_sq = theta_a * theta_a

    def evaluate(ks: float, sigma_s: float, n: float) -> np.ndarray:
        s = math.radians(sigma_s)
        lobe = np.exp(slope_sq * (-0.5 / (s * s)))
        lobe *= radial
        lobe *= ks * _slope_area_normalisation_rad(s)
        if fresnel == "dielectric":
            lobe *= fresnel_reflectance(cos_d, n)
        return lobe

    return evaluate


def torrance_sparrow_brdf(
    theta_i, phi_i, theta_r, phi_r, ks: float, sigma_s: float, n: float = 1.5, fresnel: str = "unity"
) -> np.ndarray:
    """Torrance-Sparrow specular lobe of V-cavity mirror facets, BRDF [1/sr].

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad], above the horizon.
    ks : float
        Specular weight [-]: the albedo of the mirror facets.  With F = 1 the lobe's
        directional-hemispherical reflectance is at most ks, and ks times
        :func:`normal_incidence_albedo` at normal incidence.
    sigma_s : float
        Standard deviation of the facet slope angle [deg], > 0.  gonio names it sigma_s
        (not sigma, which DESIGN.md reserves for the Oren-Nayar roughness) so that the
        combined model can give the two lobes different roughness.
    n : float, optional
        Refractive index [-] (only with ``fresnel="dielectric"``).
    fresnel : {"unity", "dielectric"}
        F = 1 (the paper's fits) or the Fresnel reflectance (WNO 1998 eq 2) at the angle
        between the source and the facet normal.

    Returns
    -------
    numpy.ndarray
        f_s = ks F GAF c exp(-theta_a^2 / (2 sigma_s^2)) /
        (4 cos(theta_i) cos(theta_r) cos(theta_a)) [1/sr], with theta_a the slope of the
        half vector and c the constant of eq 32 (:func:`slope_area_normalisation`).

    Notes
    -----
    Oren & Nayar (1995) eq 37 as a BRDF (module notes for the factor 4 and the
    normalisation).  The GAF is the V-cavity attenuation of eq 15-16
    (:func:`gonio.models.oren_nayar.vcavity.geometric_attenuation`) with the half vector
    as facet normal, the same roughness geometry as the diffuse model.  Helmholtz
    reciprocal: every factor is symmetric in source and viewer.

    References
    ----------
    Oren & Nayar (1995), section 5, eq 37; Torrance & Sparrow (1967).

    Examples
    --------
    >>> import numpy as np
    >>> peak = torrance_sparrow_brdf(np.radians(30), 0.0, np.radians(30), np.pi, 0.1, 5.0)
    >>> round(float(peak), 3)
    0.698
    """
    return _prepare_torrance_sparrow(theta_i, phi_i, theta_r, phi_r, fresnel)(ks, sigma_s, n)


def _prepare_combined(theta_i, phi_i, theta_r, phi_r, fresnel: str = "unity"):
    """Geometry terms of eq 38: the diffuse (eq 33-35) and specular (eq 37) preparations."""
    diffuse = _prepare_oren_nayar(theta_i, phi_i, theta_r, phi_r)
    specular = _prepare_torrance_sparrow(theta_i, phi_i, theta_r, phi_r, fresnel)

    def evaluate(rho: float, sigma: float, kd: float, ks: float, sigma_s: float, n: float) -> np.ndarray:
        out = diffuse(rho, sigma, 1.0)
        out *= kd
        out += specular(ks, sigma_s, n)
        return out

    return evaluate


def oren_nayar_torrance_sparrow_brdf(
    theta_i, phi_i, theta_r, phi_r, rho: float, sigma: float, kd: float, ks: float,
    sigma_s: float, n: float = 1.5, fresnel: str = "unity",
) -> np.ndarray:
    """Diffuse Oren-Nayar plus specular Torrance-Sparrow reflection, BRDF [1/sr].

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad], above the horizon.
    rho : float
        Albedo of the Lambertian facets of the diffuse term [-].
    sigma : float
        Oren-Nayar roughness [deg].
    kd, ks : float
        Diffuse and specular weights [-].
    sigma_s : float
        Roughness of the specular lobe [deg]; the paper used sigma_s = sigma.
    n : float, optional
        Refractive index for ``fresnel="dielectric"`` [-].
    fresnel : {"unity", "dielectric"}
        Fresnel factor of the specular term.

    Returns
    -------
    numpy.ndarray
        kd f_ON(rho, sigma) + ks f_s(sigma_s, n) [1/sr]: eq 33-35 (with interreflection,
        weight 1) plus :func:`torrance_sparrow_brdf` with unit ks.

    Notes
    -----
    Oren & Nayar (1995) eq 38, with the diffuse term the functional approximation of
    eq 33-34 (the paper fitted "the functional approximation", which its Fig. 13 defines
    as eq 33 with the interreflection of eq 34).  With ``fresnel="unity"`` the
    directional-hemispherical reflectance at normal incidence is
    kd rho_dh,ON(0) + ks c M(sigma_s) (:func:`normal_incidence_albedo`).  The paper's
    ks/kd map to gonio's (ks = 4 ks_paper) through
    :func:`ks_over_kd_from_paper`.

    References
    ----------
    Oren & Nayar (1995), section 5, eq 37-38, Figs 20-22.

    Examples
    --------
    >>> import numpy as np
    >>> f = oren_nayar_torrance_sparrow_brdf(np.radians(30), 0.0, 0.0, 0.0, 0.8, 20.0, 1.0, 0.0, 20.0)
    >>> round(float(f), 4)
    0.2371
    """
    return _prepare_combined(theta_i, phi_i, theta_r, phi_r, fresnel)(rho, sigma, kd, ks, sigma_s, n)


TORRANCE_SPARROW = register(
    Model(
        name="torrance-sparrow",
        params=(KS, SIGMA_S, N_INDEX),
        reference="Oren & Nayar 1995, section 5, eq 37 (Torrance & Sparrow 1967 with the V-cavity GAF of eq 15-16)",
        description="specular lobe of V-cavity mirror facets with Gaussian slopes (eq 32 normalisation, ks = facet albedo)",
        prepare=_prepare_torrance_sparrow,
        options=(FRESNEL,),
        energy_conserving=True,
        linear_in=("ks",),
    )
)

OREN_NAYAR_TORRANCE_SPARROW = register(
    Model(
        name="oren-nayar+torrance-sparrow",
        params=(RHO, SIGMA, KD, KS, SIGMA_S, N_INDEX),
        reference="Oren & Nayar 1995, section 5, eq 38 (eq 33-35 diffuse + eq 37 specular), Figs 20-22",
        description="rough diffuse Oren-Nayar plus Torrance-Sparrow specular lobe",
        prepare=_prepare_combined,
        options=(FRESNEL,),
        energy_conserving=False,
        linear_in=("kd", "ks"),
    )
)
