"""Closed-form interreflection in a spherical pit (Koenderink et al. 1999, eq 3-13)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.models.pitted import interreflection as ir
from gonio.models.pitted.hemispherical import forward_scattering_brdf, forward_scattering_series

albedos = st.floats(0.0, 1.0)
apertures = st.floats(0.5, 90.0)


def test_eq10_mean_primary_irradiance_is_flux_over_cavity_area():
    # eq 10: pi sin^2(psi) / (4 pi sin^2(psi/2)) = cos^2(psi/2); exact identity, rounding only
    psi = np.linspace(1.0, 90.0, 30)
    r = np.radians(psi)
    expected = np.sin(r) ** 2 / (4.0 * np.sin(r / 2.0) ** 2)
    np.testing.assert_allclose(ir.mean_primary_irradiance(psi), expected, rtol=1e-13)
    np.testing.assert_allclose(ir.cavity_area_ratio(psi), 1.0 / expected, rtol=1e-13)


@settings(max_examples=50, deadline=None)
@given(rho=albedos, psi=apertures)
def test_eq8_balance_is_satisfied_by_eq9_and_eq11(rho, psi):
    # eq 8: <H> = <H_prim> + rho <H> sin^2(psi/2); and eq 11 H_diff = <H> - <H_prim>
    s2 = np.sin(np.radians(psi) / 2.0) ** 2
    mean = ir.mean_irradiance(rho, psi)
    assert mean == pytest.approx(ir.mean_primary_irradiance(psi) + rho * mean * s2, rel=1e-12)
    assert ir.diffuse_irradiance(rho, psi) == pytest.approx(
        mean - ir.mean_primary_irradiance(psi), rel=1e-9, abs=1e-15
    )


def test_eq12_diffuse_radiance_of_the_hemisphere_is_eq29_d():
    # eq 12 at psi = 90 deg reduces to D = rho^2 / (2 pi (2 - rho)) (eq 29, eq 30)
    rho = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(ir.diffuse_radiance(rho, 90.0), forward_scattering_brdf(rho), rtol=1e-13)
    assert ir.diffuse_radiance(1.0, 90.0) == pytest.approx(1.0 / (2.0 * np.pi), rel=1e-13)


@pytest.mark.parametrize("orders", [1, 2, 5])
def test_eq13_series_terms_are_scattering_orders(orders):
    # eq 13 truncated after k terms misses exactly the geometric tail rho^(k+2) s^k / (1 - rho s)
    rho, psi = 0.7, 50.0
    s2 = np.sin(np.radians(psi) / 2.0) ** 2
    tail = np.sin(np.radians(psi)) ** 2 / (4 * np.pi) * rho ** (orders + 2) * s2**orders / (1 - rho * s2)
    truncated = ir.diffuse_radiance_series(rho, psi, orders=orders)
    assert ir.diffuse_radiance(rho, psi) - truncated == pytest.approx(tail, rel=1e-10)


def test_eq13_series_starts_with_double_scattering():
    # the series has no rho^0 or rho^1 term: halving rho divides the first term by 4
    assert ir.diffuse_radiance_series(0.5, 70.0, 1) / ir.diffuse_radiance_series(1.0, 70.0, 1) == pytest.approx(0.25)


def test_eq31_series_converges_to_eq30():
    # eq 31 is the series of eq 30 with ratio rho/2; 40 terms at rho = 1 leave 2^-40 ~ 1e-12
    np.testing.assert_allclose(forward_scattering_series(np.array([0.3, 1.0]), 40), forward_scattering_brdf(np.array([0.3, 1.0])), rtol=1e-11)


@settings(max_examples=50, deadline=None)
@given(rho=albedos, psi=apertures)
def test_pit_albedo_is_at_most_rho_and_one_for_white(rho, psi):
    # escaping fraction of the flux entering a pit: rho cos^2(psi/2)/(1 - rho sin^2(psi/2))
    a = float(ir.pit_albedo(rho, psi))
    assert 0.0 <= a <= rho + 1e-15
    assert float(ir.pit_albedo(1.0, psi)) == pytest.approx(1.0, rel=1e-14)


def test_series_rejects_bad_order():
    with pytest.raises(ValueError, match="orders"):
        ir.diffuse_radiance_series(0.5, 30.0, orders=0)
