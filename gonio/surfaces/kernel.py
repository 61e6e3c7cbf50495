"""The compiled path tracer: micro-surfaces of Lambertian facets lit by a collimated source.

One loop (:func:`render_geometries`) serves every surface kind; the geometry of a kind is
three small functions, chosen by an integer code:

``VGROOVE``
    One long symmetric V-groove of slope theta_a between tops in the mean plane (the
    cavity of Oren & Nayar 1995, section 4.1, Fig 5), traced in its cross-section: facet
    0 is ``z = -tan(theta_a) (x + 1)`` on x in [-1, 0] (normal (sin, 0, cos) theta_a in
    the groove frame), facet 1 is ``z = tan(theta_a) (x - 1)`` on [0, 1] (normal
    (-sin, 0, cos)).  Per path the slope is fixed or drawn from the Gaussian slope-area
    distribution (eq 32, see :func:`_gaussian_slope`) and the groove azimuth phi_a fixed
    or uniform.  Every top lies in the mean plane, so light that leaves a groove above it
    escapes: one groove is the whole periodic profile.
``PIT``
    One spherical pit of unit radius and aperture psi below the plane z = 0, centre at
    height cos(psi) (Koenderink et al. 1999, section 2, Fig 2); camera rays enter it
    through its orifice.  A chord from a cavity point p with inward normal m along d ends
    at p + 2 (m.d) d, and leaves through the orifice exactly when that end is at or above
    the plane.
``FIELD``
    A periodic height field on an N x N grid of unit cells, each cell split into two
    planar triangles along its diagonal u = w, traced by a grid traversal (Amanatides &
    Woo 1987) with a per-cell height bound; rotated by a uniform random azimuth per path
    (the average over the orientations of the sample, which makes one realisation
    isotropic).

The estimator (derivation in :func:`gonio.surfaces.render.render`): per path, one camera
ray uniform over the projected area finds the first visible point; at each vertex k of
the path, next-event estimation toward the collimated source adds
``w_k rho (n.s)+ V(p_k, s) / (pi cos theta_i)``; the path continues along a cosine-weighted
direction with ``w_{k+1} = rho w_k`` for a fixed number of bounces, or, for all bounces,
by Russian roulette with survival probability rho from the third vertex on (weights
unchanged: unbiased).  Per path the contributions are kept in three bins (vertex 1,
vertex 2, vertices 3 and more), accumulated with their squares.

V-grooves can instead be rendered with *expected bounces*
(:func:`_groove_expected_path`): in a long groove the light a facet point sends to the
other facet, and the part of it that lands on the other facet's lit strip, are view
factors in closed form, so the next vertex's direct light is added as its conditional
expectation instead of a traced 0-or-1 sample; the same expectation, a smaller variance.

Random numbers: SplitMix64 (Steele, Lea & Flood 2014), one stream per geometry, seeded by
the caller; the same seeds give the same numbers on any machine and in any thread.  Path k
of a stream starts PATH_STRIDE numbers after path k - 1 (a jump ahead of SplitMix64's
counter, :func:`path_state`), so a path's numbers depend on the stream seed and k alone,
not on how many numbers the paths before it used: rendered with the same seed, path k
of two geometries has the same groove, azimuth and camera point and the same bounce
numbers (common random numbers, :func:`gonio.surfaces.render`).

All angles here are radians, all vectors unit 3-tuples in the sample frame (z: the mean
normal).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["VGROOVE", "PIT", "FIELD", "ACCUMULATORS", "BOUNCE_CAP", "MAX_CELL_STEPS", "PATH_STRIDE",
           "render_geometries", "sample_gaussian_slopes", "uniform_numbers", "path_state"]

#: Kind codes.
VGROOVE, PIT, FIELD = 0, 1, 2
#: Columns of the accumulator row of a geometry: sums of the three bins (vertex 1, 2,
#: 3+), sums of squared deviations of the three bins, of the cumulative sums through
#: vertex 2 and through all vertices, then paths cut at the bounce cap, rays lost in the
#: traversal, traced segments, and the five reference values the deviations are taken
#: from (the first path's: no cancellation when the values hardly vary).
ACCUMULATORS = 16
#: Vertices after which a path is cut (counted in column 8).  Reached only with
#: rho = 1 in nearly vertical V-grooves (docs/surfaces.md, "Bounces").
BOUNCE_CAP = 1000
#: Cells a height-field ray may cross before it is given up (counted in column 9).
MAX_CELL_STEPS = 1_000_000

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
#: Numbers reserved for each path of a stream: 2^20, far more than a path draws (at most
#: about 3 per vertex and BOUNCE_CAP vertices, plus the slope's rejection draws), so the
#: paths of a stream never share a number; 2^44 paths fit in the 2^64-long cycle.
PATH_STRIDE = 1 << 20
_PATH_JUMP = np.uint64((0x9E3779B97F4A7C15 * PATH_STRIDE) % 2**64)
_TWO_PI = 2.0 * math.pi
#: Hits closer than this to a ray's origin [length units] are ignored (self-intersection).
_T_MIN = 1e-10
#: Tolerance of the cell and triangle tests of the height field [cell units].
_EDGE = 1e-9


@njit(cache=True, nogil=True)
def _uniform(state: np.ndarray) -> float:
    """Next number uniform in [0, 1) of the SplitMix64 stream ``state`` (uint64[1])."""
    z = state[0] + _GOLDEN
    state[0] = z
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    z = z ^ (z >> _S31)
    return float(z >> _S11) * (1.0 / 9007199254740992.0)


@njit(cache=True, nogil=True)
def path_state(seed: np.uint64, path: int) -> np.uint64:
    """SplitMix64 state at the start of path ``path`` of the stream ``seed``: the state
    after ``path * PATH_STRIDE`` draws (the counter advances by a constant per draw)."""
    return seed + np.uint64(path) * _PATH_JUMP


@njit(cache=True, nogil=True)
def uniform_numbers(seed: np.uint64, count: int) -> np.ndarray:
    """``count`` numbers of the stream seeded by ``seed`` (tests of the generator)."""
    state = np.empty(1, np.uint64)
    state[0] = seed
    out = np.empty(count)
    for k in range(count):
        out[k] = _uniform(state)
    return out


@njit(cache=True, nogil=True)
def _gaussian_slope(sigma: float, state: np.ndarray) -> float:
    """A facet slope [rad] with density exp(-t^2/(2 sigma^2)) sin(t) on [0, pi/2] (eq 32).

    The slope-area density of ``oren-nayar-exact`` (module notes of
    :mod:`gonio.models.oren_nayar.exact`).  Drawn exactly: t from the Rayleigh density
    t exp(-t^2/(2 sigma^2)) truncated to [0, pi/2] by inverting its distribution function,
    accepted with probability sin(t)/t (at least 2/pi).
    """
    top = 1.0 - math.exp(-0.125 * math.pi * math.pi / (sigma * sigma))
    while True:
        u = _uniform(state) * top
        t = sigma * math.sqrt(-2.0 * math.log1p(-u))
        if t == 0.0 or _uniform(state) * t <= math.sin(t):
            return t


@njit(cache=True, nogil=True)
def sample_gaussian_slopes(sigma: float, count: int, seed: np.uint64) -> np.ndarray:
    """``count`` slopes [rad] drawn by the kernel's sampler (tests of the distribution)."""
    state = np.empty(1, np.uint64)
    state[0] = seed
    out = np.empty(count)
    for k in range(count):
        out[k] = _gaussian_slope(sigma, state)
    return out


