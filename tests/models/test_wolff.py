"""Wolff's smooth-dielectric diffuse model (Wolff, Nayar & Oren 1998, eq 7 and 8) and the
combined rough/smooth model of eq 9."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

import gonio
from gonio.models import wolff as W
from gonio.models.chandrasekhar import h_function_numerical
from gonio.models.fresnel import fresnel_reflectance, fresnel_transmittance
from gonio.models.oren_nayar.functional import c1, c2, c3
from gonio.radiometry import directional_hemispherical_reflectance, reciprocity_violation

angle = st.floats(0.0, 89.9)
azimuth = st.floats(-180.0, 180.0)
index = st.floats(1.05, 3.0)
OPTIONS = [
    {"scale": "albedo", "fresnel": "exact"},
    {"scale": "albedo", "fresnel": "polynomial"},
    {"scale": "physical", "fresnel": "exact"},
]
DIELECTRICS = np.linspace(1.3, 2.0, 8)


def eq7_literal(theta_i_deg, theta_r_deg, n, scale):
    """Eq 7 divided by L_i cos(theta_i) d omega, written as the paper prints it."""
    ti, tr = np.radians(theta_i_deg), np.radians(theta_r_deg)
    inside = np.arcsin(np.sin(tr) / n)
    return scale * (1.0 - fresnel_reflectance(np.cos(ti), n)) * (1.0 - fresnel_reflectance(np.cos(inside), 1.0 / n))


# ---------------------------------------------------------------------- eq 7
@settings(max_examples=40, deadline=None)
@given(ti=angle, tr=angle, n=index, rho=st.floats(0.0, 1.0))
def test_albedo_mode_is_eq7_with_scale_rho_over_pi(ti, tr, n, rho):
    """Eq 7 as a BRDF: rho/pi (1 - F(theta_i, n)) (1 - F(asin(sin theta_r / n), 1/n)).
    1e-9: same formula; the literal asin/cos route loses a few digits near grazing exit
    (measured 2e-12 at theta_r = 89.5 deg)."""
    value = gonio.brdf("wolff", ti, 0.0, tr, 180.0, rho=rho, n=n)
    assert value == pytest.approx(eq7_literal(ti, tr, n, rho / np.pi), rel=1e-9, abs=1e-300)


@pytest.mark.parametrize("options", OPTIONS)
@settings(max_examples=25, deadline=None)
@given(ti=angle, pi_=azimuth, tr=angle, pr=azimuth, n=index)
def test_reciprocity(options, ti, pi_, tr, pr, n):
    """Helmholtz reciprocity: eq 7 is symmetric in theta_i, theta_r because the exit factor
    equals 1 - F(theta_r, n).  1e-9: equal up to rounding (measured ~1e-16)."""
    assert reciprocity_violation("wolff", ti, pi_, tr, pr, n=n, omega=0.7, **options).worst < 1e-9


@pytest.mark.parametrize("options", OPTIONS)
@settings(max_examples=25, deadline=None)
@given(ti=angle, tr=angle, pi_=azimuth, pr=azimuth)
def test_depends_on_polar_angles_only(options, ti, tr, pi_, pr):
    """Section 3.1, Figs 4-5: the radiance is azimuth independent and symmetric about
    theta_r = 0 (the same on the source side and the far side of the normal)."""
    reference = gonio.brdf("wolff", ti, 0.0, tr, 0.0, **options)
    assert gonio.brdf("wolff", ti, pi_, tr, pr, **options) == pytest.approx(reference, rel=1e-12)
    assert gonio.brdf("wolff", ti, 0.0, tr, 180.0, **options) == pytest.approx(reference, rel=1e-12)


@pytest.mark.parametrize("n", DIELECTRICS)
def test_maximum_at_normal_view_and_monotonic_decrease(n):
    """Section 3.1: for fixed incidence a smooth surface is brightest at theta_r = 0 and
    darkens monotonically with theta_r."""
    tr = np.linspace(0.0, 90.0, 181)
    for ti in (0.0, 30.0, 60.0):
        values = gonio.brdf("wolff", ti, 0.0, tr, 0.0, n=n)
        assert np.all(np.diff(values) <= 1e-15)
        assert values[-1] <= 1e-15  # cos(pi/2) = 6e-17 in floating point


def lambert_deviation(limit_deg: float, n: float, fresnel: str = "exact") -> float:
    """Largest |f(ti, tr)/f(0, 0) - 1| for ti, tr <= limit (Lambert: 0 everywhere)."""
    t = np.linspace(0.0, limit_deg, 51)
    ti, tr = np.meshgrid(t, t)
    ratio = gonio.brdf("wolff", ti, 0, tr, 0, n=n, fresnel=fresnel) / gonio.brdf("wolff", 0, 0, 0, 0, n=n, fresnel=fresnel)
    return float(np.max(np.abs(ratio - 1.0)))


def test_lambert_agreement_below_50_degrees():
    """Section 4: for smooth surfaces Lambert is accurate to about 5 % while theta_i and
    theta_r both stay below 50 deg.  Measured (shape, i.e. up to the scale): the largest
    deviation over n in [1.3, 2.0] is 4.34 % (n = 1.9; 2.4 % at n = 1.3, 3.6 % at n = 1.5).
    Bound 4.5 %: the measured value rounded up, still within the paper's 5 %."""
    deviations = [lambert_deviation(50.0, n) for n in DIELECTRICS]
    assert max(deviations) < 0.045
    assert max(deviations) > 0.04  # the statement is tight: 'about 5 %', not 1 %
    # beyond 50 deg the agreement is lost quickly (section 3.1: darker than Lambert)
    assert min(lambert_deviation(70.0, n) for n in DIELECTRICS) > 0.10


