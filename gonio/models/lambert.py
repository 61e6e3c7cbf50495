"""Lambert's ideal diffuse reflector.

References
----------
D. Forsyth, J. Ponce, *Computer Vision: A Modern Approach*, ch. 2, section 2.3.3:
a surface of albedo rho_d has the constant BRDF rho_d / pi.
"""
from __future__ import annotations

import numpy as np

from ._core import Model, Param, register

RHO = Param("rho", "-", 0.8, (0.0, 1.0), "diffuse albedo (directional-hemispherical reflectance)")


def lambert_brdf(theta_i, phi_i, theta_r, phi_r, rho: float) -> np.ndarray:
    """BRDF of a Lambertian surface [1/sr].

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad] (unused except for the output shape).
    rho : float
        Albedo [-].

    Returns
    -------
    numpy.ndarray
        ``rho / pi`` broadcast to the geometry's shape [1/sr].

    Notes
    -----
    Forsyth & Ponce section 2.3.3: rho_brdf = rho_d / pi, so that the
    directional-hemispherical reflectance equals rho for every incidence.
    """
    shape = np.broadcast_shapes(*(np.shape(a) for a in (theta_i, phi_i, theta_r, phi_r)))
    return np.full(shape, rho / np.pi)


LAMBERT = register(
    Model(
        name="lambert",
        params=(RHO,),
        reference="Forsyth & Ponce, Computer Vision ch. 2, section 2.3.3 (rho_brdf = rho_d/pi)",
        description="ideal diffuse reflector",
        kernel=lambert_brdf,
        linear_in=("rho",),
    )
)
