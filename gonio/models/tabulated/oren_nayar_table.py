"""Building the Oren-Nayar table: the exact components on the grid of :mod:`.coordinates`.

The table holds ``L1 = log(pi f1)`` and ``L2 = log(pi (f2 + F2_FLOOR f1))`` of the exact
V-cavity model (``oren-nayar-exact``, :func:`~gonio.models.oren_nayar.exact.exact_components`)
at every node of a regular grid in (y, zeta, t, s).  Logarithms make the interpolation
error a *relative* error and turn the power laws of the grazing regime (f1 ~ 1/cos(beta)
backwards, ~cos(beta) forwards) into straight lines in y.  The small floor on f2 keeps
its logarithm finite where the interreflection vanishes (sigma = 0); the floor is removed
after interpolation, so it costs at most F2_FLOOR times the relative error of f1 in the
BRDF.
"""
from __future__ import annotations

import math
import os
import time

import numpy as np

from .coordinates import (
    COORDINATES_VERSION,
    SIGMA_SCALE_DEG,
    Y_SLOPE,
    Y_OFFSET,
    geometry_from_coordinates,
    sigma_from_coordinate,
)
from .lookup import TableGrid

__all__ = ["PROBES", "probe_values", "F2_FLOOR", "OrenNayarGrid", "DEFAULT_GRID", "build_oren_nayar_table"]

#: f2 is tabulated as log(pi (f2 + F2_FLOOR f1)).
F2_FLOOR = 1e-4


#: The grid of the Oren-Nayar table (a :class:`~.lookup.TableGrid`).
OrenNayarGrid = TableGrid


#: Node counts of the shipped table (accuracy study: docs/tabulated.md).
DEFAULT_GRID = OrenNayarGrid(y=55, zeta=20, t=44, s=26)


def _node_geometry(grid: OrenNayarGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    y, zeta, t = grid.node_coordinates()
    theta_i, theta_r, delta_phi = geometry_from_coordinates(y, zeta, t)
    return np.degrees(theta_i), np.degrees(theta_r), np.degrees(delta_phi)


def _sigma_slice(args) -> tuple[np.ndarray, np.ndarray]:
    from ..oren_nayar.exact import exact_components

    grid, sigma, rtol = args
    theta_i, theta_r, delta_phi = _node_geometry(grid)
    if sigma == 0.0:
        f1, f2 = np.full(theta_i.shape, 1.0 / math.pi), np.zeros(theta_i.shape)
    else:
        f1, f2 = exact_components(theta_i, 0.0, theta_r, delta_phi, sigma, rtol=rtol)
    return np.log(math.pi * f1), np.log(math.pi * (f2 + F2_FLOOR * f1))


#: Geometries (theta_i, theta_r, dphi [deg], sigma [deg]) where the exact model's values
#: are stored with the table, so that a change of the exact model is detected
#: (tests/models/test_tabulated.py): ordinary, near-normal, grazing and horizon corners.
PROBES = np.array([
    [30.0, 60.0, 40.0, 20.0],
    [5.0, 2.0, 10.0, 70.0],
    [75.0, 70.0, 5.0, 45.0],
    [85.0, 80.0, 170.0, 30.0],
    [90.0, 45.0, 90.0, 10.0],
    [90.0, 90.0, 0.0, 60.0],
    [90.0, 90.0, 180.0, 60.0],
    [89.0, 10.0, 150.0, 85.0],
])


def probe_values(rtol: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Exact (f1, f2) [1/sr] at :data:`PROBES`, at accuracy ``rtol``."""
    from ..oren_nayar.exact import exact_components

    values = [exact_components(ti, 0.0, tr, dphi, sigma, rtol=rtol) for ti, tr, dphi, sigma in PROBES]
    return np.array([float(v[0]) for v in values]), np.array([float(v[1]) for v in values])


def build_oren_nayar_table(
    grid: OrenNayarGrid = DEFAULT_GRID, rtol: float = 1e-6, workers: int | None = None,
    progress=None,
) -> dict[str, np.ndarray]:
    """Evaluate the exact Oren-Nayar components on every node of ``grid``.

    Parameters
    ----------
    grid : OrenNayarGrid
        Node counts.
    rtol : float
        Accuracy of the exact model at the nodes (an ``rtol`` of ``oren-nayar-exact``).
    workers : int, optional
        Processes (one roughness node per task); default: the number of CPUs.
    progress : callable, optional
        Called with (done, total) after each roughness node.

    Returns
    -------
    dict
        ``log_f1``, ``log_f2`` of shape (y, zeta, t, s), the axis sizes and metadata.
    """
    sigmas = sigma_from_coordinate(grid.axes()[3].nodes())
    sigmas[0] = 0.0
    shape = (grid.y, grid.zeta, grid.t, grid.s)
    log_f1, log_f2 = np.empty(shape), np.empty(shape)
    tasks = [(grid, float(sigma), rtol) for sigma in sigmas]
    start = time.perf_counter()
    workers = workers or os.cpu_count() or 1
    if workers == 1:
        results = map(_sigma_slice, tasks)
    else:
        from concurrent.futures import ProcessPoolExecutor  # only a table build needs it

        pool = ProcessPoolExecutor(max_workers=workers)
        results = pool.map(_sigma_slice, tasks)
    for k, (l1, l2) in enumerate(results):
        log_f1[..., k], log_f2[..., k] = l1, l2
        if progress is not None:
            progress(k + 1, len(tasks))
    if workers != 1:
        pool.shutdown()
    probe_f1, probe_f2 = probe_values()
    return {
        "probe_f1": probe_f1,
        "probe_f2": probe_f2,
        "log_f1": log_f1,
        "log_f2": log_f2,
        "shape": np.array(shape),
        "rtol": np.array(rtol),
        "f2_floor": np.array(F2_FLOOR),
        "y_offset": np.array(Y_OFFSET),
        "y_slope": np.array(Y_SLOPE),
        "coordinates_version": np.array(COORDINATES_VERSION),
        "sigma_scale_deg": np.array(SIGMA_SCALE_DEG),
        "build_seconds": np.array(time.perf_counter() - start),
    }