@njit(cache=True, nogil=True)
def _cosine_direction(nx: float, ny: float, nz: float, state: np.ndarray) -> tuple[float, float, float]:
    """A direction with density cos/pi about the unit normal n (orthonormal basis of
    Duff et al. 2017, "Building an orthonormal basis, revisited")."""
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    u1 = _uniform(state)
    angle = _TWO_PI * _uniform(state)
    r = math.sqrt(u1)
    x, y, z = r * math.cos(angle), r * math.sin(angle), math.sqrt(max(0.0, 1.0 - u1))
    return (x * (1.0 + sign * nx * nx * a) + y * b + z * nx,
            x * (sign * b) + y * (sign + ny * ny * a) + z * ny,
            -x * sign * nx - y * ny + z * nz)


# --------------------------------------------------------------------------- V-groove
@njit(cache=True, nogil=True)
def _groove_trace(tan_a: float, x: float, z: float, dx: float, dz: float, exclude: int) -> tuple[int, float]:
    """Next facet (0, 1; -1: escaped above the tops) along (dx, dz) from (x, z), and the
    distance to it.  Inside the groove g0 = z + T (x + 1) >= 0 and g1 = z - T (x - 1) >= 0;
    a facet is met where its g falls to 0."""
    facet, best = -1, math.inf
    if exclude != 0:
        rate = dz + tan_a * dx
        if rate < 0.0:
            t = max(-(z + tan_a * (x + 1.0)) / rate, 0.0)
            if t < best:
                facet, best = 0, t
    if exclude != 1:
        rate = dz - tan_a * dx
        if rate < 0.0:
            t = max(-(z - tan_a * (x - 1.0)) / rate, 0.0)
            if t < best:
                facet, best = 1, t
    if dz > 0.0:
        t = -z / dz
        if t < best:
            facet, best = -1, t
    return facet, best


