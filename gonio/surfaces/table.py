"""Rendered BRDF tables: the grid, the interpolation and the on-disk cache.

A rendered surface is far too slow to path-trace at every evaluation of the emulator
(49 BRDF values per measured point), and a fresh Monte Carlo estimate per call would add
noise that no uncertainty budget states.  So the BRDF of an isotropic surface is rendered
once on a grid, stored in the user table cache (``$GONIO_TABLE_DIR``, default
``~/.cache/gonio/tables``, next to the tables of :mod:`gonio.models.tabulated`) and
interpolated smoothly; the emulator then measures at the speed of a table lookup, and its
sample is a fixed, smooth function.

Grid
----
Isotropic surfaces depend on (theta_i, theta_r, phi_r - phi_i).  The coordinates are
those of the Oren-Nayar table (:mod:`gonio.models.tabulated.coordinates`), restricted to
polar angles up to :data:`THETA_MAX`:

``y`` = log(z_beta + Y_OFFSET) + Y_SLOPE z_beta, z_beta = 90 deg - min(theta_i, theta_r)
    (:func:`~gonio.models.tabulated.coordinates.y_coordinate`), from z_beta =
    90 deg - THETA_MAX to 90 deg: logarithmic near grazing, where the BRDF of a rough
    surface follows power laws of cos(theta), linear near the normal.
``zeta`` = 1 - sqrt(1 - r), r = (y(z_alpha) - y_min) / (y(z_beta) - y_min) in [0, 1],
    alpha = max(theta_i, theta_r): 0 at alpha = THETA_MAX, 1 at alpha = beta, with the
    nodes crowded toward alpha = beta.  Reciprocity halves the domain to alpha >= beta
    (every surface here is reciprocal: Lambertian facets, tested within the Monte Carlo
    error), and the retro-reflection cone at alpha = beta, phi_r = phi_i lies on the edge
    zeta = 1, not inside a cell.
``t`` : the phase-angle coordinate of the Oren-Nayar table (the same function), which
    makes the cone-shaped backscatter peak of shadowing surfaces smooth.

Polar angles beyond THETA_MAX are evaluated at THETA_MAX; directions below the horizon
reflect nothing.

Each node is rendered with the source at beta and the camera at alpha: by reciprocity the
same value, and the variance of the estimator grows like 1/cos(theta_i) (a grazing source
lights a small part of the surface with a large weight) but not with the camera's angle.
The table holds log(f + FLOOR) (relative interpolation error; FLOOR keeps the logarithm
finite where a truncated render vanishes), interpolated by the tensor-product Lagrange
cubic of :mod:`gonio.models.tabulated.kernel`, and the relative standard error of every
node.  Accuracy (Monte Carlo error of the nodes, interpolation error between them):
docs/surfaces.md.

Cache
-----
A table is named ``surface-<kind>-<16 hex digits>.npz``, the digits the start of the
SHA-256 of its key: everything that changes its numbers (kind, parameters, rho, paths per
node, seed, bounce limit, grid, THETA_MAX, FLOOR, the renderer's and the coordinates'
versions).  The key is stored in the file and checked on loading.  ``gonio tables info``
lists the tables, ``gonio tables clear`` deletes them with the other tables gonio built.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..models.tabulated.coordinates import (
    COORDINATES_VERSION,
    _p_from_t,
    geometry_coordinates,
    y_coordinate,
    z_from_y,
)
from ..models.tabulated.interpolation import Axis
from .analytic import every_order_known, known_orders
from .estimator import RENDERER_VERSION, kernel_inputs, render
from .spec import SurfaceSpec

__all__ = ["THETA_MAX", "FLOOR", "TABLE_FORMAT", "SurfaceGrid", "DEFAULT_GRID", "table_coordinates",
           "node_geometries", "SurfaceTable", "GRIDS", "EXACT_GRIDS", "grid_for", "table_key", "table_path",
           "COMMON_RANDOM_NUMBERS", "node_values", "render_table", "TabulatedSurface", "cached_tables",
           "NAME_PREFIX"]

#: Largest polar angle of the table [deg] (module notes).
THETA_MAX = 89.0
#: Added to the BRDF before the logarithm [1/sr].
FLOOR = 1e-4 / math.pi
#: Version of the table layout and its node estimator (part of the key): 2 = exact low
#: orders plus sampled rest, common random numbers for the V-groove field (:func:`node_values`).
TABLE_FORMAT = 2
#: File names of surface tables start with this.
NAME_PREFIX = "surface-"

_HALF_PI = 0.5 * math.pi
_Z_MIN = math.radians(90.0 - THETA_MAX)
_Y_MIN = float(y_coordinate(_Z_MIN))
_Y_MAX = float(y_coordinate(_HALF_PI))
_THETA_MAX_RAD = math.radians(THETA_MAX)


@dataclass(frozen=True)
class SurfaceGrid:
    """Node counts of the (y, zeta, t) axes of a surface table."""

    y: int = 16
    zeta: int = 9
    t: int = 13

    def axes(self) -> tuple[Axis, Axis, Axis]:
        return (Axis("y", _Y_MIN, _Y_MAX, self.y), Axis("zeta", 0.0, 1.0, self.zeta), Axis("t", 0.0, 1.0, self.t))

    @property
    def shape(self) -> tuple[int, int, int]:
        return (self.y, self.zeta, self.t)


#: The grid of smooth surfaces (the V-groove field, the height field).
DEFAULT_GRID = SurfaceGrid()
#: The grid of each kind.  The single-slope groove and the pits have kinks inside the
#: domain (onsets of shadowing at theta = 90 deg - theta_a; the hemispherical pit's
#: forward single scattering ends at theta_i + theta_r = 90 deg, Koenderink et al. eq 28)
#: and get more nodes; interpolation errors of both grids: docs/surfaces.md.  Used where
#: part of the BRDF is sampled: the Monte Carlo error of the nodes (median 0.05-0.6 %)
#: exceeds the interpolation error (median 1e-4 to 2e-4).
GRIDS = {"vgrooves": DEFAULT_GRID, "heightfield": DEFAULT_GRID, "vgroove": SurfaceGrid(20, 11, 16),
         "pits": SurfaceGrid(20, 11, 16)}
#: The grids of tables whose every order is known exactly (:func:`~.analytic.every_order_known`:
#: pits, grooves at one or two bounces): interpolation is their only error, and their
#: nodes cost little, so they are finer (measured at 3000 random geometries up to 89 deg:
#: the V-groove field median 1.2e-5, 99th percentile 1.1e-4; the single slope and the
#: pits, kinked, median 1.3e-5 and 1.7e-5, 99th percentile 8e-4 and 1.9e-3).
EXACT_GRIDS = {"vgrooves": SurfaceGrid(28, 15, 22), "vgroove": SurfaceGrid(36, 19, 28),
               "pits": SurfaceGrid(36, 19, 28)}


def grid_for(spec: SurfaceSpec) -> SurfaceGrid:
    """The table grid of ``spec``: :data:`EXACT_GRIDS` where every order is known, else
    :data:`GRIDS`."""
    if every_order_known(spec.surface, spec.bounces):
        return EXACT_GRIDS[spec.surface.kind]
    return GRIDS[spec.surface.kind]


def table_coordinates(theta_i: np.ndarray, theta_r: np.ndarray, delta_phi: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(y, zeta, t) of geometries [rad] (module notes); polar angles clamped to THETA_MAX.

    Examples
    --------
    >>> y, zeta, t = table_coordinates(np.radians(30.0), np.radians(30.0), 0.0)
    >>> float(zeta), float(t)   # alpha = beta, retro-reflection: the corner of the table
    (1.0, 0.0)
    """
    ti = np.minimum(np.asarray(theta_i, float), _THETA_MAX_RAD)
    tr = np.minimum(np.asarray(theta_r, float), _THETA_MAX_RAD)
    y, _, t, z_beta = geometry_coordinates(ti, tr, delta_phi)
    z_alpha = _HALF_PI - np.maximum(ti, tr)
    span = y - _Y_MIN
    safe = np.where(span > 0.0, span, 1.0)
    ratio = np.where(span > 0.0, (y_coordinate(z_alpha) - _Y_MIN) / safe, 1.0)
    zeta = 1.0 - np.sqrt(np.clip(1.0 - ratio, 0.0, 1.0))
    return y, zeta, t


