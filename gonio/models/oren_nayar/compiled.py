"""Compiled plain calls of ``oren-nayar`` (eq 33-35) and ``oren-nayar-qualitative`` (eq 36).

The loops of :mod:`gonio.models._compiled` for the two closed forms of
:mod:`.functional`: the same formulas, operation for operation and in the same order, as
:func:`.functional._oren_nayar_shapes` with ``evaluate`` of
:func:`.functional._prepare_oren_nayar`, and as :func:`.functional._prepare_qualitative`;
the parameters enter through the same coefficient functions
(:func:`.functional._oren_nayar_coefficients`, :func:`.functional._qualitative_coefficients`), so
nothing of the physics is written twice except the per-geometry arithmetic, which the
tests compare with the numpy path on random geometries, the horizon, the normal, NaN,
theta_i = theta_r and the azimuths where cos(dphi) changes sign
(tests/models/test_compiled_closed_forms.py).

Tangents per geometry (rows of the buffer):

* eq 33-35: tan(dphi/2) (for cos dphi), tan(alpha/2) (for sin alpha), tan(beta),
  tan((alpha + beta)/2);
* eq 36: tan(dphi/2), tan(alpha/2), tan(beta).

Angles arrive in degrees and are converted as :func:`gonio.models._core._radians` does
(a multiplication by pi/180).

References
----------
M. Oren, S. K. Nayar, IJCV 14(3), 1995, eq 33-36.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._compiled import JIT_OPTIONS, evaluate_in_chunks
from .._compiled import domain as _domain
from .functional import C2_AMPLITUDE, C3_AMPLITUDE, _oren_nayar_coefficients, _qualitative_coefficients

__all__ = ["eq33_35", "oren_nayar_plain", "qualitative_plain"]

_DEGREE = math.pi / 180.0
_TWO_OVER_PI = 2.0 / math.pi
_FOUR_OVER_PI_SQ = 4.0 / math.pi**2


@njit(**JIT_OPTIONS)
def _arguments(theta_i, phi_i, theta_r, phi_r, buffer):
    """Tangent arguments [rad] of eq 33-35 (rows: dphi/2, alpha/2, beta, (alpha+beta)/2)."""
    rows = buffer.shape[0]
    for k in range(theta_i.size):
        if not _domain(theta_i[k], phi_i[k], theta_r[k], phi_r[k])[0]:
            for row in range(rows):
                buffer[row, k] = 0.0
            continue
        ti, tr = theta_i[k] * _DEGREE, theta_r[k] * _DEGREE
        alpha, beta = max(ti, tr), min(ti, tr)
        buffer[0, k] = 0.5 * (phi_r[k] * _DEGREE - phi_i[k] * _DEGREE)
        buffer[1, k] = 0.5 * alpha
        buffer[2, k] = beta
        if rows > 3:
            buffer[3, k] = (alpha + beta) * 0.5


@njit(**JIT_OPTIONS, inline="always")
def eq33_35(cos_dphi: float, sin_alpha: float, tan_beta: float, alpha: float, beta: float,
            tan_half_sum: float, a: float, b: float, c: float) -> float:
    """Eq 33-35 at one geometry from its trigonometric values: ``max(a + b direct_shape +
    c ir_shape, 0)`` [1/sr], with ``alpha``, ``beta`` [rad], ``tan_half_sum`` =
    ``tan((alpha + beta) / 2)`` and (a, b, c) of ``_oren_nayar_coefficients`` (the shapes of
    :func:`~gonio.models.oren_nayar.functional._oren_nayar_shapes`). The one scalar form of
    the arithmetic: :func:`_combine` and the compiled rig radiance
    (:mod:`gonio.fitting.compiled_rig`) call it with values computed their own ways."""
    two_beta = beta * _TWO_OVER_PI
    ir_shape = two_beta * two_beta
    angular_c2 = sin_alpha - (ir_shape * two_beta if cos_dphi < 0.0 else 0.0)
    ir_shape *= cos_dphi
    direct_shape = tan_beta * cos_dphi * angular_c2 * C2_AMPLITUDE
    c3 = alpha * beta * _FOUR_OVER_PI_SQ
    c3 *= c3
    c3 *= 1.0 - abs(cos_dphi)
    c3 *= tan_half_sum
    c3 *= C3_AMPLITUDE
    direct_shape += c3
    value = direct_shape * b + c * ir_shape
    value += a
    return max(value, 0.0)


@njit(**JIT_OPTIONS)
def _combine(theta_i, phi_i, theta_r, phi_r, tangent, a, b, c, out):
    """Eq 33-35 from the tangents: max(a + b direct_shape + c ir_shape, 0) [1/sr]."""
    for k in range(theta_i.size):
        valid, outside = _domain(theta_i[k], phi_i[k], theta_r[k], phi_r[k])
        if not valid:
            out[k] = outside
            continue
        ti, tr = theta_i[k] * _DEGREE, theta_r[k] * _DEGREE
        alpha, beta = max(ti, tr), min(ti, tr)
        t = tangent[0, k] * tangent[0, k]
        cos_dphi = (1.0 - t) / (1.0 + t)
        t = tangent[1, k]
        sin_alpha = 2.0 * t / (1.0 + t * t)
        out[k] = eq33_35(cos_dphi, sin_alpha, tangent[2, k], alpha, beta, tangent[3, k], a, b, c)


@njit(**JIT_OPTIONS)
def _combine_qualitative(theta_i, phi_i, theta_r, phi_r, tangent, a, b, out):
    """Eq 36 from the tangents: a + b max(0, cos dphi) sin(alpha) tan(beta) [1/sr]."""
    for k in range(theta_i.size):
        valid, outside = _domain(theta_i[k], phi_i[k], theta_r[k], phi_r[k])
        if not valid:
            out[k] = outside
            continue
        t = tangent[0, k] * tangent[0, k]
        cos_dphi = max((1.0 - t) / (1.0 + t), 0.0)
        t = tangent[1, k]
        shape = cos_dphi * (2.0 * t / (1.0 + t * t))
        shape *= tangent[2, k]
        out[k] = shape * b + a


def oren_nayar_plain(theta_i, phi_i, theta_r, phi_r, params, options) -> np.ndarray:
    """``oren-nayar`` at flat geometries [deg] for scalar parameters, compiled [1/sr]."""
    a, b, c = _oren_nayar_coefficients(params["rho"], params["sigma"], params["ir_weight"])
    return evaluate_in_chunks(_arguments, _combine, 4, (theta_i, phi_i, theta_r, phi_r),
                              (float(a), float(b), float(c)))


def qualitative_plain(theta_i, phi_i, theta_r, phi_r, params, options) -> np.ndarray:
    """``oren-nayar-qualitative`` at flat geometries [deg] for scalar parameters, compiled [1/sr]."""
    a, b = _qualitative_coefficients(params["rho"], params["sigma"], options["variant"])
    return evaluate_in_chunks(_arguments, _combine_qualitative, 3, (theta_i, phi_i, theta_r, phi_r),
                              (float(a), float(b)))
