"""Radiometric relations between BRDF, radiance, irradiance and reflectance.

References
----------
D. Forsyth, J. Ponce, *Computer Vision: A Modern Approach*, ch. 2 (draft), sections
2.2.2 (BRDF, its energy bound), 2.3.1 (radiosity of a constant-radiance surface),
2.3.2 (directional-hemispheric reflectance) and 2.3.3 (Lambertian albedo);
M. Oren, S. K. Nayar (1995), section 2 (L_r = f_r E_0 cos theta_i for a distant source).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike

from . import models as _models
from .models._core import Model

__all__ = [
    "radiance_from_brdf",
    "brdf_from_radiance",
    "lambertian_radiance",
    "radiosity_of_constant_radiance",
    "directional_hemispherical_reflectance",
    "reciprocity_violation",
    "energy_bound_violation",
    "Violation",
]


def radiance_from_brdf(brdf: ArrayLike, irradiance: ArrayLike, theta_i: ArrayLike) -> np.ndarray:
    """Reflected radiance of a surface lit by a distant source.

    Parameters
    ----------
    brdf : array_like
        BRDF f_r [1/sr].
    irradiance : array_like
        Irradiance E_0 of the source measured perpendicular to its direction [W/m^2].
    theta_i : array_like
        Source polar angle [deg].

    Returns
    -------
    numpy.ndarray
        L_r = f_r E_0 cos(theta_i) [W/(m^2 sr)] (Forsyth & Ponce section 2.2.2;
        Oren & Nayar section 2).
    """
    return np.asarray(brdf, float) * np.asarray(irradiance, float) * np.cos(np.radians(theta_i))


def brdf_from_radiance(radiance: ArrayLike, irradiance: ArrayLike, theta_i: ArrayLike) -> np.ndarray:
    """BRDF [1/sr] from measured radiance: f_r = L_r / (E_0 cos theta_i).

    Parameters
    ----------
    radiance : array_like
        Reflected radiance [W/(m^2 sr)].
    irradiance : array_like
        Source irradiance perpendicular to its direction [W/m^2].
    theta_i : array_like
        Source polar angle [deg]; must be below 90 deg (no irradiance at grazing).

    Raises
    ------
    ValueError
        If any theta_i is at or beyond 90 deg, where the surface receives no irradiance.
    """
    theta = np.asarray(theta_i, float)
    if np.any(theta >= 90.0):
        raise ValueError("theta_i must be below 90 deg to recover a BRDF from radiance "
                         "(the surface receives no irradiance at or beyond grazing incidence)")
    return np.asarray(radiance, float) / (np.asarray(irradiance, float) * np.cos(np.radians(theta)))


def lambertian_radiance(rho: ArrayLike, irradiance: ArrayLike, theta_i: ArrayLike) -> np.ndarray:
    """Radiance of a Lambertian surface of albedo rho: (rho / pi) E_0 cos theta_i [W/(m^2 sr)]."""
    return radiance_from_brdf(np.asarray(rho, float) / np.pi, irradiance, theta_i)


def radiosity_of_constant_radiance(radiance: ArrayLike) -> np.ndarray:
    """Radiosity B = pi L of a surface whose radiance L is the same in every direction.

    Forsyth & Ponce section 2.3.1.  Units: W/m^2 from W/(m^2 sr).
    """
    return np.pi * np.asarray(radiance, float)


def _gauss_panels(edges: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on consecutive panels between ``edges``."""
    x, w = np.polynomial.legendre.leggauss(order)
    lo, hi = edges[:-1, None], edges[1:, None]
    half = 0.5 * (hi - lo)
    nodes = (lo + half * (x + 1.0)).ravel()
    weights = (half * w).ravel()
    return nodes, weights


def _model_callable(model: str | Model | Callable[..., np.ndarray], params: dict[str, Any]):
    if isinstance(model, str):
        model = _models.get(model)
    if isinstance(model, Model):
        model.resolve(params)  # fail early with the parameter's name
    return lambda ti, pi_, tr, pr: np.asarray(model(ti, pi_, tr, pr, **params), float)


