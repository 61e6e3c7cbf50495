"""Fresnel reflectance of a smooth dielectric interface and its polynomial approximation.

Functions
---------
fresnel_reflectance
    Exact unpolarised reflectance (eq 2 with Snell's law), from either side of the
    interface (total internal reflection included).
fresnel_transmittance
    ``1 - fresnel_reflectance``: the fraction of energy crossing the interface.
exit_transmittance
    The exit factor of the Wolff model, 1 - F(asin(sin(theta_r)/n), 1/n): light leaving
    the dielectric towards a viewer at theta_r in air.
polynomial_epsilon, fresnel_polynomial
    The fifth-power approximation given after eq 7 and the choice of its epsilon.

References
----------
L. B. Wolff, S. K. Nayar, M. Oren, "Improved diffuse reflection models for computer
vision", IJCV 30(1), 1998, eq 2 (unpolarised Fresnel reflectance with Snell's law), eq 7
(exit factor) and the polynomial approximation stated after eq 7.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "fresnel_reflectance",
    "fresnel_transmittance",
    "exit_transmittance",
    "polynomial_epsilon",
    "fresnel_polynomial",
]


def _check_positive_index(n: np.ndarray, name: str = "n") -> None:
    bad = n <= 0.0
    if np.any(bad):
        raise ValueError(
            f"{name} = {float(n[bad].flat[0]):g} is not a valid relative refractive index; "
            "it must lie in (0, inf) (use n > 1 entering a dielectric from air, 1/n leaving it)"
        )


def fresnel_reflectance(cos_incidence: ArrayLike, n: ArrayLike) -> np.ndarray:
    """Unpolarised Fresnel reflectance of light arriving at a smooth interface [-].

    Parameters
    ----------
    cos_incidence : array_like
        Cosine of the angle between the incident ray and the interface normal, in [0, 1].
        Values a rounding error outside [0, 1] are brought back to the nearest end.
    n : array_like
        Relative refractive index n_transmitted / n_incident [-], > 0.  Use n > 1 for
        light entering a dielectric from air and 1/n for light leaving it.

    Returns
    -------
    numpy.ndarray
        F = (r_s^2 + r_p^2) / 2 with r_s, r_p the amplitude coefficients of the two
        polarisations (Wolff, Nayar & Oren 1998, eq 2); 1 beyond the critical angle
        (total internal reflection, possible only for n < 1).  NaN in gives NaN out.

    Raises
    ------
    ValueError
        If any ``n`` is <= 0.

    Notes
    -----
    Eq 2 of Wolff, Nayar & Oren writes F in terms of the incidence angle theta_i and the
    transmission angle theta_t (Snell: sin theta_i = n sin theta_t) as
    F = 1/2 sin^2(ti - tt)/sin^2(ti + tt) [1 + cos^2(ti + tt)/cos^2(ti - tt)].  The same
    quantity is computed here from the amplitude coefficients
    r_s = (cos ti - n cos tt)/(cos ti + n cos tt), r_p = (n cos ti - cos tt)/(n cos ti + cos tt),
    which, unlike the angle form, has no 0/0 at normal incidence
    (tests/models/test_fresnel.py checks the two forms agree).

    Limits: F = ((n - 1)/(n + 1))^2 at normal incidence and F = 1 at grazing incidence.
    For n = 1 there is no interface and F = 0, except exactly at grazing incidence where
    gonio returns the grazing limit 1 of every n != 1.

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, eq 2.
    R. Siegel, J. R. Howell, *Thermal Radiation Heat Transfer*, McGraw-Hill 1981 (Fresnel relations).

    Examples
    --------
    >>> round(float(fresnel_reflectance(1.0, 1.5)), 6)
    0.04
    >>> float(fresnel_reflectance(0.5, 1 / 1.5))   # 60 deg inside glass: beyond critical
    1.0
    """
    cos_i = np.clip(np.asarray(cos_incidence, float), 0.0, 1.0)
    n = np.asarray(n, float)
    _check_positive_index(n)
    sin_t_sq = (1.0 - cos_i**2) / n**2
    total = sin_t_sq >= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin_t_sq, 0.0))
    return np.where(total, 1.0, _reflectance_from_cosines(cos_i, cos_t, n))


def _reflectance_from_cosines(cos_i: np.ndarray, cos_t: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(r_s^2 + r_p^2)/2 from the cosines of the incidence and transmission angles."""
    s_den = cos_i + n * cos_t
    p_den = n * cos_i + cos_t
    degenerate = (s_den == 0.0) | (p_den == 0.0)
    s_safe = np.where(degenerate, 1.0, s_den)
    p_safe = np.where(degenerate, 1.0, p_den)
    r_s = (cos_i - n * cos_t) / s_safe
    r_p = (n * cos_i - cos_t) / p_safe
    return np.where(degenerate, 0.0, 0.5 * (r_s**2 + r_p**2))


