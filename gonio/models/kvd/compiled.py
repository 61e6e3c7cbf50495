"""Compiled plain call of a KvD isotropic series (Koenderink & van Doorn 1998, eq 26-28).

The loops of :mod:`gonio.models._compiled` for :func:`.series._prepare_for`: per geometry
the cosines of theta_i, theta_r and of the azimuth difference from half-angle tangents
(:mod:`gonio.models._trig`, one ``numpy.tan`` over the chunk), the radial Zernike
polynomials R_n^l of both directions by the Jacobi recurrence of
:func:`gonio.zernike.zernike_radial_table` (the same operations in the same order), the
cosines of the multiples of the azimuth difference by the Chebyshev recurrence of
:func:`.basis._cosines_of_multiples`, and the sum over modes of
``a_nml A_nml [R_n^l(i) R_m^l(r) + R_m^l(i) R_n^l(r)] cos(l dphi)`` (eq 26-28, with the
scale of :func:`.basis._mode_scale`).  The numpy path builds the design matrix of the
same terms and multiplies it by the amplitudes; the two differ only by the cosines
(``numpy.cos`` there, tangents here: a few ulp) and the order of the final sum, which the
tests bound (tests/models/test_compiled_closed_forms.py).

References
----------
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998, eq 26-31.
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np
from numba import njit

from .._compiled import JIT_OPTIONS, evaluate_in_chunks, half_angles
from .._compiled import domain as _domain
from .basis import Mode, _mode_scale

__all__ = ["series_plain"]

@njit(**JIT_OPTIONS, inline="always")
def _cosine(t: float) -> float:
    """cos x from t = tan(x/2) (:func:`gonio.models._trig.cos_from_half_tangent`)."""
    t *= t
    return (1.0 - t) / (1.0 + t)


@njit(**JIT_OPTIONS, inline="always")
def _radial(c: float, order: int, table) -> None:
    """R_n^l(cos theta) into ``table[n, l]`` for n - l even, n <= order: the recurrence
    of :func:`gonio.zernike.zernike_radial_table`, operation for operation."""
    x = 2.0 * c - 1.0
    rho = math.sqrt(max(1.0 - c, 0.0))
    rho_power = 1.0
    for l in range(order + 1):
        if l:
            rho_power = rho_power * rho
        previous, current = 0.0, 1.0
        for k in range((order - l) // 2 + 1):
            if k == 1:
                previous, current = current, 0.5 * ((l + 2) * x + l)
            elif k > 1:
                j = k - 1
                s = 2 * j + l
                following = ((s + 1) * (s * (s + 2) * x + l * l) * current - 2 * j * (j + l) * (s + 2) * previous) / (
                    2 * (j + 1) * (j + l + 1) * s
                )
                previous, current = current, following
            table[l + 2 * k, l] = (-1.0 if k % 2 else 1.0) * rho_power * current


@njit(**JIT_OPTIONS)
def _combine(theta_i, phi_i, theta_r, phi_r, tangent, modes, weights, order, out):
    """sum_j weights[j] [R_n^l(i) R_m^l(r) + R_m^l(i) R_n^l(r)] cos(l dphi) [1/sr]."""
    table_i = np.zeros((order + 1, order + 1))
    table_r = np.zeros((order + 1, order + 1))
    multiples = np.empty(order + 1)
    for k in range(theta_i.size):
        valid, outside = _domain(theta_i[k], phi_i[k], theta_r[k], phi_r[k])
        if not valid:
            out[k] = outside
            continue
        _radial(_cosine(tangent[0, k]), order, table_i)
        _radial(_cosine(tangent[1, k]), order, table_r)
        multiples[0] = 1.0
        if order >= 1:
            multiples[1] = _cosine(tangent[2, k])
        for l in range(2, order + 1):
            multiples[l] = 2.0 * multiples[1] * multiples[l - 1] - multiples[l - 2]
        total = 0.0
        for j in range(modes.shape[0]):
            n, m, l = modes[j, 0], modes[j, 1], modes[j, 2]
            bracket = table_i[n, l] * table_r[m, l] + table_i[m, l] * table_r[n, l]
            total += weights[j] * (bracket * multiples[l])
        out[k] = total


def series_plain(modes: Sequence[Mode], names: Sequence[str]) -> Callable[..., np.ndarray]:
    """The compiled plain call of the series of ``modes`` (amplitude parameters ``names``):
    ``evaluate(theta_i, phi_i, theta_r, phi_r, params, options)`` at flat geometries [deg]
    for scalar amplitudes [1/sr]."""
    table = np.array(modes, dtype=np.int64).reshape(-1, 3)
    scales = np.array([_mode_scale(*mode) for mode in modes])
    order = int(table.max(initial=0))

    def evaluate(theta_i, phi_i, theta_r, phi_r, params, options) -> np.ndarray:
        weights = scales * np.array([float(params[name]) for name in names])
        return evaluate_in_chunks(half_angles, _combine, 3, (theta_i, phi_i, theta_r, phi_r), (table, weights, order))

    return evaluate
