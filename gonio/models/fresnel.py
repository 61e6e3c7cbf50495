"""Fresnel reflectance of a smooth dielectric interface.

References
----------
L. B. Wolff, S. K. Nayar, M. Oren, "Improved diffuse reflection models for computer
vision", IJCV 30(1), 1998, eq 2 (unpolarised Fresnel reflectance with Snell's law).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["fresnel_reflectance"]


def fresnel_reflectance(cos_incidence: ArrayLike, n: ArrayLike) -> np.ndarray:
    """Unpolarised Fresnel reflectance of light arriving at a smooth interface [-].

    Parameters
    ----------
    cos_incidence : array_like
        Cosine of the angle between the incident ray and the interface normal, in [0, 1].
    n : array_like
        Relative refractive index n_transmitted / n_incident [-], > 0.  Use n > 1 for
        light entering a dielectric from air and 1/n for light leaving it.

    Returns
    -------
    numpy.ndarray
        F = (r_s^2 + r_p^2) / 2 with r_s, r_p the amplitude coefficients of the two
        polarisations (Wolff, Nayar & Oren 1998, eq 2); 1 beyond the critical angle
        (total internal reflection, possible only for n < 1).

    Notes
    -----
    Limits: F = ((n - 1)/(n + 1))^2 at normal incidence and F = 1 at grazing incidence.
    For n = 1 there is no interface and F = 0, except exactly at grazing incidence where
    gonio returns the grazing limit 1 of every n != 1.

    Examples
    --------
    >>> round(float(fresnel_reflectance(1.0, 1.5)), 6)
    0.04
    """
    cos_i = np.clip(np.asarray(cos_incidence, float), 0.0, 1.0)
    n = np.asarray(n, float)
    sin_t_sq = (1.0 - cos_i**2) / n**2
    total = sin_t_sq >= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin_t_sq, 0.0))
    s_den = cos_i + n * cos_t
    p_den = n * cos_i + cos_t
    degenerate = (s_den == 0.0) | (p_den == 0.0)
    s_safe = np.where(degenerate, 1.0, s_den)
    p_safe = np.where(degenerate, 1.0, p_den)
    r_s = (cos_i - n * cos_t) / s_safe
    r_p = (n * cos_i - cos_t) / p_safe
    reflectance = 0.5 * (r_s**2 + r_p**2)
    reflectance = np.where(degenerate, 0.0, reflectance)
    return np.where(total, 1.0, reflectance)
