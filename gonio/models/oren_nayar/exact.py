"""Oren-Nayar surfaces with a Gaussian distribution of V-cavity slopes, evaluated numerically.

Two registered models:

``oren-nayar-exact``
    The reference of the Oren-Nayar family: the V-cavity model integrated over facet
    normals (eq 8) with the Gaussian slope-area distribution (eq 32), the exact
    geometric attenuation of eq 15 / Table 1 and the exact two-bounce interreflection of
    eq 22-24 -- none of the paper's shortcuts (eq 44, 48).  Accuracy knob: ``rtol``.
``oren-nayar-numerical``
    What the paper itself computed (eq 31): the isotropic single-slope radiance of the
    closed form eq 45 (direct) and the approximation eq 49 (interreflection), weighted by
    eq 32 and integrated over the slope.

Both are ``rho f1 + rho^2 f2`` with f1, f2 functions of geometry and sigma only:
:func:`exact_components` and :func:`numerical_components` expose that split.

Accuracy and cost of ``oren-nayar-exact`` (option ``rtol`` in :data:`RTOL_CHOICES`,
default 1e-6): measured worst relative errors over random and grazing geometries are
below the chosen rtol (1e-6 -> 3e-7); time per geometry ~1-2 ms at the default on one
core (benchmarks/bench_oren_nayar.py, docs/benchmarks/oren_nayar.json).  The tightest
setting is 1e-7.  Accuracy of the faster methods against it: docs/oren-nayar-accuracy.md.

>>> import gonio
>>> value = gonio.brdf("oren-nayar-exact", 75.0, 0.0, 40.0, 0.0, rho=0.9, sigma=30.0)
>>> round(float(value) * 3.141592653589793 / 0.9, 3)   # backscatter: above Lambert's 1
1.109

Decisions where the paper is silent or ambiguous
------------------------------------------------
* Azimuth of the cavities: an isotropic surface has its V-cavities uniformly distributed
  in azimuth, so every facet azimuth phi_a in [0, 2 pi) has the same weight (eq 29); the
  two facets of a cavity (phi_a, phi_a + pi) are both counted by that uniform average.
* Normalisation of eq 32: P(theta_a) = c exp(-theta_a^2 / (2 sigma^2)) with
  1/c = integral over theta_a in [0, pi/2] and phi_a in [0, 2 pi) of
  exp(-theta_a^2/(2 sigma^2)) sin(theta_a), as printed.  Substituting it into eq 31,
  whose L_rp(theta_a) is already the azimuthal *mean* (eq 29), would lose a factor 2 pi;
  eq 8 (the defining integral, over both angles) does not, and gonio follows eq 8: the
  slope weight is exp(-theta_a^2/(2 sigma^2)) sin(theta_a) / integral_0^{pi/2}
  exp(-t^2/(2 sigma^2)) sin(t) dt, which makes sigma -> 0 tend to Lambert as footnote 10
  states.  The Gaussian is truncated at theta_a = 90 deg (no facets steeper than
  vertical), so sigma is the standard deviation of the *untruncated* Gaussian.
* sigma is in degrees at the interface and in radians inside (the functional
  approximation eq 33-35 uses sigma^2 in rad^2).
* sigma = 0 is Lambert exactly (footnote 10): f1 = 1/pi, f2 = 0, without integrating.
* Directions on the horizon: polar angles above 90 deg - 1e-6 rad (5.7e-5 deg) are
  evaluated at that angle.  Where the limit theta -> 90 deg is finite this is within
  ~5e-6 relative of it (measured at theta_i = 90, theta_r = 89 deg, forward; ~1e-6
  elsewhere), and the quadrature keeps its accuracy (closer to the horizon the critical
  azimuths crowd together and the interreflection integral converges more slowly).  At
  grazing retro-reflection (theta_i = theta_r -> 90 deg, phi_r = phi_i) the model
  diverges like 1/cos(theta) -- a facet lit and seen from the same grazing direction
  keeps a finite radiance while the BRDF divides by cos(theta_i), as eq 33 does through
  tan(beta) -- and the returned value is large (~1e6 rho/pi) but finite.
* BRDF = radiance / (E_0 cos theta_i) (section 4.3).

References
----------
M. Oren, S. K. Nayar, "Generalization of the Lambertian model and implications for machine
vision", IJCV 14(3), 1995; tech. report CUCS-057-92 (rev. 1996), eq 8, 29, 31-32, 39-49,
Figures 10-14.
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike

from .._core import Model, Option, Param, register
from .single_slope import (
    _unit_gauss_legendre,
    isotropic_brdf_terms,
    isotropic_direct_radiance,
    isotropic_interreflected_radiance,
)

__all__ = [
    "exact_components",
    "numerical_components",
    "slope_normalisation",
    "RTOL_CHOICES",
    "EXACT",
    "NUMERICAL",
]

#: Largest polar angle used inside the kernels [rad] (see the module notes on the horizon).
_HORIZON = np.pi / 2.0 - 1e-6

#: Quadrature settings per accuracy target ``rtol``: Gauss-Legendre nodes per slope
#: panel, per azimuth panel for the direct term, per azimuth panel (or half panel, where
#: graded) for the interreflection term.  Calibrated against (24, 12, 60) over random
#: and grazing geometries and sigma in {2, 10, 30, 60} deg; measured worst relative
#: errors: 8e-3, 4e-4, 1.1e-5, 3.6e-6, 3.1e-7, 4.5e-8.  The interreflection integrand
#: of steep facets at grazing angles converges only algebraically below ~3e-8, so no
#: tighter setting is offered (benchmarks/bench_oren_nayar.py,
#: tests/models/test_oren_nayar_exact.py).
_QUADRATURE: dict[float, tuple[int, int, int]] = {
    1e-2: (5, 3, 3),
    1e-3: (7, 3, 5),
    1e-4: (9, 4, 8),
    1e-5: (10, 5, 8),
    1e-6: (12, 5, 10),
    1e-7: (14, 6, 16),
}
RTOL_CHOICES: tuple[float, ...] = tuple(sorted(_QUADRATURE, reverse=True))

_CHUNK = 128  # geometries evaluated together (bounds the memory of the node arrays)


# --------------------------------------------------------------------------- slope weights
_SLOPE_GAUSS_X, _SLOPE_GAUSS_W = np.polynomial.legendre.leggauss(24)


def _gaussian_slope_integral(
    sigma: float,
    upper: float,
    weight: Callable[[np.ndarray], np.ndarray] | None = None,
    kinks: tuple[float, ...] = (),
) -> float:
    """int_0^upper exp(-t^2/(2 sigma^2)) w(t) sin(t) dt, sigma and upper in [rad].

    ``w`` is 1, or ``weight(t)`` (a facet attenuation, e.g. for the Torrance-Sparrow lobe)
    whose kinks [rad] are listed in ``kinks``.  Gauss-Legendre panels (24 nodes) with
    edges at multiples of sigma (the Gaussian's scale) and at the kinks; the integrand is
    negligible (< exp(-72)) beyond 12 sigma.  Relative accuracy ~1e-15.
    """
    top = min(upper, 12.0 * sigma)
    edges = [0.0, top] + [k * sigma for k in (0.5, 1.0, 2.0, 3.0, 4.5, 6.5, 9.0) if k * sigma < top]
    edges += [kink for kink in kinks if kink < top]
    edges = np.unique(edges)
    lo, hi = edges[:-1, None], edges[1:, None]
    half = 0.5 * (hi - lo)
    t = (lo + half * (_SLOPE_GAUSS_X + 1.0)).ravel()
    w = (half * _SLOPE_GAUSS_W).ravel()
    integrand = np.exp(-0.5 * (t / sigma) ** 2) * np.sin(t)
    if weight is not None:
        integrand = integrand * weight(t)
    return float(np.sum(w * integrand))


@lru_cache(maxsize=256)
def slope_normalisation(sigma: float) -> float:
    """Normalisation of the Gaussian slope-area distribution eq 32 over [0, 90 deg].

    Parameters
    ----------
    sigma : float
        Standard deviation of the facet slope [rad], > 0.

    Returns
    -------
    float
        Z = integral_0^{pi/2} exp(-t^2/(2 sigma^2)) sin(t) dt [rad]; 1/c of eq 32 is
        2 pi Z.  The one implementation of eq 32's constant: the ``torrance-sparrow``
        lobe uses it too.

    Examples
    --------
    >>> round(slope_normalisation(0.01) / 0.01**2, 6)   # small sigma: Z ~ sigma^2
    0.999967
    """
    return _gaussian_slope_integral(float(sigma), np.pi / 2.0)


def _slope_weight(theta_a: np.ndarray, sigma: float) -> np.ndarray:
    """P(theta_a) sin(theta_a) 2 pi of eq 8/32: the density of facet slopes [1/rad]."""
    return np.exp(-(theta_a * theta_a) / (2.0 * sigma * sigma)) * np.sin(theta_a) / slope_normalisation(sigma)


def _tail_cut(rtol: float) -> float:
    """Slope, in units of sigma, beyond which the Gaussian weight is negligible for rtol."""
    return math.sqrt(2.0 * math.log(100.0 / rtol))


def _slope_nodes(edges: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights on panels between sorted ``edges`` (..., P+1).

    Each panel [a, b] is mapped by theta = a + (b - a) sin^2(pi u / 2), u in [0, 1], which
    removes square-root singularities at both panel ends (the critical azimuths of eq 39
    open like sqrt(theta_a - theta_c)); Gauss-Legendre is then used in u.
    """
    u, w = _unit_gauss_legendre(order)
    lo, width = edges[..., :-1, None], np.diff(edges, axis=-1)[..., None]
    theta = lo + width * np.sin(np.pi * u / 2.0) ** 2
    jacobian = width * (np.pi / 2.0) * np.sin(np.pi * u)
    shape = edges.shape[:-1] + (-1,)
    return theta.reshape(shape), (jacobian * w).reshape(shape)


# --------------------------------------------------------------------------- geometry terms
class _Geometry:
    """Geometry-only terms of a set of (theta_i, theta_r, phi_r - phi_i), radians, 1-D."""

    def __init__(self, theta_i, phi_i, theta_r, phi_r):
        ti = np.minimum(np.ravel(np.asarray(theta_i, dtype=float)), _HORIZON)
        tr = np.minimum(np.ravel(np.asarray(theta_r, dtype=float)), _HORIZON)
        self.theta_i, self.theta_r = ti, tr
        self.delta_phi = np.ravel(np.asarray(phi_r, dtype=float) - np.asarray(phi_i, dtype=float))
        self.cos_i, self.sin_i = np.cos(ti), np.sin(ti)
        self.cos_r, self.sin_r = np.cos(tr), np.sin(tr)
        self.kinks = self._slope_kinks()

    def _slope_kinks(self) -> np.ndarray:
        """Facet slopes [rad] where the azimuthal average of eq 29/46 is not smooth.

        Onset of shadowing and masking (tan theta_a tan theta = 1, eq 39) and the slopes of
        the facets orthogonal to both s and v or to s and the azimuthally reversed v (where
        two critical azimuths of Table 2 cross).
        """
        ci, si, cr, sr, d = self.cos_i, self.sin_i, self.cos_r, self.sin_r, self.delta_phi
        kinks = [np.pi / 2.0 - self.theta_i, np.pi / 2.0 - self.theta_r]
        for sign in (1.0, -1.0):  # s x v and s x Rv (R: rotation by pi about the normal)
            cx = -sign * ci * sr * np.sin(d)
            cy = sign * ci * sr * np.cos(d) - si * cr
            cz = sign * si * sr * np.sin(d)
            kinks.append(np.arctan2(np.hypot(cx, cy), np.abs(cz)))
        return np.stack(kinks, axis=-1)

    def take(self, index: slice) -> "_Geometry":
        part = object.__new__(_Geometry)
        for name, value in vars(self).items():
            setattr(part, name, value[index])
        return part

    def __len__(self) -> int:
        return self.theta_i.size


def _slope_edges(geometry: _Geometry, sigma: float, top: float, extra: list[np.ndarray] | None = None) -> np.ndarray:
    """Sorted slope panel edges (G, P+1): 0, 2 sigma, 4 sigma, ..., top and the kinks."""
    ladder = 2.0 * sigma * np.arange(1.0, math.ceil(top / (2.0 * sigma)))
    fixed = np.concatenate([[0.0], ladder[ladder < top], [top]])
    kinks = geometry.kinks if extra is None else np.concatenate([geometry.kinks] + extra, axis=-1)
    edges = np.concatenate(
        [np.broadcast_to(fixed, (len(geometry), fixed.size)), np.clip(kinks, 0.0, top)], axis=-1
    )
    edges.sort(axis=-1)
    return edges


def _exact_chunk(geometry: _Geometry, sigma: float, rtol: float) -> tuple[np.ndarray, np.ndarray]:
    theta_order, phi_order, interreflection_order = _QUADRATURE[rtol]
    top = min(np.pi / 2.0, _tail_cut(rtol) * sigma)
    edges = _slope_edges(geometry, sigma, top)
    # only panels of non-zero width (kinks beyond the Gaussian's reach collapse onto it)
    row, panel = np.nonzero(np.diff(edges, axis=-1) > 0)
    theta_a, weight = _slope_nodes(np.stack([edges[row, panel], edges[row, panel + 1]], axis=-1), theta_order)
    weight = weight * _slope_weight(theta_a, sigma)
    column = (lambda a: a[row][:, None])
    h1, h2 = isotropic_brdf_terms(
        column(geometry.cos_i), column(geometry.sin_i), column(geometry.cos_r), column(geometry.sin_r),
        column(geometry.delta_phi), np.cos(theta_a), np.sin(theta_a), order=phi_order,
        interreflection_order=interreflection_order,
    )
    size = len(geometry)
    return (np.bincount(row, weights=np.sum(h1 * weight, axis=-1), minlength=size),
            np.bincount(row, weights=np.sum(h2 * weight, axis=-1), minlength=size))


def _components(
    geometry: _Geometry, sigma: float, chunk: Callable[..., tuple[np.ndarray, np.ndarray]], *args
) -> tuple[np.ndarray, np.ndarray]:
    if sigma == 0.0:
        return np.full(len(geometry), 1.0 / np.pi), np.zeros(len(geometry))
    f1, f2 = np.empty(len(geometry)), np.empty(len(geometry))
    for start in range(0, len(geometry), _CHUNK):
        part = slice(start, start + _CHUNK)
        f1[part], f2[part] = chunk(geometry.take(part), sigma, *args)
    return f1, f2


def _check_rtol(rtol: float) -> float:
    if rtol not in _QUADRATURE:
        raise ValueError(f"rtol = {rtol!r} is not one of the calibrated accuracies {list(RTOL_CHOICES)}")
    return float(rtol)


def _check_sigma(sigma: float) -> float:
    sigma = float(sigma)
    if not 0.0 <= sigma <= 90.0 or math.isnan(sigma):
        raise ValueError(f"sigma = {sigma:g} deg is outside its valid range [0, 90] deg")
    return sigma


def exact_components(
    theta_i: ArrayLike, phi_i: ArrayLike, theta_r: ArrayLike, phi_r: ArrayLike,
    sigma: float, rtol: float = 1e-6,
) -> tuple[np.ndarray, np.ndarray]:
    """Direct and interreflected parts of ``oren-nayar-exact``: BRDF = rho f1 + rho^2 f2.

    Parameters
    ----------
    theta_i, phi_i : array_like
        Source direction [deg], theta_i in [0, 90].
    theta_r, phi_r : array_like
        Viewing direction [deg], theta_r in [0, 90].
    sigma : float
        Standard deviation of the facet slope [deg], in [0, 90].
    rtol : float, optional
        Target relative accuracy, one of :data:`RTOL_CHOICES` (default 1e-6).

    Returns
    -------
    f1, f2 : numpy.ndarray
        [1/sr], broadcast shape of the angles.  f1 is the BRDF of the direct light per unit
        albedo; f2 the two-bounce interreflection per unit albedo squared.

    Notes
    -----
    f_k = integral_0^{pi/2} w(theta_a) h_k(theta_a) d theta_a with w the normalised
    Gaussian slope density (eq 8, 32; normalisation over [0, 90 deg], see the module
    notes) and h_k the exact azimuthal average over the cavity orientation (eq 29, 46) of
    the facet terms of Table 1 (GAF of eq 15) and eq 23-24.  The slope integral is split
    at the onsets of shadowing and masking (eq 39: theta_a = 90 deg - theta_i, 90 deg -
    theta_r), at the slopes where two critical azimuths cross, and at multiples of sigma;
    each panel uses a sin^2 change of variable (for the square-root onsets) and
    Gauss-Legendre nodes.  The azimuth integral is split at the ten critical azimuths (see
    :func:`~gonio.models.oren_nayar.single_slope.azimuth_breakpoints`).  The Gaussian is
    cut where its remaining weight is below rtol/100.  All geometries are evaluated
    together, in chunks.

    References
    ----------
    Oren & Nayar (1995), eq 8, 15, 23-24, 29, 32, Table 1-2, Figure 10.

    Examples
    --------
    >>> f1, f2 = exact_components(0.0, 0.0, 0.0, 0.0, sigma=0.0)   # footnote 10: Lambert
    >>> float(f1 * np.pi), float(f2)
    (1.0, 0.0)
    """
    sigma = _check_sigma(sigma)
    rtol = _check_rtol(rtol)
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (theta_i, phi_i, theta_r, phi_r)))
    geometry = _Geometry(*(np.radians(a) for a in arrays))
    f1, f2 = _components(geometry, math.radians(sigma), _exact_chunk, rtol)
    return f1.reshape(arrays[0].shape), f2.reshape(arrays[0].shape)


