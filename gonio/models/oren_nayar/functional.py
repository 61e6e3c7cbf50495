"""Closed-form Oren-Nayar models: the functional approximation and the qualitative model.

The formulas of two models, which :mod:`gonio.models.oren_nayar.registered` registers
(with their compiled plain calls, :mod:`gonio.models.oren_nayar.compiled`, which takes its
constants and coefficients from here):

``oren-nayar``
    The functional approximation of the Gaussian-slope V-cavity model with two-bounce
    interreflection (Oren & Nayar 1995, eq 33-35), with the optional interreflection
    weight the paper mentions after eq 35 (parameter ``ir_weight``).
``oren-nayar-qualitative``
    The simplified model of eq 36 (coefficients A and B, no C3 term, no
    interreflection), with the variant of footnote 11 (0.57 in place of 0.33 in A) as the
    option ``variant="footnote11"``.

The coefficient functions :func:`c1`, :func:`c2`, :func:`c3`, :func:`qualitative_a`,
:func:`qualitative_b` and the geometry-maximum bounds :func:`c2_bound`, :func:`c3_bound`
(the quantities compared in Wolff, Nayar & Oren 1998, section 4 and Fig. 16) are public.
All take the roughness ``sigma`` and angles in degrees; the formulas use radians inside.

Notation: alpha = max(theta_i, theta_r), beta = min(theta_i, theta_r), and the azimuth
difference dphi = phi_r - phi_i.  Each formula is written once (in the private
``_*_rad`` helpers and the named constants below) and used by both the public
coefficient functions and the registered models.

References
----------
M. Oren, S. K. Nayar, "Generalization of the Lambertian model and implications for machine
vision", IJCV 14(3), 1995, section 4.3 (eq 33-35, footnotes 9-10) and section 4.4
(eq 36, footnote 11).
L. B. Wolff, S. K. Nayar, M. Oren, "Improved diffuse reflection models for computer
vision", IJCV 30(1), 1998, eq 3-6 (the same formulas) and section 4 (C1 versus the C2/C3
bounds, Fig. 16).
"""
from __future__ import annotations

import math
from math import cos, sin, tan
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike

from .._core import LinearForm, Option, Param, outside, with_linear_form
from .._trig import cos_from_half_tangent, sin_from_half_tangent

__all__ = [
    "c1",
    "c2",
    "c3",
    "c2_bound",
    "c3_bound",
    "qualitative_a",
    "qualitative_b",
    "interreflection_coefficient",
    "oren_nayar_brdf",
    "oren_nayar_qualitative_brdf",
    "RHO",
    "SIGMA",
    "IR_WEIGHT",
    "VARIANT",
]

# ---------------------------------------------------------------- constants of eq 33-36
#: sigma^2 [rad^2] at which C1 (and A of eq 36) has lost half of its total drop of 0.5.
C1_SATURATION = 0.33
#: Footnote 11: the value replacing 0.33 in A to compensate for the missing interreflection.
C1_SATURATION_FOOTNOTE11 = 0.57
#: sigma^2 [rad^2] of half saturation of C2, C3 (and B of eq 36).
C23_SATURATION = 0.09
#: Amplitude of C2 (and B of eq 36).
C2_AMPLITUDE = 0.45
#: Amplitude of C3.
C3_AMPLITUDE = 0.125
#: Amplitude and half-saturation sigma^2 [rad^2] of the interreflection term, eq 34.
IR_AMPLITUDE = 0.17
IR_SATURATION = 0.13

_TWO_OVER_PI = 2.0 / math.pi
_FOUR_OVER_PI_SQ = 4.0 / math.pi**2

SIGMA = Param(
    "sigma", "deg", 20.0, (0.0, 90.0),
    "Oren-Nayar roughness: standard deviation of the facet slope angle",
)
RHO = Param("rho", "-", 0.8, (0.0, 1.0), "albedo of the Lambertian facets")
IR_WEIGHT = Param(
    "ir_weight", "-", 1.0, (0.0, 1.0),
    "weight of the two-bounce interreflection term (1 = the model of eq 33-35)",
)
VARIANT = Option(
    "variant", "eq36", ("eq36", "footnote11"),
    "constant in A: 0.33 as in eq 36, or 0.57 of footnote 11 (compensates the missing interreflection)",
)


