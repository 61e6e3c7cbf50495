"""The hemispherical pit: eq 21-31 of Koenderink et al. (1999), against each other and MC."""
from __future__ import annotations

import numpy as np
import pytest

from gonio.models.pitted.hemispherical import (
    aux_f1, aux_f2, aux_f3, aux_f4, forward_scattering_brdf, in_plane_brdf, integral_brdf,
)
from gonio.models.pitted.model import pitted_terms
from gonio.models.pitted.shallow import monte_carlo_brdf


def test_eq22_25_auxiliary_functions_are_tail_integrals():
    # f1..f4 are integrals from t to pi of sin^2 cos, sin^3, sin cos, sin^2 (module docstring);
    # checked by a 60-point Gauss rule, exact to rounding for these entire integrands
    x, w = np.polynomial.legendre.leggauss(60)
    for t in (0.0, 0.4, 1.3, 2.5):
        nodes = t + (np.pi - t) * (x + 1) / 2
        weights = (np.pi - t) / 2 * w
        for f, g in ((aux_f1, np.sin(nodes) ** 2 * np.cos(nodes)), (aux_f2, np.sin(nodes) ** 3),
                     (aux_f3, np.sin(nodes) * np.cos(nodes)), (aux_f4, np.sin(nodes) ** 2)):
            assert f(t) == pytest.approx(np.sum(g * weights), abs=1e-13)


SIGNED = [-85.0, -70.0, -45.0, -20.0, -5.0, 0.0, 5.0, 25.0, 29.0, 31.0, 50.0, 80.0]


@pytest.mark.parametrize("alpha", [0.0, 15.0, 30.0, 45.0, 60.0, 75.0])
def test_eq21_integral_equals_eq26_29_closed_form_in_plane(alpha):
    # Fig 4 curves: the 1-D integral of eq 21 (64-node Gauss panels split at the jump of
    # the visible interval) matches the elementary functions to 1e-12 relative
    signed = np.array(SIGNED)
    single, multiple = integral_brdf(alpha, np.abs(signed), np.where(signed >= 0, 0.0, 180.0), rho=0.8)
    np.testing.assert_allclose(single + multiple, in_plane_brdf(alpha, signed, rho=0.8), rtol=1e-12)


@pytest.mark.parametrize("alpha", [0.0, 30.0, 60.0])
def test_registered_quadrature_equals_eq26_29_in_plane(alpha):
    # the registered model's cap quadrature (default order) vs the closed form: the
    # quadrature converges spectrally; 1e-8 relative leaves room for the default order
    signed = np.array(SIGNED)
    terms = pitted_terms(alpha, 0.0, np.abs(signed), np.where(signed >= 0, 0.0, 180.0), psi=90.0)
    np.testing.assert_allclose(terms.pit_brdf(0.8), in_plane_brdf(alpha, signed, rho=0.8), rtol=1e-8)


@pytest.mark.parametrize("alpha,beta,eps", [(60.0, 40.0, 30.0), (60.0, 70.0, 90.0), (20.0, 50.0, 135.0),
                                            (45.0, 45.0, -60.0), (0.0, 80.0, 10.0)])
def test_eq21_integral_equals_quadrature_off_plane(alpha, beta, eps):
    # Fig 9 (meridional sections): two independent parametrisations of the same integral
    # (polar axis in the surface vs along the normal) agree to 1e-9 relative
    single, multiple = integral_brdf(alpha, beta, eps, rho=1.0)
    terms = pitted_terms(alpha, 0.0, beta, eps, psi=90.0)
    assert float(terms.pit_brdf(1.0)) == pytest.approx(float(single + multiple), rel=1e-9)


def test_eq21_multiple_scattering_term_is_d_everywhere():
    # the second term of eq 21 integrates the constant diffuse radiance over the visible
    # cavity, so it must equal D of eq 29 for every geometry (checks the visible region)
    beta = np.array([0.0, 10.0, 40.0, 70.0, 85.0])
    for eps in (0.0, 45.0, 90.0, 180.0):
        _, multiple = integral_brdf(30.0, beta, eps, rho=0.6)
        np.testing.assert_allclose(multiple, forward_scattering_brdf(0.6), rtol=1e-12)


@pytest.mark.parametrize("alpha,beta", [(30.0, 70.0), (60.0, 35.0), (80.0, 15.0), (45.0, 45.0)])
def test_eq30_forward_scattering_limit(alpha, beta):
    # eq 30: where alpha + |beta| >= 90 deg in the forward direction only shadow is seen,
    # BRDF = rho^2 / (2 pi (2 - rho)); half the Lambertian value for rho = 1
    for rho in (0.3, 1.0):
        assert float(in_plane_brdf(alpha, -beta, rho)) == pytest.approx(float(forward_scattering_brdf(rho)), rel=1e-12)
        terms = pitted_terms(alpha, 0.0, beta, 180.0, psi=90.0)
        assert float(terms.pit_brdf(rho)) == pytest.approx(float(forward_scattering_brdf(rho)), rel=1e-9)
    assert float(forward_scattering_brdf(1.0)) == pytest.approx(0.5 / np.pi, rel=1e-14)


def test_fig4_backscatter_boost_exceeds_lambert():
    # Fig 4 / section 3.2.1: for rho = 1 the hemispherical pit is much lighter than
    # Lambert (1/pi) in retro-reflection at 60 deg (boost of order 1/cos 60 = 2)
    assert float(in_plane_brdf(60.0, 60.0, 1.0)) > 1.7 / np.pi


@pytest.mark.parametrize("signed", [-50.0, -10.0, 10.0, 45.0])
def test_closed_form_agrees_with_monte_carlo_within_its_error(signed):
    # section 4.1 Monte Carlo (fixed seed, 2e5 samples): agreement within 4 standard
    # errors (a 4-sigma band fails by chance with probability 6e-5 per case)
    alpha, rho = 30.0, 0.9
    est = monte_carlo_brdf(alpha, abs(signed), 0.0 if signed >= 0 else 180.0, rho=rho, psi=90.0,
                           samples=200_000, seed=7)
    assert abs(est.value - float(in_plane_brdf(alpha, signed, rho))) < 4.0 * est.standard_error
    assert est.standard_error < 0.01 * est.value  # the check has teeth: SE below 1 %
