"""Zernike polynomials on the hemisphere (Koenderink & van Doorn 1998, eq 1-16, Figs 1-2)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import eval_legendre

from gonio.zernike import (
    azimuthal_factor,
    hemisphere_basis,
    hemisphere_basis_indices,
    hemisphere_radius,
    zernike_radial,
    zernike_radial_of_cos,
)


def radial_by_factorial_sum(n: int, m: int, rho: np.ndarray) -> np.ndarray:
    """KvD eq 3 written out literally (the reference for the Jacobi-polynomial path)."""
    m = abs(m)
    total = np.zeros_like(rho)
    for s in range((n - m) // 2 + 1):
        coefficient = (-1) ** s * math.factorial(n - s) / (
            math.factorial(s) * math.factorial((n + m) // 2 - s) * math.factorial((n - m) // 2 - s)
        )
        total = total + coefficient * rho ** (n - 2 * s)
    return total


def hemisphere_quadrature(n_theta: int = 40, n_phi: int = 48):
    """Gauss-Legendre in cos(theta) and equally spaced azimuths: exact for K_n^l products
    up to n = 2 n_theta - 1 in the radial part and |l| < n_phi / 2 in the azimuth."""
    x, w = np.polynomial.legendre.leggauss(n_theta)
    mu, w_mu = 0.5 * (x + 1.0), 0.5 * w
    phi = 360.0 * np.arange(n_phi) / n_phi
    theta = np.degrees(np.arccos(mu))
    weights = w_mu[:, None] * (2 * math.pi / n_phi) * np.ones(n_phi)[None, :]
    return theta[:, None], phi[None, :], weights


ZERNIKE_PAIRS = [(n, m) for n in range(13) for m in range(-n, n + 1, 2)]


@pytest.mark.parametrize("n,m", ZERNIKE_PAIRS)
def test_radial_polynomial_matches_the_factorial_sum_of_eq3(n, m):
    rho = np.linspace(0.0, 1.0, 41)
    # Both are the same polynomial; up to n = 12 the factorial sum loses at most ~1e-12
    # to cancellation (coefficients below 1e4), so 1e-10 absolute is a safe margin.
    np.testing.assert_allclose(zernike_radial(n, m, rho), radial_by_factorial_sum(n, m, rho), atol=1e-10, rtol=0)


@pytest.mark.parametrize("n", range(0, 9))
def test_even_radial_polynomial_is_a_legendre_polynomial_eq37(n):
    """KvD eq 37: R_2n^0(rho) = P_n(2 rho^2 - 1)."""
    rho = np.linspace(0.0, 1.0, 23)
    np.testing.assert_allclose(zernike_radial(2 * n, 0, rho), eval_legendre(n, 2 * rho**2 - 1), atol=1e-12)


def test_radial_polynomial_is_one_on_the_rim_and_known_low_orders():
    rho = np.array([0.0, 0.3, 1.0])
    np.testing.assert_allclose(zernike_radial(3, 1, rho), 3 * rho**3 - 2 * rho, atol=1e-15)
    np.testing.assert_allclose(zernike_radial(4, 2, rho), 4 * rho**4 - 3 * rho**2, atol=1e-15)
    for n, m in ZERNIKE_PAIRS:
        assert zernike_radial(n, m, 1.0) == pytest.approx(1.0, abs=1e-12)


def test_hemisphere_map_eq10_takes_the_horizon_to_the_rim_and_preserves_area():
    assert hemisphere_radius(0.0) == 0.0
    assert hemisphere_radius(90.0) == pytest.approx(1.0, abs=1e-15)
    # eq 11: rho d(rho) = sin(theta) d(theta) / 2, checked by a central difference (1e-8
    # is the truncation error of the step 1e-4 rad, far below the 1e-6 tolerance).
    theta = np.radians(np.array([10.0, 45.0, 80.0]))
    h = 1e-4
    rho = hemisphere_radius(np.degrees(theta))
    derivative = (hemisphere_radius(np.degrees(theta + h)) - hemisphere_radius(np.degrees(theta - h))) / (2 * h)
    np.testing.assert_allclose(rho * derivative, np.sin(theta) / 2, rtol=1e-6)


def test_azimuthal_factors_eq5_to_9_normalisation_and_parity():
    phi = 360.0 * np.arange(64) / 64
    for k in range(-4, 5):
        for l in range(-4, 5):
            inner = np.sum(azimuthal_factor(k, phi) * azimuthal_factor(l, phi)) * 2 * math.pi / 64
            assert inner == pytest.approx(math.pi if k == l else 0.0, abs=1e-12)  # exact trapezoid
        np.testing.assert_allclose(azimuthal_factor(k, phi + 180.0), (-1) ** abs(k) * azimuthal_factor(k, phi), atol=1e-12)


def test_hemisphere_basis_is_orthonormal_by_quadrature_eq16():
    """KvD eq 16, all K_n^l up to n = 10, to 1e-10 as the issue requires.

    The quadrature is exact for these polynomial integrands, so the observed error is
    rounding only (~1e-14)."""
    theta, phi, weights = hemisphere_quadrature()
    indices = hemisphere_basis_indices(10)
    values = np.array([hemisphere_basis(n, l, theta, phi).ravel() for n, l in indices])
    gram = (values * weights.ravel()) @ values.T
    np.testing.assert_allclose(gram, np.eye(len(indices)), atol=1e-10)
    assert len(indices) == 66


def test_lowest_hemisphere_function_is_uniform():
    assert hemisphere_basis(0, 0, [0.0, 45.0, 90.0], 30.0) == pytest.approx(1 / math.sqrt(2 * math.pi))


@pytest.mark.parametrize(
    "call",
    [
        lambda: zernike_radial(-1, 0, 0.5),
        lambda: zernike_radial(3, 0, 0.5),  # n - m odd
        lambda: zernike_radial(2, 4, 0.5),  # m > n
        lambda: zernike_radial(2, 0, 1.5),  # outside the disk
        lambda: hemisphere_basis(2, 0, 95.0, 0.0),
        lambda: hemisphere_basis_indices(-1),
        lambda: zernike_radial(2.5, 0, 0.5),
    ],
)
def test_bad_indices_and_angles_raise_value_error(call):
    with pytest.raises(ValueError):
        call()


def test_negative_order_message_names_the_value():
    with pytest.raises(ValueError, match="order = -2 is negative"):
        hemisphere_basis_indices(-2)


def test_nan_propagates_and_normal_and_grazing_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        values = hemisphere_basis(4, 2, np.array([0.0, 1e-9, 89.999, 90.0, np.nan]), 30.0)
        radial = zernike_radial_of_cos(5, 1, np.array([0.0, 1.0, np.nan]))
    assert np.isnan(values[-1]) and np.all(np.isfinite(values[:-1]))
    assert np.isnan(radial[-1]) and np.all(np.isfinite(radial[:-1]))
    assert values[0] == 0.0  # R_4^2 vanishes at the centre of the disk (rho^2 factor)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 12).flatmap(lambda n: st.tuples(st.just(n), st.sampled_from(range(-n, n + 1, 2)))), st.floats(0.0, 1.0))
def test_radial_polynomial_is_bounded_by_one_on_the_disk(pair, rho):
    """|R_n^m| <= 1 on the unit disk (a classical Zernike property), 1e-12 for rounding."""
    n, m = pair
    assert abs(float(zernike_radial(n, m, rho))) <= 1.0 + 1e-12


def test_recurrence_table_equals_the_reference_radial_polynomials():
    """The fast path (three-term Jacobi recurrence) against the reference
    zernike_radial_of_cos, all (n, l) up to 16: rounding only (measured 1e-14), 1e-12."""
    from gonio.zernike import zernike_radial_table

    cos_theta = np.concatenate([np.linspace(0.0, 1.0, 401), [np.nan]])
    table = zernike_radial_table(16, cos_theta)
    assert sorted(table) == sorted((n, l) for n in range(17) for l in range(n % 2, n + 1, 2))
    for (n, l), values in table.items():
        np.testing.assert_allclose(values, zernike_radial_of_cos(n, l, cos_theta), atol=1e-12, rtol=0)
        assert np.isnan(values[-1])
