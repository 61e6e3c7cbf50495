"""Radiometric relations (Forsyth & Ponce ch. 2) and the physical-law checks."""
from __future__ import annotations

import numpy as np
import pytest

from gonio import radiometry as rad


def test_radiance_brdf_round_trip():
    """L = f E0 cos(theta_i) and back (Forsyth & Ponce 2.2.2; Oren & Nayar section 2)."""
    L = rad.radiance_from_brdf(0.2, 100.0, 60.0)
    assert L == pytest.approx(0.2 * 100.0 * 0.5, rel=1e-14)
    assert rad.brdf_from_radiance(L, 100.0, 60.0) == pytest.approx(0.2, rel=1e-14)


def test_brdf_from_radiance_rejects_grazing_incidence():
    with pytest.raises(ValueError, match="theta_i must be below 90"):
        rad.brdf_from_radiance(1.0, 1.0, 90.0)


def test_lambertian_radiance_and_radiosity():
    """A Lambertian surface of albedo rho lit by E0 has radiosity rho E0 cos(theta_i):
    B = pi L (Forsyth & Ponce 2.3.1) with L = rho/pi E0 cos(theta_i) (2.3.3)."""
    L = rad.lambertian_radiance(0.7, 3.0, 30.0)
    assert rad.radiosity_of_constant_radiance(L) == pytest.approx(0.7 * 3.0 * np.cos(np.radians(30.0)), rel=1e-14)


@pytest.mark.parametrize("theta_i", [0.0, 30.0, 75.0, 89.9])
def test_rho_dh_of_lambert_is_its_albedo(theta_i):
    """Forsyth & Ponce 2.3.3: rho_d = pi * (rho/pi) for every incidence."""
    # Gauss-Legendre integrates cos*sin exactly up to rounding on each panel.
    assert rad.directional_hemispherical_reflectance("lambert", theta_i, rho=0.37) == pytest.approx(0.37, abs=1e-13)


def test_rho_dh_of_minnaert_matches_closed_form():
    """Minnaert: rho_dh = rho cos(theta_i)^(k - 1) (integrating Oren & Nayar's eq of section 1)."""
    theta = np.array([0.0, 30.0, 60.0])
    expected = 0.8 * np.cos(np.radians(theta)) ** (0.6 - 1.0)
    got = rad.directional_hemispherical_reflectance("minnaert", theta, rho=0.8, k=0.6)
    # cos^k(theta_r) with k = 0.6 has an infinite derivative at the horizon, so Gauss-
    # Legendre converges only algebraically there: order 24 per panel measured 1.1e-5
    # relative; 3e-5 leaves margin while still catching any wrong factor or exponent.
    np.testing.assert_allclose(got, expected, rtol=3e-5)


def test_rho_dh_of_phong_is_rho_s_at_normal_incidence():
    """The (n+2)/(2 pi) normalisation of gonio.models.phong makes rho_dh(0) = rho_s."""
    value = rad.directional_hemispherical_reflectance("phong", 0.0, order=48, rho_s=0.3, exponent=10.0)
    assert value == pytest.approx(0.3, rel=1e-8)


def test_rho_dh_accepts_plain_callables_and_validates_order():
    f = lambda ti, pi_, tr, pr: np.full(np.broadcast(ti, pi_, tr, pr).shape, 0.5 / np.pi)
    assert rad.directional_hemispherical_reflectance(f, 20.0) == pytest.approx(0.5, abs=1e-13)
    with pytest.raises(ValueError, match="order"):
        rad.directional_hemispherical_reflectance("lambert", 20.0, order=0)
    with pytest.raises(ValueError, match="rho = 2"):
        rad.directional_hemispherical_reflectance("lambert", 20.0, rho=2.0)


def test_reciprocity_violation_detects_a_non_reciprocal_function():
    def lopsided(ti, pi_, tr, pr):
        return np.cos(np.radians(ti)) ** 2 * np.ones_like(np.asarray(tr, float))

    v = rad.reciprocity_violation(lopsided, [10.0, 60.0], 0.0, [60.0, 10.0], 180.0)
    assert v and v.worst == pytest.approx(1 - np.cos(np.radians(60)) ** 2 / np.cos(np.radians(10)) ** 2)
    assert not rad.reciprocity_violation("lambert", [10.0, 60.0], 0.0, [60.0, 10.0], 180.0)


def test_energy_bound_violation_detects_excess_and_passes_lambert():
    assert not rad.energy_bound_violation("lambert", rho=1.0)
    too_bright = lambda ti, pi_, tr, pr: np.full(np.broadcast(ti, pi_, tr, pr).shape, 1.2 / np.pi)
    v = rad.energy_bound_violation(too_bright)
    assert v.worst == pytest.approx(0.2, abs=1e-12)


@pytest.mark.parametrize("name", ["phong", "lambert+phong"])
def test_phong_energy_within_bound_for_albedos_summing_to_one(name):
    """Measured: the normalised Phong lobe never exceeds rho_s (see docs/models.md)."""
    params = {"rho_s": 0.2, "exponent": 5.0} | ({"rho": 0.8} if name == "lambert+phong" else {})
    assert not rad.energy_bound_violation(name, np.linspace(0, 89, 30), order=32, **params)