# --------------------------------------------------------------------------- spherical pit
@njit(cache=True, nogil=True)
def _pit_chord(centre_z: float, px: float, py: float, pz: float,
               dx: float, dy: float, dz: float) -> tuple[bool, float, float, float]:
    """From cavity point p along d (into the sphere): (hits the cavity, end point)."""
    mx, my, mz = -px, -py, centre_z - pz
    length = 2.0 * (mx * dx + my * dy + mz * dz)
    qx, qy, qz = px + length * dx, py + length * dy, pz + length * dz
    return qz < 0.0, qx, qy, qz


# --------------------------------------------------------------------------- height field
@njit(cache=True, nogil=True)
def _cell_hit(heights, i: int, j: int, cx: float, cy: float, ox, oy, oz, dx, dy, dz,
              t_enter: float, t_exit: float, exclude: int) -> tuple[int, float, float, float]:
    """Nearest hit on the two triangles of cell (i, j) (corner at (cx, cy)) within
    [t_enter, t_exit]: (facet id or -1, t, slope b, slope c) with the plane
    z = a + b u + c w of the facet."""
    n = heights.shape[0]
    i1, j1 = (i + 1) % n, (j + 1) % n
    h00, h10, h01, h11 = heights[i, j], heights[i1, j], heights[i, j1], heights[i1, j1]
    u0, w0 = ox - cx, oy - cy
    best_id, best_t, best_b, best_c = -1, math.inf, 0.0, 0.0
    for triangle in range(2):
        if triangle == 0:  # u >= w: (0,0), (1,0), (1,1)
            b, c = h10 - h00, h11 - h10
        else:  # w >= u: (0,0), (1,1), (0,1)
            b, c = h11 - h01, h01 - h00
        facet = 2 * (i * n + j) + triangle
        rate = dz - b * dx - c * dy
        if facet == exclude or rate >= 0.0:
            continue
        t = -(oz - (h00 + b * u0 + c * w0)) / rate
        if t <= _T_MIN or t < t_enter - _EDGE or t > t_exit + _EDGE or t >= best_t:
            continue
        u, w = u0 + t * dx, w0 + t * dy
        if u < -_EDGE or u > 1.0 + _EDGE or w < -_EDGE or w > 1.0 + _EDGE:
            continue
        if (triangle == 0 and u < w - _EDGE) or (triangle == 1 and w < u - _EDGE):
            continue
        best_id, best_t, best_b, best_c = facet, t, b, c
    return best_id, best_t, best_b, best_c


@njit(cache=True, nogil=True)
def _axis_start(origin: float, direction: float) -> tuple[int, float, float]:
    """Grid traversal along one axis: step, parameter of the first cell wall, wall spacing."""
    cell = math.floor(origin)
    if direction > 0.0:
        return 1, (cell + 1.0 - origin) / direction, 1.0 / direction
    if direction < 0.0:
        return -1, (cell - origin) / direction, -1.0 / direction
    return 0, math.inf, math.inf


