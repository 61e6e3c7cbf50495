"""The sample as labs meet it: a textured surface, mounted in a holder, optionally spun.

A real sample is not the uniform surface a reflectance model describes. Its albedo and
the slope of its surface vary from place to place (the "mega scale" of a surface,
Oren & Nayar 1995 section 1; the spatial non-uniformity every reflectance laboratory
lists in its budget), the camera's window averages what a few hundred square
millimetres of it reflect, and each time the sample is put into its holder it sits at
another rotation, a slightly different place and a slightly different tilt. This module
renders that, as pure functions of seeded random fields:

- **Texture** (:func:`realise_texture`): on the sample's own surface, an albedo factor
  ``a = 1 + albedo_rms g_1`` and a height ``h = slope_rms l g_2`` whose gradient is the
  mesoscale slope ``s = grad h`` (each component of rms ``slope_rms``), where ``g_1, g_2``
  are independent unit-variance Gaussian random fields with the Gaussian correlation
  ``exp(-r^2 / (2 l^2))`` of length ``l`` (:func:`gaussian_random_field`).
- **What a pixel sees** (:func:`pixel_maps`, :func:`relative_radiance`): the radiance of a
  facet of slope ``s`` is the sample's BRDF in the facet's frame, and the pixel weights it
  by the facet's projected area toward the camera relative to the mean plane's,
  ``cos(theta_r,facet) / (cos(theta_r) n_z)`` (a surface with relief puts more pixels on
  the facets that face the camera). This apparent reflectance ``F(s)`` is expanded to
  second order about ``s = 0`` (:func:`slope_response`, a 3 x 3 stencil at the
  Gauss-Hermite nodes ``0, +/- sqrt(3) slope_rms``, so that its mean over the slopes is
  exact for any ``F`` of degree up to 5 along each axis), and every pixel gets
  ``a F(s) / F(0)``, its fields averaged over the pixel's footprint on the sample
  (``p / m`` by ``p / (m cos theta_r)``).
- **Mounting** (:class:`Mounting`): the sample rotated about its normal by
  ``rotation_deg``, displaced in the holder by ``offset_mm``, seated with an extra tilt
  ``seat_tilt_deg``; its own wedge (a tilt fixed in the sample) turns with it
  (:func:`mounting_tilt`).
- **Spinning** (``Mounting.spin``): the holder turns the sample about the window's centre
  during the exposure (whole turns): every field is averaged over the rotation, and the
  tilts that turn with the sample (its wedge and its seat) average out to first order
  (their second-order residual, ``tilt^2 / 2`` ~ 1e-6, is left out).

Mesoscale shadowing and masking between facets are not modelled: with slopes of a fraction
of a degree they matter only within a degree of grazing, where the rig refuses to measure.

References
----------
M. Oren, S. K. Nayar, "Generalization of the Lambertian model and implications for
machine vision", IJCV 14(3), 1995: section 1 (the macroscopic, mesoscopic and microscopic
scales of a surface) and section 5 (the rig).
J. J. Koenderink, A. J. van Doorn, "Illuminance texture due to surface mesostructure",
JOSA A 13(3), 1996 (the radiance of a surface with relief as a sum over its facets,
weighted by their projected areas).
C. R. Dietrich, G. N. Newsam, "Fast and exact simulation of stationary Gaussian
processes through circulant embedding", SIAM J. Sci. Comput. 18(4), 1997 (Gaussian random
fields by filtering white noise in Fourier space on a padded grid).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import ndimage

from ..rig_geometry import misaligned_angles
from .world import Optics, pixel_sample_coordinates

__all__ = ["TextureRealisation", "LabTexture", "Mounting", "SlopeResponse", "SAMPLE_HALF_SIDE_MM",
           "MOUNT_PLAY_MM", "SPIN_STEPS", "FIELDS", "Footprints", "gaussian_random_field", "realise_texture",
           "lab_texture", "footprints", "pixel_maps", "slope_response", "relative_radiance", "relative_radiance_image",
           "mounting_tilt", "draw_mounting"]

Brdf = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]

#: Half the side of the 2-inch sample [mm].
SAMPLE_HALF_SIDE_MM = 25.4
#: Standard deviation of where a remounted sample's centre lands in the holder, per axis
#: [mm]: the play of a 2-inch sample in a recess machined 0.5 mm oversize.
MOUNT_PLAY_MM = 0.3
#: Rotation steps over which a spinning sample's fields are averaged (one whole turn).
SPIN_STEPS = 36
#: Grid steps per correlation length of the texture's fields.
_STEPS_PER_LENGTH = 4
#: Largest grid of a texture realisation, per side [cells].
_MAX_GRID = 1024
#: Index 0 of the six fields of :class:`LabTexture`: a, a sx, a sy, a sx^2, a sx sy, a sy^2.
FIELDS = ("a", "a_sx", "a_sy", "a_sxx", "a_sxy", "a_syy")


def gaussian_random_field(shape: tuple[int, int], step_mm: float, length_mm: float, rng: np.random.Generator,
                          derivatives: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A unit-variance Gaussian random field with correlation ``exp(-r^2 / (2 l^2))``.

    White noise on a grid padded by four correlation lengths is filtered in Fourier space
    by the square root of the correlation's spectrum, ``exp(-k^2 l^2 / 4)``, normalised so
    that the field's variance is 1 (the discrete spectrum's sum); the padding keeps the
    circular convolution from correlating opposite edges.

    Parameters
    ----------
    shape : (int, int)
        Grid size (rows along y, columns along x).
    step_mm : float
        Grid step [mm].
    length_mm : float
        Correlation length ``l`` [mm].
    rng : numpy.random.Generator
        Source of the white noise.
    derivatives : bool
        Also return the field's derivatives along x and y [1/mm] (spectral derivatives).

    Returns
    -------
    numpy.ndarray or (field, d/dx, d/dy)

    Examples
    --------
    >>> g = gaussian_random_field((256, 256), 0.25, 1.0, np.random.default_rng(0))
    >>> bool(0.8 < g.std() < 1.2), g.shape
    (True, (256, 256))
    """
    pad = int(math.ceil(4 * length_mm / step_mm))
    ny, nx = shape[0] + 2 * pad, shape[1] + 2 * pad
    ky = 2 * np.pi * np.fft.fftfreq(ny, d=step_mm)
    kx = 2 * np.pi * np.fft.rfftfreq(nx, d=step_mm)
    k2 = ky[:, None] ** 2 + kx[None, :] ** 2
    spectrum = np.exp(-k2 * length_mm**2 / 2.0)  # of exp(-r^2/(2 l^2)), up to a constant
    weights = np.full(kx.shape, 2.0)
    weights[0] = 1.0
    if nx % 2 == 0:
        weights[-1] = 1.0
    norm = math.sqrt(float(np.sum(spectrum * weights[None, :])) / (ny * nx))
    filtered = np.fft.rfft2(rng.standard_normal((ny, nx))) * (np.sqrt(spectrum) / norm)
    crop = (slice(pad, pad + shape[0]), slice(pad, pad + shape[1]))
    field = np.fft.irfft2(filtered, s=(ny, nx))[crop]
    if not derivatives:
        return field
    dx = np.fft.irfft2(filtered * (1j * kx[None, :]), s=(ny, nx))[crop]
    dy = np.fft.irfft2(filtered * (1j * ky[:, None]), s=(ny, nx))[crop]
    return field, dx, dy


