"""Oren & Nayar's sigma in the roughness conventions renderers use.

A measured or fitted Oren-Nayar roughness sigma (the standard deviation of the facet slope
angle [deg], gonio's ``sigma``) is not the number a renderer asks for:

Mitsuba 0.6 ``roughdiffuse``, parameter ``alpha``
    The RMS slope of a Beckmann-style microfacet surface.  The plugin converts it with
    sigma [rad] = alpha / sqrt(2) and then evaluates Oren & Nayar's functional
    approximation eq 33-35 (``useFastApprox = false``, the default: gonio's
    ``oren-nayar``) or the qualitative model eq 36 (``useFastApprox = true``: gonio's
    ``oren-nayar-qualitative``) with that sigma (mitsuba-renderer/mitsuba,
    src/bsdfs/roughdiffuse.cpp: "Conversion from Beckmann-style RMS roughness to
    Oren-Nayar-style slope-area variance", factor 1/sqrt(2)).  The factor is that of a
    one-dimensional slope: an isotropic Gaussian of slopes with mean square alpha^2 has
    variance alpha^2/2 along each direction, and a V-cavity tilts its facets along one.
    The mapping alpha = sqrt(2) sigma [rad] is therefore exact for the formulas: with it,
    Mitsuba renders gonio's ``oren-nayar`` (:func:`sigma_to_mitsuba_alpha`).
EON / OpenPBR ``base_diffuse_roughness`` / Fujii's sigma', parameter ``r`` in [0, 1]
    A mixing ratio of two lobes (:mod:`gonio.models.fujii`, :mod:`gonio.models.eon`), in
    no closed-form relation to sigma: :func:`sigma_to_eon_r` and :func:`sigma_to_fujii_r`
    *fit* it, and :func:`match_roughness` says how well the fit reproduces the surface.

The fit: the renderer parameter (and, on request, its albedo) minimising the
cosine-weighted squared BRDF difference

    E = sum w (f_renderer - f_reference)^2 / sum w f_reference^2,
    w = cos(theta_i) cos(theta_r) d omega_i d omega_r,

over the pair of hemispheres (:func:`match_geometry`: Gauss-Legendre nodes in cos(theta)
for each direction and in the azimuth difference on [0, 90] and [90, 180] deg).  The
weight is the one an image integrates: light arriving and leaving near grazing counts
with its projected solid angle.  sqrt(E) is the reported ``rms``; ``max_rel`` is the
largest |f_renderer / f_reference - 1| at nodes with both polar angles <= 80 deg (the
range of a gonioreflectometer), ``max_rel_all`` over all nodes.

References
----------
W. Jakob, Mitsuba renderer 0.6, plugin ``roughdiffuse`` (src/bsdfs/roughdiffuse.cpp and
its documentation block).
J. Portsmouth, P. Kutz, S. Hill, "EON: A practical energy-preserving rough diffuse BRDF",
JCGT 14(1), 2025.
Y. Fujii, "A tiny improvement of Oren-Nayar reflectance model", 2012.
M. Oren, S. K. Nayar, IJCV 14(3), 1995, eq 33-36.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from ._core import get

__all__ = [
    "MITSUBA_ALPHA_PER_SIGMA",
    "RENDERERS",
    "Renderer",
    "RoughnessMatch",
    "match_geometry",
    "match_roughness",
    "match_values",
    "mapping_error",
    "mitsuba_alpha_to_sigma",
    "sigma_to_eon_r",
    "sigma_to_fujii_r",
    "sigma_to_mitsuba_alpha",
]

#: alpha = sqrt(2) sigma [rad]: Mitsuba's roughdiffuse divides alpha by sqrt(2).
MITSUBA_ALPHA_PER_SIGMA = math.sqrt(2.0)
#: Largest alpha whose sigma = alpha/sqrt(2) [rad] is in gonio's range (90 deg).
_MITSUBA_ALPHA_MAX = MITSUBA_ALPHA_PER_SIGMA * math.pi / 2.0
#: Polar angles [deg] up to which ``max_rel`` is taken.
MAX_REL_THETA = 80.0


def sigma_to_mitsuba_alpha(sigma: ArrayLike) -> np.ndarray:
    """Mitsuba 0.6 ``roughdiffuse`` alpha for an Oren-Nayar sigma [-].

    Parameters
    ----------
    sigma : array_like
        Oren-Nayar roughness, standard deviation of the facet slope angle [deg].

    Returns
    -------
    numpy.ndarray
        alpha = sqrt(2) sigma [rad] (RMS slope in Mitsuba's convention).  With it Mitsuba
        evaluates exactly gonio's ``oren-nayar`` (``useFastApprox = false``) or
        ``oren-nayar-qualitative`` (``useFastApprox = true``) at this sigma.

    Notes
    -----
    Mitsuba 0.6, src/bsdfs/roughdiffuse.cpp, ``eval``: sigma = alpha / sqrt(2).

    Examples
    --------
    >>> round(float(sigma_to_mitsuba_alpha(30.0)), 4)
    0.7405
    """
    return MITSUBA_ALPHA_PER_SIGMA * np.radians(np.asarray(sigma, float))


def mitsuba_alpha_to_sigma(alpha: ArrayLike) -> np.ndarray:
    """Oren-Nayar sigma [deg] that Mitsuba 0.6 ``roughdiffuse`` uses for ``alpha``.

    Parameters
    ----------
    alpha : array_like
        Mitsuba's roughness, the RMS slope of the microfacets [-].

    Returns
    -------
    numpy.ndarray
        sigma = alpha / sqrt(2) [rad], in degrees.

    Examples
    --------
    >>> round(float(mitsuba_alpha_to_sigma(0.2)), 3)
    8.103
    """
    return np.degrees(np.asarray(alpha, float) / MITSUBA_ALPHA_PER_SIGMA)


# ---------------------------------------------------------------------------- renderers
@dataclass(frozen=True)
class Renderer:
    """A renderer's rough-diffuse BRDF as a gonio model with a roughness convention.

    Attributes
    ----------
    name : str
        Key in :data:`RENDERERS`.
    model : str
        The registered gonio model that evaluates the renderer's BRDF.
    parameter : str
        The renderer's roughness parameter name.
    bounds : tuple of float
        Range of the roughness parameter the renderer accepts (within gonio's bounds).
    to_params : callable
        ``to_params(roughness) -> dict`` of gonio model parameters other than ``rho``.
    description : str
        The renderer and setting this stands for.
    """

    name: str
    model: str
    parameter: str
    bounds: tuple[float, float]
    to_params: Callable[[float], dict]
    description: str


RENDERERS: dict[str, Renderer] = {
    r.name: r for r in (
        Renderer("eon", "eon", "r", (0.0, 1.0), lambda v: {"r": v},
                 "EON (OpenPBR base_diffuse_roughness, OSL/MaterialX oren_nayar_diffuse_bsdf with "
                 "energy_compensation)"),
        Renderer("fujii-oren-nayar", "fujii-oren-nayar", "r", (0.0, 1.0), lambda v: {"r": v},
                 "Fujii's Oren-Nayar (FON) without energy compensation"),
        Renderer("mitsuba-roughdiffuse", "oren-nayar", "alpha", (0.0, _MITSUBA_ALPHA_MAX),
                 lambda v: {"sigma": float(mitsuba_alpha_to_sigma(v)), "ir_weight": 1.0},
                 "Mitsuba 0.6 roughdiffuse (useFastApprox = false: eq 33-35, sigma = alpha/sqrt(2))"),
        Renderer("mitsuba-roughdiffuse-fast", "oren-nayar-qualitative", "alpha", (0.0, _MITSUBA_ALPHA_MAX),
                 lambda v: {"sigma": float(mitsuba_alpha_to_sigma(v))},
                 "Mitsuba 0.6 roughdiffuse (useFastApprox = true: eq 36, sigma = alpha/sqrt(2))"),
    )
}


def _renderer(name: str) -> Renderer:
    try:
        return RENDERERS[name]
    except KeyError:
        raise ValueError(f"unknown renderer {name!r}; known renderers: {sorted(RENDERERS)}") from None


# ---------------------------------------------------------------------------- geometry
def match_geometry(order: int = 10, azimuths: int = 8) -> tuple[np.ndarray, ...]:
    """The geometry set and weights of the roughness match.

    Parameters
    ----------
    order : int, optional
        Gauss-Legendre nodes in cos(theta) on (0, 1), for each of the two directions.
    azimuths : int, optional
        Gauss-Legendre nodes in the azimuth difference on each of [0, 90] and [90, 180] deg
        (the models are isotropic and even in the azimuth difference; 90 deg is where
        Oren-Nayar's C2 and Fujii's s/t change form).

    Returns
    -------
    theta_i, phi_i, theta_r, phi_r, weight : numpy.ndarray
        Flat arrays: angles [deg] (phi_i = 0) and the normalised weights (sum 1) of the
        measure cos(theta_i) cos(theta_r) d omega_i d omega_r over both hemispheres.

    Examples
    --------
    >>> ti, pi_, tr, pr, w = match_geometry(4, 3)
    >>> ti.size, round(float(w.sum()), 12)
    (96, 1.0)
    """
    if int(order) < 1 or int(azimuths) < 1:
        raise ValueError(f"order = {order!r} and azimuths = {azimuths!r} must be positive integers")
    x, w = np.polynomial.legendre.leggauss(int(order))
    mu, mu_w = 0.5 * (x + 1.0), 0.5 * w                       # nodes on (0, 1)
    xa, wa = np.polynomial.legendre.leggauss(int(azimuths))
    dphi = np.concatenate([45.0 * (xa + 1.0), 90.0 + 45.0 * (xa + 1.0)])
    dphi_w = np.concatenate([wa, wa])
    theta = np.degrees(np.arccos(mu))
    ti, tr, pr = (a.ravel() for a in np.meshgrid(theta, theta, dphi, indexing="ij"))
    # d omega = d mu d phi: the weight of cos_i cos_r d omega_i d omega_r is mu_i mu_r w_i w_r w_phi
    weight = np.einsum("i,j,k->ijk", mu * mu_w, mu * mu_w, dphi_w).ravel()
    return ti, np.zeros_like(ti), tr, pr, weight / weight.sum()


# ---------------------------------------------------------------------------- matching
@dataclass(frozen=True)
class RoughnessMatch:
    """The renderer roughness that best reproduces a reference BRDF, and how well.

    Attributes
    ----------
    renderer : str
        Key in :data:`RENDERERS`.
    parameter : str
        The renderer's roughness parameter (``r`` or ``alpha``).
    value : float
        Its fitted value.
    rho : float
        The renderer's albedo: the reference's, or fitted when ``fit_albedo``.
    rms : float
        Cosine-weighted relative rms BRDF difference (module notes) [-].
    max_rel : float
        Largest relative difference at nodes with both polar angles <= 80 deg [-].
    max_rel_all : float
        Largest relative difference over all nodes [-].
    at_bound : bool
        Whether the fitted roughness sits on a bound of the renderer's range (the
        reference is rougher, or smoother, than the renderer can express).
    """

    renderer: str
    parameter: str
    value: float
    rho: float
    rms: float
    max_rel: float
    max_rel_all: float
    at_bound: bool

    def as_dict(self) -> dict[str, Any]:
        """The fields as a plain dict (for JSON)."""
        return asdict(self)


def _objective(reference: ArrayLike, geometry: tuple[np.ndarray, ...], renderer: str):
    """(spec, values(value, rho), residuals(value, rho), errors(values)) of a match."""
    spec = _renderer(renderer)
    ti, pi_, tr, pr, weight = geometry
    target = np.asarray(reference, float)
    model = get(spec.model).at(ti, pi_, tr, pr)
    sqrt_w = np.sqrt(weight)
    norm = math.sqrt(float(np.sum(weight * target**2)))
    inside = (ti <= MAX_REL_THETA) & (tr <= MAX_REL_THETA)
    positive = target > 0.0

    def values(value: float, rho: float) -> np.ndarray:
        return model(rho=rho, **spec.to_params(value))

    def residuals(value: float, rho: float) -> np.ndarray:
        return sqrt_w * (values(value, rho) - target) / norm

    def errors(fitted: np.ndarray) -> tuple[float, float, float]:
        rms = math.sqrt(float(np.sum(weight * (fitted - target) ** 2))) / norm
        relative = np.where(fitted == target, 0.0, np.inf)  # a reference of 0 only matches 0
        relative[positive] = np.abs(fitted[positive] / target[positive] - 1.0)
        return rms, float(np.max(relative[inside])), float(np.max(relative))

    return spec, values, residuals, errors


def mapping_error(
    reference: ArrayLike,
    geometry: tuple[np.ndarray, ...],
    rho: float,
    renderer: str,
    value: float,
) -> RoughnessMatch:
    """How well a renderer at a given roughness reproduces reference BRDF values (no fit).

    Parameters
    ----------
    reference : array_like
        Reference BRDF [1/sr] at the geometries.
    geometry : tuple of numpy.ndarray
        ``(theta_i, phi_i, theta_r, phi_r, weight)`` as :func:`match_geometry` returns.
    rho : float
        Albedo handed to the renderer [-].
    renderer : str
        Key in :data:`RENDERERS`.
    value : float
        The renderer's roughness (``r`` or ``alpha``), e.g. a closed-form mapping.

    Returns
    -------
    RoughnessMatch
        With ``value`` as given and its errors.
    """
    spec, values, _, errors = _objective(reference, geometry, renderer)
    lo, hi = spec.bounds
    if not lo <= value <= hi:
        raise ValueError(f"renderer {renderer!r}: {spec.parameter} = {value:g} is outside [{lo:g}, {hi:g}]")
    rms, max_rel, max_rel_all = errors(values(value, rho))
    return RoughnessMatch(renderer, spec.parameter, float(value), float(rho), rms, max_rel, max_rel_all,
                          bool(value in (lo, hi)))


def match_values(
    reference: ArrayLike,
    geometry: tuple[np.ndarray, ...],
    rho: float,
    renderer: str = "eon",
    fit_albedo: bool = False,
) -> RoughnessMatch:
    """Fit a renderer's roughness to reference BRDF values on a weighted geometry set.

    Parameters
    ----------
    reference : array_like
        Reference BRDF [1/sr] at the geometries (any model, or data).
    geometry : tuple of numpy.ndarray
        ``(theta_i, phi_i, theta_r, phi_r, weight)`` as :func:`match_geometry` returns.
    rho : float
        Albedo [-] handed to the renderer, and the starting value when ``fit_albedo``.
    renderer : str, optional
        Key in :data:`RENDERERS`.
    fit_albedo : bool, optional
        Also fit the renderer's albedo (in [0, 1]); otherwise it is ``rho``.

    Returns
    -------
    RoughnessMatch
    """
    spec, values, residuals_of, errors = _objective(reference, geometry, renderer)
    lo, hi = spec.bounds

    def residuals(x: np.ndarray) -> np.ndarray:
        return residuals_of(float(x[0]), float(x[1]) if fit_albedo else rho)

    def cost(x: np.ndarray) -> float:
        return float(np.sum(residuals(x) ** 2))

    # a coarse scan picks the start (the objective can be flat near a bound), then a
    # bounded least-squares polish
    starts = [np.array([g, rho]) if fit_albedo else np.array([g]) for g in np.linspace(lo, hi, 21)]
    best = min(starts, key=cost)
    lower = [lo, 0.0] if fit_albedo else [lo]
    upper = [hi, 1.0] if fit_albedo else [hi]
    fit = least_squares(residuals, best, bounds=(lower, upper), x_scale="jac", xtol=1e-12, ftol=1e-12)
    # the polish stays strictly inside the bounds: keep the start where it is as good
    x = fit.x if cost(fit.x) < cost(best) else best
    albedo = float(x[1]) if fit_albedo else float(rho)
    rms, max_rel, max_rel_all = errors(values(float(x[0]), albedo))
    span = hi - lo
    return RoughnessMatch(
        renderer=renderer,
        parameter=spec.parameter,
        value=float(x[0]),
        rho=albedo,
        rms=rms,
        max_rel=max_rel,
        max_rel_all=max_rel_all,
        at_bound=bool(x[0] <= lo + 1e-6 * span or x[0] >= hi - 1e-6 * span),
    )


def match_roughness(
    sigma: float,
    rho: float,
    renderer: str = "eon",
    reference: str = "oren-nayar-exact",
    fit_albedo: bool = False,
    order: int = 10,
    azimuths: int = 8,
) -> RoughnessMatch:
    """The renderer roughness that best reproduces an Oren-Nayar surface.

    Parameters
    ----------
    sigma : float
        Oren-Nayar roughness [deg].
    rho : float
        Facet albedo [-].
    renderer : str, optional
        Key in :data:`RENDERERS`: ``"eon"``, ``"fujii-oren-nayar"``,
        ``"mitsuba-roughdiffuse"``, ``"mitsuba-roughdiffuse-fast"``.
    reference : str, optional
        The Oren-Nayar model taken as the surface: ``"oren-nayar-exact"`` (the V-cavity
        model integrated numerically, the default), ``"oren-nayar"`` (eq 33-35) or
        ``"oren-nayar-qualitative"`` (eq 36).
    fit_albedo : bool, optional
        Also fit the renderer's albedo instead of handing it ``rho``.
    order, azimuths : int, optional
        Size of the geometry set (:func:`match_geometry`).

    Returns
    -------
    RoughnessMatch
        The fitted value and the residual errors of the mapping.

    Notes
    -----
    Module notes for the objective.  The measured values over sigma in [0, 50] deg are in
    docs/roughness.md (benchmarks/roughness_mapping.py).

    Examples
    --------
    >>> m = match_roughness(30.0, 0.8, "mitsuba-roughdiffuse", reference="oren-nayar", order=4, azimuths=3)
    >>> round(m.value, 4), m.rms < 1e-9
    (0.7405, True)
    """
    if reference not in ("oren-nayar-exact", "oren-nayar", "oren-nayar-qualitative"):
        raise ValueError(f"reference {reference!r} is not one of 'oren-nayar-exact', 'oren-nayar', "
                         "'oren-nayar-qualitative'")
    geometry = match_geometry(order, azimuths)
    values = get(reference)(*geometry[:4], rho=rho, sigma=sigma)
    return match_values(values, geometry, rho, renderer, fit_albedo)


def sigma_to_eon_r(sigma: float, rho: float, reference: str = "oren-nayar-exact", fit_albedo: bool = False) -> float:
    """EON roughness r [-] that best reproduces an Oren-Nayar surface of roughness sigma [deg].

    :func:`match_roughness` with ``renderer="eon"``; returns the fitted ``r`` only.

    Examples
    --------
    >>> sigma_to_eon_r(0.0, 0.8, reference="oren-nayar")
    0.0
    """
    return match_roughness(sigma, rho, "eon", reference, fit_albedo).value


def sigma_to_fujii_r(sigma: float, rho: float, reference: str = "oren-nayar-exact", fit_albedo: bool = False) -> float:
    """Fujii (FON) roughness r [-] that best reproduces an Oren-Nayar surface of roughness sigma [deg].

    :func:`match_roughness` with ``renderer="fujii-oren-nayar"``; returns the fitted ``r``.

    Examples
    --------
    >>> round(sigma_to_fujii_r(30.0, 0.9, reference="oren-nayar"), 3)
    0.396
    """
    return match_roughness(sigma, rho, "fujii-oren-nayar", reference, fit_albedo).value
