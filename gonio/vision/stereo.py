"""Photometric stereo under Lambert's model and under any reflectance model, with the
uncertainty of each recovered orientation (Oren & Nayar 1995, section 6.3, Figs 26-27;
Woodham 1980).

K images of a shape are taken by an orthographic camera looking along ``-v`` (``v`` the
direction towards the camera), each under one distant source ``s_k`` of irradiance
``E_k`` on a surface facing it. A pixel of unit normal ``n`` has the radiance
(:func:`gonio.vision.shading.render`)

    I_k = c E_k f_r(theta_i, theta_r, dphi) cos(theta_i),   0 in attached shadow,

with the angles of ``n`` to ``s_k`` and ``v`` and ``c`` the pixel's albedo scale (1: the
model's own albedo).

**Lambertian least squares** (Woodham 1980; the paper's Fig 26(a)): with ``f_r = 1/pi``
the radiance is linear in ``g = c n / pi``, ``I_k = E_k s_k . g``, solved per pixel by
least squares over the sources that light it (``I_k > 0``; all sources where fewer than
three do), ``n = g / |g|`` and ``c = pi |g|`` (Lambert's albedo). Decision: shadowed
readings are left out rather than fitted as ``s_k . g = 0``; that is the common practice
and it favours Lambert, the baseline.

**Inversion of a model** (Fig 26(b)): the weighted sum of squared residuals is minimised
over the normal and, unless the albedo is known, over ``c`` (solved in closed form for a
given normal). First the best of a few thousand normals spread evenly over the visible
hemisphere (a Fibonacci lattice) is taken at each pixel, so no local minimum near a
wrong orientation traps the fit; then Levenberg-Marquardt on the normal's tangent-plane
coordinates, ``n(a, b) = (n0 + a t1 + b t2) / |n0 + a t1 + b t2|``, with the Jacobian by
central differences (the model is any callable).

**Uncertainty.** At the solution the covariance of ``(a, b[, c])`` is
``(J^T W J)^-1`` times a variance factor, with ``W`` the inverse variances of the
readings. With the noise stated the factor is the reduced chi-square pooled over all
pixels when it exceeds 1, else 1: readings scattered more than the stated noise allows
(texture, or a model that is not the surface's: a fitted formula inverted on a rendered
micro-surface leaves a reduced chi-square near 1.4) widen every region by the measured
factor, as a Birge ratio does. Without stated noise the factor is the pooled residual
variance itself. Either needs more readings than unknowns somewhere. When the model comes with posterior draws (a fit), each draw's
model is inverted again from the solution and the scatter of the draws' normals is added
to the covariance. The 95 % region of the orientation is the ellipse
``d^T C^-1 d <= chi2_2(0.95) = -2 ln 0.05`` in the tangent coordinates (gnomonic: ``d`` of
a direction ``m`` is ``(t1 . m, t2 . m) / (n . m)``); :meth:`StereoResult.covers` tests a
true normal against it.

With two sources (the paper's vase, sources at -10 and +10 deg) and a known albedo the
normal is determined up to its mirror image in the plane of the two sources; the
candidate search returns one of the two.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from .shading import Brdf, direction, local_angles

__all__ = ["StereoResult", "angular_error", "tangent_basis", "lambertian_stereo", "photometric_stereo",
           "region_radius2", "variance_factor", "summary", "height_profile"]

#: Candidate normals of the initial search over the visible hemisphere (about 1.8 deg apart).
DEFAULT_CANDIDATES = 6000
#: Levenberg-Marquardt iterations of the refinement (and of each posterior draw's re-solve).
DEFAULT_ITERATIONS = 20
DRAW_ITERATIONS = 8
#: Step of the central differences of the Jacobian [rad].
DIFFERENCE_STEP = 1e-4
#: Largest condition number of an information matrix taken as invertible.
MAX_CONDITION = 1e10
#: Pixels per block of the candidate search (blocks x candidates temporaries).
_BLOCK = 512


def region_radius2(level: float = 0.95, dof: int = 2) -> float:
    """Squared Mahalanobis radius of a ``level`` region of a Gaussian in ``dof``
    dimensions, ``chi2_dof^-1(level)`` (2-D: ``-2 ln(1 - level)``).

    >>> round(region_radius2(0.95), 4), round(region_radius2(0.95, 1), 4)
    (5.9915, 3.8415)
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level!r}")
    from scipy.stats import chi2

    return float(chi2.ppf(level, dof))