@dataclass(frozen=True)
class TextureRealisation:
    """One sample's texture on its own surface (sample frame, origin at its centre).

    Attributes
    ----------
    coordinates_mm : numpy.ndarray
        Grid coordinates along x and along y [mm] (the same for both).
    albedo : numpy.ndarray
        Albedo factor ``a`` [-], shape (y, x).
    slope_x, slope_y : numpy.ndarray
        Mesoscale slope ``dh/dx``, ``dh/dy`` [rad] (small angles).
    """

    coordinates_mm: np.ndarray
    albedo: np.ndarray
    slope_x: np.ndarray
    slope_y: np.ndarray

    @property
    def step_mm(self) -> float:
        """Grid step [mm]."""
        return float(self.coordinates_mm[1] - self.coordinates_mm[0])


def realise_texture(albedo_rms: float, slope_rms_deg: float, length_mm: float, rng: np.random.Generator,
                    half_extent_mm: float = SAMPLE_HALF_SIDE_MM * math.sqrt(2.0) + 4 * MOUNT_PLAY_MM
                    ) -> TextureRealisation:
    """A seeded realisation of the texture over the sample (and the corners a rotation brings in).

    Parameters
    ----------
    albedo_rms : float
        Relative rms of the local albedo factor ``a = 1 + albedo_rms g_1`` [-] (clipped at
        0, which at the magnitudes allowed never acts).
    slope_rms_deg : float
        Rms of each component of the mesoscale slope [deg].
    length_mm : float
        Correlation length of both fields [mm].
    rng : numpy.random.Generator
        Source of the realisation.
    half_extent_mm : float
        Half the side of the square grid [mm] (default: the sample's half-diagonal and the
        holder's play, so that any rotation and displacement stays on the grid).

    Examples
    --------
    >>> t = realise_texture(0.03, 1.0, 1.0, np.random.default_rng(1))
    >>> bool(0.02 < t.albedo.std() < 0.04), bool(0.01 < np.degrees(t.slope_x.std()) < 1.3)
    (True, True)
    """
    step = length_mm / _STEPS_PER_LENGTH
    n = int(math.ceil(2 * half_extent_mm / step)) + 1
    if n > _MAX_GRID:
        raise ValueError(f"texture correlation length {length_mm!r} mm is too short for the emulated texture "
                         f"grid (at least {2 * half_extent_mm * _STEPS_PER_LENGTH / _MAX_GRID:.2f} mm)")
    coordinates = (np.arange(n) - (n - 1) / 2.0) * step
    albedo = 1.0 + albedo_rms * gaussian_random_field((n, n), step, length_mm, rng) if albedo_rms \
        else np.ones((n, n))
    np.maximum(albedo, 0.0, out=albedo)
    if slope_rms_deg:
        # h = sigma_h g with Var(dh/dx) = sigma_h^2 / l^2 for this correlation: sigma_h = s l
        sigma_h = math.radians(slope_rms_deg) * length_mm
        _, gx, gy = gaussian_random_field((n, n), step, length_mm, rng, derivatives=True)
        slope_x, slope_y = sigma_h * gx, sigma_h * gy
    else:
        slope_x = slope_y = np.zeros((n, n))
    return TextureRealisation(coordinates, albedo, slope_x, slope_y)


