"""Tensor-product cubic interpolation on regular grids, vectorised with numpy.

Each axis uses the four-node Lagrange cubic around the point (one-sided stencils in the
first and last cell), so a d-dimensional evaluation combines 4^d table values.  The
interpolation error is O(h^4) in every cell, boundary cells included; the interpolant is
continuous, with derivative jumps of O(h^3) at grid lines.

Two evaluation patterns are provided, both built on :func:`axis_stencil`:

* :func:`contract_last_axis` reduces a table along its last axis at one coordinate
  (the roughness of one call), leaving a smaller table;
* :func:`gather_3d` evaluates a 3-D table at many scattered points (64 values each).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Axis", "axis_stencil", "lagrange_weights", "contract_last_axis", "gather_3d"]


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
    t0, t1, t2, t3 = tau, tau - 1.0, tau - 2.0, tau - 3.0
    return np.stack(
        [-t1 * t2 * t3 / 6.0, t0 * t2 * t3 / 2.0, -t0 * t1 * t3 / 2.0, t0 * t1 * t2 / 6.0], axis=-1
    )


def axis_stencil(axis: Axis, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First node index (``intp``) and the four weights of the stencil containing ``x``.

    Coordinates outside [lo, hi] are clamped to the interval (callers map the physical
    domain onto the table's range, so this only absorbs rounding).
    """
    u = (np.clip(x, axis.lo, axis.hi) - axis.lo) / axis.step
    first = np.clip(np.floor(u).astype(np.intp) - 1, 0, axis.size - 4)
    return first, lagrange_weights(u - first)


def contract_last_axis(table: np.ndarray, axis: Axis, x: float) -> np.ndarray:
    """Interpolate ``table`` (last axis along ``axis``) at the scalar coordinate ``x``."""
    first, weights = axis_stencil(axis, np.asarray(float(x)))
    return table[..., int(first) : int(first) + 4] @ weights


def gather_3d(
    table: np.ndarray,
    stencils: tuple[tuple[np.ndarray, np.ndarray], ...],
    chunk: int = 16384,
) -> np.ndarray:
    """Evaluate a 3-D table at points given by their per-axis stencils.

    Parameters
    ----------
    table : numpy.ndarray
        Values on the grid, shape (n0, n1, n2) (made C-contiguous here).
    stencils : three (first, weights) pairs
        From :func:`axis_stencil` for the three axes; ``first`` of shape (m,), ``weights``
        of shape (m, 4).
    chunk : int
        Points processed together (bounds the (chunk, 64) work array).

    Returns
    -------
    numpy.ndarray
        Interpolated values, shape (m,).
    """
    flat = np.ascontiguousarray(table).ravel()
    n1, n2 = table.shape[1], table.shape[2]
    offsets = (np.arange(4)[:, None, None] * n1 + np.arange(4)[None, :, None]) * n2 + np.arange(4)[None, None, :]
    offsets = offsets.ravel()
    (f0, w0), (f1, w1), (f2, w2) = stencils
    base = (f0 * n1 + f1) * n2 + f2
    out = np.empty(base.shape[0])
    for start in range(0, base.shape[0], chunk):
        part = slice(start, start + chunk)
        values = flat[base[part, None] + offsets].reshape(-1, 4, 4, 4)
        inner = np.matmul(values, w2[part, None, :, None])[..., 0]          # (m, 4, 4)
        middle = np.matmul(inner, w1[part, :, None])[..., 0]                # (m, 4)
        out[part] = np.einsum("mi,mi->m", middle, w0[part])
    return out
