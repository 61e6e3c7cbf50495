"""Closed-form KvD series of the Lambertian surface, the ideal mirror and the retroreflector.

References
----------
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998: eq 26-27 (Lambert as the lowest mode), eq 32-36 (ideal
mirror), eq 38-39 (ideal retroreflector), Figs 4-6.
"""
from __future__ import annotations

import math

import numpy as np

from .basis import isotropic_indices
from .series import KvdCoefficients

__all__ = ["lambert_coefficients", "mirror_coefficients", "retroreflector_coefficients"]


def lambert_coefficients(rho: float) -> KvdCoefficients:
    """Series of the Lambertian BRDF rho/pi: the lowest mode alone, a_000 = 2 rho.

    Parameters
    ----------
    rho : float
        Albedo [-], in [0, 1].

    Returns
    -------
    KvdCoefficients
        ``{(0, 0, 0): 2 rho}``.

    Notes
    -----
    I_000 = 1/(2 pi) sr^-1 (KvD eq 26 with A_000 = 4), so rho/pi = 2 rho I_000.

    Examples
    --------
    >>> lambert_coefficients(0.8).as_dict()
    {(0, 0, 0): 1.6}
    """
    rho = float(rho)
    if not 0.0 <= rho <= 1.0:
        raise ValueError(f"rho = {rho:g} is outside its valid range [0, 1] (albedo)")
    return KvdCoefficients(((0, 0, 0),), np.array([2.0 * rho]))


def _delta_series(order: int, sign_of_l: int) -> KvdCoefficients:
    modes = [mode for mode in isotropic_indices(order) if mode[0] == mode[1]]
    values = [(sign_of_l**l) * (1.0 if l == 0 else math.sqrt(2.0)) for _, _, l in modes]
    return KvdCoefficients(tuple(modes), np.array(values))


def mirror_coefficients(order: int) -> KvdCoefficients:
    """Truncated series of the ideal mirror up to radial order ``order``.

    Parameters
    ----------
    order : int
        Highest radial order [-], ``>= 0``.

    Returns
    -------
    KvdCoefficients
        ``a_nnl = (-1)^l c_l`` with c_0 = 1 and c_l = sqrt(2) for l > 0; all modes with
        n != m vanish.

    Notes
    -----
    KvD eq 32-36 expand the scattering kernel of the mirror, a delta function on the
    sphere at the mirror direction (``f cos(theta_i)`` in BRDF terms: the kernel that
    turns incident radiance per solid angle into reflected radiance), and find the
    product-basis amplitudes ``a_nmkl = (-1)^k delta_nm delta_kl``.  The isotropic modes
    collect the two signs of k: ``sum_{k = +-l} K_n^k(i) K_n^k(r) = c_l I_nnl``, which gives
    the amplitudes above (checked numerically in the tests).  The full series does not
    converge (a delta is not square integrable); its truncations show the specular lobe
    narrowing with order and ringing around it (KvD Figs 4-5).  gonio evaluates the
    truncation as the series itself, as the paper's figures do.

    Examples
    --------
    >>> mirror_coefficients(1).as_dict()
    {(0, 0, 0): 1.0, (1, 1, 1): -1.4142135623730951}
    """
    return _delta_series(order, -1)


def retroreflector_coefficients(order: int) -> KvdCoefficients:
    """Truncated series of the ideal retroreflector up to radial order ``order``.

    Parameters
    ----------
    order : int
        Highest radial order [-], ``>= 0``.

    Returns
    -------
    KvdCoefficients
        ``a_nnl = c_l`` with c_0 = 1 and c_l = sqrt(2) for l > 0; all other modes vanish.

    Notes
    -----
    KvD eq 38-39: the kernel is the delta on the sphere at the source direction itself;
    the product-basis amplitudes are ``delta_nm delta_kl`` (the completeness relation of
    K_n^l).  Truncations show the back-scatter lobe (KvD Fig 6).

    Examples
    --------
    >>> retroreflector_coefficients(1).as_dict()
    {(0, 0, 0): 1.0, (1, 1, 1): 1.4142135623730951}
    """
    return _delta_series(order, +1)