def directional_hemispherical_reflectance(
    model: str | Model | Callable[..., np.ndarray],
    theta_i: ArrayLike,
    phi_i: float = 0.0,
    order: int = 24,
    **params: Any,
) -> np.ndarray:
    """Directional-hemispherical reflectance rho_dh(theta_i) by quadrature [-].

    rho_dh(theta_i) = integral over the exit hemisphere of f_r cos(theta_r) d omega_r
    (Forsyth & Ponce section 2.3.2).

    Parameters
    ----------
    model : str, Model or callable
        A registered model name, a :class:`~gonio.models.Model`, or any
        ``f(theta_i, phi_i, theta_r, phi_r)`` in degrees returning [1/sr].
    theta_i : array_like
        Source polar angles [deg].
    phi_i : float, optional
        Source azimuth [deg].
    order : int, optional
        Gauss-Legendre nodes per panel.  The exit hemisphere is split into panels at
        theta_r = theta_i and at phi_r - phi_i = -180, -90, 0, 90, 180 deg, the places
        where the Oren-Nayar family has kinks (max(alpha, beta), max(0, cos dphi)), so
        the rule converges quickly for them.
    **params
        Model parameters.

    Returns
    -------
    numpy.ndarray
        rho_dh for each theta_i [-].

    Notes
    -----
    Accuracy: exact (to rounding) for Lambert; for the Oren-Nayar family the default
    order reaches about 1e-9 relative (tests/test_radiometry.py checks it against order
    48).  Narrow specular lobes (Phong exponent >~ 100, Torrance-Sparrow sigma < 5 deg)
    need a larger ``order``: the error is measured in docs/models.md.

    Examples
    --------
    >>> round(float(directional_hemispherical_reflectance("lambert", 40.0, rho=0.3)), 12)
    0.3
    """
    if int(order) < 1:
        raise ValueError(f"order = {order!r} must be a positive integer (Gauss nodes per panel)")
    f = _model_callable(model, params)
    thetas = np.atleast_1d(np.asarray(theta_i, float))
    out = np.empty(thetas.shape)
    phi_edges = phi_i + np.array([-180.0, -90.0, 0.0, 90.0, 180.0])
    phi_nodes, phi_weights = _gauss_panels(phi_edges, int(order))
    for index, ti in np.ndenumerate(thetas):
        if np.isnan(ti):
            out[index] = np.nan
            continue
        theta_edges = np.unique(np.clip([0.0, ti, 90.0], 0.0, 90.0))
        t_nodes, t_weights = _gauss_panels(theta_edges, int(order))
        tr, pr = np.meshgrid(t_nodes, phi_nodes, indexing="ij")
        values = f(ti, phi_i, tr, pr)
        t_rad = np.radians(t_nodes)
        jacobian = np.cos(t_rad) * np.sin(t_rad)  # cos(theta_r) d omega = cos sin dtheta dphi
        weights = np.outer(np.radians(t_weights) * jacobian, np.radians(phi_weights))
        out[index] = np.sum(values * weights)
    return out.reshape(np.shape(theta_i)) if np.ndim(theta_i) else out[0]


@dataclass(frozen=True)
class Violation:
    """Worst violation of a physical law over a set of geometries.

    Attributes
    ----------
    worst : float
        Largest violation found (0 when the law holds everywhere) [relative, -].
    geometry : tuple of float
        (theta_i, phi_i, theta_r, phi_r) [deg] where it occurred (or theta_i only, for
        the energy bound), NaN-filled when nothing was violated.
    values : tuple of float
        The two numbers compared there.
    """

    worst: float
    geometry: tuple[float, ...]
    values: tuple[float, float]

    def __bool__(self) -> bool:  # truthy when something is violated
        return self.worst > 0.0


def reciprocity_violation(
    model: str | Model | Callable[..., np.ndarray],
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_r: ArrayLike,
    phi_r: ArrayLike,
    **params: Any,
) -> Violation:
    """Worst relative asymmetry |f(i, r) - f(r, i)| / max(|f|) over the given geometries.

    Helmholtz reciprocity (Forsyth & Ponce section 2.2.2) says the BRDF is symmetric in
    the source and viewing directions.  The relative difference is taken against the
    larger of the two values (geometries where both are 0 count as 0).
    """
    f = _model_callable(model, params)
    ti, pi_, tr, pr = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))
    forward, backward = f(ti, pi_, tr, pr), f(tr, pr, ti, pi_)
    scale = np.maximum(np.abs(forward), np.abs(backward))
    with np.errstate(invalid="ignore", divide="ignore"):
        relative = np.where(scale > 0, np.abs(forward - backward) / scale, 0.0)
    relative = np.nan_to_num(relative, nan=0.0)
    k = int(np.argmax(relative)) if relative.size else 0
    if relative.size == 0 or relative.flat[k] == 0.0:
        return Violation(0.0, (np.nan,) * 4, (np.nan, np.nan))
    geometry = tuple(float(a.flat[k]) for a in (ti, pi_, tr, pr))
    return Violation(float(relative.flat[k]), geometry, (float(forward.flat[k]), float(backward.flat[k])))


def energy_bound_violation(
    model: str | Model | Callable[..., np.ndarray],
    theta_i: ArrayLike = np.linspace(0.0, 89.0, 90),
    order: int = 24,
    **params: Any,
) -> Violation:
    """Worst excess of rho_dh(theta_i) over 1 (Forsyth & Ponce section 2.2.2).

    A passive surface cannot reflect more than it receives: rho_dh <= 1 for every
    incidence.  Returns the largest ``rho_dh - 1`` found (0 if none is positive) and the
    incidence where it occurs; ``values`` holds (rho_dh, 1).
    """
    rho = directional_hemispherical_reflectance(model, theta_i, order=order, **params)
    rho = np.atleast_1d(rho)
    thetas = np.atleast_1d(np.asarray(theta_i, float))
    k = int(np.nanargmax(rho))
    excess = float(rho[k] - 1.0)
    if excess <= 0.0:
        return Violation(0.0, (float(thetas[k]),), (float(rho[k]), 1.0))
    return Violation(excess, (float(thetas[k]),), (float(rho[k]), 1.0))
