"""Periodic Gaussian random height fields, triangulated, with a prescribed facet slope.

A surface the V-cavity model only approximates: smooth random hills and valleys instead
of grooves, with slopes in every direction at once, convex tops that shadow their
neighbours and concave valleys that interreflect.

Construction
------------
1. Heights on an N x N periodic grid of unit cells by spectral synthesis: white Gaussian
   noise filtered in Fourier space by the amplitude exp(-k^2 l^2 / 8), k the wave number
   [1/cell], l the correlation length [cells]: a stationary Gaussian field with the
   correlation function exp(-r^2 / l^2) (the filter is the square root of its power
   spectrum, ~exp(-k^2 l^2 / 4)).  Periodic by construction (discrete Fourier series).
2. Each cell is split along its diagonal u = w into two planar triangles, the facets
   the renderer traces (:mod:`.kernel`, ``FIELD``).
3. The heights are scaled so that the rms facet slope angle, every triangle weighted by
   its projected area (all equal: half a cell), equals :func:`.shapes.rms_slope_angle` of
   the requested sigma: the rms slope angle of Oren & Nayar's Gaussian slope-area
   distribution with that sigma (``oren-nayar-exact``'s convention, eq 6 and 32).

Decision: the mapping matches the rms facet slope *angle* weighted by projected area,
because that is what Oren & Nayar's sigma describes (the slope-area distribution is a
distribution over the mean-plane area, section 3) and it is defined for both surfaces
whatever their shapes.  The two slope distributions still differ: the height field's
gradient is Gaussian (its slope angles are the arctangent of a Rayleigh variable), while
eq 32 is a Gaussian in the angle itself, truncated at 90 deg.  With the default l = 8 cells the triangles resolve the smooth field (the rms
angle of the triangles is within 0.4 % of that of the spectral gradient of the same
heights, measured from 7 to 63 deg; tested to 1 %).  Roughness is
limited to sigma <= 60 deg: beyond it the facets needed approach vertical and the
traversal cost grows without bound.

References
----------
M. Oren, S. K. Nayar, IJCV 14(3), 1995, section 3 (eq 6) and 4.3 (eq 32) for the roughness
the height field is matched to.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .shapes import HeightField, rms_slope_angle

__all__ = ["unit_gaussian_heights", "facet_slopes", "rms_facet_angle", "RealisedField", "realise"]


def unit_gaussian_heights(cells: int, correlation: float, seed: int) -> np.ndarray:
    """A periodic Gaussian random field of unit rms on a cells x cells grid.

    Parameters
    ----------
    cells : int
        Grid points per side (the period) [-].
    correlation : float
        Correlation length l [cells] of the correlation function exp(-r^2/l^2).
    seed : int
        Seed of ``numpy.random.default_rng``.

    Returns
    -------
    numpy.ndarray
        Heights (cells, cells) [arbitrary units], mean 0 and rms 1 exactly.

    Examples
    --------
    >>> h = unit_gaussian_heights(64, 4.0, seed=1)
    >>> h.shape, round(float(np.sqrt(np.mean(h**2))), 12)
    ((64, 64), 1.0)
    """
    noise = np.random.default_rng(seed).standard_normal((cells, cells))
    k = 2.0 * np.pi * np.fft.fftfreq(cells)
    k2 = k[:, None] ** 2 + k[None, :] ** 2
    heights = np.fft.ifft2(np.fft.fft2(noise) * np.exp(-k2 * correlation**2 / 8.0)).real
    heights -= heights.mean()
    return heights / np.sqrt(np.mean(heights**2))


def facet_slopes(heights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients (b, c) of the two triangles of every cell, planes z = a + b u + c w.

    Triangle 0 (u >= w) has corners (0,0), (1,0), (1,1), triangle 1 (w >= u) (0,0),
    (1,1), (0,1) of the cell, as the renderer splits them (:mod:`.kernel`).

    Returns
    -------
    b, c : numpy.ndarray
        Shape (2, cells, cells): [triangle, i, j] [height per cell].
    """
    h00 = heights
    h10 = np.roll(heights, -1, axis=0)
    h01 = np.roll(heights, -1, axis=1)
    h11 = np.roll(h10, -1, axis=1)
    b = np.stack([h10 - h00, h11 - h01])
    c = np.stack([h11 - h10, h01 - h00])
    return b, c


def rms_facet_angle(heights: np.ndarray) -> float:
    """Rms slope angle [deg] of the triangles, each weighted by its projected area.

    Examples
    --------
    >>> round(rms_facet_angle(np.zeros((8, 8))), 12)
    0.0
    """
    b, c = facet_slopes(heights)
    return float(np.degrees(np.sqrt(np.mean(np.arctan(np.hypot(b, c)) ** 2))))


def _scale_for_angle(unit: np.ndarray, target_deg: float) -> float:
    """The factor k with rms_facet_angle(k unit) = target (bisection on the monotone map)."""
    from scipy.optimize import brentq

    if target_deg == 0.0:
        return 0.0
    high = 1.0
    while rms_facet_angle(high * unit) < target_deg:
        high *= 2.0
    return brentq(lambda k: rms_facet_angle(k * unit) - target_deg, 0.0, high, xtol=1e-12 * high, rtol=1e-13)


@dataclass(frozen=True)
class RealisedField:
    """One realisation of a :class:`~.shapes.HeightField`, ready to trace.

    Attributes
    ----------
    heights : numpy.ndarray
        (cells, cells) heights [cell units], C-contiguous float64.
    cell_top : numpy.ndarray
        Highest corner of every cell [cell units].
    top : float
        Highest point [cell units].
    rms_angle : float
        Rms facet slope angle [deg], projected-area weighted (equals
        :func:`.shapes.rms_slope_angle` of sigma).
    rms_height : float
        Rms height [cell units].
    """

    heights: np.ndarray
    cell_top: np.ndarray
    top: float
    rms_angle: float
    rms_height: float


def realise(surface: HeightField) -> RealisedField:
    """The triangulated height field of ``surface`` (module notes).

    Examples
    --------
    >>> field = realise(HeightField(sigma=20.0, rho=0.5, cells=64, correlation=4.0))
    >>> round(field.rms_angle, 6) == round(rms_slope_angle(20.0), 6)
    True
    """
    unit = unit_gaussian_heights(surface.cells, surface.correlation, surface.seed)
    target = rms_slope_angle(surface.sigma)
    heights = np.ascontiguousarray(_scale_for_angle(unit, target) * unit)
    corners = np.stack([heights, np.roll(heights, -1, 0), np.roll(heights, -1, 1),
                        np.roll(np.roll(heights, -1, 0), -1, 1)])
    cell_top = np.ascontiguousarray(corners.max(axis=0))
    return RealisedField(heights, cell_top, float(heights.max()), rms_facet_angle(heights),
                         float(math.sqrt(np.mean(heights**2))))
