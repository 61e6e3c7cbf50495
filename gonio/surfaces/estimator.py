"""Monte Carlo BRDF of a rendered micro-surface, with its standard error.

:func:`render` is the estimator (derivation in its Notes); :func:`render_albedo` the
directional-hemispherical reflectance by the same estimator at random viewing
directions.  Both are seeded: the same seed gives the same numbers, whatever the number
of threads.
"""
from __future__ import annotations

import math
import struct
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from .shapes import HeightField, PittedPlane, Surface, VGroove, VGrooveField

__all__ = ["Rendering", "Albedo", "render", "render_albedo", "RENDERER_VERSION", "THETA_LIMIT", "kernel_inputs"]

#: Version of the estimator and the kernel; part of every table's cache key, so a change
#: of the numbers (a fix, another sampler) never reuses an old table.
RENDERER_VERSION = 2
#: Largest polar angle rendered [deg]; directions between it and 90 deg are rendered at
#: it (the BRDF is continuous there except at grazing retro-reflection, where it grows
#: like 1/cos theta).
THETA_LIMIT = 89.99
#: Geometries per task handed to a thread.
_CHUNK = 8
#: Accumulator columns per geometry: :data:`.kernel.ACCUMULATORS` (a test keeps them equal;
#: importing the kernel here would load numba with the package).
COLUMNS = 16


@dataclass(frozen=True)
class Rendering:
    """A rendered BRDF [1/sr] with its Monte Carlo standard error.

    Attributes
    ----------
    value, standard_error : numpy.ndarray
        The BRDF at the bounce limit and its standard error [1/sr], broadcast shape of
        the geometries.
    cumulative, cumulative_error : numpy.ndarray
        Shape (3, ...): the BRDF through the first vertex (direct light only), through
        the second (one interreflection) and through all vertices traced, with their
        standard errors; from one set of paths, so differences between them are precise.
    orders, order_error : numpy.ndarray
        Shape (3, ...): what the first vertex, the second and all further vertices add,
        and their standard errors (``orders[2]`` is the light of three and more bounces).
    paths, seed : int
        Paths per geometry; the seed.
    bounces : int or None
        Vertices per path (1 = direct light only), None = all (Russian roulette).
    cut : numpy.ndarray
        Paths cut at the kernel's BOUNCE_CAP per geometry (0 unless rho = 1 in nearly
        vertical grooves; a cut path loses the rest of its light).
    segments : numpy.ndarray
        Mean rays traced per path (speed diagnostics; height field: cells crossed).
    """

    value: np.ndarray
    standard_error: np.ndarray
    cumulative: np.ndarray
    cumulative_error: np.ndarray
    orders: np.ndarray
    order_error: np.ndarray
    paths: int
    seed: int
    bounces: int | None
    cut: np.ndarray
    segments: np.ndarray


@dataclass(frozen=True)
class Albedo:
    """A directional-hemispherical reflectance [-] with its Monte Carlo standard error.

    Attributes
    ----------
    value, standard_error : float
        The reflectance (all vertices traced under the bounce limit) and its error.
    orders, order_error : numpy.ndarray
        Shape (3,): what the first vertex, the second and all further vertices reflect,
        with their standard errors.
    """

    value: float
    standard_error: float
    orders: np.ndarray
    order_error: np.ndarray


def kernel_inputs(surface: Surface) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's (kind code, parameters, heights, cell tops) for ``surface``."""
    from . import kernel

    dummy = np.zeros((1, 1))
    if isinstance(surface, VGrooveField):
        gaussian = surface.sigma > 0.0
        params = [surface.rho, 1.0 if gaussian else 0.0, math.radians(surface.sigma), 1.0, 0.0]
        return kernel.VGROOVE, np.array(params), dummy, dummy
    if isinstance(surface, VGroove):
        uniform = surface.phi_a is None
        params = [surface.rho, 0.0, math.radians(surface.theta_a), 1.0 if uniform else 0.0,
                  0.0 if uniform else math.radians(surface.phi_a)]
        return kernel.VGROOVE, np.array(params), dummy, dummy
    if isinstance(surface, PittedPlane):
        return kernel.PIT, np.array([surface.rho, math.radians(surface.psi)]), dummy, dummy
    if isinstance(surface, HeightField):
        field = _realised(surface)
        return kernel.FIELD, np.array([surface.rho, field.top]), field.heights, field.cell_top
    raise TypeError(f"not a surface gonio renders: {surface!r}")