@dataclass
class StereoResult:
    """Orientations recovered by photometric stereo.

    Attributes
    ----------
    normals : numpy.ndarray, shape (H, W, 3)
        Unit normals; NaN where nothing was recovered (off the mask, too few readings).
    scale : numpy.ndarray, shape (H, W)
        Albedo scale ``c`` (module notes): Lambert's albedo for :func:`lambertian_stereo`,
        the ratio of the image to the model's prediction for a model.
    covariance : numpy.ndarray, shape (H, W, 2, 2), or None
        Covariance of the normal's tangent coordinates in ``basis`` [rad^2]; None when
        neither the noise was stated nor could be estimated.
    basis : numpy.ndarray, shape (H, W, 2, 3)
        The tangent vectors ``t1, t2`` of each normal.
    rms_residual : numpy.ndarray, shape (H, W)
        Root-mean-square of the residuals in units of the noise (1 when model and noise
        agree), or in radiance when no noise was stated.
    method : str
        ``"lambert"`` or the model's description.
    variance_factor : float or None
        What multiplied ``(J^T W J)^-1`` (:func:`variance_factor`): above 1 when the
        residuals exceed the stated noise.
    dof : int
        Degrees of freedom of an orientation: 2, or 1 for normals held in a plane (the
        second tangent vector is then the plane's axis, its variance 0).
    """

    normals: np.ndarray
    scale: np.ndarray
    covariance: np.ndarray | None
    basis: np.ndarray
    rms_residual: np.ndarray
    method: str
    variance_factor: float | None = None
    dof: int = 2

    def cone_deg(self, level: float = 0.95) -> np.ndarray:
        """Half-angle of the cone about each normal that holds its ``level`` region [deg]
        (the region's long semi-axis); NaN without a covariance."""
        if self.covariance is None:
            return np.full(self.scale.shape, np.nan)
        bounded = np.all(np.isfinite(self.covariance), axis=(-2, -1))
        longest = np.full(self.scale.shape, np.inf)
        longest[bounded] = np.linalg.eigvalsh(self.covariance[bounded])[..., -1]
        cone = np.degrees(np.arctan(np.sqrt(region_radius2(level, self.dof) * np.clip(longest, 0.0, None))))
        return np.where(np.isfinite(self.normals[..., 0]), cone, np.nan)

    @property
    def determined(self) -> np.ndarray:
        """Pixels whose normal the readings determine (a bounded region), shape (H, W)."""
        if self.covariance is None:
            return np.isfinite(self.normals[..., 0])
        return np.isfinite(self.normals[..., 0]) & np.all(np.isfinite(self.covariance), axis=(-2, -1))

    def covers(self, true_normals: np.ndarray, level: float = 0.95) -> np.ndarray:
        """Whether each true normal lies in the ``level`` region of the recovered one
        (module notes); True where the region is the whole hemisphere (not
        :attr:`determined`), False where nothing was recovered or no covariance exists."""
        if self.covariance is None:
            return np.zeros(self.scale.shape, bool)
        d = _tangent_coordinates(self.normals, self.basis, np.asarray(true_normals, float))
        inside = np.zeros(self.scale.shape, bool)
        bounded = self.determined
        if self.dof == 1:  # a segment of the plane: the true normal must lie in it
            d, c = d[bounded], self.covariance[bounded]
            distance2 = np.where(np.abs(d[:, 1]) < 1e-6, d[:, 0] ** 2 / c[:, 0, 0], np.inf)
        else:
            distance2 = np.einsum("pi,pij,pj->p", d[bounded], np.linalg.inv(self.covariance[bounded]), d[bounded])
        inside[bounded] = distance2 <= region_radius2(level, self.dof)
        recovered = np.isfinite(self.normals[..., 0])
        return inside | (recovered & ~bounded)


