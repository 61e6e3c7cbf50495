"""Compiled radiance of a misaligned rig through its apertures, for fits of the alignment.

A fit with free alignment parameters (:mod:`gonio.fitting.rig_errors`) gives every walker
its own true geometry, so the aperture average of the model (the k x k sub-rays of
:func:`gonio.instrument.aperture_averaged` about each true lamp and camera axis, k = 7 for
the full cubature and 4 for the compact one) cannot be prepared once.  Done with numpy
arrays, every walker's W x N x k^2 sub-rays go through
:func:`drivers.rig_geometry.misaligned_angles`, :func:`gonio.instrument.cone_quadrature`
and the model, each writing temporaries in degrees and back (about 0.6 ms per walker on
the Fig 16 recording).  This module computes the same number in one compiled loop:

- the true lamp axis of each walker and each distinct recorded lamp direction, and the
  true camera axis of each walker and each distinct recorded camera direction, as unit
  vectors (the rotations of :func:`~drivers.rig_geometry.misaligned_angles`: axis zero
  offsets, then the sample's tilt);
- the sub-rays of each axis in the frame of that axis for both cubatures (the 7 of the full
  rule and the 4 of the compact one, :func:`~gonio.instrument.cone_quadrature`),
  each with its polar angle, ``sin``, ``cos`` and ``tan`` and the cosine and sine of its
  azimuth computed once;
- for every value, the rule :func:`gonio.instrument.aperture_rule` chooses at its true
  axes (the compact one, 16 pairs, for a model of
  :data:`gonio.instrument.COMPACT_RULE_MODELS` away from the horizon and the
  retro-reflection direction; the full one, 49 pairs, elsewhere), and its (lamp, camera)
  pairs: the Oren-Nayar BRDF of eq 33-35 written
  with per-direction sines and cosines (``sin(alpha)`` is the larger of the two sines,
  ``tan(beta)`` the smaller tangent, ``cos(dphi)`` the dot product of the two azimuths'
  unit vectors, ``tan((alpha + beta)/2) = (sin a + sin b)/(cos a + cos b)``), floored at 0,
  weighted by the cubature and the lamp sub-ray's ``cos(theta_i)``.

Lambert is the same loop with the coefficients (rho/pi, 0, 0); the qualitative model (eq 36)
the same loop with its own shape, ``a + b max(0, cos dphi) sin(alpha) tan(beta)``.  The lamp sub-rays depend on
the lamp direction only and the camera sub-rays on the camera direction only, so a
recording's three lamp directions cost 3 x 11 sub-rays per walker, not N x 11.

``oren-nayar-tabulated`` (the exact V-cavity model read from its table) is the same loop
with the table read at every (lamp, camera) pair instead of eq 33-35
(:func:`rig_radiance_table`): each walker's table is first reduced along the roughness
axis at its sigma (:func:`gonio.models.tabulated.interpolation.contract_first_axis`, four
slabs), then every pair's table coordinates and tricubic sum are those of the model's own
compiled kernel (:func:`gonio.models.tabulated.kernel.table_coordinates`, the same
``_tricubic_into``), and ``f = rho f1 + rho^2 f2`` with
``f1, f2`` from the logarithms exactly as :class:`gonio.models.tabulated.oren_nayar.OrenNayarTable`
takes them.

The arithmetic of eq 33-35 is the models' own scalar form
(:func:`gonio.models.oren_nayar.compiled.eq33_35`), the cubature's points those of
:func:`gonio.instrument.cone_offsets`; the rotations are those of
:func:`~drivers.rig_geometry.misaligned_angles` and the sub-ray frame that of
:func:`~gonio.instrument.cone_quadrature` in scalar form: any change there must be made
here too (tests/fitting/test_compiled_rig.py compares the two paths on random alignments,
the normal view, a lamp pushed through the normal and grazing axes).

References
----------
M. Oren, S. K. Nayar, IJCV 14(3), 1995, eq 33-35 (the model), section 5 (the apertures).
A. H. Stroud, *Approximate Calculation of Multiple Integrals*, 1971, formula S2:3-1.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
from numba import njit, prange

from drivers.rig_geometry import ALIGNMENT_ERRORS
from gonio.instrument import COMPACT_MAX_THETA_DEG, COMPACT_MIN_SEPARATION_DEG, COMPACT_RULE_MODELS, RULES, cone_offsets
from gonio import models
from gonio.models import Model
from gonio.models._compiled import JIT_OPTIONS
from gonio.models.oren_nayar.compiled import eq33_35
from gonio.models.tabulated.coordinates import Y_OFFSET, Y_SLOPE, y_coordinate
from gonio.models.tabulated.kernel import _tricubic_into, phase_coordinate
from gonio.models.tabulated.oren_nayar_table import F2_FLOOR

from .evaluation import COMPILED_MODELS

__all__ = ["CompiledRigRadiance", "rig_radiance", "rig_radiance_table"]

#: The model whose table the compiled loop reads (:func:`rig_radiance_table`).
TABULATED = "oren-nayar-tabulated"
#: The model whose shape is eq 36's (:func:`_qualitative`), not eq 33-35's.
QUALITATIVE = "oren-nayar-qualitative"
#: The diffuse + specular model (eq 38), whose loop adds the lobe of :func:`_specular`.
COMBINED = "oren-nayar+torrance-sparrow"

_RAD = math.pi / 180.0
_HALF_PI = 0.5 * math.pi
_Y_FLOOR = float(y_coordinate(0.0))
#: The tabulated loop's options: walkers in parallel threads (measured on two cores,
#: docs/fitting.md "The rig's errors as parameters").
JIT_OPTIONS_PARALLEL = dict(JIT_OPTIONS, parallel=True)
#: cos(theta_i) of an axis at or below which the aperture average is not weighted by the
#: sub-rays' cosines (as :class:`gonio.instrument._SubRays` does at grazing incidence).
_GRAZING_COS = 1e-12
#: The sub-rays of both cubatures of :data:`gonio.instrument.RULES` in the kernels' arrays:
#: the full rule's 7 (its first the cone's axis), then the compact rule's 4.
_FULL = len(RULES["full"][2])
_POINTS = _FULL + len(RULES["compact"][2])
#: :func:`gonio.instrument.aperture_rule`'s limits as cosines: of the largest polar angle of
#: an axis, and of the smallest angle between lamp and camera axes.
_COMPACT_COS_THETA = math.cos(math.radians(COMPACT_MAX_THETA_DEG))
_COMPACT_COS_SEPARATION = math.cos(math.radians(COMPACT_MIN_SEPARATION_DEG))
# The fields of a sub-ray in the kernel's scratch arrays (11, 6): theta [rad], cos(phi),
# sin(phi), sin(theta), cos(theta), tan(theta).


@njit(**JIT_OPTIONS)
def _to_sample(x: float, y: float, z: float, ca: float, sa: float, cb: float, sb: float):
    """A lab direction in the tilted sample's frame: ``R^T d`` with ``R = R_y(a) R_x(-b)``."""
    x1, z1 = x * ca - z * sa, x * sa + z * ca
    return x1, y * cb - z1 * sb, y * sb + z1 * cb


