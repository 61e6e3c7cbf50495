"""The surfaces gonio renders: what each kind is, its parameters and their ranges.

Every surface is made of Lambertian facets of albedo ``rho`` and is periodic in the mean
plane (z = 0, normal +z); angles are in degrees here, as at every public interface.

``VGroove(theta_a, phi_a, rho)``
    Parallel long symmetric V-grooves of one facet slope ``theta_a`` whose facet normals
    face the azimuths ``phi_a`` and ``phi_a + 180 deg``, tops in the mean plane: Oren &
    Nayar's uni-directional single-slope surface (1995, section 4.1, eq 27-28;
    anisotropic).  ``phi_a=None`` turns the grooves uniformly in azimuth: the isotropic
    single-slope surface of eq 29-30 and Appendix A.
``VGrooveField(sigma, rho)``
    Oren & Nayar's surface model (section 4.3, eq 31-32): isotropic V-grooves whose
    slopes follow the Gaussian slope-area distribution of standard deviation ``sigma``.
    The distribution is exactly the one of ``oren-nayar-exact``: density
    exp(-theta_a^2/(2 sigma^2)) sin(theta_a) over [0, 90 deg], the fraction of the *mean
    plane* (projected) area covered by grooves of each slope (the slope-area distribution,
    eq 6), orientations uniform.  All tops lie in the mean plane, so light leaving a groove
    above it escapes, and the field's BRDF is the slope- and orientation-weighted average
    of single-groove renders: each path draws its groove.
``HeightField(sigma, rho, cells, correlation, seed)``
    A periodic Gaussian random surface (:mod:`.heightfield`), triangulated, whose rms
    facet slope angle, weighted by projected area, equals that of the V-groove field of
    the same ``sigma`` (the mapping to Oren & Nayar's roughness, :func:`rms_slope_angle`).
``PittedPlane(psi, coverage, rho)``
    A plane with spherical pits of aperture ``psi`` whose orifices cover the fraction
    ``coverage`` (Koenderink, van Doorn, Dana & Nayar 1999); shallow pits (psi < 90 deg)
    included.

Every constructor checks its parameters and raises ``ValueError`` naming the parameter,
the value and the valid range.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np

__all__ = ["Surface", "VGroove", "VGrooveField", "HeightField", "PittedPlane", "KINDS", "rms_slope_angle",
           "HEIGHTFIELD_SIGMA_MAX"]

#: Largest roughness of the height field [deg] (module notes of :mod:`.heightfield`).
HEIGHTFIELD_SIGMA_MAX = 60.0


def _check(name: str, value: float, low: float, high: float, low_open: bool = False,
           high_open: bool = False) -> float:
    """``value`` as a float, or ValueError naming the parameter, the value and the range."""
    value = float(value)
    below = value <= low if low_open else value < low
    above = value >= high if high_open else value > high
    if math.isnan(value) or below or above:
        left, right = "(" if low_open else "[", ")" if high_open else "]"
        raise ValueError(f"{name} = {value:g} is outside its valid range {left}{low:g}, {high:g}{right}")
    return value


def _check_integer(name: str, value, low: int, high: int) -> int:
    if isinstance(value, bool) or not float(value).is_integer():
        raise ValueError(f"{name} = {value!r} must be an integer in [{low}, {high}]")
    value = int(value)
    if not low <= value <= high:
        raise ValueError(f"{name} = {value} is outside its valid range [{low}, {high}]")
    return value


@dataclass(frozen=True)
class Surface:
    """Base of the surface kinds: ``kind`` names it in specs, tables and caches."""

    kind: ClassVar[str] = ""
    #: True when the BRDF depends on theta_i, theta_r and phi_r - phi_i only.
    isotropic: ClassVar[bool] = True

    def parameters(self) -> dict[str, float | int | None]:
        """The parameters by name, as plain values (for cache keys and metadata)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class VGroove(Surface):
    """Parallel V-grooves of one slope (Oren & Nayar 1995, eq 28; eq 29 when isotropic).

    Parameters
    ----------
    theta_a : float
        Facet slope [deg], in [0, 90).
    phi_a : float or None
        Azimuth of one facet normal [deg]; the other facet faces phi_a + 180.  None: the
        grooves turn uniformly in azimuth (isotropic single-slope surface).
    rho : float
        Facet albedo [-], in [0, 1].
    """

    theta_a: float
    phi_a: float | None
    rho: float
    kind: ClassVar[str] = "vgroove"

    def __post_init__(self) -> None:
        object.__setattr__(self, "theta_a", _check("theta_a [deg]", self.theta_a, 0.0, 90.0, high_open=True))
        object.__setattr__(self, "rho", _check("rho", self.rho, 0.0, 1.0))
        if self.phi_a is not None:
            phi = float(self.phi_a)
            if not math.isfinite(phi):
                raise ValueError(f"phi_a = {phi!r} deg must be a finite azimuth (or omitted: isotropic grooves)")
            object.__setattr__(self, "phi_a", phi)

    @property
    def isotropic(self) -> bool:  # type: ignore[override]
        return self.phi_a is None


