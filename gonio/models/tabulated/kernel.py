"""Compiled evaluation of the tables: coordinates and tricubic sum per geometry (numba).

The tables are read at scattered geometries by the four-point Lagrange cubic of
:mod:`.interpolation` in the three geometry coordinates (y, zeta, t) of
:mod:`.coordinates`.  Done with numpy arrays, every step (the coordinates, the stencils,
the 64-value gather) writes temporaries and the whole costs about 350 ns per geometry;
compiled, one loop computes the coordinates of a geometry, its three stencils and the
weighted sum of its 4 x 4 x 4 block for every component without temporaries (about
100-150 ns per geometry on one core; docs/tabulated.md).

Numba is used rather than C through a compiler at install time: it is a wheel on PyPI for
every supported Python, so the install needs no compiler, and the kernel stays Python
source next to the numpy reference it must agree with
(:func:`.coordinates.geometry_coordinates`, tested to 1e-12).  Compiled code is cached on
disk (``cache=True``), so only the first import on a machine pays the compilation (a few
seconds).

The formulas are those of :mod:`.coordinates` (module notes there) in scalar form; any
change there must be made here too (the tests compare the two on random geometries, the
horizon, the normal and theta_i = theta_r).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .coordinates import Y_OFFSET, Y_SLOPE, y_coordinate

__all__ = ["table_coordinates", "phase_coordinate", "cubic_stencil", "interpolate_points", "interpolate_geometries"]

_HALF_PI = 0.5 * math.pi
_Y_FLOOR = float(y_coordinate(0.0))


@njit(cache=True, nogil=True)
def table_coordinates(theta_i: float, theta_r: float, delta_phi: float) -> tuple[float, float, float]:
    """(y, zeta, t) of one geometry [rad]: :func:`.coordinates.geometry_coordinates` in scalar form."""
    alpha = max(theta_i, theta_r)
    beta = min(theta_i, theta_r)
    z_beta = max(_HALF_PI - beta, 0.0)
    z_alpha = max(_HALF_PI - alpha, 0.0)
    y = math.log(z_beta + Y_OFFSET) + Y_SLOPE * z_beta
    if z_beta > 0.0:
        y_alpha = math.log(z_alpha + Y_OFFSET) + Y_SLOPE * z_alpha
        zeta = 1.0 - math.sqrt(max(1.0 - 0.5 * (z_alpha / z_beta + (y_alpha - _Y_FLOOR) / (y - _Y_FLOOR)), 0.0))
    else:
        zeta = 1.0
    half_dphi = math.sin(0.5 * delta_phi)
    limit = half_dphi * half_dphi
    return y, zeta, phase_coordinate(alpha, beta, math.sin(0.5 * (alpha - beta)), math.sin(0.5 * (alpha + beta)),
                                     limit)


@njit(cache=True, nogil=True)
def phase_coordinate(alpha: float, beta: float, half_diff: float, half_sum: float, limit: float) -> float:
    """The t coordinate of the phase angle between two directions at polar angles ``alpha``
    >= ``beta`` [rad], given ``sin((alpha - beta)/2)``, ``sin((alpha + beta)/2)`` and
    ``sin^2(dphi / 2)``: the phase angle by the haversine formula (``sin(alpha) sin(beta)``
    written as ``sin^2((alpha + beta)/2) - sin^2((alpha - beta)/2)``: two positive terms),
    then its position p between the extremes, mapped to t."""
    half = half_diff * half_diff * (1.0 - limit) + half_sum * half_sum * limit
    phase = 2.0 * math.asin(math.sqrt(min(max(half, 0.0), 1.0)))
    if beta > 1e-6:
        p = (phase - (alpha - beta)) / (2.0 * beta)
    else:
        p = limit
    p = min(max(p, 0.0), 1.0)
    return 0.5 * (math.sqrt(p) + 1.0 - math.sqrt(math.sqrt(1.0 - p)))


@njit(cache=True, nogil=True)
def cubic_stencil(x: float, lo: float, step: float, size: int) -> tuple[int, float, float, float, float]:
    """First node and the four Lagrange weights of the cubic stencil containing ``x``.

    :func:`.interpolation.axis_stencil` for one coordinate: ``x`` is clamped to the axis,
    the stencil is the four nodes around its cell (one-sided in the first and last cells).
    """
    hi = lo + step * (size - 1)
    u = (min(max(x, lo), hi) - lo) / step
    first = min(max(int(u) - 1, 0), size - 4)
    tau = u - first
    t1, t2, t3 = tau - 1.0, tau - 2.0, tau - 3.0
    t01, t23 = tau * t1, t2 * t3
    return (first, -t1 * t23 * (1.0 / 6.0), 0.5 * tau * t23, -0.5 * t01 * t3, t01 * t2 * (1.0 / 6.0))


@njit(cache=True, nogil=True)
def _tricubic_into(flat: np.ndarray, shape: tuple[int, int, int, int], lo: np.ndarray, step: np.ndarray,
                   y: float, zeta: float, t: float, out: np.ndarray, k: int) -> None:
    """The 4 x 4 x 4 tensor-product cubic of one or two components at one point, into ``out[:, k]``.

    ``flat`` is the (y, zeta, t, component) table raveled, of the given ``shape``.  The four
    t nodes of both components lie next to each other (8 values), so the block is 16 short
    runs; they are weighted by the (y, zeta) weights into eight accumulators, then by the
    t weights.  Offsets are unsigned, so no negative-index handling is compiled in.
    """
    ny, nz, nt, components = shape
    fy, a0, a1, a2, a3 = cubic_stencil(y, lo[0], step[0], ny)
    fz, b0, b1, b2, b3 = cubic_stencil(zeta, lo[1], step[1], nz)
    ft, c0, c1, c2, c3 = cubic_stencil(t, lo[2], step[2], nt)
    wy = (a0, a1, a2, a3)
    wz = (b0, b1, b2, b3)
    z_stride = nt * components
    y_stride = nz * z_stride
    base = (fy * nz + fz) * z_stride + ft * components
    c = np.uint64(components)
    last = np.uint64(components - 1)  # reads component 0 twice when there is one
    s00 = s01 = s10 = s11 = s20 = s21 = s30 = s31 = 0.0
    for i in range(4):
        for j in range(4):
            w = wy[i] * wz[j]
            o = np.uint64(base + i * y_stride + j * z_stride)
            s00 += w * flat[o]
            s01 += w * flat[o + last]
            s10 += w * flat[o + c]
            s11 += w * flat[o + c + last]
            s20 += w * flat[o + c + c]
            s21 += w * flat[o + c + c + last]
            s30 += w * flat[o + c + c + c]
            s31 += w * flat[o + c + c + c + last]
    out[0, k] = c0 * s00 + c1 * s10 + c2 * s20 + c3 * s30
    if components == 2:
        out[1, k] = c0 * s01 + c1 * s11 + c2 * s21 + c3 * s31


@njit(cache=True, nogil=True)
def interpolate_points(
    table: np.ndarray, lo: np.ndarray, step: np.ndarray,
    y: np.ndarray, zeta: np.ndarray, t: np.ndarray, out: np.ndarray,
) -> None:
    """Tricubic interpolation of a (y, zeta, t, component) table at given table coordinates.

    Parameters as :func:`interpolate_geometries`, with the coordinates (each of shape (m,))
    in place of the geometries.
    """
    flat = table.ravel()
    for k in range(y.shape[0]):
        _tricubic_into(flat, table.shape, lo, step, y[k], zeta[k], t[k], out, k)


@njit(cache=True, nogil=True)
def interpolate_geometries(
    table: np.ndarray,
    lo: np.ndarray,
    step: np.ndarray,
    theta_i: np.ndarray,
    theta_r: np.ndarray,
    delta_phi: np.ndarray,
    out: np.ndarray,
) -> None:
    """Tricubic interpolation of a (y, zeta, t, component) table at many geometries.

    Parameters
    ----------
    table : numpy.ndarray
        C-contiguous float64 values, shape (ny, nz, nt, C) with C = 1 or 2 components
        (one accumulator each, kept in registers), nodes regular on each axis.
    lo, step : numpy.ndarray
        First node and node spacing of the three axes, shape (3,).
    theta_i, theta_r, delta_phi : numpy.ndarray
        Geometries [rad], shape (m,).
    out : numpy.ndarray
        Receives the interpolated values, shape (C, m) (one contiguous row per component).
    """
    flat = table.ravel()
    for k in range(theta_i.shape[0]):
        y, zeta, t = table_coordinates(theta_i[k], theta_r[k], delta_phi[k])
        _tricubic_into(flat, table.shape, lo, step, y, zeta, t, out, k)
