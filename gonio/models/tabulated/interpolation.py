"""Tensor-product cubic interpolation on regular grids, vectorised with numpy.

Each axis uses the four-node Lagrange cubic around the point (one-sided stencils in the
first and last cell), so a d-dimensional evaluation combines 4^d table values.  The
interpolation error is O(h^4) in every cell, boundary cells included; the interpolant is
continuous, with derivative jumps of O(h^3) at grid lines.

Two evaluation patterns are provided, both built on :func:`axis_stencil`:

* :func:`contract_last_axis` reduces a table along its last axis at one coordinate
  (the roughness of one call), leaving a smaller table;
* :func:`gather_3d` (:class:`CellRows`) evaluates a 3-D table (one or several
  components) at many scattered points (64 values each, read as 16 rows of four nodes).

Speed (numpy only, one core; docs/tabulated.md): the gather and contraction cost about
0.2 us per point for two components, bound by copying the 64 x 2 values (1 kB) per point
and by numpy's per-point overhead in the batched 1 x 16 by 16 x 8 matrix product.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import as_strided

__all__ = ["Axis", "axis_stencil", "lagrange_weights", "contract_last_axis", "CellRows", "gather_3d"]


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

    The weights have shape ``x.shape + (4,)`` (a view of rows stored point-contiguous,
    which is the layout :func:`gather_3d` reads fastest).  Coordinates outside [lo, hi]
    are clamped to the interval (callers map the physical domain onto the table's range,
    so this only absorbs rounding).
    """
    u = (np.clip(x, axis.lo, axis.hi) - axis.lo) / axis.step
    # u >= 0, so truncation is the floor; intp arithmetic, then one clip to the stencils
    first = np.clip(u.astype(np.intp) - 1, 0, axis.size - 4)
    return first, np.moveaxis(_lagrange_rows(u - first), 0, -1)


def contract_last_axis(table: np.ndarray, axis: Axis, x: float) -> np.ndarray:
    """Interpolate ``table`` (last axis along ``axis``) at the scalar coordinate ``x``."""
    first, weights = axis_stencil(axis, np.asarray(float(x)))
    return table[..., int(first) : int(first) + 4] @ weights


class CellRows:
    """A 3-D table arranged so that the 64 values of a cubic stencil come in 16 reads.

    Element ``i`` of :attr:`rows` holds the four consecutive nodes along the last axis
    starting at flat node ``i``, every component (4 C contiguous floats, one opaque
    item), so one ``numpy.take`` of 16 indices per point gathers the whole 4 x 4 x 4
    block without per-value fancy indexing.

    Parameters
    ----------
    table : numpy.ndarray
        Values on the grid, shape (n0, n1, n2) or (n0, n1, n2, C).
    """

    def __init__(self, table: np.ndarray):
        self.single = np.ndim(table) == 3
        values = np.ascontiguousarray(table[..., None] if self.single else table, dtype=float)
        self.shape = values.shape
        n0, n1, n2, components = values.shape
        flat = values.ravel()
        item = flat.itemsize
        rows = np.ascontiguousarray(
            as_strided(flat, shape=(n0 * n1 * n2 - 3, 4 * components), strides=(components * item, item),
                       writeable=False)
        )
        self.rows = rows.view(np.dtype((np.void, 4 * components * item))).ravel()
        self.offsets = ((np.arange(4)[:, None] * n1 + np.arange(4)[None, :]) * n2).ravel()

    def __call__(self, stencils: tuple[tuple[np.ndarray, np.ndarray], ...], chunk: int = 2048,
                 out: np.ndarray | None = None) -> np.ndarray:
        """Interpolated values at the points of ``stencils``: shape (m,) or (m, C).

        ``stencils`` are three (first, weights) pairs from :func:`axis_stencil`; ``out``
        (shape (m, C)) receives the result if given.
        """
        _, n1, n2, components = self.shape
        (f0, w0), (f1, w1), (f2, w2) = stencils
        base = (f0 * n1 + f1) * n2 + f2
        m = base.shape[0]
        if out is None:
            out = np.empty((m, components))
        for start in range(0, m, chunk):
            part = slice(start, start + chunk)
            k = base[part].shape[0]
            cell = np.take(self.rows, base[part, None] + self.offsets).view(float).reshape(k, 16, 4 * components)
            # weights of the 16 (axis 0, axis 1) rows, built point-last (long inner loops)
            row_weights = np.ascontiguousarray((w0[part].T[:, None, :] * w1[part].T[None, :, :]).reshape(16, k).T)
            along_t = np.matmul(row_weights[:, None, :], cell).reshape(k, 4, components)
            wt = w2[part]
            for c in range(components):
                column = along_t[:, :, c]
                out[part, c] = (column[:, 0] * wt[:, 0] + column[:, 1] * wt[:, 1]
                                + column[:, 2] * wt[:, 2] + column[:, 3] * wt[:, 3])
        return out[:, 0] if self.single else out


def gather_3d(
    table: np.ndarray,
    stencils: tuple[tuple[np.ndarray, np.ndarray], ...],
    chunk: int = 2048,
) -> np.ndarray:
    """Evaluate a 3-D table (optionally with a trailing component axis) at many points.

    Parameters
    ----------
    table : numpy.ndarray
        Values on the grid, shape (n0, n1, n2) or (n0, n1, n2, C) for C components
        interpolated together.
    stencils : three (first, weights) pairs
        From :func:`axis_stencil` for the three axes; ``first`` of shape (m,), ``weights``
        of shape (m, 4).
    chunk : int
        Points processed together (bounds the (chunk, 16, 4 C) work array; ~2000 keeps it
        in cache).

    Returns
    -------
    numpy.ndarray
        Interpolated values, shape (m,) or (m, C).

    Notes
    -----
    See :class:`CellRows`: the 4 x 4 x 4 block of each point is read as 16 rows of four
    nodes; the rows are combined with the (axis 0, axis 1) weights by one small matrix
    product per point, then the four nodes along axis 2 with their weights.
    """
    return CellRows(table)(stencils, chunk=chunk)
