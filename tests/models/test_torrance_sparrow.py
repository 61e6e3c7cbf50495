"""Torrance-Sparrow specular lobe (Oren & Nayar 1995 eq 37) and the combined model (eq 38).

The lobe uses the V-cavity GAF of eq 15-16 with the half vector as facet normal and the
Gaussian slope-area distribution of eq 32 (normalised over the hemisphere), so ks is the
albedo of the mirror facets.  Figures 20-22 give the paper's fitted ks/kd.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

import gonio
from gonio.geometry import half_vector
from gonio.models import torrance_sparrow as ts
from gonio.models.fresnel import fresnel_reflectance
from gonio.models.oren_nayar.vcavity import geometric_attenuation
from gonio.radiometry import directional_hemispherical_reflectance, reciprocity_violation

MODELS = ("torrance-sparrow", "oren-nayar+torrance-sparrow")


def random_geometry(n: int, seed: int = 4):
    rng = np.random.default_rng(seed)
    return (rng.uniform(0, 89, n), rng.uniform(-180, 180, n), rng.uniform(0, 89, n), rng.uniform(-180, 180, n))


def gaussian_c(sigma_deg: float) -> float:
    """Eq 32's c by adaptive quadrature (independent of gonio's Gauss-Legendre panels)."""
    s = math.radians(sigma_deg)
    integral = quad(lambda t: math.exp(-t * t / (2 * s * s)) * math.sin(t), 0, math.pi / 2,
                    points=[s, 3 * s], limit=200, epsabs=0, epsrel=1e-13)[0]
    return 1.0 / (2 * math.pi * integral)


def normal_incidence_m(sigma_deg: float) -> float:
    """M of the normal-incidence albedo, with GAF_0(t) = min(1, 2 cos 2t) written out:
    at normal incidence eq 15 gives shadowing term 2 and masking term 2 cos(2t)."""
    s = math.radians(sigma_deg)
    g = lambda t: math.exp(-t * t / (2 * s * s)) * math.sin(t) * min(1.0, 2 * math.cos(2 * t))
    return 2 * math.pi * sum(quad(g, a, b, epsabs=0, epsrel=1e-13, limit=200)[0]
                             for a, b in ((0, math.pi / 6), (math.pi / 6, math.pi / 4)))


# ------------------------------------------------------------------ eq 37 itself
def test_lobe_is_eq_37_as_a_brdf():
    """Eq 37 as a BRDF: ks F GAF c exp(-theta_a^2/2 sigma^2) / (4 cos ti cos tr cos theta_a),
    rebuilt here from gonio.geometry.half_vector, the V-cavity GAF and an independent c.
    rtol 1e-10: c agrees to ~1e-15; the rest is the same arithmetic in another order."""
    ti, pi_, tr, pr = random_geometry(400)
    theta_a, phi_a = half_vector(ti, pi_, tr, pr)
    gaf = geometric_attenuation(*np.radians([ti, pi_, tr, pr, theta_a, phi_a]))
    cos_d = np.cos(np.radians(0.5 * gonio.geometry.angle_between(ti, pi_, tr, pr)))
    sigma = 12.0
    lobe = gaussian_c(sigma) * np.exp(-np.radians(theta_a) ** 2 / (2 * math.radians(sigma) ** 2))
    expected = 0.3 * fresnel_reflectance(cos_d, 1.7) * gaf * lobe / (
        4 * np.cos(np.radians(ti)) * np.cos(np.radians(tr)) * np.cos(np.radians(theta_a)))
    got = gonio.brdf("torrance-sparrow", ti, pi_, tr, pr, ks=0.3, sigma_s=sigma, n=1.7, fresnel="dielectric")
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-300)


@pytest.mark.parametrize("sigma", [0.5, 5.0, 20.0, 42.0, 90.0])
def test_slope_area_normalisation_is_eq_32(sigma):
    """Eq 32: 1/c = int over the hemisphere of exp(-theta^2/2 sigma^2); gonio's panels vs
    scipy's adaptive quad, rtol 1e-12 (both converge to ~1e-15)."""
    assert ts.slope_area_normalisation(sigma) == pytest.approx(gaussian_c(sigma), rel=1e-12)
    assert ts.normal_incidence_albedo(sigma) == pytest.approx(gaussian_c(sigma) * normal_incidence_m(sigma), rel=1e-12)


