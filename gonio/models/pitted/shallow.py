"""Pits of any aperture by the Monte Carlo method of Koenderink et al. (1999), section 4.1.

Orifice points are drawn uniformly (uniform on the disk is uniform on its projection
orthogonal to the viewing direction); for each one the visual ray is followed to the
cavity point it meets, the cast-shadow test decides whether that point is lit, and its
radiance is the Lambertian micro-radiance of the primary plus the diffuse irradiance
(eq 5, 11).  The mean radiance over the orifice divided by the plane irradiance is the
BRDF of the pit (eq 15); its standard error comes from the sample variance.

This is a stochastic *estimator* with a seed, used to check the deterministic
evaluations (the quadrature of :mod:`.quadrature` and the closed form of
:mod:`.closed_form` that the registered ``pitted`` model uses) and to render textons
(:mod:`.textons`).

References
----------
J. J. Koenderink, A. J. van Doorn, K. J. Dana, S. K. Nayar, IJCV 31(2/3), 1999,
section 4.1, Figs 11-12.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import cavity
from .interreflection import diffuse_irradiance
from .validation import check_pit_parameters

__all__ = ["MonteCarloEstimate", "uniform_disk_points", "orifice_radiance", "monte_carlo_brdf"]


@dataclass(frozen=True)
class MonteCarloEstimate:
    """A Monte Carlo BRDF estimate [1/sr] with its standard error [1/sr].

    Attributes
    ----------
    value : float
        Estimated BRDF of the pitted surface [1/sr].
    standard_error : float
        Standard error of ``value`` (sample standard deviation / sqrt(samples), at least
        the floor of :func:`_rare_lit_error` where few samples see the lit part) [1/sr].
    samples : int
        Number of orifice points.
    seed : int
        Seed of the random generator (``numpy.random.default_rng``).
    """

    value: float
    standard_error: float
    samples: int
    seed: int


def uniform_disk_points(samples: int, radius: float, rng: np.random.Generator) -> np.ndarray:
    """``samples`` points ``(samples, 2)`` uniform on a disk of ``radius``."""
    r = radius * np.sqrt(rng.random(samples))
    angle = 2.0 * np.pi * rng.random(samples)
    return np.stack([r * np.cos(angle), r * np.sin(angle)], axis=-1)


def orifice_radiance(
    orifice_xy: np.ndarray, theta_i: float, theta_r: float, epsilon: float, rho: float, psi: float
) -> np.ndarray:
    """Radiance seen through orifice points per unit normal irradiance of the beam [1/sr].

    Parameters
    ----------
    orifice_xy : numpy.ndarray
        Orifice points ``(..., 2)`` in units of the sphere radius (``|xy| <= sin psi``).
    theta_i : float
        Source co-elevation alpha [deg]; the source lies in the x-z plane, azimuth 0.
    theta_r, epsilon : float
        Viewer co-elevation beta and azimuth [deg] (epsilon 0: backward scattering).
    rho : float
        Micro-scale albedo [-].
    psi : float
        Aperture [deg].

    Returns
    -------
    numpy.ndarray
        ``(rho/pi) (m.i [lit] + H_diff)`` for beam normal irradiance H_perp = 1 [1/sr]
        (eq 5 with H(p) = H_prim(p) + H_diff, section 2.3; H_diff from eq 11).

    Examples
    --------
    >>> import numpy as np
    >>> float(orifice_radiance(np.zeros((1, 2)), 0.0, 0.0, 0.0, 1.0, 90.0)[0] * np.pi)
    1.5
    """
    psi_rad = np.radians(psi)
    source = cavity.unit_vector(np.radians(theta_i), 0.0)
    view = cavity.unit_vector(np.radians(theta_r), np.radians(epsilon))
    point, normal = cavity.cavity_point_seen(orifice_xy, view, psi_rad)
    primary = cavity.primary_irradiance(point, normal, source)
    diffuse = float(diffuse_irradiance(rho, psi)) * np.cos(np.radians(theta_i))  # eq 11
    return rho / np.pi * (primary + diffuse)


def monte_carlo_brdf(
    theta_i: float,
    theta_r: float,
    epsilon: float,
    rho: float,
    psi: float,
    coverage: float = 1.0,
    samples: int = 100_000,
    seed: int = 0,
) -> MonteCarloEstimate:
    """BRDF of the pitted surface by Monte Carlo over the orifice (section 4.1) [1/sr].

    Parameters
    ----------
    theta_i : float
        Source co-elevation alpha [deg], 0 <= alpha < 90.
    theta_r : float
        Viewer co-elevation beta [deg], 0 <= beta < 90.
    epsilon : float
        Viewer azimuth relative to the source azimuth [deg] (0: backward, 180: forward).
    rho : float
        Micro-scale albedo [-].
    psi : float
        Aperture [deg], 0 < psi <= 90.
    coverage : float
        Fraction of the plane covered by pits [-]; the rest is flat Lambertian.
    samples : int
        Number of orifice points.
    seed : int
        Seed for ``numpy.random.default_rng``.

    Returns
    -------
    MonteCarloEstimate
        BRDF estimate and standard error.  The flat part ``(1 - coverage) rho/pi`` is
        exact; only the pit part is sampled.

    Notes
    -----
    Section 4.1 (Figs 11-12): the average radiance over the orifice, divided by the plane
    irradiance ``H_perp cos(alpha)`` (eq 1), is the pit's BRDF (eq 15).

    Examples
    --------
    >>> est = monte_carlo_brdf(30.0, 70.0, 180.0, rho=1.0, psi=90.0, samples=20000)  # eq 30 region
    >>> abs(est.value - 1 / (2 * 3.141592653589793)) < 5 * est.standard_error + 1e-12
    True
    """
    rho, psi, coverage = check_pit_parameters(rho=rho, psi=psi, coverage=coverage)
    for label, angle in (("theta_i", theta_i), ("theta_r", theta_r)):
        if not 0.0 <= angle < 90.0:
            raise ValueError(f"{label} = {angle:g} deg must lie in [0, 90) deg for the Monte Carlo estimate")
    if int(samples) < 2:
        raise ValueError(f"samples = {samples!r} must be an integer >= 2")
    rng = np.random.default_rng(seed)
    points = uniform_disk_points(int(samples), np.sin(np.radians(psi)), rng)
    cos_i = np.cos(np.radians(theta_i))
    values = orifice_radiance(points, theta_i, theta_r, epsilon, rho, psi) / cos_i
    pit = float(values.mean())
    diffuse_only = rho / np.pi * float(diffuse_irradiance(rho, psi))  # a sample no direct light reaches
    error = max(float(values.std(ddof=1) / np.sqrt(values.size)), _rare_lit_error(values, diffuse_only, rho, cos_i))
    flat = (1.0 - coverage) * rho / np.pi
    return MonteCarloEstimate(coverage * pit + flat, coverage * error, int(samples), int(seed))


def _rare_lit_error(values: np.ndarray, diffuse_only: float, rho: float, cos_i: float) -> float:
    """Floor of the standard error where few samples see the lit part of the cavity [1/sr].

    At a grazing source or view the lit-and-visible part of the orifice can be so small that
    no sample lands in it: the estimate is then the diffuse term alone, and the samples'
    own scatter says its error is zero although the lit part it missed may carry most of
    the BRDF (found by benchmarks/validity_atlas.py: -93 % with a standard error of 1e-19).
    The floor is the part of the error that the lit fraction's uncertainty carries: the
    mean contribution of a lit sample (at most ``rho / (pi cos theta_i)``, primary
    irradiance m.i <= 1, when none was lit) times the standard error of the lit fraction,
    taken with one more hit and one more miss than counted (``(k + 1) / (n + 2)``) so that
    no hits do not mean no uncertainty. Where many samples are lit the samples' own scatter
    already holds this part and exceeds the floor. Decision: this floor, rather than
    refusing the geometry.
    """
    n = values.size
    lit = values > diffuse_only * (1.0 + 1e-9)
    k = int(np.count_nonzero(lit))
    contribution = float(np.mean(values[lit]) - diffuse_only) if k else rho / (np.pi * cos_i)
    fraction = (k + 1.0) / (n + 2.0)
    return float(contribution * np.sqrt(fraction * (1.0 - fraction) / n))