# ---------------------------------------------------------------- formulas, in radians
def _saturation(sigma_sq: float | np.ndarray, half: float):
    """sigma^2 / (sigma^2 + half): the roughness dependence shared by every coefficient."""
    return sigma_sq / (sigma_sq + half)


def _c1_rad(sigma_sq, half: float = C1_SATURATION):
    """C1 of eq 33 (and A of eq 36 with ``half`` = 0.33 or 0.57), sigma^2 in rad^2."""
    return 1.0 - 0.5 * _saturation(sigma_sq, half)


def _c2_angular(alpha, beta, cos_dphi):
    """The angular factor of C2 (eq 33): sin(alpha), minus (2 beta/pi)^3 when cos(dphi) < 0."""
    return np.sin(alpha) - np.where(cos_dphi < 0.0, (_TWO_OVER_PI * beta) ** 3, 0.0)


def _c3_angular(alpha, beta):
    """The angular factor of C3 (eq 33): (4 alpha beta / pi^2)^2."""
    return (_FOUR_OVER_PI_SQ * alpha * beta) ** 2


def _ir_amplitude_rad(rho: float, sigma_sq: float) -> float:
    """The interreflection prefactor of eq 34 without the 1/pi: 0.17 rho^2 sigma^2/(sigma^2+0.13)."""
    return IR_AMPLITUDE * rho * rho * _saturation(sigma_sq, IR_SATURATION)


def _sigma_sq(sigma_deg: ArrayLike):
    return np.radians(np.asarray(sigma_deg, dtype=float)) ** 2


def _alpha_beta_cos(theta_i, theta_r, delta_phi):
    ti, tr = np.radians(np.asarray(theta_i, float)), np.radians(np.asarray(theta_r, float))
    return np.maximum(ti, tr), np.minimum(ti, tr), np.cos(np.radians(np.asarray(delta_phi, float)))


# ---------------------------------------------------------------- public coefficients
def c1(sigma: ArrayLike) -> np.ndarray:
    """Coefficient C1 of the Oren-Nayar functional approximation [-].

    Parameters
    ----------
    sigma : array_like
        Roughness: standard deviation of the facet slope angle [deg].

    Returns
    -------
    numpy.ndarray
        C1 = 1 - 0.5 sigma^2 / (sigma^2 + 0.33), sigma in radians; 1 at sigma = 0,
        decreasing towards 0.5 for very rough surfaces.

    Notes
    -----
    Oren & Nayar (1995) eq 33; Wolff, Nayar & Oren (1998) eq 3.  The coefficient A of the
    qualitative model (eq 36) is the same expression (:func:`qualitative_a`).

    References
    ----------
    M. Oren, S. K. Nayar, IJCV 14(3), 1995, eq 33.

    Examples
    --------
    >>> float(c1(0.0))
    1.0
    >>> round(float(c1(30.0)), 4)
    0.7731
    """
    return _c1_rad(_sigma_sq(sigma))


def c2(sigma: ArrayLike, theta_i: ArrayLike, theta_r: ArrayLike, delta_phi: ArrayLike) -> np.ndarray:
    """Coefficient C2 of the Oren-Nayar functional approximation [-].

    Parameters
    ----------
    sigma : array_like
        Roughness [deg].
    theta_i, theta_r : array_like
        Source and viewing polar angles [deg]; alpha and beta are their maximum and
        minimum (the coefficient is symmetric in the two).
    delta_phi : array_like
        Azimuth difference phi_r - phi_i [deg].

    Returns
    -------
    numpy.ndarray
        C2 = 0.45 sigma^2/(sigma^2 + 0.09) sin(alpha) when cos(delta_phi) >= 0, and
        0.45 sigma^2/(sigma^2 + 0.09) (sin(alpha) - (2 beta/pi)^3) otherwise (angles in
        radians).

    Notes
    -----
    Oren & Nayar (1995) eq 33.  C2 lies in [0, 0.45 sigma^2/(sigma^2 + 0.09)]: since
    beta <= alpha <= pi/2, sin(alpha) >= 2 alpha/pi >= (2 beta/pi)^3.  Its maximum over
    geometry is :func:`c2_bound`.

    Examples
    --------
    >>> round(float(c2(30.0, 60.0, 20.0, 0.0)), 4)
    0.2934
    """
    alpha, beta, cos_dphi = _alpha_beta_cos(theta_i, theta_r, delta_phi)
    k = _saturation(_sigma_sq(sigma), C23_SATURATION)
    return C2_AMPLITUDE * k * _c2_angular(alpha, beta, cos_dphi)