@lru_cache(maxsize=4)
def _realised(surface: HeightField):
    from .heightfield import realise

    return realise(surface)


def _unit_vectors(theta_deg: np.ndarray, phi_deg: np.ndarray) -> np.ndarray:
    theta = np.radians(np.minimum(theta_deg, THETA_LIMIT))
    phi = np.radians(phi_deg)
    return np.ascontiguousarray(np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)],
                                         axis=-1))


def geometry_seed(seed: int, surface: Surface, geometry: tuple[float, float, float, float] | None = None
                  ) -> np.uint64:
    """The stream of one geometry: a function of the seed, the kind and the four angles.

    Keyed by the geometry, so a geometry gets the same numbers whatever else is rendered
    with it; reciprocal geometries get independent streams.  ``geometry=None`` gives the
    common stream of every geometry (common random numbers, :func:`render`).
    """
    words = [int(seed), sum(map(ord, surface.kind))]
    if geometry is None:
        words.append(1)  # a geometry's next word is the bit pattern of theta_i, 1 only for 5e-324 deg
    else:
        words += [int.from_bytes(struct.pack("<d", float(a)), "little") for a in geometry]
    return np.random.SeedSequence(words).generate_state(1, np.uint64)[0]


def _accumulate(surface: Surface, sources: np.ndarray, views: np.ndarray, seeds: np.ndarray, paths: int,
                bounces: int | None, workers: int, expected_bounces: bool = False) -> np.ndarray:
    """Kernel accumulators (G, ACCUMULATORS) of the pit, groove or field, in threads."""
    from .kernel import render_geometries

    kind, params, heights, cell_top = kernel_inputs(surface)
    out = np.zeros((sources.shape[0], COLUMNS))
    max_bounces = 0 if bounces is None else int(bounces)

    def task(start: int) -> None:
        part = slice(start, start + _CHUNK)
        render_geometries(kind, params, heights, cell_top, sources[part], views[part], seeds[part], int(paths),
                          max_bounces, out[part], expected_bounces)

    starts = range(0, sources.shape[0], _CHUNK)
    if workers <= 1 or sources.shape[0] <= _CHUNK:
        for start in starts:
            task(start)
    else:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            list(pool.map(task, starts))
    return out


