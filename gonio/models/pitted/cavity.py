"""Geometry of one spherical pit: what is seen through the orifice, and what is lit.

Coordinates: the mega-scale surface is the plane z = 0 with normal +z; the pit's sphere
has unit radius R = 1 and its centre on the z axis at height ``cos(psi)``, so the cavity
is the part of the sphere below the plane, its orifice the disk of radius ``sin(psi)``
and its depth ``1 - cos(psi)`` (Koenderink et al. 1999, section 2, Fig 2).  The
macro-scale normal of a cavity point p is the unit vector ``m = c - p`` towards the
centre.  The source lies in the x-z plane at co-elevation alpha; the viewer at
co-elevation beta and azimuth epsilon from the plane of incidence (section 3.1).

A ray leaving a cavity point p along a direction d (d_z > 0) meets the sphere again at
``q = p + 2 (m.d) d``; it escapes through the orifice exactly when ``q_z >= 0``.  This
one test decides the cast shadow (d = source) and interposition (d = viewer); both
boundaries are small circles with the radius of the orifice (section 2.1, Fig 11).

All angles here are in radians (internal module); the public functions of
:mod:`gonio.models.pitted` take degrees.

References
----------
J. J. Koenderink, A. J. van Doorn, K. J. Dana, S. K. Nayar, IJCV 31(2/3), 1999,
sections 2.1-2.2 and 4.1, Figs 2, 3 and 11.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "unit_vector",
    "centre_height",
    "orifice_radius",
    "cavity_point_seen",
    "escapes",
    "primary_irradiance",
]


def unit_vector(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Direction (theta, phi) [rad] as an array ``(..., 3)``."""
    s = np.sin(theta)
    return np.stack(np.broadcast_arrays(s * np.cos(phi), s * np.sin(phi), np.cos(theta)), axis=-1)


def centre_height(psi: float) -> float:
    """Height of the sphere centre above the orifice plane for R = 1 (psi [rad])."""
    return float(np.cos(psi))


def orifice_radius(psi: float) -> float:
    """Radius of the orifice for R = 1: ``sin(psi)`` (psi [rad])."""
    return float(np.sin(psi))


def cavity_point_seen(orifice_xy: np.ndarray, view: np.ndarray, psi: float) -> tuple[np.ndarray, np.ndarray]:
    """The cavity point seen through an orifice point, and its macro-scale normal.

    Parameters
    ----------
    orifice_xy : numpy.ndarray
        Points ``(..., 2)`` of the orifice disk (``|xy| <= sin psi``), R = 1 units.
    view : numpy.ndarray
        Unit viewing direction(s) ``(..., 3)`` pointing from the surface to the eye.
    psi : float
        Aperture [rad].

    Returns
    -------
    point, normal : numpy.ndarray
        The cavity point ``(..., 3)`` met by the visual ray ``o - t view`` (t > 0) and the
        unit normal ``m`` there (towards the sphere centre).

    Notes
    -----
    First method of section 4.1: solve ``|o - t e - c| = 1`` for the positive root.
    Because every orifice point lies inside the sphere, the root always exists.

    Examples
    --------
    >>> point, normal = cavity_point_seen(np.zeros((1, 2)), np.array([0.0, 0.0, 1.0]), np.pi / 2)
    >>> point.round(12).tolist(), normal.round(12).tolist()   # bottom of a hemisphere
    ([[0.0, 0.0, -1.0]], [[0.0, 0.0, 1.0]])
    """
    xy = np.asarray(orifice_xy, float)
    offset = np.concatenate([xy, np.full(xy.shape[:-1] + (1,), -centre_height(psi))], axis=-1)
    along = np.sum(offset * view, axis=-1)
    inside = 1.0 - np.sum(offset * offset, axis=-1)  # >= 0 up to rounding
    t = along + np.sqrt(np.maximum(along * along + inside, 0.0))
    normal = t[..., None] * view - offset
    point = np.array([0.0, 0.0, centre_height(psi)]) - normal
    return point, normal


def escapes(point: np.ndarray, normal: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Whether the ray from a cavity point along ``direction`` leaves through the orifice.

    Parameters
    ----------
    point, normal : numpy.ndarray
        Cavity points ``(..., 3)`` and their normals towards the sphere centre.
    direction : numpy.ndarray
        Unit direction(s) ``(..., 3)`` with positive z.

    Returns
    -------
    numpy.ndarray of bool
        True where the point is lit by (or visible from) ``direction``.

    Notes
    -----
    Second method of section 4.1 (cast-shadow test, Fig 11): the ray meets the sphere
    again at ``p + 2 (m.d) d``; the point is lit if that exit lies at or above the
    orifice plane and the surface faces the ray.

    Examples
    --------
    >>> p, m = np.array([1.0, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0])  # rim of a hemisphere
    >>> bool(escapes(p, m, np.array([-0.6, 0.0, 0.8]))), bool(escapes(p, m, np.array([0.6, 0.0, 0.8])))
    (True, False)
    """
    cosine = np.sum(normal * direction, axis=-1)
    exit_height = point[..., 2] + 2.0 * cosine * direction[..., 2]
    return (cosine > 0.0) & (exit_height >= 0.0)


def primary_irradiance(point: np.ndarray, normal: np.ndarray, source: np.ndarray) -> np.ndarray:
    """Primary irradiance of cavity points per unit normal irradiance of the beam [-].

    ``m.i`` where the point is lit, 0 in the cast shadow (section 2.2, Fig 3; third
    method of section 4.1 without the diffuse part).
    """
    cosine = np.sum(normal * source, axis=-1)
    return np.where(escapes(point, normal, source), cosine, 0.0)