def c3(sigma: ArrayLike, theta_i: ArrayLike, theta_r: ArrayLike) -> np.ndarray:
    """Coefficient C3 of the Oren-Nayar functional approximation [-].

    Parameters
    ----------
    sigma : array_like
        Roughness [deg].
    theta_i, theta_r : array_like
        Source and viewing polar angles [deg] (alpha, beta = their max, min).

    Returns
    -------
    numpy.ndarray
        C3 = 0.125 sigma^2/(sigma^2 + 0.09) (4 alpha beta / pi^2)^2 (radians).

    Notes
    -----
    Oren & Nayar (1995) eq 33.  Its maximum over geometry (alpha = beta = 90 deg) is
    :func:`c3_bound`.

    Examples
    --------
    >>> round(float(c3(30.0, 60.0, 20.0)), 5)
    0.00207
    """
    alpha, beta, _ = _alpha_beta_cos(theta_i, theta_r, 0.0)
    k = _saturation(_sigma_sq(sigma), C23_SATURATION)
    return C3_AMPLITUDE * k * _c3_angular(alpha, beta)


def c2_bound(sigma: ArrayLike) -> np.ndarray:
    """Maximum of C2 over all geometries [-]: 0.45 sigma^2 / (sigma^2 + 0.09).

    Parameters
    ----------
    sigma : array_like
        Roughness [deg].

    Returns
    -------
    numpy.ndarray
        The upper bound of C2 plotted in Wolff, Nayar & Oren (1998) Fig. 16, reached at
        alpha = 90 deg with cos(dphi) >= 0 (sin(alpha) = 1).

    Notes
    -----
    Wolff, Nayar & Oren (1998) section 4 compare C1 with "the upper bound" of C2 and C3;
    the tangent factors of eq 3 are not part of it (they are unbounded as beta -> 90 deg).
    The bound equals B of the qualitative model (:func:`qualitative_b`).

    Examples
    --------
    >>> round(float(c1(2.5) / c2_bound(2.5)), 1)
    107.0
    """
    return C2_AMPLITUDE * _saturation(_sigma_sq(sigma), C23_SATURATION)


def c3_bound(sigma: ArrayLike) -> np.ndarray:
    """Maximum of C3 over all geometries [-]: 0.125 sigma^2 / (sigma^2 + 0.09).

    Parameters
    ----------
    sigma : array_like
        Roughness [deg].

    Returns
    -------
    numpy.ndarray
        C3 at alpha = beta = 90 deg, where (4 alpha beta / pi^2)^2 = 1.  Always
        0.125/0.45 = 0.28 times :func:`c2_bound`.

    Notes
    -----
    Wolff, Nayar & Oren (1998) section 4 and Fig. 16.

    Examples
    --------
    >>> float(c3_bound(0.0))
    0.0
    """
    return C3_AMPLITUDE * _saturation(_sigma_sq(sigma), C23_SATURATION)


def qualitative_a(sigma: ArrayLike, variant: str = "eq36") -> np.ndarray:
    """Coefficient A of the qualitative Oren-Nayar model [-].

    Parameters
    ----------
    sigma : array_like
        Roughness [deg].
    variant : {"eq36", "footnote11"}
        ``"eq36"``: A = 1 - 0.5 sigma^2/(sigma^2 + 0.33) (equal to C1);
        ``"footnote11"``: 0.57 replaces 0.33, which raises A to compensate partly for the
        interreflection the qualitative model leaves out.

    Returns
    -------
    numpy.ndarray
        A [-].

    Notes
    -----
    Oren & Nayar (1995) eq 36 and footnote 11.

    Examples
    --------
    >>> round(float(qualitative_a(30.0, "footnote11")), 4)
    0.8376
    """
    halves = {"eq36": C1_SATURATION, "footnote11": C1_SATURATION_FOOTNOTE11}
    if variant not in halves:
        raise ValueError(f"variant = {variant!r} is not one of {list(halves)}")
    return _c1_rad(_sigma_sq(sigma), halves[variant])