def test_polynomial_fresnel_lambert_deviation_is_larger():
    """With the polynomial Fresnel factor the normalised shape is independent of n
    ((1 - P) = (1 - (2x/pi)^5)/(1 + eps)) and deviates from Lambert by 10.3 % at 50/50 deg:
    the approximation does not reproduce the 5 % statement (recorded in docs/wolff.md)."""
    values = [lambert_deviation(50.0, n, "polynomial") for n in (1.3, 2.0)]
    assert values[0] == pytest.approx(values[1], rel=1e-12)
    # 1 - (1 - (5/9)^5)^2, the exact value at theta_i = theta_r = 50 deg
    assert values[0] == pytest.approx(1.0 - (1.0 - (5.0 / 9.0) ** 5) ** 2, rel=1e-12)


@pytest.mark.parametrize("n", DIELECTRICS)
def test_darker_than_lambert_at_grazing(n):
    """Section 3.1 and Fig. 7: relative to Lambert (constant BRDF) the smooth surface
    darkens towards grazing incidence or viewing and goes to 0 at the horizon.  Measured
    f(85, 0)/f(0, 0): 0.40 at n = 1.5; the bound 0.55 holds for n in [1.3, 2.0]."""
    normal = gonio.brdf("wolff", 0, 0, 0, 0, n=n)
    for ti, tr in ((85.0, 0.0), (0.0, 85.0)):
        assert gonio.brdf("wolff", ti, 0, tr, 0, n=n) / normal < 0.55
    assert gonio.brdf("wolff", 89.999, 0, 30.0, 0, n=n) / normal < 1e-3


def cylinder_profile(n: float, fresnel: str = "exact") -> tuple[np.ndarray, np.ndarray]:
    """Radiance across a cylinder lit at 90 deg to the viewing direction (Figs 8-9):
    at relative orientation psi (angle between normal and viewer), theta_r = psi and the
    source, in the same plane on the lit side, is at theta_i = 90 - psi."""
    psi = np.linspace(0.0, 90.0, 9001)
    theta_i = 90.0 - psi
    radiance = gonio.brdf("wolff", theta_i, 0.0, psi, 180.0, n=n, fresnel=fresnel) * np.cos(np.radians(theta_i))
    return psi, radiance


@pytest.mark.parametrize("n", DIELECTRICS)
def test_smooth_cylinder_peak_near_65_degrees(n):
    """Figs 8-9: under 90-degree illumination the radiance across a smooth cylinder is
    small at the occluding contour and peaks near 65 deg relative orientation, where
    Lambert (cos theta_i = sin psi) rises monotonically to the contour.  Measured peaks:
    64.2-65.7 deg for n in [1.3, 2.0]; bound +-2 deg around 65 (the paper's 'approximately')."""
    psi, radiance = cylinder_profile(n)
    peak = psi[np.argmax(radiance)]
    assert 63.0 < peak < 67.0
    assert radiance[-1] < 1e-12 * radiance.max()
    lambert = np.sin(np.radians(psi))
    assert np.argmax(lambert) == psi.size - 1


