"""Appearance of a reflectance model: rendered shapes and reflectance maps (Oren & Nayar
1995, section 6, "Implications for machine vision").

A shape is given by its surface normals as seen by a distant (orthographic) camera looking
down the -z axis: the viewer direction is ``v = (0, 0, 1)`` unless told otherwise. A pixel
with normal ``n`` under a distant source of direction ``s`` and irradiance ``E0`` (on a
surface facing it) has the radiance

    L = f_r(theta_i, theta_r, dphi) E0 cos(theta_i),

with ``theta_i`` the angle between ``n`` and ``s``, ``theta_r`` between ``n`` and ``v``,
and ``dphi`` the angle between their projections on the tangent plane (the models of gonio
are isotropic: only the difference of azimuths enters). Points the source does not reach
(``theta_i >= 90 deg``, attached shadow) have zero radiance; points turned away from the
camera (``theta_r >= 90 deg``) are not in the image (masked). Cast shadows and
interreflections between distant parts of the shape are left out, as in the paper's
renderings of spheres and cylinders (Figs 3, 23-24).

A reflectance map (Horn 1977; the paper's Fig 25) is the same radiance as a function of
the surface gradient ``(p, q) = (dz/dx, dz/dy)``: the normal is
``(-p, -q, 1) / sqrt(1 + p^2 + q^2)`` and the viewer is along +z.

Decision: the Lambertian surface a model is compared with has the model's albedo ``rho``
when the model has that parameter (the paper compares a rough sphere of albedo rho with a
Lambertian one of the same rho, Fig 3), otherwise the model's directional-hemispherical
reflectance at normal incidence (:func:`gonio.radiometry.directional_hemispherical_reflectance`).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = ["direction", "sphere_normals", "cylinder_normals", "gradient_normals", "local_angles", "render",
           "lambert_brdf", "lambert_albedo", "reflectance_map"]

#: A BRDF ``brdf(theta_i, phi_i, theta_r, phi_r) -> array`` [1/sr], angles in degrees, broadcasting.
Brdf = Callable[..., np.ndarray]


def direction(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    """Unit vector of polar angle ``theta`` from +z and azimuth ``phi`` from +x [deg].

    >>> direction(0.0).round(12).tolist(), direction(90.0, 90.0).round(12).tolist()
    ([0.0, 0.0, 1.0], [0.0, 1.0, 0.0])
    """
    theta, phi = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def _checked_size(size: int) -> int:
    if int(size) != size or size < 3:
        raise ValueError(f"size must be an integer >= 3 (pixels across the shape), got {size!r}")
    return int(size)


def sphere_normals(size: int = 201) -> tuple[np.ndarray, np.ndarray]:
    """Normals of a sphere filling a ``size`` x ``size`` image, and its mask.

    Returns
    -------
    normals : numpy.ndarray, shape (size, size, 3)
        Unit normals (x to the right, y up, z towards the camera); (0, 0, 0) off the sphere.
    mask : numpy.ndarray of bool, shape (size, size)
        Pixels on the sphere (strictly inside its outline).
    """
    size = _checked_size(size)
    x = np.linspace(-1.0, 1.0, size)
    xx, yy = np.meshgrid(x, x[::-1])
    r2 = xx**2 + yy**2
    mask = r2 < 1.0
    zz = np.sqrt(np.clip(1.0 - r2, 0.0, None))
    normals = np.where(mask[..., None], np.stack([xx, yy, zz], axis=-1), 0.0)
    return normals, mask


def cylinder_normals(size: int = 201) -> tuple[np.ndarray, np.ndarray]:
    """Normals of a vertical cylinder (axis along y) filling a ``size`` x ``size`` image,
    and its mask (:func:`sphere_normals` for the conventions)."""
    size = _checked_size(size)
    x = np.linspace(-1.0, 1.0, size)
    xx = np.broadcast_to(x, (size, size))
    mask = np.abs(xx) < 1.0
    normals = np.where(mask[..., None],
                       np.stack([xx, np.zeros_like(xx), np.sqrt(np.clip(1.0 - xx**2, 0.0, None))], axis=-1), 0.0)
    return normals, mask


def gradient_normals(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Unit normals ``(-p, -q, 1) / sqrt(1 + p^2 + q^2)`` of the gradients ``(p, q)``."""
    p, q = np.broadcast_arrays(np.asarray(p, float), np.asarray(q, float))
    norm = np.sqrt(1.0 + p**2 + q**2)
    return np.stack([-p / norm, -q / norm, 1.0 / norm], axis=-1)


