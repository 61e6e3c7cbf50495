"""Phong specular lobe and the Lambertian + specular model.

References
----------
D. Forsyth, J. Ponce, *Computer Vision: A Modern Approach*, ch. 2, section 2.3.4 (Phong
lobe: radiance proportional to cos^n of the angle between the exit direction and the
specular direction) and section 2.3.5 (Lambertian + specular model, specular albedo rho_s).
"""
from __future__ import annotations

import numpy as np

from ._core import Model, Param, register
from .lambert import RHO, lambert_brdf

SPECULAR_ALBEDO = Param("rho_s", "-", 0.1, (0.0, 1.0), "specular albedo: weight of the Phong lobe")
EXPONENT = Param("exponent", "-", 20.0, (0.0, 1.0e4), "Phong exponent: larger is a narrower lobe")


def cos_specular_offset(theta_i, phi_i, theta_r, phi_r) -> np.ndarray:
    """Cosine of the angle between the viewing direction and the mirror direction [-].

    The mirror direction of (theta_i, phi_i) is (theta_i, phi_i + pi), so
    cos(delta) = cos ti cos tr - sin ti sin tr cos(phi_r - phi_i).  The expression is
    symmetric in source and viewer, which makes the Phong lobe reciprocal.  Angles [rad].
    """
    return np.cos(theta_i) * np.cos(theta_r) - np.sin(theta_i) * np.sin(theta_r) * np.cos(phi_r - phi_i)


def phong_brdf(theta_i, phi_i, theta_r, phi_r, rho_s: float, exponent: float) -> np.ndarray:
    """Energy-normalised Phong lobe BRDF [1/sr].

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad].
    rho_s : float
        Specular albedo [-].
    exponent : float
        Phong exponent n of Forsyth & Ponce section 2.3.4 [-].

    Returns
    -------
    numpy.ndarray
        ``rho_s (n + 2) / (2 pi) max(cos delta, 0)^n`` [1/sr].

    Notes
    -----
    Forsyth & Ponce give the lobe shape cos^n(delta) only up to a factor ("it is common not
    to reason about the exact magnitude").  gonio fixes the factor at (n + 2)/(2 pi), which
    makes the directional-hemispherical reflectance exactly rho_s at normal incidence, and
    rho_s cos(theta_i) wherever the lobe does not reach the horizon, so rho_s is a true
    specular albedo.  Near grazing incidence the horizon cuts the lobe; the energy measured
    there is documented in docs/models.md (``gonio.radiometry.energy_bound_violation``).
    """
    c = np.maximum(cos_specular_offset(theta_i, phi_i, theta_r, phi_r), 0.0)
    return rho_s * (exponent + 2.0) / (2.0 * np.pi) * np.power(c, exponent)


PHONG = register(
    Model(
        name="phong",
        params=(SPECULAR_ALBEDO, EXPONENT),
        reference="Forsyth & Ponce, Computer Vision ch. 2, section 2.3.4 (Phong lobe cos^n)",
        description="energy-normalised Phong specular lobe",
        kernel=phong_brdf,
        linear_in=("rho_s",),
        broadcasts_params=True,
    )
)


def lambert_phong_brdf(theta_i, phi_i, theta_r, phi_r, rho: float, rho_s: float, exponent: float) -> np.ndarray:
    """Lambertian + Phong specular BRDF [1/sr] (Forsyth & Ponce section 2.3.5).

    ``rho / pi + phong_brdf(...)``; energy conserving when rho + rho_s <= 1 up to the
    horizon effect documented in :func:`phong_brdf`.
    """
    return lambert_brdf(theta_i, phi_i, theta_r, phi_r, rho) + phong_brdf(
        theta_i, phi_i, theta_r, phi_r, rho_s, exponent
    )


LAMBERT_PHONG = register(
    Model(
        name="lambert+phong",
        params=(RHO, SPECULAR_ALBEDO, EXPONENT),
        reference="Forsyth & Ponce, Computer Vision ch. 2, section 2.3.5 (Lambertian + specular model)",
        description="Lambertian diffuse plus Phong specular lobe",
        kernel=lambert_phong_brdf,
        linear_in=("rho", "rho_s"),
        broadcasts_params=True,
    )
)