def test_peak_at_the_specular_direction_for_small_roughness():
    """Section 5 after eq 37: the lobe peaks close to the specular direction and widens
    with sigma.  For sigma_s = 2 deg the in-plane maximum lies beyond the mirror direction
    by the Torrance-Sparrow off-specular shift: maximising exp(-(dtheta/2)^2/(2 s^2)) /
    cos(theta_r) gives dtheta = 4 s^2 tan(theta_i) [rad] (0.05, 0.20, 0.48 deg here).
    Tolerance 0.02 deg: grid step 0.005 deg plus the neglected cos(theta_a) and GAF
    terms (measured residual <= 0.012 deg).  The half-maximum width grows with sigma_s."""
    view = np.arange(0.0, 89.0, 0.005)
    for theta_i in (10.0, 35.0, 60.0):
        values = gonio.brdf("torrance-sparrow", theta_i, 0.0, view, 180.0, sigma_s=2.0)
        shift = np.degrees(4 * math.radians(2.0) ** 2 * math.tan(math.radians(theta_i)))
        assert view[np.argmax(values)] - theta_i == pytest.approx(shift, abs=0.02)
        # on the source side the lobe only falls off from the normal; at the retro
        # direction the half vector is tilted by theta_i >= 5 sigma_s: exp(-12.5) = 4e-6
        retro = gonio.brdf("torrance-sparrow", theta_i, 0.0, theta_i, 0.0, sigma_s=2.0)
        assert retro < 1e-5 * values.max()
    widths = []
    for sigma in (2.0, 5.0, 10.0):
        values = gonio.brdf("torrance-sparrow", 30.0, 0.0, view, 180.0, sigma_s=sigma)
        widths.append(np.ptp(view[values >= 0.5 * values.max()]))
    assert widths[0] < widths[1] < widths[2]
    # a Gaussian in theta_a = |theta_r - theta_i| / 2 has FWHM 2 * 2.355 sigma in theta_r
    assert widths[1] == pytest.approx(2 * 2.3548 * 5.0, rel=0.1)


def test_fresnel_option_multiplies_by_the_fresnel_factor():
    """Eq 37's F(n): with fresnel='dielectric' the lobe is the F = 1 lobe times the
    Fresnel reflectance at the angle between source and facet normal (WNO eq 2); at the
    mirror direction that angle is theta_i, at normal incidence F = ((n-1)/(n+1))^2."""
    ti, pi_, tr, pr = random_geometry(300, seed=9)
    unity = gonio.brdf("torrance-sparrow", ti, pi_, tr, pr, sigma_s=30.0)
    dielectric = gonio.brdf("torrance-sparrow", ti, pi_, tr, pr, sigma_s=30.0, n=1.5, fresnel="dielectric")
    cos_d = np.cos(np.radians(0.5 * gonio.geometry.angle_between(ti, pi_, tr, pr)))
    np.testing.assert_allclose(dielectric, unity * fresnel_reflectance(cos_d, 1.5), rtol=1e-12, atol=1e-300)
    mirror = [gonio.brdf("torrance-sparrow", 40.0, 0.0, 40.0, 180.0, sigma_s=5.0, fresnel=f) for f in ("unity", "dielectric")]
    assert mirror[1] / mirror[0] == pytest.approx(float(fresnel_reflectance(np.cos(np.radians(40.0)), 1.5)), rel=1e-12)
    normal = [gonio.brdf("torrance-sparrow", 0.0, 0.0, 0.0, 0.0, n=2.0, fresnel=f) for f in ("unity", "dielectric")]
    assert normal[1] / normal[0] == pytest.approx((1.0 / 3.0) ** 2, rel=1e-12)


# ------------------------------------------------------------------ energy
@pytest.mark.parametrize("sigma, rtol", [(5.0, 1e-8), (20.0, 2e-4), (45.0, 2e-4)])
def test_energy_at_normal_incidence_is_ks_times_normal_incidence_albedo(sigma, rtol):
    """The normalisation claim (module notes): rho_dh(0) = ks c M(sigma_s) with F = 1,
    i.e. ks for narrow lobes.  Tolerances: quadrature error of the rho_dh rule, measured
    6.5e-11 at 5 deg and 4.2e-5 at 20 and 45 deg, where the GAF kink at theta_r = 60 deg is
    not a panel edge (it converges only algebraically)."""
    rho = directional_hemispherical_reflectance("torrance-sparrow", 0.0, order=48, ks=0.6, sigma_s=sigma)
    expected = 0.6 * gaussian_c(sigma) * normal_incidence_m(sigma)
    assert float(rho) == pytest.approx(expected, rel=rtol)
    if sigma == 5.0:
        assert float(rho) == pytest.approx(0.6, rel=1e-8)  # narrow lobe: exactly ks


