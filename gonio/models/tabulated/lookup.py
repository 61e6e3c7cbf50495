"""Tables of logarithms on the grid (y, zeta, t, s) and their fast evaluation.

A :class:`LogTable` holds one or more 4-D arrays of tabulated logarithms (one per model
component) on a :class:`TableGrid`.  :meth:`LogTable.prepare` maps fixed geometries to
their table coordinates and cubic stencils once and returns a function of the parameter
coordinate ``s`` giving the interpolated logarithms:

* on its first call it reduces each table along s (4 slices) and interpolates the
  remaining 3-D table at every geometry (64 values each), streaming the geometries
  through coordinates, stencils and gather a few thousand at a time so that every
  temporary stays in cache (the plain call of a model is this path);
* from the second call on (the same geometries evaluated again: fitting, ``Model.at``) it
  keeps the 3-D interpolation of each s node it has needed, so a call only combines four
  stored columns: a few operations per geometry.

Both orders apply the same linear weights to the same values and agree to rounding; the
result of the first call is kept, so evaluating the same s again returns the same bits.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from .coordinates import geometry_coordinates, y_coordinate
from .interpolation import Axis, CellRows, axis_stencil, contract_last_axis, gather_3d

__all__ = ["TableGrid", "LogTable"]

#: Geometries taken together by a one-off evaluation, from coordinates to values: small
#: enough that every temporary stays in cache (measured: 4096 is ~1.5 times faster than
#: whole-array steps on 1e6 geometries).
_STREAM_CHUNK = 4096


@dataclass(frozen=True)
class TableGrid:
    """Node counts of the four table axes (y, zeta, t, s); see :mod:`.coordinates`."""

    y: int
    zeta: int
    t: int
    s: int

    def axes(self) -> tuple[Axis, Axis, Axis, Axis]:
        """The four regular axes."""
        return (
            Axis("y", float(y_coordinate(0.0)), float(y_coordinate(0.5 * math.pi)), self.y),
            Axis("zeta", 0.0, 1.0, self.zeta),
            Axis("t", 0.0, 1.0, self.t),
            Axis("s", 0.0, 1.0, self.s),
        )

    @property
    def shape(self) -> tuple[int, int, int, int]:
        return (self.y, self.zeta, self.t, self.s)

    @property
    def nodes(self) -> int:
        return math.prod(self.shape)

    def node_coordinates(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(y, zeta, t) of every geometry node, each of shape (y, zeta, t)."""
        ay, az, at, _ = self.axes()
        return tuple(np.meshgrid(ay.nodes(), az.nodes(), at.nodes(), indexing="ij"))


class LogTable:
    """Interpolation of tabulated logarithms at geometries and a parameter coordinate.

    Parameters
    ----------
    tables : sequence of numpy.ndarray
        Arrays of the same shape (y, zeta, t, s).
    """

    def __init__(self, tables: Sequence[np.ndarray]):
        shapes = {np.shape(t) for t in tables}
        if len(shapes) != 1 or len(next(iter(shapes))) != 4:
            raise ValueError(f"tables must share one 4-D shape, got {sorted(shapes)}")
        # components last, so that one gather reads every component of a cell
        self.values = np.ascontiguousarray(np.stack([np.asarray(t, float) for t in tables], axis=-1))
        self.grid = TableGrid(*self.values.shape[:4])
        self.axes = self.grid.axes()

    def prepare(self, theta_i, phi_i, theta_r, phi_r) -> Callable[[float], tuple[np.ndarray, ...]]:
        """Geometries [rad] -> function of s returning the interpolated logs (flattened)."""
        ti, pi_, tr, pr = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))
        theta_i, theta_r, delta_phi = ti.ravel(), tr.ravel(), (pr - pi_).ravel()
        m = theta_i.shape[0]
        s_axis = self.axes[3]
        columns: dict[int, np.ndarray] = {}
        first_call: dict[float, tuple[np.ndarray, ...]] = {}
        kept_stencils: list[tuple[tuple[np.ndarray, np.ndarray], ...]] = []
        components = self.values.shape[-1]

        def stencils(part: slice = slice(None)) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
            y, zeta, t, _ = geometry_coordinates(theta_i[part], theta_r[part], delta_phi[part])
            return tuple(axis_stencil(axis, x) for axis, x in zip(self.axes[:3], (y, zeta, t)))

        def column(node: int) -> np.ndarray:
            if not kept_stencils:
                kept_stencils.append(stencils())
            if node not in columns:
                columns[node] = np.ascontiguousarray(gather_3d(self.values[..., node, :], kept_stencils[0]).T)
            return columns[node]

        def evaluate(s: float) -> tuple[np.ndarray, ...]:
            s = float(s)
            if not first_call:  # one-off evaluation: reduce along s first, then stream the geometries
                reduced = CellRows(contract_last_axis(np.moveaxis(self.values, 3, -1), s_axis, s))  # (y, zeta, t, C)
                out = np.empty((m, components))
                for start in range(0, m, _STREAM_CHUNK):  # coordinates to values, chunk by chunk in cache
                    part = slice(start, start + _STREAM_CHUNK)
                    reduced(stencils(part), chunk=_STREAM_CHUNK, out=out[part])
                first_call[s] = tuple(np.ascontiguousarray(out.T))
            if s in first_call:  # the same s again gives the same bits
                return first_call[s]
            first, weights = axis_stencil(s_axis, np.asarray(float(s)))
            sums = np.zeros((components, m))
            for node, weight in zip(range(int(first), int(first) + 4), weights):
                sums += weight * column(node)
            return tuple(sums)

        return evaluate