def test_polynomial_fresnel_moves_the_cylinder_peak():
    """With the polynomial Fresnel factor the peak sits at 58.7 deg for every n (the shape
    does not depend on eps) - 6 deg off the figure; recorded in docs/wolff.md."""
    for n in (1.3, 2.0):
        psi, radiance = cylinder_profile(n, "polynomial")
        assert psi[np.argmax(radiance)] == pytest.approx(58.7, abs=0.05)


# ---------------------------------------------------------------------- energy
@pytest.mark.parametrize("n", [1.3, 1.5, 2.0])
def test_albedo_mode_reflects_rho_times_the_two_transmittances(n):
    """Albedo scale: rho_dh(theta_i) = rho (1 - F(theta_i, n)) T(n) <= rho, with
    T(n) = 2 int (1 - F) cos sin the hemispherical transmittance (0.908 at n = 1.5).
    Quadrature tolerance 1e-8 (order 48, smooth integrand)."""
    theta = np.array([0.0, 30.0, 60.0, 85.0])
    rho_dh = directional_hemispherical_reflectance("wolff", theta, order=48, rho=1.0, n=n)
    hemispherical, _ = quad(lambda t: 2.0 * fresnel_transmittance(np.cos(t), n) * np.cos(t) * np.sin(t), 0, np.pi / 2, epsabs=1e-13)
    expected = fresnel_transmittance(np.cos(np.radians(theta)), n) * hemispherical
    np.testing.assert_allclose(rho_dh, expected, rtol=1e-8)
    assert np.all(rho_dh <= 1.0)
    if n == 1.5:
        assert hemispherical == pytest.approx(0.908, abs=5e-4)


@pytest.mark.parametrize("n, closure", [(1.3, 1.0202), (1.5, 1.0137), (2.0, 1.0065)])
def test_physical_scale_conserves_energy_for_conservative_scattering(n, closure):
    """Eq 8 with omega = 1: nothing is absorbed, so all light that enters (1 - F(theta_i))
    should come back out.  The model returns rho_dh / (1 - F(theta_i, n)) = 1.020, 1.014,
    1.007 for n = 1.3, 1.5, 2.0: eq 8's single geometric series for internal reflection
    (K at one direction) overestimates by 2 % at most.  Tolerance 5e-4 around the measured
    values; the ratio is the same at every incidence since the scale is constant."""
    theta = np.array([0.0, 45.0, 80.0])
    rho_dh = directional_hemispherical_reflectance("wolff", theta, order=48, scale="physical", omega=1.0, n=n)
    ratio = rho_dh / fresnel_transmittance(np.cos(np.radians(theta)), n)
    np.testing.assert_allclose(ratio, closure, atol=5e-4)


# ---------------------------------------------------------------------- eq 8
def eq8_reference(n: float, omega: float, theta_i: float = 0.0, theta_r: float = 0.0) -> float:
    """Eq 8 evaluated independently: exact H (integral-equation solver) and adaptive
    quadrature for K (split at the critical angle)."""
    def h(x):
        return float(h_function_numerical(x, omega))

    mu_i = np.sqrt(1.0 - np.sin(np.radians(theta_i)) ** 2 / n**2)
    mu_r = np.sqrt(1.0 - np.sin(np.radians(theta_r)) ** 2 / n**2)
    rho_1 = omega / (4.0 * np.pi * n**2) * h(mu_i) * h(mu_r) / (mu_i + mu_r)
    critical = np.sqrt(1.0 - 1.0 / n**2)

    def integrand(x):  # F(phi', 1/n) C(cos phi', mu_r) 2 pi sin phi' dphi' with x = cos phi'
        c = omega / (4.0 * np.pi) * x / (x + mu_r) * h(x) * h(mu_r)
        return float(fresnel_reflectance(x, 1.0 / n)) * c * 2.0 * np.pi

    k = quad(integrand, 0.0, critical, epsabs=1e-12)[0] + quad(integrand, critical, 1.0, epsabs=1e-12, limit=100)[0]
    return rho_1 / (1.0 - k)


@pytest.mark.parametrize("n", [1.3, 1.5, 2.0])
@pytest.mark.parametrize("omega", [0.5, 0.9, 1.0])
def test_physical_scale_against_independent_eq8(n, omega):
    """The model's eq 8 (N = 32 H-function, 2x48-node K rule) against eq 8 with the exact
    H and adaptive quadrature.  Measured differences <= 6.6e-4 (n = 2, omega = 1), all from
    the H approximation; bound 1e-3."""
    assert W.physical_scale(n, omega) == pytest.approx(eq8_reference(n, omega), rel=1e-3)


