"""Compiled plain calls of the closed forms: two fused loops around numpy's tangent.

numpy evaluates a closed form one operation at a time, each a pass over the arrays (about
60 passes for Oren-Nayar eq 33-35, whose cost is those passes, not the arithmetic).  A
loop compiled by numba does all the arithmetic of one geometry at once, but calls the
scalar ``tan``/``sin``/``cos`` of the C library, which cost more than the whole numpy
pass of numpy's vectorised (SIMD) ``tan`` (benchmarks/closed_form_speed.py).  The plain
call of a closed form with a compiled path therefore runs, on
:data:`gonio.models._core.CHUNK` geometries at a time (the arrays of a chunk stay in the
processor's cache):

1. a compiled loop writing the arguments of every tangent the formula needs (half angles
   for the sines and cosines, :mod:`gonio.models._trig`) into one buffer, 0 where the
   geometry is below the horizon or NaN;
2. ``numpy.tan`` over the whole buffer in one call;
3. a compiled loop combining the tangents with the parameters' coefficients into the
   BRDF, with the horizon (0) and NaN rules of :class:`gonio.models.Model`.

Each model's loops live beside its numpy formula and repeat its operations in the same
order; the tests compare the two paths (tests/models/test_compiled_closed_forms.py).
Numba loads on the first call large enough to use this path
(:data:`gonio.models._core.COMPILED_MIN` geometries), never at ``import gonio``; the
compiled loops are cached on disk (``cache=True``), so only the first such call on a
machine compiles them.
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np
from numba import njit

from . import _core

__all__ = ["JIT_OPTIONS", "evaluate_in_chunks", "half_angles"]

#: numba options of every compiled loop: cached on disk, no GIL held, numpy's error model
#: (a division by zero gives inf or NaN as numpy does, no exception).
JIT_OPTIONS = dict(cache=True, nogil=True, error_model="numpy")

_DEGREE = math.pi / 180.0
_RIGHT_ANGLE = 90.0


@njit(**JIT_OPTIONS, inline="always")
def domain(ti: float, pi_: float, tr: float, pr: float) -> tuple[bool, float]:
    """(whether the formula applies, the BRDF where it does not): NaN where an angle is
    NaN, 0 below the horizon (the rules of gonio.models._core._domain)."""
    if math.isnan(ti) or math.isnan(pi_) or math.isnan(tr) or math.isnan(pr):
        return False, math.nan
    if ti > _RIGHT_ANGLE or tr > _RIGHT_ANGLE:
        return False, 0.0
    return True, 0.0


@njit(**JIT_OPTIONS)
def half_angles(theta_i, phi_i, theta_r, phi_r, buffer):
    """Tangent arguments [rad] of the cosines of theta_i and theta_r (rows 0 and 1:
    theta/2) and, for a buffer of three rows, of the azimuth difference (row 2:
    (phi_r - phi_i)/2); 0 where :func:`domain` does not apply."""
    rows = buffer.shape[0]
    for k in range(theta_i.size):
        if not domain(theta_i[k], phi_i[k], theta_r[k], phi_r[k])[0]:
            for row in range(rows):
                buffer[row, k] = 0.0
            continue
        buffer[0, k] = 0.5 * (theta_i[k] * _DEGREE)
        buffer[1, k] = 0.5 * (theta_r[k] * _DEGREE)
        if rows > 2:
            buffer[2, k] = 0.5 * (phi_r[k] * _DEGREE - phi_i[k] * _DEGREE)


def evaluate_in_chunks(arguments: Callable, combine: Callable, tangents: int,
                       angles: Sequence[np.ndarray], coefficients: Sequence[float]) -> np.ndarray:
    """A closed form on flat geometries through its two compiled loops.

    Parameters
    ----------
    arguments : callable
        Compiled ``arguments(theta_i, phi_i, theta_r, phi_r, buffer)``: writes the
        ``tangents`` tangent arguments [rad] of every geometry into ``buffer`` (shape
        ``(tangents, n)``).
    combine : callable
        Compiled ``combine(theta_i, phi_i, theta_r, phi_r, tan_values, *coefficients, out)``:
        the BRDF [1/sr] of every geometry from its tangents.
    tangents : int
        Number of tangents per geometry.
    angles : sequence of numpy.ndarray
        theta_i, phi_i, theta_r, phi_r [deg]: 1-D, contiguous, float64, of equal length.
    coefficients : sequence of float
        The parameters' scalar coefficients, passed to ``combine``.

    Returns
    -------
    numpy.ndarray
        The BRDF [1/sr], 1-D.
    """
    size, chunk = angles[0].size, _core.CHUNK
    out = np.empty(size)
    storage = np.empty(tangents * min(size, chunk))
    for start in range(0, size, chunk):
        stop = min(start + chunk, size)
        part = [a[start:stop] for a in angles]
        buffer = storage[: tangents * (stop - start)].reshape(tangents, stop - start)
        arguments(*part, buffer)
        np.tan(buffer, out=buffer)
        combine(*part, buffer, *coefficients, out[start:stop])
    return out