# --------------------------------------------------------------------------- eq 31
_NUMERICAL_ORDER = 12


def _numerical_chunk(geometry: _Geometry, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    ti, tr = geometry.theta_i[:, None], geometry.theta_r[:, None]
    top = min(np.pi / 2.0, _tail_cut(1e-12) * sigma)
    # A_3 of eq 45 switches on where phi_c^i + phi_c^r = pi/2: tan^2 theta_a = cot^2 ti + cot^2 tr
    overlap = np.arctan(np.hypot(np.cos(ti) / np.sin(np.maximum(ti, 1e-300)),
                                 np.cos(tr) / np.sin(np.maximum(tr, 1e-300))))
    edges = _slope_edges(geometry, sigma, top, [overlap])
    theta_a, weight = _slope_nodes(edges, _NUMERICAL_ORDER)
    weight = weight * _slope_weight(theta_a, sigma)
    d = geometry.delta_phi[:, None]
    # radiance per unit E0 cos(theta_i) and per unit rho (rho^2): pass rho = 1, e0 = 1/cos
    scale = 1.0 / np.cos(ti)
    h1 = isotropic_direct_radiance(ti, tr, d, theta_a, rho=1.0) * scale
    h2 = isotropic_interreflected_radiance(ti, tr, d, theta_a, rho=1.0) * scale
    return np.sum(h1 * weight, axis=-1), np.sum(h2 * weight, axis=-1)


def numerical_components(
    theta_i: ArrayLike, phi_i: ArrayLike, theta_r: ArrayLike, phi_r: ArrayLike, sigma: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Direct and interreflected parts of ``oren-nayar-numerical``: BRDF = rho f1 + rho^2 f2.

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [deg].
    sigma : float
        Standard deviation of the facet slope [deg], in [0, 90].

    Returns
    -------
    f1, f2 : numpy.ndarray
        [1/sr], broadcast shape of the angles.

    Notes
    -----
    Oren & Nayar eq 31 as the paper evaluated it (Figures 10-14, "numerical evaluation"):
    the isotropic single-slope radiance of the closed form eq 45 (the weighted sum eq 44
    of the in-plane and perpendicular exact results) plus the interreflection
    approximation eq 49, weighted by the Gaussian eq 32 (normalised over [0, 90 deg], see
    the module notes) and integrated over theta_a with Gauss-Legendre panels split at the
    onsets of shadowing/masking (eq 39) and of A_3.  Quadrature error < 1e-9 relative.

    References
    ----------
    Oren & Nayar (1995), eq 31-32, 45, 49.

    Examples
    --------
    >>> f1, f2 = numerical_components(30.0, 0.0, 30.0, 180.0, sigma=0.0)
    >>> float(f1 * np.pi), float(f2)
    (1.0, 0.0)
    """
    sigma = _check_sigma(sigma)
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (theta_i, phi_i, theta_r, phi_r)))
    geometry = _Geometry(*(np.radians(a) for a in arrays))
    f1, f2 = _components(geometry, math.radians(sigma), _numerical_chunk)
    return f1.reshape(arrays[0].shape), f2.reshape(arrays[0].shape)


# --------------------------------------------------------------------------- models
RHO = Param("rho", "-", 0.8, (0.0, 1.0), "albedo of the Lambertian facets")
SIGMA = Param("sigma", "deg", 20.0, (0.0, 90.0),
              "roughness: standard deviation of the facet slope angle (Gaussian, eq 32)")
RTOL = Option("rtol", 1e-6, RTOL_CHOICES,
              "target relative accuracy of the numerical integration over facet normals")


INTERREFLECTION = Option(
    "interreflection", True, (True, False),
    "include the two-bounce interreflection term rho^2 f2 (False: direct illumination only, "
    "the thin line of Fig 10)",
)


def _cached_by_sigma(compute: Callable[[float], tuple[np.ndarray, np.ndarray]], interreflection: bool = True):
    """f(rho, sigma) = rho f1 + rho^2 f2 (or rho f1 alone) with (f1, f2) computed once per sigma."""
    cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}

    def evaluate(rho: float, sigma: float) -> np.ndarray:
        if sigma not in cache:
            if len(cache) > 64:
                cache.clear()
            cache[sigma] = compute(math.radians(sigma))
        f1, f2 = cache[sigma]
        return rho * f1 + rho * rho * f2 if interreflection else rho * f1

    return evaluate


def _prepare_exact(theta_i, phi_i, theta_r, phi_r, rtol: float = 1e-6, interreflection: bool = True):
    arrays = np.broadcast_arrays(theta_i, phi_i, theta_r, phi_r)
    geometry = _Geometry(*arrays)
    shape = arrays[0].shape

    def compute(sigma: float):
        f1, f2 = _components(geometry, sigma, _exact_chunk, rtol)
        return f1.reshape(shape), f2.reshape(shape)

    return _cached_by_sigma(compute, interreflection)


def _prepare_numerical(theta_i, phi_i, theta_r, phi_r, interreflection: bool = True):
    arrays = np.broadcast_arrays(theta_i, phi_i, theta_r, phi_r)
    geometry = _Geometry(*arrays)
    shape = arrays[0].shape

    def compute(sigma: float):
        f1, f2 = _components(geometry, sigma, _numerical_chunk)
        return f1.reshape(shape), f2.reshape(shape)

    return _cached_by_sigma(compute, interreflection)


EXACT = register(
    Model(
        name="oren-nayar-exact",
        params=(RHO, SIGMA),
        reference=(
            "Oren & Nayar 1995, eq 8 with the Gaussian slope-area distribution eq 32, exact GAF "
            "(eq 15, Table 1) and two-bounce interreflection (eq 22-24), integrated numerically"
        ),
        description="V-cavity rough diffuse model integrated over facet normals (the reference)",
        prepare=_prepare_exact,
        options=(RTOL, INTERREFLECTION),
        linear_in=(),
    )
)

NUMERICAL = register(
    Model(
        name="oren-nayar-numerical",
        params=(RHO, SIGMA),
        reference=(
            "Oren & Nayar 1995, eq 31-32 with the single-slope closed form eq 45 and the "
            "interreflection approximation eq 49 (the paper's numerical evaluation, Figs 10-14)"
        ),
        description="rough diffuse model as evaluated numerically in the paper (eq 31)",
        prepare=_prepare_numerical,
        options=(INTERREFLECTION,),
    )
)
