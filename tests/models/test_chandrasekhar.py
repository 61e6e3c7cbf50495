"""Chandrasekhar's H-function for isotropic scattering: the N-th order approximation quoted
after eq 8 of Wolff, Nayar & Oren (1998), validated against an independent solution of the
integral equation, an exact integral representation, exact moments and the classical
limb-darkening value."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from gonio.models.chandrasekhar import (
    DEFAULT_ORDER,
    characteristic_roots,
    discrete_ordinates,
    h_function,
    h_function_numerical,
)

ALBEDOS = [0.0, 0.1, 0.5, 0.9, 0.99, 1.0]


def h_closed_integral(mu: float, omega: float) -> float:
    """H from its exact integral representation (Chandrasekhar 1960, ch. V):
    ln H(mu) = -(mu/pi) int_0^{pi/2} ln(1 - omega t cot t) / (cos^2 t + mu^2 sin^2 t) dt.
    Independent of both the discrete approximation and the integral-equation solver."""
    if mu == 0.0 or omega == 0.0:
        return 1.0

    def integrand(t: float) -> float:
        t_cot_t = 1.0 if t == 0.0 else t / np.tan(t)
        return np.log(1.0 - omega * t_cot_t) / (np.cos(t) ** 2 + mu**2 * np.sin(t) ** 2)

    value, _ = quad(integrand, 0.0, np.pi / 2, limit=200, epsabs=1e-14, epsrel=1e-13)
    return float(np.exp(-mu / np.pi * value))


@pytest.mark.parametrize("omega", [0.1, 0.5, 0.9, 0.999])
@pytest.mark.parametrize("mu", [0.02, 0.3, 0.7, 1.0])
def test_integral_equation_solver_matches_exact_integral_representation(mu, omega):
    """The reference solver (nonlinear integral equation, Gauss grid + Newton) against the
    closed integral representation; 1e-9: both are converged quadratures (measured 1e-14)."""
    assert h_function_numerical(mu, omega) == pytest.approx(h_closed_integral(mu, omega), rel=1e-9)


def test_conservative_h_of_one_matches_milne_limb_darkening():
    """Published value: for conservative isotropic scattering H(1) = 2.9078, the inverse of
    the exact limb-to-centre intensity ratio 0.3439 of the Milne problem (Chandrasekhar 1960,
    ch. V tables).  Tolerance: the last quoted digit."""
    assert h_function_numerical(1.0, 1.0) == pytest.approx(2.9078, abs=1e-4)
    assert 1.0 / h_function_numerical(1.0, 1.0) == pytest.approx(0.3439, abs=1e-4)


@pytest.mark.parametrize("omega", [0.3, 0.9, 1.0])
def test_exact_moments(omega):
    """Exact identities of the H-function (Chandrasekhar 1960, ch. V):
    int_0^1 H dmu = (2/omega)(1 - sqrt(1 - omega)); for omega = 1 also int_0^1 mu H dmu = 2/sqrt(3)."""
    x, w = np.polynomial.legendre.leggauss(200)
    mu, w = 0.5 * (x + 1.0), 0.5 * w
    h = h_function_numerical(mu, omega)
    # 1e-8: the 400-node solver is accurate to ~1e-10 away from mu = 0 (measured 4e-11).
    assert np.sum(w * h) == pytest.approx(2.0 / omega * (1.0 - np.sqrt(1.0 - omega)), rel=1e-8)
    if omega == 1.0:
        assert np.sum(w * mu * h) == pytest.approx(2.0 / np.sqrt(3.0), rel=1e-8)


@pytest.mark.parametrize("order", [1, 3, 8, 32])
@pytest.mark.parametrize("omega", [0.2, 0.8, 1.0])
def test_approximation_solves_the_discrete_integral_equation(order, omega):
    """The N-th order closed form is the exact solution of the integral equation with the
    integral replaced by the half-range Gauss sum over the zeros of P_2N:
    H(mu) = 1 + (omega/2) mu H(mu) sum_j a_j H(mu_j)/(mu + mu_j), and its zeroth moment
    sum_j a_j H(mu_j) = (2/omega)(1 - sqrt(1 - omega)).  1e-12: identities up to rounding."""
    mu_j, a = discrete_ordinates(order)
    h_j = h_function(mu_j, omega, order)
    mu = np.array([0.0, 0.05, 0.3, 0.77, 1.0])
    h = h_function(mu, omega, order)
    rhs = 1.0 + 0.5 * omega * mu * h * np.sum(a * h_j / (mu[:, None] + mu_j), axis=1)
    np.testing.assert_allclose(h, rhs, rtol=1e-12)
    assert np.sum(a * h_j) == pytest.approx(2.0 / omega * (1.0 - np.sqrt(1.0 - omega)), rel=1e-12)


def test_first_approximation_closed_form():
    """N = 1: mu_1 = 1/sqrt(3), k = sqrt(3 (1 - omega)), H = (1 + sqrt(3) mu)/(1 + k mu)."""
    mu = np.linspace(0.0, 1.0, 11)
    for omega in (0.3, 0.75):
        k = np.sqrt(3.0 * (1.0 - omega))
        assert characteristic_roots(omega, 1) == pytest.approx([k], rel=1e-12)
        np.testing.assert_allclose(h_function(mu, omega, 1), (1 + np.sqrt(3) * mu) / (1 + k * mu), rtol=1e-12)


@pytest.mark.parametrize("omega", [1e-6, 0.4, 0.95, 1.0])
def test_characteristic_roots_solve_the_characteristic_equation(omega):
    """Characteristic equation after eq 8: 1 = omega sum_j a_j / (1 - k^2 mu_j^2); N roots
    for omega < 1, N - 1 for omega = 1 (k = 0 excluded), one between consecutive 1/mu_j."""
    order = 8
    mu, a = discrete_ordinates(order)
    roots = characteristic_roots(omega, order)
    assert roots.size == (order - 1 if omega == 1.0 else order)
    s = roots**2
    residual = np.array([omega * np.sum(a / (1.0 - k2 * mu**2)) - 1.0 for k2 in s])
    slope = np.array([omega * np.sum(a * mu**2 / (1.0 - k2 * mu**2) ** 2) for k2 in s])
    # The Newton correction residual/slope measures how far each root is from the true
    # one; 1e-12 relative: the roots are bracketed to rounding (brentq rtol 1e-15), and
    # near a pole the residual itself is ill-conditioned, the correction is not.
    assert np.all(np.abs(residual / slope) <= 1e-12 * s)
    assert np.all(np.diff(roots) > 0)
    poles = np.sort(1.0 / mu)
    interior = roots[-(order - 1):]
    assert np.all((interior > poles[:-1]) & (interior < poles[1:]))


def test_error_of_nth_approximation_falls_with_order():
    """The N-th approximation converges to the exact H (integral-equation solution).
    Measured worst relative error over mu in [0, 1], omega in {0.01, ..., 1}: 7.5e-2 (N=1),
    7.9e-3 (N=8), 1.9e-3 (N=32); it halves when N doubles (benchmarks/bench_wolff.py)."""
    mu = np.linspace(0.0, 1.0, 101)
    worst = {}
    for order in (1, 2, 4, 8, 16, 32):
        worst[order] = max(
            float(np.max(np.abs(h_function(mu, omega, order) / h_function_numerical(mu, omega) - 1.0)))
            for omega in (0.01, 0.5, 0.9, 1.0)
        )
    errors = [worst[k] for k in sorted(worst)]
    assert all(later < 0.6 * earlier for earlier, later in zip(errors, errors[1:]))
    # bounds: measured values rounded up
    assert worst[1] < 0.08 and worst[8] < 0.008 and worst[DEFAULT_ORDER] < 0.002


def test_approximation_at_default_order_for_directions_inside_a_dielectric():
    """Inside a dielectric with n <= 2 the refracted cosines are >= sqrt(3)/2 ~ 0.87, where
    the default approximation is within 2e-4 of the exact H (measured 5.8e-5)."""
    mu = np.linspace(np.sqrt(3) / 2, 1.0, 21)
    for omega in ALBEDOS:
        np.testing.assert_allclose(h_function(mu, omega), h_function_numerical(mu, omega), rtol=2e-4)


@settings(max_examples=30, deadline=None)
@given(omega=st.floats(0.0, 1.0), mu=st.floats(0.0, 1.0))
def test_h_is_at_least_one_and_increases_with_mu(omega, mu):
    """H(0) = 1 and H increases with mu (all terms of the integral equation are positive)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        values = h_function(np.array([0.0, mu, min(mu + 0.01, 1.0)]), omega)
    assert values[0] == pytest.approx(1.0, abs=1e-14)
    assert np.all(np.diff(values) >= -1e-14)
    assert h_function(mu, 0.0) == 1.0


def test_extreme_albedos_are_warning_free_and_continuous():
    """Roots crowd the poles as omega -> 0 and one root -> 0 as omega -> 1; H stays
    continuous there (1e-6: the change of H over those albedo steps is smaller)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tiny = h_function(0.5, 1e-300)
        small = h_function(0.5, 1e-12)
        almost = h_function(0.5, 1.0 - 1e-15)
        one = h_function(0.5, 1.0)
    assert tiny == pytest.approx(1.0, abs=1e-12) and small == pytest.approx(1.0, abs=1e-9)
    assert almost == pytest.approx(one, rel=1e-6)


def test_nan_and_bad_input():
    assert np.isnan(h_function(np.nan, 0.5))
    with pytest.raises(ValueError, match=r"omega = 1.1 .*\[0, 1\]"):
        h_function(0.5, 1.1)
    with pytest.raises(ValueError, match=r"omega = -0.1"):
        characteristic_roots(-0.1)
    with pytest.raises(ValueError, match="order"):
        h_function(0.5, 0.5, order=0)