@njit(cache=True, nogil=True)
def _field_trace(heights, cell_top, top: float, ox, oy, oz, dx, dy, dz,
                 exclude: int) -> tuple[int, float, float, float, int]:
    """First facet of the height field along d from o (cell units): (facet id, -1 escaped
    above the highest point, -2 given up after MAX_CELL_STEPS cells; t; slopes b, c of the
    facet; cells crossed)."""
    n = heights.shape[0]
    ix, iy = math.floor(ox), math.floor(oy)
    step_x, next_x, delta_x = _axis_start(ox, dx)
    step_y, next_y, delta_y = _axis_start(oy, dy)
    t_enter = 0.0
    for crossed in range(MAX_CELL_STEPS):
        t_exit = min(next_x, next_y)
        z_enter = oz + t_enter * dz
        z_exit = z_enter if dz == 0.0 else oz + t_exit * dz
        i, j = int(ix) % n, int(iy) % n
        if min(z_enter, z_exit) <= cell_top[i, j]:
            facet, t, b, c = _cell_hit(heights, i, j, ix, iy, ox, oy, oz, dx, dy, dz, t_enter, t_exit, exclude)
            if facet >= 0:
                return facet, t, b, c, crossed + 1
        if dz > 0.0 and z_exit > top:
            return -1, math.inf, 0.0, 0.0, crossed + 1
        if next_x < next_y:
            ix += step_x
            t_enter = next_x
            next_x += delta_x
        else:
            iy += step_y
            t_enter = next_y
            next_y += delta_y
    return -2, math.inf, 0.0, 0.0, MAX_CELL_STEPS


@njit(cache=True, nogil=True)
def _facet_normal(b: float, c: float) -> tuple[float, float, float]:
    """Unit normal of the plane z = a + b u + c w (upward)."""
    scale = 1.0 / math.sqrt(1.0 + b * b + c * c)
    return -b * scale, -c * scale, scale


# --------------------------------------------------------------------------- one kind interface
@njit(cache=True, nogil=True)
def _trace(kind: int, shape: np.ndarray, heights, cell_top, px, py, pz, facet: int,
           dx, dy, dz) -> tuple[int, float, float, float, float, float, float, int]:
    """Next surface point along d from p on ``facet`` (-1: a camera ray from above).

    Returns (facet, point, normal, segments): facet -1 when the ray escapes, -2 when the
    traversal gave up.  ``shape`` holds per-path constants: VGROOVE (tan, sin, cos of the
    slope), PIT (cos psi, sin psi), FIELD (highest point).
    """
    if kind == VGROOVE:
        tan_a, sin_a, cos_a = shape[0], shape[1], shape[2]
        hit, t = _groove_trace(tan_a, px, pz, dx, dz, facet)
        if hit < 0:
            return -1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1
        nx = sin_a if hit == 0 else -sin_a
        return hit, px + t * dx, py + t * dy, pz + t * dz, nx, 0.0, cos_a, 1
    if kind == PIT:
        centre_z = shape[0]
        if facet < 0:  # entering through the orifice (pz = 0) from above
            ax, ay, az = px, py, pz - centre_z
            along = -(ax * dx + ay * dy + az * dz)
            inside = 1.0 - (ax * ax + ay * ay + az * az)
            t = along + math.sqrt(max(along * along + inside, 0.0))
            qx, qy, qz = px + t * dx, py + t * dy, pz + t * dz
        else:
            inside_hit, qx, qy, qz = _pit_chord(centre_z, px, py, pz, dx, dy, dz)
            if not inside_hit:
                return -1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1
        return 0, qx, qy, qz, -qx, -qy, centre_z - qz, 1
    hit, t, b, c, crossed = _field_trace(heights, cell_top, shape[0], px, py, pz, dx, dy, dz, facet)
    if hit < 0:
        return hit, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, crossed
    nx, ny, nz = _facet_normal(b, c)
    return hit, px + t * dx, py + t * dy, pz + t * dz, nx, ny, nz, crossed


@njit(cache=True, nogil=True)
def _camera_origin(kind: int, shape: np.ndarray, heights, state: np.ndarray) -> tuple[float, float, float]:
    """Origin of a camera ray, uniform over the projected area of one period.

    A line of direction -v crossing a horizontal plane at a point uniform over one period
    is uniform over the period's projection orthogonal to v (a linear map, constant
    Jacobian cos theta_r), whichever plane: the groove's and the pit's mean plane z = 0,
    the plane just above the height field's highest point.  For the pitted plane the
    period is the orifice disk (the flat rest of the plane is exact: see
    :func:`gonio.surfaces.render.render`).
    """
    if kind == VGROOVE:
        return 2.0 * _uniform(state) - 1.0, 0.0, 0.0
    if kind == PIT:
        r = shape[1] * math.sqrt(_uniform(state))
        angle = _TWO_PI * _uniform(state)
        return r * math.cos(angle), r * math.sin(angle), 0.0
    n = heights.shape[0]
    return n * _uniform(state), n * _uniform(state), shape[0] + 1e-9 * (1.0 + abs(shape[0]))


