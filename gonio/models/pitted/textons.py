"""Textons, radiance histograms and textures of pitted surfaces (section 4.2, Figs 13-14).

A *texton* is the orthographic image of one pit (and a little of the plane around it)
seen from the viewing direction, lit from the source direction; its pixels sample the
orifice uniformly in the projected (image) area, so the histogram of the pit's pixel
radiances is the radiance histogram of section 4.2.  Tiling pits of several diameters
over the plane gives the texture of the pitted surface; the BRDF does not depend on the
diameters, the texture does (section 5).

Radiances are per unit normal irradiance of the beam (H_perp = 1) [1/sr]; the flat plane
has the Lambertian radiance ``rho cos(alpha) / pi``.

Image orientation: columns run along the horizontal direction perpendicular to the
viewing azimuth, rows along the viewing azimuth with the far side of the surface at the
top (row 0), as a camera tilted towards the surface would see it.

References
----------
J. J. Koenderink, A. J. van Doorn, K. J. Dana, S. K. Nayar, IJCV 31(2/3), 1999,
section 4.1 (method), section 4.2 (textons and histograms, Figs 13-14), section 5.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .interreflection import diffuse_radiance
from .shallow import orifice_radiance
from .validation import check_pit_parameters

__all__ = [
    "FIGURE_13_GEOMETRIES",
    "Texton",
    "render_texton",
    "radiance_histogram",
    "Texture",
    "place_pits",
    "render_texture",
]

#: The (alpha, beta, epsilon) triples of Figs 13-14 [deg], row by row; None marks an empty
#: cell of the 5 x 3 layout (epsilon is irrelevant for alpha = 0 or beta = 0 and set to 0).
FIGURE_13_GEOMETRIES: tuple[tuple[tuple[float, float, float] | None, ...], ...] = (
    ((0.0, 0.0, 0.0), (0.0, 30.0, 0.0), (0.0, 60.0, 0.0)),
    (None, (30.0, 30.0, 0.0), (30.0, 60.0, 0.0)),
    ((30.0, 0.0, 0.0), (30.0, 30.0, 180.0), (30.0, 60.0, 180.0)),
    (None, (60.0, 30.0, 0.0), (60.0, 60.0, 0.0)),
    ((60.0, 0.0, 0.0), (60.0, 30.0, 180.0), (60.0, 60.0, 180.0)),
)


def _check_directions(theta_i: float, theta_r: float) -> None:
    for label, angle in (("theta_i", theta_i), ("theta_r", theta_r)):
        if not 0.0 <= angle < 90.0:
            raise ValueError(f"{label} = {angle:g} deg must lie in [0, 90) deg to render a view")


def _plane_points(u: np.ndarray, v: np.ndarray, theta_r: float, epsilon: float) -> np.ndarray:
    """Plane points ``(..., 2)`` seen at image coordinates (u right, v up) [length]."""
    along = -v / np.cos(np.radians(theta_r))  # far side (negative along) at the top
    e = np.radians(epsilon)
    x = along * np.cos(e) - u * np.sin(e)
    y = along * np.sin(e) + u * np.cos(e)
    return np.stack([x, y], axis=-1)


@dataclass(frozen=True)
class Texton:
    """Radiance image of one pit [1/sr per unit beam irradiance].

    Attributes
    ----------
    radiance : numpy.ndarray
        ``(pixels, pixels)`` image, row 0 at the top (far side).
    in_pit : numpy.ndarray of bool
        Pixels that see into the pit (the rest see the flat plane).
    extent : tuple of float
        (left, right, bottom, top) of the image in units of the sphere radius.
    plane_radiance : float
        Radiance of the flat plane ``rho cos(alpha) / pi``.
    diffuse_radiance : float
        Radiance of the cast-shadow part (eq 12 times cos alpha).
    geometry : tuple of float
        (alpha, beta, epsilon) [deg].
    """

    radiance: np.ndarray
    in_pit: np.ndarray
    extent: tuple[float, float, float, float]
    plane_radiance: float
    diffuse_radiance: float
    geometry: tuple[float, float, float]

    @property
    def pit_radiances(self) -> np.ndarray:
        """Radiances of the pixels inside the pit (1-D)."""
        return self.radiance[self.in_pit]


def render_texton(
    theta_i: float, theta_r: float, epsilon: float, rho: float = 1.0, psi: float = 90.0,
    pixels: int = 128, margin: float = 1.15,
) -> Texton:
    """Render the texton of one pit (section 4.2, Fig 13).

    Parameters
    ----------
    theta_i : float
        Source co-elevation alpha [deg], in [0, 90); the source azimuth is 0.
    theta_r : float
        Viewing co-elevation beta [deg], in [0, 90).
    epsilon : float
        Viewing azimuth [deg] (0: backward scattering, 180: forward scattering).
    rho : float
        Micro-scale albedo [-].
    psi : float
        Aperture [deg], 0 < psi <= 90.
    pixels : int
        Image size (square).
    margin : float
        Half-width of the image in units of the orifice radius (>= 1).

    Returns
    -------
    Texton

    Notes
    -----
    Each pixel's line of sight meets the plane at an orifice point or on the flat
    plane; inside the orifice the visual ray is followed into the cavity, the cast-shadow
    test applied and the radiance is ``(rho/pi)(m.i [lit] + H_diff)`` (section 4.1,
    eq 5, 11) -- the same function as the Monte Carlo estimator uses.

    Examples
    --------
    >>> t = render_texton(0.0, 0.0, 0.0, rho=1.0, psi=90.0, pixels=33)
    >>> round(float(t.radiance[16, 16] * 3.141592653589793), 6)   # centre: 1 + H_diff = 1.5
    1.5
    """
    rho, psi, _ = check_pit_parameters(rho=rho, psi=psi)
    _check_directions(theta_i, theta_r)
    if int(pixels) < 2 or not margin >= 1.0:
        raise ValueError(f"pixels = {pixels!r} must be >= 2 and margin = {margin!r} >= 1")
    radius = float(np.sin(np.radians(psi)))
    half = margin * radius
    coords = np.linspace(-half, half, int(pixels))
    u, v = np.meshgrid(coords, coords[::-1])  # row 0 is the top
    points = _plane_points(u, v, theta_r, epsilon)
    in_pit = np.hypot(points[..., 0], points[..., 1]) <= radius
    plane = rho * np.cos(np.radians(theta_i)) / np.pi
    radiance = np.full(u.shape, plane)
    radiance[in_pit] = orifice_radiance(points[in_pit], theta_i, theta_r, epsilon, rho, psi)
    shadow = float(diffuse_radiance(rho, psi)) * np.cos(np.radians(theta_i))
    return Texton(radiance, in_pit, (-half, half, -half, half), plane, shadow, (theta_i, theta_r, epsilon))


def radiance_histogram(radiances: np.ndarray, bins: int = 64, value_range: tuple[float, float] | None = None):
    """Normalised histogram of radiances (section 4.2, Fig 14).

    Parameters
    ----------
    radiances : numpy.ndarray
        Radiance samples, e.g. :attr:`Texton.pit_radiances` [1/sr].
    bins : int
        Number of bins.
    value_range : (float, float), optional
        Histogram range; default the samples' range.

    Returns
    -------
    density, edges : numpy.ndarray
        Probability density per unit radiance and the bin edges [1/sr].

    Examples
    --------
    >>> density, edges = radiance_histogram(np.array([0.1, 0.15, 0.25, 0.3]), bins=2)
    >>> np.round(density, 9).tolist()
    [5.0, 5.0]
    """
    values = np.asarray(radiances, float).ravel()
    if values.size == 0:
        raise ValueError("radiance_histogram needs at least one radiance sample")
    lo, hi = value_range if value_range is not None else (float(values.min()), float(values.max()))
    if hi <= lo:
        hi = lo + max(abs(lo), 1.0) * 1e-6
    return np.histogram(values, bins=int(bins), range=(lo, hi), density=True)


@dataclass(frozen=True)
class Texture:
    """Radiance image of a pitted plane [1/sr per unit beam irradiance].

    Attributes
    ----------
    radiance : numpy.ndarray
        ``(pixels, pixels)`` image, row 0 at the top.
    centres : numpy.ndarray
        Pit centres ``(k, 2)`` on the plane [length units of ``size``].
    diameters : numpy.ndarray
        Pit orifice diameters ``(k,)``.
    coverage : float
        Fraction of the plane covered by the orifices actually placed [-].
    """

    radiance: np.ndarray
    centres: np.ndarray
    diameters: np.ndarray
    coverage: float


def place_pits(
    coverage: float, size: float = 1.0, mean_diameter: float = 0.08, spread: float = 0.5,
    seed: int = 0, tries_per_pit: int = 200,
) -> tuple[np.ndarray, np.ndarray]:
    """Non-overlapping pits with log-normal diameters on a square, periodic plane.

    Parameters
    ----------
    coverage : float
        Target fraction of the plane covered by orifices [-].  Diameters are drawn until
        their total orifice area reaches the target, then placed largest first at random
        positions; a pit that finds no free place in ``tries_per_pit`` draws is dropped,
        so dense targets (above ~0.5 for equal pits) are reached only in part.
    size : float
        Side of the square plane.
    mean_diameter : float
        Median orifice diameter (same length unit as ``size``).
    spread : float
        Standard deviation of log(diameter) [-]; 0 gives equal pits.
    seed : int
        Seed of ``numpy.random.default_rng``.
    tries_per_pit : int
        Random positions tried for each pit.

    Returns
    -------
    centres, diameters : numpy.ndarray
        Placed pits, ``(k, 2)`` and ``(k,)``, by decreasing diameter.
    """
    _, _, coverage = check_pit_parameters(rho=0.0, psi=90.0, coverage=coverage)
    if not (size > 0.0 and 0.0 < mean_diameter <= size and spread >= 0.0):
        raise ValueError(
            f"need size > 0, 0 < mean_diameter <= size and spread >= 0; got size={size!r}, "
            f"mean_diameter={mean_diameter!r}, spread={spread!r}"
        )
    rng = np.random.default_rng(seed)
    target = coverage * size * size
    drawn: list[float] = []
    total = 0.0
    while total < target:
        d = float(min(mean_diameter * np.exp(spread * rng.standard_normal()), 0.5 * size))
        drawn.append(d)
        total += np.pi * d * d / 4.0
    centres = np.empty((0, 2))
    diameters = np.empty(0)
    for d in sorted(drawn, reverse=True):
        trial = rng.random((int(tries_per_pit), 2)) * size
        delta = trial[:, None, :] - centres[None, :, :]
        delta -= size * np.round(delta / size)  # periodic plane
        free = np.all(np.hypot(delta[..., 0], delta[..., 1]) >= 0.5 * (diameters + d), axis=1)
        if np.any(free):
            centres = np.vstack([centres, trial[np.argmax(free)]])
            diameters = np.append(diameters, d)
    return centres, diameters


def render_texture(
    theta_i: float, theta_r: float, epsilon: float, rho: float = 1.0, psi: float = 90.0,
    coverage: float = 0.5, size: float = 1.0, pixels: int = 256, mean_diameter: float = 0.08,
    spread: float = 0.5, seed: int = 0,
) -> Texture:
    """Render the texture of a plane pitted with a distribution of diameters.

    Parameters
    ----------
    theta_i, theta_r, epsilon : float
        Source co-elevation, viewing co-elevation and viewing azimuth [deg].
    rho : float
        Micro-scale albedo [-].
    psi : float
        Aperture of every pit [deg].
    coverage : float
        Target pit coverage [-] (see :func:`place_pits`).
    size : float
        Side of the (periodic) square patch of plane seen in the image's width.
    pixels : int
        Image size (square).
    mean_diameter, spread : float
        Log-normal diameter distribution (median, sigma of the log).
    seed : int
        Seed for the pit placement.

    Returns
    -------
    Texture

    Notes
    -----
    Each pit is the texton of :func:`render_texton` scaled to its diameter (section
    4.1: "repeating textons according to the distribution of pits").  The mean of the
    image over a large patch tends to the BRDF times cos(alpha).

    Examples
    --------
    >>> tex = render_texture(30.0, 0.0, 0.0, pixels=32, coverage=0.3)
    >>> tex.radiance.shape
    (32, 32)
    """
    rho, psi, coverage = check_pit_parameters(rho=rho, psi=psi, coverage=coverage)
    _check_directions(theta_i, theta_r)
    centres, diameters = place_pits(coverage, size, mean_diameter, spread, seed)
    coords = (np.arange(int(pixels)) + 0.5) / int(pixels) * size - 0.5 * size
    u, v = np.meshgrid(coords, coords[::-1])
    # the image shows a size x size window of the image plane; wrap plane points
    points = np.mod(_plane_points(u, v, theta_r, epsilon), size)
    radiance = np.full(u.shape, rho * np.cos(np.radians(theta_i)) / np.pi)
    pit_radius = float(np.sin(np.radians(psi)))
    for centre, diameter in zip(centres, diameters):
        delta = points - centre
        delta -= size * np.round(delta / size)
        inside = np.hypot(delta[..., 0], delta[..., 1]) <= 0.5 * diameter
        if np.any(inside):
            local = delta[inside] * (2.0 * pit_radius / diameter)
            radiance[inside] = orifice_radiance(local, theta_i, theta_r, epsilon, rho, psi)
    area = float(np.sum(np.pi * diameters**2 / 4.0)) / (size * size)
    return Texture(radiance, centres, diameters, area)