def _mean_and_error(sums: np.ndarray, squares: np.ndarray, shifts: np.ndarray, n: int
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Mean and its standard error from the sum, the sum of squared deviations from a
    reference value ``shifts`` and the count."""
    mean = sums / n
    offset = mean - shifts
    variance = np.maximum(squares / n - offset * offset, 0.0) * (n / max(n - 1, 1))
    return mean, np.sqrt(variance / n)


def _check_render_options(paths: int, bounces: int | None) -> None:
    if isinstance(paths, bool) or int(paths) != paths or int(paths) < 2:
        raise ValueError(f"paths = {paths!r} must be an integer >= 2")
    if bounces is not None and (isinstance(bounces, bool) or int(bounces) != bounces or int(bounces) < 1):
        raise ValueError(f"bounces = {bounces!r} must be an integer >= 1 (1 = direct light only) or None (all)")


def render(surface: Surface, theta_i: ArrayLike, phi_i: ArrayLike, theta_r: ArrayLike, phi_r: ArrayLike,
           paths: int = 20_000, seed: int = 0, bounces: int | None = None, workers: int = 1,
           common_random_numbers: bool = False, expected_bounces: bool = False) -> Rendering:
    """Render the BRDF of ``surface`` by Monte Carlo path tracing [1/sr].

    Parameters
    ----------
    surface : Surface
        A :class:`~.shapes.VGroove`, :class:`~.shapes.VGrooveField`,
        :class:`~.shapes.HeightField` or :class:`~.shapes.PittedPlane`.
    theta_i, phi_i : array_like
        Source direction [deg], theta_i in [0, 90].
    theta_r, phi_r : array_like
        Viewing direction [deg], theta_r in [0, 90].
    paths : int
        Paths per geometry (the standard error falls like 1/sqrt(paths)).
    seed : int
        Seed: the same seed gives the same numbers.
    bounces : int or None
        Scattering events per path: 1 = direct light only, 2 = one interreflection, ...;
        None (default) = all, unbiased.
    workers : int
        Threads (geometries are shared out; the numbers do not depend on it).
    common_random_numbers : bool
        False (default): every geometry has its own random stream, keyed by the seed and
        its angles, and the errors of different geometries are independent.  True: every
        geometry is rendered with the same paths (path k has the same groove, azimuth,
        camera point and bounce numbers at every geometry), so the result is the exact
        BRDF of one finite sample of paths and its error varies smoothly with the angles
        instead of jumping from one geometry to the next (rendered tables, Notes).
    expected_bounces : bool
        V-grooves (``VGroove``, ``VGrooveField``) only: the light each bounce brings from
        the other facet is integrated over that facet in closed form instead of traced
        (Notes); the same expectation with a smaller variance.  Ignored for other kinds.

    Returns
    -------
    Rendering
        Value, standard error and the cumulative orders.  Directions below the horizon
        (theta > 90 deg) give 0 with error 0, NaN angles NaN.

    Notes
    -----
    The BRDF of a surface patch is f_r = L_r / (E_0 cos theta_i): L_r its radiance toward
    the viewer v, E_0 the irradiance of the collimated source s on a plane facing it
    (Oren & Nayar 1995, section 4.3).  L_r is the mean, over the patch's area projected
    orthogonally to v, of the radiance L(p, v) of the first surface point p that the
    viewer sees there (flux per projected area).  So a camera ray is drawn uniformly over
    the projected area of one period (uniform over the period in a horizontal plane is
    uniform over its projection, a linear map), and L(p, v) is estimated at its first hit.

    A Lambertian facet of albedo rho and normal n radiates L(p, v) = (rho/pi) E(p), with
    the irradiance E(p) = E_0 (n.s)+ V(p, s) + integral over the hemisphere of n of
    L(p, w) (n.w) dw (V: 1 if the source is unobstructed).  The direct term is evaluated
    exactly (next-event estimation toward the collimated source: one shadow ray, no
    sampling); the integral by one direction w drawn with density (n.w)/pi, for which
    (rho/pi) L(p, w) (n.w) / ((n.w)/pi) = rho L(p, w): the next vertex of the path, found
    by tracing w, is estimated the same way with weight rho.  A ray that leaves the
    surface sees the black sky (a collimated source is never hit by a sampled
    direction).  Per path

        X = sum_k w_k rho (n_k.s)+ V(p_k, s) / (pi cos theta_i),   w_1 = 1,

    and E[X] = f_r.  With a bounce limit B, w_k = rho^(k-1) for k <= B (exact truncation
    of the Neumann series at B scattering events: B = 1 is direct light, B = 2 the
    two-bounce interreflection of Oren & Nayar eq 17-26).  With all bounces, from the
    third vertex on the path survives each step with probability rho and keeps its weight
    (Russian roulette: unbiased, E[w_k] = rho^(k-1)); paths end when they escape.  A path
    is cut after BOUNCE_CAP vertices (:mod:`.kernel`; counted in ``cut``).  The standard
    error is the sample standard deviation of X over the paths / sqrt(paths).

    Kinds (:mod:`.shapes`): the V-groove field draws the groove of each path from the
    slope-area distribution (its BRDF is the area-weighted average of groove renders,
    since every top lies in the mean plane); the height field turns by a uniform azimuth
    per path; the pitted plane renders one pit through its orifice and adds the flat rest
    exactly: a camera ray that meets the plane sees an unobstructed facet
    (contribution rho/pi, zero variance) and light leaving a pit never returns below the
    plane, so f = (1 - coverage) rho/pi + coverage f_pit for every bounce limit.

    Expected bounces (V-grooves): in a long groove the cross-section is all that matters
    (eq 18), and the light a facet point u sends that lands on the other facet's strip
    [v1, v2] is the integral of eq 19's kernel, the view factor |sin phi(v2) -
    sin phi(v1)| / 2 (phi: the cross-section angle from the point's normal under which
    it sees v).  The other facet is lit uniformly on [m^s/w, 1] (eq 21), so the next
    vertex's direct light is added as its expectation, w_k rho * rho (n'.s)+ F(u -> lit
    strip), and the path moves to a point of the other facet drawn with sin phi uniform
    (weight times rho F(u -> facet)); the first vertex keeps its exact 0-or-1 shadow test
    (is it on its facet's lit strip).  Unbiased (the conditional expectation of the
    traced estimate); the per-path variance of the second and later orders falls
    (:mod:`.kernel`, ``_groove_expected_path``).

    Random numbers: SplitMix64, path k of a stream starting a fixed 2^20 draws after path
    k - 1 (:mod:`.kernel`).  By default the stream of a geometry is keyed by the seed, the
    kind and its four angles, so each geometry's standard error describes an error
    independent of every other geometry's (what the error-bar tests need).  With
    ``common_random_numbers`` every geometry uses the stream of the seed and the kind:
    the standard error of each value is unchanged, but the errors of different
    geometries are correlated (for nearby geometries nearly equal): the rendered values
    are then the BRDF of one finite random sample of the surface, as a measured sample is
    one finite patch of it, and differences between nearby geometries are much more
    precise than the values (docs/surfaces.md, "Tables").

    References
    ----------
    M. Oren, S. K. Nayar, IJCV 14(3), 1995, section 4 (the BRDF of a facet surface, eq 8,
    the two-bounce truncation eq 17-26); J. J. Koenderink et al., IJCV 31(2/3), 1999,
    section 4.1 (Monte Carlo over the orifice); J. T. Kajiya, "The rendering equation",
    SIGGRAPH 1986 (path tracing, Russian roulette).

    Examples
    --------
    >>> flat = VGrooveField(sigma=0.0, rho=0.5)                  # a plane: Lambert, exactly
    >>> r = render(flat, 30.0, 0.0, 60.0, 180.0, paths=100)
    >>> round(float(r.value) * 3.141592653589793, 12), float(r.standard_error)
    (0.5, 0.0)
    """
    _check_render_options(paths, bounces)
    arrays = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))
    shape = arrays[0].shape
    ti, pi_, tr, pr = (a.ravel() for a in arrays)
    valid = (ti >= 0.0) & (ti <= 90.0) & (tr >= 0.0) & (tr <= 90.0)
    index = np.flatnonzero(valid)
    sums = np.zeros((len(ti), COLUMNS))
    if index.size and not (isinstance(surface, PittedPlane) and surface.coverage == 0.0):
        if common_random_numbers:
            seeds = np.full(index.size, geometry_seed(seed, surface), np.uint64)
        else:
            seeds = np.array([geometry_seed(seed, surface, (ti[k], pi_[k], tr[k], pr[k])) for k in index], np.uint64)
        expected = expected_bounces and isinstance(surface, (VGroove, VGrooveField))
        sums[index] = _accumulate(surface, _unit_vectors(ti[index], pi_[index]), _unit_vectors(tr[index], pr[index]),
                                  seeds, paths, bounces, workers, expected)
    cumulative, cumulative_error = _mean_and_error(np.cumsum(sums[:, 0:3].T, axis=0),
                                                   np.stack([sums[:, 3], sums[:, 6], sums[:, 7]]),
                                                   np.stack([sums[:, 11], sums[:, 14], sums[:, 15]]), paths)
    orders, order_error = _mean_and_error(sums[:, 0:3].T, sums[:, 3:6].T, sums[:, 11:14].T, paths)
    if isinstance(surface, PittedPlane):
        cumulative, cumulative_error = _with_flat_part(surface, cumulative, cumulative_error, valid)
        orders, order_error = _with_flat_part(surface, orders, order_error, valid, first_only=True)
    invalid = ~valid
    nan = np.isnan(ti) | np.isnan(tr) | np.isnan(pi_) | np.isnan(pr)
    for array in (cumulative, cumulative_error, orders, order_error):
        array[:, invalid] = 0.0
        array[:, nan] = np.nan
    reshape = (lambda a: a.reshape(a.shape[:-1] + shape))
    return Rendering(
        value=reshape(cumulative[2]), standard_error=reshape(cumulative_error[2]),
        cumulative=reshape(cumulative), cumulative_error=reshape(cumulative_error),
        orders=reshape(orders), order_error=reshape(order_error),
        paths=int(paths), seed=int(seed), bounces=None if bounces is None else int(bounces),
        cut=sums[:, 8].reshape(shape), segments=(sums[:, 10] / paths).reshape(shape),
    )


def _with_flat_part(surface: PittedPlane, values: np.ndarray, errors: np.ndarray, valid: np.ndarray,
                    first_only: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(1 - coverage) rho/pi + coverage * pit (render Notes): for every cumulative order,
    or (``first_only``) for the first vertex's contribution alone."""
    flat = np.zeros_like(values)
    flat[0 if first_only else slice(None)] = (1.0 - surface.coverage) * surface.rho / math.pi * valid
    return flat + surface.coverage * values, surface.coverage * errors


