"""Wolff's diffuse reflection model for smooth dielectrics.

Light refracts into a smooth dielectric, is scattered isotropically by inhomogeneities
beneath the surface and refracts back out.  The reflected radiance (Wolff, Nayar & Oren
1998, eq 7) is a scale factor times two Fresnel transmittances, one for entering at
theta_i and one for leaving towards theta_r, times the foreshortening cos(theta_i):

    L_r = scale * L_i (1 - F(theta_i, n)) cos(theta_i) (1 - F(asin(sin(theta_r)/n), 1/n)) d omega

so the BRDF is scale * (1 - F(theta_i, n)) (1 - F(asin(sin(theta_r)/n), 1/n)) [1/sr].

Registered models
-----------------
``wolff``
    Eq 7 as a BRDF.  Option ``scale`` chooses how the scale is set: ``"albedo"`` (a free
    albedo ``rho``, scale = rho/pi) or ``"physical"`` (eq 8, from the refractive index
    ``n`` and the single-scattering albedo ``omega`` through Chandrasekhar's H-function).
    Option ``fresnel`` chooses the exact Fresnel factor (eq 2) or its polynomial
    approximation (after eq 7).

``wolff-oren-nayar``
    The combined rough/smooth model of eq 9: the Oren-Nayar functional model (eq 3) with
    its C1 term multiplied by the two Fresnel transmittances of eq 7.

References
----------
L. B. Wolff, S. K. Nayar, M. Oren, "Improved diffuse reflection models for computer
vision", IJCV 30(1), 1998, eq 2, 3, 7, 8, 9 and sections 3-4.
L. B. Wolff, "A diffuse reflectance model for smooth dielectrics", JOSA A 11(11), 1994.
S. Chandrasekhar, *Radiative Transfer*, Dover 1960, ch. V.
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike

from ._core import Model, Option, Param, register
from ._trig import cos_from_half_tangent
from .chandrasekhar import DEFAULT_ORDER, _check_omega, h_function
from .oren_nayar.functional import SIGMA, _prepare_oren_nayar, c1
from .fresnel import (
    exit_transmittance,
    fresnel_polynomial,
    fresnel_reflectance,
    fresnel_transmittance,
    polynomial_epsilon,
)

__all__ = [
    "internal_cosine",
    "single_scattering_factor",
    "internal_reflection_integral",
    "physical_scale",
    "transmission_product",
    "scale_factor",
    "wolff_brdf",
    "wolff_oren_nayar_brdf",
    "WOLFF",
    "WOLFF_OREN_NAYAR",
]

RHO = Param(
    "rho", "-", 0.8, (0.0, 1.0),
    "albedo of the body beneath the interface; the BRDF is rho/pi times the two Fresnel "
    "transmittances (used when scale='albedo')",
)
N_INDEX = Param(
    "n", "-", 1.5, (1.0, math.inf),
    "refractive index of the dielectric relative to air", open_lower=True,
)
OMEGA = Param(
    "omega", "-", 0.95, (0.0, 1.0),
    "single-scattering albedo of the subsurface scatterers (used when scale='physical')",
)
SCALE = Option(
    "scale", "albedo", ("albedo", "physical"),
    "how the scale of eq 7 is set: free albedo rho ('albedo') or eq 8 from n and omega "
    "('physical')",
)
FRESNEL = Option(
    "fresnel", "exact", ("exact", "polynomial"),
    "Fresnel factor: exact eq 2 ('exact') or the polynomial approximation after eq 7 "
    "('polynomial')",
)

# Gauss-Legendre rule for the integral K of eq 8 (see internal_reflection_integral).
_K_NODES = 48


# ---------------------------------------------------------------------- eq 8 pieces
def internal_cosine(cos_theta: ArrayLike, n: float) -> np.ndarray:
    """Cosine of the refracted angle inside the dielectric [-].

    Parameters
    ----------
    cos_theta : array_like
        Cosine of the angle in air, in [0, 1].
    n : float
        Refractive index relative to air [-], > 1.

    Returns
    -------
    numpy.ndarray
        mu_bar = sqrt(1 - sin^2(theta)/n^2) (Snell's law; the mu_inc, mu_ref of eq 8 of
        Wolff, Nayar & Oren 1998).

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, eq 8 (mu_inc, mu_ref).

    Examples
    --------
    >>> round(float(internal_cosine(0.0, 1.5)), 6)   # grazing: the critical angle
    0.745356
    """
    cos_theta = np.clip(np.asarray(cos_theta, float), 0.0, 1.0)
    return np.sqrt(1.0 - (1.0 - cos_theta**2) / n**2)


def single_scattering_factor(
    mu_inc: ArrayLike, mu_ref: ArrayLike, n: float, omega: float, order: int = DEFAULT_ORDER
) -> np.ndarray:
    """The factor rho_1 of eq 8: diffuse reflection inside a semi-infinite medium [1/sr].

    Parameters
    ----------
    mu_inc, mu_ref : array_like
        Cosines of the refracted incident and viewing directions inside the dielectric.
    n : float
        Refractive index relative to air [-], > 1.
    omega : float
        Single-scattering albedo [-], in [0, 1].
    order : int, optional
        Order of the H-function approximation.

    Returns
    -------
    numpy.ndarray
        rho_1 = omega / (4 pi n^2) H(mu_inc) H(mu_ref) / (mu_inc + mu_ref) [1/sr].

    Notes
    -----
    Eq 8 of Wolff, Nayar & Oren (1998).  omega H H / (4 pi (mu + mu')) is Chandrasekhar's
    (1960, ch. V) reflection function of a semi-infinite medium of isotropic scatterers
    per unit incident irradiance; 1/n^2 is the change of radiance across the interface.

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, eq 8.
    S. Chandrasekhar, *Radiative Transfer*, Dover 1960, ch. V (reflection function).

    Examples
    --------
    >>> round(float(single_scattering_factor(1.0, 1.0, 1.5, 1.0)), 4)
    0.1495
    """
    mu_inc = np.asarray(mu_inc, float)
    mu_ref = np.asarray(mu_ref, float)
    h_product = h_function(mu_inc, omega, order) * h_function(mu_ref, omega, order)
    return omega / (4.0 * np.pi * n**2) * h_product / (mu_inc + mu_ref)


@lru_cache(maxsize=64)
def _k_rule(n: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes x = cos(phi'), weights and internal Fresnel reflectance for the K integral."""
    t, w = np.polynomial.legendre.leggauss(_K_NODES)
    t, w = 0.5 * (t + 1.0), 0.5 * w
    critical = math.sqrt(1.0 - 1.0 / n**2)  # cos of the critical angle inside
    # [0, critical]: total internal reflection, F = 1, smooth integrand.
    x_tir, w_tir = critical * t, critical * w
    # [critical, 1]: F ~ 1 - c sqrt(x - critical) near the critical angle; x = critical +
    # (1 - critical) t^2 makes the integrand smooth in t.
    x_out = critical + (1.0 - critical) * t**2
    w_out = 2.0 * (1.0 - critical) * t * w
    x = np.concatenate([x_tir, x_out])
    weights = np.concatenate([w_tir, w_out])
    reflectance = np.concatenate([np.ones_like(x_tir), fresnel_reflectance(x_out, 1.0 / n)])
    return x, weights, reflectance


def internal_reflection_integral(
    mu_ref: ArrayLike, n: float, omega: float, order: int = DEFAULT_ORDER
) -> np.ndarray:
    """The integral K of eq 8: internally reflected light scattered back up [-].

    Parameters
    ----------
    mu_ref : array_like
        Cosine of the refracted viewing direction inside the dielectric.
    n : float
        Refractive index relative to air [-], > 1.
    omega : float
        Single-scattering albedo [-], in [0, 1].
    order : int, optional
        Order of the H-function approximation.

    Returns
    -------
    numpy.ndarray
        K = int_0^{pi/2} F(phi', 1/n) C(cos phi', mu_ref) 2 pi sin phi' dphi' with
        C(x, y) = omega/(4 pi) x/(x + y) H(x) H(y), i.e.
        K = (omega/2) H(mu_ref) int_0^1 F(x, 1/n) x H(x)/(x + mu_ref) dx.

    Notes
    -----
    Eq 8 of Wolff, Nayar & Oren (1998).  Upwelling light inside the dielectric is partly
    reflected back down at the surface (F(., 1/n), total beyond the critical angle); the
    medium then reflects it up again towards mu_ref with Chandrasekhar's reflection
    function C.  Summing the repeated round trips as a geometric series gives the factor
    1/(1 - K) of eq 8.  The printed C carries a stray factor "L"; gonio reads C per unit
    radiance (L = 1), which is what makes eq 8 dimensionally consistent.

    The integral is split at the critical angle and evaluated with two 48-node
    Gauss-Legendre rules (the second after x = x_c + (1 - x_c) t^2, which removes the
    square-root onset of transmission); tests/models/test_wolff.py checks it against
    adaptive quadrature (``scipy.integrate.quad``).  K < 1 always: with F = 1 it would be
    the plane albedo 1 - sqrt(1 - omega) H(mu_ref) <= 1.

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, eq 8 (K and C_rho).
    S. Chandrasekhar, *Radiative Transfer*, Dover 1960, ch. V.

    Examples
    --------
    >>> round(float(internal_reflection_integral(1.0, 1.5, 1.0)), 3)
    0.579
    """
    mu_ref = np.asarray(mu_ref, float)
    x, weights, reflectance = _k_rule(float(n))
    h_x = h_function(x, omega, order)
    integrand = weights * reflectance * x * h_x / (x + mu_ref[..., None])
    return 0.5 * omega * h_function(mu_ref, omega, order) * np.sum(integrand, axis=-1)


@lru_cache(maxsize=1024)
def _physical_scale_normal(n: float, omega: float, order: int) -> float:
    rho_1 = single_scattering_factor(1.0, 1.0, n, omega, order)
    k = internal_reflection_integral(1.0, n, omega, order)
    return float(rho_1 / (1.0 - k))


def physical_scale(
    n: float,
    omega: float,
    theta_i: ArrayLike = 0.0,
    theta_r: ArrayLike = 0.0,
    order: int = DEFAULT_ORDER,
) -> np.ndarray:
    """The physical scale factor of the Wolff model, eq 8 [1/sr].

    Parameters
    ----------
    n : float
        Refractive index of the dielectric relative to air [-], > 1.
    omega : float
        Single-scattering albedo of the subsurface scatterers [-], in [0, 1].
    theta_i, theta_r : array_like, optional
        Incidence and viewing angles in air [deg] at which to evaluate eq 8 (default:
        normal incidence and viewing, the value the ``wolff`` model uses).
    order : int, optional
        Order N of the H-function approximation.

    Returns
    -------
    numpy.ndarray
        rho = rho_1 / (1 - K) [1/sr], to multiply the two Fresnel transmittances of eq 7.

    Raises
    ------
    ValueError
        If n <= 1 or omega is outside [0, 1].

    Notes
    -----
    Eq 8 of Wolff, Nayar & Oren (1998): rho_1 from :func:`single_scattering_factor` and K
    from :func:`internal_reflection_integral`, both at the refracted cosines
    mu_inc, mu_ref of theta_i, theta_r.  The paper says the factor may be treated as
    independent of theta_i and theta_r; the ``wolff`` model therefore uses its value at
    normal incidence and viewing, which keeps eq 7 exactly reciprocal.  How far the
    full expression moves with angle depends on omega: for omega = 1 it stays within
    5 % of the normal value (n in [1.3, 2]), for omega = 0.5 it rises by up to 30 %
    (n = 1.5) towards grazing, where the Fresnel factors already make the BRDF small
    (docs/wolff.md).  As a check of the reading of eq 8, a conservative medium
    (omega = 1) should return all the light it admits: the model's
    directional-hemispherical reflectance divided by 1 - F(theta_i, n) is 1.014 for
    n = 1.5 (tests/models/test_wolff.py).

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, eq 8 and the text after eq 7.
    L. B. Wolff, JOSA A 11(11), 1994 (derivation of the model).

    Examples
    --------
    >>> round(float(physical_scale(1.5, 1.0)), 3)
    0.355
    """
    n, omega = _check_index(n), _check_omega(omega)
    theta_i = np.asarray(theta_i, float)
    theta_r = np.asarray(theta_r, float)
    if theta_i.ndim == 0 and theta_r.ndim == 0 and theta_i == 0.0 and theta_r == 0.0:
        return np.asarray(_physical_scale_normal(n, omega, order))
    mu_inc = internal_cosine(np.cos(np.radians(theta_i)), n)
    mu_ref = internal_cosine(np.cos(np.radians(theta_r)), n)
    rho_1 = single_scattering_factor(mu_inc, mu_ref, n, omega, order)
    return rho_1 / (1.0 - internal_reflection_integral(mu_ref, n, omega, order))


def _check_index(n: float) -> float:
    value = float(n)
    if not value > 1.0:
        raise ValueError(
            f"n = {value:g} (refractive index relative to air) is outside its valid range (1, inf)"
        )
    return value


# ---------------------------------------------------------------------- eq 7
def transmission_product(
    theta_i: ArrayLike, theta_r: ArrayLike, n: float, fresnel: str = "exact"
) -> np.ndarray:
    """The two Fresnel transmittances of eq 7, (1 - F(theta_i, n)) (1 - F(theta_t', 1/n)) [-].

    Parameters
    ----------
    theta_i, theta_r : array_like
        Incidence and viewing angles in air [rad], in [0, pi/2].
    n : float
        Refractive index relative to air [-], > 1.
    fresnel : {"exact", "polynomial"}
        Exact Fresnel reflectance (eq 2) or the polynomial approximation after eq 7.

    Returns
    -------
    numpy.ndarray
        The product, 1 at most ((1 - F0)^2 at normal incidence and viewing), 0 at grazing.

    Notes
    -----
    theta_t' = asin(sin(theta_r)/n) is the internal angle that refracts into theta_r.
    With ``fresnel="polynomial"`` both factors use ((2x/pi)^5 + eps)/(1 + eps) with eps
    from :func:`gonio.models.fresnel.polynomial_epsilon`, the exit factor at x = theta_r
    (Fresnel reciprocity, see :func:`gonio.models.fresnel.fresnel_polynomial`).

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, eq 2, eq 7 and the polynomial after eq 7.

    Examples
    --------
    >>> round(float(transmission_product(0.0, 0.0, 1.5)), 4)
    0.9216
    """
    theta_i = np.asarray(theta_i, float)
    theta_r = np.asarray(theta_r, float)
    return _transmission_product(theta_i, theta_r, np.cos(theta_i), np.cos(theta_r), n, fresnel)


def _transmission_product(theta_i, theta_r, cos_i, cos_r, n: float, fresnel: str) -> np.ndarray:
    """:func:`transmission_product` from precomputed cosines (the fixed-geometry path)."""
    if fresnel == "polynomial":
        eps = polynomial_epsilon(n)
        return (1.0 - fresnel_polynomial(theta_i, eps)) * (1.0 - fresnel_polynomial(theta_r, eps))
    return fresnel_transmittance(cos_i, n) * exit_transmittance(cos_r, n)


def wolff_brdf(
    theta_i: ArrayLike,
    theta_r: ArrayLike,
    n: float,
    scale: float,
    fresnel: str = "exact",
) -> np.ndarray:
    """BRDF of Wolff's smooth-dielectric diffuse model [1/sr].

    Parameters
    ----------
    theta_i, theta_r : array_like
        Incidence and viewing angles [rad], in [0, pi/2].
    n : float
        Refractive index relative to air [-], > 1.
    scale : float
        The factor in front of eq 7 [1/sr]: rho/pi for a free albedo, or
        :func:`physical_scale` for eq 8.
    fresnel : {"exact", "polynomial"}
        Fresnel factor used in both transmittances.

    Returns
    -------
    numpy.ndarray
        scale (1 - F(theta_i, n)) (1 - F(asin(sin theta_r / n), 1/n)) [1/sr].

    Notes
    -----
    Eq 7 of Wolff, Nayar & Oren (1998) gives the reflected radiance
    scale L_i (1 - F_in) cos(theta_i) (1 - F_out) d omega; dividing by the irradiance
    L_i cos(theta_i) d omega gives this BRDF.  It depends on theta_i and theta_r only
    (no azimuth), and it is symmetric in them because 1 - F_out = 1 - F(theta_r, n).
    For the free-albedo scale rho/pi, rho is the albedo the body would have without its
    interface: the directional-hemispherical reflectance is
    rho (1 - F(theta_i, n)) T(n) <= rho, with T(n) the hemispherical transmittance
    (0.908 for n = 1.5), so the model conserves energy for rho <= 1.  This is also the
    sigma = 0 limit of the combined model of eq 9.

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, eq 7, Figs 4-5 and 8-9, section 4.

    Examples
    --------
    >>> round(float(wolff_brdf(0.0, 0.0, 1.5, 0.8 / np.pi)), 4)
    0.2347
    """
    return scale * transmission_product(theta_i, theta_r, n, fresnel)


def scale_factor(params, scale: str = "albedo") -> float:
    """The factor in front of eq 7 [1/sr] for the ``wolff`` model's parameter values:
    rho/pi (``scale="albedo"``) or :func:`physical_scale` at normal incidence and viewing
    from ``n`` and ``omega`` (``scale="physical"``)."""
    if scale == "albedo":
        return params["rho"] / np.pi
    return _physical_scale_normal(params["n"], params["omega"], DEFAULT_ORDER)


def _transmission_at(theta_i, theta_r, cos_i, cos_r, fresnel: str) -> Callable[[float], np.ndarray]:
    """:func:`_transmission_product` at fixed geometries as a function of n, remembering
    its value for the last scalar n: the Fresnel terms depend on the geometry and n only,
    so a fit with n fixed (or any repeated call) computes them once. An array n (an
    ensemble of walkers) is evaluated each time."""
    last: list = [None, None]

    def product(n) -> np.ndarray:
        if np.ndim(n):
            return _transmission_product(theta_i, theta_r, cos_i, cos_r, n, fresnel)
        if last[0] != float(n):
            last[:] = [float(n), _transmission_product(theta_i, theta_r, cos_i, cos_r, float(n), fresnel)]
        return last[1]

    return product


def _prepare(ti, pi_, tr, pr, scale: str = "albedo", fresnel: str = "exact") -> Callable[..., np.ndarray]:
    """Fixed-geometry evaluator of the ``wolff`` model (angles [rad])."""
    cos_i, cos_r = cos_from_half_tangent(ti), cos_from_half_tangent(tr)
    product = _transmission_at(np.asarray(ti, float), np.asarray(tr, float), cos_i, cos_r, fresnel)

    def evaluate(rho: float, n: float, omega: float) -> np.ndarray:
        return scale_factor({"rho": rho, "n": n, "omega": omega}, scale) * product(n)

    return evaluate


def _compiled_wolff():
    """The compiled plain call of ``wolff`` (numba loads here, on first use): eq 7 from
    :mod:`gonio.models.wolff_compiled` times :func:`scale_factor`."""
    from .wolff_compiled import wolff_plain

    def plain(theta_i, phi_i, theta_r, phi_r, params, options) -> np.ndarray:
        return wolff_plain(theta_i, phi_i, theta_r, phi_r, float(scale_factor(params, options["scale"])),
                           params["n"], options["fresnel"])

    return plain


WOLFF = register(
    Model(
        name="wolff",
        params=(RHO, N_INDEX, OMEGA),
        reference=(
            "Wolff, Nayar & Oren 1998, IJCV 30(1), eq 7 (diffuse radiance of a smooth "
            "dielectric), eq 2 and the polynomial after eq 7 (Fresnel), eq 8 (physical "
            "albedo factor with Chandrasekhar's H-function)"
        ),
        description="smooth-dielectric diffuse reflection: subsurface scattering between two Fresnel transmissions",
        prepare=_prepare,
        options=(SCALE, FRESNEL),
        # not linear_in=("rho",): under scale="physical" the BRDF does not depend on rho
        energy_conserving=True,
        reciprocal=True,
        isotropic=True,
        compiled=_compiled_wolff,
    )
)


# ---------------------------------------------------------------------- eq 9
RHO_ROUGH = Param(
    "rho", "-", 0.8, (0.0, 1.0),
    "albedo of the facets beneath their interface (the rho of eq 3)",
)


def _prepare_combined(ti, pi_, tr, pr, fresnel: str = "exact") -> Callable[..., np.ndarray]:
    """Fixed-geometry evaluator of ``wolff-oren-nayar`` (angles [rad])."""
    cos_i, cos_r = cos_from_half_tangent(ti), cos_from_half_tangent(tr)
    transmission = _transmission_at(np.asarray(ti, float), np.asarray(tr, float), cos_i, cos_r, fresnel)
    oren_nayar = _prepare_oren_nayar(ti, pi_, tr, pr)

    def evaluate(rho: float, sigma: float, n: float) -> np.ndarray:
        product = transmission(n)
        # eq 3 without interreflection, then C1 -> C1 * product (eq 9); a radiance cannot
        # be negative (see wolff_oren_nayar_brdf, Notes)
        direct = oren_nayar(rho, sigma, 0.0)
        return np.maximum(direct + (rho / np.pi) * float(c1(sigma)) * (product - 1.0), 0.0)

    return evaluate


def wolff_oren_nayar_brdf(
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_r: ArrayLike,
    phi_r: ArrayLike,
    rho: float,
    sigma: float,
    n: float,
    fresnel: str = "exact",
) -> np.ndarray:
    """BRDF of the combined rough/smooth diffuse model of Wolff, Nayar & Oren [1/sr].

    Parameters
    ----------
    theta_i, phi_i : array_like
        Source direction [rad], above the horizon.
    theta_r, phi_r : array_like
        Viewing direction [rad], above the horizon.
    rho : float
        Albedo [-], in [0, 1].
    sigma : float
        Oren-Nayar roughness, standard deviation of the facet slope angle [deg].
    n : float
        Refractive index relative to air [-], > 1.
    fresnel : {"exact", "polynomial"}
        Fresnel factor in the two transmittances.

    Returns
    -------
    numpy.ndarray
        f_r = (rho/pi) [C1(sigma) (1 - F(theta_i, n)) (1 - F(asin(sin theta_r / n), 1/n))
        + cos(dphi) C2 tan(beta) + (1 - |cos dphi|) C3 tan((alpha + beta)/2)] [1/sr].

    Notes
    -----
    Eq 9 of Wolff, Nayar & Oren (1998): in the direct-illumination Oren-Nayar radiance of
    eq 3 (Oren & Nayar 1995, eq 33), the Lambertian term C1 is multiplied by the two
    Fresnel transmittances of the Wolff model (eq 7).  C2, C3 and the tangents are those
    of eq 3, unchanged; as in eq 9, the interreflection term (eq 4) is not included.
    C1, C2 and C3 come from :mod:`gonio.models.oren_nayar.functional` (one
    implementation): the value is the ``oren-nayar`` BRDF without interreflection plus
    rho/pi C1 (T - 1), with T the transmittance product.

    Limits: sigma = 0 gives the ``wolff`` model with scale rho/pi exactly (C2 = C3 = 0,
    C1 = 1).  The transmittances are symmetric in theta_i and theta_r, so the model is
    reciprocal like eq 3.

    Negative values: eq 9 damps only the C1 term, which the transmittances drive to 0 at
    grazing incidence or viewing, while the C2 term of eq 3 is negative for forward
    scattering (cos dphi < 0).  Near the horizon on the far side of the normal the printed
    expression therefore turns negative: for n = 1.5 beyond max(theta_i, theta_r) = 87 deg
    at sigma = 5 deg, 78 deg at sigma = 20 deg, 70 deg at sigma = 40 deg (docs/wolff.md).
    A radiance cannot be negative, so gonio returns max(eq 9, 0) there.  The paper offers
    eq 9 for smooth to moderately rough surfaces (section 4: sigma below roughly 10-20 deg),
    where the affected region is a few degrees wide.

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, eq 3 and eq 9, section 4 and Fig. 16.
    M. Oren, S. K. Nayar, IJCV 14(3), 1995, eq 33.

    Examples
    --------
    >>> round(float(wolff_oren_nayar_brdf(0.0, 0.0, 0.0, 0.0, 0.8, 0.0, 1.5)), 4)
    0.2347
    """
    arrays = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))
    return _prepare_combined(*arrays, fresnel=fresnel)(rho, sigma, n)


WOLFF_OREN_NAYAR = register(
    Model(
        name="wolff-oren-nayar",
        params=(RHO_ROUGH, SIGMA, N_INDEX),
        reference=(
            "Wolff, Nayar & Oren 1998, IJCV 30(1), eq 9 (eq 3 with C1 times the Fresnel "
            "transmittances of eq 7); Oren & Nayar 1995, eq 33"
        ),
        description="rough dielectric: Oren-Nayar direct term with Wolff's Fresnel transmittances on C1",
        prepare=_prepare_combined,
        options=(FRESNEL,),
        energy_conserving=False,
        reciprocal=True,
        isotropic=True,
        linear_in=("rho",),
    )
)
