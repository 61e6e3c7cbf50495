"""Table coordinates in which the exact Oren-Nayar components are smooth.

The exact V-cavity components f1, f2 (``oren-nayar-exact``) are not smooth in the plain
angles (theta_i, theta_r, phi_r - phi_i, sigma): interpolating them there loses the
accuracy a cubic rule should have.  This module maps a geometry and a roughness onto four
coordinates, each in a fixed interval, in which they are (numerically checked: the
accuracy study of docs/tabulated.md):

``y``  = log(z_beta + Y_OFFSET) + Y_SLOPE z_beta,  z_beta = pi/2 - beta  [rad],
    beta = min(theta_i, theta_r)
    Near grazing the BRDF changes on the angular scale sigma (shadowing and masking
    switch on where tan(theta) tan(theta_a) = 1, Oren & Nayar eq 39), and it follows
    power laws of cos(beta) (growing like 1/cos(beta) backwards, vanishing like cos(beta)
    forwards).  A logarithmic distance from the horizon resolves every such scale with
    the same number of nodes and makes the power laws linear; Y_OFFSET sets the smallest
    resolved distance (directions closer to the horizon than a few Y_OFFSET are
    interpolated between the horizon itself and that distance).  The linear term keeps
    the nodes a few degrees apart near the normal, where a rough surface's BRDF still
    changes by tens of percent (a pure logarithm would space them 20 deg apart there).
``zeta`` = 1 - sqrt(1 - (r + l) / 2) in [0, 1],  r = z_alpha / z_beta,
    l = (y(z_alpha) - y(0)) / (y(z_beta) - y(0)),  alpha = max(theta_i, theta_r), y(z) the
    map of the y coordinate.  Reciprocity (the model is symmetric in source and viewer)
    halves the domain to alpha >= beta; the kink of the components at theta_i = theta_r
    becomes the edge zeta = 1 of the table.  The linear part r keeps nodes close to that
    edge (the backward peak is sharpest there); the logarithmic part l resolves the
    grazing boundary layer of the upper direction (width ~ sigma, like beta's) when
    alpha -> 90 deg.  Near the grazing corner alpha = beta = 90 deg both parts are
    functions of the ratio of the two distances from the horizon, on which the
    components depend there.  The outer square root crowds the nodes towards the edge
    zeta = 1 (alpha - beta ~ (1 - zeta)^2 there): near grazing the retro-reflection peak
    is a cone whose slope differs in and out of the plane (elevation differences matter
    far more than azimuth differences there), so the components are not smooth at the
    corner zeta = 1, t = 0, and the cells next to it must be small in alpha - beta
    (without it the error there reached 3e-3; docs/tabulated.md).
``t``  = (sqrt(p) + 1 - (1 - p)^(1/4)) / 2,  p = (g - (alpha - beta)) / (2 beta)
    in [0, 1],  g the phase angle between the two directions.  The V-cavity model has a
    cone-shaped peak at the retro-reflection direction (g = 0): linear in g, not smooth
    in phi_r - phi_i.  p runs over the phase angles that are possible for the given polar
    angles (from alpha - beta at dphi = 0 to alpha + beta at dphi = 180 deg) and is linear
    in g; as beta -> 0 it tends to (1 - cos dphi)/2.  At the backward end
    t = sqrt(p)/2 + O(p), so p is a polynomial in t there and any smooth function of p
    (the cone) is smooth in t, with the nodes crowded towards the backward peak.  At the
    forward end 1 - t = (1 - p)^(1/4)/2 + O(1 - p), so sqrt(1 - p) is a polynomial in t:
    away from grazing p is quadratic in 180 deg - dphi and the components are smooth in
    dphi, while near grazing (alpha + beta -> 180 deg) g becomes linear in 180 deg - dphi
    inside a layer of width ~ z_alpha + z_beta and the components grow like
    |180 deg - dphi| there; the fourth root crowds the nodes into that layer (with a
    square root in its place the error there reached 2.7e-3).  Measured on the same node
    budget: t = p, 1 - sqrt(1 - p), (2/pi) arcsin(sqrt(p)), their average, and
    (sqrt(p) + 1 - sqrt(1 - p))/2; docs/tabulated.md.
``s``  = asinh(p / scale) / asinh(p_max / scale) in [0, 1] for the model parameter p
    (the roughness sigma of Oren-Nayar), see
    :class:`ParameterMap`.  Linear in p for small p and logarithmic for large p: the
    grazing behaviour changes on the angular scale p (the similarity variable is
    z_beta / p), which a logarithmic axis resolves uniformly.

The tabulated quantities are logarithms of the components (:mod:`.oren_nayar_table`).

References
----------
M. Oren, S. K. Nayar, IJCV 14(3), 1995: eq 8, 32 (the model tabulated), eq 39 (onset of
shadowing and masking), Figure 10 (the backward peak).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = [
    "COORDINATES_VERSION",
    "Y_OFFSET",
    "Y_SLOPE",
    "y_coordinate",
    "z_from_y",
    "SIGMA_SCALE_DEG",
    "SIGMA_MAX_DEG",
    "geometry_coordinates",
    "geometry_from_coordinates",
    "ParameterMap",
    "SIGMA_MAP",
    "sigma_coordinate",
    "sigma_from_coordinate",
]

#: Smallest resolved angular distance from the horizon [rad] (about 0.0006 deg).
Y_OFFSET = 1.0e-5
#: Version of the coordinate maps (stored in tables; a table of another version is refused).
COORDINATES_VERSION = 6
#: Weight of the linear term of the y coordinate [1/rad].
Y_SLOPE = 2.0
#: Roughness [deg] where the sigma coordinate turns from linear to logarithmic.
SIGMA_SCALE_DEG = 0.5
#: Largest roughness [deg] (the physical bound of ``sigma``).
SIGMA_MAX_DEG = 90.0

_HALF_PI = 0.5 * math.pi


def y_coordinate(z_beta: np.ndarray) -> np.ndarray:
    """The y coordinate of a distance from the horizon ``z_beta`` [rad]."""
    return np.log(z_beta + Y_OFFSET) + Y_SLOPE * z_beta


_Y_FLOOR = float(y_coordinate(0.0))


def z_from_y(y: np.ndarray) -> np.ndarray:
    """Inverse of :func:`y_coordinate` (bisection then Newton; used to place nodes)."""
    y = np.asarray(y, float)
    lo, hi = np.zeros(y.shape), np.full(y.shape, _HALF_PI)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        above = y_coordinate(mid) > y
        hi, lo = np.where(above, mid, hi), np.where(above, lo, mid)
    z = 0.5 * (lo + hi)
    for _ in range(3):
        z = z - (y_coordinate(z) - y) / (1.0 / (z + Y_OFFSET) + Y_SLOPE)
    return np.clip(z, 0.0, _HALF_PI)


def _zeta(z_alpha: np.ndarray, z_beta: np.ndarray) -> np.ndarray:
    """The zeta coordinate (module notes) of z_alpha <= z_beta [rad]; 1 where z_beta = 0."""
    positive = z_beta > 0.0
    # np.where on a safe denominator, not np.divide(where=...): same values, ~5x faster
    safe = np.where(positive, z_beta, 1.0)
    ratio = z_alpha / safe
    logratio = (y_coordinate(z_alpha) - _Y_FLOOR) / (y_coordinate(safe) - _Y_FLOOR)
    return np.where(positive, 1.0 - np.sqrt(np.maximum(1.0 - 0.5 * (ratio + logratio), 0.0)), 1.0)


def _z_alpha_from_zeta(zeta: np.ndarray, z_beta: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_zeta` in z_alpha (bisection; used to place nodes)."""
    lo, hi = np.zeros(np.shape(zeta)), np.broadcast_to(z_beta, np.shape(zeta)).astype(float)
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        above = _zeta(mid, z_beta) > zeta
        hi, lo = np.where(above, mid, hi), np.where(above, lo, mid)
    return 0.5 * (lo + hi)