@pytest.mark.parametrize("n", [1.3, 2.0])
def test_k_rule_against_adaptive_quadrature(n):
    """The fixed Gauss rule for K of eq 8 against scipy quad with the same H-function:
    1e-10 (the t^2 substitution makes the integrand smooth; measured ~1e-14)."""
    from gonio.models.chandrasekhar import h_function

    omega, mu_r = 0.8, 0.9
    critical = np.sqrt(1.0 - 1.0 / n**2)

    def integrand(x):
        return float(fresnel_reflectance(x, 1.0 / n) * x * h_function(x, omega) / (x + mu_r))

    total = quad(integrand, 0.0, critical, epsabs=1e-14)[0] + quad(integrand, critical, 1.0, epsabs=1e-14, limit=100)[0]
    expected = 0.5 * omega * float(h_function(mu_r, omega)) * total
    assert W.internal_reflection_integral(mu_r, n, omega) == pytest.approx(expected, rel=1e-10)


def test_k_below_plane_albedo():
    """K < 1: with F = 1 it would be the plane albedo 1 - sqrt(1 - omega) H(mu) <= 1;
    F(., 1/n) < 1 outside total internal reflection makes it smaller."""
    for n in (1.05, 1.5, 3.0):
        k = W.internal_reflection_integral(np.linspace(0.5, 1.0, 6), n, 1.0)
        assert np.all((k > 0.0) & (k < 1.0))


def test_physical_scale_angle_dependence():
    """Eq 8 depends on theta_i, theta_r through mu_inc, mu_ref; the paper treats it as
    constant.  Measured range of rho(ti, tr)/rho(0, 0) over ti, tr in {0, 45, 90} deg:
    omega = 1: [0.968, 1] (n = 1.5); omega = 0.5: [1, 1.30] (n = 1.5).  Recorded in
    docs/wolff.md; tolerance 0.01 on those figures."""
    angles = np.array([0.0, 45.0, 90.0])
    ti, tr = np.meshgrid(angles, angles)
    for omega, low, high in ((1.0, 0.968, 1.0), (0.5, 1.0, 1.30)):
        ratio = W.physical_scale(1.5, omega, ti, tr) / W.physical_scale(1.5, omega)
        assert ratio.min() == pytest.approx(low, abs=0.01)
        assert ratio.max() == pytest.approx(high, abs=0.01)


def test_physical_mode_uses_eq8_scale():
    """scale='physical': BRDF = rho(n, omega) x transmittances, independent of rho; omega = 0
    reflects nothing (no scatterers)."""
    ti, tr = np.array([0.0, 40.0, 70.0]), np.array([10.0, 50.0, 20.0])
    value = gonio.brdf("wolff", ti, 0, tr, 0, scale="physical", n=1.6, omega=0.8, rho=0.1)
    expected = eq7_literal(ti, tr, 1.6, float(W.physical_scale(1.6, 0.8)))
    np.testing.assert_allclose(value, expected, rtol=1e-12)
    assert np.all(gonio.brdf("wolff", ti, 0, tr, 0, scale="physical", omega=0.0) == 0.0)


def test_physical_scale_increases_with_single_scattering_albedo():
    values = [float(W.physical_scale(1.5, omega)) for omega in np.linspace(0.0, 1.0, 11)]
    assert values[0] == 0.0 and np.all(np.diff(values) > 0)


# ---------------------------------------------------------------------- polynomial Fresnel
def test_polynomial_fresnel_relative_error_of_the_brdf():
    """Exact vs polynomial Fresnel in eq 7: relative BRDF error for theta_i, theta_r <= 50
    deg and n in [1.3, 2.0]; measured: the polynomial is darker by up to 8.1 % (n = 1.3),
    6.9 % (n = 1.5), 6.3 % (n = 2.0), and never brighter by more than 1.1e-5 (the
    approximation is exact at normal incidence).  Near grazing both go to 0 at different
    rates.  Bounds around the measured 8.1 %."""
    t = np.linspace(0.0, 50.0, 26)
    ti, tr = np.meshgrid(t, t)
    worst = 0.0
    for n in DIELECTRICS:
        exact = gonio.brdf("wolff", ti, 0, tr, 0, n=n)
        approx = gonio.brdf("wolff", ti, 0, tr, 0, n=n, fresnel="polynomial")
        worst = max(worst, float(np.max(np.abs(approx / exact - 1.0))))
    assert 0.075 < worst < 0.085