@njit(cache=True, nogil=True)
def _visible(kind: int, shape: np.ndarray, heights, cell_top, px, py, pz, facet: int,
             sx, sy, sz) -> tuple[bool, int]:
    """Whether the source direction s is unobstructed from p (and segments traced)."""
    if kind == PIT:
        inside_hit, _, _, _ = _pit_chord(shape[0], px, py, pz, sx, sy, sz)
        return not inside_hit, 1
    hit, _, _, _, _, _, _, crossed = _trace(kind, shape, heights, cell_top, px, py, pz, facet, sx, sy, sz)
    return hit == -1, crossed


@njit(cache=True, nogil=True)
def _path_frame(kind: int, params: np.ndarray, shape: np.ndarray, state: np.ndarray) -> float:
    """Per-path constants into ``shape``; returns the azimuth [rad] of the sample frame.

    VGROOVE: slope fixed (params[2]) or Gaussian with sigma params[2] (params[1] = 1);
    groove azimuth fixed (params[4]) or uniform (params[3] = 1).  PIT: cos psi, sin psi.
    FIELD: the highest point (params[1]) and a uniform azimuth.
    """
    if kind == VGROOVE:
        slope = _gaussian_slope(params[2], state) if params[1] == 1.0 else params[2]
        shape[0], shape[1], shape[2] = math.tan(slope), math.sin(slope), math.cos(slope)
        return _TWO_PI * _uniform(state) if params[3] == 1.0 else params[4]
    if kind == PIT:
        shape[0], shape[1] = math.cos(params[1]), math.sin(params[1])
        return 0.0
    shape[0] = params[1]
    return _TWO_PI * _uniform(state)


@njit(cache=True, nogil=True)
def _rotated(x: float, y: float, z: float, azimuth: float) -> tuple[float, float, float]:
    """(x, y, z) in a frame turned by ``azimuth`` about the normal."""
    c, s = math.cos(azimuth), math.sin(azimuth)
    return c * x + s * y, -s * x + c * y, z


# --------------------------------------------------------------------------- V-groove, expected bounces
@njit(cache=True, nogil=True)
def _lit_from(tan_a: float, sx_mirror: float, sz: float) -> float:
    """Lowest lit position v (0: bottom, 1: top) of facet 1 in the frame where source x is
    ``sx_mirror``: the shadow line of the top of facet 0, (-1, 0) along -s, meets facet 1
    at x = -(1 + r)/(1 - r), r = tan_a sx/sz (facet 1 faces the source iff r < 1)."""
    r = tan_a * sx_mirror / sz
    return max(0.0, -(1.0 + r) / (1.0 - r))


@njit(cache=True, nogil=True)
def _strip_sine(tan_a: float, sin_a: float, cos_a: float, u: float, v: float) -> float:
    """sin of the angle from the normal of facet 0, in the groove's cross-section, under
    which its point at u sees the point v of facet 1 (u, v: 0 bottom, 1 top)."""
    dx, dz = v + u, tan_a * (v - u)
    length = math.sqrt(dx * dx + dz * dz)
    return (-dx * cos_a + dz * sin_a) / length if length > 0.0 else -1.0