def _t_from_p(p: np.ndarray) -> np.ndarray:
    """The t coordinate (module notes) of p in [0, 1]."""
    return 0.5 * (np.sqrt(p) + 1.0 - np.sqrt(np.sqrt(np.maximum(1.0 - p, 0.0))))


def _p_from_t(t: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_t_from_p` (bisection; used to place nodes)."""
    lo, hi = np.zeros(np.shape(t)), np.ones(np.shape(t))
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        above = _t_from_p(mid) > t
        hi, lo = np.where(above, mid, hi), np.where(above, lo, mid)
    return 0.5 * (lo + hi)


class ParameterMap:
    """The table coordinate s = asinh(p / scale) / asinh(maximum / scale) of a parameter.

    Parameters
    ----------
    scale : float
        Value [deg] where the coordinate turns from linear to logarithmic.
    maximum : float
        Largest value [deg] (s = 1).
    """

    def __init__(self, scale: float, maximum: float):
        self.scale, self.maximum = float(scale), float(maximum)
        self._norm = math.asinh(self.maximum / self.scale)

    def coordinate(self, value_deg: float | np.ndarray) -> np.ndarray:
        """s in [0, 1] of a parameter value [deg]."""
        return np.arcsinh(np.asarray(value_deg, float) / self.scale) / self._norm

    def value(self, s: float | np.ndarray) -> np.ndarray:
        """Inverse: parameter value [deg] at coordinate ``s``."""
        return self.scale * np.sinh(np.asarray(s, float) * self._norm)


#: The roughness coordinate of the Oren-Nayar table.
SIGMA_MAP = ParameterMap(SIGMA_SCALE_DEG, SIGMA_MAX_DEG)


def sigma_coordinate(sigma_deg: float | np.ndarray) -> np.ndarray:
    """The table coordinate s in [0, 1] of a roughness ``sigma`` [deg]."""
    return SIGMA_MAP.coordinate(sigma_deg)


def sigma_from_coordinate(s: float | np.ndarray) -> np.ndarray:
    """Inverse of :func:`sigma_coordinate`: roughness [deg] at table coordinate ``s``."""
    return SIGMA_MAP.value(s)


def geometry_coordinates(
    theta_i: np.ndarray, theta_r: np.ndarray, delta_phi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Table coordinates (y, zeta, t) and z_beta of geometries given in radians.

    Parameters
    ----------
    theta_i, theta_r : numpy.ndarray
        Polar angles [rad] in [0, pi/2].
    delta_phi : numpy.ndarray
        Azimuth difference phi_r - phi_i [rad] (any value; only its cosine matters).

    Returns
    -------
    y, zeta, t, z_beta : numpy.ndarray
        Coordinates of the module notes and the distance of the lower direction from the
        horizon [rad], broadcast together.
    """
    theta_i, theta_r, delta_phi = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, theta_r, delta_phi)))
    alpha = np.asarray(np.maximum(theta_i, theta_r))
    beta = np.asarray(np.minimum(theta_i, theta_r))
    z_beta = np.maximum(_HALF_PI - beta, 0.0)
    z_alpha = np.maximum(_HALF_PI - alpha, 0.0)
    y = y_coordinate(z_beta)
    zeta = _zeta(z_alpha, z_beta)
    # phase angle by the haversine formula (accurate near the retro-reflection direction),
    # with sin(alpha) sin(beta) = sin^2((alpha + beta)/2) - sin^2((alpha - beta)/2)
    limit = np.sin(0.5 * delta_phi) ** 2  # (1 - cos dphi)/2, also the beta -> 0 limit of p
    half = np.sin(0.5 * (alpha - beta)) ** 2 * (1.0 - limit) + np.sin(0.5 * (alpha + beta)) ** 2 * limit
    phase = 2.0 * np.arcsin(np.sqrt(np.clip(half, 0.0, 1.0)))
    away = beta > 1e-6
    p = np.where(away, (phase - (alpha - beta)) / np.where(away, 2.0 * beta, 1.0), limit)
    return y, zeta, _t_from_p(np.clip(p, 0.0, 1.0)), z_beta


def geometry_from_coordinates(
    y: np.ndarray, zeta: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse map: (theta_i, theta_r, delta_phi) [rad] with theta_i = alpha >= theta_r."""
    y, zeta, t = np.broadcast_arrays(*(np.asarray(a, float) for a in (y, zeta, t)))
    z_beta = np.asarray(z_from_y(y))
    beta = _HALF_PI - z_beta
    alpha = _HALF_PI - _z_alpha_from_zeta(zeta, z_beta)
    p = _p_from_t(t)
    phase = (alpha - beta) + 2.0 * beta * p
    denominator = np.sin(alpha) * np.sin(beta)
    cos_dphi = np.divide(
        np.cos(phase) - np.cos(alpha) * np.cos(beta), denominator,
        out=np.array(np.broadcast_to(1.0 - 2.0 * p, beta.shape)), where=denominator > 1e-12,
    )
    return alpha, beta, np.arccos(np.clip(cos_dphi, -1.0, 1.0))
