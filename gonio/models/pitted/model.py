"""The registered ``pitted`` model: a plane partly covered by spherical pits.

A fraction ``coverage`` of the plane is covered by spherical pits of aperture ``psi``
(Koenderink et al. 1999, section 1.5 and Fig 2); the pits and the flat rest are
Lambertian with albedo ``rho`` at the micro scale.  The pit diameter does not enter the
BRDF (section 5).  The BRDF separates as

    f = (1 - coverage) rho/pi + coverage (rho F1(geometry, psi) + F2(rho, psi))

with ``F1`` the single-scattering factor (eq 14-15; in closed form, :mod:`.closed_form`,
or by quadrature, :mod:`.quadrature`; see :func:`single_scattering`) and ``F2`` the
interreflection term, the diffuse radiance of eq 12 per unit plane irradiance, which does
not depend on the directions at all.  :func:`pitted_terms` exposes this split.

References
----------
J. J. Koenderink, A. J. van Doorn, K. J. Dana, S. K. Nayar, "Bidirectional reflection
distribution function of thoroughly pitted surfaces", IJCV 31(2/3), 1999.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from .._core import Model, Param, register
from .quadrature import FLAT_LIMIT, single_scattering_factor
from .validation import check_pit_parameters

__all__ = ["PitTerms", "single_scattering", "pitted_terms", "pitted_brdf", "aperture_mixture_brdf", "PITTED"]

#: Where sin^2(psi) cos(alpha) cos(beta) is below this, F1 is taken from the quadrature
#: instead of the closed form.  The closed form is accurate to ~1e-16 in the integral I,
#: absolutely, and F1 = I / (pi^2 sin^2(psi) cos(alpha) cos(beta)), so its relative error
#: near the horizon (or for very shallow pits) grows like 1e-17 / (sin^2 psi cos alpha
#: cos beta); below 1e-10 (both directions within ~1e-5 rad of the horizon for a
#: hemispherical pit) the quadrature, accurate in relative terms there, is used.
SLIVER_LIMIT = 1e-10
#: Quadrature nodes per panel at those points (few, so the higher order costs nothing).
SLIVER_ORDER = 32
#: Where sin^2(psi) < SHALLOW_LIMIT cos(alpha) cos(beta), F1 is taken as 1/pi, the flat
#: pit's value. Its departure from 1/pi is 0.25 psi^2 / (cos alpha cos beta) of it
#: (measured by the quadrature at psi = 1e-2 to 1e-4 rad, from normal to 1e-4 of grazing:
#: tests/models/test_pitted_model.py), so below 3e-9 of it here, less than the closed
#: form's own error at the sliver limit (1e-7). Such pits (a quadrature node of the
#: evidence at psi = 7e-5 deg) had been slivers everywhere: 850 times the cost.
SHALLOW_LIMIT = 1e-8


@dataclass(frozen=True)
class PitTerms:
    """The rho-separated parts of the pit BRDF at fixed geometry and aperture.

    Attributes
    ----------
    single_scattering : numpy.ndarray
        F1 [1/sr]: single-scattering BRDF of one pit per unit micro-albedo.
    interreflection_scale : float
        ``sin^2(psi) / (4 pi)`` [1/sr].
    interreflection_sin2_half : float
        ``sin^2(psi / 2)`` [-].

    Notes
    -----
    The pit BRDF is ``rho F1 + interreflection_scale rho^2 / (1 - rho
    interreflection_sin2_half)`` (eq 12 for the second term); the pitted surface adds
    ``(1 - coverage) rho/pi`` for the flat part.  Tabulating ``single_scattering`` over
    geometry and psi is all a fast version needs.
    """

    single_scattering: np.ndarray
    interreflection_scale: float | np.ndarray
    interreflection_sin2_half: float | np.ndarray

    def pit_brdf(self, rho: float) -> np.ndarray:
        """BRDF of a fully pitted surface [1/sr] for micro-albedo ``rho``."""
        return rho * self.single_scattering + self.interreflection_scale * rho**2 / (
            1.0 - rho * self.interreflection_sin2_half
        )

    def brdf(self, rho: float, coverage: float) -> np.ndarray:
        """BRDF of the pitted surface [1/sr]."""
        return (1.0 - coverage) * rho / np.pi + coverage * self.pit_brdf(rho)


def single_scattering(alpha: np.ndarray, beta: np.ndarray, epsilon: np.ndarray, psi: float | np.ndarray,
                      order: int | None = None) -> np.ndarray:
    """F1 [1/sr]: single-scattering BRDF of one pit per unit micro-albedo (angles [rad]).

    Parameters
    ----------
    alpha, beta : numpy.ndarray
        Source and viewer polar angles [rad] in [0, pi/2].
    epsilon : numpy.ndarray
        Viewer azimuth from the plane of incidence [rad].
    psi : float or numpy.ndarray
        Aperture [rad], 0 < psi <= pi/2; an array broadcasts with the angles (a sampler's
        particles, one aperture each; the closed form only).
    order : int, optional
        None (default): the closed form (:mod:`.closed_form`, ~1e-10 relative, millions of
        geometries per second), with the quadrature (``SLIVER_ORDER`` nodes per panel)
        where ``sin^2(psi) cos(alpha) cos(beta) < SLIVER_LIMIT`` and 1/pi where
        ``sin^2(psi) < SHALLOW_LIMIT cos(alpha) cos(beta)``; an integer: the quadrature of :mod:`.quadrature` with
        that many nodes per panel everywhere (the reference the closed form is tested
        against).

    Returns
    -------
    numpy.ndarray
        F1, broadcast shape of the angles.
    """
    if order is not None:
        alpha, beta, epsilon = np.broadcast_arrays(*(np.asarray(a, float) for a in (alpha, beta, epsilon)))
        return single_scattering_factor(alpha, beta, epsilon, float(psi), order)
    from .closed_form import single_scattering_factor_closed  # numba loads on first use

    alpha, beta, epsilon, apertures = np.broadcast_arrays(*(np.asarray(a, float) for a in (alpha, beta, epsilon, psi)))
    factor = np.array(single_scattering_factor_closed(alpha, beta, epsilon, apertures), float,
                      ndmin=1).reshape(alpha.shape)
    a, b, e, p = (x.reshape(-1) for x in (alpha, beta, epsilon, apertures))
    sin2_psi = np.broadcast_to(np.sin(np.asarray(psi, float)) ** 2, alpha.shape).reshape(-1)
    flat = factor.reshape(-1)
    shallow = _shallow(a, b, sin2_psi)
    flat[shallow] = 1.0 / np.pi
    # cos(x) >= (2/pi)(pi/2 - x) on [0, pi/2]: only geometries with a small product of the
    # distances from the horizon can be slivers, and only those need the cosines
    limit = SLIVER_LIMIT / np.maximum(sin2_psi, FLAT_LIMIT)
    half_pi = 0.5 * np.pi
    candidate = np.flatnonzero((sin2_psi >= FLAT_LIMIT) & ((half_pi - a) * (half_pi - b) < half_pi**2 * limit))
    candidate = np.setdiff1d(candidate, shallow, assume_unique=True)
    slivers = candidate[np.cos(a[candidate]) * np.cos(b[candidate]) < limit[candidate]]
    for aperture in np.unique(p[slivers]):  # one quadrature per distinct aperture
        at = slivers[p[slivers] == aperture]
        flat[at] = single_scattering_factor(a[at], b[at], e[at], float(aperture), SLIVER_ORDER)
    return factor


def _shallow(alpha: np.ndarray, beta: np.ndarray, sin2_psi: np.ndarray) -> np.ndarray:
    """Indices (into the flat arrays) of the geometries where the pit is flat to within
    :data:`SHALLOW_LIMIT` of F1 = 1/pi: ``sin^2(psi) < SHALLOW_LIMIT cos(alpha) cos(beta)``
    (a pit of sin^2(psi) below the limit at least; the cosines only for those)."""
    near = np.flatnonzero((sin2_psi < SHALLOW_LIMIT) & (sin2_psi >= FLAT_LIMIT))
    return near[sin2_psi[near] < SHALLOW_LIMIT * np.cos(alpha[near]) * np.cos(beta[near])]


def _terms_rad(ti, pi_, tr, pr, psi_deg: float | np.ndarray, order: int | None = None) -> PitTerms:
    psi = np.radians(psi_deg)
    factor = single_scattering(ti, tr, pr - pi_, psi, order)
    if np.ndim(psi):
        return PitTerms(factor, np.sin(psi) ** 2 / (4.0 * np.pi), np.sin(psi / 2.0) ** 2)
    return PitTerms(factor, float(np.sin(psi) ** 2 / (4.0 * np.pi)), float(np.sin(psi / 2.0) ** 2))


def pitted_terms(
    theta_i: ArrayLike, phi_i: ArrayLike, theta_r: ArrayLike, phi_r: ArrayLike, psi: float,
    order: int | None = None,
) -> PitTerms:
    """The split of the pit BRDF into geometry-and-aperture factors (see :class:`PitTerms`).

    Parameters
    ----------
    theta_i, phi_i : array_like
        Source direction [deg], theta_i in [0, 90].
    theta_r, phi_r : array_like
        Viewing direction [deg], theta_r in [0, 90].
    psi : float
        Aperture [deg], 0 < psi <= 90.
    order : int, optional
        None: F1 in closed form; an integer: by quadrature with that many nodes per
        panel (see :func:`single_scattering`).

    Returns
    -------
    PitTerms

    Notes
    -----
    Eq 12 and eq 14-15 of Koenderink et al. (1999).

    Examples
    --------
    >>> terms = pitted_terms(0.0, 0.0, 0.0, 0.0, psi=90.0)
    >>> round(float(terms.pit_brdf(1.0)), 6)   # 2/(3 pi) + 1/(2 pi), eq 26 + 29
    0.371362
    """
    check_pit_parameters(rho=0.0, psi=psi, coverage=0.0)
    ti, pi_, tr, pr = (np.radians(np.asarray(a, float)) for a in np.broadcast_arrays(theta_i, phi_i, theta_r, phi_r))
    return _terms_rad(ti, pi_, tr, pr, float(psi), order)


def _prepare(ti, pi_, tr, pr) -> Callable[..., np.ndarray]:
    """Geometry [rad] -> f(rho, psi, coverage); F1 is cached per aperture. Parameters may
    be arrays broadcasting with the geometry (the model broadcasts its parameters: a
    sampler's particles in one call)."""
    cache: dict[float, PitTerms] = {}

    def evaluate(rho, psi, coverage) -> np.ndarray:
        if np.ndim(psi):
            return _terms_rad(ti, pi_, tr, pr, np.asarray(psi, float)).brdf(rho, coverage)
        if psi not in cache:
            if len(cache) > 8:
                cache.clear()
            cache[psi] = _terms_rad(ti, pi_, tr, pr, psi)
        return cache[psi].brdf(rho, coverage)

    return evaluate


def pitted_brdf(theta_i, phi_i, theta_r, phi_r, rho: float, psi: float, coverage: float) -> np.ndarray:
    """BRDF of a plane partly covered by spherical pits [1/sr] (angles in radians).

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad], above the horizon.
    rho : float
        Micro-scale Lambertian albedo [-].
    psi : float
        Pit aperture [deg], 0 < psi <= 90 (90: hemispherical pits).
    coverage : float
        Fraction of the plane covered by pit orifices [-].

    Returns
    -------
    numpy.ndarray
        ``(1 - coverage) rho/pi + coverage (rho F1 + F2)`` [1/sr].

    Notes
    -----
    Koenderink et al. (1999): F1 is eq 15 with the Lambertian micro-radiance (eq 5),
    integrated over the lit and visible cavity in closed form (:mod:`.closed_form`,
    Stokes' theorem over the arcs of its boundary; the quadrature of :mod:`.quadrature`
    at the horizon slivers, see :func:`single_scattering`); for psi = 90 deg it equals
    eq 21 and, in the plane of incidence, eq 26-28.  F2 is eq 12 (= D of eq 29 for the
    hemisphere).  Deterministic: a registered BRDF must be a function, so the
    Monte Carlo method of section 4.1 (:mod:`.shallow`) is only used to check it.

    * Reciprocal: F1 is symmetric in source and viewer (the lit and visible conditions
      are the same test) and F2 is constant, so the model obeys Helmholtz reciprocity
      exactly (tested).
    * Energy: the directional-hemispherical reflectance is
      ``(1 - coverage) rho + coverage rho cos^2(psi/2) / (1 - rho sin^2(psi/2))`` for
      every incidence (derived from eq 9-10), <= 1, and 1 for rho = 1 (tested).
    * At exactly grazing incidence or view the formula is 0/0; it is evaluated
      ``GRAZING_MARGIN`` = 1e-7 rad inside the hemisphere.  The limit is finite except
      towards grazing retro-reflection (theta_i = theta_r -> 90 deg, same azimuth), where
      the BRDF of deep pits grows like 1/cos(theta_i) (the "attitude effect" curve of
      Fig 4 goes to infinity); there the returned value is large (~1e6 1/sr) but finite,
      and the radiance ``f cos(theta_i)`` stays bounded.

    Examples
    --------
    >>> import gonio
    >>> round(float(gonio.models.get("pitted")(30.0, 0.0, 60.0, 180.0, rho=1.0, psi=90.0, coverage=1.0)), 6)
    0.159155
    """
    return _prepare(theta_i, phi_i, theta_r, phi_r)(rho=rho, psi=psi, coverage=coverage)


def aperture_mixture_brdf(
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_r: ArrayLike,
    phi_r: ArrayLike,
    rho: float,
    apertures: Sequence[float],
    weights: Sequence[float],
    coverage: float = 1.0,
) -> np.ndarray:
    """BRDF [1/sr] of a surface pitted with a distribution of apertures (section 5).

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [deg].
    rho : float
        Micro-scale albedo [-].
    apertures : sequence of float
        Pit apertures [deg], each in (0, 90].
    weights : sequence of float
        Non-negative fractions of the pitted area with each aperture (normalised here;
        they must not all be zero).
    coverage : float
        Total fraction of the plane covered by pits [-].

    Returns
    -------
    numpy.ndarray
        ``(1 - coverage) rho/pi + coverage sum_k w_k f_pit(psi_k)`` [1/sr].

    Notes
    -----
    Section 5 (conclusion): the BRDF of a distribution of apertures is the area-weighted
    average of the pits' BRDFs; the distribution of diameters does not enter.

    Examples
    --------
    >>> f = aperture_mixture_brdf(20.0, 0.0, 20.0, 0.0, rho=0.5, apertures=[90.0], weights=[1.0])
    >>> import gonio
    >>> bool(abs(f - gonio.brdf("pitted", 20.0, 0.0, 20.0, 0.0, rho=0.5, psi=90.0, coverage=1.0)) < 1e-14)
    True
    """
    apertures = np.atleast_1d(np.asarray(apertures, float))
    weights = np.atleast_1d(np.asarray(weights, float))
    if apertures.shape != weights.shape or apertures.ndim != 1:
        raise ValueError(
            f"apertures and weights must be 1-D sequences of the same length, got {apertures.shape} and {weights.shape}"
        )
    if np.any(~(weights >= 0.0)) or weights.sum() <= 0.0:
        raise ValueError(f"weights = {weights.tolist()} must be non-negative and not all zero")
    rho, _, coverage = check_pit_parameters(rho=rho, psi=90.0, coverage=coverage)
    for psi in apertures:
        check_pit_parameters(rho=rho, psi=psi, coverage=coverage)
    weights = weights / weights.sum()
    pits = sum(w * PITTED(theta_i, phi_i, theta_r, phi_r, rho=rho, psi=psi, coverage=1.0)
               for psi, w in zip(apertures, weights))
    return (1.0 - coverage) * rho / np.pi + coverage * pits


PITTED = register(
    Model(
        name="pitted",
        params=(
            Param("rho", "-", 0.8, (0.0, 1.0), "micro-scale Lambertian albedo of pits and plane"),
            Param("psi", "deg", 90.0, (0.0, 90.0), "pit aperture; 90 is a hemispherical pit",
                  open_lower=True),
            Param("coverage", "-", 0.4, (0.0, 1.0), "fraction of the plane covered by pit orifices"),
        ),
        reference=(
            "Koenderink, van Doorn, Dana & Nayar 1999, IJCV 31: eq 12 (interreflection), "
            "eq 14-15 (single scattering, in closed form over the boundary arcs), eq 21 and 26-29 (psi = 90)"
        ),
        description="plane partly covered by Lambertian spherical pits (shadowing and interreflection)",
        prepare=_prepare,
        energy_conserving=True,
        reciprocal=True,
        broadcasts_params=True,
    )
)