@njit(**JIT_OPTIONS)
def _cone_rays(vx: float, vy: float, vz: float, cos_beta, sin_beta, cos_ring, sin_ring, rays) -> float:
    """The sub-rays of both cubatures about the axis ``v`` into ``rays`` (11, 6: theta [rad],
    cos and sin of phi, sin, cos and tan of theta); returns cos(theta) of the axis.

    The frame of :func:`gonio.instrument.cone_quadrature`: ``e1`` along increasing polar
    angle, ``e2`` along increasing azimuth (the azimuth of an axis on the normal is
    ``atan2(y, x)`` of its components, as the angles' path takes it).
    """
    norm = math.sqrt(vx * vx + vy * vy + vz * vz)
    ax, ay, az = vx / norm, vy / norm, vz / norm
    rho = math.hypot(ax, ay)
    if rho > 0.0:
        cp, sp = ax / rho, ay / rho
    else:
        p = math.atan2(ay, ax)
        cp, sp = math.cos(p), math.sin(p)
    e1x, e1y, e1z = az * cp, az * sp, -rho
    for j in range(cos_beta.shape[0]):
        u = sin_beta[j] * cos_ring[j]
        w = sin_beta[j] * sin_ring[j]
        x = cos_beta[j] * ax + u * e1x - w * sp
        y = cos_beta[j] * ay + u * e1y + w * cp
        z = cos_beta[j] * az + u * e1z
        r = math.hypot(x, y)
        theta = math.atan2(r, z)
        rays[j, 0] = theta
        if r > 0.0:
            rays[j, 1] = x / r
            rays[j, 2] = y / r
        else:  # on the normal: beta = 0 and no term of the model depends on the azimuth
            rays[j, 1] = 1.0
            rays[j, 2] = 0.0
        rays[j, 3] = r
        rays[j, 4] = z
        rays[j, 5] = math.tan(theta)
    return az


