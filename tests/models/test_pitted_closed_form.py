"""Closed-form single scattering of a spherical pit against the quadrature (eq 14-15).

The reference is :func:`gonio.models.pitted.quadrature.single_scattering_integral` at
order 64.  At order 32 the quadrature itself is off by up to ~3e-9 (relative) at a few
geometries in a thousand: there orders 64, 128 and 256 agree with each other and with the
closed form to ~1e-14, so order 32 would test the reference rather than this module.

Tolerance: ``|closed - reference| <= RTOL |reference| + ATOL``.  ATOL covers the
geometries where the integral is ~0 (a thin lit and visible sliver, degenerate triple
points): there both methods are exact only in absolute terms (~1e-15 for the quadrature,
~1e-16 for the closed form).
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from gonio.models.pitted import closed_form
from gonio.models.pitted.closed_form import (
    single_scattering_factor_closed,
    single_scattering_integral_closed,
)
from gonio.models.pitted.quadrature import (
    FLAT_LIMIT,
    GRAZING_MARGIN,
    single_scattering_factor,
    single_scattering_integral,
)

REFERENCE_ORDER = 64
RTOL = 1e-9
ATOL = 1e-13
HALF_PI = 0.5 * np.pi


def reference(alpha, beta, epsilon, psi):
    """The quadrature integral at REFERENCE_ORDER, broadcast shape [sr]."""
    return single_scattering_integral(alpha, beta, epsilon, psi, order=REFERENCE_ORDER)


def assert_agrees(alpha, beta, epsilon, psi, rtol=RTOL, atol=ATOL):
    """Closed form within rtol |reference| + atol of the quadrature."""
    alpha, beta, epsilon = np.broadcast_arrays(*(np.asarray(x, float) for x in (alpha, beta, epsilon)))
    expected = reference(alpha, beta, epsilon, psi)
    got = single_scattering_integral_closed(alpha, beta, epsilon, psi)
    excess = np.abs(got - expected) - (rtol * np.abs(expected) + atol)
    worst = int(np.argmax(excess))
    assert excess.flat[worst] <= 0.0, (
        f"alpha={alpha.flat[worst]!r} beta={beta.flat[worst]!r} eps={epsilon.flat[worst]!r} psi={psi!r}: "
        f"closed {got.flat[worst]!r} vs quadrature {expected.flat[worst]!r}"
    )


def random_angles(rng, n):
    """alpha, beta uniform in [0, pi/2), epsilon uniform in [-pi, pi] [rad]."""
    return rng.uniform(0.0, HALF_PI, n), rng.uniform(0.0, HALF_PI, n), rng.uniform(-np.pi, np.pi, n)


# ---------------------------------------------------------------- random geometries

RANDOM_PSI = np.append(HALF_PI * (1.0 - np.random.default_rng(11).uniform(size=39)), HALF_PI)  # (0, pi/2]


def test_random_geometries_agree_with_quadrature():
    # 40 apertures x 150 geometries = 6000 random geometries over the whole domain
    rng = np.random.default_rng(12)
    for psi in RANDOM_PSI:
        assert_agrees(*random_angles(rng, 150), float(psi))


@pytest.mark.parametrize("psi", [1e-3, 0.05, 0.3, 0.7, 1.2, HALF_PI])
def test_grazing_stratum_agrees_with_quadrature(psi):
    # source, or both directions, within 1e-7 .. 1e-2 rad of the horizon; and retro
    rng = np.random.default_rng(13)
    n = 300
    alpha = HALF_PI - 10.0 ** rng.uniform(-7.0, -2.0, n)
    beta = rng.uniform(0.0, HALF_PI, n)
    epsilon = rng.uniform(-np.pi, np.pi, n)
    assert_agrees(alpha, beta, epsilon, psi)
    assert_agrees(beta, alpha, epsilon, psi)
    assert_agrees(alpha, HALF_PI - 10.0 ** rng.uniform(-7.0, -2.0, n), epsilon, psi)
    assert_agrees(alpha, alpha, 0.0, psi)
    assert_agrees(HALF_PI - GRAZING_MARGIN, HALF_PI - GRAZING_MARGIN, epsilon, psi)


@pytest.mark.parametrize("psi", [0.3, 1.0, HALF_PI])
def test_factor_is_clamped_at_grazing_like_the_quadrature(psi):
    epsilon = np.linspace(-np.pi, np.pi, 13)
    limit = HALF_PI - GRAZING_MARGIN
    at_limit = single_scattering_factor_closed(limit, 0.4, epsilon, psi)
    for alpha in (HALF_PI - 1e-9, HALF_PI, HALF_PI + 0.1):
        np.testing.assert_array_equal(single_scattering_factor_closed(alpha, 0.4, epsilon, psi), at_limit)
        np.testing.assert_array_equal(single_scattering_factor_closed(0.4, alpha, epsilon, psi),
                                      single_scattering_factor_closed(0.4, limit, epsilon, psi))
    expected = single_scattering_factor(HALF_PI, 0.4, epsilon, psi, order=REFERENCE_ORDER)
    np.testing.assert_allclose(at_limit, expected, rtol=1e-8, atol=1e-10)


def test_factor_agrees_with_quadrature_factor():
    rng = np.random.default_rng(14)
    for psi in (0.2, 0.9, HALF_PI):
        alpha, beta, epsilon = random_angles(rng, 400)
        expected = single_scattering_factor(alpha, beta, epsilon, psi, order=REFERENCE_ORDER)
        got = single_scattering_factor_closed(alpha, beta, epsilon, psi)
        # the integral's tolerance, divided like the integral
        scale = np.pi**2 * np.sin(psi) ** 2 * np.cos(alpha) * np.cos(beta)
        assert np.all(np.abs(got - expected) <= RTOL * np.abs(expected) + ATOL / scale)


# ---------------------------------------------------------------- degenerate cases

DEGENERATE_PSI = [0.2, 0.7, 1.1, 1.5, HALF_PI]


@pytest.mark.parametrize("psi", DEGENERATE_PSI)
@pytest.mark.parametrize("epsilon", [0.0, 2.0 * np.pi, -2.0 * np.pi, 1e-200, 1e-160, 1e-13, 1e-9, 1e-5])
def test_retro_reflection_counts_the_shared_circle_once(psi, epsilon):
    # alpha = beta, eps = 0: the lit and the visible boundary are the same circle
    alpha = np.linspace(0.0, HALF_PI - 1e-4, 23)
    assert_agrees(alpha, alpha, epsilon, psi)


@pytest.mark.parametrize("psi", DEGENERATE_PSI)
def test_retro_reflection_is_approached_linearly(psi):
    # near retro-reflection the lit and visible caps are shifted copies, whose common part
    # shrinks linearly with the shift: I(eps) = I(0) - c |eps| + O(eps^2).  The slope seen
    # from exact coincidence agrees at eps = 1e-5 and 1e-9 (a mishandled coincidence would
    # not), and a shift of 1e-15 in beta changes I by rounding only
    alpha = np.linspace(0.0, HALF_PI - 1e-4, 23)
    exact = single_scattering_integral_closed(alpha, alpha, 0.0, psi)
    slopes = [(single_scattering_integral_closed(alpha, alpha, eps, psi) - exact) / eps
              for eps in (1e-5, 1e-9)]
    assert np.all(slopes[1] <= 1e-5)
    np.testing.assert_allclose(slopes[1], slopes[0], rtol=0.0, atol=1e-5)
    np.testing.assert_allclose(single_scattering_integral_closed(alpha, alpha + 1e-15, 0.0, psi), exact,
                               rtol=0.0, atol=1e-14)


@pytest.mark.parametrize("psi", DEGENERATE_PSI)
def test_tangent_circles(psi):
    beta = np.linspace(0.01, 1.56, 7)
    epsilon = np.linspace(-3.0, 3.0, 7)
    if psi < HALF_PI:
        # cavity rim tangent to the shadow (and to the occlusion) boundary
        tangent = HALF_PI - psi
        assert_agrees(tangent, beta, epsilon, psi)
        assert_agrees(beta, tangent, epsilon, psi)
        assert_agrees(tangent, tangent, np.linspace(-3.1, 3.1, 9), psi)
    # shadow and occlusion boundaries tangent: |s_lit s_vis| = 2 psi
    alpha = np.linspace(0.0, 1.5, 9)
    inside = alpha + psi < HALF_PI
    if np.any(inside):
        assert_agrees(alpha[inside], alpha[inside] + psi, 0.0, psi)
    alpha = np.linspace(0.0, min(psi, 1.5), 9)
    assert_agrees(alpha, psi - alpha, np.pi, psi)


@pytest.mark.parametrize("psi", DEGENERATE_PSI)
def test_three_circles_through_one_point(psi):
    # the viewer's boundary passes through a crossing of the rim and the shadow boundary:
    # on the rim those are at azimuths +-u_a, +-eps +- u_b, cos u = -cot(angle) cot(psi)
    rng = np.random.default_rng(15)
    low = HALF_PI - psi + 1e-3
    alpha, beta = rng.uniform(low, HALF_PI - 1e-3, (2, 40))
    u_alpha = np.arccos(-1.0 / (np.tan(alpha) * np.tan(psi)))
    u_beta = np.arccos(-1.0 / (np.tan(beta) * np.tan(psi)))
    for sign_a in (1.0, -1.0):
        for sign_b in (1.0, -1.0):
            epsilon = sign_a * u_alpha - sign_b * u_beta
            for shift in (0.0, 1e-14, 1e-10, 1e-6):
                assert_agrees(alpha, beta, epsilon + shift, psi)


@pytest.mark.parametrize("psi", DEGENERATE_PSI)
def test_source_or_viewer_at_the_normal(psi):
    # s = z: the shadow cap is centred at -z (for psi = 90 deg its circle is the rim)
    other = np.linspace(0.0, 1.57, 9)
    epsilon = np.linspace(-3.0, 3.0, 9)
    assert_agrees(0.0, other, epsilon, psi)
    assert_agrees(other, 0.0, epsilon, psi)
    # mirror vectors opposite: the two boundaries coincide for psi = 90 deg
    assert_agrees(other[1:-1], HALF_PI - other[1:-1], np.pi, psi)


def test_hemisphere_random_geometries():
    rng = np.random.default_rng(16)
    assert_agrees(*random_angles(rng, 1000), HALF_PI)


@pytest.mark.parametrize("psi", [1e-2, 1e-4, 1e-6, 1e-8, 1e-12])
def test_shallow_pits_keep_relative_accuracy(psi):
    # away from grazing the whole rim bounds R (no cancelling arcs)
    rng = np.random.default_rng(17)
    alpha, beta, epsilon = random_angles(rng, 300)
    alpha, beta = 0.99 * alpha, 0.99 * beta
    got = single_scattering_factor_closed(alpha, beta, epsilon, psi)
    expected = single_scattering_factor(alpha, beta, epsilon, psi, order=REFERENCE_ORDER)
    np.testing.assert_allclose(got, expected, rtol=RTOL, atol=0.0)


def test_flat_limit_is_one_over_pi():
    # sin^2 psi below FLAT_LIMIT: 1/pi exactly, as the quadrature
    assert np.sin(1e-101) ** 2 < FLAT_LIMIT
    for psi in (0.0, 1e-101):
        got = single_scattering_factor_closed([0.0, 0.3, 1.2], [0.5, 0.0, 1.5], [0.0, 1.0, 3.0], psi)
        np.testing.assert_array_equal(got, np.full(3, 1.0 / np.pi))
    assert float(single_scattering_factor_closed(0.3, 0.5, 1.0, 1e-4)) * np.pi == pytest.approx(1.0, abs=1e-8)


@pytest.mark.parametrize("epsilon", [-3.0, -0.4, 0.0, 1.3, np.pi])
def test_azimuth_is_periodic_and_even(epsilon):
    rng = np.random.default_rng(18)
    alpha, beta, _ = random_angles(rng, 50)
    psi = 1.1
    base = single_scattering_integral_closed(alpha, beta, epsilon, psi)
    for turns in (-3, -1, 1, 2, 5):
        shifted = single_scattering_integral_closed(alpha, beta, epsilon + 2.0 * np.pi * turns, psi)
        np.testing.assert_allclose(shifted, base, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(single_scattering_integral_closed(alpha, beta, -epsilon, psi), base,
                               rtol=1e-12, atol=1e-15)
    assert_agrees(alpha, beta, epsilon + 2.0 * np.pi * 7, psi)


# ---------------------------------------------------------------- known values, symmetry

@pytest.mark.parametrize("psi", [1e-6, 1e-3, 0.1, 0.5, 1.0, 1.4, HALF_PI])
def test_normal_incidence_and_view_is_the_cap_integral(psi):
    # alpha = beta = 0: all of the cavity, integral of m_z^2 = 2 pi (1 - cos^3 psi) / 3,
    # with 1 - cos psi = 2 sin^2(psi / 2)
    one_minus_cos = 2.0 * np.sin(psi / 2.0) ** 2
    cos_psi = np.cos(psi)
    expected = 2.0 * np.pi * one_minus_cos * (1.0 + cos_psi + cos_psi**2) / 3.0
    got = single_scattering_integral_closed(0.0, 0.0, np.linspace(-3.0, 3.0, 5), psi)
    np.testing.assert_allclose(got, expected, rtol=1e-14)


def test_hemisphere_at_normal_is_two_pi_over_three():
    assert float(single_scattering_integral_closed(0.0, 0.0, 0.0, HALF_PI)) == pytest.approx(
        2.0 * np.pi / 3.0, rel=1e-15)


def test_reciprocity():
    # swapping source and viewer (eps -> -eps for the mirrored frame) leaves I unchanged
    rng = np.random.default_rng(19)
    for psi in (0.05, 0.6, 1.3, HALF_PI):
        alpha, beta, epsilon = random_angles(rng, 500)
        alpha[:100] = HALF_PI - 10.0 ** rng.uniform(-7.0, -2.0, 100)
        forward = single_scattering_integral_closed(alpha, beta, epsilon, psi)
        np.testing.assert_allclose(single_scattering_integral_closed(beta, alpha, -epsilon, psi), forward,
                                   rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(single_scattering_integral_closed(beta, alpha, epsilon, psi), forward,
                                   rtol=1e-12, atol=1e-15)
        # the factor, with the integral's absolute rounding divided like the integral
        factor = single_scattering_factor_closed(alpha, beta, epsilon, psi)
        swapped = single_scattering_factor_closed(beta, alpha, -epsilon, psi)
        scale = np.pi**2 * np.sin(psi) ** 2 * np.cos(alpha) * np.cos(beta)
        assert np.all(np.abs(swapped - factor) <= 1e-12 * factor + 1e-15 / scale)


def test_integral_is_nonnegative_and_bounded_by_the_cavity():
    # random geometries, and forward grazing where R is a sliver of area ~1e-20 and the
    # arc sums cancel to rounding (m.i >= 0 where lit and m.e >= 0 where visible)
    rng = np.random.default_rng(20)
    for psi in RANDOM_PSI[:10]:
        alpha, beta, epsilon = random_angles(rng, 500)
        alpha[:250] = beta[:250] = HALF_PI - 10.0 ** rng.uniform(-7.0, -4.0, 250)
        epsilon[:250] = np.pi - 10.0 ** rng.uniform(-3.0, 0.0, 250)
        got = single_scattering_integral_closed(alpha, beta, epsilon, float(psi))
        assert np.all(got >= 0.0)
        assert np.all(got <= 2.0 * np.pi * (1.0 - np.cos(psi)))  # (m.i)(m.e) <= 1 on the cap


# ---------------------------------------------------------------- interface

def test_no_warnings_on_degenerate_inputs():
    inside = [0.0, 1e-300, 1e-8, 0.3, HALF_PI - GRAZING_MARGIN, HALF_PI - 1e-16]
    azimuths = [0.0, 1e-300, 1.0, np.pi, -np.pi, 40.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for psi in (0.0, 1e-300, 1e-8, 0.7, HALF_PI):
            beyond = inside + [HALF_PI, HALF_PI + 0.2]
            alpha, beta, epsilon = np.meshgrid(beyond, inside + [HALF_PI], azimuths)
            assert np.all(np.isfinite(single_scattering_factor_closed(alpha, beta, epsilon, psi)))
            if psi > 0.0:
                alpha, beta, epsilon = np.meshgrid(inside, inside, azimuths)
                assert np.all(np.isfinite(single_scattering_integral_closed(alpha, beta, epsilon, psi)))


def test_shapes_broadcasting_and_array_aperture():
    alpha = np.linspace(0.0, 1.5, 4)[:, None]
    beta = np.linspace(0.1, 1.4, 3)
    got = single_scattering_factor_closed(alpha, beta, 0.5, 0.8)
    assert got.shape == (4, 3)
    assert np.ndim(single_scattering_factor_closed(0.1, 0.2, 0.3, 0.8)) == 0
    assert single_scattering_integral_closed(0.1, 0.2, 0.3, 0.8).shape == ()
    # an array of apertures is the same as one call per aperture
    psi = np.array([0.3, 0.8, HALF_PI])
    together = single_scattering_integral_closed(0.4, 0.9, 2.0, psi)
    one_by_one = [float(single_scattering_integral_closed(0.4, 0.9, 2.0, p)) for p in psi]
    np.testing.assert_array_equal(together, one_by_one)


def test_scalar_kernel_matches_the_array_function():
    psi = 0.9
    half = np.sin(psi / 2.0)
    for alpha, beta, epsilon in [(0.2, 0.7, 1.0), (1.3, 1.1, -2.5), (0.0, 0.0, 0.0), (0.9, 0.9, 0.0)]:
        scalar = closed_form.integral_kernel(alpha, beta, epsilon, np.cos(psi), np.sin(psi),
                                             2.0 * half * half)
        assert scalar == float(single_scattering_integral_closed(alpha, beta, epsilon, psi))


def test_nan_propagates():
    assert np.isnan(single_scattering_integral_closed(np.nan, 0.3, 0.2, 1.0))
    assert np.isnan(single_scattering_factor_closed(0.3, np.nan, 0.2, 1.0))
    assert np.isnan(single_scattering_factor_closed(0.3, 0.4, np.nan, 1.0))
