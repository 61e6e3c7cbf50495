"""EON: the energy-preserving Oren-Nayar BRDF of Portsmouth, Kutz & Hill (2025).

EON is Fujii's Oren-Nayar lobe (FON, :mod:`gonio.models.fujii`) plus a reciprocal
multiple-scattering lobe that returns the light FON loses:

    f = f_FON + (rho_ms / pi) (1 - E_F(theta_i)) (1 - E_F(theta_r)) / (1 - <E_F>),
    rho_ms = rho^2 <E_F> / (1 - rho (1 - <E_F>)),

with E_F the exact directional albedo of FON for rho = 1 and <E_F> its cosine-weighted
average (:func:`~gonio.models.fujii.fujii_albedo`,
:func:`~gonio.models.fujii.fujii_average_albedo`).  The directional albedo of EON is
rho E_F + rho_ms (1 - E_F), which is 1 for every incidence and roughness when rho = 1
(the white-furnace test; tests/test_renderer_roughness.py integrates the BRDF to check
it).  Roughness ``r`` in [0, 1] is Fujii's sigma' (OpenPBR ``base_diffuse_roughness``),
``rho`` the single-scattering albedo; r = 0 is Lambert.

Which version: the *exact* one.  The paper gives E_F in closed form (its ``E_FON_exact``)
and, for speed, a quartic fit (``E_FON_approx``); gonio evaluates the closed form.  The
paper's listing guards the divisions with max(1e-7, 1 - E); gonio cancels the common
factor A r from 1 - E_F(theta) = A r (c1 - G(theta)/pi) and 1 - <E_F> = A r (c1 - c2)
instead, so the lobe is

    f_ms = (rho_ms / pi) A r (c1 - G(theta_i)/pi) (c1 - G(theta_r)/pi) / (c1 - c2),

the same function wherever the listing's guard is inactive and continuous down to r = 0
(c1 = 1/2 - 2/(3 pi), c2 = 2/3 - 28/(15 pi)).

Renderers: OpenPBR's diffuse base (spec section "Glossy-diffuse", equations EON_brdf,
FON_brdf, EON_comp) and the MaterialX/OSL ``oren_nayar_diffuse_bsdf`` closure with
``energy_compensation`` on.  The OpenPBR text (v1.1.1) prints rho_ms with an extra
factor 1/pi that the paper and its code do not have; with it the white-furnace test fails,
so gonio follows the paper.

References
----------
J. Portsmouth, P. Kutz, S. Hill, "EON: A practical energy-preserving rough diffuse BRDF",
Journal of Computer Graphics Techniques 14(1), 2025 (arXiv:2410.18026); reference code
github.com/portsmouth/EON-diffuse, main.glsl (``f_EON``, ``E_EON``, ``E_FON_exact``).
Y. Fujii, "A tiny improvement of Oren-Nayar reflectance model", 2012.
OpenPBR Surface specification v1.1, Academy Software Foundation, section on the
glossy-diffuse base.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ._core import LinearForm, Model, register, with_linear_form
from .fujii import FON_C1, FON_C2, RHO, R, _g_over_pi, _s_over_t, fujii_albedo, fujii_average_albedo

__all__ = ["eon_brdf", "eon_albedo", "multiple_scattering_albedo", "EON"]

_C1_MINUS_C2 = FON_C1 - FON_C2


def multiple_scattering_albedo(rho: ArrayLike, r: ArrayLike) -> np.ndarray:
    """rho_ms = rho^2 <E_F> / (1 - rho (1 - <E_F>)), the albedo of EON's second lobe [-].

    Parameters
    ----------
    rho : array_like
        Single-scattering albedo [-].
    r : array_like
        Fujii roughness [-].

    Returns
    -------
    numpy.ndarray
        rho_ms [-]: rho at r = 0 (where it has no weight), 1 when rho = 1; it sums the
        geometric series of bounces of the light FON loses, each bounce keeping rho <E_F>.

    Notes
    -----
    Portsmouth, Kutz & Hill (2025), the multiple-scattering albedo of the energy
    compensation lobe (``rho_ms`` of their listing ``f_EON``).

    Examples
    --------
    >>> float(multiple_scattering_albedo(1.0, 0.7))
    1.0
    """
    rho = np.asarray(rho, float)
    average = fujii_average_albedo(r)
    return rho * rho * average / (1.0 - rho * (1.0 - average))


def _eon_coefficients(rho, r) -> tuple:
    """Coefficients of the terms (1, s/t, m) with m = (c1 - g_i)(c1 - g_r), g = G/pi."""
    a = 1.0 / (1.0 + FON_C1 * r)
    lambertian = np.multiply(rho, a) / math.pi
    average = a * (1.0 + FON_C2 * r)
    rho_ms = np.multiply(rho, rho) * average / (1.0 - np.multiply(rho, 1.0 - average))
    return lambertian, lambertian * r, rho_ms * a * r / (math.pi * _C1_MINUS_C2)


def _prepare_eon(theta_i, phi_i, theta_r, phi_r):
    """Geometry-only terms s/t and (c1 - G(theta_i)/pi)(c1 - G(theta_r)/pi) (angles [rad]);
    returns f(rho, r), carrying its exact three-term ``linear_form``."""
    s_over_t = _s_over_t(theta_i, phi_i, theta_r, phi_r)
    # c1 - G/pi >= 0 (G rises to pi c1 at grazing); the floor only removes rounding
    deficit = np.maximum(FON_C1 - _g_over_pi(theta_i), 0.0) * np.maximum(FON_C1 - _g_over_pi(theta_r), 0.0)

    def evaluate(rho: float, r: float) -> np.ndarray:
        lambertian, shaped, compensation = _eon_coefficients(rho, r)
        out = s_over_t * shaped
        out += deficit * compensation
        out += lambertian
        return out

    return with_linear_form(evaluate, lambda: LinearForm(
        np.stack(np.broadcast_arrays(np.ones_like(s_over_t), s_over_t, deficit)), _eon_coefficients))


def eon_brdf(theta_i, phi_i, theta_r, phi_r, rho: float, r: float) -> np.ndarray:
    """EON BRDF, exact-albedo version [1/sr].

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad], above the horizon.
    rho : float or array_like
        Single-scattering albedo [-].
    r : float or array_like
        Fujii roughness in [0, 1] [-].

    Returns
    -------
    numpy.ndarray
        f_FON + f_ms (module docstring) [1/sr].

    Notes
    -----
    Portsmouth, Kutz & Hill (2025), the EON BRDF (``f_EON`` with ``exact = true``).
    Reciprocal: both lobes are symmetric in the two directions.  r = 0 gives rho/pi.
    This is the plain-call form of the registered model ``eon``.

    Examples
    --------
    >>> import numpy as np
    >>> float(eon_brdf(np.radians(40), 0.0, np.radians(70), 2.0, 0.5, 0.0)) * np.pi
    0.5
    """
    return _prepare_eon(theta_i, phi_i, theta_r, phi_r)(rho, r)


def eon_albedo(theta: ArrayLike, rho: ArrayLike, r: ArrayLike) -> np.ndarray:
    """Directional albedo of EON, rho E_F + rho_ms (1 - E_F) [-].

    Parameters
    ----------
    theta : array_like
        Polar angle of incidence [deg].
    rho : array_like
        Single-scattering albedo [-].
    r : array_like
        Fujii roughness [-].

    Returns
    -------
    numpy.ndarray
        The directional-hemispherical reflectance [-]; exactly 1 for rho = 1.

    Notes
    -----
    Portsmouth, Kutz & Hill (2025), the EON albedo (``E_EON`` of their listing).

    Examples
    --------
    >>> round(float(eon_albedo(35.0, 1.0, 0.8)), 12)
    1.0
    """
    e_f = fujii_albedo(theta, r)
    return np.asarray(rho, float) * e_f + multiple_scattering_albedo(rho, r) * (1.0 - e_f)


EON = register(
    Model(
        name="eon",
        params=(RHO, R),
        reference=("Portsmouth, Kutz & Hill 2025, 'EON: A practical energy-preserving rough diffuse BRDF', "
                   "JCGT 14(1) (f_EON with the exact FON albedo E_FON_exact); Fujii 2012 (FON lobe)"),
        description="rough diffuse surface: energy-preserving Oren-Nayar (Fujii lobe + multiple-scattering lobe)",
        prepare=_prepare_eon,
        energy_conserving=True,
        broadcasts_params=True,
    )
)
