"""Compiled plain call of ``wolff`` (Wolff, Nayar & Oren 1998, eq 7 with eq 2 or the
polynomial after eq 7).

The loops of :mod:`gonio.models._compiled` for :func:`gonio.models.wolff._prepare`: the
cosines of theta_i and theta_r from half-angle tangents (:mod:`gonio.models._trig`), then
the two Fresnel transmittances of :mod:`gonio.models.fresnel` per geometry, in the same
operations and order as :func:`~gonio.models.fresnel.fresnel_transmittance` and
:func:`~gonio.models.fresnel.exit_transmittance` (or
:func:`~gonio.models.fresnel.fresnel_polynomial`), times the scale.  The scale (rho/pi
or the physical scale of eq 8) and the index-dependent constants come from the same
functions as the numpy path; the tests compare the two paths
(tests/models/test_compiled_closed_forms.py).

References
----------
L. B. Wolff, S. K. Nayar, M. Oren, IJCV 30(1), 1998, eq 2, eq 7 and the polynomial after eq 7.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._compiled import JIT_OPTIONS, evaluate_in_chunks, half_angles
from ._compiled import domain as _domain
from .fresnel import polynomial_epsilon

__all__ = ["wolff_plain"]

_DEGREE = math.pi / 180.0
_TWO_OVER_PI = 2.0 / math.pi


@njit(**JIT_OPTIONS, inline="always")
def _cosine(t: float) -> float:
    """cos x from t = tan(x/2), clipped to [0, 1] as the Fresnel functions clip it."""
    t *= t
    return min(max((1.0 - t) / (1.0 + t), 0.0), 1.0)


@njit(**JIT_OPTIONS, inline="always")
def _reflectance_from_cosines(cos_i: float, cos_t: float, m: float) -> float:
    """(r_s^2 + r_p^2)/2 (fresnel._reflectance_from_cosines), 0 where a denominator is 0."""
    s_den = cos_i + m * cos_t
    p_den = m * cos_i + cos_t
    if s_den == 0.0 or p_den == 0.0:
        return 0.0
    r_s = (cos_i - m * cos_t) / s_den
    r_p = (m * cos_i - cos_t) / p_den
    return 0.5 * (r_s * r_s + r_p * r_p)


@njit(**JIT_OPTIONS)
def _combine_exact(theta_i, phi_i, theta_r, phi_r, tangent, scale, index, index_sq, inverse, out):
    """scale (1 - F(theta_i, n)) (1 - F(theta_t', 1/n)) with the exact eq 2 [1/sr]."""
    for k in range(theta_i.size):
        valid, outside = _domain(theta_i[k], phi_i[k], theta_r[k], phi_r[k])
        if not valid:
            out[k] = outside
            continue
        cos_i = _cosine(tangent[0, k])
        sin_t_sq = (1.0 - cos_i * cos_i) / index_sq
        if sin_t_sq >= 1.0:
            entry = 1.0 - 1.0
        else:
            entry = 1.0 - _reflectance_from_cosines(cos_i, math.sqrt(max(1.0 - sin_t_sq, 0.0)), index)
        cos_r = _cosine(tangent[1, k])
        cos_internal = math.sqrt(1.0 - (1.0 - cos_r * cos_r) / index_sq)
        leave = 1.0 - _reflectance_from_cosines(cos_internal, cos_r, inverse)
        out[k] = scale * (entry * leave)


@njit(**JIT_OPTIONS)
def _combine_polynomial(theta_i, phi_i, theta_r, phi_r, tangent, scale, epsilon, out):
    """scale (1 - F_poly(theta_i)) (1 - F_poly(theta_r)), F_poly = ((2x/pi)^5 + eps)/(1 + eps)."""
    for k in range(theta_i.size):
        valid, outside = _domain(theta_i[k], phi_i[k], theta_r[k], phi_r[k])
        if not valid:
            out[k] = outside
            continue
        entry = 1.0 - ((_TWO_OVER_PI * (theta_i[k] * _DEGREE)) ** 5.0 + epsilon) / (1.0 + epsilon)
        leave = 1.0 - ((_TWO_OVER_PI * (theta_r[k] * _DEGREE)) ** 5.0 + epsilon) / (1.0 + epsilon)
        out[k] = scale * (entry * leave)


def wolff_plain(theta_i, phi_i, theta_r, phi_r, scale: float, n: float, fresnel: str) -> np.ndarray:
    """``wolff`` at flat geometries [deg], compiled [1/sr]: eq 7 times ``scale`` (the
    factor in front of it, :func:`gonio.models.wolff.scale_factor`, which the caller
    computes) for the refractive index ``n`` and the Fresnel form ``fresnel``."""
    index = np.asarray(n, float)
    angles = (theta_i, phi_i, theta_r, phi_r)
    if fresnel == "polynomial":
        return evaluate_in_chunks(half_angles, _combine_polynomial, 2, angles,
                                  (float(scale), float(polynomial_epsilon(index))))
    return evaluate_in_chunks(half_angles, _combine_exact, 2, angles,
                              (float(scale), float(index), float(index**2), float(1.0 / index)))
