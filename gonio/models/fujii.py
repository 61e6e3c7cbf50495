"""Fujii's form of the Oren-Nayar model ("FON"), the rough-diffuse lobe renderers use.

Fujii (2012) rewrote the qualitative Oren-Nayar model (eq 36 of Oren & Nayar 1995) in
vector form and, in a second step, gave it a new roughness parameter:

    f_r = (rho / pi) A (1 + r s/t),    A = 1 / (1 + (1/2 - 2/(3 pi)) r),

with s = cos(phi_r - phi_i) sin(theta_i) sin(theta_r) (= L.V - (N.L)(N.V)) and
t = max(cos theta_i, cos theta_r) where s > 0, t = 1 where s <= 0.  The roughness ``r``
(Fujii's sigma') is the ratio B/A of the non-Lambertian to the Lambertian term; the
normalisation of A makes the directional albedo exactly rho at grazing incidence, where
it is largest, so the model never reflects more than rho (Fujii's statement, checked in
tests/test_renderer_roughness.py).  This is the single-scattering lobe of the EON model
(Portsmouth, Kutz & Hill 2025, :mod:`gonio.models.eon`) and of OpenPBR's diffuse base,
whose ``base_diffuse_roughness`` is this ``r`` in [0, 1].

Relation to Oren & Nayar's sigma
--------------------------------
``r`` is not an angle and not a slope: it is a mixing ratio.  For s > 0, s/t =
cos(dphi) sin(alpha) tan(beta), the geometry factor of eq 36, so FON has the angular
shape of the qualitative model with B/A = r; Fujii obtained his A, B "matched to the
full Oren-Nayar model" as (with sigma in radians)

    A_ON = 1 - 0.5 sigma^2/(sigma^2 + 0.33) + 0.17 rho sigma^2/(sigma^2 + 0.13),
    B_ON = 0.45 sigma^2/(sigma^2 + 0.09),

i.e. eq 36 with the interreflection of eq 34 folded into A.  Their ratio is the
closed-form guess :func:`r_from_sigma_ratio`; the value that reproduces a V-cavity
surface best is measured in :mod:`gonio.models.roughness_conventions` and docs/roughness.md.
Unlike eq 36, FON keeps a negative s/t in the forward half-space (s < 0, t = 1), which
darkens forward scattering; r <= 1 keeps the BRDF non-negative (min s = -1), which is why
renderers bound it there.

References
----------
Y. Fujii, "A tiny improvement of Oren-Nayar reflectance model", 2012,
https://mimosa-pudica.net/improved-oren-nayar.html (the formula, the A, B matched to full
O-N, and the sigma' parameterisation with A = 1/(pi + (pi/2 - 2/3) sigma'), B = sigma' A).
J. Portsmouth, P. Kutz, S. Hill, "EON: A practical energy-preserving rough diffuse BRDF",
JCGT 14(1), 2025 (arXiv:2410.18026): the FON lobe and its exact directional albedo E_F
(the paper's code listing ``E_FON_exact``, github.com/portsmouth/EON-diffuse).
M. Oren, S. K. Nayar, IJCV 14(3), 1995, eq 34 and 36.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ._core import LinearForm, Model, Param, register, with_linear_form

__all__ = [
    "FON_C1",
    "FON_C2",
    "R",
    "RHO",
    "fujii_a",
    "fujii_albedo",
    "fujii_average_albedo",
    "fujii_oren_nayar_brdf",
    "r_from_sigma_ratio",
    "FUJII_OREN_NAYAR",
]

#: 1/2 - 2/(3 pi): A = 1/(1 + FON_C1 r), so that the albedo at grazing incidence is 1.
FON_C1 = 0.5 - 2.0 / (3.0 * math.pi)
#: 2/3 - 28/(15 pi): the cosine-weighted average albedo is A (1 + FON_C2 r).
FON_C2 = 2.0 / 3.0 - 28.0 / (15.0 * math.pi)

R = Param(
    "r", "-", 0.5, (0.0, 1.0),
    "Fujii roughness sigma' = B/A, ratio of the non-Lambertian to the Lambertian term (OpenPBR "
    "base_diffuse_roughness); not Oren-Nayar's sigma",
)
RHO = Param("rho", "-", 0.8, (0.0, 1.0), "albedo of the Lambertian facets (single-scattering albedo)")


# ---------------------------------------------------------------- formulas, in radians
def _s_over_t(theta_i, phi_i, theta_r, phi_r) -> np.ndarray:
    """Fujii's s/t [-]: s = cos(dphi) sin(theta_i) sin(theta_r); divided by
    max(cos theta_i, cos theta_r) where s > 0 (angles [rad], above the horizon)."""
    s = np.cos(np.subtract(phi_r, phi_i)) * (np.sin(theta_i) * np.sin(theta_r))
    t = np.cos(np.minimum(theta_i, theta_r))  # max of the cosines
    positive = s > 0.0
    # where s > 0 both polar angles are < 90 deg, so t > 0; elsewhere t = 1
    return np.where(positive, s / np.where(positive, t, 1.0), s)


def _g_over_pi(theta) -> np.ndarray:
    """G(theta)/pi of the exact FON albedo E_F = A (1 + r G/pi) [-], theta [rad] in [0, pi/2].

    G = sin(theta) (theta - sin theta cos theta) + (2/3) (tan(theta) (1 - sin^3 theta)
    - sin theta), written with tan(theta)(1 - sin^3) = sin cos (1 + sin + sin^2)/(1 + sin)
    (1 - sin = cos^2/(1 + sin)), which is finite and free of cancellation at grazing.
    G rises from 0 at normal incidence to pi/2 - 2/3 = pi FON_C1 at grazing.
    """
    sin, cos = np.sin(theta), np.cos(theta)
    g = sin * (theta - sin * cos) + (2.0 / 3.0) * sin * (cos * (1.0 + sin + sin * sin) / (1.0 + sin) - 1.0)
    return g / math.pi


def _a(r):
    """A(r) = 1/(1 + FON_C1 r) [-]."""
    return 1.0 / (1.0 + FON_C1 * r)


def _fujii_coefficients(rho, r) -> tuple:
    """(rho A/pi, rho A r/pi): the coefficients of the terms (1, s/t)."""
    lambertian = np.multiply(rho, _a(r)) / math.pi
    return lambertian, lambertian * r


def _prepare_fujii(theta_i, phi_i, theta_r, phi_r):
    """Geometry-only term s/t (angles [rad]); returns f(rho, r) = rho/pi A (1 + r s/t).

    Carries its exact two-term ``linear_form`` (terms 1 and s/t)."""
    s_over_t = _s_over_t(theta_i, phi_i, theta_r, phi_r)

    def evaluate(rho: float, r: float) -> np.ndarray:
        lambertian, shaped = _fujii_coefficients(rho, r)
        out = s_over_t * shaped
        out += lambertian
        return out

    return with_linear_form(evaluate, lambda: LinearForm(
        np.stack(np.broadcast_arrays(np.ones_like(s_over_t), s_over_t)), _fujii_coefficients))


# ---------------------------------------------------------------- public functions
def fujii_oren_nayar_brdf(theta_i, phi_i, theta_r, phi_r, rho: float, r: float) -> np.ndarray:
    """Fujii's Oren-Nayar BRDF (FON) [1/sr].

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad], above the horizon.
    rho : float or array_like
        Facet (single-scattering) albedo [-].
    r : float or array_like
        Fujii roughness sigma' in [0, 1] [-].

    Returns
    -------
    numpy.ndarray
        f_r = (rho/pi) A (1 + r s/t), A = 1/(1 + (1/2 - 2/(3 pi)) r) [1/sr].

    Notes
    -----
    Fujii (2012), the sigma' form; Portsmouth, Kutz & Hill (2025), the FON lobe f_ss of
    their listing ``f_EON``.  Reciprocal (s and t are symmetric in the two directions);
    r = 0 gives rho/pi exactly.  This is the plain-call form of the registered model
    ``fujii-oren-nayar``.

    References
    ----------
    Y. Fujii, "A tiny improvement of Oren-Nayar reflectance model", 2012.

    Examples
    --------
    >>> import numpy as np
    >>> float(fujii_oren_nayar_brdf(np.radians(30), 0.0, np.radians(50), np.pi, 0.6, 0.0)) * np.pi
    0.6
    """
    return _prepare_fujii(theta_i, phi_i, theta_r, phi_r)(rho, r)


def fujii_a(r: ArrayLike) -> np.ndarray:
    """Fujii's A = 1/(1 + (1/2 - 2/(3 pi)) r) [-]; B = r A.

    Parameters
    ----------
    r : array_like
        Fujii roughness [-].

    Examples
    --------
    >>> round(float(fujii_a(1.0)), 4)
    0.7765
    """
    return 1.0 / (1.0 + FON_C1 * np.asarray(r, float))


def fujii_albedo(theta: ArrayLike, r: ArrayLike) -> np.ndarray:
    """Exact directional albedo E_F(theta) of FON for rho = 1 [-].

    Parameters
    ----------
    theta : array_like
        Polar angle of incidence (or, by reciprocity, of exit) [deg], in [0, 90].
    r : array_like
        Fujii roughness [-].

    Returns
    -------
    numpy.ndarray
        E_F = A (1 + r G(theta)/pi), G = sin(theta)(theta - sin theta cos theta)
        + (2/3)(tan(theta)(1 - sin^3 theta) - sin theta) [-]; multiply by rho for an
        albedo rho.  E_F = A at normal incidence and 1 at grazing for every r.

    Notes
    -----
    Portsmouth, Kutz & Hill (2025): the analytic FON albedo (their ``E_FON_exact``),
    rewritten to be finite at theta = 90 deg.  tests/test_renderer_roughness.py checks it
    against a quadrature of the BRDF.

    Examples
    --------
    >>> round(float(fujii_albedo(90.0, 1.0)), 12)
    1.0
    """
    return fujii_a(r) * (1.0 + np.asarray(r, float) * _g_over_pi(np.radians(np.asarray(theta, float))))


def fujii_average_albedo(r: ArrayLike) -> np.ndarray:
    """Cosine-weighted average albedo <E_F> = 2 int_0^1 E_F(mu) mu dmu for rho = 1 [-].

    Parameters
    ----------
    r : array_like
        Fujii roughness [-].

    Returns
    -------
    numpy.ndarray
        A (1 + (2/3 - 28/(15 pi)) r): 1 at r = 0, 0.8328 at r = 1 (FON loses 16.7 % of
        the light it receives under uniform illumination at r = 1).

    Notes
    -----
    Portsmouth, Kutz & Hill (2025), the average FON albedo (``avgEF`` of their listing).

    Examples
    --------
    >>> round(float(fujii_average_albedo(1.0)), 4)
    0.8328
    """
    r = np.asarray(r, float)
    return fujii_a(r) * (1.0 + FON_C2 * r)


def r_from_sigma_ratio(sigma: ArrayLike, rho: ArrayLike) -> np.ndarray:
    """Fujii's r as the ratio B/A of his coefficients matched to full Oren-Nayar [-].

    Parameters
    ----------
    sigma : array_like
        Oren-Nayar roughness, standard deviation of the facet slope angle [deg].
    rho : array_like
        Facet albedo [-] (enters through the interreflection term folded into A).

    Returns
    -------
    numpy.ndarray
        r = 0.45 s/(s + 0.09) / (1 - 0.5 s/(s + 0.33) + 0.17 rho s/(s + 0.13)),
        s = sigma^2 [rad^2].  A closed-form guess only: it keeps the shape ratio of the
        matched coefficients but not their overall brightness, and FON's forward
        darkening differs from Oren-Nayar's (module notes).

    Notes
    -----
    Fujii (2012), the A and B "matched to full O-N" (Oren & Nayar 1995 eq 33-34 folded into
    the form of eq 36), combined with the sigma' parameterisation where B/A = sigma'.  Values
    above 1 (sigma >~ 60 deg) leave the range renderers accept.

    Examples
    --------
    >>> round(float(r_from_sigma_ratio(30.0, 0.9)), 3)
    0.386
    """
    s = np.radians(np.asarray(sigma, float)) ** 2
    a = 1.0 - 0.5 * s / (s + 0.33) + 0.17 * np.asarray(rho, float) * s / (s + 0.13)
    return 0.45 * s / (s + 0.09) / a


FUJII_OREN_NAYAR = register(
    Model(
        name="fujii-oren-nayar",
        params=(RHO, R),
        reference=("Fujii 2012, 'A tiny improvement of Oren-Nayar reflectance model' (sigma' form, "
                   "A = 1/(1 + (1/2 - 2/(3 pi)) r), B = r A); Portsmouth, Kutz & Hill 2025 (JCGT), FON lobe"),
        description="rough diffuse surface: Fujii's Oren-Nayar form (FON), renderers' single-scattering lobe",
        prepare=_prepare_fujii,
        energy_conserving=True,
        linear_in=("rho",),
        broadcasts_params=True,
    )
)