@njit(**JIT_OPTIONS)
def _rule_range(lamp_rays, camera_rays, lamp: int, camera: int, compact: bool) -> tuple[int, int]:
    """The sub-rays ``[first, stop)`` of the cubature :func:`gonio.instrument.aperture_rule`
    chooses for one true (lamp, camera) pair of axes: the compact rule's where ``compact``
    (the model is one of :data:`gonio.instrument.COMPACT_RULE_MODELS`), both axes are within
    its polar angle and apart by at least its separation; the full rule's elsewhere."""
    c_i, c_r = lamp_rays[lamp, 0, 4], camera_rays[camera, 0, 4]  # the full rule's first ray is the axis
    if compact and c_i >= _COMPACT_COS_THETA and c_r >= _COMPACT_COS_THETA:
        dot = (lamp_rays[lamp, 0, 3] * camera_rays[camera, 0, 3]
               * (lamp_rays[lamp, 0, 1] * camera_rays[camera, 0, 1] + lamp_rays[lamp, 0, 2] * camera_rays[camera, 0, 2])
               + c_i * c_r)
        if dot <= _COMPACT_COS_SEPARATION:
            return _FULL, _POINTS
    return 0, _FULL


@njit(**JIT_OPTIONS)
def _oren_nayar(t_i: float, cp_i: float, sp_i: float, s_i: float, c_i: float, tan_i: float,
                t_r: float, cp_r: float, sp_r: float, s_r: float, c_r: float, tan_r: float,
                a: float, b: float, c: float) -> float:
    """``max(a + b direct_shape + c ir_shape, 0)`` of one (lamp, camera) sub-ray pair, each
    given by theta [rad], cos and sin of phi, sin, cos and tan of theta: the arguments of
    eq 33-35 (:func:`~gonio.models.oren_nayar.compiled.eq33_35`) from these per-direction
    values."""
    cos_dphi = min(max(cp_i * cp_r + sp_i * sp_r, -1.0), 1.0)
    if t_i >= t_r:
        alpha, beta, sin_alpha, tan_beta = t_i, t_r, s_i, tan_r
    else:
        alpha, beta, sin_alpha, tan_beta = t_r, t_i, s_r, tan_i
    cosines = c_i + c_r
    half = (s_i + s_r) / cosines if cosines > 0.0 else math.tan(0.5 * (alpha + beta))
    return eq33_35(cos_dphi, sin_alpha, tan_beta, alpha, beta, half, a, b, c)


@njit(**JIT_OPTIONS)
def _qualitative(t_i: float, cp_i: float, sp_i: float, s_i: float, tan_i: float,
                 t_r: float, cp_r: float, sp_r: float, s_r: float, tan_r: float, a: float, b: float) -> float:
    """``a + b max(0, cos dphi) sin(alpha) tan(beta)`` of one (lamp, camera) sub-ray pair:
    the qualitative model, eq 36 (as :func:`gonio.models.oren_nayar.functional._prepare_qualitative`
    forms it), from the per-direction values of :func:`_oren_nayar`."""
    cos_dphi = min(max(cp_i * cp_r + sp_i * sp_r, -1.0), 1.0)
    if cos_dphi <= 0.0:
        return a
    sin_alpha, tan_beta = (s_i, tan_r) if t_i >= t_r else (s_r, tan_i)
    return a + b * cos_dphi * sin_alpha * tan_beta


@njit(**JIT_OPTIONS)
def _specular(s_i: float, cp_i: float, sp_i: float, c_i: float, s_r: float, cp_r: float, sp_r: float, c_r: float,
              amplitude: float, exponent: float) -> float:
    """The Torrance-Sparrow lobe of eq 37 with F = 1 of one (lamp, camera) sub-ray pair,
    ``amplitude exp(exponent theta_a^2) GAF / (4 cos ti cos tr cos theta_a)`` with
    ``amplitude = ks c(sigma_s)`` and ``exponent = -1 / (2 sigma_s^2)`` [rad^-2], as
    :func:`gonio.models.torrance_sparrow._specular_geometry` forms it: the half vector
    h = s + v is the facet normal (theta_a its slope), and the V-cavity GAF of eq 15 with
    <s,a> = <v,a> = |h| / 2 and <a,n> = h_z / |h| is min(1, 4 cos(theta) h_z / |h|^2) for
    the lower of the two cosines, floored at 0."""
    hx = s_i * cp_i + s_r * cp_r
    hy = s_i * sp_i + s_r * sp_r
    hz = c_i + c_r
    planar = math.sqrt(hx * hx + hy * hy)
    length_sq = planar * planar + hz * hz
    denominator = 4.0 * c_i * c_r * hz
    if length_sq <= 0.0 or not denominator > 0.0:
        return 0.0
    gaf = min(1.0, 4.0 * min(c_i, c_r) * hz / length_sq)
    if gaf <= 0.0:
        return 0.0
    theta_a = math.atan2(planar, hz)
    # GAF / (4 cos ti cos tr cos theta_a), cos theta_a = h_z / |h|
    return amplitude * math.exp(exponent * theta_a * theta_a) * gaf * math.sqrt(length_sq) / denominator


