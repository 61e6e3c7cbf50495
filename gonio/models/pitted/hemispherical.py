"""The hemispherical pit (psi = 90 deg): Koenderink et al. (1999), section 3, eq 14-31.

For the hemisphere the boundaries of the cast shadow and of the visible region are great
circles, so the BRDF reduces to one-dimensional integrals (eq 21-25) and, in the plane of
incidence, to elementary functions (eq 26-29).

Orientation used for eq 19-25 (decided here, because the paper's printed signs mix two
orientations): the macro-scale normal of a cavity point is parametrised about the axis b
(perpendicular to the plane of incidence) as ``m = (sin t cos p, -cos t, sin t sin p)``
with the source ``i = (sin alpha, 0, cos alpha)`` and the viewer
``e = (sin beta cos eps, sin beta sin eps, cos beta)``.  Then the cavity is 0 <= p <= pi,
``m.i = sin t sin(p + alpha)``, the lit part is ``0 <= p <= pi - 2 alpha`` and the visible
part is ``sin t A(p) - cos t sin(2 beta) sin(eps) >= 0`` with
``A(p) = sin(2 beta) cos(eps) cos(p) + cos(2 beta) sin(p)`` (eq 20's boundary).  The
integrals over t are the auxiliary functions f1..f4 of eq 22-25 evaluated at the visible
boundary.  With this orientation the 1-D integral reproduces the closed form of eq 26-29
to quadrature precision (tested), and the diffuse part integrates to exactly the D of
eq 29.

References
----------
J. J. Koenderink, A. J. van Doorn, K. J. Dana, S. K. Nayar, IJCV 31(2/3), 1999,
section 3, eq 14-31, Figs 4, 7 and 9.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .quadrature import GRAZING_MARGIN

__all__ = [
    "aux_f1",
    "aux_f2",
    "aux_f3",
    "aux_f4",
    "in_plane_brdf",
    "integral_brdf",
    "forward_scattering_brdf",
    "forward_scattering_series",
]


def aux_f1(t: ArrayLike) -> np.ndarray:
    """Eq 22: ``-sin^3(t)/3`` = integral of sin^2 cos from t to pi [rad in]."""
    return -np.sin(t) ** 3 / 3.0


def aux_f2(t: ArrayLike) -> np.ndarray:
    """Eq 23: ``2/3 + 3/4 cos t - 1/12 cos^3 t + 1/4 cos t sin^2 t`` = integral of sin^3 from t to pi."""
    c, s = np.cos(t), np.sin(t)
    return 2.0 / 3.0 + 0.75 * c - c**3 / 12.0 + 0.25 * c * s * s


def aux_f3(t: ArrayLike) -> np.ndarray:
    """Eq 24: ``-1/2 + 1/2 cos^2 t`` = integral of sin cos from t to pi."""
    return -0.5 + 0.5 * np.cos(t) ** 2


def aux_f4(t: ArrayLike) -> np.ndarray:
    """Eq 25: ``pi/2 - t/2 + 1/2 cos t sin t`` = integral of sin^2 from t to pi."""
    return np.pi / 2.0 - np.asarray(t) / 2.0 + 0.5 * np.cos(t) * np.sin(t)


def _visible_t_integral(f, lower_or_upper: np.ndarray, upper_branch: np.ndarray) -> np.ndarray:
    """Integral over the visible t-interval of the integrand whose tail integral is f.

    The visible interval is [d, pi] (f(d)) when ``upper_branch`` and [0, pi + d]
    (f(0) - f(pi + d)) otherwise.
    """
    return np.where(upper_branch, f(lower_or_upper), f(0.0) - f(np.pi + lower_or_upper))


def _deg_inputs(theta_i, theta_r, epsilon):
    limit = 90.0 - np.degrees(GRAZING_MARGIN)
    alpha = np.radians(np.minimum(np.asarray(theta_i, float), limit))
    beta = np.radians(np.minimum(np.asarray(theta_r, float), limit))
    return alpha, beta, np.radians(np.asarray(epsilon, float))


def in_plane_brdf(theta_i: ArrayLike, signed_view: ArrayLike, rho: float) -> np.ndarray:
    """BRDF of a surface fully covered by hemispherical pits, in the plane of incidence [1/sr].

    Parameters
    ----------
    theta_i : array_like
        Source co-elevation alpha [deg], 0 <= alpha <= 90.
    signed_view : array_like
        Signed viewing co-elevation beta [deg]: positive on the source side (backward
        scattering, epsilon = 0), negative on the far side (forward, epsilon = 180).
    rho : float
        Micro-scale albedo [-].

    Returns
    -------
    numpy.ndarray
        A + D (backward, |beta| < alpha), B + D (backward, |beta| >= alpha),
        C + D (forward, alpha + |beta| < 90 deg) or D (forward otherwise) [1/sr].

    Notes
    -----
    Eq 26-29 and the four cases that follow them.  A and B are the same expression with
    max(alpha, |beta|), which makes the result reciprocal.  Angles within
    ``GRAZING_MARGIN`` of 90 deg are evaluated at that margin (finite limit).

    Examples
    --------
    >>> round(float(in_plane_brdf(0.0, 0.0, 1.0)), 6)   # 2/(3 pi) + 1/(2 pi)
    0.371362
    """
    alpha, beta, _ = _deg_inputs(theta_i, np.abs(signed_view), 0.0)
    backward = np.asarray(signed_view, float) >= 0.0
    norm = 2.0 * rho / (3.0 * np.pi**2 * np.cos(alpha) * np.cos(beta))
    top = np.maximum(alpha, beta)
    a_or_b = norm * np.cos(alpha - beta) * (np.pi - 2.0 * top + np.sin(2.0 * top))  # eq 26-27
    c = norm * np.cos(alpha + beta) * (
        np.pi - 2.0 * alpha - 2.0 * beta + np.sin(2.0 * alpha) + np.sin(2.0 * beta)
    )  # eq 28
    c = np.where(alpha + beta < np.pi / 2.0, c, 0.0)
    d = rho**2 / (2.0 * np.pi * (2.0 - rho))  # eq 29
    return np.where(backward, a_or_b, c) + d


def integral_brdf(
    theta_i: ArrayLike, theta_r: ArrayLike, epsilon: ArrayLike, rho: float, order: int = 64
) -> tuple[np.ndarray, np.ndarray]:
    """Single- and multiple-scattering BRDF of the hemispherical pit by eq 21 [1/sr].

    Parameters
    ----------
    theta_i : array_like
        Source co-elevation alpha [deg].
    theta_r : array_like
        Viewer co-elevation beta [deg].
    epsilon : array_like
        Viewer azimuth from the plane of incidence [deg] (0: backward, 180: forward).
    rho : float
        Micro-scale albedo [-].
    order : int
        Gauss-Legendre nodes per panel in p (two panels, split where A(p) = 0).

    Returns
    -------
    single, multiple : numpy.ndarray
        The first and second terms of eq 21 [1/sr]; the BRDF is their sum.  The second
        term equals the D of eq 29 up to quadrature error (a check of the integration
        region).

    Notes
    -----
    Eq 21 with eq 22-25, in the orientation stated in the module docstring.  The p
    integral is split at the root of A(p), where the visible t-interval jumps from
    complete to empty in the plane of incidence.

    Examples
    --------
    >>> single, multiple = integral_brdf(30.0, 20.0, 0.0, rho=1.0)
    >>> round(float(single + multiple), 5) == round(float(in_plane_brdf(30.0, 20.0, 1.0)), 5)
    True
    """
    alpha, beta, eps = _deg_inputs(theta_i, theta_r, epsilon)
    alpha, beta, eps = (a.ravel() for a in np.broadcast_arrays(alpha, beta, eps))
    shape = np.broadcast_shapes(np.shape(theta_i), np.shape(theta_r), np.shape(epsilon))
    sb, cb, se, ce = np.sin(beta), np.cos(beta), np.sin(eps), np.cos(eps)
    s2b, c2b = np.sin(2.0 * beta), np.cos(2.0 * beta)
    root = np.remainder(np.arctan2(-s2b * ce, c2b), np.pi)  # A(root) = 0, in [0, pi)
    nodes, weights = np.polynomial.legendre.leggauss(int(order))

    def panels(lo, hi, split):
        split = np.clip(split, lo, hi)
        edges = np.stack([lo, split, hi], axis=-1)
        a, b = edges[:, :-1, None], edges[:, 1:, None]
        half = 0.5 * (b - a)
        return (a + half * (nodes + 1.0)).reshape(len(lo), -1), (half * weights).reshape(len(lo), -1)

    def t_integrals(p, f_pairs):
        big_a = s2b[:, None] * ce[:, None] * np.cos(p) + c2b[:, None] * np.sin(p)
        big_b = np.broadcast_to((s2b * se)[:, None], p.shape)
        delta = np.arctan2(big_b, big_a)  # visible: sin(t - delta) >= 0, t in [0, pi]
        in_plane = big_b == 0.0
        upper = np.where(in_plane, big_a > 0.0, big_b > 0.0)
        lower = np.where(in_plane, np.where(big_a > 0.0, 0.0, np.pi), delta)
        lower = np.where(~in_plane & ~upper, delta, lower)
        return [_visible_t_integral(f, lower, upper | in_plane) for f in f_pairs]

    zeros = np.zeros_like(alpha)
    # single scattering: lit and visible, p in [0, pi - 2 alpha]
    p, w = panels(zeros, np.pi - 2.0 * alpha, root)
    g1, g2 = t_integrals(p, (aux_f1, aux_f2))
    factor = sb[:, None] * ce[:, None] * np.cos(p) + cb[:, None] * np.sin(p)
    lit = np.sin(p + alpha[:, None]) * (factor * g2 - (sb * se)[:, None] * g1)
    single = rho / (np.pi**2 * np.cos(alpha) * cb) * np.sum(lit * w, axis=-1)
    # multiple scattering: visible, p in [0, pi]
    p, w = panels(zeros, zeros + np.pi, root)
    g3, g4 = t_integrals(p, (aux_f3, aux_f4))
    factor = sb[:, None] * ce[:, None] * np.cos(p) + cb[:, None] * np.sin(p)
    visible = factor * g4 - (sb * se)[:, None] * g3
    multiple = rho**2 / (2.0 * np.pi**2 * (2.0 - rho) * cb) * np.sum(visible * w, axis=-1)
    return single.reshape(shape), multiple.reshape(shape)


def forward_scattering_brdf(rho: ArrayLike) -> np.ndarray:
    """BRDF of the hemispherical pit where only its shadowed part is seen [1/sr].

    Parameters
    ----------
    rho : array_like
        Micro-scale albedo [-].

    Returns
    -------
    numpy.ndarray
        ``rho^2 / (2 pi (2 - rho))``: eq 30 (= D of eq 29); for rho = 1 half the
        Lambertian BRDF.

    Examples
    --------
    >>> round(float(forward_scattering_brdf(1.0)) * 3.141592653589793, 12)
    0.5
    """
    rho = np.asarray(rho, float)
    return rho**2 / (2.0 * np.pi * (2.0 - rho))


def forward_scattering_series(rho: ArrayLike, orders: int = 6) -> np.ndarray:
    """Eq 31: ``(1/4pi) sum_k rho^(k+2) / 2^k`` truncated after ``orders`` terms [1/sr].

    Examples
    --------
    >>> bool(abs(forward_scattering_series(0.5, 60) - forward_scattering_brdf(0.5)) < 1e-15)
    True
    """
    if int(orders) < 1:
        raise ValueError(f"orders = {orders!r} must be a positive integer (number of series terms)")
    rho = np.asarray(rho, float)
    k = np.arange(int(orders)).reshape((-1,) + (1,) * rho.ndim)
    return (rho ** (k + 2) / 2.0**k).sum(axis=0) / (4.0 * np.pi)