def local_angles(normals: np.ndarray, light: np.ndarray, view: np.ndarray) -> tuple[np.ndarray, ...]:
    """Incidence, viewing and azimuth-difference angles at each normal [deg].

    Parameters
    ----------
    normals : numpy.ndarray, shape (..., 3)
        Unit normals.
    light, view : numpy.ndarray, shape (3,)
        Unit vectors towards the source and the viewer.

    Returns
    -------
    theta_i, theta_r, dphi : numpy.ndarray, shape (...)
        In degrees; ``dphi`` in [0, 180] (0 where either direction is along the normal).

    Examples
    --------
    >>> ti, tr, dphi = local_angles(np.array([0.0, 0.0, 1.0]), direction(30.0, 0.0), direction(40.0, 180.0))
    >>> round(float(ti), 9), round(float(tr), 9), round(float(dphi), 9)
    (30.0, 40.0, 180.0)
    """
    light, view = (np.asarray(a, float) / np.linalg.norm(a) for a in (light, view))
    cos_i = np.clip(normals @ light, -1.0, 1.0)
    cos_r = np.clip(normals @ view, -1.0, 1.0)
    along_l = light - cos_i[..., None] * normals
    along_v = view - cos_r[..., None] * normals
    lengths = np.linalg.norm(along_l, axis=-1) * np.linalg.norm(along_v, axis=-1)
    cos_phi = np.divide(np.sum(along_l * along_v, axis=-1), lengths, out=np.ones_like(lengths), where=lengths > 1e-12)
    return (np.degrees(np.arccos(cos_i)), np.degrees(np.arccos(cos_r)),
            np.degrees(np.arccos(np.clip(cos_phi, -1.0, 1.0))))


def render(brdf: Brdf, normals: np.ndarray, mask: np.ndarray, light: np.ndarray,
           view: np.ndarray = np.array([0.0, 0.0, 1.0]), irradiance: float = 1.0) -> np.ndarray:
    """Radiance image of a shape under a distant source (module notes) [W m^-2 sr^-1 per
    unit ``irradiance``].

    Parameters
    ----------
    brdf : callable
        ``brdf(theta_i, phi_i, theta_r, phi_r)`` [1/sr], degrees, broadcasting.
    normals, mask : numpy.ndarray
        The shape (:func:`sphere_normals`, :func:`cylinder_normals`, or any normal map).
    light, view : numpy.ndarray, shape (3,)
        Directions towards the source and the camera (:func:`direction`).
    irradiance : float
        Irradiance of a surface facing the source [W/m^2].

    Returns
    -------
    numpy.ndarray, shape of ``mask``
        Radiance; 0 in attached shadow, NaN off the shape and where the camera sees the
        surface from behind.
    """
    theta_i, theta_r, dphi = local_angles(normals, light, view)
    seen = mask & (theta_r < 90.0)
    lit = seen & (theta_i < 90.0)
    image = np.where(seen, 0.0, np.nan)
    values = np.asarray(brdf(theta_i[lit], 0.0, theta_r[lit], dphi[lit]), float)
    image[lit] = values * irradiance * np.cos(np.radians(theta_i[lit]))
    return image


def lambert_brdf(albedo: float) -> Brdf:
    """The Lambertian BRDF ``albedo / pi`` [1/sr] as a :data:`Brdf` (the paper's
    comparison surface)."""
    return lambda ti, pi_, tr, pr: np.full(np.broadcast(ti, pi_, tr, pr).shape, albedo / np.pi)


def lambert_albedo(brdf: Brdf, rho: float | None = None) -> float:
    """Albedo of the Lambertian surface a model is compared with (module notes) [-]:
    ``rho`` when given, else the model's directional-hemispherical reflectance at normal
    incidence."""
    if rho is not None:
        return float(rho)
    from gonio.radiometry import directional_hemispherical_reflectance

    return float(directional_hemispherical_reflectance(brdf, 0.0))


def reflectance_map(brdf: Brdf, light: np.ndarray, p: np.ndarray, q: np.ndarray, irradiance: float = 1.0) -> np.ndarray:
    """Radiance as a function of the surface gradient ``(p, q)`` for a source ``light`` and
    a viewer along +z (module notes; the paper's Fig 25) [per unit ``irradiance``]; 0 where
    the source does not reach the surface, NaN where the viewer sees it from behind."""
    normals = gradient_normals(p, q)
    return render(brdf, normals, np.ones(normals.shape[:-1], bool), light, irradiance=irradiance)