@pytest.mark.parametrize("sigma", [20.0, 45.0, 90.0])
def test_lobe_never_reflects_more_than_ks(sigma):
    """Energy (Forsyth & Ponce 2.2.2): mirror facets of albedo ks with the eq 32
    distribution reflect at most ks.  Measured (docs/models.md): rho_dh rises from
    c M at normal incidence towards ks at grazing (0.9995 ks at 89.9 deg).  Margin 1e-4:
    the quadrature error measured at these points (order 48 vs 96) is <= 2e-5."""
    thetas = np.array([0.0, 30.0, 60.0, 80.0, 89.0])
    rho = directional_hemispherical_reflectance("torrance-sparrow", thetas, order=48, ks=1.0, sigma_s=sigma)
    assert np.all(rho <= 1.0 + 1e-4)
    # it is lowest near normal incidence (a 5e-4 dip to 30 deg at sigma_s = 20 deg) and
    # approaches ks towards grazing
    assert np.all(rho[2:] > rho[0]) and rho[-1] > 0.95


# ------------------------------------------------------------------ eq 38 and the paper's ratios
def test_combined_model_is_kd_diffuse_plus_ks_specular():
    """Eq 38: kd L_d + ks L_s, with L_d the functional approximation (eq 33-35)."""
    ti, pi_, tr, pr = random_geometry(300, seed=12)
    kw = dict(sigma_s=15.0, n=1.4, fresnel="dielectric")
    combined = gonio.brdf("oren-nayar+torrance-sparrow", ti, pi_, tr, pr, rho=0.7, sigma=25.0, kd=0.6, ks=0.3, **kw)
    diffuse = gonio.brdf("oren-nayar", ti, pi_, tr, pr, rho=0.7, sigma=25.0)
    specular = gonio.brdf("torrance-sparrow", ti, pi_, tr, pr, ks=0.3, **kw)
    np.testing.assert_allclose(combined, 0.6 * diffuse + specular, rtol=1e-12)


@pytest.mark.parametrize("sample, sigma, rho, ratio", [
    ("foam, Fig. 20", 20.0, 0.8, 0.019),
    ("cotton towel, Fig. 21", 42.0, 0.75, 0.085),
    ("wood shavings, Fig. 22", 26.0, 0.7, 0.043),
])
def test_paper_ks_over_kd_maps_to_four_times_gonio_ratio(sample, sigma, rho, ratio):
    """Figs 20-22 report ks/kd of eq 38 in the paper's radiance formulation, where eq 37
    has no factor 1/4 and no E_0.  The paper's BRDF, kd f_ON + ks F GAF c exp(.) /
    (cos ti cos tr cos theta_a) with F = 1 and one sigma, equals gonio's combined model
    with ks_gonio / kd = ks_over_kd_from_paper(ratio) = 4 ratio.  rtol 1e-9: c agrees to
    1e-15, the rest is the same arithmetic."""
    ti, pi_, tr, pr = random_geometry(300, seed=int(sigma))
    kd = 1.0
    theta_a, phi_a = half_vector(ti, pi_, tr, pr)
    gaf = geometric_attenuation(*np.radians([ti, pi_, tr, pr, theta_a, phi_a]))
    paper_specular = ratio * kd * gaf * gaussian_c(sigma) * np.exp(-np.radians(theta_a) ** 2 / (2 * math.radians(sigma) ** 2)) / (
        np.cos(np.radians(ti)) * np.cos(np.radians(tr)) * np.cos(np.radians(theta_a)))
    paper = kd * gonio.brdf("oren-nayar", ti, pi_, tr, pr, rho=rho, sigma=sigma) + paper_specular
    ks = float(ts.ks_over_kd_from_paper(ratio)) * kd
    assert ks == pytest.approx(4 * ratio, rel=1e-15)
    got = gonio.brdf("oren-nayar+torrance-sparrow", ti, pi_, tr, pr, rho=rho, sigma=sigma, kd=kd, ks=ks, sigma_s=sigma)
    np.testing.assert_allclose(got, paper, rtol=1e-9)