def summary(result: StereoResult, true_normals: np.ndarray | None = None, where: np.ndarray | None = None,
            level: float = 0.95) -> dict[str, float]:
    """Figures of a recovery over the pixels ``where`` (default: every recovered pixel):
    pixels recovered and determined, the median 95 % cone [deg], and with the true
    normals the mean, median and 95th-percentile angular error [deg] and the fraction of
    true normals inside their ``level`` regions."""
    recovered = np.isfinite(result.normals[..., 0])
    where = recovered if where is None else (np.asarray(where, bool) & recovered)
    out = {"pixels": int(np.sum(where)), "determined": int(np.sum(where & result.determined)),
           "median_cone_deg": float(np.median(result.cone_deg(level)[where & result.determined]))
           if np.any(where & result.determined) and result.covariance is not None else float("nan")}
    if true_normals is not None and np.any(where):
        error = angular_error(result.normals, true_normals)[where]
        out |= {"mean_error_deg": float(np.mean(error)), "median_error_deg": float(np.median(error)),
                "p95_error_deg": float(np.percentile(error, 95)),
                "coverage": float(np.mean(result.covers(true_normals, level)[where]))
                if result.covariance is not None else float("nan")}
    return out


def height_profile(normals: np.ndarray, spacing: float = 1.0, anchor: int | None = None) -> np.ndarray:
    """Height along a row of normals (the paper's Fig 27): the slope ``dz/dx = -n_x / n_z``
    integrated by the trapezoid rule over the finite run around ``anchor`` (default: the
    middle), height 0 at ``anchor`` [units of ``spacing``]; NaN outside the run.

    >>> x = np.linspace(-0.5, 0.5, 5)
    >>> row = np.stack([x, np.zeros(5), np.sqrt(1 - x**2)], axis=-1)  # a unit sphere's middle row
    >>> (height_profile(row, 0.25) - (np.sqrt(1 - x**2) - 1)).round(2).tolist()
    [-0.0, -0.0, 0.0, -0.0, -0.0]
    """
    normals = np.asarray(normals, float)
    with np.errstate(divide="ignore", invalid="ignore"):  # off the shape: no normal
        slope = np.where(normals[:, 2] > 0, -normals[:, 0] / normals[:, 2], np.nan)
    anchor = len(slope) // 2 if anchor is None else int(anchor)
    finite = np.isfinite(slope)
    if not finite[anchor]:
        return np.full(len(slope), np.nan)
    lo, hi = anchor, anchor
    while lo > 0 and finite[lo - 1]:
        lo -= 1
    while hi < len(slope) - 1 and finite[hi + 1]:
        hi += 1
    out = np.full(len(slope), np.nan)
    steps = np.concatenate([[0.0], np.cumsum(0.5 * (slope[lo:hi] + slope[lo + 1:hi + 1]) * spacing)])
    out[lo:hi + 1] = steps - steps[anchor - lo]
    return out


