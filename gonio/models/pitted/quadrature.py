"""Single scattering of a spherical pit of any aperture by deterministic quadrature.

The single-scattering BRDF of a pit is an integral of ``(m.i)(m.e)`` over the part of
the cavity that is both lit and visible (eq 14-15 with the Lambertian micro-BRDF, eq 5).
Written over the macro-scale normals m (unit sphere, R = 1, ``da = d omega_m``), the
cavity is the cap ``m_z >= cos psi`` and the lit and visible regions are
``m.s >= -cos psi`` for the mirror vectors ``s = 2 (d.z) d - z`` of the source and the
viewer (see :mod:`.cavity`).  In polar coordinates (t, u) about the normal z each of the
two conditions is an arc of azimuths u, found in closed form, and the integrand is a
trigonometric polynomial in u, integrated in closed form over the intersection of the two
arcs.  What remains is a one-dimensional integral over t in [0, psi], done by
Gauss-Legendre panels split at every kink of the inner integral (an arc becoming empty
or complete, the two boundary circles crossing), with a cosine substitution that removes
the square-root behaviour at the panel ends, so the rule converges spectrally (16 nodes
per panel: ~1e-9 RMS relative error; docs/pitted.md).

The registered ``pitted`` model evaluates the same integral in closed form
(:mod:`.closed_form`); this quadrature is the independent reference it is tested
against, and the model uses it where the closed form's absolute accuracy is not enough
(directions within ~1e-5 rad of the horizon).  It is the same integral that the Monte
Carlo method of section 4.1 estimates, and for psi = 90 deg the same integral as eq 21
(there with the polar axis in the surface, here along the normal, which makes the
shallow-pit boundaries simple).

References
----------
J. J. Koenderink, A. J. van Doorn, K. J. Dana, S. K. Nayar, IJCV 31(2/3), 1999,
eq 14-15 (BRDF as an integral over the visible cavity), section 4 (shallow pits).
"""
from __future__ import annotations

import numpy as np

__all__ = ["single_scattering_integral", "single_scattering_factor", "GRAZING_MARGIN", "DEFAULT_ORDER"]

#: Angles closer to 90 deg than this [rad] are evaluated at 90 deg - GRAZING_MARGIN: the
#: BRDF has a finite limit at grazing incidence/view, but the formula is 0/0 there.
GRAZING_MARGIN = 1e-7

#: Below this value of sin^2(psi) the pit is flat to double precision (the factor is
#: 1/pi + O(psi^2)) and is returned as 1/pi instead of dividing underflowed numbers.
FLAT_LIMIT = 1e-200

#: Gauss-Legendre nodes per panel: ~1e-9 RMS relative error (benchmarks/bench_pitted.py).
DEFAULT_ORDER = 16