@dataclass(frozen=True)
class VGrooveField(Surface):
    """Isotropic V-grooves with Gaussian slopes (Oren & Nayar 1995, eq 31-32).

    Parameters
    ----------
    sigma : float
        Standard deviation of the facet slope [deg], in [0, 90] (the ``sigma`` of
        ``oren-nayar-exact``; 0 is a plane).
    rho : float
        Facet albedo [-], in [0, 1].
    """

    sigma: float
    rho: float
    kind: ClassVar[str] = "vgrooves"

    def __post_init__(self) -> None:
        object.__setattr__(self, "sigma", _check("sigma [deg]", self.sigma, 0.0, 90.0))
        object.__setattr__(self, "rho", _check("rho", self.rho, 0.0, 1.0))


@dataclass(frozen=True)
class HeightField(Surface):
    """A periodic Gaussian random height field of triangular facets (:mod:`.heightfield`).

    Parameters
    ----------
    sigma : float
        Roughness [deg], in [0, HEIGHTFIELD_SIGMA_MAX]: the rms facet slope angle
        (projected-area weighted) equals :func:`rms_slope_angle` of sigma, that of the
        V-groove field with this sigma.
    rho : float
        Facet albedo [-], in [0, 1].
    cells : int
        Grid points along each side of the period, in [16, 2048] (default 256).
    correlation : float
        Correlation length of the heights [cells], in [2, cells/8] (default 8): the
        correlation function is exp(-r^2/correlation^2).
    seed : int
        Seed of the realisation, >= 0 (default 0).
    """

    sigma: float
    rho: float
    cells: int = 256
    correlation: float = 8.0
    seed: int = 0
    kind: ClassVar[str] = "heightfield"

    def __post_init__(self) -> None:
        object.__setattr__(self, "sigma", _check("sigma [deg]", self.sigma, 0.0, HEIGHTFIELD_SIGMA_MAX))
        object.__setattr__(self, "rho", _check("rho", self.rho, 0.0, 1.0))
        cells = _check_integer("cells", self.cells, 16, 2048)
        object.__setattr__(self, "cells", cells)
        object.__setattr__(self, "correlation", _check("correlation [cells]", self.correlation, 2.0, cells / 8.0))
        object.__setattr__(self, "seed", _check_integer("seed", self.seed, 0, 2**63 - 1))


@dataclass(frozen=True)
class PittedPlane(Surface):
    """A plane with spherical pits (Koenderink et al. 1999).

    Parameters
    ----------
    psi : float
        Pit aperture [deg], in (0, 90]; 90 is the hemispherical pit.
    coverage : float
        Fraction of the plane covered by the orifices [-], in [0, 1].
    rho : float
        Albedo of pits and plane [-], in [0, 1].
    """

    psi: float
    coverage: float
    rho: float
    kind: ClassVar[str] = "pits"

    def __post_init__(self) -> None:
        object.__setattr__(self, "psi", _check("psi [deg]", self.psi, 0.0, 90.0, low_open=True))
        object.__setattr__(self, "coverage", _check("coverage", self.coverage, 0.0, 1.0))
        object.__setattr__(self, "rho", _check("rho", self.rho, 0.0, 1.0))


#: Every kind by its name in specs.
KINDS: dict[str, type[Surface]] = {cls.kind: cls for cls in (VGroove, VGrooveField, HeightField, PittedPlane)}


def rms_slope_angle(sigma: float) -> float:
    """Rms facet slope angle [deg] of the V-groove field of roughness ``sigma`` [deg].

    Parameters
    ----------
    sigma : float
        Standard deviation of the Gaussian slope-area distribution [deg] (eq 32).

    Returns
    -------
    float
        sqrt(E[theta_a^2]) over the slope-area (projected-area) density
        exp(-t^2/(2 sigma^2)) sin(t) / Z on [0, 90 deg] of ``oren-nayar-exact``; about
        sqrt(2) sigma for small sigma (the Gaussian is two-dimensional in the facet
        normal), less for large sigma (truncation at 90 deg).

    Notes
    -----
    This is the mapping of a height field's roughness onto Oren & Nayar's sigma: a height
    field "of roughness sigma" has this rms facet slope angle, weighted by projected area
    like the slope-area distribution (eq 6).

    Examples
    --------
    >>> round(rms_slope_angle(1.0) / 1.0, 4)   # sqrt(2) for small sigma
    1.4141
    """
    from ..models.oren_nayar.exact import _gaussian_slope_integral, slope_normalisation

    sigma = _check("sigma [deg]", sigma, 0.0, 90.0)
    if sigma == 0.0:
        return 0.0
    s = math.radians(sigma)
    mean_square = _gaussian_slope_integral(s, math.pi / 2.0, weight=np.square) / slope_normalisation(s)
    return math.degrees(math.sqrt(mean_square))
