"""Single scattering of a spherical pit in closed form (compiled with numba).

The same integral as :mod:`.quadrature` (eq 14-15 with the Lambertian micro-BRDF, eq 5),

    I = integral over R of (m.i)(m.e) d omega_m,

over the lit and visible part R of the cavity, written over the macro-scale normals m on
the unit sphere (see :mod:`.cavity`), evaluated without quadrature: R is an intersection
of three spherical caps and Stokes' theorem turns the area integral into a sum over the
circular arcs of its boundary, each integrated in closed form.

Derivation
----------
*Region.*  With ``i = (sin a, 0, cos a)``, ``e = (sin b cos eps, sin b sin eps, cos b)``
and the mirror vectors ``s_lit = (sin 2a, 0, cos 2a)``,
``s_vis = (sin 2b cos eps, sin 2b sin eps, cos 2b)``,
R is the intersection of the caps ``m.g_k >= kappa_k``: the cavity (g_0 = z,
kappa_0 = cos psi, angular radius psi), the lit cap (g_1 = s_lit, kappa_1 = -cos psi) and
the visible cap (g_2 = s_vis, kappa_2 = -cos psi); the last two have angular radius
pi - psi (they are the complements of the caps of radius psi about -s_lit and -s_vis).

*Integrand.*  ``(m.i)(m.e) = m^T A m`` with ``A = (i e^T + e i^T)/2``.  On the sphere
``m^T A m = (i.e)/3 + h`` where ``h = m^T A_0 m``, ``A_0 = A - (i.e/3) Id``, is a harmonic
polynomial of degree 2, so ``Delta h = -6 h`` (Laplace-Beltrami operator) and, by the
divergence theorem, ``integral_R h = -(1/6) loop dh/dnu ds = -(1/3) loop nu^T A m ds``
(nu the outward unit conormal; ``nu.m = 0`` lets A replace A_0).

*Area.*  ``Area(R) = loop eta`` with ``eta = (1 - cos t) du`` (polar angle t, azimuth u
about z), ``d eta = sin t dt du``; eta is smooth except at -z, which is never in R.  On a
circle ``m(phi) = cos(th) c + sin(th) (cos(phi) e1 + sin(phi) e2)`` ((e1, e2, c)
right-handed) ``eta = [-cos th + (c_z + cos th) / (D + E cos x)] dphi`` with
``D = 1 + cos(th) c_z``, ``E cos x = sin(th) (cos(phi) e1_z + sin(phi) e2_z)``,
``D^2 - E^2 = (c_z + cos th)^2``; with ``w = |c_z + cos th|`` the continuous antiderivative
of the second term is ``sign(c_z + cos th) [x - 2 atan(E sin x / (D + w + E cos x))]``
(its denominator is positive for every x).

*Arcs.*  Each boundary circle k (centre g_k, cos th = kappa_k) is traversed in +phi with
nu = dm/dth (for the lit and visible caps this is the boundary of the cap of radius psi
about -s traversed backwards); its part on the boundary of R is where both other caps
hold.  Cap j meets circle k in the arc ``|phi - phi_kj| <= h_kj`` about the azimuth
phi_kj of g_j, with ``h_kj = atan2(sqrt(Q), kappa_j - g kappa_k)``, ``g = g_k.g_j`` and
``Q = 1 - g^2 - kappa_k^2 - kappa_j^2 + 2 g kappa_k kappa_j`` (Q <= 0: the circles do not
cross, the arc is empty or the whole circle); the intersection of the two arcs is at
most two intervals.  On an arc ``nu^T A m ds`` is a trigonometric polynomial of degree 2
in phi, integrated in closed form, and

    I = (1/3) sum over arcs [ (i.e) integral eta - integral nu^T A m ds ].

*Degenerate cases.*  Both circles of a pair take their crossing points from the same Q and
the same cross product ``g_k x g_j`` (for the rim and a mirror cap, ``h`` and ``pi - h``):
computed separately, the ends of two arcs that should meet differ by up to
sqrt(machine epsilon) where circles are tangent or nearly coincide, and the boundary
would not close.  A cap that coincides with another (``s_lit = s_vis``: retro-reflection;
``s = z`` with psi = 90 deg, where the shadow circle is the rim) contributes its circle
once.  Where a circle lies whole inside both other caps its periodic terms are dropped
exactly, which keeps shallow pits (psi -> 0) accurate to rounding relative to I.

*Accuracy.*  Against the quadrature at order 64-96 the relative difference on 1e5 random
geometries is <= 1.4e-10 where I > 1e-6, the reference's own error (orders 192-384 agree with this
module to ~1e-15).  Where R is a thin sliver (grazing alpha or beta, forward scattering,
three circles through one point) the O(1) arc terms cancel to the small result, so the
error is absolute, a few 1e-16 in I: in the factor this is ~1e-17 / (sin^2 psi cos alpha
cos beta), e.g. ~1e-7 1/sr at alpha = beta = 90 deg - 1e-5 rad, where the factor ranges
from 0 (forward) to 2e4 (retro).  I >= 0 is enforced (the integrand is nonnegative on R).

*Speed.*  About 180-200 ns per geometry on one core (5e6 geometries/s), against ~2e-5 s
for the order-16 quadrature.

References
----------
J. J. Koenderink, A. J. van Doorn, K. J. Dana, S. K. Nayar, "Bidirectional reflection
distribution function of thoroughly pitted surfaces", IJCV 31(2/3), 1999, eq 14-15
(BRDF as an integral over the lit and visible cavity) and section 4 (shallow pits).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .quadrature import FLAT_LIMIT, GRAZING_MARGIN

__all__ = [
    "single_scattering_integral_closed",
    "single_scattering_factor_closed",
    "integral_kernel",
    "integral_loop",
    "factor_loop",
]

_PI = math.pi
_TWO_PI = 2.0 * math.pi
_GRAZING_LIMIT = 0.5 * math.pi - GRAZING_MARGIN

_JIT = dict(cache=True, nogil=True, error_model="numpy")
#: helpers are inlined into the kernel at the numba level (measured: ~10% faster)
_JIT_INLINE = dict(_JIT, inline="always")


@njit(**_JIT_INLINE)
def _half_width(x: float, q: float, r: float) -> tuple[float, float, float]:
    """Half-width h [rad] of the arc where one cap meets a circle, cos h and sin h.

    ``(x, sqrt(q)) = r (cos h, sin h)``: ``x = kappa_j - g kappa_k``, ``q`` proportional
    to Q (module notes).  For q <= 0 the circles do not cross: h = pi (whole circle) if
    x < 0, h = 0 (empty) otherwise.
    """
    if q > 0.0:
        y = math.sqrt(q)
        return math.atan2(y, x), x / r, y / r
    if x < 0.0:
        return _PI, -1.0, 0.0
    return 0.0, 1.0, 0.0


@njit(**_JIT_INLINE)
def _norm(x: float, y: float) -> float:
    """``sqrt(x^2 + y^2)`` without underflow."""
    r2 = x * x + y * y
    if r2 > 1e-280:
        return math.sqrt(r2)
    return math.hypot(x, y)


@njit(**_JIT_INLINE)
def _arc_value(
    length: float, ca: float, sa: float, cb: float, sb: float,
    lin: float, bs: float, bc: float, cs2: float, cc2: float,
    atan_weight: float, kn: float, m0: float,
) -> float:
    """Closed-form integral over one arc from azimuth phi_a to phi_b = phi_a + length.

    ``(ca, sa)`` and ``(cb, sb)`` are the cosines and sines of the arc ends.  The
    antiderivative is ``lin phi + bs sin(phi) + bc cos(phi) + cs2 sin(2 phi)
    + cc2 cos(2 phi) + atan_weight atan(N / M)`` with ``N = kn sin(phi)``,
    ``M = m0 + kn cos(phi)`` (M >= 1 on the boundary of R); the atan difference is taken
    as one atan2, exact within (-pi, pi).
    """
    value = lin * length
    value += bs * (sb - sa) + bc * (cb - ca)
    value += cs2 * 2.0 * (sb * cb - sa * ca) + cc2 * ((cb - sb) * (cb + sb) - (ca - sa) * (ca + sa))
    if atan_weight != 0.0:
        na, ma = kn * sa, m0 + kn * ca
        nb, mb = kn * sb, m0 + kn * cb
        value += atan_weight * math.atan2(nb * ma - na * mb, ma * mb + na * nb)
    return value


@njit(**_JIT_INLINE)
def _circle_sum(
    p1: float, c1: float, s1: float, h1: float, ch1: float, sh1: float,
    p2: float, c2: float, s2: float, h2: float, ch2: float, sh2: float,
    lin: float, bs: float, bc: float, cs2: float, cc2: float,
    atan_weight: float, kn: float, m0: float,
) -> float:
    """Sum of :func:`_arc_value` over the part of one circle inside two caps.

    Cap 1 covers the azimuths ``|phi - p1| <= h1`` (``c1, s1``: cos and sin of p1;
    ``ch1, sh1``: of h1), cap 2 likewise; their intersection is at most two intervals.
    """
    if h1 <= 0.0 or h2 <= 0.0:
        return 0.0
    if h1 >= _PI and h2 >= _PI:
        # the whole circle: the periodic terms vanish exactly (split into arcs they would
        # leave rounding of their size, large against the result for small psi)
        return lin * _TWO_PI
    # cos and sin of the ends (start = p - h, end = p + h) by the addition theorems
    c1s, s1s = c1 * ch1 + s1 * sh1, s1 * ch1 - c1 * sh1
    c1e, s1e = c1 * ch1 - s1 * sh1, s1 * ch1 + c1 * sh1
    c2s, s2s = c2 * ch2 + s2 * sh2, s2 * ch2 - c2 * sh2
    c2e, s2e = c2 * ch2 - s2 * sh2, s2 * ch2 + c2 * sh2
    len1, len2 = 2.0 * h1, 2.0 * h2
    d = (p2 - h2) - (p1 - h1)  # start of arc 2 from the start of arc 1, reduced to [0, 2 pi)
    while d < 0.0:
        d += _TWO_PI
    while d >= _TWO_PI:
        d -= _TWO_PI
    total = 0.0
    if d < len1:  # from the start of arc 2 to the first end
        if d + len2 < len1:
            total += _arc_value(len2, c2s, s2s, c2e, s2e, lin, bs, bc, cs2, cc2, atan_weight, kn, m0)
        else:
            total += _arc_value(len1 - d, c2s, s2s, c1e, s1e, lin, bs, bc, cs2, cc2, atan_weight, kn, m0)
    over = d + len2 - _TWO_PI  # arc 2 wraps past the start of arc 1
    if over > 0.0:
        if over < len1:
            total += _arc_value(over, c1s, s1s, c2e, s2e, lin, bs, bc, cs2, cc2, atan_weight, kn, m0)
        else:
            total += _arc_value(len1, c1s, s1s, c1e, s1e, lin, bs, bc, cs2, cc2, atan_weight, kn, m0)
    return total


@njit(**_JIT_INLINE)
def _mirror_circle(
    cap0: tuple[float, float, float, float, float, float],
    cap_other: tuple[float, float, float, float, float, float],
    ic: float, i1: float, i2: float, ec: float, e1: float, e2: float, ie: float,
    cos_2s: float, sin_2s: float, cos_psi: float, sin_psi: float, one_minus_cos_psi: float,
) -> float:
    """Sum over the boundary arcs of a lit or visible cap (centre s, cos th = -cos psi).

    ``(ic, i1, i2)``, ``(ec, e1, e2)``: i and e in the circle frame
    ``c = s = (sin 2s cos, sin 2s sin, cos 2s)``, ``e1`` along increasing polar angle of s
    (``e1_z = -sin 2s``), ``e2`` horizontal.
    """
    ct, st = -cos_psi, sin_psi
    k0 = st * ct * (ie - 3.0 * ic * ec) * 0.5
    half_cos_2th = 0.5 * (ct - st) * (ct + st)
    quarter_sc = 0.25 * st * ct
    # area form: sign(c_z + cos th) with c_z = cos 2s; D + w in a cancellation-free form
    if cos_2s >= cos_psi:
        sign, sign_minus_ct, m0 = 1.0, 1.0 + cos_psi, (1.0 + cos_2s) * one_minus_cos_psi
    else:
        sign, sign_minus_ct, m0 = -1.0, -one_minus_cos_psi, (1.0 - cos_2s) * (1.0 + cos_psi)
    lin = ie * sign_minus_ct - st * k0
    bs = -st * half_cos_2th * (ic * e1 + ec * i1)
    bc = st * half_cos_2th * (ic * e2 + ec * i2)
    cs2 = -st * quarter_sc * (i1 * e1 - i2 * e2)
    cc2 = st * quarter_sc * (i1 * e2 + i2 * e1)
    return _circle_sum(
        cap0[0], cap0[1], cap0[2], cap0[3], cap0[4], cap0[5],
        cap_other[0], cap_other[1], cap_other[2], cap_other[3], cap_other[4], cap_other[5],
        lin, bs, bc, cs2, cc2, -2.0 * ie * sign, -sin_psi * sin_2s, m0,
    )


@njit(**_JIT_INLINE)
def _reduced_azimuth(epsilon: float) -> float:
    """epsilon [rad] reduced to [-pi, pi)."""
    if -_PI <= epsilon < _PI:
        return epsilon
    return (epsilon + _PI) % _TWO_PI - _PI


@njit(**_JIT)
def integral_kernel(
    alpha: float, beta: float, epsilon: float, cos_psi: float, sin_psi: float, one_minus_cos_psi: float
) -> float:
    """``integral (m.i)(m.e) d omega`` over the lit and visible cavity (R = 1) [sr].

    Scalar kernel of :func:`single_scattering_integral_closed`: angles [rad]
    (0 <= alpha, beta < pi/2; epsilon any), the aperture psi given as cos psi, sin psi and
    1 - cos psi (the last computed as 2 sin^2(psi/2) by the caller, for small psi).
    """
    eps = _reduced_azimuth(epsilon)
    return _integral(
        math.sin(alpha), math.cos(alpha), math.sin(beta), math.cos(beta),
        eps, math.sin(eps), math.cos(eps), cos_psi, sin_psi, one_minus_cos_psi,
    )


@njit(**_JIT)
def _integral(
    sa: float, ca: float, sb: float, cb: float, eps: float, se: float, ce: float,
    cp: float, sp: float, omc: float,
) -> float:
    """:func:`integral_kernel` from the sines and cosines of alpha, beta, eps (in [-pi, pi))."""
    if math.isnan(sa + sb + se + cp):
        return math.nan
    s2a, c2a = 2.0 * sa * ca, (ca - sa) * (ca + sa)
    s2b, c2b = 2.0 * sb * cb, (cb - sb) * (cb + sb)
    ie = sa * sb * ce + ca * cb

    # cavity and lit cap: (x, sqrt(Q)) / (2 cos a) = (-cos a cos psi,
    # sqrt(sin^2 a sin^2 psi - cos^2 a cos^2 psi)), of norm sin a sin psi; the arc is about
    # azimuth 0 on the cavity rim, about pi (towards z) on the lit circle, with half-widths
    # h and pi - h
    h_lit, ch_lit, sh_lit = _half_width(-ca * cp, (sa * sp - ca * cp) * (sa * sp + ca * cp), sa * sp)
    h_vis, ch_vis, sh_vis = _half_width(-cb * cp, (sb * sp - cb * cp) * (sb * sp + cb * cp), sb * sp)

    # lit and visible caps (same kappa): 1 - g = |s_lit - s_vis|^2 / 2,
    # Q = (1 - g)(2 sin^2 psi - (1 - g)), x = -cos psi (1 - g)
    dx, dy, dz = s2a - s2b * ce, s2b * se, c2a - c2b
    omg = 0.5 * (dx * dx + dy * dy + dz * dz)
    if omg == 0.0:  # the same cap: its circle counts once (on the lit side)
        h_lv, ch_lv, sh_lv = _PI, -1.0, 0.0
        h_vl, ch_vl, sh_vl = 0.0, 1.0, 0.0
    else:
        h_lv, ch_lv, sh_lv = _half_width(
            -cp * omg, omg * (2.0 * sp * sp - omg), sp * math.sqrt(omg * (2.0 - omg))
        )
        h_vl, ch_vl, sh_vl = h_lv, ch_lv, sh_lv
    # azimuths of the partner caps from one cross product v = s_lit x s_vis, projected on
    # both frames (shared rounding keeps the crossing points common to both circles)
    p_lv, c_lv, s_lv = 0.0, 1.0, 0.0
    p_vl, c_vl, s_vl = 0.0, 1.0, 0.0
    if 0.0 < h_lv < _PI:
        vy = c2a * s2b * ce - s2a * c2b
        v1, v2 = -s2b * se, vy  # v in the lit frame
        r = _norm(v1, v2)
        if r > 0.0:
            p_lv, c_lv, s_lv = math.atan2(-v1, v2), v2 / r, -v1 / r
        v1, v2 = -s2a * se, ce * vy + c2a * s2b * se * se  # v in the visible frame
        r = _norm(v1, v2)
        if r > 0.0:
            p_vl, c_vl, s_vl = math.atan2(v1, -v2), -v2 / r, v1 / r

    # cavity rim: centre z, cos th = cos psi, frame (x, y, z); area form (1 - cos psi) du
    ct, st = cp, sp
    k0 = st * ct * (ie - 3.0 * ca * cb) * 0.5
    half_cos_2th = 0.5 * (ct - st) * (ct + st)
    quarter_sc = 0.25 * st * ct
    i1, ec, e1, e2 = sa, cb, sb * ce, sb * se
    total = _circle_sum(
        0.0, 1.0, 0.0, h_lit, ch_lit, sh_lit,
        eps, ce, se, h_vis, ch_vis, sh_vis,
        ie * omc - st * k0,
        -st * half_cos_2th * (ca * e1 + ec * i1),
        st * half_cos_2th * (ca * e2),
        -st * quarter_sc * (i1 * e1),
        st * quarter_sc * (i1 * e2),
        0.0, 0.0, 1.0,
    )
    # lit circle: centre s_lit, e1 = (cos 2a, 0, -sin 2a), e2 = y; i = (cos a, -sin a, 0)
    total += _mirror_circle(
        (_PI, -1.0, 0.0, _PI - h_lit, -ch_lit, sh_lit),
        (p_lv, c_lv, s_lv, h_lv, ch_lv, sh_lv),
        ca, -sa, 0.0, sb * ce * s2a + cb * c2a, sb * ce * c2a - cb * s2a, sb * se, ie,
        c2a, s2a, cp, sp, omc,
    )
    # visible circle: centre s_vis, e1 = (cos 2b cos eps, cos 2b sin eps, -sin 2b),
    # e2 = (-sin eps, cos eps, 0); e = (cos b, -sin b, 0)
    total += _mirror_circle(
        (_PI, -1.0, 0.0, _PI - h_vis, -ch_vis, sh_vis),
        (p_vl, c_vl, s_vl, h_vl, ch_vl, sh_vl),
        sa * s2b * ce + ca * c2b, sa * c2b * ce - ca * s2b, -sa * se, cb, -sb, 0.0, ie,
        c2b, s2b, cp, sp, omc,
    )
    # the integrand is >= 0 on R (m.i >= 0 where lit, m.e >= 0 where visible): a thin
    # sliver may come out as -1e-17 (written so that NaN propagates)
    if total < 0.0:
        return 0.0
    return total / 3.0


@njit(**_JIT_INLINE)
def _aperture(psi: float) -> tuple[float, float, float]:
    """cos psi, sin psi and 1 - cos psi = 2 sin^2(psi/2) (accurate for small psi)."""
    half = math.sin(0.5 * psi)
    return math.cos(psi), math.sin(psi), 2.0 * half * half


@njit(**_JIT)
def integral_loop(
    alpha: np.ndarray, beta: np.ndarray, epsilon: np.ndarray, psi: np.ndarray, out: np.ndarray
) -> None:
    """:func:`integral_kernel` over 1-D arrays of equal length [rad], written to ``out`` [sr]."""
    last_psi, cp, sp, omc = np.nan, 0.0, 0.0, 0.0
    for n in range(alpha.size):
        if psi[n] != last_psi:  # apertures usually repeat: their trigonometry once
            last_psi = psi[n]
            cp, sp, omc = _aperture(last_psi)
        out[n] = integral_kernel(alpha[n], beta[n], epsilon[n], cp, sp, omc)


@njit(**_JIT)
def factor_loop(
    alpha: np.ndarray, beta: np.ndarray, epsilon: np.ndarray, psi: np.ndarray, out: np.ndarray
) -> None:
    """Single-scattering factor [1/sr] over 1-D arrays of equal length (angles [rad]).

    ``I / (pi^2 sin^2 psi cos alpha cos beta)`` with the conventions of
    :func:`.quadrature.single_scattering_factor`: angles beyond pi/2 - GRAZING_MARGIN are
    moved there, and 1/pi where ``sin^2 psi < FLAT_LIMIT``.
    """
    last_psi, cp, sp, omc = np.nan, 0.0, 0.0, 0.0
    for n in range(alpha.size):
        if psi[n] != last_psi:
            last_psi = psi[n]
            cp, sp, omc = _aperture(last_psi)
        if sp * sp < FLAT_LIMIT:
            out[n] = 1.0 / _PI
            continue
        a = _GRAZING_LIMIT if alpha[n] > _GRAZING_LIMIT else alpha[n]  # NaN stays NaN
        b = _GRAZING_LIMIT if beta[n] > _GRAZING_LIMIT else beta[n]
        ca, cb = math.cos(a), math.cos(b)
        eps = _reduced_azimuth(epsilon[n])
        value = _integral(math.sin(a), ca, math.sin(b), cb, eps, math.sin(eps), math.cos(eps), cp, sp, omc)
        out[n] = value / (_PI * _PI * sp * sp * ca * cb)


def _flat_arrays(*arrays: np.ndarray) -> tuple[tuple[int, ...], list[np.ndarray]]:
    """Broadcast the inputs; return the shape and contiguous 1-D float64 copies."""
    broadcast = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in arrays))
    shape = broadcast[0].shape
    return shape, [np.ascontiguousarray(a, dtype=np.float64).ravel() for a in broadcast]


def single_scattering_integral_closed(
    alpha: np.ndarray, beta: np.ndarray, epsilon: np.ndarray, psi: float | np.ndarray
) -> np.ndarray:
    """``integral (m.i)(m.e) d omega`` over the lit and visible cavity (R = 1), closed form.

    The integral of :func:`.quadrature.single_scattering_integral` (eq 14-15), exact to
    rounding (module notes).

    Parameters
    ----------
    alpha : numpy.ndarray
        Source co-elevation [rad], 0 <= alpha < pi/2.
    beta : numpy.ndarray
        Viewer co-elevation [rad], 0 <= beta < pi/2.
    epsilon : numpy.ndarray
        Viewer azimuth from the plane of incidence [rad] (0: backward, pi: forward).
    psi : float or numpy.ndarray
        Aperture [rad], 0 < psi <= pi/2 (broadcast with the angles).

    Returns
    -------
    numpy.ndarray
        The integral [sr], broadcast shape of the inputs.

    Examples
    --------
    >>> round(float(single_scattering_integral_closed(0.0, 0.0, 0.0, np.pi / 2)), 12)  # 2 pi / 3
    2.094395102393
    """
    shape, (a, b, e, p) = _flat_arrays(alpha, beta, epsilon, psi)
    out = np.empty(a.size)
    integral_loop(a, b, e, p, out)
    return out.reshape(shape)


def single_scattering_factor_closed(
    alpha: np.ndarray, beta: np.ndarray, epsilon: np.ndarray, psi: float | np.ndarray
) -> np.ndarray:
    """Single-scattering BRDF of one pit per unit micro-albedo [1/sr], closed form.

    ``I / (pi^2 sin^2(psi) cos(alpha) cos(beta))`` with I from
    :func:`single_scattering_integral_closed`: eq 15 divided by the plane irradiance
    (eq 1), Lambertian micro-radiance (eq 5), orifice area ``pi sin^2 psi``; the same
    conventions as :func:`.quadrature.single_scattering_factor` (alpha, beta beyond
    pi/2 - GRAZING_MARGIN moved there; 1/pi for ``sin^2 psi < FLAT_LIMIT``).  Angles [rad].

    Examples
    --------
    >>> round(float(single_scattering_factor_closed(0.3, 0.5, 1.0, 1e-4) * np.pi), 6)  # flat: 1/pi
    1.0
    """
    shape, (a, b, e, p) = _flat_arrays(alpha, beta, epsilon, psi)
    out = np.empty(a.size)
    factor_loop(a, b, e, p, out)
    return out.reshape(shape)[()]  # a NumPy scalar for scalar input, as the quadrature