def test_paper_fits_normal_incidence_specular_reflectance():
    """Documented numbers (docs/models.md): the specular reflectance at normal incidence of
    the paper's fits, 4 ratio c M(sigma), is 0.063, 0.138, 0.115 (x kd) for foam, towel,
    wood shavings (rounded to 3 digits, hence abs 5e-4)."""
    for sigma, ratio, documented in ((20.0, 0.019, 0.063), (42.0, 0.085, 0.138), (26.0, 0.043, 0.115)):
        value = float(ts.ks_over_kd_from_paper(ratio)) * ts.normal_incidence_albedo(sigma)
        assert value == pytest.approx(documented, abs=5e-4)


# ------------------------------------------------------------------ reciprocity
@settings(max_examples=60, deadline=None)
@given(ti=st.floats(0.0, 90.0), pi_=st.floats(-180.0, 180.0), tr=st.floats(0.0, 90.0), pr=st.floats(-180.0, 180.0),
       sigma_s=st.floats(0.5, 90.0), n=st.floats(1.01, 3.0), fresnel=st.sampled_from(["unity", "dielectric"]),
       sigma=st.floats(0.0, 90.0))
def test_reciprocity(ti, pi_, tr, pr, sigma_s, n, fresnel, sigma):
    """Helmholtz reciprocity of eq 37 and eq 38: the half vector (s + v), the GAF (min over
    source and viewer), F(<s,h>) = F(<v,h>) and cos ti cos tr are symmetric expressions,
    evaluated with commutative float operations, so the swap is exact to rounding (1e-12)."""
    for name, extra in (("torrance-sparrow", {}), ("oren-nayar+torrance-sparrow", {"sigma": sigma})):
        violation = reciprocity_violation(name, ti, pi_, tr, pr, sigma_s=sigma_s, n=n, fresnel=fresnel, **extra)
        assert violation.worst < 1e-12, (name, violation)


# ------------------------------------------------------------------ bad input and numerics
@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("sigma_s", [1e-3, 10.0, 90.0])
def test_no_warning_at_grazing_normal_and_equal_angles(name, sigma_s):
    """DESIGN.md "Bad input": finite, non-negative, warning-free at theta = 0, 90 and
    theta_i == theta_r (the lobe diverges like 1/(cos ti cos tr) at the grazing mirror
    direction, but stays finite in floating point)."""
    thetas = np.array([0.0, 1e-12, 30.0, 89.999999, 90.0])
    ti, tr, dphi = (a.ravel() for a in np.meshgrid(thetas, thetas, [0.0, 90.0, 180.0], indexing="ij"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for fresnel in ("unity", "dielectric"):
            values = gonio.brdf(name, ti, 0.0, tr, dphi, sigma_s=sigma_s, fresnel=fresnel)
            assert np.all(np.isfinite(values)) and np.all(values >= 0.0)


@pytest.mark.parametrize("name", MODELS)
def test_nan_in_nan_out(name):
    values = gonio.brdf(name, [np.nan, 30.0, 30.0], [0.0, np.nan, 0.0], [30.0, 30.0, np.nan], 180.0)
    assert np.isnan(values).all()


@pytest.mark.parametrize("name, bad, match", [
    ("torrance-sparrow", {"sigma_s": 0.0}, r"sigma_s = 0 deg is outside its valid range \(0, 90\]"),
    ("torrance-sparrow", {"ks": -0.1}, r"ks = -0.1 - is outside its valid range \[0, 1\]"),
    ("torrance-sparrow", {"n": 1.0}, r"n = 1 - is outside its valid range \(1, inf\)"),
    ("torrance-sparrow", {"fresnel": "schlick"}, r"fresnel = 'schlick' is not one of"),
    ("torrance-sparrow", {"sigma": 10.0}, r"no parameter 'sigma' \(did you mean 'sigma_s'\?\)"),
    ("oren-nayar+torrance-sparrow", {"kd": 1.2}, r"kd = 1.2 - is outside its valid range \[0, 1\]"),
    ("oren-nayar+torrance-sparrow", {"sigma": 100.0}, r"sigma = 100 deg"),
])
def test_bad_parameters_raise_value_error_naming_them(name, bad, match):
    with pytest.raises(ValueError, match=match):
        gonio.brdf(name, 30.0, 0.0, 20.0, 180.0, **bad)