@njit(**JIT_OPTIONS)
def _walker_rays(alignment, lamp_directions, camera_directions, lamp_rule, camera_rule, ring, lamp_rays, camera_rays,
                 lamp_cos, camera_cos, w) -> None:
    """The sub-rays of every distinct lamp and camera direction at walker ``w``'s alignment
    (as :func:`rig_radiance` computes them)."""
    swing = alignment[w, 0] * _RAD
    cs, ss = math.cos(swing), math.sin(swing)
    ta, tb = alignment[w, 3] * _RAD, alignment[w, 4] * _RAD
    ca, sa, cb, sb = math.cos(ta), math.sin(ta), math.cos(tb), math.sin(tb)
    for k in range(lamp_directions.shape[0]):
        t = (lamp_directions[k, 0] + alignment[w, 1]) * _RAD
        p = (lamp_directions[k, 1] + alignment[w, 2]) * _RAD
        x, y, z = _to_sample(math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t), ca, sa, cb, sb)
        lamp_cos[k] = _cone_rays(x, y, z, lamp_rule[0], lamp_rule[1], ring[0], ring[1], lamp_rays[k])
    for k in range(camera_directions.shape[0]):
        t, p = camera_directions[k, 0] * _RAD, camera_directions[k, 1] * _RAD
        cx, cy, cz = math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)
        x, y, z = _to_sample(cx * cs + cz * ss, cy, cz * cs - cx * ss, ca, sa, cb, sb)
        camera_cos[k] = _cone_rays(x, y, z, camera_rule[0], camera_rule[1], ring[0], ring[1], camera_rays[k])


