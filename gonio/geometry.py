"""Directions on the hemisphere and the angle conventions of gonio.

Conventions (DESIGN.md): angles in degrees at every public interface; theta is the polar
angle from the mean surface normal (+z), phi the azimuth about it.  In-plane plots use a
*signed viewing angle*: positive when the viewer is on the source side of the normal
(backward scattering, phi_r = phi_i), negative on the far side (forward scattering,
phi_r = phi_i + 180 deg).  This is the sign convention of the theta_r axes of Oren & Nayar
(1995), Figs 10-11 and 16-18.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "direction",
    "angles",
    "azimuth_difference",
    "signed_viewing_angle",
    "in_plane_angles",
    "half_vector",
    "angle_between",
]


def direction(theta: ArrayLike, phi: ArrayLike) -> np.ndarray:
    """Unit vector of the direction (theta, phi).

    Parameters
    ----------
    theta : array_like
        Polar angle from the surface normal [deg].
    phi : array_like
        Azimuth [deg].

    Returns
    -------
    numpy.ndarray
        Array of shape ``broadcast(theta, phi).shape + (3,)``: (x, y, z) components.

    Examples
    --------
    >>> bool(np.allclose(direction(0.0, 123.0), [0.0, 0.0, 1.0]))   # the normal, whatever phi
    True
    """
    t, p = np.radians(np.asarray(theta, float)), np.radians(np.asarray(phi, float))
    s = np.sin(t)
    return np.stack(np.broadcast_arrays(s * np.cos(p), s * np.sin(p), np.cos(t)), axis=-1)


def angles(vector: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Polar angle and azimuth [deg] of (not necessarily unit) vectors ``(..., 3)``.

    The azimuth lies in (-180, 180]; it is 0 for vectors along the normal.
    """
    v = np.asarray(vector, float)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    theta = np.degrees(np.arctan2(np.hypot(x, y), z))
    phi = np.degrees(np.arctan2(y, x))
    return theta, phi


def azimuth_difference(phi_i: ArrayLike, phi_r: ArrayLike) -> np.ndarray:
    """Azimuth of the viewer relative to the source, wrapped to (-180, 180] [deg]."""
    d = np.remainder(np.asarray(phi_r, float) - np.asarray(phi_i, float) + 180.0, 360.0) - 180.0
    return np.where(d == -180.0, 180.0, d)


def signed_viewing_angle(theta_r: ArrayLike, phi_r: ArrayLike, phi_i: ArrayLike = 0.0) -> np.ndarray:
    """Signed in-plane viewing angle [deg]: +theta_r on the source side, -theta_r beyond.

    The side is decided by the sign of cos(phi_r - phi_i); out of the plane of incidence
    this is the sign of the projection onto the plane.
    """
    side = np.cos(np.radians(azimuth_difference(phi_i, phi_r)))
    return np.where(side >= 0.0, 1.0, -1.0) * np.asarray(theta_r, float)


def in_plane_angles(
    theta_i: ArrayLike, signed_view: ArrayLike, phi_i: ArrayLike = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(theta_i, phi_i, theta_r, phi_r) [deg] of a signed in-plane viewing angle.

    Parameters
    ----------
    theta_i : array_like
        Source polar angle [deg].
    signed_view : array_like
        Signed viewing angle [deg], positive on the source side (backward scattering).
    phi_i : array_like, optional
        Source azimuth [deg] (default 0).

    Examples
    --------
    >>> [float(a) for a in in_plane_angles(30.0, -20.0)]
    [30.0, 0.0, 20.0, 180.0]
    """
    v = np.asarray(signed_view, float)
    pi_ = np.asarray(phi_i, float)
    phi_r = np.where(v >= 0.0, pi_, pi_ + 180.0)
    ti, pi_b, tr, pr = np.broadcast_arrays(np.asarray(theta_i, float), pi_, np.abs(v), phi_r)
    return ti, pi_b, tr, pr


def half_vector(theta_i: ArrayLike, phi_i: ArrayLike, theta_r: ArrayLike, phi_r: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Polar angle and azimuth [deg] of the half vector between source and viewer.

    The half vector is the facet normal that mirrors the source into the viewer
    (the specular facet of Torrance-Sparrow, Oren & Nayar eq 37).
    """
    h = direction(theta_i, phi_i) + direction(theta_r, phi_r)
    return angles(h)


def angle_between(theta_a: ArrayLike, phi_a: ArrayLike, theta_b: ArrayLike, phi_b: ArrayLike) -> np.ndarray:
    """Angle between two directions [deg], accurate also for nearly parallel directions."""
    a, b = direction(theta_a, phi_a), direction(theta_b, phi_b)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    dot = np.sum(a * b, axis=-1)
    return np.degrees(np.arctan2(cross, dot))
