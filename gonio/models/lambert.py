"""Lambert's ideal diffuse reflector.

References
----------
D. Forsyth, J. Ponce, *Computer Vision: A Modern Approach*, ch. 2, section 2.3.3:
a surface of albedo rho_d has the constant BRDF rho_d / pi.
"""
from __future__ import annotations

import numpy as np

from ._core import LinearForm, Model, Param, register, with_linear_form

RHO = Param("rho", "-", 0.8, (0.0, 1.0), "diffuse albedo (directional-hemispherical reflectance)")


def lambert_brdf(theta_i, phi_i, theta_r, phi_r, rho: float) -> np.ndarray:
    """BRDF of a Lambertian surface [1/sr].

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad] (unused except for the output shape).
    rho : float or array_like
        Albedo [-] (an array broadcasts with the angles).

    Returns
    -------
    numpy.ndarray
        ``rho / pi`` broadcast to the geometry's (and rho's) shape [1/sr].

    Notes
    -----
    Forsyth & Ponce section 2.3.3: rho_brdf = rho_d / pi, so that the
    directional-hemispherical reflectance equals rho for every incidence.
    """
    shape = np.broadcast_shapes(*(np.shape(a) for a in (theta_i, phi_i, theta_r, phi_r, rho)))
    return np.broadcast_to(np.divide(rho, np.pi), shape).copy()


def _prepare_lambert(theta_i, phi_i, theta_r, phi_r):
    """f(rho) = rho/pi on the given geometry [rad], with its one-term ``linear_form``."""
    ones = np.ones(np.broadcast_shapes(*(np.shape(a) for a in (theta_i, phi_i, theta_r, phi_r))))

    def evaluate(rho: float) -> np.ndarray:
        return lambert_brdf(theta_i, phi_i, theta_r, phi_r, rho)

    return with_linear_form(evaluate, lambda: LinearForm(ones[None], lambda rho: (np.divide(rho, np.pi),)))


LAMBERT = register(
    Model(
        name="lambert",
        params=(RHO,),
        reference="Forsyth & Ponce, Computer Vision ch. 2, section 2.3.3 (rho_brdf = rho_d/pi)",
        description="ideal diffuse reflector",
        prepare=_prepare_lambert,
        linear_in=("rho",),
        broadcasts_params=True,
    )
)
