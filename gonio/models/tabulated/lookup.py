"""Tables of logarithms on the grid (y, zeta, t, s) and their fast evaluation.

A :class:`LogTable` holds one or more 4-D arrays of tabulated logarithms (one per model
component) on a :class:`TableGrid`.  :meth:`LogTable.prepare` takes fixed geometries and
returns a function of the parameter coordinate ``s`` giving the interpolated logarithms:

* on its first call it reduces each table along s (4 slices) and interpolates the
  remaining 3-D table at every geometry (the compiled loop of :mod:`.kernel`: table
  coordinates, cubic stencils and the 64-value sum per geometry; the plain call of a
  model is this path);
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

from .coordinates import y_coordinate
from .interpolation import Axis, axis_stencil, contract_first_axis

__all__ = ["TableGrid", "LogTable"]



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
        if not 1 <= len(tables) <= 2:
            raise ValueError(f"a LogTable interpolates one or two components, got {len(tables)}")
        # stored (s, y, zeta, t, component): every s node is one contiguous (y, zeta, t, C)
        # slab (what the compiled loop reads), and reducing along s reads four slabs only;
        # components last, so that the values of one node are adjacent in memory
        stacked = np.stack([np.asarray(t, float) for t in tables], axis=-1)
        self.values = np.ascontiguousarray(np.moveaxis(stacked, 3, 0))
        self.grid = TableGrid(*stacked.shape[:4])
        self.axes = self.grid.axes()
        #: First node and node spacing of the three geometry axes (what the kernel reads)
        self.lo = np.array([axis.lo for axis in self.axes[:3]])
        self.step = np.array([axis.step for axis in self.axes[:3]])

    def interpolate(self, slab: np.ndarray, theta_i: np.ndarray, theta_r: np.ndarray,
                    delta_phi: np.ndarray) -> np.ndarray:
        """Tricubic interpolation of a (y, zeta, t, component) slab at geometries [rad].

        Returns an array of shape (C, m) for m geometries (1-D float arrays).
        """
        from .kernel import interpolate_geometries  # numba loads on first use, not at import

        out = np.empty((slab.shape[-1], theta_i.shape[0]))
        interpolate_geometries(slab, self.lo, self.step, theta_i, theta_r, delta_phi, out)
        return out

    def slab_at(self, s: float) -> np.ndarray:
        """The table reduced along s at coordinate ``s``: shape (y, zeta, t, C), contiguous."""
        return contract_first_axis(self.values, self.axes[3], s)

    def node_slab(self, node: int) -> np.ndarray:
        """The table at s node ``node``: shape (y, zeta, t, C), contiguous (a view)."""
        return self.values[node]

    def prepare(self, theta_i, phi_i, theta_r, phi_r) -> Callable[[float], tuple[np.ndarray, ...]]:
        """Geometries [rad] -> function of s returning the interpolated logs (flattened);
        its ``rows(s_array)`` gives them for many coordinates at once, shape (C, W, m)."""
        ti, pi_, tr, pr = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))
        theta_i, theta_r = np.ascontiguousarray(ti.ravel()), np.ascontiguousarray(tr.ravel())
        delta_phi = np.ascontiguousarray((pr - pi_).ravel())
        s_axis = self.axes[3]
        columns: dict[int, np.ndarray] = {}
        first_call: dict[float, tuple[np.ndarray, ...]] = {}

        def column(node: int) -> np.ndarray:
            if node not in columns:
                columns[node] = self.interpolate(self.node_slab(node), theta_i, theta_r, delta_phi)
            return columns[node]

        def evaluate(s: float) -> tuple[np.ndarray, ...]:
            s = float(s)
            if not first_call:  # one-off evaluation: reduce along s first, then the geometries
                first_call[s] = tuple(self.interpolate(self.slab_at(s), theta_i, theta_r, delta_phi))
            if s in first_call:  # the same s again gives the same bits
                return first_call[s]
            first, weights = axis_stencil(s_axis, np.asarray(float(s)))
            sums = np.zeros((self.values.shape[-1], theta_i.shape[0]))
            for node, weight in zip(range(int(first), int(first) + 4), weights):
                sums += weight * column(node)
            return tuple(sums)

        def rows(s: np.ndarray) -> np.ndarray:
            """The logs at every coordinate of ``s`` (shape (W,)): shape (C, W, m), each row
            the bits ``evaluate`` gives after its first call (the same columns, summed in
            the same order)."""
            s = np.asarray(s, float).reshape(-1)
            first, weights = axis_stencil(s_axis, s)
            sums = np.zeros((self.values.shape[-1], s.size, theta_i.shape[0]))
            for offset in range(4):
                nodes = first + offset
                for node in np.unique(nodes):
                    chosen = nodes == node
                    sums[:, chosen, :] += weights[chosen, offset][None, :, None] * column(int(node))[:, None, :]
            return sums

        evaluate.rows = rows  # type: ignore[attr-defined]
        return evaluate