# ---------------------------------------------------------------------- eq 9
@settings(max_examples=40, deadline=None)
@given(ti=angle, pi_=azimuth, tr=angle, pr=azimuth, sigma=st.floats(0.0, 60.0), n=index)
def test_combined_model_is_eq3_with_eq9_c1(ti, pi_, tr, pr, sigma, n):
    """Eq 9 in eq 3, composed from the public Oren-Nayar coefficients:
    rho/pi [C1 T + cos(dphi) C2 tan(beta) + (1 - |cos dphi|) C3 tan((alpha + beta)/2)].
    1e-9 relative: same formula, summed in a different order."""
    rho = 0.7
    dphi = pr - pi_
    alpha, beta = np.radians(max(ti, tr)), np.radians(min(ti, tr))
    cos_dphi = np.cos(np.radians(dphi))
    transmittances = eq7_literal(ti, tr, n, 1.0)
    expected = rho / np.pi * (
        c1(sigma) * transmittances
        + cos_dphi * c2(sigma, ti, tr, dphi) * np.tan(beta)
        + (1.0 - abs(cos_dphi)) * c3(sigma, ti, tr) * np.tan(0.5 * (alpha + beta))
    )
    value = gonio.brdf("wolff-oren-nayar", ti, pi_, tr, pr, rho=rho, sigma=sigma, n=n)
    # gonio returns max(eq 9, 0) (see test_combined_model_negative_region)
    assert value == pytest.approx(max(float(expected), 0.0), rel=1e-9, abs=1e-12)


@settings(max_examples=30, deadline=None)
@given(ti=angle, pi_=azimuth, tr=angle, pr=azimuth, n=index)
def test_combined_model_at_zero_roughness_is_wolff(ti, pi_, tr, pr, n):
    """Eq 9 with sigma = 0: C1 = 1, C2 = C3 = 0, the Wolff model with scale rho/pi."""
    combined = gonio.brdf("wolff-oren-nayar", ti, pi_, tr, pr, rho=0.6, sigma=0.0, n=n)
    assert combined == pytest.approx(gonio.brdf("wolff", ti, pi_, tr, pr, rho=0.6, n=n), rel=1e-12)


@settings(max_examples=25, deadline=None)
@given(ti=angle, pi_=azimuth, tr=angle, pr=azimuth, sigma=st.floats(0.0, 60.0))
def test_combined_model_reciprocity(ti, pi_, tr, pr, sigma):
    """Eq 9 keeps eq 3 reciprocal (the transmittance product is symmetric)."""
    assert reciprocity_violation("wolff-oren-nayar", ti, pi_, tr, pr, sigma=sigma).worst < 1e-9


@pytest.mark.parametrize("sigma, onset", [(5.0, 87.1), (20.0, 77.9), (40.0, 69.8)])
def test_combined_model_negative_region(sigma, onset):
    """Eq 9 as printed goes negative in forward scattering near the horizon (C1 T -> 0 while
    the negative C2 tan(beta) term of eq 3 stays); gonio returns 0 there.  Measured onset
    (n = 1.5, dphi = 180, 0.1-deg grid): max(theta_i, theta_r) = 87.1, 77.9, 69.8 deg for
    sigma = 5, 20, 40 deg; tolerance one grid step either side.  Backward scattering
    (dphi = 0) is never clipped."""
    t = np.linspace(0.0, 90.0, 901)
    ti, tr = np.meshgrid(t, t)
    forward = gonio.brdf("wolff-oren-nayar", ti, 0, tr, 180, sigma=sigma)
    zero = forward == 0.0
    first = np.maximum(ti, tr)[zero & (np.maximum(ti, tr) < 90.0)].min()
    assert first == pytest.approx(onset, abs=0.11)
    backward = gonio.brdf("wolff-oren-nayar", ti[:, :-1], 0, tr[:, :-1], 0, sigma=sigma)
    assert np.all(backward[:-1] > 0.0)