@njit(**JIT_OPTIONS)
def rig_radiance(lamp_directions, camera_directions, lamp_of, camera_of, alignment, coefficients,
                 lamp_rule, camera_rule, ring, weights, compact, qualitative, specular, out) -> None:
    """``<f cos theta_i>`` through the apertures at the true geometry of every alignment [1/sr].

    Parameters
    ----------
    lamp_directions, camera_directions : numpy.ndarray
        Distinct recorded lamp and camera directions (theta, phi) [deg], shapes (L, 2), (C, 2).
    lamp_of, camera_of : numpy.ndarray of int
        For each of the N values, its lamp and camera direction.
    alignment : numpy.ndarray
        (W, 5) view_offset, theta_i_offset, phi_i_offset, tilt_x, tilt_y [deg].
    coefficients : numpy.ndarray
        (W, 5) the model's a, b, c (:func:`_oren_nayar`; :func:`_qualitative` takes a, b)
        and the specular lobe's amplitude and exponent (:func:`_specular`).
    lamp_rule, camera_rule : numpy.ndarray
        (2, 11) cos and sin of each cubature point's angle from its cone's axis (the full
        rule's 7 points, then the compact rule's 4, :func:`_rule`).
    ring, weights : numpy.ndarray
        (2, 11) cos and sin of the points' angles around the axis; (11,) their weights
        (each rule's summing to 1).
    compact : bool
        Whether the model may take the compact rule (:func:`_rule_range`).
    qualitative : bool
        The qualitative model's shape (eq 36, :func:`_qualitative`) instead of eq 33-35's.
    specular : bool
        Add the Torrance-Sparrow lobe (eq 37-38, :func:`_specular`).
    out : numpy.ndarray
        (W, N), written: 0 where a true axis lies below the horizon.
    """
    lamp_rays = np.empty((lamp_directions.shape[0], _POINTS, 6))
    camera_rays = np.empty((camera_directions.shape[0], _POINTS, 6))
    lamp_cos = np.empty(lamp_directions.shape[0])
    camera_cos = np.empty(camera_directions.shape[0])
    for w in range(alignment.shape[0]):
        _walker_rays(alignment, lamp_directions, camera_directions, lamp_rule, camera_rule, ring, lamp_rays,
                     camera_rays, lamp_cos, camera_cos, w)
        a, b, c = coefficients[w, 0], coefficients[w, 1], coefficients[w, 2]
        amplitude, exponent = coefficients[w, 3], coefficients[w, 4]
        for n in range(lamp_of.shape[0]):
            lamp, camera = lamp_of[n], camera_of[n]
            if lamp_cos[lamp] < 0.0 or camera_cos[camera] < 0.0:  # an axis below the horizon
                out[w, n] = 0.0
                continue
            grazing = lamp_cos[lamp] <= _GRAZING_COS
            first, stop = _rule_range(lamp_rays, camera_rays, lamp, camera, compact)
            total = 0.0
            for i in range(first, stop):
                c_i = lamp_rays[lamp, i, 4]
                if c_i < 0.0:  # a sub-ray below the horizon reflects nothing
                    continue
                t_i, cp_i, sp_i = lamp_rays[lamp, i, 0], lamp_rays[lamp, i, 1], lamp_rays[lamp, i, 2]
                s_i, tan_i = lamp_rays[lamp, i, 3], lamp_rays[lamp, i, 5]
                weight = weights[i] * (1.0 if grazing else c_i)
                for j in range(first, stop):
                    c_r = camera_rays[camera, j, 4]
                    if c_r < 0.0:
                        continue
                    if qualitative:
                        value = _qualitative(t_i, cp_i, sp_i, s_i, tan_i, camera_rays[camera, j, 0],
                                             camera_rays[camera, j, 1], camera_rays[camera, j, 2],
                                             camera_rays[camera, j, 3], camera_rays[camera, j, 5], a, b)
                    else:
                        value = _oren_nayar(t_i, cp_i, sp_i, s_i, c_i, tan_i, camera_rays[camera, j, 0],
                                            camera_rays[camera, j, 1], camera_rays[camera, j, 2],
                                            camera_rays[camera, j, 3], c_r, camera_rays[camera, j, 5], a, b, c)
                    if specular:
                        value += _specular(s_i, cp_i, sp_i, c_i, camera_rays[camera, j, 3], camera_rays[camera, j, 1],
                                           camera_rays[camera, j, 2], c_r, amplitude, exponent)
                    total += weight * weights[j] * value
            out[w, n] = total * lamp_cos[lamp] if grazing else total


@njit(**JIT_OPTIONS)
def _table_fields(rays, count: int, out) -> None:
    """Per sub-ray quantities of the table's coordinates (:func:`gonio.models.tabulated.kernel.table_coordinates`),
    computed once per direction instead of once per pair: ``z = max(pi/2 - theta, 0)``, the
    y coordinate ``log(z + Y_OFFSET) + Y_SLOPE z``, ``sin`` and ``cos`` of ``theta / 2``."""
    for k in range(count):
        for j in range(rays.shape[1]):
            theta = rays[k, j, 0]
            z = max(_HALF_PI - theta, 0.0)
            out[k, j, 0] = z
            out[k, j, 1] = math.log(z + Y_OFFSET) + Y_SLOPE * z
            out[k, j, 2] = math.sin(0.5 * theta)
            out[k, j, 3] = math.cos(0.5 * theta)


@njit(**JIT_OPTIONS)
def _pair_coordinates(t_i, z_i, y_i, sh_i, ch_i, t_r, z_r, y_r, sh_r, ch_r, cos_dphi):
    """(y, zeta, t) of a (lamp, camera) sub-ray pair from their per-ray fields
    (:func:`_table_fields`): :func:`gonio.models.tabulated.kernel.table_coordinates` with
    ``sin^2(dphi / 2) = (1 - cos dphi) / 2`` and the half-angle sines of ``alpha - beta`` and
    ``alpha + beta`` from those of the two polar angles."""
    if t_i >= t_r:
        alpha, beta, z_alpha, z_beta, y_alpha, y = t_i, t_r, z_i, z_r, y_i, y_r
        s_a, c_a, s_b, c_b = sh_i, ch_i, sh_r, ch_r
    else:
        alpha, beta, z_alpha, z_beta, y_alpha, y = t_r, t_i, z_r, z_i, y_r, y_i
        s_a, c_a, s_b, c_b = sh_r, ch_r, sh_i, ch_i
    if z_beta > 0.0:
        zeta = 1.0 - math.sqrt(max(1.0 - 0.5 * (z_alpha / z_beta + (y_alpha - _Y_FLOOR) / (y - _Y_FLOOR)), 0.0))
    else:
        zeta = 1.0
    limit = min(max(0.5 * (1.0 - cos_dphi), 0.0), 1.0)
    return y, zeta, phase_coordinate(alpha, beta, s_a * c_b - c_a * s_b, s_a * c_b + c_a * s_b, limit)


