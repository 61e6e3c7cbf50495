"""Minnaert's empirical lunar reflectance function.

References
----------
M. Minnaert, "The reciprocity principle in lunar photometry", ApJ 93, 1941, as quoted by
Oren & Nayar (1995), section 1, and by Koenderink & van Doorn (1998), eq 46.
"""
from __future__ import annotations

import numpy as np

from ._core import Model, Param, register


def minnaert_brdf(theta_i, phi_i, theta_r, phi_r, k: float, rho: float) -> np.ndarray:
    """Minnaert BRDF [1/sr].

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad].
    k : float
        Minnaert exponent [-], 0 <= k <= 1; k = 1 is Lambert.
    rho : float
        Scale [-]: the albedo of the k = 1 (Lambertian) case.

    Returns
    -------
    numpy.ndarray
        ``rho (k + 1) / (2 pi) (cos theta_i cos theta_r)^(k - 1)`` [1/sr].

    Notes
    -----
    Oren & Nayar section 1 quote Minnaert's function as
    f_r = (k + 1)/(2 pi) (cos theta_i cos theta_r)^(k - 1), 0 <= k <= 1, which integrates to
    a directional-hemispherical reflectance of cos(theta_i)^(k-1) (so it is *not* energy
    conserving for k < 1: it diverges at grazing incidence).  gonio multiplies it by a scale
    ``rho`` so that k = 1 gives the Lambertian BRDF rho/pi.  At a direction exactly on the
    horizon (cos = 0) and k < 1 the function is infinite; gonio returns ``inf`` there rather
    than warning, since the divergence is the model's own.
    """
    product = np.cos(theta_i) * np.cos(theta_r)
    product = np.maximum(product, 0.0)
    with np.errstate(divide="ignore"):
        # k = 1 is Lambertian everywhere, the horizon included (0^0 = 1 in numpy too)
        powered = np.power(product, np.subtract(k, 1.0))
    return rho * (k + 1.0) / (2.0 * np.pi) * powered


MINNAERT = register(
    Model(
        name="minnaert",
        params=(
            Param("rho", "-", 0.8, (0.0, 1.0), "scale; the albedo of the Lambertian case k = 1"),
            Param("k", "-", 0.8, (0.0, 1.0), "Minnaert exponent; 1 is Lambertian, smaller is darker at the limb"),
        ),
        reference="Minnaert 1941 as quoted in Oren & Nayar 1995 section 1 and Koenderink & van Doorn 1998 eq 46",
        description="empirical reciprocal lunar reflectance, (cos ti cos tr)^(k-1)",
        kernel=lambda ti, pi_, tr, pr, rho, k: minnaert_brdf(ti, pi_, tr, pr, k=k, rho=rho),
        energy_conserving=False,
        linear_in=("rho",),
        broadcasts_params=True,
    )
)