@dataclass(frozen=True)
class Mounting:
    """How the sample sits in its holder for one mounting.

    Attributes
    ----------
    index : int
        Which mounting (0 for the first).
    rotation_deg : float
        Rotation of the sample about its normal, counter-clockwise seen from above [deg].
    offset_mm : (float, float)
        Displacement of the sample's centre from the holder's centre (the window's) [mm].
    seat_tilt_deg : (float, float)
        Tilt of this seating toward +x and +y of the rig, beyond the holder's own [deg].
    spin : bool
        The holder spins the sample about the window's centre during exposures.
    """

    index: int = 0
    rotation_deg: float = 0.0
    offset_mm: tuple[float, float] = (0.0, 0.0)
    seat_tilt_deg: tuple[float, float] = (0.0, 0.0)
    spin: bool = False


def draw_mounting(seed: int, index: int, rotation_deg: float | None, spin: bool, seat_tilt_rms_deg: float,
                  stream: int) -> Mounting:
    """Mounting ``index`` of rig ``seed``: the same draw every time it is asked for.

    The displacement (``N(0, MOUNT_PLAY_MM)`` per axis), the seat's tilt
    (``N(0, seat_tilt_rms_deg)`` per axis) and, when ``rotation_deg`` is None, a rotation
    uniform over the turn come from the random stream ``(seed, stream, index)``, so that a
    resumed run meets each mounting as it was.

    Examples
    --------
    >>> draw_mounting(0, 2, 90.0, False, 0.05, 11) == draw_mounting(0, 2, 90.0, False, 0.05, 11)
    True
    """
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(stream), int(index))))
    offset = tuple(float(v) for v in MOUNT_PLAY_MM * rng.standard_normal(2))
    tilt = tuple(float(v) for v in seat_tilt_rms_deg * rng.standard_normal(2))
    drawn = float(rng.uniform(0.0, 360.0))
    rotation = drawn if rotation_deg is None else float(rotation_deg)
    return Mounting(int(index), rotation, offset, tilt, bool(spin))  # type: ignore[arg-type]