def angular_error(normals: np.ndarray, true_normals: np.ndarray) -> np.ndarray:
    """Angle between recovered and true unit normals [deg]; NaN where either is NaN.

    >>> float(angular_error(np.array([0.0, 0.0, 1.0]), direction(10.0)).round(9))
    10.0
    """
    cosine = np.sum(np.asarray(normals, float) * np.asarray(true_normals, float), axis=-1)
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def tangent_basis(normals: np.ndarray) -> np.ndarray:
    """Two unit vectors ``t1, t2`` perpendicular to each unit normal and to each other,
    shape ``(..., 2, 3)``; ``t1`` is horizontal (perpendicular to z) unless the normal is."""
    normals = np.asarray(normals, float)
    helper = np.where((np.abs(normals[..., 2]) < 0.9)[..., None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    t1 = np.cross(helper, normals)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    return np.stack([t1, np.cross(normals, t1)], axis=-2)


def _tilted(normals: np.ndarray, basis: np.ndarray, a: np.ndarray | float, b: np.ndarray | float) -> np.ndarray:
    """``n(a, b)`` of the module notes."""
    moved = normals + np.asarray(a)[..., None] * basis[..., 0, :] + np.asarray(b)[..., None] * basis[..., 1, :]
    return moved / np.linalg.norm(moved, axis=-1, keepdims=True)


def _tangent_coordinates(normals: np.ndarray, basis: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Gnomonic coordinates ``(t1 . m, t2 . m) / (n . m)`` of directions ``m``."""
    along = np.sum(normals * other, axis=-1)
    return np.einsum("...ij,...j->...i", basis, other) / along[..., None]


def shading(brdf: Brdf, normals: np.ndarray, lights: np.ndarray, view: np.ndarray,
            irradiance: np.ndarray) -> np.ndarray:
    """Radiance of unit albedo scale at normals (P, 3) under each source (K, 3): shape
    (P, K); 0 in attached shadow and where the camera sees the surface from behind."""
    out = np.zeros((normals.shape[0], lights.shape[0]))
    for k, light in enumerate(lights):
        theta_i, theta_r, dphi = local_angles(normals, light, view)
        lit = (theta_i < 90.0) & (theta_r < 90.0)
        if np.any(lit):
            values = np.asarray(brdf(theta_i[lit], 0.0, theta_r[lit], dphi[lit]), float)
            out[lit, k] = values * irradiance[k] * np.cos(np.radians(theta_i[lit]))
    return out


def hemisphere_normals(count: int, view: np.ndarray) -> np.ndarray:
    """``count`` unit normals spread evenly (equal area, Fibonacci lattice) over the
    hemisphere about ``view``, shape (count, 3)."""
    j = np.arange(count) + 0.5
    z = 1.0 - j / count
    azimuth = np.pi * (3.0 - np.sqrt(5.0)) * j
    r = np.sqrt(1.0 - z**2)
    local = np.stack([r * np.cos(azimuth), r * np.sin(azimuth), z], axis=-1)
    t1, t2 = tangent_basis(view)
    return local[:, :1] * t1 + local[:, 1:2] * t2 + local[:, 2:] * view


def _best_candidates(observed: np.ndarray, weights: np.ndarray, predicted: np.ndarray,
                     known_scale: bool) -> np.ndarray:
    """Index of the candidate (rows of ``predicted``, (C, K)) that fits each pixel's
    readings (P, K) best, the scale profiled out (or fixed at 1)."""
    best = np.empty(observed.shape[0], int)
    for start in range(0, observed.shape[0], _BLOCK):
        block = slice(start, start + _BLOCK)
        cross = (weights[block] * observed[block]) @ predicted.T
        power = weights[block] @ (predicted**2).T
        if known_scale:
            gain = 2.0 * cross - power
        else:
            gain = np.divide(cross**2, power, out=np.zeros_like(cross), where=(power > 0) & (cross > 0))
        best[block] = np.argmax(gain, axis=1)
    return best


def plane_basis(normals: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Tangent vectors of normals held perpendicular to ``axis``: ``t1`` in the plane of
    the normals, ``t2`` the axis, shape ``(..., 2, 3)``."""
    t1 = np.cross(axis, normals)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    return np.stack([t1, np.broadcast_to(axis, t1.shape)], axis=-2)


def plane_normals(count: int, view: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """``count`` unit normals evenly spaced over the half circle perpendicular to ``axis``
    that faces ``view``, shape (count, 3)."""
    facing = view - (view @ axis) * axis
    facing /= np.linalg.norm(facing)
    across = np.cross(axis, facing)
    angle = np.linspace(-0.5 * np.pi, 0.5 * np.pi, count + 2)[1:-1]
    return np.cos(angle)[:, None] * facing + np.sin(angle)[:, None] * across


@dataclass
class _Problem:
    """One inversion: the readings of P pixels under K sources and what predicts them;
    with an ``axis`` the normals are held perpendicular to it (one tangent direction)."""

    brdf: Brdf
    observed: np.ndarray       # (P, K) radiance, 0 where missing
    weights: np.ndarray        # (P, K) inverse variances, 0 where missing
    lights: np.ndarray         # (K, 3)
    view: np.ndarray           # (3,)
    irradiance: np.ndarray     # (K,)
    known_scale: bool
    axis: np.ndarray | None = None

    @property
    def directions(self) -> int:
        """Free tangent directions of a normal: 2, or 1 in a plane."""
        return 2 if self.axis is None else 1

    def basis(self, normals: np.ndarray) -> np.ndarray:
        return tangent_basis(normals) if self.axis is None else plane_basis(normals, self.axis)

    def predict(self, normals: np.ndarray) -> np.ndarray:
        return shading(self.brdf, normals, self.lights, self.view, self.irradiance)

    def cost(self, normals: np.ndarray, scale: np.ndarray) -> np.ndarray:
        residual = self.observed - scale[:, None] * self.predict(normals)
        return np.sum(self.weights * residual**2, axis=1)

    def best_scale(self, normals: np.ndarray) -> np.ndarray:
        if self.known_scale:
            return np.ones(normals.shape[0])
        m = self.predict(normals)
        power = np.sum(self.weights * m**2, axis=1)
        return np.divide(np.sum(self.weights * m * self.observed, axis=1), power,
                         out=np.zeros_like(power), where=power > 0)

    def jacobian(self, normals: np.ndarray, scale: np.ndarray, basis: np.ndarray) -> np.ndarray:
        """d(prediction)/d(a[, b][, c]), shape (P, K, 1 to 3)."""
        h = DIFFERENCE_STEP
        columns = [(self.predict(_tilted(normals, basis, h * e[0], h * e[1]))
                    - self.predict(_tilted(normals, basis, -h * e[0], -h * e[1]))) / (2.0 * h) * scale[:, None]
                   for e in ((1.0, 0.0), (0.0, 1.0))[:self.directions]]
        if not self.known_scale:
            columns.append(self.predict(normals))
        return np.stack(columns, axis=-1)


def _refine(problem: _Problem, normals: np.ndarray, scale: np.ndarray,
            iterations: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Levenberg-Marquardt from ``normals`` and ``scale``: the refined normals, scales and
    weighted sums of squares."""
    cost = problem.cost(normals, scale)
    damping = np.full(normals.shape[0], 1e-3)
    for _ in range(iterations):
        basis = problem.basis(normals)
        jac = problem.jacobian(normals, scale, basis)
        residual = problem.observed - scale[:, None] * problem.predict(normals)
        normal_matrix = np.einsum("pk,pki,pkj->pij", problem.weights, jac, jac)
        gradient = np.einsum("pk,pki,pk->pi", problem.weights, jac, residual)
        diagonal = np.einsum("pii->pi", normal_matrix)
        damped = normal_matrix + np.einsum("p,pi,ij->pij", damping, diagonal + 1e-12, np.eye(jac.shape[-1]))
        step = np.linalg.solve(damped, gradient[..., None])[..., 0]
        along = step[:, 1] if problem.directions == 2 else 0.0
        trial_normals = _tilted(normals, basis, step[:, 0], along)
        trial_scale = scale + step[:, problem.directions] if not problem.known_scale else scale
        trial_cost = problem.cost(trial_normals, trial_scale)
        better = trial_cost < cost
        normals = np.where(better[:, None], trial_normals, normals)
        scale = np.where(better, trial_scale, scale)
        cost = np.where(better, trial_cost, cost)
        damping = np.where(better, damping / 3.0, damping * 4.0)
    return normals, scale, cost


def _well_conditioned(matrices: np.ndarray) -> np.ndarray:
    """Which of the stacked information matrices can be inverted (condition below 1e10)."""
    finite = np.all(np.isfinite(matrices), axis=(-2, -1))
    out = np.zeros(matrices.shape[0], bool)
    out[finite] = np.linalg.cond(matrices[finite]) < MAX_CONDITION
    return out


def _covariance(problem: _Problem, normals: np.ndarray, scale: np.ndarray, basis: np.ndarray,
                variance_factor: float) -> np.ndarray:
    """Covariance of the tangent coordinates (P, 2, 2) [rad^2]: ``(J^T W J)^-1`` times the
    variance factor (1 with stated noise); infinite where the readings do not determine
    the normal (fewer lit readings than unknowns: the region is the whole hemisphere)."""
    jac = problem.jacobian(normals, scale, basis)
    information = np.einsum("pk,pki,pkj->pij", problem.weights, jac, jac)
    determined = _well_conditioned(information)
    out = np.full((normals.shape[0], 2, 2), np.inf)
    out[determined] = 0.0
    f = problem.directions
    out[determined, :f, :f] = np.linalg.inv(information[determined])[:, :f, :f] * variance_factor
    return out


def _draws_scatter(problem: _Problem, draws: Sequence[Brdf], normals: np.ndarray, scale: np.ndarray,
                   basis: np.ndarray) -> np.ndarray:
    """Covariance (P, 2, 2) of the tangent coordinates of the normals that each posterior
    draw's model recovers, re-solved from the solution."""
    coordinates = []
    for brdf in draws:
        drawn = _Problem(brdf, problem.observed, problem.weights, problem.lights, problem.view,
                         problem.irradiance, problem.known_scale, problem.axis)
        moved, _, _ = _refine(drawn, normals, scale, DRAW_ITERATIONS)
        coordinates.append(_tangent_coordinates(normals, basis, moved))
    d = np.stack(coordinates) - np.mean(coordinates, axis=0)
    return np.einsum("dpi,dpj->pij", d, d) / max(len(draws) - 1, 1)


def _checked_inputs(images: Any, light_directions: Any, mask: Any, irradiance: Any,
                    noise_sd: Any, minimum_sources: int) -> tuple[np.ndarray, ...]:
    """Images (K, H, W), unit lights (K, 3), mask (H, W), irradiance (K,) and noise
    standard deviations (K, H, W) or None, checked."""
    images = np.asarray(images, float)
    if images.ndim != 3:
        raise ValueError(f"images must have shape (K, H, W) (one radiance image per source), got {images.shape}")
    lights = np.asarray(light_directions, float)
    if lights.ndim == 2 and lights.shape[1] == 2:
        lights = np.stack([direction(theta, phi) for theta, phi in lights])
    if lights.shape != (images.shape[0], 3):
        raise ValueError(f"light_directions must be {images.shape[0]} unit vectors (K, 3) or (theta, phi) pairs in "
                         f"degrees (K, 2), one per image; got shape {lights.shape}")
    if images.shape[0] < minimum_sources:
        raise ValueError(f"photometric stereo needs at least {minimum_sources} images here, got {images.shape[0]}")
    lights = lights / np.linalg.norm(lights, axis=1, keepdims=True)
    mask = np.all(np.isfinite(images), axis=0) if mask is None else np.asarray(mask, bool)
    if mask.shape != images.shape[1:]:
        raise ValueError(f"mask must have the images' shape {images.shape[1:]}, got {mask.shape}")
    irradiance = np.broadcast_to(np.asarray(irradiance, float), (images.shape[0],)).copy()
    if np.any(~np.isfinite(irradiance)) or np.any(irradiance <= 0):
        raise ValueError(f"irradiance must be positive and finite, got {irradiance}")
    if noise_sd is not None:
        noise_sd = np.broadcast_to(np.asarray(noise_sd, float), images.shape)
        if np.any(~(noise_sd > 0)):
            raise ValueError("noise_sd must be positive (the standard deviation of the image values, in radiance)")
    return images, lights, mask, irradiance, noise_sd


def _readings(images: np.ndarray, mask: np.ndarray, noise_sd: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The masked pixels' readings (P, K) and weights (inverse variances; 1 without stated
    noise; 0 where a reading is missing)."""
    observed = np.moveaxis(images[:, mask], 0, -1)
    weights = np.ones_like(observed) if noise_sd is None else np.moveaxis(noise_sd[:, mask], 0, -1) ** -2.0
    missing = ~np.isfinite(observed)
    return np.where(missing, 0.0, observed), np.where(missing, 0.0, weights)


def _pooled_variance(cost: np.ndarray, weights: np.ndarray, unknowns: int) -> float | None:
    """Residual variance pooled over pixels (per unit weight), None without spare readings."""
    finite = np.isfinite(cost)
    spare = int(np.sum(np.maximum(np.sum(weights[finite] > 0, axis=1) - unknowns, 0)))
    return float(np.sum(cost[finite]) / spare) if spare > 0 else None


def variance_factor(cost: np.ndarray, weights: np.ndarray, unknowns: int, stated: bool) -> float | None:
    """What multiplies ``(J^T W J)^-1`` (module notes): with stated noise the pooled reduced
    chi-square when it exceeds 1 (the residuals show what the stated noise leaves out,
    model discrepancy included), else 1; without, the pooled residual variance (None
    without spare readings)."""
    pooled = _pooled_variance(cost, weights, unknowns)
    if not stated:
        return pooled
    return 1.0 if pooled is None else max(1.0, pooled)


def _as_images(mask: np.ndarray, values: np.ndarray, fill: float = np.nan) -> np.ndarray:
    out = np.full(mask.shape + values.shape[1:], fill)
    out[mask] = values
    return out


def _result(mask: np.ndarray, normals: np.ndarray, scale: np.ndarray, covariance: np.ndarray | None,
            basis: np.ndarray, cost: np.ndarray, weights: np.ndarray, method: str, factor: float | None,
            dof: int = 2) -> StereoResult:
    """The per-pixel arrays put back into images."""
    used = np.maximum(np.sum(weights > 0, axis=1), 1)
    rms = np.sqrt(cost / used)
    return StereoResult(_as_images(mask, normals), _as_images(mask, scale),
                        None if covariance is None else _as_images(mask, covariance),
                        _as_images(mask, basis), _as_images(mask, rms), method, factor, dof)


def lambertian_stereo(images: Any, light_directions: Any, mask: Any = None, irradiance: Any = 1.0,
                      noise_sd: Any = None) -> StereoResult:
    """Lambertian least-squares photometric stereo (Woodham 1980; module notes).

    Parameters
    ----------
    images : array_like, shape (K, H, W)
        Radiance images, one per source, K >= 3 [W m^-2 sr^-1]; NaN where not seen.
    light_directions : array_like, shape (K, 3) or (K, 2)
        Directions towards the sources (unit vectors, or polar and azimuth angles [deg]).
    mask : array_like of bool, shape (H, W), optional
        Pixels to recover (default: finite in every image).
    irradiance : float or array_like, shape (K,)
        Irradiance of a surface facing each source [W/m^2].
    noise_sd : float or array_like, optional
        Standard deviation of the image values [radiance], broadcast to the images; without
        it the variance is estimated from the residuals.

    Returns
    -------
    StereoResult
        ``scale`` holds Lambert's albedo.
    """
    images, lights, mask, irradiance, noise_sd = _checked_inputs(images, light_directions, mask, irradiance,
                                                                 noise_sd, 3)
    observed, weights = _readings(images, mask, noise_sd)
    lit = observed > 0
    weights = np.where((np.sum(lit & (weights > 0), axis=1) >= 3)[:, None], weights * lit, weights)
    rows = lights * irradiance[:, None]
    information = np.einsum("pk,ki,kj->pij", weights, rows, rows)
    solvable = _well_conditioned(information)
    g = np.full((observed.shape[0], 3), np.nan)
    inverse = np.full(information.shape, np.nan)
    inverse[solvable] = np.linalg.inv(information[solvable])
    g[solvable] = np.einsum("pij,kj,pk,pk->pi", inverse[solvable], rows, weights[solvable], observed[solvable])
    length = np.linalg.norm(g, axis=1)
    normals = g / length[:, None]
    cost = np.sum(weights * (observed - g @ rows.T) ** 2, axis=1)
    factor = variance_factor(cost, weights, 3, noise_sd is not None)
    basis = tangent_basis(np.where(solvable[:, None], normals, [0.0, 0.0, 1.0]))
    covariance = None if factor is None else \
        np.einsum("pai,pij,pbj->pab", basis, inverse, basis) / length[:, None, None] ** 2 * factor
    return _result(mask, normals, np.pi * length, covariance, basis, cost, weights, "lambert", factor)


def _model_of(model: Any, draws: int) -> tuple[Brdf, list[Brdf], str]:
    """The BRDF to invert, its posterior draws' BRDFs and a description, from a callable,
    a material (:class:`gonio.export.Material`), a model spec, a fit folder or a FitResult."""
    if callable(model) and not hasattr(model, "draw_brdf"):
        return model, [], getattr(model, "__name__", "model")
    if not hasattr(model, "draw_brdf"):
        from gonio.export import material_of

        model = material_of(model, max_draws=max(draws, 1))
    rows = range(min(len(model.draws), draws)) if model.draws is not None else ()
    drawn = [lambda ti, pi, tr, pr, k=k: model.draw_brdf(ti, pi, tr, pr, np.array([k]))[0] for k in rows]
    return model.brdf, drawn, model.source or model.model


def photometric_stereo(images: Any, light_directions: Any, model: Any = None, mask: Any = None, *,
                       view: Sequence[float] = (0.0, 0.0, 1.0), irradiance: Any = 1.0, noise_sd: Any = None,
                       albedo_known: bool = False, in_plane_of: Sequence[float] | None = None, draws: int = 20,
                       candidates: int = DEFAULT_CANDIDATES, iterations: int = DEFAULT_ITERATIONS,
                       progress: Callable[[str], None] | None = None) -> StereoResult:
    """Orientations from K images under known sources, under a reflectance model (module
    notes).

    Parameters
    ----------
    images, light_directions, mask, irradiance, noise_sd
        As in :func:`lambertian_stereo`; K at least the number of unknowns per pixel (two
        tangent directions, one in a plane, and the albedo scale unless known), and 2.
    model : callable, str, path, Material or FitResult, optional
        The reflectance: ``brdf(theta_i, phi_i, theta_r, phi_r)`` [1/sr], a model spec
        (``oren-nayar:sigma=30,rho=0.9``), a folder written by ``gonio fit`` or a fit
        result (:func:`gonio.export.material_of`). None: Lambertian least squares
        (:func:`lambertian_stereo`).
    view : sequence of 3 float
        Direction towards the camera.
    albedo_known : bool
        Hold the albedo scale at 1 (the model's albedo is the surface's) instead of
        fitting it per pixel.
    in_plane_of : sequence of 3 float, optional
        Hold every normal perpendicular to this axis (a cylinder's axis: the paper's vase,
        whose translational symmetry lets two sources fix its shape).
    draws : int
        Posterior draws of a fitted model whose re-inversion adds the model's uncertainty.
    candidates : int
        Normals of the initial search over the visible hemisphere (or half circle).
    iterations : int
        Levenberg-Marquardt iterations.
    progress : callable, optional
        Receives a line of text at each stage.

    Returns
    -------
    StereoResult
    """
    if model is None:
        if albedo_known or in_plane_of is not None:
            raise ValueError("Lambertian least squares fits the albedo and a free normal; for a known albedo or "
                             "normals in a plane pass Lambert's BRDF as the model")
        return lambertian_stereo(images, light_directions, mask, irradiance, noise_sd)
    if int(candidates) < 10 or int(iterations) < 0 or int(draws) < 0:
        raise ValueError(f"candidates >= 10, iterations >= 0 and draws >= 0 expected, got {candidates}, "
                         f"{iterations}, {draws}")
    axis = None if in_plane_of is None else _unit(in_plane_of, "in_plane_of")
    unknowns = (2 if axis is None else 1) + (0 if albedo_known else 1)
    brdf, drawn, name = _model_of(model, int(draws))
    images, lights, mask, irradiance, noise_sd = _checked_inputs(images, light_directions, mask, irradiance,
                                                                 noise_sd, max(unknowns, 2))
    observed, weights = _readings(images, mask, noise_sd)
    problem = _Problem(brdf, observed, weights, lights, _unit(view, "view"), irradiance, bool(albedo_known), axis)
    say = progress or (lambda text: None)
    normals, scale, cost = _solve(problem, int(candidates), int(iterations), say)
    factor = variance_factor(cost, weights, unknowns, noise_sd is not None)
    basis = problem.basis(normals)
    covariance = None if factor is None else _covariance(problem, normals, scale, basis, factor)
    if covariance is not None and drawn:
        say(f"re-inverting with {len(drawn)} posterior draws of the model")
        covariance = covariance + _draws_scatter(problem, drawn, normals, scale, basis)
    return _result(mask, normals, scale, covariance, basis, cost, weights, name, factor, problem.directions)


def _unit(vector: Sequence[float], name: str) -> np.ndarray:
    vector = np.asarray(vector, float)
    if vector.shape != (3,) or not np.all(np.isfinite(vector)) or not np.linalg.norm(vector) > 0:
        raise ValueError(f"{name} must be a non-zero 3-vector, got {vector.tolist()}")
    return vector / np.linalg.norm(vector)


def _solve(problem: _Problem, candidates: int, iterations: int,
           say: Callable[[str], None]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The best candidate normal of each pixel, refined: normals, scales, weighted sums of
    squares."""
    say(f"searching {candidates} candidate normals for {problem.observed.shape[0]} pixels")
    grid = (hemisphere_normals(candidates, problem.view) if problem.axis is None
            else plane_normals(candidates, problem.view, problem.axis))
    normals = grid[_best_candidates(problem.observed, problem.weights, problem.predict(grid), problem.known_scale)]
    say(f"refining ({iterations} Levenberg-Marquardt iterations)")
    return _refine(problem, normals, problem.best_scale(normals), iterations)