def qualitative_b(sigma: ArrayLike) -> np.ndarray:
    """Coefficient B of the qualitative Oren-Nayar model [-]: 0.45 sigma^2/(sigma^2 + 0.09).

    Oren & Nayar (1995) eq 36 (the amplitude of C2 in eq 33).  ``sigma`` in [deg].

    Examples
    --------
    >>> round(float(qualitative_b(30.0)), 4)
    0.3388
    """
    return c2_bound(sigma)


def interreflection_coefficient(sigma: ArrayLike, rho: ArrayLike) -> np.ndarray:
    """Amplitude of the two-bounce interreflection BRDF term, times pi [-].

    Parameters
    ----------
    sigma : array_like
        Roughness [deg].
    rho : array_like
        Facet albedo [-].

    Returns
    -------
    numpy.ndarray
        0.17 rho^2 sigma^2 / (sigma^2 + 0.13): the interreflection BRDF of eq 34 is this
        over pi times [1 - cos(dphi) (2 beta / pi)^2].

    Examples
    --------
    >>> float(interreflection_coefficient(0.0, 0.9))
    0.0
    """
    return _ir_amplitude_rad(np.asarray(rho, float), _sigma_sq(sigma))


# ---------------------------------------------------------------- the models
_DEGREE = math.pi / 180.0
_RIGHT_ANGLE = 90.0


def _radians_sq(sigma):
    """sigma^2 [rad^2] of sigma [deg] (float or array): the multiplication of
    :func:`gonio.models._core._radians`, no numpy call for a float."""
    sigma_rad = sigma * _DEGREE
    return sigma_rad * sigma_rad


def _oren_nayar_coefficients(rho, sigma, ir_weight) -> tuple:
    """The scalars a, b, c of  a + b direct_shape + c ir_shape  (eq 33-34; see below).

    Floats give floats (plain Python arithmetic, no numpy call: the small plain call,
    :func:`_oren_nayar_point`, computes them per call); arrays broadcast.
    """
    sigma_sq = _radians_sq(sigma)
    diffuse = rho / math.pi
    interreflection = ir_weight * _ir_amplitude_rad(rho, sigma_sq) / math.pi
    return (diffuse * _c1_rad(sigma_sq) + interreflection,
            diffuse * _saturation(sigma_sq, C23_SATURATION),
            -interreflection)


#: sigma^2 [rad^2] of the roughest surface in range (sigma = 90 deg).
_ROUGHEST_SQ = (math.pi / 2.0) ** 2
#: Where direct_shape >= -this, eq 33-35 is >= 0 for every rho, sigma, ir_weight in range,
#: so the floor at 0 cannot act: a + c ir_shape >= rho/pi C1 (ir_shape <= 1, c <= 0) and
#: C1 + sat(sigma) direct_shape is smallest at sigma = 90 deg (C1 falls and sat rises
#: with sigma), where it is 0 at direct_shape = -C1/sat = -0.579.
_FLOOR_FREE_SHAPE = _c1_rad(_ROUGHEST_SQ) / _saturation(_ROUGHEST_SQ, C23_SATURATION)


#: Rows of the scratch array of :func:`_oren_nayar_shapes`.
SCRATCH_ROWS = 5


