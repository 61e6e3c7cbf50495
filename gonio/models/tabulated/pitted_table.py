"""Building the pitted-surface table: the single-scattering factor F1 on the table grid.

The pitted BRDF (Koenderink et al. 1999) is ``(1 - coverage) rho/pi + coverage (rho F1 +
F2)`` where only F1 (eq 14-15) needs a numerical integral; F2 (eq 12) is closed form.
The table holds ``asinh(pi F1 / PIT_SCALE)`` of :func:`~gonio.models.pitted.model.pitted_terms`
at every node of a :class:`~.lookup.TableGrid`, the last axis being the aperture psi in
the coordinate :data:`PSI_MAP`.

Why asinh and not a logarithm as for Oren-Nayar: F1 is exactly zero on open sets of
geometries (deep pits seen in the forward direction: the lit and the visible parts of the
cavity do not overlap), where a logarithm has no value and its steep descent towards the
zero set cannot be interpolated.  asinh(x / PIT_SCALE) is linear for x << PIT_SCALE (the
zero set and its edge are interpolated with an absolute error) and logarithmic for
x >> PIT_SCALE (relative accuracy, and the 1/cos(theta) growth of grazing
retro-reflection becomes linear in the y coordinate).
"""
from __future__ import annotations

import math
import os
import time
from concurrent.futures import ProcessPoolExecutor

from typing import Callable

import numpy as np

from .coordinates import COORDINATES_VERSION, Y_OFFSET, Y_SLOPE, ParameterMap, geometry_from_coordinates
from .lookup import LogTable, TableGrid
from .store import check_constants, load

__all__ = [
    "PIT_SCALE", "PSI_SCALE_DEG", "PSI_MAP", "DEFAULT_PIT_GRID", "PIT_TABLE_NAME", "build_pitted_table",
    "PittedTable", "table", "reset_table",
]

#: F1 is tabulated as asinh(pi F1 / PIT_SCALE).
PIT_SCALE = 1e-3
#: Aperture [deg] where the psi coordinate turns from linear to logarithmic.
PSI_SCALE_DEG = 0.5
#: The aperture coordinate: s = asinh(psi / 0.5 deg) / asinh(90 deg / 0.5 deg).
PSI_MAP = ParameterMap(PSI_SCALE_DEG, 90.0)
#: Node counts of the shipped pitted table.
DEFAULT_PIT_GRID = TableGrid(y=55, zeta=16, t=32, s=32)


def _psi_slice(args) -> np.ndarray:
    from ..pitted.model import pitted_terms

    grid, psi = args
    alpha, beta, delta_phi = geometry_from_coordinates(*grid.node_coordinates())
    if psi == 0.0:  # psi -> 0: a flat Lambertian plane (F1 = 1/pi off the horizon)
        factor = np.full(alpha.shape, 1.0 / math.pi)
    else:
        factor = pitted_terms(np.degrees(alpha), 0.0, np.degrees(beta), np.degrees(delta_phi), psi).single_scattering
    return np.arcsinh(math.pi * factor / PIT_SCALE)


def build_pitted_table(grid: TableGrid = DEFAULT_PIT_GRID, workers: int | None = None, progress=None) -> dict:
    """Evaluate the pitted single-scattering factor F1 on every node of ``grid``.

    Parameters
    ----------
    grid : TableGrid
        Node counts (the last axis is the aperture).
    workers : int, optional
        Processes (default: the number of CPUs).
    progress : callable, optional
        Called with (done, total) after each aperture node.

    Returns
    -------
    dict
        ``asinh_f1`` of shape (y, zeta, t, s) and metadata.
    """
    apertures = PSI_MAP.value(grid.axes()[3].nodes())
    apertures[0] = 0.0
    log_f1 = np.empty(grid.shape)
    tasks = [(grid, float(psi)) for psi in apertures]
    start = time.perf_counter()
    workers = workers or os.cpu_count() or 1
    pool = ProcessPoolExecutor(max_workers=workers) if workers > 1 else None
    results = pool.map(_psi_slice, tasks) if pool else map(_psi_slice, tasks)
    for k, values in enumerate(results):
        log_f1[..., k] = values
        if progress is not None:
            progress(k + 1, len(tasks))
    if pool:
        pool.shutdown()
    return {
        "asinh_f1": log_f1,
        "shape": np.array(grid.shape),
        "rtol": np.array(1e-9),
        "pit_scale": np.array(PIT_SCALE),
        "y_offset": np.array(Y_OFFSET),
        "y_slope": np.array(Y_SLOPE),
        "coordinates_version": np.array(COORDINATES_VERSION),
        "psi_scale_deg": np.array(PSI_SCALE_DEG),
        "build_seconds": np.array(time.perf_counter() - start),
    }


#: File name (without ``.npz``) of the pitted table.
PIT_TABLE_NAME = "pitted"

_COORDINATE_CONSTANTS = {
    "y_offset": Y_OFFSET, "psi_scale_deg": PSI_SCALE_DEG, "pit_scale": PIT_SCALE,
    "y_slope": Y_SLOPE, "coordinates_version": COORDINATES_VERSION,
}


class PittedTable:
    """The tabulated single-scattering factor (asinh-transformed) and its evaluation.

    Parameters
    ----------
    arrays : dict
        ``asinh_f1`` (shape (y, zeta, t, s)) and the constants it was built with.
    """

    def __init__(self, arrays: dict[str, np.ndarray]):
        check_constants(arrays, _COORDINATE_CONSTANTS, PIT_TABLE_NAME)
        self.lookup = LogTable((arrays["asinh_f1"],))
        self.grid = self.lookup.grid

    def prepare(self, theta_i, phi_i, theta_r, phi_r) -> Callable[[float], np.ndarray]:
        """Geometry [rad] -> function of psi [deg] returning F1 [1/sr]."""
        shape = np.broadcast_shapes(*(np.shape(a) for a in (theta_i, phi_i, theta_r, phi_r)))
        logs = self.lookup.prepare(theta_i, phi_i, theta_r, phi_r)

        def factor(psi: float) -> np.ndarray:
            (values,) = logs(float(PSI_MAP.coordinate(psi)))
            return (np.sinh(values) * (PIT_SCALE / math.pi)).reshape(shape)

        return factor


_TABLE: list[PittedTable] = []


def table() -> PittedTable:
    """The pitted table (loaded on first use, then kept)."""
    if not _TABLE:
        _TABLE.append(PittedTable(load(PIT_TABLE_NAME)))
    return _TABLE[0]


def reset_table() -> None:
    """Forget the loaded table (after ``gonio tables build`` or ``clear``)."""
    _TABLE.clear()
    load.cache_clear()