def test_combined_model_close_to_wolff_for_smooth_surfaces():
    """Section 4: for sigma < 2.5 deg C1 dominates C2, C3 by 100x, so the combined model is
    the smooth model.  Measured over theta_i, theta_r <= 60 deg: 0.23 % (sigma = 1 deg),
    1.4 % (sigma = 2.5 deg), 5.3 % (sigma = 5 deg)."""
    t = np.linspace(0.0, 60.0, 31)
    ti, tr = np.meshgrid(t, t)
    smooth = gonio.brdf("wolff", ti, 0, tr, 0)
    for sigma, bound in ((1.0, 0.003), (2.5, 0.015)):
        for dphi in (0.0, 180.0):
            rough = gonio.brdf("wolff-oren-nayar", ti, 0, tr, dphi, sigma=sigma)
            assert np.max(np.abs(rough / smooth - 1.0)) < bound


@pytest.mark.parametrize("name, options", [("wolff", o) for o in OPTIONS] + [("wolff-oren-nayar", {"fresnel": "polynomial"})])
def test_fixed_geometry_path_equals_direct_call_for_every_option(name, options):
    """Model.at (fitting's path, geometry precomputed) is the same formula as the plain call,
    also when it reuses the Fresnel terms of a repeated n (the sequence returns to earlier
    indices, so a cache keyed wrongly would give the previous n's values)."""
    model = gonio.models.get(name)
    rng = np.random.default_rng(11)
    ti, tr = rng.uniform(0, 90, 300), rng.uniform(0, 90, 300)
    pi_, pr = rng.uniform(-180, 180, 300), rng.uniform(-180, 180, 300)
    fixed = model.at(ti, pi_, tr, pr, **options)
    for values in ({}, {"n": 1.33}, {"n": 1.33, "rho": 0.5}, {"n": 2.2, "rho": 0.3}, {}, {"n": 1.33}):
        direct = model(ti, pi_, tr, pr, **values, **options)
        np.testing.assert_allclose(fixed(**values), direct, rtol=1e-13, atol=0)


# ---------------------------------------------------------------------- bad input
@pytest.mark.parametrize("name", ["wolff", "wolff-oren-nayar"])
@pytest.mark.parametrize("bad", [1.0, 0.5, -2.0])
def test_index_at_or_below_one_is_rejected(name, bad):
    with pytest.raises(ValueError, match=rf"n = {bad:g} .*\(1, inf\)"):
        gonio.brdf(name, 30, 0, 30, 0, n=bad)


def test_other_bad_input_names_the_parameter():
    with pytest.raises(ValueError, match=r"omega = 1.5 .*\[0, 1\]"):
        gonio.brdf("wolff", 30, 0, 30, 0, scale="physical", omega=1.5)
    with pytest.raises(ValueError, match="option scale = 'lambert'"):
        gonio.brdf("wolff", 30, 0, 30, 0, scale="lambert")
    with pytest.raises(ValueError, match="option fresnel = 'schlick'"):
        gonio.brdf("wolff", 30, 0, 30, 0, fresnel="schlick")
    with pytest.raises(ValueError, match=r"n = 1 .*\(1, inf\)"):
        W.physical_scale(1.0, 0.5)
    with pytest.raises(ValueError, match=r"omega = -0.5"):
        W.physical_scale(1.5, -0.5)


@pytest.mark.parametrize("name, options", [("wolff", o) for o in OPTIONS] + [("wolff-oren-nayar", {}), ("wolff-oren-nayar", {"fresnel": "polynomial"})])
def test_special_geometries_warning_free_and_nan_propagates(name, options):
    """Normal, grazing and theta_i == theta_r geometries give finite values without numpy
    warnings; NaN in gives NaN out; below the horizon is 0."""
    thetas = np.array([0.0, 1e-9, 45.0, 89.999, 90.0])
    ti, tr = np.meshgrid(thetas, thetas)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        values = gonio.brdf(name, ti, 0.0, tr, 180.0, **options)
        odd = gonio.brdf(name, [np.nan, 30.0, 95.0], 0.0, [30.0, np.nan, 30.0], 0.0, **options)
    assert np.all(np.isfinite(values)) and np.all(values >= 0.0)
    assert np.isnan(odd[0]) and np.isnan(odd[1]) and odd[2] == 0.0
    # the Fresnel factors vanish at the horizon (cos(pi/2) = 6e-17 in floating point)
    assert np.all(values[-1, :] <= 1e-15) and np.all(values[:, -1] <= 1e-15)