def render_albedo(surface: Surface, theta_i: float, phi_i: float = 0.0, paths: int = 100_000, seed: int = 0,
                  bounces: int | None = None, workers: int = 1) -> Albedo:
    """Directional-hemispherical reflectance of ``surface`` by the estimator of :func:`render`.

    Parameters
    ----------
    surface : Surface
        The surface.
    theta_i, phi_i : float
        Source direction [deg], theta_i in [0, 90).
    paths : int
        Paths, each with its own viewing direction.
    seed : int
        Seed.
    bounces : int or None
        As in :func:`render`.
    workers : int
        Threads.

    Returns
    -------
    Albedo
        rho_dh = integral of f_r cos(theta_r) over the hemisphere [-] (Forsyth & Ponce,
        ch. 2), estimated as pi times the mean of one-path BRDF estimates at viewing
        directions drawn with density cos(theta_r)/pi; its standard error; the same for
        the first, the second and the further vertices of the paths.

    Notes
    -----
    With rho = 1 and all bounces nothing is absorbed, so the result must be 1: a test of
    the whole estimator (camera sampling over the projected area, shadow rays, bounces,
    escapes), not of a formula.

    Examples
    --------
    >>> albedo = render_albedo(VGrooveField(sigma=0.0, rho=0.7), 40.0, paths=1000)
    >>> round(albedo.value, 12), albedo.standard_error < 1e-15   # a plane: every path gives rho
    (0.7, True)
    """
    _check_render_options(paths, bounces)
    if not 0.0 <= float(theta_i) < 90.0:
        raise ValueError(f"theta_i = {theta_i!r} deg must lie in [0, 90) for the directional-hemispherical reflectance")
    rng = np.random.default_rng([int(seed), sum(map(ord, surface.kind)), 7])
    u = rng.random((2, int(paths)))
    view_theta = np.degrees(np.arcsin(np.sqrt(u[0])))  # density cos/pi over the hemisphere
    view_phi = 360.0 * u[1]
    seeds = rng.integers(0, np.iinfo(np.uint64).max, size=int(paths), dtype=np.uint64, endpoint=True)
    sources = np.repeat(_unit_vectors(np.array([float(theta_i)]), np.array([float(phi_i)])), int(paths), axis=0)
    orders = _accumulate(surface, sources, _unit_vectors(view_theta, view_phi), seeds, 1, bounces, workers)[:, 0:3]
    if isinstance(surface, PittedPlane):
        orders = surface.coverage * orders
        orders[:, 0] += (1.0 - surface.coverage) * surface.rho / math.pi
    orders = math.pi * orders
    total = orders.sum(axis=1)
    error = (lambda values: float(values.std(ddof=1) / math.sqrt(values.size)))  # noqa: E731
    return Albedo(float(total.mean()), error(total), orders.mean(axis=0),
                  np.array([error(orders[:, k]) for k in range(3)]))