@njit(**JIT_OPTIONS)
def _reduce_along_sigma(table, first: int, s_weights, out) -> None:
    """``out = sum_k s_weights[k] table[first + k]``: the table at one roughness
    (:func:`gonio.models.tabulated.interpolation.contract_first_axis`, flattened)."""
    size = out.shape[0]
    for m in range(size):
        out[m] = (s_weights[0] * table[first, m] + s_weights[1] * table[first + 1, m]
                  + s_weights[2] * table[first + 2, m] + s_weights[3] * table[first + 3, m])


@njit(**JIT_OPTIONS_PARALLEL)
def rig_radiance_table(lamp_directions, camera_directions, lamp_of, camera_of, alignment, table, s_first, s_weights,
                       rho, lambertian, shape, lo, step, lamp_rule, camera_rule, ring, weights, compact, out) -> None:
    """:func:`rig_radiance` for ``oren-nayar-tabulated``: the table read at every sub-ray pair.

    Walkers are independent and run in parallel (numba ``prange``).

    Parameters
    ----------
    table : numpy.ndarray
        (S, ny * nz * nt * 2) the table of (log pi f1, log pi (f2 + F2_FLOOR f1)) per roughness
        node, each node's (y, zeta, t, component) slab flattened.
    s_first, s_weights : numpy.ndarray
        (W,) first roughness node and (W, 4) the cubic weights of each walker's sigma.
    rho : numpy.ndarray
        (W,) albedo.
    lambertian : numpy.ndarray of bool
        (W,) walkers at sigma = 0, where the model is Lambert exactly (footnote 10).
    shape : tuple of int
        (ny, nz, nt, 2) of a slab.
    lo, step : numpy.ndarray
        (3,) first node and spacing of the table's geometry axes.

    The other parameters and ``out`` as :func:`rig_radiance`.
    """
    for w in prange(alignment.shape[0]):
        lamp_rays = np.empty((lamp_directions.shape[0], _POINTS, 6))
        camera_rays = np.empty((camera_directions.shape[0], _POINTS, 6))
        lamp_fields = np.empty((lamp_directions.shape[0], _POINTS, 4))
        camera_fields = np.empty((camera_directions.shape[0], _POINTS, 4))
        lamp_cos = np.empty(lamp_directions.shape[0])
        camera_cos = np.empty(camera_directions.shape[0])
        logs = np.empty((2, 1))
        slab = np.empty(table.shape[1])
        _walker_rays(alignment, lamp_directions, camera_directions, lamp_rule, camera_rule, ring, lamp_rays,
                     camera_rays, lamp_cos, camera_cos, w)
        _table_fields(lamp_rays, lamp_directions.shape[0], lamp_fields)
        _table_fields(camera_rays, camera_directions.shape[0], camera_fields)
        if not lambertian[w]:
            _reduce_along_sigma(table, s_first[w], s_weights[w], slab)
        r = rho[w]
        for n in range(lamp_of.shape[0]):
            lamp, camera = lamp_of[n], camera_of[n]
            if lamp_cos[lamp] < 0.0 or camera_cos[camera] < 0.0:  # an axis below the horizon
                out[w, n] = 0.0
                continue
            grazing = lamp_cos[lamp] <= _GRAZING_COS
            first, stop = _rule_range(lamp_rays, camera_rays, lamp, camera, compact)
            total = 0.0
            for i in range(first, stop):
                c_i = lamp_rays[lamp, i, 4]
                if c_i < 0.0:  # a sub-ray below the horizon reflects nothing
                    continue
                weight = weights[i] * (1.0 if grazing else c_i)
                cp_i, sp_i = lamp_rays[lamp, i, 1], lamp_rays[lamp, i, 2]
                for j in range(first, stop):
                    c_r = camera_rays[camera, j, 4]
                    if c_r < 0.0:
                        continue
                    if lambertian[w]:
                        f = r / math.pi
                    else:
                        cos_dphi = cp_i * camera_rays[camera, j, 1] + sp_i * camera_rays[camera, j, 2]
                        y, zeta, t = _pair_coordinates(
                            lamp_rays[lamp, i, 0], lamp_fields[lamp, i, 0], lamp_fields[lamp, i, 1],
                            lamp_fields[lamp, i, 2], lamp_fields[lamp, i, 3],
                            camera_rays[camera, j, 0], camera_fields[camera, j, 0], camera_fields[camera, j, 1],
                            camera_fields[camera, j, 2], camera_fields[camera, j, 3], cos_dphi)
                        _tricubic_into(slab, shape, lo, step, y, zeta, t, logs, 0)
                        f1 = math.exp(logs[0, 0])
                        f2 = max(math.exp(logs[1, 0]) - F2_FLOOR * f1, 0.0)
                        f = (r * f1 + r * r * f2) / math.pi
                    total += weight * weights[j] * f
            out[w, n] = total * lamp_cos[lamp] if grazing else total