def _oren_nayar_shapes(theta_i, phi_i, theta_r, phi_r, out=None, scratch=None, mask=None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """direct_shape and ir_shape of eq 33-34 (see :func:`_prepare_oren_nayar`), angles [rad].

    Every operation writes into ``out`` or ``scratch`` (the plain call's cost is the
    number of passes over the arrays, and a call on preallocated arrays allocates
    nothing: :func:`_oren_nayar_fill`): the same formulas as :func:`c2`, :func:`c3` and
    :func:`interreflection_coefficient` (tests/models/test_oren_nayar_functional.py), with
    cos(dphi) and sin(alpha) from half-angle tangents (:mod:`gonio.models._trig`), in the
    order of :func:`gonio.models.oren_nayar.compiled.eq33_35`.

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad], above the horizon (broadcast together).
    out : tuple of numpy.ndarray, optional
        Two float arrays of the broadcast shape receiving direct_shape and ir_shape [-];
        when None, they and the temporaries are allocated here.
    scratch : numpy.ndarray, optional
        Float array of shape ``(SCRATCH_ROWS,) + shape`` for the temporaries (with ``out``).
    mask : numpy.ndarray, optional
        Boolean array of the broadcast shape, a temporary (with ``out``).

    Returns
    -------
    direct_shape, ir_shape : numpy.ndarray
        The two geometry terms [-] (``out`` when given).
    """
    if out is None:
        shape = np.broadcast(theta_i, phi_i, theta_r, phi_r).shape
        out, scratch, mask = (np.empty(shape), np.empty(shape)), np.empty((SCRATCH_ROWS,) + shape), np.empty(shape, bool)
    direct, ir = out
    # the rows of the scratch block (as 0-d arrays, not numpy scalars, for scalar angles)
    cos_dphi, alpha, beta, b, angular_c2 = scratch if scratch.ndim > 1 else [row[...] for row in scratch]
    _half_tangent_cos(np.subtract(phi_r, phi_i, out=cos_dphi), b)
    np.maximum(theta_i, theta_r, out=alpha)
    np.minimum(theta_i, theta_r, out=beta)
    np.multiply(beta, _TWO_OVER_PI, out=b)          # 2 beta / pi
    np.multiply(b, b, out=ir)                       # (2 beta / pi)^2
    _half_tangent_sin(np.multiply(alpha, 0.5, out=angular_c2), direct)
    np.multiply(ir, b, out=b)                       # sin(alpha) - (2 beta/pi)^3 [cos dphi < 0]
    b *= np.less(cos_dphi, 0.0, out=mask)          # (a masked subtraction, where=, is 4 times slower)
    angular_c2 -= b
    ir *= cos_dphi
    np.tan(beta, out=direct)
    direct *= cos_dphi
    direct *= angular_c2
    direct *= C2_AMPLITUDE
    c3 = np.multiply(alpha, beta, out=b)            # C3' = (4 alpha beta / pi^2)^2
    c3 *= _FOUR_OVER_PI_SQ
    c3 *= c3
    np.abs(cos_dphi, out=cos_dphi)
    c3 *= np.subtract(1.0, cos_dphi, out=cos_dphi)
    half = np.add(alpha, beta, out=alpha)
    half *= 0.5
    c3 *= np.tan(half, out=half)
    c3 *= C3_AMPLITUDE
    direct += c3
    return direct, ir


def _half_tangent_cos(x: np.ndarray, work: np.ndarray) -> np.ndarray:
    """cos(x) in place of x [rad] through tan(x/2) (:func:`gonio.models._trig.cos_from_half_tangent`,
    the same operations); ``work`` is a temporary of x's shape."""
    x *= 0.5
    t = np.tan(x, out=x)
    t *= t
    np.subtract(1.0, t, out=work)
    t += 1.0
    return np.divide(work, t, out=t)


def _half_tangent_sin(half: np.ndarray, work: np.ndarray) -> np.ndarray:
    """sin(2 half) in place of ``half`` [rad] through tan(half)
    (:func:`gonio.models._trig.sin_from_half_tangent`, the same operations); ``work`` is a
    temporary of its shape."""
    t = np.tan(half, out=half)
    np.multiply(t, t, out=work)
    work += 1.0
    t *= 2.0
    return np.divide(t, work, out=t)


def _prepare_oren_nayar(theta_i, phi_i, theta_r, phi_r):
    """Geometry-only terms of eq 33-34 (angles [rad]); returns f(rho, sigma, ir_weight).

    The BRDF is written as  a + b * direct_shape + c * ir_shape  with scalars a, b, c that
    depend on the parameters only (:func:`_oren_nayar_coefficients`):

    * direct_shape = 0.45 cos(dphi) C2'(alpha, beta) tan(beta)
      + 0.125 (1 - |cos dphi|) C3'(alpha, beta) tan((alpha + beta)/2)
      (C2', C3' the angular factors of C2 and C3; the common sigma factor goes into b);
    * ir_shape = cos(dphi) (2 beta / pi)^2;
    * a = rho/pi C1 + w A_ir / pi,  b = rho/pi sigma^2/(sigma^2 + 0.09),  c = -w A_ir / pi.

    The result is floored at 0 (see :func:`oren_nayar_brdf`, Notes).  The function carries
    this form as its ``linear_form`` (:class:`gonio.models.LinearForm`), exact wherever
    the floor cannot act (direct_shape >= -0.579 for every parameter in range).
    """
    direct_shape, ir_shape = _oren_nayar_shapes(theta_i, phi_i, theta_r, phi_r)

    def evaluate(rho: float, sigma: float, ir_weight: float) -> np.ndarray:
        a, b, c = _oren_nayar_coefficients(rho, sigma, ir_weight)
        # (parameters may be arrays broadcasting with the geometry: the first line makes
        # the full shape, the in-place addition then only adds the parameter term)
        out = direct_shape * b + c * ir_shape
        out += a
        return np.maximum(out, 0.0)  # eq 33 dips below 0 near forward grazing (see notes)

    return with_linear_form(evaluate, lambda: LinearForm(
        np.stack(np.broadcast_arrays(np.ones_like(direct_shape), direct_shape, ir_shape)),
        _oren_nayar_coefficients, exact=direct_shape >= -_FLOOR_FREE_SHAPE))


def _oren_nayar_point(params: dict, options: dict) -> Callable[[float, float, float, float], float]:
    """The small plain call of ``oren-nayar`` (:attr:`gonio.models.Model.point`).

    Parameters
    ----------
    params : dict
        Checked float values of rho [-], sigma [deg] and ir_weight [-].
    options : dict
        None for this model.

    Returns
    -------
    callable
        ``value(theta_i, phi_i, theta_r, phi_r)``: the BRDF [1/sr] of one geometry given
        as floats [deg], in plain Python (:mod:`math`); below the horizon, at NaN and at
        negative polar angles that of :func:`gonio.models._core.outside`, NaN at a NaN
        azimuth (``ValueError`` at an infinite one).

    Notes
    -----
    The operations of :func:`_oren_nayar_shapes` and :func:`_combine_into` on one
    geometry, in the same order (the scalar form of
    :func:`gonio.models.oren_nayar.compiled.eq33_35`, written out: a call per geometry
    would cost a quarter of the arithmetic), except that cos(dphi) and sin(alpha) come
    from the C library's ``cos`` and ``sin`` (cheaper in plain Python than the half-angle
    tangents that numpy's vectorised ``tan`` makes cheaper there): the values agree to a
    few ulp (tests/test_models_fast_paths.py).
    """
    a, b, c = _oren_nayar_coefficients(params["rho"], params["sigma"], params["ir_weight"])

    def value(theta_i: float, phi_i: float, theta_r: float, phi_r: float) -> float:
        if not (0.0 <= theta_i <= _RIGHT_ANGLE and 0.0 <= theta_r <= _RIGHT_ANGLE):  # NaN too
            return outside(theta_i, phi_i, theta_r, phi_r)
        if theta_i > theta_r:
            alpha, beta = theta_i * _DEGREE, theta_r * _DEGREE
        else:
            alpha, beta = theta_r * _DEGREE, theta_i * _DEGREE
        cos_dphi = cos(phi_r * _DEGREE - phi_i * _DEGREE)
        two_beta = beta * _TWO_OVER_PI
        ir_shape = two_beta * two_beta
        if cos_dphi < 0.0:
            angular_c2 = sin(alpha) - ir_shape * two_beta
            c3 = 1.0 + cos_dphi                   # 1 - |cos dphi|
        else:
            angular_c2 = sin(alpha)
            c3 = 1.0 - cos_dphi
        direct_shape = tan(beta) * cos_dphi * angular_c2 * C2_AMPLITUDE
        t = alpha * beta * _FOUR_OVER_PI_SQ
        c3 *= t * t
        c3 *= tan((alpha + beta) * 0.5)
        direct_shape += c3 * C3_AMPLITUDE
        t = direct_shape * b + c * (ir_shape * cos_dphi)
        t += a
        return t if not t < 0.0 else 0.0      # max(t, 0) of numpy: NaN stays NaN

    return value


def _combine_into(direct: np.ndarray, ir: np.ndarray, a, b, c) -> np.ndarray:
    """max(a + b direct + c ir, 0) [1/sr] in place of ``direct`` (``ir`` is overwritten)
    for scalar coefficients; the operations of ``evaluate`` in :func:`_prepare_oren_nayar`."""
    direct *= b
    ir *= c
    direct += ir
    direct += a
    return np.maximum(direct, 0.0, out=direct)


def _oren_nayar_fill(params: dict, options: dict, size: int) -> Callable[..., np.ndarray]:
    """The large plain call of ``oren-nayar`` (:attr:`gonio.models.Model.fill`).

    Parameters
    ----------
    params : dict
        Checked float values of rho [-], sigma [deg] and ir_weight [-].
    options : dict
        None for this model.
    size : int
        Largest number of geometries of one call of the returned function.

    Returns
    -------
    callable
        ``fill(theta_i, phi_i, theta_r, phi_r, out)``: writes the BRDF [1/sr] of 1-D
        angles [rad] (at most ``size``, above the horizon, not NaN) into ``out`` and
        returns it, allocating nothing (its temporaries are allocated here once).
    """
    a, b, c = _oren_nayar_coefficients(params["rho"], params["sigma"], params["ir_weight"])
    scratch = np.empty((SCRATCH_ROWS + 1, size))
    mask = np.empty(size, bool)

    def fill(theta_i, phi_i, theta_r, phi_r, out: np.ndarray) -> np.ndarray:
        n = out.size
        rows = scratch[:, :n]
        direct, ir = _oren_nayar_shapes(theta_i, phi_i, theta_r, phi_r, out=(out, rows[0]),
                                        scratch=rows[1:], mask=mask[:n])
        return _combine_into(direct, ir, a, b, c)

    return fill


def oren_nayar_brdf(theta_i, phi_i, theta_r, phi_r, rho: float, sigma: float, ir_weight: float = 1.0) -> np.ndarray:
    """Oren-Nayar functional approximation with interreflection, BRDF [1/sr].

    Parameters
    ----------
    theta_i, phi_i : array_like
        Source direction [rad], above the horizon.
    theta_r, phi_r : array_like
        Viewing direction [rad], above the horizon.
    rho : float
        Albedo of the Lambertian facets [-].
    sigma : float
        Roughness, standard deviation of the facet slope angle [deg].
    ir_weight : float, optional
        Weight w of the interreflection term [-] (1: the model of eq 35).

    Returns
    -------
    numpy.ndarray
        f_r = (rho/pi) [C1 + cos(dphi) C2 tan(beta)
        + (1 - |cos dphi|) C3 tan((alpha + beta)/2)]
        + w 0.17 (rho^2/pi) sigma^2/(sigma^2 + 0.13) [1 - cos(dphi) (2 beta/pi)^2]
        [1/sr], floored at 0 (Notes).

    Notes
    -----
    Oren & Nayar (1995) eq 33 (direct illumination), eq 34 (two-bounce interreflection)
    and eq 35 (their sum), divided by E_0 cos(theta_i) to give the BRDF.  The paper
    suggests, after eq 35, an extra weight on the interreflection term for surfaces
    rougher than the zero-mean Gaussian describes; gonio exposes it as ``ir_weight`` in
    [0, 1], the physically meaningful range (0 drops interreflection, as eq 36 does).

    The formula depends on the two polar angles only through alpha and beta and on the
    azimuths only through cos(dphi), so it is reciprocal by construction.  sigma = 0 gives
    C1 = 1, C2 = C3 = 0 and no interreflection: exactly rho/pi (footnote 10).  The
    tangents stay finite up to and including the horizon (tan of the float nearest pi/2
    is 1.6e16), so no numpy warning is raised; the BRDF grows as tan(beta) when both
    directions approach the horizon, as the formula says.

    Negative values (a decision): as printed, eq 33 becomes negative in the forward
    direction near grazing for sigma > 38.07 deg (at theta_i, theta_r -> 90 deg,
    dphi = 180 deg, C2 tan(beta) tends to 0.45 sigma^2/(sigma^2 + 0.09) 6/pi, which
    exceeds C1 there), e.g. (rho/pi) x (-0.27) at sigma = 90 deg.  The interreflection
    term compensates when rho w is large (for rho = w = 1 the sum stays positive), but
    not for dark surfaces or small ``ir_weight``.  A BRDF cannot be negative, so gonio
    returns max(f_r, 0): identical to the paper's formula wherever that is physical.

    This is the plain-call form of the registered model ``oren-nayar``, which evaluates
    the same expression through ``prepare`` (geometry terms computed once).

    References
    ----------
    M. Oren, S. K. Nayar, IJCV 14(3), 1995, section 4.3, eq 33-35 and Fig. 13.

    Examples
    --------
    >>> import numpy as np
    >>> float(oren_nayar_brdf(np.radians(30), 0.0, np.radians(10), np.pi, 0.5, 0.0)) * np.pi
    0.5
    """
    return _prepare_oren_nayar(theta_i, phi_i, theta_r, phi_r)(rho, sigma, ir_weight)


def _qualitative_coefficients(rho, sigma, variant: str = "eq36") -> tuple:
    """The scalars a = rho/pi A and b = rho/pi B of  a + b shape  (eq 36; see below)."""
    half = C1_SATURATION_FOOTNOTE11 if variant == "footnote11" else C1_SATURATION
    sigma_sq = _radians_sq(sigma)
    diffuse = rho / math.pi
    return diffuse * _c1_rad(sigma_sq, half), diffuse * (C2_AMPLITUDE * _saturation(sigma_sq, C23_SATURATION))


def _prepare_qualitative(theta_i, phi_i, theta_r, phi_r, variant: str = "eq36"):
    """Geometry-only term of eq 36 (angles [rad]); returns f(rho, sigma).

    f = a + b shape with a = rho/pi A, b = rho/pi B (:func:`_qualitative_coefficients`)
    and shape = max(0, cos dphi) sin(alpha) tan(beta) >= 0, carried as its exact
    ``linear_form``.
    """
    shape = np.maximum(cos_from_half_tangent(phi_r - phi_i), 0.0) * sin_from_half_tangent(np.maximum(theta_i, theta_r))
    shape *= np.tan(np.minimum(theta_i, theta_r))

    def coefficients(rho, sigma) -> tuple:
        return _qualitative_coefficients(rho, sigma, variant)

    def evaluate(rho: float, sigma: float) -> np.ndarray:
        a, b = coefficients(rho, sigma)
        out = shape * b
        out += a
        return out

    return with_linear_form(evaluate, lambda: LinearForm(np.stack(np.broadcast_arrays(np.ones_like(shape), shape)),
                                                         coefficients))


def oren_nayar_qualitative_brdf(
    theta_i, phi_i, theta_r, phi_r, rho: float, sigma: float, variant: str = "eq36"
) -> np.ndarray:
    """Qualitative Oren-Nayar model, BRDF [1/sr].

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Source and viewing directions [rad], above the horizon.
    rho : float
        Albedo [-].
    sigma : float
        Roughness [deg].
    variant : {"eq36", "footnote11"}
        Constant 0.33 (eq 36) or 0.57 (footnote 11) in coefficient A.

    Returns
    -------
    numpy.ndarray
        f_r = (rho/pi) (A + B max(0, cos dphi) sin(alpha) tan(beta)) [1/sr].

    Notes
    -----
    Oren & Nayar (1995) eq 36: eq 33 without the C3 term and without interreflection;
    A and B are C1 and the amplitude of C2.  Footnote 11 proposes 0.57 instead of 0.33 in
    A to make up part of the missing interreflection; ``variant="footnote11"`` selects it.
    Reciprocal by construction; sigma = 0 gives rho/pi exactly.

    References
    ----------
    M. Oren, S. K. Nayar, IJCV 14(3), 1995, section 4.4, eq 36, footnote 11, Fig. 14.

    Examples
    --------
    >>> import numpy as np
    >>> round(float(oren_nayar_qualitative_brdf(np.radians(60), 0.0, np.radians(60), 0.0, 0.9, 30.0)), 4)
    0.3671
    """
    return _prepare_qualitative(theta_i, phi_i, theta_r, phi_r, variant)(rho, sigma)
