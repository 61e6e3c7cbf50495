"""KvD series coefficients of any isotropic model, by quadrature (KvD eq 29).

The amplitude of mode I_nml is the inner product ``a_nml = integral f I_nml dOmega_i
dOmega_r`` over the product of two hemispheres (KvD eq 29).  With ``mu = cos(theta)`` the
solid angle is ``dOmega = dmu dphi`` and every product of two basis functions is a
polynomial in mu_i, mu_r times a trigonometric polynomial in the azimuth difference, so

* Gauss-Legendre nodes in mu on [0, 1] (``n_theta`` per hemisphere) and
* equally spaced azimuth differences on one turn (``n_phi``)

integrate the basis exactly for ``n_theta > order`` and ``n_phi > 2 order``: on this grid
the modes are orthonormal to rounding error and the projection is the discrete
least-squares fit.  How well it approximates the continuous integral depends only on the
smoothness of the BRDF being projected (kinks such as Oren-Nayar's max/min of the polar
angles give algebraic convergence in ``n_theta``).

The isotropic BRDF depends on the azimuths through phi_r - phi_i only, so the double
azimuth integral reduces to ``2 pi`` times one integral over the difference; the cosine
transform in the azimuth is done once for all modes.

References
----------
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998, eq 28-29.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from gonio.models._core import Model, get
from gonio.zernike import _check_order

from .basis import _mode_scale, isotropic_indices, radial_table
from .series import KvdCoefficients

__all__ = ["ProductQuadrature", "product_quadrature", "project", "relative_l2_error", "tabulate_on_grid", "series_on_grid"]

Brdf = Callable[..., np.ndarray]


@dataclass(frozen=True)
class ProductQuadrature:
    """Quadrature on (hemisphere x hemisphere) for isotropic functions.

    Attributes
    ----------
    cos_nodes, cos_weights : numpy.ndarray
        Gauss-Legendre nodes and weights for mu = cos(theta) on [0, 1].
    dphi_nodes : numpy.ndarray
        Equally spaced azimuth differences on [0, 2 pi) [rad].
    """

    cos_nodes: np.ndarray
    cos_weights: np.ndarray
    dphi_nodes: np.ndarray

    @property
    def dphi_weight(self) -> float:
        """Weight of one azimuth-difference node times the 2 pi of the second azimuth."""
        return 2.0 * math.pi * (2.0 * math.pi / self.dphi_nodes.size)

    def theta_degrees(self) -> np.ndarray:
        """Polar angles of the nodes [deg]."""
        return np.degrees(np.arccos(self.cos_nodes))


def product_quadrature(n_theta: int = 64, n_phi: int = 128) -> ProductQuadrature:
    """Quadrature rule for the projections (see the module notes).

    Parameters
    ----------
    n_theta : int
        Gauss-Legendre nodes in cos(theta) per hemisphere (>= 1).
    n_phi : int
        Azimuth-difference nodes on one turn (>= 1).

    Returns
    -------
    ProductQuadrature
    """
    if int(n_theta) < 1 or int(n_phi) < 1:
        raise ValueError(f"quadrature sizes n_theta = {n_theta}, n_phi = {n_phi} must be >= 1")
    x, w = np.polynomial.legendre.leggauss(int(n_theta))
    return ProductQuadrature(0.5 * (x + 1.0), 0.5 * w, 2.0 * math.pi * np.arange(int(n_phi)) / int(n_phi))


def _as_brdf(model: str | Model | Brdf, params: Mapping[str, Any] | None) -> tuple[Brdf, str]:
    params = dict(params or {})
    if isinstance(model, str):
        model = get(model)
    if isinstance(model, Model):
        if not model.isotropic:
            raise ValueError(f"model {model.name!r} is anisotropic; the KvD isotropic series needs an isotropic model")
        model.resolve(params)  # ValueError for bad parameters before any work
        bound = model
        return (lambda ti, pi_, tr, pr: bound(ti, pi_, tr, pr, **params)), model.name
    if not callable(model):
        raise ValueError(f"model must be a registered name, a Model or a callable, got {model!r}")
    if params:
        return (lambda ti, pi_, tr, pr: model(ti, pi_, tr, pr, **params)), getattr(model, "__name__", "callable")
    return model, getattr(model, "__name__", "callable")


def tabulate_on_grid(model: str | Model | Brdf, quadrature: ProductQuadrature, params: Mapping[str, Any] | None = None) -> np.ndarray:
    """BRDF values [1/sr] on the quadrature grid, shape (n_theta, n_theta, n_phi).

    Axis 0 is theta_i, axis 1 theta_r, axis 2 the azimuth difference (phi_i = 0,
    phi_r = dphi).
    """
    brdf, name = _as_brdf(model, params)
    theta = quadrature.theta_degrees()
    dphi = np.degrees(quadrature.dphi_nodes)
    values = np.asarray(brdf(theta[:, None, None], 0.0, theta[None, :, None], dphi[None, None, :]), dtype=float)
    values = np.broadcast_to(values, (theta.size, theta.size, dphi.size))
    if not np.all(np.isfinite(values)):
        raise ValueError(f"model {name!r} is not finite on the quadrature grid; it cannot be projected")
    return values


def project(
    model: str | Model | Brdf,
    order: int,
    params: Mapping[str, Any] | None = None,
    n_theta: int = 64,
    n_phi: int = 128,
) -> KvdCoefficients:
    """Coefficients a_nml of a model up to ``order`` by quadrature (KvD eq 29).

    Parameters
    ----------
    model : str, Model or callable
        A registered model name, a :class:`~gonio.models.Model`, or a function
        ``brdf(theta_i, phi_i, theta_r, phi_r) -> [1/sr]`` of angles in degrees.
    order : int
        Highest radial order n of the modes kept [-], ``>= 0``.
    params : mapping, optional
        Model parameters.
    n_theta, n_phi : int
        Quadrature sizes (see :func:`product_quadrature`); raised automatically to
        ``order + 1`` and ``2 order + 1`` so that the basis stays exactly orthonormal.

    Returns
    -------
    KvdCoefficients
        All modes with n <= order.

    Raises
    ------
    ValueError
        Negative order, bad parameters, an anisotropic model, or a model that is not
        finite on the grid (e.g. Minnaert on the horizon is fine: Gauss nodes avoid it).

    Notes
    -----
    A non-reciprocal model is projected onto its reciprocal part, since every I_nml is
    symmetric in source and viewer.  The Lambertian BRDF rho/pi gives a_000 = 2 rho and
    nothing else (KvD eq 26 with A_000 = 4).

    Examples
    --------
    >>> coefficients = project("lambert", 2, {"rho": 0.5})
    >>> round(coefficients[(0, 0, 0)], 12), round(float(abs(coefficients.values[1:]).max()), 12)
    (1.0, 0.0)
    """
    order = _check_order(order)
    quadrature = product_quadrature(max(int(n_theta), order + 1), max(int(n_phi), 2 * order + 1))
    values = tabulate_on_grid(model, quadrature, params)
    modes = isotropic_indices(order)
    # cosine transform in the azimuth difference: C_l(a, b) = sum_c f(a, b, c) cos(l dphi_c)
    ls = np.arange(order + 1)
    cosines = np.cos(np.outer(quadrature.dphi_nodes, ls))  # (n_phi, L)
    transform = np.tensordot(values, cosines, axes=([2], [0])) * quadrature.dphi_weight  # (a, b, L)
    radial = radial_table([(n, l) for n, _, l in modes] + [(m, l) for _, m, l in modes], quadrature.cos_nodes)
    w = quadrature.cos_weights
    amplitudes = np.empty(len(modes))
    for j, (n, m, l) in enumerate(modes):
        left_n, left_m = w * radial[(n, l)], w * radial[(m, l)]
        weighted = transform[:, :, l]
        both = left_n @ weighted @ left_m + left_m @ weighted @ left_n
        amplitudes[j] = _mode_scale(n, m, l) * both
    return KvdCoefficients(tuple(modes), amplitudes)


def relative_l2_error(
    model: str | Model | Brdf,
    coefficients: KvdCoefficients,
    params: Mapping[str, Any] | None = None,
    n_theta: int = 64,
    n_phi: int = 128,
    measure: str = "projected-solid-angle",
) -> float:
    """Relative L2 distance between a model and a series over both hemispheres [-].

    Parameters
    ----------
    model : str, Model or callable
        As in :func:`project`.
    coefficients : KvdCoefficients
        The series.
    params : mapping, optional
        Model parameters.
    n_theta, n_phi : int
        Quadrature sizes.
    measure : {"projected-solid-angle", "solid-angle"}
        ``"solid-angle"``: the measure dOmega_i dOmega_r of the KvD inner product (eq 29);
        ``"projected-solid-angle"``: cos(theta_i) cos(theta_r) dOmega_i dOmega_r, i.e. the
        error of the radiometric quantity f cos(theta_i) cos(theta_r).

    Returns
    -------
    float
        ``sqrt(integral (f - f_N)^2 dmu / integral f^2 dmu)`` by the quadrature of
        :func:`product_quadrature`; the series is evaluated directly on the grid (not
        through Parseval's identity).

    Notes
    -----
    Models with a tan(theta) factor, such as the Oren-Nayar approximation (its C2 term
    grows like 1/cos(theta) when both directions approach the horizon), are not square
    integrable under dOmega_i dOmega_r: the solid-angle norm diverges logarithmically and
    its quadrature value is dominated by the nodes nearest the horizon.  The
    projected-solid-angle measure weights the horizon by cos(theta) and stays finite for
    every gonio model; it is the default for that reason.
    """
    quadrature = product_quadrature(n_theta, n_phi)
    values = tabulate_on_grid(model, quadrature, params)
    if measure not in ("projected-solid-angle", "solid-angle"):
        raise ValueError(f"measure = {measure!r} is not 'projected-solid-angle' or 'solid-angle'")
    series = series_on_grid(coefficients, quadrature)
    per_node = quadrature.cos_weights
    if measure == "projected-solid-angle":
        per_node = per_node * quadrature.cos_nodes
    weights = np.broadcast_to((per_node[:, None] * per_node[None, :])[:, :, None], values.shape)
    difference = float(np.sum(weights * (values - series) ** 2))
    norm = float(np.sum(weights * values**2))
    return math.sqrt(difference / norm) if norm > 0 else math.sqrt(difference)


def series_on_grid(coefficients: KvdCoefficients, quadrature: ProductQuadrature) -> np.ndarray:
    """Series values [1/sr] on the quadrature grid, shape (n_theta, n_theta, n_phi).

    Separable form of :func:`~gonio.models.kvd.basis.design_matrix`: for each azimuthal
    order l the radial part is summed on the (theta_i, theta_r) grid first; the tests check
    it against the design matrix.
    """
    mu = quadrature.cos_nodes
    modes = coefficients.modes
    radial = radial_table([(n, l) for n, _, l in modes] + [(m, l) for _, m, l in modes], mu)
    by_l: dict[int, np.ndarray] = {}
    for (n, m, l), amplitude in zip(modes, coefficients.values):
        term = np.outer(radial[(n, l)], radial[(m, l)])
        term = term + term.T
        by_l[l] = by_l.get(l, 0.0) + amplitude * _mode_scale(n, m, l) * term
    out = np.zeros((mu.size, mu.size, quadrature.dphi_nodes.size))
    for l, radial_part in by_l.items():
        out += radial_part[:, :, None] * np.cos(l * quadrature.dphi_nodes)[None, None, :]
    return out