def mounting_tilt(mounting: Mounting, wedge_deg: tuple[float, float]) -> tuple[float, float]:
    """Tilt of the sample's normal beyond the holder's, toward +x and +y of the rig [deg]:
    its wedge (fixed in the sample, turned with it) and its seat. Zero while spinning
    (both turn with the sample and average out to first order).

    Examples
    --------
    >>> [round(v, 9) for v in mounting_tilt(Mounting(rotation_deg=90.0), (0.1, 0.0))]
    [0.0, 0.1]
    """
    if mounting.spin:
        return 0.0, 0.0
    c, s = math.cos(math.radians(mounting.rotation_deg)), math.sin(math.radians(mounting.rotation_deg))
    wx, wy = wedge_deg
    return (c * wx - s * wy + mounting.seat_tilt_deg[0], s * wx + c * wy + mounting.seat_tilt_deg[1])


@dataclass(frozen=True)
class LabTexture:
    """The texture as the rig sees it for one mounting: six fields on a grid of the rig's
    frame (x in the camera's swing plane), slopes in the rig's frame [rad].

    Attributes
    ----------
    coordinates_mm : numpy.ndarray
        Grid coordinates along x and y [mm].
    fields : numpy.ndarray
        ``a, a sx, a sy, a sx^2, a sx sy, a sy^2`` (:data:`FIELDS`), shape (6, y, x).
    integrals : numpy.ndarray
        Their cumulative integrals along x [mm], shape (6, y, x) (for averages over a
        pixel's footprint).
    """

    coordinates_mm: np.ndarray
    fields: np.ndarray
    integrals: np.ndarray