def _arc(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Half-width a [rad] of the arc of u where ``x cos(u) >= y`` (x >= 0), cos a, sin a."""
    partial = x > np.abs(y)  # divide only there, so |y/x| < 1 and nothing overflows
    cos_a = np.clip(np.divide(y, x, out=np.where(y > 0.0, 1.0, -1.0), where=partial), -1.0, 1.0)
    sin_a = np.sqrt((1.0 - cos_a) * (1.0 + cos_a))
    return np.arccos(cos_a), cos_a, sin_a


def _periodic_part(sin_u, cos_u, k1, k2, k3, ce, se):
    """Periodic part of the antiderivative in u of ``(m.i)(m.e)``.

    With m = (st cos u, st sin u, ct), i = (sa, 0, ca), e = (sb ce, sb se, cb):
    ``(m.i)(m.e) = st^2 sa sb cos u cos(u - eps) + st ct sa cb cos u
    + ct st ca sb cos(u - eps) + ct^2 ca cb``, whose antiderivative is
    ``k1 sin(2u - eps) + k2 sin u + k3 sin(u - eps) + lin u`` with
    k1 = st^2 sa sb / 4, k2 = st ct sa cb, k3 = st ct ca sb and
    lin = st^2 sa sb ce / 2 + ct^2 ca cb.  Written in sin u and cos u so that the arc ends
    need no further trigonometric calls.
    """
    sin_2u_eps = 2.0 * sin_u * cos_u * ce - (cos_u * cos_u - sin_u * sin_u) * se
    return k1 * sin_2u_eps + k2 * sin_u + k3 * (sin_u * ce - cos_u * se)


def _breakpoints(alpha: np.ndarray, beta: np.ndarray, epsilon: np.ndarray, psi: float) -> np.ndarray:
    """Panel edges in t ``(n, 8)``: every t where the inner integral has a kink.

    These are where the lit or the visible arc becomes empty or complete (the boundary
    circle touches the circle of constant t) and the polar angles of the two points where
    the shadow boundary crosses the visibility boundary (there the end of one arc passes
    the end of the other).
    """
    candidates = [np.zeros_like(alpha), np.full_like(alpha, psi)]
    for angle in (alpha, beta):
        candidates.append(np.pi - psi - 2.0 * angle)
        candidates.append(2.0 * angle + psi - np.pi)
    s_lit = np.stack([np.sin(2 * alpha), np.zeros_like(alpha), np.cos(2 * alpha)], axis=-1)
    s_vis = np.stack(
        [np.sin(2 * beta) * np.cos(epsilon), np.sin(2 * beta) * np.sin(epsilon), np.cos(2 * beta)], axis=-1
    )
    g = np.sum(s_lit * s_vis, axis=-1)
    cross = np.cross(s_lit, s_vis)
    cross_norm2 = np.sum(cross * cross, axis=-1)
    # crossing points m = lam (s_lit + s_vis) + nu (s_lit x s_vis): m.s = -cos psi for
    # both mirror vectors and |m| = 1
    # (when s_lit = +-s_vis the circles coincide or are disjoint: no crossing point)
    crossing = (cross_norm2 > 1e-24) & (1.0 + g > 1e-12)
    one_plus_g = np.where(crossing, 1.0 + g, 1.0)
    lam = -np.cos(psi) / one_plus_g
    nu2 = np.where(crossing, (1.0 - 2.0 * lam * lam * one_plus_g) / np.where(crossing, cross_norm2, 1.0), -1.0)
    nu = np.sqrt(np.maximum(nu2, 0.0))
    base_z = lam * (s_lit[..., 2] + s_vis[..., 2])
    for sign in (1.0, -1.0):
        z = np.clip(base_z + sign * nu * cross[..., 2], -1.0, 1.0)
        candidates.append(np.where(nu2 > 0.0, np.arccos(z), 0.0))
    edges = np.clip(np.stack(candidates, axis=-1), 0.0, psi)
    return np.sort(edges, axis=-1)


def _panel_rule(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes in [0, 1] and weights of Gauss-Legendre after the substitution x = (1 - cos v)/2.

    At a panel end where an arc appears, vanishes or becomes complete the inner integral
    behaves like the square root of the distance to the end; the substitution makes it
    smooth in v, so the rule converges spectrally instead of algebraically.
    """
    v, w = np.polynomial.legendre.leggauss(order)
    v = 0.5 * np.pi * (v + 1.0)
    return 0.5 * (1.0 - np.cos(v)), 0.25 * np.pi * np.sin(v) * w


def single_scattering_integral(
    alpha: np.ndarray, beta: np.ndarray, epsilon: np.ndarray, psi: float, order: int = DEFAULT_ORDER
) -> np.ndarray:
    """``integral (m.i)(m.e) d omega`` over the lit and visible cavity (R = 1).

    Parameters
    ----------
    alpha : numpy.ndarray
        Source co-elevation [rad], 0 <= alpha < pi/2.
    beta : numpy.ndarray
        Viewer co-elevation [rad], 0 <= beta < pi/2.
    epsilon : numpy.ndarray
        Viewer azimuth from the plane of incidence [rad] (0: backward, pi: forward).
    psi : float
        Aperture [rad], 0 < psi <= pi/2.
    order : int
        Gauss-Legendre nodes per panel (7 panels, some possibly empty).

    Returns
    -------
    numpy.ndarray
        The integral [sr], broadcast shape of the angles.

    Examples
    --------
    >>> round(float(single_scattering_integral(0.0, 0.0, 0.0, np.pi / 2)), 9)  # 2 pi / 3
    2.094395102
    """
    alpha, beta, epsilon = (np.asarray(a, float) for a in np.broadcast_arrays(alpha, beta, epsilon))
    shape = alpha.shape
    alpha, beta, epsilon = alpha.ravel(), beta.ravel(), epsilon.ravel()
    if alpha.size == 0:  # nothing to integrate (e.g. no geometry needs the quadrature)
        return np.zeros(shape)
    eps = np.remainder(epsilon + np.pi, 2.0 * np.pi) - np.pi  # (-pi, pi]
    nodes, weights = _panel_rule(int(order))
    edges = _breakpoints(alpha, beta, eps, psi)
    lo, hi = edges[:, :-1, None], edges[:, 1:, None]
    t = (lo + (hi - lo) * nodes).reshape(len(alpha), -1)  # (n, panels * order)
    w = ((hi - lo) * weights).reshape(len(alpha), -1)

    col = lambda a: a[:, None]  # noqa: E731
    sa, ca, sb, cb = col(np.sin(alpha)), col(np.cos(alpha)), col(np.sin(beta)), col(np.cos(beta))
    ce, se, e = col(np.cos(eps)), col(np.sin(eps)), col(eps)
    st, ct = np.sin(t), np.cos(t)
    cos_psi = np.cos(psi)
    # lit: m.s_i >= -cos psi with s_i = (sin 2a, 0, cos 2a)  ->  X cos u >= Y, arc about 0;
    # visible: the same with beta, arc about eps
    a_lit, c_lit, s_lit = _arc(col(np.sin(2.0 * alpha)) * st, -cos_psi - col(np.cos(2.0 * alpha)) * ct)
    a_vis, c_vis, s_vis = _arc(col(np.sin(2.0 * beta)) * st, -cos_psi - col(np.cos(2.0 * beta)) * ct)
    k1 = 0.25 * st * st * sa * sb
    k2 = st * ct * sa * cb
    k3 = st * ct * ca * sb
    lin = 2.0 * k1 * ce + ct * ct * ca * cb
    part = lambda sin_u, cos_u: _periodic_part(sin_u, cos_u, k1, k2, k3, ce, se)  # noqa: E731
    lit_lo, lit_hi = part(-s_lit, c_lit), part(s_lit, c_lit)
    vis_lo = part(se * c_vis - ce * s_vis, ce * c_vis + se * s_vis)  # at u = eps - a_vis
    vis_hi = part(se * c_vis + ce * s_vis, ce * c_vis - se * s_vis)  # at u = eps + a_vis
    inner = np.zeros_like(t)
    for turn in (-2.0 * np.pi, 0.0, 2.0 * np.pi):
        # intersection of [-a_lit, a_lit] with the visible arc shifted by whole turns
        start, stop = e - a_vis + turn, e + a_vis + turn
        from_vis_lo, from_vis_hi = start > -a_lit, stop < a_lit
        u_lo = np.where(from_vis_lo, start, -a_lit)
        u_hi = np.where(from_vis_hi, stop, a_lit)
        value = (np.where(from_vis_hi, vis_hi, lit_hi) - np.where(from_vis_lo, vis_lo, lit_lo)
                 + lin * (u_hi - u_lo))
        inner += np.where(u_hi > u_lo, value, 0.0)
    return np.sum(inner * st * w, axis=-1).reshape(shape)


def single_scattering_factor(
    alpha: np.ndarray, beta: np.ndarray, epsilon: np.ndarray, psi: float, order: int = DEFAULT_ORDER
) -> np.ndarray:
    """Single-scattering BRDF of one pit per unit micro-albedo [1/sr].

    ``I / (pi^2 sin^2(psi) cos(alpha) cos(beta))`` with I from
    :func:`single_scattering_integral`: eq 15 divided by the plane irradiance (eq 1), with
    the Lambertian micro-radiance ``(rho/pi) H_perp m.i`` (eq 5) and orifice area
    ``pi sin^2 psi``.  Angles [rad]; alpha and beta within GRAZING_MARGIN of pi/2 are
    moved to that margin (the factor is continuous there except towards grazing
    retro-reflection, where it grows like 1/cos).

    Examples
    --------
    >>> round(float(single_scattering_factor(0.3, 0.5, 1.0, 1e-4) * np.pi), 6)  # flat: 1/pi
    1.0
    """
    if np.sin(psi) ** 2 < FLAT_LIMIT:
        # the factor is 1/pi + O(psi^2); below this the orifice area underflows
        shape = np.broadcast_shapes(np.shape(alpha), np.shape(beta), np.shape(epsilon))
        return np.full(shape, 1.0 / np.pi)
    limit = np.pi / 2.0 - GRAZING_MARGIN
    alpha = np.minimum(np.asarray(alpha, float), limit)
    beta = np.minimum(np.asarray(beta, float), limit)
    integral = single_scattering_integral(alpha, beta, epsilon, psi, order)
    return integral / (np.pi**2 * np.sin(psi) ** 2 * np.cos(alpha) * np.cos(beta))
