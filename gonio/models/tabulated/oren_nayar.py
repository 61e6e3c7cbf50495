"""``oren-nayar-tabulated``: the exact V-cavity model read from a precomputed table.

The exact model (``oren-nayar-exact``) is ``rho f1 + rho^2 f2`` with f1, f2 functions of
the geometry and sigma only, but each evaluation integrates over facet slopes and
azimuths (a few hundred evaluations per second).  Here f1 and f2 come from a table of
their logarithms on a regular grid in the smooth coordinates of :mod:`.coordinates`,
computed once by the exact method (:mod:`.oren_nayar_table`, ``gonio tables build``),
and tensor-product cubic interpolation (:mod:`.interpolation`).

Evaluation (one implementation, ``prepare``, see :mod:`.lookup`): the geometry's table
coordinates and cubic stencils are computed once; a one-off call reduces the table along
sigma and interpolates in the three geometry coordinates; repeated calls at the same
geometries (fitting, :meth:`Model.at`) keep the geometry interpolation of the roughness
nodes they need and only combine four stored columns per call.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from .._core import Model, Param, register
from .coordinates import COORDINATES_VERSION, SIGMA_SCALE_DEG, Y_OFFSET, Y_SLOPE, sigma_coordinate
from .lookup import LogTable
from .oren_nayar_table import F2_FLOOR
from .store import check_constants, load

__all__ = ["TABLE_NAME", "OrenNayarTable", "tabulated_components", "OREN_NAYAR_TABULATED"]

#: File name (without ``.npz``) of the Oren-Nayar table.
TABLE_NAME = "oren-nayar"

#: Constants a table must have been built with to be read by this module.
_COORDINATE_CONSTANTS = {
    "y_offset": Y_OFFSET, "sigma_scale_deg": SIGMA_SCALE_DEG, "f2_floor": F2_FLOOR,
    "y_slope": Y_SLOPE, "coordinates_version": COORDINATES_VERSION,
}


class OrenNayarTable:
    """The tabulated logarithms of the exact components and their evaluation.

    Parameters
    ----------
    arrays : dict
        ``log_f1``, ``log_f2`` (shape (y, zeta, t, s)) and the constants of
        ``_COORDINATE_CONSTANTS``, as returned by
        :func:`~.oren_nayar_table.build_oren_nayar_table` or read by :func:`.store.load`.
    """

    def __init__(self, arrays: dict[str, np.ndarray]):
        check_constants(arrays, _COORDINATE_CONSTANTS, TABLE_NAME)
        self.lookup = LogTable((arrays["log_f1"], arrays["log_f2"]))
        self.grid = self.lookup.grid

    def prepare(self, theta_i, phi_i, theta_r, phi_r) -> Callable[[float], tuple[np.ndarray, np.ndarray]]:
        """Geometry [rad] -> function of sigma [deg] returning (f1, f2) [1/sr]."""
        shape = np.broadcast_shapes(*(np.shape(a) for a in (theta_i, phi_i, theta_r, phi_r)))
        logs = self.lookup.prepare(theta_i, phi_i, theta_r, phi_r)

        def components(sigma: float) -> tuple[np.ndarray, np.ndarray]:
            if sigma == 0.0:  # footnote 10: Lambert, exactly (as the exact model does)
                return np.full(shape, 1.0 / math.pi), np.zeros(shape)
            log_f1, log_f2 = logs(float(sigma_coordinate(sigma)))
            f1, f2 = _from_logs(log_f1, log_f2)
            return f1.reshape(shape), f2.reshape(shape)

        def rows(sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """(f1, f2) for every sigma of a 1-D array (W,): shape (W,) + the geometry's."""
            sigma = np.asarray(sigma, float).reshape(-1)
            log_f1, log_f2 = logs.rows(sigma_coordinate(sigma))
            f1, f2 = _from_logs(log_f1, log_f2)
            smooth = sigma == 0.0  # footnote 10: Lambert, exactly
            f1[smooth], f2[smooth] = 1.0 / math.pi, 0.0
            return f1.reshape(sigma.shape + shape), f2.reshape(sigma.shape + shape)

        components.rows = rows  # type: ignore[attr-defined]
        return components