def _rotated_fields(texture: TextureRealisation, rotation_deg: float, offset_mm: tuple[float, float],
                    x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The six fields at rig points (x, y) [mm] for the sample rotated and displaced."""
    c, s = math.cos(math.radians(rotation_deg)), math.sin(math.radians(rotation_deg))
    dx, dy = x - offset_mm[0], y - offset_mm[1]
    xs, ys = c * dx + s * dy, -s * dx + c * dy  # sample frame: R(-rotation) (p - offset)
    index = (ys - texture.coordinates_mm[0]) / texture.step_mm, (xs - texture.coordinates_mm[0]) / texture.step_mm
    sample = lambda f: ndimage.map_coordinates(f, index, order=1, mode="nearest")  # noqa: E731
    a, sx0, sy0 = sample(texture.albedo), sample(texture.slope_x), sample(texture.slope_y)
    sx, sy = c * sx0 - s * sy0, s * sx0 + c * sy0  # slopes turned into the rig's frame
    return np.stack([a, a * sx, a * sy, a * sx * sx, a * sx * sy, a * sy * sy])


def lab_texture(texture: TextureRealisation, mounting: Mounting,
                half_extent_mm: float = SAMPLE_HALF_SIDE_MM + 1.0) -> LabTexture:
    """The texture of ``mounting`` on a grid of the rig's frame covering the sample's image.

    Parameters
    ----------
    texture : TextureRealisation
    mounting : Mounting
        Rotation, displacement and spinning (spinning: every field averaged over
        :data:`SPIN_STEPS` rotations about the window's centre, a whole turn).
    half_extent_mm : float
        Half the side of the rig-frame grid [mm].

    Examples
    --------
    >>> t = realise_texture(0.03, 0.0, 1.0, np.random.default_rng(0))
    >>> still, spun = lab_texture(t, Mounting()), lab_texture(t, Mounting(spin=True))
    >>> bool(spun.fields[0].std() < still.fields[0].std())    # spinning smooths the albedo
    True
    """
    step = texture.step_mm
    n = int(math.ceil(2 * half_extent_mm / step)) + 1
    coordinates = (np.arange(n) - (n - 1) / 2.0) * step
    x, y = np.meshgrid(coordinates, coordinates)
    if mounting.spin:
        angles = mounting.rotation_deg + 360.0 * np.arange(SPIN_STEPS) / SPIN_STEPS
        fields = sum(_rotated_fields(texture, a, mounting.offset_mm, x, y) for a in angles) / SPIN_STEPS
    else:
        fields = _rotated_fields(texture, mounting.rotation_deg, mounting.offset_mm, x, y)
    integrals = np.concatenate([np.zeros(fields.shape[:2] + (1,)),
                                np.cumsum(0.5 * (fields[..., 1:] + fields[..., :-1]) * step, axis=-1)], axis=-1)
    return LabTexture(coordinates, fields, integrals)


@dataclass(frozen=True)
class Footprints:
    """The six fields averaged over the pixels' footprints along x (:func:`footprints`),
    before their interpolation to the image's rows.

    Attributes
    ----------
    columns : numpy.ndarray
        Shape (6, grid rows, image width).
    row_index, row_weight : numpy.ndarray
        Each image row lies between grid rows ``k`` and ``k + 1`` with weight ``w`` on
        ``k + 1``, shape (height,).
    outside : numpy.ndarray
        Pixels off the grid (outside the sample's image), shape (height, width).
    """

    columns: np.ndarray
    row_index: np.ndarray
    row_weight: np.ndarray
    outside: np.ndarray

    def rows(self, columns: np.ndarray) -> np.ndarray:
        """Fields given per grid row and image column (..., grid rows, width) at the image's rows."""
        k, w = self.row_index, self.row_weight[:, None]
        return columns[..., k, :] * (1.0 - w) + columns[..., k + 1, :] * w


def footprints(texture: LabTexture, optics: Optics, theta_r: float) -> Footprints:
    """The texture's fields averaged over each pixel's footprint on the sample.

    A pixel sees ``p / m`` [mm] of the sample across the swing plane and
    ``p / (m cos theta_r)`` along it (:func:`~drivers.emulator.world.pixel_sample_coordinates`):
    each field is averaged over that length along x (from its cumulative integral); along
    y it is interpolated linearly (the grid is finer than the texture's length / 3). Pixels
    off the grid (outside the sample's image) are marked ``outside``.
    """
    x, y = pixel_sample_coordinates(optics, theta_r)
    grid = texture.coordinates_mm
    lo, hi, step = grid[0], grid[-1], grid[1] - grid[0]
    pixel_mm = optics.pixel_pitch_um * 1e-3 / optics.magnification
    half = 0.5 * pixel_mm / max(math.cos(math.radians(theta_r)), 1e-9)
    inside_x = np.isfinite(x) & (x - half >= lo) & (x + half <= hi)
    x_lo, x_hi = x[inside_x] - half, x[inside_x] + half

    def integral_at(points: np.ndarray) -> np.ndarray:  # (6, grid rows, columns), linear along x
        position = (points - lo) / step
        k = np.clip(np.floor(position).astype(int), 0, grid.size - 2)
        w = position - k
        return texture.integrals[..., k] * (1.0 - w) + texture.integrals[..., k + 1] * w

    # only the columns that see the sample: the others are marked outside and never read
    columns = np.zeros(texture.integrals.shape[:2] + x.shape)
    columns[..., inside_x] = (integral_at(x_hi) - integral_at(x_lo)) / (x_hi - x_lo)
    position = (y - lo) / step
    inside_y = (position >= 0) & (position <= grid.size - 1)
    k = np.clip(np.floor(position).astype(int), 0, grid.size - 2)
    w = np.clip(position - k, 0.0, 1.0)
    return Footprints(columns, k, w, ~(inside_y[:, None] & inside_x[None, :]))


def pixel_maps(texture: LabTexture, optics: Optics, theta_r: float) -> np.ndarray:
    """The six fields over each pixel's footprint (:func:`footprints`), shape (6, height, width);
    pixels off the sample take the neutral values ``a = 1``, slopes 0.

    Examples
    --------
    >>> t = lab_texture(realise_texture(0.03, 1.0, 1.0, np.random.default_rng(0)), Mounting())
    >>> maps = pixel_maps(t, Optics(), 30.0)
    >>> maps.shape, float(maps[0, 0, 0]), float(maps[1, 0, 0])    # a corner pixel: off the sample
    ((6, 480, 512), 1.0, 0.0)
    """
    where = footprints(texture, optics, theta_r)
    maps = where.rows(where.columns)
    maps[:, where.outside] = 0.0
    maps[0, where.outside] = 1.0
    return maps


@dataclass(frozen=True)
class SlopeResponse:
    """Second-order expansion of a facet's apparent reflectance in its slope (sx, sy) [rad]:
    ``F(s) = value + gx sx + gy sy + (hxx sx^2 + 2 hxy sx sy + hyy sy^2) / 2`` [1/sr]."""

    value: float
    gx: float = 0.0
    gy: float = 0.0
    hxx: float = 0.0
    hxy: float = 0.0
    hyy: float = 0.0


def slope_response(brdf: Brdf, theta_i: float, phi_i: float, theta_r: float, phi_r: float,
                   slope_rms_deg: float) -> SlopeResponse:
    """How the apparent reflectance of a facet changes with its slope, to second order.

    The facet's normal is tipped by ``(sx, sy)`` toward +x and +y
    (:func:`drivers.rig_geometry.misaligned_angles`' convention); its apparent
    reflectance is ``F(s) = f cos(theta_i,facet) x cos(theta_r,facet) / (cos(theta_r) n_z)``
    with ``n_z = cos sx cos sy`` (the BRDF and irradiance in the facet's frame times the
    facet's projected area toward the camera relative to the mean plane's; 0 for a facet
    that faces away from the camera or the lamp). It is evaluated on a 3 x 3 stencil at
    ``0, +/- sqrt(3) slope_rms`` (the nodes of 3-point Gauss-Hermite quadrature) and
    expanded by central differences.

    Decision: ``F`` is evaluated on the lamp's and the camera's axes, not averaged over
    their cones as the rig's radiance is (:func:`~drivers.emulator.world.cone_averaged_reflectance`):
    only its relative change with the slope is used (:func:`relative_radiance`), and the
    cones (half-angles 1.8 and 1.0 deg) change that by a fraction of order half-angle^2,
    1e-3 of itself, at 1/49 of the cost (the exact V-cavity model takes 2 ms a direction).

    Parameters
    ----------
    brdf : callable
        The sample's BRDF [1/sr], degrees, broadcasting.
    theta_i, phi_i, theta_r, phi_r : float
        Lamp and camera directions in the sample's mean frame [deg].
    slope_rms_deg : float
        Rms slope of the facets [deg] (0: only ``value``).

    Examples
    --------
    >>> lambert = lambda ti, pi, tr, pr: np.full(np.broadcast(ti, pi, tr, pr).shape, 1 / np.pi)
    >>> r = slope_response(lambert, 60.0, 0.0, 0.0, 0.0, 1.0)
    >>> round(r.gx / r.value, 2)        # d ln cos(theta_i) / d tilt toward the lamp (+x): tan 60
    1.73
    """
    h_deg = math.sqrt(3.0) * slope_rms_deg if slope_rms_deg > 0 else 0.0
    sx, sy = np.meshgrid([-h_deg, 0.0, h_deg], [-h_deg, 0.0, h_deg], indexing="ij")
    sx, sy = sx.ravel(), sy.ravel()
    ti, pi_, tr, pr = misaligned_angles(theta_i, phi_i, theta_r, phi_r, tilt_x=sx, tilt_y=sy)
    f = np.asarray(brdf(ti, pi_, tr, pr), float) * np.ones(ti.shape)
    n_z = np.cos(np.radians(sx)) * np.cos(np.radians(sy))
    cos_mean = max(math.cos(math.radians(theta_r)), 1e-12)
    lit, seen = np.cos(np.radians(ti)), np.cos(np.radians(tr))
    visible = (lit > 0) & (seen > 0)
    values = np.where(visible, f * np.clip(lit, 0, None) * np.clip(seen, 0, None) / (cos_mean * n_z), 0.0)
    grid = values.reshape(3, 3)
    if h_deg == 0.0:
        return SlopeResponse(float(grid[1, 1]))
    h = math.radians(h_deg)
    return SlopeResponse(
        value=float(grid[1, 1]),
        gx=float((grid[2, 1] - grid[0, 1]) / (2 * h)), gy=float((grid[1, 2] - grid[1, 0]) / (2 * h)),
        hxx=float((grid[2, 1] - 2 * grid[1, 1] + grid[0, 1]) / h**2),
        hyy=float((grid[1, 2] - 2 * grid[1, 1] + grid[1, 0]) / h**2),
        hxy=float((grid[2, 2] - grid[2, 0] - grid[0, 2] + grid[0, 0]) / (4 * h**2)),
    )


def _coefficients(response: SlopeResponse) -> np.ndarray:
    """Weights of the six fields in a pixel's relative radiance (:func:`relative_radiance`)."""
    r = response
    if r.value <= 0 or not math.isfinite(r.value):
        return np.array([1.0, 0, 0, 0, 0, 0])  # nothing reflected on the axes: the albedo alone
    return np.array([r.value, r.gx, r.gy, 0.5 * r.hxx, r.hxy, 0.5 * r.hyy]) / r.value


def relative_radiance(maps: np.ndarray, response: SlopeResponse) -> np.ndarray:
    """Each pixel's radiance relative to the untextured sample's, shape (height, width).

    ``(a F(0) + gx <a sx> + gy <a sy> + (hxx <a sx^2> + 2 hxy <a sx sy> + hyy <a sy^2>) / 2) / F(0)``
    with the fields of :func:`pixel_maps` (the albedo factor alone where ``F(0)`` is 0).

    Examples
    --------
    >>> maps = np.zeros((6, 2, 2)); maps[0] = [[1.0, 1.1], [0.9, 1.0]]
    >>> relative_radiance(maps, SlopeResponse(0.2)).tolist()
    [[1.0, 1.1], [0.9, 1.0]]
    """
    return np.tensordot(_coefficients(response), maps, axes=1)


def relative_radiance_image(where: Footprints, response: SlopeResponse) -> np.ndarray:
    """:func:`relative_radiance` from the footprints directly (the fields combined per grid row
    first, then interpolated to the image's rows: one interpolation instead of six); 1
    outside the sample's image."""
    combined = np.tensordot(_coefficients(response), where.columns, axes=1)
    image = where.rows(combined)
    image[where.outside] = 1.0
    return image
