"""The scattering orders of a rendered surface that the papers give exactly.

A rendered table needs the all-bounce BRDF of a surface at its nodes.  Where a paper
gives the first scattering orders of *this very surface* exactly, they need not be
sampled: a node is the exact sum of those orders plus the Monte Carlo estimate of the
rest, from the same paths the renderer traces (it keeps the orders apart,
:class:`~.estimator.Rendering`).  That is an analytic partial sum, a control variate with
coefficient 1: the expectation is still the all-bounce BRDF of the surface, and the
variance is that of the remaining orders alone.

``vgrooves`` (:class:`~.shapes.VGrooveField`)
    Orders 1 and 2 are ``oren-nayar-exact``: rho f1 + rho^2 f2 of
    :func:`~gonio.models.oren_nayar.exact.exact_components` (Oren & Nayar 1995, eq 8,
    15, 22-24 with the slope-area distribution eq 32), the same groove population, slope
    distribution and truncation as the renderer (tested against renders:
    tests/surfaces/test_surfaces_render.py).
``vgroove`` without ``phi_a`` (isotropic single slope)
    Orders 1 and 2 are the exact azimuthal average of the facet terms, eq 29 and 46:
    rho h1 + rho^2 h2 of :func:`~gonio.models.oren_nayar.single_slope.isotropic_brdf_terms`.
``pits`` (:class:`~.shapes.PittedPlane`)
    Every order: single scattering rho F1 (Koenderink et al. 1999, eq 14-15, closed
    form) and the interreflection of eq 12, uniform over the sphere (eq 11), whose
    series eq 13 also gives every truncation; with the flat part (1 - coverage) rho/pi.
    The renders agree with it within their errors at every bounce limit (tested), so
    the pitted plane's table *is* the paper's exact result, validated by rendering.
``heightfield``
    Nothing is known exactly: every order is sampled.

The aligned groove (``vgroove`` with ``phi_a``) is not tabulated and has no entry here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .shapes import PittedPlane, Surface, VGroove, VGrooveField

__all__ = ["KnownOrders", "known_orders", "every_order_known", "EXACT_RTOL", "AZIMUTH_ORDER",
           "INTERREFLECTION_ORDER"]

#: Accuracy target of ``oren-nayar-exact`` for the groove field (measured worst relative
#: error below 3.1e-7 at this setting: gonio/models/oren_nayar/exact.py).
EXACT_RTOL = 1e-6
#: Gauss-Legendre nodes per azimuth panel of the single-slope terms, direct light and
#: interreflection (the direct term converges exponentially, ~1e-11 at 6 nodes; the
#: interreflection to ~1e-8 on graded panels: single_slope.isotropic_brdf_terms).
AZIMUTH_ORDER = 12
INTERREFLECTION_ORDER = 16


@dataclass(frozen=True)
class KnownOrders:
    """The exactly known part of a surface's BRDF.

    Attributes
    ----------
    value : numpy.ndarray
        BRDF of the first ``orders`` scattering events [1/sr] (broadcast shape of the
        angles).
    orders : int or None
        How many leading scattering orders ``value`` holds; None: every order the bounce
        limit keeps (nothing is left to sample).
    """

    value: np.ndarray
    orders: int | None


def _has_exact_two_bounces(surface: Surface) -> bool:
    return isinstance(surface, VGrooveField) or (isinstance(surface, VGroove) and surface.phi_a is None)


def every_order_known(surface: Surface, bounces: int | None = None) -> bool:
    """Whether :func:`known_orders` holds every order the bounce limit keeps (nothing to
    sample): the pits at any limit, the V-grooves at one or two bounces.

    Examples
    --------
    >>> every_order_known(PittedPlane(60.0, 1.0, 0.9)), every_order_known(VGrooveField(30.0, 0.9), bounces=2)
    (True, True)
    >>> every_order_known(VGrooveField(30.0, 0.9))     # the third and later bounces are sampled
    False
    """
    if isinstance(surface, PittedPlane):
        return True
    return _has_exact_two_bounces(surface) and bounces is not None and bounces <= 2


def known_orders(surface: Surface, theta_i: ArrayLike, phi_i: ArrayLike, theta_r: ArrayLike, phi_r: ArrayLike,
                 bounces: int | None = None) -> KnownOrders | None:
    """The leading scattering orders of ``surface`` that a paper gives exactly [1/sr].

    Parameters
    ----------
    surface : Surface
        The surface (module notes: which kinds have known orders).
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [deg], polar angles in [0, 90).
    bounces : int or None
        The bounce limit of the rendering (None: all); orders beyond it are not included.

    Returns
    -------
    KnownOrders or None
        None when nothing is known exactly (the height field, the aligned groove).

    Notes
    -----
    Polar angles above :data:`~.estimator.THETA_LIMIT` are taken at it, as the renderer
    does.  The ``vgrooves`` and ``vgroove`` parts are computed by quadrature (relative
    accuracy about 1e-7 and 1e-8, module constants), the pits' in closed form.

    Examples
    --------
    >>> part = known_orders(VGrooveField(sigma=0.0, rho=0.5), 30.0, 0.0, 60.0, 180.0)
    >>> round(float(part.value) * math.pi, 12), part.orders   # a plane: Lambert, one order
    (0.5, 2)
    """
    from .estimator import THETA_LIMIT

    arrays = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))
    ti, pi_, tr, pr = arrays
    ti, tr = np.minimum(ti, THETA_LIMIT), np.minimum(tr, THETA_LIMIT)
    if isinstance(surface, PittedPlane):
        return KnownOrders(_pits(surface, ti, pi_, tr, pr, bounces), None)
    if not _has_exact_two_bounces(surface):
        return None
    orders = 2 if bounces is None else min(int(bounces), 2)
    held = None if every_order_known(surface, bounces) else 2  # None: nothing left to sample
    if isinstance(surface, VGrooveField):
        from ..models.oren_nayar.exact import exact_components

        f1, f2 = exact_components(ti, pi_, tr, pr, surface.sigma, rtol=EXACT_RTOL)
    else:
        f1, f2 = _single_slope(surface.theta_a, ti, tr, pr - pi_)
    rho = surface.rho
    return KnownOrders(rho * f1 + (rho * rho * f2 if orders == 2 else 0.0), held)


def _single_slope(theta_a: float, ti: np.ndarray, tr: np.ndarray, delta_phi: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """h1, h2 of eq 29/46 [1/sr] at angles [deg]."""
    from ..models.oren_nayar.single_slope import isotropic_brdf_terms

    a, i, r = math.radians(theta_a), np.radians(ti), np.radians(tr)
    h1, h2 = isotropic_brdf_terms(np.cos(i), np.sin(i), np.cos(r), np.sin(r), np.radians(delta_phi), math.cos(a),
                                  math.sin(a), order=AZIMUTH_ORDER, interreflection_order=INTERREFLECTION_ORDER)
    return h1.reshape(ti.shape), h2.reshape(ti.shape)


def _pits(surface: PittedPlane, ti: np.ndarray, pi_: np.ndarray, tr: np.ndarray, pr: np.ndarray,
          bounces: int | None) -> np.ndarray:
    """(1 - c) rho/pi + c (rho F1 + interreflection through ``bounces`` events) [1/sr]."""
    from ..models.pitted.interreflection import diffuse_radiance, diffuse_radiance_series
    from ..models.pitted.model import pitted_terms

    rho, psi = surface.rho, surface.psi
    single = rho * pitted_terms(ti, pi_, tr, pr, psi).single_scattering
    if bounces is None:
        interreflection = diffuse_radiance(rho, psi)
    elif bounces >= 2:
        interreflection = diffuse_radiance_series(rho, psi, orders=int(bounces) - 1)
    else:
        interreflection = 0.0
    return (1.0 - surface.coverage) * rho / math.pi + surface.coverage * (single + interreflection)