def _from_logs(log_f1: np.ndarray, log_f2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """f1, f2 [1/sr] from the tabulated logs of pi f1 and pi (f2 + F2_FLOOR f1)."""
    f1, f2 = np.exp(log_f1), np.exp(log_f2)
    # the floor is removed exactly; rounding can leave -1e-20 where f2 = 0
    f2 -= F2_FLOOR * f1
    np.maximum(f2, 0.0, out=f2)
    f1 *= 1.0 / math.pi
    f2 *= 1.0 / math.pi
    return f1, f2


_TABLE: list[OrenNayarTable] = []


def table() -> OrenNayarTable:
    """The Oren-Nayar table (loaded on first use, then kept)."""
    if not _TABLE:
        _TABLE.append(OrenNayarTable(load(TABLE_NAME)))
    return _TABLE[0]


def reset_table() -> None:
    """Forget the loaded table (after ``gonio tables build`` or ``clear``)."""
    _TABLE.clear()
    load.cache_clear()


def tabulated_components(theta_i, phi_i, theta_r, phi_r, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Tabulated direct and interreflected parts: BRDF = rho f1 + rho^2 f2.

    Parameters
    ----------
    theta_i, phi_i : array_like
        Source direction [deg], theta_i in [0, 90].
    theta_r, phi_r : array_like
        Viewing direction [deg], theta_r in [0, 90].
    sigma : float
        Standard deviation of the facet slope [deg], in [0, 90].

    Returns
    -------
    f1, f2 : numpy.ndarray
        [1/sr], broadcast shape of the angles; the interpolated counterparts of
        :func:`gonio.models.oren_nayar.exact.exact_components`.

    Notes
    -----
    Oren & Nayar (1995) eq 8 and 32 with the exact GAF (eq 15) and interreflection
    (eq 22-24), as computed by ``oren-nayar-exact`` at the table nodes; accuracy in
    docs/tabulated.md.

    References
    ----------
    M. Oren, S. K. Nayar, IJCV 14(3), 1995.

    Examples
    --------
    >>> f1, f2 = tabulated_components(30.0, 0.0, 30.0, 180.0, sigma=0.0)   # Lambert
    >>> round(float(f1 * np.pi), 12), float(f2)
    (1.0, 0.0)
    """
    if not (0.0 <= float(sigma) <= 90.0):
        raise ValueError(f"sigma = {float(sigma):g} deg is outside its valid range [0, 90] deg")
    angles = [np.radians(np.asarray(a, float)) for a in np.broadcast_arrays(theta_i, phi_i, theta_r, phi_r)]
    return table().prepare(*angles)(float(sigma))


def _prepare(theta_i, phi_i, theta_r, phi_r):
    components = table().prepare(theta_i, phi_i, theta_r, phi_r)
    shape = np.broadcast_shapes(*(np.shape(a) for a in (theta_i, phi_i, theta_r, phi_r)))

    def evaluate(rho, sigma) -> np.ndarray:
        """rho f1 + rho^2 f2; parameters scalars or arrays broadcasting against the
        geometry (the sampler's walkers as (W, 1) columns take one call for all)."""
        if np.ndim(sigma) == 0:
            f1, f2 = components(float(sigma))
        else:
            f1, f2 = _components_of_array(components, np.asarray(sigma, float), shape)
        if np.ndim(rho) == 0 and f1.shape == shape:
            f1 *= rho  # fresh arrays from components(): updated in place
            f2 *= rho * rho
            f1 += f2
            return f1
        return rho * f1 + rho * rho * f2

    return evaluate


def _components_of_array(components, sigma: np.ndarray, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(f1, f2) for an array of sigma broadcasting against the geometry's ``shape``: one
    row per leading entry when sigma is constant along the geometry (``components.rows``),
    else one evaluation per distinct sigma."""
    full = np.broadcast_shapes(sigma.shape, shape)
    trailing = sigma.shape[sigma.ndim - len(shape):] if len(shape) else ()
    if sigma.ndim >= len(shape) and all(n == 1 for n in trailing):
        lead = sigma.shape[:sigma.ndim - len(shape)]
        f1, f2 = components.rows(sigma.reshape(-1))
        return f1.reshape(lead + shape), f2.reshape(lead + shape)
    sigma = np.broadcast_to(sigma, full)
    f1, f2 = np.empty(full), np.empty(full)
    for value in np.unique(sigma):
        chosen = sigma == value
        one = components(float(value))
        f1[chosen] = np.broadcast_to(one[0], full)[chosen]
        f2[chosen] = np.broadcast_to(one[1], full)[chosen]
    return f1, f2


OREN_NAYAR_TABULATED = register(
    Model(
        name="oren-nayar-tabulated",
        params=(
            Param("rho", "-", 0.8, (0.0, 1.0), "albedo of the Lambertian facets"),
            Param("sigma", "deg", 20.0, (0.0, 90.0),
                  "roughness: standard deviation of the facet slope angle (Gaussian, eq 32)"),
        ),
        reference=(
            "Oren & Nayar 1995, eq 8 and 32 with the exact GAF (eq 15) and interreflection "
            "(eq 22-24): oren-nayar-exact tabulated on a smooth grid, cubic interpolation"
        ),
        description="exact V-cavity rough diffuse model from a precomputed table (fast)",
        prepare=_prepare,
        broadcasts_params=True,
    )
)
