"""Sines and cosines from half-angle tangents, for the closed forms' hot paths.

numpy evaluates ``tan`` with vectorised (SIMD) code but ``sin`` and ``cos`` of float64
without, so on this class of machine a tangent costs about a quarter of a cosine
(benchmarks/closed_form_speed.py).  With t = tan(x/2):

    cos x = (1 - t^2) / (1 + t^2),    sin x = 2 t / (1 + t^2).

Both agree with ``np.cos``/``np.sin`` to a few units in the last place (absolute); at
x = pi, t^2 ~ 3e32 and the cosine is -1 exactly.
"""
from __future__ import annotations

import numpy as np

__all__ = ["cos_from_half_tangent", "sin_from_half_tangent"]


def cos_from_half_tangent(x):
    """cos(x) [-] for x [rad] (any real), through tan(x/2).

    Examples
    --------
    >>> float(cos_from_half_tangent(np.pi))
    -1.0
    """
    t = np.tan(0.5 * np.asarray(x, float))
    t *= t
    return (1.0 - t) / (1.0 + t)


def sin_from_half_tangent(x):
    """sin(x) [-] for x [rad] in [-pi/2, pi/2] (polar angles), through tan(x/2).

    Examples
    --------
    >>> round(float(sin_from_half_tangent(np.pi / 6)), 15)
    0.5
    """
    t = np.tan(0.5 * np.asarray(x, float))
    return 2.0 * t / (1.0 + t * t)