@njit(cache=True, nogil=True)
def _groove_expected_path(params, shape, source, view, max_bounces: int, state: np.ndarray,
                          bins: np.ndarray) -> int:
    """One path of a V-groove with the light of every bounce integrated over the facet.

    In a long groove everything depends on the cross-section alone (Oren & Nayar 1995,
    eq 18).  A facet point u (0 bottom, 1 top) sees the other facet's point v under the
    cross-section angle phi from its normal; the share of the light a Lambertian point
    sends that lands on the strip [v1, v2] of the other facet is the integral of the
    translational-symmetry kernel K'/pi of eq 19 over the strip, in closed form the view
    factor F = |sin phi(v2) - sin phi(v1)| / 2 (Siegel & Howell, Thermal Radiation Heat
    Transfer: the crossed-strings result for an infinitely long strip; sin phi is uniform
    over the light a point sends).  A collimated source lights the other facet uniformly
    on [v_lit, 1] (the shadow of the near top edge: v_lit = m^s/w of eq 21), so the next
    vertex's direct light has the conditional expectation
    w rho * rho (n'.s)+ F(u -> [v_lit, 1]), which is added in place of its traced 0-or-1
    sample; the path then moves to a point of the other facet drawn with sin phi uniform
    over the whole facet, with weight times rho F(u -> [0, 1]), and so on.  The first
    vertex (the camera ray's hit) keeps its exact 0-or-1 shadow test (is it on its
    facet's lit strip).  With all bounces, a weight below 1e-4 goes on with probability
    weight/1e-4 at weight 1e-4 (Russian roulette, unbiased).  Returns 1 if the path was
    cut at BOUNCE_CAP.
    """
    rho = params[0]
    azimuth = _path_frame(VGROOVE, params, shape, state)
    tan_a, sin_a, cos_a = shape[0], shape[1], shape[2]
    sx, _, sz = _rotated(source[0], source[1], source[2], azimuth)
    vx, _, vz = _rotated(view[0], view[1], view[2], azimuth)
    ox = 2.0 * _uniform(state) - 1.0  # the camera ray of _camera_origin, traced in the cross-section
    facet, t = _groove_trace(tan_a, ox, 0.0, -vx, -vz, -1)
    bins[0] = bins[1] = bins[2] = 0.0
    if facet < 0:
        return 0
    u = min(abs(ox - t * vx), 1.0)
    # frame mirrored so that the current facet is facet 0: source x is sx (facet 0) or -sx
    mirror = sx if facet == 0 else -sx
    own_cosine = sin_a * mirror + cos_a * sz
    if own_cosine > 0.0 and u >= _lit_from(tan_a, -mirror, sz):
        bins[0] += rho * own_cosine
    weight = 1.0
    vertex = 1
    while tan_a > 0.0:
        if max_bounces > 0 and vertex >= max_bounces:
            return 0
        if vertex >= BOUNCE_CAP:
            return 1
        bottom = _strip_sine(tan_a, sin_a, cos_a, u, 0.0)
        top = _strip_sine(tan_a, sin_a, cos_a, u, 1.0)
        other_cosine = -sin_a * mirror + cos_a * sz
        if other_cosine > 0.0:
            lit = _strip_sine(tan_a, sin_a, cos_a, u, _lit_from(tan_a, mirror, sz))
            bins[min(vertex + 1, 3) - 1] += weight * rho * rho * other_cosine * 0.5 * abs(top - lit)
        weight *= rho * 0.5 * abs(top - bottom)
        if weight <= 0.0:
            return 0
        if max_bounces == 0 and weight < 1e-4:
            if _uniform(state) * 1e-4 >= weight:
                return 0
            weight = 1e-4
        sine = bottom + (top - bottom) * _uniform(state)
        cosine = math.sqrt(max(0.0, 1.0 - sine * sine))
        # direction cos(phi) n0 + sin(phi) t0 (n0 = (sin a, cos a), t0 = (-cos a, sin a)) from
        # p = (-u, tan_a (u - 1)) to the line of facet 1, z = tan_a (x - 1)
        dx, dz = cosine * sin_a - sine * cos_a, cosine * cos_a + sine * sin_a
        x0, z0 = -u, tan_a * (u - 1.0)
        step = (tan_a * (x0 - 1.0) - z0) / (dz - tan_a * dx)
        u = min(max(x0 + step * dx, 0.0), 1.0)
        mirror = -mirror
        vertex += 1
    return 0