def node_geometries(grid: SurfaceGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(alpha, beta, delta_phi) [rad] of every node, alpha >= beta, each of shape grid.shape."""
    ay, az, at = grid.axes()
    y, zeta, t = np.meshgrid(ay.nodes(), az.nodes(), at.nodes(), indexing="ij")
    z_beta = z_from_y(y)
    ratio = 1.0 - (1.0 - zeta) ** 2
    z_alpha = np.asarray(z_from_y(_Y_MIN + ratio * (y - _Y_MIN)))
    z_alpha = np.clip(z_alpha, _Z_MIN, z_beta)
    alpha, beta = _HALF_PI - z_alpha, _HALF_PI - z_beta
    phase = (alpha - beta) + 2.0 * beta * _p_from_t(t)
    denominator = np.sin(alpha) * np.sin(beta)
    cos_dphi = np.divide(np.cos(phase) - np.cos(alpha) * np.cos(beta), denominator,
                         out=np.array(1.0 - 2.0 * _p_from_t(t)), where=denominator > 1e-12)
    return alpha, beta, np.arccos(np.clip(cos_dphi, -1.0, 1.0))


class SurfaceTable:
    """Interpolation of a rendered table of log(f + FLOOR) on a :class:`SurfaceGrid`.

    Parameters
    ----------
    log_brdf : numpy.ndarray
        Shape (y, zeta, t): log(f + FLOOR) at the nodes.
    relative_error : numpy.ndarray, optional
        Relative standard error of f at the nodes (kept for reports).
    """

    def __init__(self, log_brdf: np.ndarray, relative_error: np.ndarray | None = None):
        values = np.asarray(log_brdf, float)
        if values.ndim != 3:
            raise ValueError(f"a surface table is 3-D (y, zeta, t), got shape {values.shape}")
        self.grid = SurfaceGrid(*values.shape)
        self.values = np.ascontiguousarray(values[..., None])
        axes = self.grid.axes()
        self.lo = np.array([a.lo for a in axes])
        self.step = np.array([a.step for a in axes])
        self.relative_error = relative_error

    def __call__(self, theta_i, phi_i, theta_r, phi_r) -> np.ndarray:
        """BRDF [1/sr] at geometries [deg] (broadcast); 0 below the horizon, NaN for NaN."""
        from ..models.tabulated.kernel import interpolate_points  # numba on first use

        arrays = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))
        ti, pi_, tr, pr = (np.radians(a.ravel()) for a in arrays)
        valid = (ti <= _HALF_PI) & (tr <= _HALF_PI) & (ti >= 0.0) & (tr >= 0.0)
        y, zeta, t = table_coordinates(np.where(valid, ti, 0.0), np.where(valid, tr, 0.0), pr - pi_)
        out = np.empty((1, ti.size))
        interpolate_points(self.values, self.lo, self.step, np.ascontiguousarray(y), np.ascontiguousarray(zeta),
                           np.ascontiguousarray(np.nan_to_num(t)), out)
        brdf = np.maximum(np.exp(out[0]) - FLOOR, 0.0)
        brdf = np.where(valid, brdf, 0.0)
        brdf[np.isnan(ti) | np.isnan(tr) | np.isnan(pi_) | np.isnan(pr)] = np.nan
        return brdf.reshape(arrays[0].shape)


def table_key(spec: SurfaceSpec, grid: SurfaceGrid | None = None) -> dict:
    """Everything that changes a table's numbers (module notes), as plain values."""
    grid = grid or grid_for(spec)
    return {"format": TABLE_FORMAT, "renderer": RENDERER_VERSION, "coordinates": COORDINATES_VERSION,
            "kind": spec.surface.kind, "parameters": spec.surface.parameters(), "paths": spec.paths,
            "seed": spec.seed, "bounces": spec.bounces, "grid": list(grid.shape), "theta_max": THETA_MAX,
            "floor": FLOOR}


def _key_text(key: dict) -> str:
    return json.dumps(key, sort_keys=True, separators=(",", ":"))


def table_path(spec: SurfaceSpec, grid: SurfaceGrid | None = None, directory: Path | None = None) -> Path:
    """Where the table of ``spec`` is cached: ``surface-<kind>-<digest>.npz``."""
    from ..models.tabulated.store import cache_dir

    digest = hashlib.sha256(_key_text(table_key(spec, grid)).encode()).hexdigest()[:16]
    return Path(directory or cache_dir()) / f"{NAME_PREFIX}{spec.surface.kind}-{digest}.npz"


#: Kinds whose table nodes share one stream (common random numbers), chosen by
#: measurement (benchmarks/surfaces_tables.py, docs/surfaces.md "Tables"): for the
#: V-groove field the shared paths make the node error three times less jagged and halve
#: what a fit cannot absorb of it; for the single-slope groove they make the error larger
#: and the fitted parameters scatter more, for the height field larger and no smoother
#: (its nodes' paths see different facets): those keep one stream per node.
COMMON_RANDOM_NUMBERS = {"vgrooves": True, "vgroove": False, "heightfield": False, "pits": False}


def node_values(spec: SurfaceSpec, theta_i: np.ndarray, theta_r: np.ndarray, delta_phi: np.ndarray,
                common_random_numbers: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A table's estimate of the all-bounce (or truncated) BRDF at geometries [1/sr].

    Parameters
    ----------
    spec : SurfaceSpec
        The surface, paths, seed and bounce limit.
    theta_i, theta_r, delta_phi : numpy.ndarray
        Source and viewing polar angles and phi_r - phi_i [deg] (1-D, equal length).
    common_random_numbers : bool, optional
        Render every geometry with the same paths (:func:`~.estimator.render`); default:
        the kind's entry of :data:`COMMON_RANDOM_NUMBERS`.

    Returns
    -------
    value, standard_error : numpy.ndarray
        The BRDF and the standard error of its sampled part [1/sr]; 0 where nothing is
        sampled.

    Notes
    -----
    value = the orders a paper gives exactly (:func:`~.analytic.known_orders`) + the
    Monte Carlo estimate of the remaining orders from :func:`~.estimator.render`'s paths
    (``orders[2]``: the third and later scattering events).  An analytic partial sum (a
    control variate of coefficient 1): the expectation is the BRDF of the surface at the
    bounce limit, the variance that of the sampled orders alone.  The V-grooves render
    with ``expected_bounces`` (the light of each bounce integrated over the other facet).
    Where every order is known (pits; grooves at one or two bounces) nothing is rendered;
    where nothing is (the height field) every order is sampled.
    """
    known = known_orders(spec.surface, theta_i, 0.0, theta_r, delta_phi, spec.bounces)
    if known is not None and known.orders is None:
        return np.asarray(known.value, float), np.zeros(np.shape(theta_i))
    if common_random_numbers is None:
        common_random_numbers = COMMON_RANDOM_NUMBERS[spec.surface.kind]
    rendered = render(spec.surface, theta_i, 0.0, theta_r, delta_phi, paths=spec.paths, seed=spec.seed,
                      bounces=spec.bounces, common_random_numbers=common_random_numbers, expected_bounces=True)
    if known is None:
        return rendered.value, rendered.standard_error
    return known.value + rendered.orders[2], rendered.order_error[2]


def render_table(spec: SurfaceSpec, grid: SurfaceGrid | None = None, workers: int | None = None,
                 progress: Callable[[int, int, float | None], None] | None = None) -> dict[str, np.ndarray]:
    """Render the BRDF of ``spec`` at every node of ``grid``.

    Parameters
    ----------
    spec : SurfaceSpec
        The surface, paths per node, seed, bounce limit.
    grid : SurfaceGrid, optional
        Node counts (default: the kind's, :data:`GRIDS`).
    workers : int, optional
        Threads (default: every CPU); the numbers do not depend on it.
    progress : callable, optional
        Called as ``progress(done, total, seconds_left)`` after each batch of nodes
        (``seconds_left`` None until a batch is done).

    Returns
    -------
    dict
        ``log_brdf`` (grid shape), ``relative_error``, the key (``key``, JSON text), the
        spec text, and ``build_seconds``.
    """
    if not spec.surface.isotropic:
        raise ValueError(f"surface {spec.text()}: only isotropic surfaces are tabulated "
                         "(render an anisotropic one with gonio.surfaces.render)")
    grid = grid or grid_for(spec)
    alpha, beta, dphi = (np.degrees(a).ravel() for a in node_geometries(grid))
    kernel_inputs(spec.surface)  # a height field is realised once, before the threads start
    batch = 16
    starts = list(range(0, alpha.size, batch))
    value, error = np.empty(alpha.size), np.empty(alpha.size)
    start_time = time.perf_counter()

    def task(first: int) -> int:
        part = slice(first, first + batch)
        # source at beta (nearer the normal), camera at alpha: the reciprocal configuration
        value[part], error[part] = node_values(spec, beta[part], alpha[part], dphi[part])
        return min(batch, alpha.size - first)

    done = 0
    if progress is not None:
        progress(0, alpha.size, None)
    with ThreadPoolExecutor(max_workers=workers or os.cpu_count() or 1) as pool:
        for future in as_completed([pool.submit(task, first) for first in starts]):
            done += future.result()
            if progress is not None:
                elapsed = time.perf_counter() - start_time
                progress(done, alpha.size, elapsed * (alpha.size - done) / done)
    relative = np.divide(error, value, out=np.zeros_like(error), where=value > 0.0)
    return {"log_brdf": np.log(value + FLOOR).reshape(grid.shape), "relative_error": relative.reshape(grid.shape),
            "key": np.array(_key_text(table_key(spec, grid))), "spec": np.array(spec.text()),
            "build_seconds": np.array(time.perf_counter() - start_time)}


def _read(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        return {name: data[name] for name in data.files}


class TabulatedSurface:
    """The emulator's sample for a surface spec: its cached table, rendered on first use.

    Parameters
    ----------
    spec : SurfaceSpec
        The surface and its rendering.
    grid : SurfaceGrid, optional
        Table grid (default: the kind's, :data:`GRIDS`).
    progress : callable, optional
        ``progress(done, total, seconds_left)`` while a table is rendered.
    workers : int, optional
        Threads for rendering (default: every CPU).

    Calling it (``brdf(theta_i, phi_i, theta_r, phi_r)`` in degrees, [1/sr]) loads the
    table, or renders and caches it first.
    """

    def __init__(self, spec: SurfaceSpec, grid: SurfaceGrid | None = None,
                 progress: Callable[[int, int, float | None], None] | None = None, workers: int | None = None):
        if not spec.surface.isotropic:
            raise ValueError(f"surface {spec.text()}: an anisotropic surface (a V-groove with phi_a) cannot be an "
                             "emulated sample: the rig has no sample rotation and its tables are isotropic; omit "
                             "phi_a for the isotropic single-slope surface")
        self.spec, self.grid, self.progress, self.workers = spec, grid or grid_for(spec), progress, workers
        self._table: SurfaceTable | None = None
        #: Whether the last :meth:`load` rendered the table (False: read from the cache).
        self.rendered = False

    @property
    def path(self) -> Path:
        """Where the table is cached (read at call time: ``$GONIO_TABLE_DIR`` may change)."""
        return table_path(self.spec, self.grid)

    def load(self) -> SurfaceTable:
        """The table: from the cache, or rendered now (with progress) and cached."""
        if self._table is not None:
            return self._table
        from ..models.tabulated import store

        path = self.path
        expected = _key_text(table_key(self.spec, self.grid))
        arrays = _read(path) if path.is_file() else None
        if arrays is not None and str(arrays.get("key", "")) != expected:
            raise store.TableError(f"table {path} holds another surface's numbers (its key differs from "
                                   f"{self.spec.text()}); delete it with 'gonio tables clear'")
        if arrays is None:
            store.save(path, render_table(self.spec, self.grid, self.workers, self.progress))
            arrays = _read(path)  # as stored (float32): the first use and later ones agree to the bit
            self.rendered = True
        self._table = SurfaceTable(arrays["log_brdf"], arrays["relative_error"])
        return self._table

    def __call__(self, theta_i, phi_i, theta_r, phi_r) -> np.ndarray:
        return self.load()(theta_i, phi_i, theta_r, phi_r)


def cached_tables(directory: Path | None = None) -> list[dict]:
    """Facts about every surface table in the cache: path, spec, nodes, error, build time."""
    from ..models.tabulated.store import cache_dir, written_by_builder

    folder = Path(directory or cache_dir())
    found = []
    for path in sorted(folder.glob(f"{NAME_PREFIX}*.npz")) if folder.is_dir() else []:
        if not written_by_builder(path):
            continue
        arrays = _read(path)
        error = arrays.get("relative_error")
        found.append({"path": path, "spec": str(arrays.get("spec", "?")), "bytes": path.stat().st_size,
                      "nodes": int(np.size(arrays.get("log_brdf", []))),
                      "median_error": float(np.median(error)) if error is not None else math.nan,
                      "max_error": float(np.max(error)) if error is not None else math.nan,
                      "build_seconds": float(arrays.get("build_seconds", math.nan))})
    return found