def _rule(solid_angle_sr: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Both cubatures of a cone (:func:`gonio.instrument.cone_offsets`, the full rule's 7
    points then the compact rule's 4) as the kernel takes them: cos and sin of the points'
    angles from the axis, (2, 11); cos and sin of their angles around it, (2, 11); their
    weights, (11,)."""
    beta, around, weights = (np.concatenate(parts) for parts in zip(cone_offsets(solid_angle_sr, "full"),
                                                                    cone_offsets(solid_angle_sr, "compact")))
    return np.stack([np.cos(beta), np.sin(beta)]), np.stack([np.cos(around), np.sin(around)]), weights


class CompiledRigRadiance:
    """The compiled :func:`rig_radiance` at fixed recorded geometries, for any alignments.

    Parameters
    ----------
    base : Model
        ``oren-nayar``, ``lambert`` or ``oren-nayar-tabulated``
        (:data:`gonio.fitting.evaluation.COMPILED_MODELS`: eq 33-35 and its sigma = 0 limit,
        and the exact model's table).
    geometry : tuple of numpy.ndarray
        Recorded (theta_i, phi_i, theta_r, phi_r) [deg], flat, equal length.
    apertures : (float, float)
        Lamp and camera solid angles [sr].

    Examples
    --------
    >>> import gonio
    >>> rig = CompiledRigRadiance(gonio.models.get("lambert"), (np.array([30.0]), np.zeros(1),
    ...                           np.array([10.0]), np.full(1, 180.0)), (0.003, 0.0009))
    >>> value = rig({"rho": 0.9}, {"view_offset": np.array([[0.0], [0.5]])})   # two alignments
    >>> value.shape, bool(np.allclose(value * np.pi / 0.9, np.cos(np.radians(30)), rtol=1e-3))
    ((2, 1), True)
    """

    def __init__(self, base: Model, geometry, apertures: tuple[float, float]) -> None:
        if base.name not in COMPILED_MODELS:
            raise ValueError(f"the compiled rig radiance knows {list(COMPILED_MODELS)}, not {base.name!r}")
        self.base = base
        ti, pi_, tr, pr = (np.asarray(g, float).reshape(-1) for g in geometry)
        self.n = ti.size
        self._lamp, self._lamp_of = _distinct(ti, pi_)
        self._camera, self._camera_of = _distinct(tr, pr)
        (lamp_rule, self._ring, self._weights), (camera_rule, _, _) = _rule(apertures[0]), _rule(apertures[1])
        self._rules = (lamp_rule, camera_rule)
        #: Whether the compact cubature may average the model's cones (gonio.instrument.aperture_rule).
        self._compact = base.name in COMPACT_RULE_MODELS
        if base.name == TABULATED:
            from gonio.models.tabulated.oren_nayar import table

            self._table = table().lookup
            return
        diffuse = models.get("oren-nayar") if base.name == COMBINED else base
        self._coefficients = diffuse.at(30.0, 0.0, 10.0, 180.0).linear_form().coefficients

    def coefficients(self, params: Mapping[str, Any]) -> np.ndarray:
        """The model's (a, b, c) of :func:`_oren_nayar` and the lobe's amplitude and
        exponent of :func:`_specular` (0 for a model without it) per parameter row, shape
        (W, 5). The combined model's diffuse part is eq 33-35 with the interreflection
        term whole (``ir_weight`` 1, as it evaluates it) times ``kd``."""
        if self.base.name == COMBINED:
            terms = [np.asarray(t, float) * np.asarray(params["kd"], float) for t in
                     self._coefficients(rho=params["rho"], sigma=params["sigma"], ir_weight=1.0)]
            terms += _lobe(params["ks"], params["sigma_s"])
        else:
            terms = list(self._coefficients(**params))
        rows = max([np.size(t) for t in terms] + [1])
        columns = [np.broadcast_to(np.reshape(np.asarray(t, float), -1), (rows,)) for t in terms]
        columns += [np.zeros(rows)] * (5 - len(columns))  # lambert: (rho / pi, 0, 0), no lobe
        return np.ascontiguousarray(np.stack(columns, axis=1))

    def __call__(self, params: Mapping[str, Any], alignment: Mapping[str, Any]) -> np.ndarray:
        """``<f cos theta_i>`` [1/sr], shape (W, N) for parameter and alignment columns of
        W rows (shape (W, 1)), (N,) when every value is a scalar."""
        if self.base.name == TABULATED:
            rows = max([np.size(v) for v in (*params.values(), *alignment.values())] + [1])
        else:
            coefficients = self.coefficients(params)
            rows = max([coefficients.shape[0]] + [np.size(v) for v in alignment.values()])
        offsets = np.zeros((rows, len(ALIGNMENT_ERRORS)))
        for k, name in enumerate(ALIGNMENT_ERRORS):
            if name in alignment:
                offsets[:, k] = np.broadcast_to(np.reshape(np.asarray(alignment[name], float), -1), (rows,))
        out = np.empty((rows, self.n))
        if self.base.name == TABULATED:
            self._tabulated(params, rows, offsets, out)
        else:
            coefficients = np.ascontiguousarray(np.broadcast_to(coefficients, (rows, 5)))
            rig_radiance(self._lamp, self._camera, self._lamp_of, self._camera_of, offsets, coefficients,
                         self._rules[0], self._rules[1], self._ring, self._weights, self._compact,
                         self.base.name == QUALITATIVE, self.base.name == COMBINED, out)
        if all(np.ndim(v) == 0 for v in (*params.values(), *alignment.values())):
            return out[0]
        return out

    def _tabulated(self, params: Mapping[str, Any], rows: int, offsets: np.ndarray, out: np.ndarray) -> None:
        """:func:`rig_radiance_table` for parameter rows of ``rho`` and ``sigma`` [deg]."""
        from gonio.models.tabulated.coordinates import sigma_coordinate
        from gonio.models.tabulated.interpolation import axis_stencil

        column = lambda name: np.broadcast_to(np.reshape(np.asarray(params[name], float), -1), (rows,))  # noqa: E731
        rho, sigma = np.ascontiguousarray(column("rho")), column("sigma")
        lookup = self._table
        first, s_weights = axis_stencil(lookup.axes[3], np.asarray(sigma_coordinate(sigma), float))
        flat = lookup.values.reshape(lookup.values.shape[0], -1)
        rig_radiance_table(self._lamp, self._camera, self._lamp_of, self._camera_of, offsets, flat,
                           np.ascontiguousarray(first, dtype=np.int64), np.ascontiguousarray(s_weights), rho,
                           np.ascontiguousarray(sigma == 0.0), tuple(int(n) for n in lookup.values.shape[1:]),
                           lookup.lo, lookup.step, self._rules[0], self._rules[1], self._ring, self._weights,
                           self._compact, out)


def _lobe(ks, sigma_s) -> list[np.ndarray]:
    """The specular lobe's amplitude ``ks c(sigma_s)`` (eq 32's constant, the lobe's own
    normalisation, :mod:`gonio.models.torrance_sparrow`) and exponent ``-1/(2 sigma_s^2)``
    [rad^-2] per row, for ``sigma_s`` [deg]."""
    from gonio.models.torrance_sparrow import slope_area_normalisation

    degrees = np.reshape(np.asarray(sigma_s, float), -1)
    constant = np.array([slope_area_normalisation(float(s)) for s in degrees])
    slope = np.radians(degrees)
    return [np.reshape(np.asarray(ks, float), -1) * constant, -0.5 / (slope * slope)]


def _distinct(theta: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct directions (D, 2) [deg] and the index of each input among them."""
    directions, index = np.unique(np.column_stack([theta, phi]), axis=0, return_inverse=True)
    return np.ascontiguousarray(directions), np.ascontiguousarray(index.reshape(-1).astype(np.int64))