def fresnel_transmittance(cos_incidence: ArrayLike, n: ArrayLike) -> np.ndarray:
    """Fraction of unpolarised energy transmitted through a smooth interface [-].

    Parameters
    ----------
    cos_incidence : array_like
        Cosine of the incidence angle, in [0, 1].
    n : array_like
        Relative refractive index n_transmitted / n_incident [-], > 0.

    Returns
    -------
    numpy.ndarray
        1 - F with F from :func:`fresnel_reflectance` (Wolff, Nayar & Oren 1998, eq 2);
        the entry factor (1 - F(theta_i, n)) of eq 7.

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, eq 2 and eq 7.

    Examples
    --------
    >>> round(float(fresnel_transmittance(1.0, 1.5)), 6)
    0.96
    """
    return 1.0 - fresnel_reflectance(cos_incidence, n)


def exit_transmittance(cos_exit: ArrayLike, n: ArrayLike) -> np.ndarray:
    """Transmittance for light leaving a dielectric towards a viewer in air [-].

    Parameters
    ----------
    cos_exit : array_like
        Cosine of the viewing angle theta_r in air, in [0, 1].
    n : array_like
        Refractive index of the dielectric relative to air [-], > 0.

    Returns
    -------
    numpy.ndarray
        1 - F(theta_t', 1/n) where theta_t' = asin(sin(theta_r)/n) is the internal angle
        that refracts into theta_r: the exit factor of eq 7 (Wolff, Nayar & Oren 1998).

    Notes
    -----
    The internal angle never exceeds the critical angle (sin theta_t' = sin theta_r / n
    <= 1/n), so light that reaches a viewer is never totally reflected.  By the
    reciprocity of the Fresnel coefficients the value equals 1 - F(theta_r, n); it is
    computed here literally, from inside, as eq 7 writes it (tests check the identity).

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, eq 7.

    Examples
    --------
    >>> round(float(exit_transmittance(1.0, 1.5)), 6)
    0.96
    """
    cos_r = np.clip(np.asarray(cos_exit, float), 0.0, 1.0)
    n = np.asarray(n, float)
    _check_positive_index(n)
    cos_internal = np.sqrt(1.0 - (1.0 - cos_r**2) / n**2)
    # Both cosines are known here; recomputing the one in air from cos_internal by Snell's
    # law would lose it to rounding near grazing exit (where 1 - sin^2 ~ 1e-16).
    return 1.0 - _reflectance_from_cosines(cos_internal, cos_r, 1.0 / n)


def polynomial_epsilon(n: ArrayLike) -> np.ndarray:
    """Epsilon of the polynomial Fresnel approximation for refractive index n [-].

    Parameters
    ----------
    n : array_like
        Refractive index of the dielectric relative to air [-], > 0.

    Returns
    -------
    numpy.ndarray
        epsilon = F0 / (1 - F0) = (n - 1)^2 / (4 n), with F0 = ((n - 1)/(n + 1))^2.

    Notes
    -----
    Wolff, Nayar & Oren (1998, after eq 7) give F(x, n) ~ ((2x/pi)^5 + eps)/(1 + eps)
    and say only that eps depends on n and is typically 0.07.  gonio chooses the eps that
    makes the approximation exact at normal incidence (its value at x = 0 is
    eps/(1 + eps)); it is also exact at grazing incidence (value 1) for every eps.
    eps = 0.07 corresponds to n = 1.69 under this rule.  The maximum error of the
    approximation for n in [1.3, 2.0] is measured in tests/models/test_fresnel.py and
    docs/wolff.md.

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, text after eq 7.

    Examples
    --------
    >>> round(float(polynomial_epsilon(1.5)), 6)
    0.041667
    """
    n = np.asarray(n, float)
    _check_positive_index(n)
    return (n - 1.0) ** 2 / (4.0 * n)


def fresnel_polynomial(theta: ArrayLike, epsilon: ArrayLike) -> np.ndarray:
    """Polynomial approximation of the Fresnel reflectance from air [-].

    Parameters
    ----------
    theta : array_like
        Incidence angle in air [rad], in [0, pi/2].
    epsilon : array_like
        Material constant [-], >= 0 (see :func:`polynomial_epsilon`).

    Returns
    -------
    numpy.ndarray
        ((2 theta / pi)^5 + epsilon) / (1 + epsilon).

    Notes
    -----
    The approximation stated after eq 7 of Wolff, Nayar & Oren (1998).  It describes
    light arriving from air (n > 1).  For the exit factor of eq 7, whose internal angle
    spans only [0, asin(1/n)], gonio applies it to the viewing angle theta_r in air,
    using the Fresnel reciprocity F(asin(sin theta_r / n), 1/n) = F(theta_r, n).

    References
    ----------
    L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, text after eq 7.

    Examples
    --------
    >>> float(fresnel_polynomial(np.pi / 2, 0.07))
    1.0
    """
    theta = np.asarray(theta, float)
    epsilon = np.asarray(epsilon, float)
    if np.any(epsilon < 0.0):
        raise ValueError(
            f"epsilon = {float(epsilon[epsilon < 0].flat[0]):g} is outside its valid range [0, inf)"
        )
    return ((2.0 / np.pi * theta) ** 5 + epsilon) / (1.0 + epsilon)
