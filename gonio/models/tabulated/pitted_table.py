"""Building the pitted-surface table: the single-scattering factor F1 on the table grid.

The pitted BRDF (Koenderink et al. 1999) is ``(1 - coverage) rho/pi + coverage (rho F1 +
F2)`` where only F1 (eq 14-15) needs a numerical integral; F2 (eq 12) is closed form.

F1 is not smooth: it vanishes identically on open sets of geometries (deep pits seen in
the forward direction, where the lit and the visible parts of the cavity do not overlap)
and has kinks wherever a lit or visible arc of the cavity appears, vanishes or becomes
complete.  Those edges cross any fixed grid, and near the zero sets a relative accuracy
is impossible for any interpolation of F1 itself.  So the table holds the logarithm of
the ratio

    H = F1 / G,   G = the same integral by a coarse rule (DIVISOR_ORDER nodes per panel)

at every node of a :class:`~.lookup.TableGrid` (last axis: the aperture psi in the
coordinate :data:`PSI_MAP`), and a lookup multiplies the interpolated H by G computed at
the evaluated geometry and aperture.  G is the deterministic quadrature of
:mod:`gonio.models.pitted.quadrature` (panels split at every kink of the inner integral,
arcs integrated exactly in closed form) with 2 instead of 16 nodes per panel: it is zero
exactly where F1 is, it carries F1's kinks (its panels end at them), and near a vanishing
lit-and-visible region, which shrinks self-similarly, its relative error tends to a
constant, so H is smooth across the edges (measured: docs/tabulated.md).  Where F1 = G = 0
at a node, H is copied from the nearest node along the azimuth axis where it is defined
(the value there only matters as an extension; the product is 0 anyway).
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
    "DIVISOR_ORDER", "PSI_SCALE_DEG", "PSI_MAP", "DEFAULT_PIT_GRID", "PIT_TABLE_NAME", "build_pitted_table",
    "coarse_factor", "PittedTable", "table", "reset_table",
]

#: Gauss-Legendre nodes per panel of the coarse divisor G (the exact model uses 16).
DIVISOR_ORDER = 10
#: Aperture [deg] where the psi coordinate turns from linear to logarithmic.
PSI_SCALE_DEG = 20.0
#: The aperture coordinate: s = asinh(psi / 20 deg) / asinh(90 deg / 20 deg).
PSI_MAP = ParameterMap(PSI_SCALE_DEG, 90.0)
#: Node counts of the shipped pitted table.
DEFAULT_PIT_GRID = TableGrid(y=55, zeta=16, t=48, s=32)


def coarse_factor(theta_i: np.ndarray, theta_r: np.ndarray, delta_phi: np.ndarray, psi_deg: float) -> np.ndarray:
    """The divisor G: F1 by the coarse rule (DIVISOR_ORDER nodes per panel) [1/sr].

    Parameters
    ----------
    theta_i, theta_r : numpy.ndarray
        Polar angles [rad] in [0, pi/2].
    delta_phi : numpy.ndarray
        Azimuth difference [rad].
    psi_deg : float
        Aperture [deg] in [0, 90]; 0 gives the flat-plane value 1/pi.

    Returns
    -------
    numpy.ndarray
        G [1/sr]; zero exactly where the single-scattering factor F1 is (eq 14-15 of
        Koenderink et al. 1999, :func:`gonio.models.pitted.quadrature.single_scattering_factor`).
    """
    from ..pitted.quadrature import single_scattering_factor

    if psi_deg == 0.0:  # psi -> 0: a flat Lambertian plane (F1 = 1/pi off the horizon)
        return np.full(np.broadcast_shapes(np.shape(theta_i), np.shape(theta_r), np.shape(delta_phi)), 1.0 / math.pi)
    return single_scattering_factor(theta_i, theta_r, delta_phi, math.radians(psi_deg), DIVISOR_ORDER)


def _fill_undefined(log_ratio: np.ndarray, defined: np.ndarray) -> np.ndarray:
    """Copy each undefined value from the nearest defined node along the t axis (axis 2)."""
    out = log_ratio.copy()
    n = out.shape[2]
    index = np.arange(n)
    for position in np.argwhere(~defined.all(axis=2)):
        line = defined[position[0], position[1], :]
        if not line.any():
            out[position[0], position[1], :] = 0.0
            continue
        known = index[line]
        nearest = known[np.abs(index[:, None] - known[None, :]).argmin(axis=1)]
        out[position[0], position[1], :] = out[position[0], position[1], nearest]
    return out


def _psi_slice(args) -> np.ndarray:
    from ..pitted.model import pitted_terms

    grid, psi = args
    alpha, beta, delta_phi = geometry_from_coordinates(*grid.node_coordinates())
    if psi == 0.0:
        return np.zeros(alpha.shape)
    exact = pitted_terms(np.degrees(alpha), 0.0, np.degrees(beta), np.degrees(delta_phi), psi).single_scattering
    coarse = coarse_factor(alpha, beta, delta_phi, psi)
    defined = (coarse > 0.0) & (exact > 0.0)
    ratio = np.divide(exact, coarse, out=np.ones_like(exact), where=defined)
    return _fill_undefined(np.log(ratio), defined)


def build_pitted_table(grid: TableGrid = DEFAULT_PIT_GRID, workers: int | None = None, progress=None) -> dict:
    """Evaluate log(F1 / G) (module notes) on every node of ``grid``.

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
        ``log_ratio`` of shape (y, zeta, t, s) and metadata.
    """
    apertures = PSI_MAP.value(grid.axes()[3].nodes())
    apertures[0] = 0.0
    log_ratio = np.empty(grid.shape)
    tasks = [(grid, float(psi)) for psi in apertures]
    start = time.perf_counter()
    workers = workers or os.cpu_count() or 1
    pool = ProcessPoolExecutor(max_workers=workers) if workers > 1 else None
    results = pool.map(_psi_slice, tasks) if pool else map(_psi_slice, tasks)
    for k, values in enumerate(results):
        log_ratio[..., k] = values
        if progress is not None:
            progress(k + 1, len(tasks))
    if pool:
        pool.shutdown()
    return {
        "log_ratio": log_ratio,
        "shape": np.array(grid.shape),
        "rtol": np.array(1e-9),
        "divisor_order": np.array(DIVISOR_ORDER),
        "y_offset": np.array(Y_OFFSET),
        "y_slope": np.array(Y_SLOPE),
        "coordinates_version": np.array(COORDINATES_VERSION),
        "psi_scale_deg": np.array(PSI_SCALE_DEG),
        "build_seconds": np.array(time.perf_counter() - start),
    }


#: File name (without ``.npz``) of the pitted table.
PIT_TABLE_NAME = "pitted"

_COORDINATE_CONSTANTS = {
    "y_offset": Y_OFFSET, "psi_scale_deg": PSI_SCALE_DEG, "divisor_order": DIVISOR_ORDER,
    "y_slope": Y_SLOPE, "coordinates_version": COORDINATES_VERSION,
}


class PittedTable:
    """The tabulated ratio log(F1 / G) and the evaluation of F1 from it.

    Parameters
    ----------
    arrays : dict
        ``log_ratio`` (shape (y, zeta, t, s)) and the constants it was built with.
    """

    def __init__(self, arrays: dict[str, np.ndarray]):
        check_constants(arrays, _COORDINATE_CONSTANTS, PIT_TABLE_NAME)
        self.lookup = LogTable((arrays["log_ratio"],))
        self.grid = self.lookup.grid

    def prepare(self, theta_i, phi_i, theta_r, phi_r) -> Callable[[float], np.ndarray]:
        """Geometry [rad] -> function of psi [deg] returning F1 [1/sr].

        The interpolated ratio is combined with the divisor G computed at the geometry and
        aperture of the call (about 2.5e5 geometries/s; kept per aperture by the model).
        """
        ti, pi_, tr, pr = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))
        shape = ti.shape
        logs = self.lookup.prepare(ti, pi_, tr, pr)
        ti, tr, dphi = ti.ravel(), tr.ravel(), (pr - pi_).ravel()

        def factor(psi: float) -> np.ndarray:
            (values,) = logs(float(PSI_MAP.coordinate(psi)))
            return (np.exp(values) * coarse_factor(ti, tr, dphi, float(psi))).reshape(shape)

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
