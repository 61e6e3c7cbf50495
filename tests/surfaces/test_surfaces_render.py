"""The path tracer against the papers: Oren & Nayar 1995 (eq 28-32, 40-45, App. A),
Koenderink et al. 1999 (eq 3-13), energy, reciprocity and honest error bars.

Tolerances are Monte Carlo errors: a rendered value agrees with a closed form when it is
within 4.5 of its own standard errors (a false alarm once in ~1.5e5 comparisons of a
Gaussian estimate), and every comparison also asserts that the standard error is small
enough (a resolution in percent) for the check to be able to fail.  Path counts keep each
test to about a second.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import gonio
from gonio.models.oren_nayar.exact import exact_components
from gonio.models.oren_nayar.single_slope import (
    in_plane_direct_radiance,
    isotropic_brdf_terms,
    perpendicular_direct_radiance,
    unidirectional_radiance,
)
from gonio.models.pitted.interreflection import diffuse_radiance_series, pit_albedo
from gonio.models.pitted.model import pitted_terms
from gonio.surfaces import HeightField, PittedPlane, VGroove, VGrooveField, render, render_albedo
from gonio.surfaces.kernel import sample_gaussian_slopes, uniform_numbers
from gonio.surfaces.shapes import rms_slope_angle

#: Agreement within this many standard errors (module notes).
Z = 4.5
R = np.radians


def _agrees(value, error, expected, resolution):
    """|value - expected| < Z errors, and the error below ``resolution`` of the value.

    Where every path gives the same number (a view that sees only a fully lit part of a
    groove, at one bounce) the error is 0, and the rounding of a sum of 2e5 equal values
    (~1e-12 relative) is allowed: 1e-10.
    """
    value, error, expected = (np.asarray(a, float) for a in (value, error, expected))
    assert np.all(error < resolution * np.abs(expected)), (error, expected)
    assert np.all(np.abs(value - expected) <= Z * error + 1e-10 * np.abs(expected)), (value - expected, error)


# --------------------------------------------------------------------------- V-grooves
GROOVE_CASES = [  # (theta_i, phi_i, theta_r, phi_r, theta_a, phi_a): shadowing, masking, both
    (60.0, 0.0, 30.0, 180.0, 40.0, 20.0),
    (70.0, 0.0, 60.0, 10.0, 50.0, 100.0),
    (30.0, 0.0, 80.0, 180.0, 30.0, 0.0),
    (80.0, 40.0, 75.0, 45.0, 35.0, 30.0),
]


@pytest.mark.parametrize("ti,pi_,tr,pr,ta,pa", GROOVE_CASES)
def test_aligned_grooves_reproduce_eq28_at_one_and_two_bounces(ti, pi_, tr, pr, ta, pa):
    # eq 28: the mean of the two facets' projected radiances, Table 1 (GAF, eq 15) for the
    # direct light and eq 23-26 (exact two-bounce interreflection of the long cavity)
    rho = 0.8
    rendered = render(VGroove(ta, pa, rho), ti, pi_, tr, pr, paths=200_000, seed=1, bounces=2)
    angles = (R(ti), R(pi_), R(tr), R(pr), R(ta), R(pa))
    direct = unidirectional_radiance(*angles, rho=rho, interreflection=False) / math.cos(R(ti))
    both = unidirectional_radiance(*angles, rho=rho) / math.cos(R(ti))
    _agrees(rendered.cumulative[0], rendered.cumulative_error[0], direct, 0.01)
    _agrees(rendered.cumulative[1], rendered.cumulative_error[1], both, 0.01)


@pytest.mark.parametrize("ti,tr,same_side,ta", [(60.0, 30.0, True, 40.0), (75.0, 50.0, False, 30.0),
                                                (20.0, 70.0, True, 60.0), (45.0, 45.0, False, 50.0)])
def test_isotropic_single_slope_direct_light_is_eq40_41_in_the_plane(ti, tr, same_side, ta):
    # Appendix A, eq 40 (phi_r = phi_i) and eq 41 (phi_r = phi_i + pi): exact closed forms
    rho = 0.7
    rendered = render(VGroove(ta, None, rho), ti, 0.0, tr, 0.0 if same_side else 180.0, paths=200_000, seed=2,
                      bounces=1)
    expected = in_plane_direct_radiance(R(ti), R(tr), R(ta), same_side, rho=rho) / math.cos(R(ti))
    _agrees(rendered.value, rendered.standard_error, expected, 0.01)


@pytest.mark.parametrize("ti,tr,ta", [(60.0, 40.0, 45.0), (80.0, 70.0, 30.0)])
def test_isotropic_single_slope_direct_light_is_eq42_43_perpendicular(ti, tr, ta):
    # eq 42 (shadow and mask apart) and eq 43 (they overlap: A_3 > 0), phi_r = phi_i + pi/2
    rho = 0.7
    rendered = render(VGroove(ta, None, rho), ti, 0.0, tr, 90.0, paths=200_000, seed=3, bounces=1)
    expected = perpendicular_direct_radiance(R(ti), R(tr), R(ta), rho=rho) / math.cos(R(ti))
    _agrees(rendered.value, rendered.standard_error, expected, 0.01)


@pytest.mark.parametrize("ti,tr,dphi,ta", [(60.0, 30.0, 135.0, 40.0), (70.0, 65.0, 20.0, 55.0)])
def test_isotropic_single_slope_two_bounces_is_eq29_46(ti, tr, dphi, ta):
    # eq 29 and 46: the azimuthal average of the exact facet terms (Table 1, eq 23-26)
    rho = 0.9
    rendered = render(VGroove(ta, None, rho), ti, 0.0, tr, dphi, paths=200_000, seed=4, bounces=2)
    h1, h2 = isotropic_brdf_terms(math.cos(R(ti)), math.sin(R(ti)), math.cos(R(tr)), math.sin(R(tr)), R(dphi),
                                  math.cos(R(ta)), math.sin(R(ta)), order=12)
    _agrees(rendered.cumulative[0], rendered.cumulative_error[0], rho * h1, 0.01)
    _agrees(rendered.cumulative[1], rendered.cumulative_error[1], rho * h1 + rho**2 * h2, 0.01)


@pytest.mark.parametrize("ti,pi_,tr,pr,sigma", [
    (45.0, 0.0, 30.0, 180.0, 30.0),   # forward, in the plane
    (75.0, 0.0, 40.0, 0.0, 20.0),     # backward (Fig 10's peak side)
    (60.0, 10.0, 70.0, 100.0, 40.0),  # out of the plane
    (85.0, 0.0, 80.0, 5.0, 10.0),     # grazing, near retro-reflection
])
def test_gaussian_groove_field_at_two_bounces_is_oren_nayar_exact(ti, pi_, tr, pr, sigma):
    # eq 31-32 with eq 8, 15, 22-24: oren-nayar-exact integrates the same groove
    # population (its slope-area distribution) with the two-bounce interreflection
    rho = 0.9
    rendered = render(VGrooveField(sigma, rho), ti, pi_, tr, pr, paths=300_000, seed=5, bounces=2)
    f1, f2 = exact_components(ti, pi_, tr, pr, sigma)
    _agrees(rendered.cumulative[0], rendered.cumulative_error[0], rho * f1, 0.01)
    _agrees(rendered.cumulative[1], rendered.cumulative_error[1], rho * f1 + rho**2 * f2, 0.01)


def test_more_bounces_add_light_to_the_groove_field():
    # section 4.1.2 truncates at two bounces; the rest is positive and, at rho = 0.9 and
    # sigma = 30 deg, a few percent of the total (measured: docs/surfaces.md)
    rendered = render(VGrooveField(30.0, 0.9), 45.0, 0.0, 30.0, 180.0, paths=200_000, seed=6)
    extra = rendered.orders[2]
    assert extra == pytest.approx(rendered.cumulative[2] - rendered.cumulative[1], rel=1e-12)
    assert 10 * rendered.order_error[2] < extra < 0.15 * rendered.value


def test_slope_sampler_follows_the_distribution_of_oren_nayar_exact():
    # eq 32 with gonio's normalisation: the mean square slope of 2e5 draws equals the
    # quadrature of exact.py's density (rms_slope_angle); 5 standard errors of the mean
    for sigma in (5.0, 30.0, 70.0):
        draws = np.degrees(sample_gaussian_slopes(math.radians(sigma), 200_000, np.uint64(9)))
        assert draws.min() >= 0.0 and draws.max() <= 90.0
        mean_square = np.mean(draws**2)
        error = np.std(draws**2) / math.sqrt(draws.size)
        assert abs(mean_square - rms_slope_angle(sigma) ** 2) < 5 * error


def test_a_flat_surface_is_lambert_exactly():
    # footnote 10: sigma = 0 is Lambert; every path gives rho/pi
    rendered = render(VGrooveField(0.0, 0.6), [0.0, 50.0, 89.0], 0.0, [80.0, 10.0, 45.0], 180.0, paths=500)
    assert np.allclose(rendered.value, 0.6 / np.pi, rtol=1e-14)
    assert np.all(rendered.standard_error < 1e-12)


def test_height_field_seen_and_lit_from_the_normal_is_the_mean_facet_cosine():
    # lit and seen along the mean normal, nothing is shadowed or masked: the direct light
    # is rho/pi times the projected-area mean of the facet cosines n_z (eq 8 with
    # GAF = 1 and eq 10 at s = v = n), known exactly for the triangulated realisation
    from gonio.surfaces.estimator import kernel_inputs
    from gonio.surfaces.heightfield import facet_slopes

    surface = HeightField(35.0, 0.8, cells=128, correlation=6.0)
    _, _, heights, _ = kernel_inputs(surface)
    b, c = facet_slopes(heights)
    expected = 0.8 / np.pi * np.mean(1.0 / np.sqrt(1.0 + b**2 + c**2))
    rendered = render(surface, 0.0, 0.0, 0.0, 0.0, paths=200_000, seed=13, bounces=1)
    _agrees(rendered.value, rendered.standard_error, expected, 0.005)
    assert expected < 0.97 * 0.8 / np.pi  # the facets' tilt is resolved


# --------------------------------------------------------------------------- pits
PIT_CASES = [(30.0, 10.0, 0.0, 90.0), (60.0, 30.0, 180.0, 90.0), (45.0, 60.0, 70.0, 45.0), (70.0, 50.0, 120.0, 20.0)]


@pytest.mark.parametrize("ti,tr,eps,psi", PIT_CASES)
def test_pits_at_one_bounce_are_the_pitted_single_scattering(ti, tr, eps, psi):
    # eq 14-15 with eq 5: (1 - c) rho/pi + c rho F1, the pitted model without eq 12
    rho, coverage = 0.9, 0.6
    rendered = render(PittedPlane(psi, coverage, rho), ti, 0.0, tr, eps, paths=200_000, seed=7, bounces=1)
    terms = pitted_terms(ti, 0.0, tr, eps, psi)
    expected = (1 - coverage) * rho / np.pi + coverage * rho * terms.single_scattering
    _agrees(rendered.value, rendered.standard_error, expected, 0.01)


@pytest.mark.parametrize("ti,tr,eps,psi", PIT_CASES)
def test_pits_with_all_bounces_are_the_closed_form_interreflection(ti, tr, eps, psi):
    # eq 3-13: in a sphere the interreflected irradiance is uniform (eq 11), so the exact
    # all-bounce BRDF is the pitted model; two bounces keep the first term of eq 13
    rho, coverage = 0.9, 0.6
    rendered = render(PittedPlane(psi, coverage, rho), ti, 0.0, tr, eps, paths=200_000, seed=8)
    expected = gonio.brdf("pitted", ti, 0.0, tr, eps, rho=rho, psi=psi, coverage=coverage)
    _agrees(rendered.value, rendered.standard_error, expected, 0.01)
    terms = pitted_terms(ti, 0.0, tr, eps, psi)
    two = (1 - coverage) * rho / np.pi + coverage * (rho * terms.single_scattering
                                                     + diffuse_radiance_series(rho, psi, orders=1))
    _agrees(rendered.cumulative[1], rendered.cumulative_error[1], two, 0.01)


def test_hemispherical_pits_forward_of_the_shadow_see_only_interreflection():
    # eq 30: alpha + beta > 90 deg in the forward plane, only the shadowed part of the pit
    # is seen: the BRDF is D = rho^2 / (2 pi (2 - rho)) and direct light gives 0
    rho = 0.8
    rendered = render(PittedPlane(90.0, 1.0, rho), 60.0, 0.0, 50.0, 180.0, paths=100_000, seed=9)
    assert rendered.cumulative[0] == 0.0
    _agrees(rendered.value, rendered.standard_error, rho**2 / (2 * np.pi * (2 - rho)), 0.01)


@pytest.mark.parametrize("psi", [90.0, 35.0])
def test_pit_albedo_is_the_escaping_fraction_of_eq9_10(psi):
    # the flux entering a pit that leaves it: rho cos^2(psi/2) / (1 - rho sin^2(psi/2))
    rho = 0.7
    albedo = render_albedo(PittedPlane(psi, 1.0, rho), 40.0, paths=100_000, seed=10)
    _agrees(albedo.value, albedo.standard_error, pit_albedo(rho, psi), 0.01)
    # single scattering escapes with the view factor of the missing cap, which in a sphere
    # is its share of the sphere's area, cos^2(psi/2) (eq 3, 10): rho cos^2(psi/2)
    _agrees(albedo.orders[0], albedo.order_error[0], rho * np.cos(np.radians(psi) / 2) ** 2, 0.01)


# --------------------------------------------------------------------------- every kind
SURFACES = {
    "groove": VGroove(50.0, 20.0, 1.0),
    "isotropic groove": VGroove(50.0, None, 1.0),
    "groove field": VGrooveField(30.0, 1.0),
    "height field": HeightField(30.0, 1.0, cells=128, correlation=6.0),
    "pits": PittedPlane(60.0, 0.7, 1.0),
}


@pytest.mark.parametrize("name", SURFACES)
@pytest.mark.parametrize("theta_i", [20.0, 65.0])
def test_nothing_is_absorbed_at_unit_albedo(name, theta_i):
    # rho = 1, all bounces: the directional-hemispherical reflectance is 1 (Forsyth &
    # Ponce ch. 2): camera sampling, shadow rays, bounces and escapes all have to be right
    albedo = render_albedo(SURFACES[name], theta_i, phi_i=15.0, paths=60_000, seed=11)
    assert albedo.standard_error < 0.01
    assert abs(albedo.value - 1.0) < Z * albedo.standard_error
    assert albedo.orders.sum() == pytest.approx(albedo.value, rel=1e-12)


@pytest.mark.parametrize("name", SURFACES)
def test_renders_are_reciprocal(name):
    # Helmholtz reciprocity of Lambertian facets: f(s, v) = f(v, s), rendered with
    # independent streams; the difference within 4.5 combined standard errors
    surface = SURFACES[name]
    ti, pi_, tr, pr = np.array([70.0, 30.0, 85.0]), np.array([0.0, 40.0, 10.0]), np.array([40.0, 60.0, 60.0]), \
        np.array([160.0, 100.0, 20.0])
    forward = render(surface, ti, pi_, tr, pr, paths=60_000, seed=12)
    backward = render(surface, tr, pr, ti, pi_, paths=60_000, seed=12)
    combined = np.hypot(forward.standard_error, backward.standard_error)
    assert np.all(combined < 0.03 * forward.value)
    assert np.all(np.abs(forward.value - backward.value) < Z * combined)


@pytest.mark.parametrize("name", SURFACES)
def test_error_bars_describe_the_scatter_of_independent_seeds(name):
    # 40 seeds of 3000 paths: the sample standard deviation of the values over the rms
    # of the stated errors is 1 within its sampling spread (sd ~ 1/sqrt(78) = 0.11 for
    # Gaussian values, more for the skewed per-path sums): the window [0.7, 1.35]
    surface = SURFACES[name].__class__(**{**SURFACES[name].parameters(), "rho": 0.8})
    values, errors = [], []
    for seed in range(40):
        rendered = render(surface, 60.0, 0.0, 45.0, 150.0, paths=3000, seed=100 + seed)
        values.append(float(rendered.value))
        errors.append(float(rendered.standard_error))
    ratio = np.std(values, ddof=1) / np.sqrt(np.mean(np.square(errors)))
    assert 0.7 < ratio < 1.35, ratio


def test_same_seed_same_numbers_other_seed_other_numbers():
    surface = HeightField(20.0, 0.7, cells=64, correlation=4.0)
    a = render(surface, [30.0, 60.0], 0.0, [45.0, 10.0], 180.0, paths=2000, seed=3)
    b = render(surface, [30.0, 60.0], 0.0, [45.0, 10.0], 180.0, paths=2000, seed=3, workers=2)
    c = render(surface, [30.0, 60.0], 0.0, [45.0, 10.0], 180.0, paths=2000, seed=4)
    assert np.array_equal(a.value, b.value) and np.array_equal(a.standard_error, b.standard_error)
    assert not np.any(a.value == c.value)
    # a geometry's numbers do not depend on what else is rendered with it
    alone = render(surface, 60.0, 0.0, 10.0, 180.0, paths=2000, seed=3)
    assert float(alone.value) == a.value[1]


def test_the_renderer_reads_every_accumulator_of_the_kernel():
    from gonio.surfaces import estimator, kernel

    assert estimator.COLUMNS == kernel.ACCUMULATORS


def test_random_stream_is_uniform():
    # SplitMix64: mean 1/2, variance 1/12 of 1e6 numbers within 5 standard errors
    u = uniform_numbers(np.uint64(12345), 1_000_000)
    assert u.min() >= 0.0 and u.max() < 1.0
    assert abs(u.mean() - 0.5) < 5 * math.sqrt(1 / 12 / u.size)
    assert abs(u.var() - 1 / 12) < 5 * math.sqrt(1 / 180 / u.size)


def test_bad_geometry_and_parameters():
    rendered = render(VGrooveField(20.0, 0.5), [95.0, np.nan, 30.0], 0.0, [30.0, 30.0, 100.0], 0.0, paths=100)
    assert rendered.value[0] == 0.0 and np.isnan(rendered.value[1]) and rendered.value[2] == 0.0
    with pytest.raises(ValueError, match=r"sigma \[deg\] = 95 is outside its valid range \[0, 90\]"):
        VGrooveField(95.0, 0.5)
    with pytest.raises(ValueError, match=r"psi \[deg\] = 0 is outside its valid range \(0, 90\]"):
        PittedPlane(0.0, 0.5, 0.5)
    with pytest.raises(ValueError, match=r"theta_a \[deg\] = 90 is outside its valid range \[0, 90\)"):
        VGroove(90.0, None, 0.5)
    with pytest.raises(ValueError, match="paths = 1 must be an integer >= 2"):
        render(VGrooveField(20.0, 0.5), 30.0, 0.0, 30.0, 0.0, paths=1)
    with pytest.raises(ValueError, match="bounces = 0 must be an integer >= 1"):
        render(VGrooveField(20.0, 0.5), 30.0, 0.0, 30.0, 0.0, bounces=0)