@njit(cache=True, nogil=True)
def _one_path(kind, params, shape, heights, cell_top, source, view, max_bounces: int,
              state: np.ndarray, bins: np.ndarray) -> tuple[int, int]:
    """Trace one path; its three bin contributions (unscaled) into ``bins``.

    Returns (1 if cut at the bounce cap else 0, segments traced); a lost height-field ray
    is reported as segments = -1.
    """
    rho = params[0]
    azimuth = _path_frame(kind, params, shape, state)
    sx, sy, sz = _rotated(source[0], source[1], source[2], azimuth)
    vx, vy, vz = _rotated(view[0], view[1], view[2], azimuth)
    ox, oy, oz = _camera_origin(kind, shape, heights, state)
    facet, px, py, pz, nx, ny, nz, segments = _trace(kind, shape, heights, cell_top, ox, oy, oz, -1, -vx, -vy, -vz)
    bins[0] = bins[1] = bins[2] = 0.0
    if facet < 0:
        return 0, -1
    weight = 1.0
    vertex = 1
    while True:
        cosine = nx * sx + ny * sy + nz * sz
        if cosine > 0.0:
            seen, crossed = _visible(kind, shape, heights, cell_top, px, py, pz, facet, sx, sy, sz)
            segments += crossed
            if seen:
                bins[min(vertex, 3) - 1] += weight * rho * cosine
        if max_bounces > 0 and vertex >= max_bounces:
            return 0, segments
        if max_bounces == 0 and vertex >= 2:
            if _uniform(state) >= rho:  # Russian roulette, survival rho: weight unchanged
                return 0, segments
        else:
            weight *= rho
            if weight == 0.0:
                return 0, segments
        if vertex >= BOUNCE_CAP:
            return 1, segments
        dx, dy, dz = _cosine_direction(nx, ny, nz, state)
        facet, px, py, pz, nx, ny, nz, crossed = _trace(kind, shape, heights, cell_top, px, py, pz, facet, dx, dy, dz)
        segments += crossed
        if facet == -2:
            return 0, -1
        if facet < 0:
            return 0, segments
        vertex += 1


@njit(cache=True, nogil=True)
def render_geometries(kind: int, params: np.ndarray, heights: np.ndarray, cell_top: np.ndarray,
                      sources: np.ndarray, views: np.ndarray, seeds: np.ndarray, paths: int,
                      max_bounces: int, out: np.ndarray, expected: bool = False) -> None:
    """Accumulate ``paths`` paths for each geometry into ``out`` (G, ACCUMULATORS).

    Parameters
    ----------
    kind : int
        VGROOVE, PIT or FIELD.
    params : numpy.ndarray
        rho, then the kind's constants (see ``_path_frame``).
    heights, cell_top : numpy.ndarray
        FIELD: the N x N heights and each cell's highest corner [cell units]; others: any
        (1, 1) arrays.
    sources, views : numpy.ndarray
        Unit directions (G, 3) of the source and the viewer, z > 0.
    seeds : numpy.ndarray
        uint64 (G,): the stream of each geometry.
    paths : int
        Paths per geometry.
    max_bounces : int
        Vertices per path (1 = direct light only); 0: all, by Russian roulette.
    out : numpy.ndarray
        Receives the accumulators (module notes) of each geometry; the bins are divided by
        pi cos(theta_i), so that their means are BRDF contributions [1/sr].
    expected : bool
        VGROOVE only: integrate the light of each bounce over the other facet
        (:func:`_groove_expected_path`) instead of tracing it.
    """
    shape = np.zeros(4)
    bins = np.zeros(3)
    state = np.empty(1, np.uint64)
    for g in range(sources.shape[0]):
        scale = 1.0 / (math.pi * sources[g, 2])
        for k in range(ACCUMULATORS):
            out[g, k] = 0.0
        for k in range(paths):
            state[0] = path_state(seeds[g], k)
            if expected and kind == VGROOVE:
                cut, segments = _groove_expected_path(params, shape, sources[g], views[g], max_bounces, state,
                                                      bins), 1
            else:
                cut, segments = _one_path(kind, params, shape, heights, cell_top, sources[g], views[g],
                                          max_bounces, state, bins)
            b0, b1, b2 = bins[0] * scale, bins[1] * scale, bins[2] * scale
            if k == 0:
                out[g, 11], out[g, 12], out[g, 13] = b0, b1, b2
                out[g, 14], out[g, 15] = b0 + b1, b0 + b1 + b2
            out[g, 0] += b0
            out[g, 1] += b1
            out[g, 2] += b2
            d0, d1, d2 = b0 - out[g, 11], b1 - out[g, 12], b2 - out[g, 13]
            d01, d012 = b0 + b1 - out[g, 14], b0 + b1 + b2 - out[g, 15]
            out[g, 3] += d0 * d0
            out[g, 4] += d1 * d1
            out[g, 5] += d2 * d2
            out[g, 6] += d01 * d01
            out[g, 7] += d012 * d012
            out[g, 8] += cut
            if segments < 0:
                out[g, 9] += 1.0
            else:
                out[g, 10] += segments
