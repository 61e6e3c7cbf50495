"""Fresnel reflectance of a smooth dielectric (Wolff, Nayar & Oren 1998, eq 2) and the
polynomial approximation stated after eq 7."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.models.fresnel import (
    exit_transmittance,
    fresnel_polynomial,
    fresnel_reflectance,
    fresnel_transmittance,
    polynomial_epsilon,
)

index = st.floats(1.01, 4.0)
cosine = st.floats(0.0, 1.0)


def eq2_angle_form(theta_i: np.ndarray, n: float) -> np.ndarray:
    """Eq 2 written literally with the angles (valid away from normal incidence)."""
    theta_t = np.arcsin(np.sin(theta_i) / n)
    minus, plus = theta_i - theta_t, theta_i + theta_t
    return 0.5 * np.sin(minus) ** 2 / np.sin(plus) ** 2 * (1.0 + np.cos(plus) ** 2 / np.cos(minus) ** 2)


@pytest.mark.parametrize("n", [1.3, 1.5, 2.0, 2.42])
def test_amplitude_form_equals_eq2_angle_form(n):
    """Eq 2: the r_s/r_p form computed by gonio equals the paper's angle form."""
    theta = np.radians(np.linspace(1.0, 89.0, 89))
    # 1e-12: two exact rearrangements of one formula differ by rounding only.
    np.testing.assert_allclose(fresnel_reflectance(np.cos(theta), n), eq2_angle_form(theta, n), rtol=1e-12)


@settings(max_examples=40, deadline=None)
@given(n=index)
def test_limits_normal_and_grazing(n):
    """Eq 2 limits: ((n-1)/(n+1))^2 at normal incidence, 1 at grazing incidence."""
    assert fresnel_reflectance(1.0, n) == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-12, abs=1e-15)
    assert fresnel_reflectance(0.0, n) == pytest.approx(1.0, abs=1e-12)
    # also from inside (relative index 1/n): same normal value, total reflection at grazing
    assert fresnel_reflectance(1.0, 1.0 / n) == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-12, abs=1e-15)
    assert fresnel_reflectance(0.0, 1.0 / n) == 1.0


@settings(max_examples=40, deadline=None)
@given(n=index, c=cosine)
def test_reflectance_is_a_fraction(n, c):
    """0 <= F <= 1 (eq 2 is an energy fraction)."""
    for value in (fresnel_reflectance(c, n), fresnel_reflectance(c, 1.0 / n)):
        assert 0.0 <= float(value) <= 1.0


@pytest.mark.parametrize("n", [1.3, 1.5, 2.0])
def test_total_internal_reflection_from_inside(n):
    """Snell's law from inside (relative index 1/n): F = 1 beyond the critical angle
    asin(1/n), F < 1 just inside it, and continuous at it."""
    critical = np.degrees(np.arcsin(1.0 / n))
    beyond = np.radians(np.linspace(critical + 1e-6, 90.0, 50))
    assert np.all(fresnel_reflectance(np.cos(beyond), 1.0 / n) == 1.0)
    within = np.radians(np.linspace(0.0, critical - 0.5, 50))
    assert np.all(fresnel_reflectance(np.cos(within), 1.0 / n) < 1.0)
    # continuity: F -> 1 as the critical angle is approached (sqrt onset: 1e-8 deg away
    # leaves 1 - F of order sqrt(1e-10) ~ 1e-5)
    near = np.radians(critical - 1e-8)
    assert fresnel_reflectance(np.cos(near), 1.0 / n) > 1.0 - 1e-3


@settings(max_examples=40, deadline=None)
@given(n=index, c=cosine)
def test_exit_transmittance_equals_entry_transmittance(n, c):
    """Eq 7 exit factor: 1 - F(asin(sin(theta_r)/n), 1/n) = 1 - F(theta_r, n) (reciprocity of
    the Fresnel coefficients), which makes eq 7 symmetric in theta_i and theta_r."""
    # 1e-12 absolute: the two paths differ by rounding in the internal cosine.
    assert exit_transmittance(c, n) == pytest.approx(fresnel_transmittance(c, n), abs=1e-12)


def test_nan_propagates_and_no_warnings_at_normal_or_grazing():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        values = fresnel_reflectance(np.array([np.nan, 0.0, 1.0]), 1.5)
        inside = fresnel_reflectance(np.array([0.0, 1.0]), 1 / 1.5)
        out = exit_transmittance(np.array([np.nan, 0.0, 1.0]), 1.5)
    assert np.isnan(values[0]) and np.isnan(out[0])
    assert np.all(np.isfinite(values[1:])) and np.all(np.isfinite(inside)) and np.all(np.isfinite(out[1:]))


@pytest.mark.parametrize("bad", [0.0, -1.5])
def test_non_positive_index_is_rejected(bad):
    with pytest.raises(ValueError, match=rf"n = {bad:g} .*\(0, inf\)"):
        fresnel_reflectance(0.5, bad)
    with pytest.raises(ValueError, match="n = "):
        exit_transmittance(0.5, bad)
    with pytest.raises(ValueError, match="epsilon"):
        fresnel_polynomial(0.5, -0.1)


@settings(max_examples=40, deadline=None)
@given(n=index)
def test_polynomial_is_exact_at_normal_and_grazing(n):
    """After eq 7: with gonio's epsilon = F0/(1 - F0) the polynomial matches eq 2 at x = 0
    and both equal 1 at x = pi/2."""
    eps = polynomial_epsilon(n)
    assert fresnel_polynomial(0.0, eps) == pytest.approx(fresnel_reflectance(1.0, n), rel=1e-12)
    assert fresnel_polynomial(np.pi / 2, eps) == pytest.approx(1.0, rel=1e-15)


def test_polynomial_epsilon_near_paper_typical_value():
    """After eq 7: epsilon is 'typically 0.07'; gonio's rule gives 0.07 at n = 1.687
    (root of n^2 - 2.28 n + 1 = 0) and 0.017-0.125 over n in [1.3, 2.0]."""
    assert polynomial_epsilon(1.687) == pytest.approx(0.07, abs=1e-4)
    assert 0.017 < polynomial_epsilon(1.3) < polynomial_epsilon(2.0) < 0.13


def test_polynomial_error_against_eq2_for_common_dielectrics():
    """After eq 7: measured error of the polynomial against eq 2 for n in [1.3, 2.0]
    (recorded in docs/wolff.md).  The paper calls it a good approximation; measured, it is
    within 0.004 of eq 2 up to 30 deg, 0.04 up to 50 deg, but 0.23 at worst (near 80 deg,
    n = 1.3), because (2x/pi)^5 rises earlier than the true reflectance."""
    theta = np.linspace(0.0, np.pi / 2, 4001)
    worst = {30: 0.0, 50: 0.0, 90: 0.0}
    for n in np.linspace(1.3, 2.0, 15):
        error = np.abs(fresnel_polynomial(theta, polynomial_epsilon(n)) - fresnel_reflectance(np.cos(theta), n))
        for limit in worst:
            worst[limit] = max(worst[limit], float(error[theta <= np.radians(limit) + 1e-12].max()))
    # Bounds are the measured values rounded up in the second digit: a change in either
    # formula that moves the error by more than that fails here.
    assert worst[30] < 0.0035
    assert worst[50] < 0.041
    assert 0.20 < worst[90] < 0.23
