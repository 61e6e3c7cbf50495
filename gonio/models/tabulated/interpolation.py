"""Tensor-product cubic interpolation on regular grids: the rule and its numpy form.

Each axis uses the four-node Lagrange cubic around the point (one-sided stencils in the
first and last cell), so a d-dimensional evaluation combines 4^d table values.  The
interpolation error is O(h^4) in every cell, boundary cells included; the interpolant is
continuous, with derivative jumps of O(h^3) at grid lines.

:func:`axis_stencil` gives the stencil of many coordinates on one axis and
:func:`contract_first_axis` reduces a table along its first axis at one coordinate (the
roughness of one call), leaving a smaller table.  The 3-D evaluation at scattered
geometries is compiled (:func:`.kernel.interpolate_geometries`, the same rule per point;
:func:`.kernel.cubic_stencil` is :func:`axis_stencil` for one coordinate).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Axis", "axis_stencil", "lagrange_weights", "contract_first_axis"]


@dataclass(frozen=True)
class Axis:
    """A regular grid of ``size`` nodes on [lo, hi]."""

    name: str
    lo: float
    hi: float
    size: int

    def __post_init__(self) -> None:
        if self.size < 4 or not self.hi > self.lo:
            raise ValueError(f"axis {self.name!r}: need size >= 4 and hi > lo, got {self}")

    @property
    def step(self) -> float:
        return (self.hi - self.lo) / (self.size - 1)

    def nodes(self) -> np.ndarray:
        """Node coordinates, ``size`` values from lo to hi."""
        return np.linspace(self.lo, self.hi, self.size)


def lagrange_weights(tau: np.ndarray) -> np.ndarray:
    """Weights of the cubic Lagrange polynomial through nodes 0, 1, 2, 3 at ``tau``.

    Returns an array of shape ``tau.shape + (4,)`` whose last axis sums to 1.
    """
    return np.moveaxis(_lagrange_rows(np.asarray(tau, float)), 0, -1)


def _lagrange_rows(tau: np.ndarray) -> np.ndarray:
    """The four Lagrange weights at ``tau`` as rows: shape ``(4,) + tau.shape``."""
    t1, t2, t3 = tau - 1.0, tau - 2.0, tau - 3.0
    t01, t23 = tau * t1, t2 * t3
    rows = np.empty((4,) + np.shape(tau))
    np.multiply(t1, t23, out=rows[0, ...])
    np.multiply(tau, t23, out=rows[1, ...])
    np.multiply(t01, t3, out=rows[2, ...])
    np.multiply(t01, t2, out=rows[3, ...])
    rows *= np.array([-1.0 / 6.0, 0.5, -0.5, 1.0 / 6.0]).reshape((4,) + (1,) * np.ndim(tau))
    return rows


def axis_stencil(axis: Axis, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First node index (``intp``) and the four weights of the stencil containing ``x``.

    The weights have shape ``x.shape + (4,)``.  Coordinates outside [lo, hi]
    are clamped to the interval (callers map the physical domain onto the table's range,
    so this only absorbs rounding).
    """
    u = (np.clip(x, axis.lo, axis.hi) - axis.lo) / axis.step
    # u >= 0, so truncation is the floor; intp arithmetic, then one clip to the stencils
    first = np.clip(u.astype(np.intp) - 1, 0, axis.size - 4)
    return first, np.moveaxis(_lagrange_rows(u - first), 0, -1)


def contract_first_axis(table: np.ndarray, axis: Axis, x: float) -> np.ndarray:
    """Interpolate ``table`` (first axis along ``axis``) at the scalar coordinate ``x``.

    Reads the four slices of the stencil only (contiguous when ``table`` is C-ordered) and
    returns a new C-contiguous array of shape ``table.shape[1:]``.
    """
    first, weights = axis_stencil(axis, np.asarray(float(x)))
    first = int(first)
    result = weights[0] * table[first]
    for offset in range(1, 4):
        result += weights[offset] * table[first + offset]
    return result
