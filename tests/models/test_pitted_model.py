"""The registered ``pitted`` model (Koenderink et al. 1999): limits, MC agreement, invariants."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.models.pitted.interreflection import diffuse_brdf, pit_albedo
from gonio.models.pitted.model import PITTED, aperture_mixture_brdf, pitted_terms
from gonio.models.pitted.shallow import monte_carlo_brdf
from gonio.radiometry import directional_hemispherical_reflectance, reciprocity_violation

MC_CASES = [
    # (alpha, beta, epsilon, psi): in-plane backward/forward and off-plane, shallow to deep
    (30.0, 10.0, 0.0, 15.0),
    (60.0, 30.0, 180.0, 30.0),
    (45.0, 60.0, 70.0, 45.0),
    (0.0, 45.0, 0.0, 60.0),
    (70.0, 50.0, 120.0, 75.0),
    (20.0, 80.0, -150.0, 90.0),
]


@pytest.mark.parametrize("alpha,beta,eps,psi", MC_CASES)
def test_section41_monte_carlo_agrees_with_quadrature_within_its_error(alpha, beta, eps, psi):
    # Fig 12 / section 4.1: the Monte Carlo estimate (fixed seed, 1e5 orifice points) and
    # the deterministic quadrature estimate the same integral; 4 standard errors
    rho, coverage = 0.9, 0.7
    est = monte_carlo_brdf(alpha, beta, eps, rho=rho, psi=psi, coverage=coverage, samples=100_000, seed=3)
    exact = float(PITTED(alpha, 0.0, beta, eps, rho=rho, psi=psi, coverage=coverage))
    assert abs(est.value - exact) < 4.0 * est.standard_error + 1e-12
    assert est.standard_error < 0.01 * exact  # 1 % resolution, so the check can fail


def test_monte_carlo_reports_seed_and_is_reproducible():
    a = monte_carlo_brdf(40.0, 20.0, 180.0, rho=0.5, psi=50.0, samples=2000, seed=11)
    b = monte_carlo_brdf(40.0, 20.0, 180.0, rho=0.5, psi=50.0, samples=2000, seed=11)
    assert a == b and a.seed == 11 and a.samples == 2000 and a.standard_error > 0


@pytest.mark.parametrize("alpha,beta,eps", [(0.0, 0.0, 0.0), (50.0, 70.0, 180.0), (80.0, 30.0, 45.0)])
def test_small_aperture_and_zero_coverage_give_lambert(alpha, beta, eps):
    # section 2: psi -> 0 is the flat Lambertian surface (eq 2); F1 -> 1/pi like psi^2
    # (1e-3 deg: deviation ~1e-10), the interreflection term vanishes like sin^2 psi
    rho = 0.6
    assert float(PITTED(alpha, 0.0, beta, eps, rho=rho, psi=1e-3, coverage=1.0)) == pytest.approx(rho / np.pi, rel=1e-8)
    assert float(PITTED(alpha, 0.0, beta, eps, rho=rho, psi=60.0, coverage=0.0)) == pytest.approx(rho / np.pi, rel=1e-15)


def test_fig12_shallow_pits_lie_between_lambert_and_hemisphere_at_normal_incidence():
    # Fig 12 (left, normal incidence, rho = 1): the BRDF at normal view grows with psi from
    # the Lambertian 1/pi to the hemisphere's 2/(3 pi) + 1/(2 pi)
    values = [float(PITTED(0.0, 0.0, 0.0, 0.0, rho=1.0, psi=p, coverage=1.0)) for p in (1, 15, 30, 45, 60, 75, 90)]
    assert values[0] == pytest.approx(1 / np.pi, rel=1e-6)
    assert np.all(np.diff(values) > 0)
    assert values[-1] == pytest.approx(2 / (3 * np.pi) + 1 / (2 * np.pi), rel=1e-10)


def test_split_in_rho_reproduces_the_model():
    # the separation rho F1 + F2(rho, psi) exposed for tabulation equals the model
    rng = np.random.default_rng(1)
    ti, tr = rng.uniform(0, 89, 50), rng.uniform(0, 89, 50)
    pi_, pr = rng.uniform(-180, 180, 50), rng.uniform(-180, 180, 50)
    terms = pitted_terms(ti, pi_, tr, pr, psi=35.0)
    for rho in (0.0, 0.4, 1.0):
        expected = PITTED(ti, pi_, tr, pr, rho=rho, psi=35.0, coverage=0.8)
        np.testing.assert_allclose(terms.brdf(rho, 0.8), expected, rtol=1e-13)
        np.testing.assert_allclose(terms.pit_brdf(rho) - rho * terms.single_scattering, diffuse_brdf(rho, 35.0), rtol=1e-12, atol=1e-16)


angle = st.floats(0.0, 89.0)
azimuth = st.floats(-180.0, 180.0)


@settings(max_examples=40, deadline=None)
@given(ti=angle, pi_=azimuth, tr=angle, pr=azimuth, psi=st.floats(1.0, 90.0))
def test_reciprocity_at_every_aperture(ti, pi_, tr, pr, psi):
    # section 1.3: the model is reciprocal (lit and visible are the same test, the diffuse
    # term is constant); quadrature nodes are symmetric, so only rounding remains
    violation = reciprocity_violation(PITTED, ti, pi_, tr, pr, rho=0.7, psi=psi, coverage=0.5)
    assert violation.worst < 1e-9, violation


@settings(max_examples=40, deadline=None)
@given(ti=angle, pi_=azimuth, tr=angle, pr=azimuth, psi=st.floats(0.01, 90.0), rho=st.floats(0.0, 1.0))
def test_non_negative(ti, pi_, tr, pr, psi, rho):
    assert float(PITTED(ti, pi_, tr, pr, rho=rho, psi=psi, coverage=1.0)) >= 0.0


@pytest.mark.parametrize("psi", [20.0, 55.0, 90.0])
def test_energy_directional_hemispherical_reflectance(psi):
    # energy: rho_dh = (1-c) rho + c rho cos^2(psi/2)/(1 - rho sin^2(psi/2)) for every
    # incidence (from eq 9-10), <= 1 and exactly 1 for rho = 1.  The BRDF has kinks at
    # shadow boundaries, so the 24-node quadrature of gonio.radiometry is not exact:
    # measured <= 4e-6 (psi = 90), 6e-8 (shallower); tolerance 3e-5.
    thetas = np.array([0.0, 35.0, 70.0])
    for rho, coverage in ((1.0, 1.0), (0.6, 0.5)):
        rho_dh = directional_hemispherical_reflectance(PITTED, thetas, rho=rho, psi=psi, coverage=coverage)
        expected = (1 - coverage) * rho + coverage * pit_albedo(rho, psi)
        np.testing.assert_allclose(rho_dh, expected, rtol=3e-5)
        assert np.all(rho_dh <= 1.0 + 3e-5)


def test_special_geometries_are_warning_free_and_finite():
    # DESIGN.md bad input: grazing, normal and theta_i == theta_r give finite values, no warnings
    thetas = np.array([0.0, 1e-9, 45.0, 89.999, 90.0])
    ti, tr, dphi = np.meshgrid(thetas, thetas, [0.0, 90.0, 180.0], indexing="ij")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for psi in (1e-200, 1e-6, 30.0, 90.0):
            values = PITTED(ti, 0.0, tr, dphi, rho=1.0, psi=psi, coverage=1.0)
            assert np.all(np.isfinite(values)) and np.all(values >= 0)


def test_grazing_forward_limit_is_the_diffuse_term():
    # at grazing incidence nothing of a hemispherical pit is lit: only D (eq 29) remains
    value = float(PITTED(90.0, 0.0, 40.0, 180.0, rho=1.0, psi=90.0, coverage=1.0))
    assert value == pytest.approx(1.0 / (2.0 * np.pi), rel=1e-6)


@pytest.mark.parametrize("kwargs,name", [({"psi": 0.0}, "psi"), ({"psi": 90.5}, "psi"), ({"psi": -3.0}, "psi"),
                                         ({"coverage": -0.1}, "coverage"), ({"coverage": 1.2}, "coverage"),
                                         ({"rho": 1.5}, "rho")])
def test_bad_parameters_raise_value_error_naming_them(kwargs, name):
    with pytest.raises(ValueError, match=name) as info:
        PITTED(30.0, 0.0, 30.0, 0.0, **kwargs)
    assert "(0, 90]" in str(info.value) or "[0, 1]" in str(info.value)
    with pytest.raises(ValueError, match=name):
        monte_carlo_brdf(30.0, 30.0, 0.0, **{"rho": 0.5, "psi": 45.0, "coverage": 1.0, **kwargs})
    if name == "psi":
        with pytest.raises(ValueError, match="psi"):
            pitted_terms(30.0, 0.0, 30.0, 0.0, psi=kwargs["psi"])


def test_aperture_mixture_is_weighted_average():
    # section 5: a distribution of apertures averages the pit BRDFs by area
    geom = (40.0, 0.0, 25.0, 180.0)
    mix = aperture_mixture_brdf(*geom, rho=0.8, apertures=[30.0, 90.0], weights=[3.0, 1.0], coverage=0.6)
    pits = [float(PITTED(*geom, rho=0.8, psi=p, coverage=1.0)) for p in (30.0, 90.0)]
    expected = 0.4 * 0.8 / np.pi + 0.6 * (0.75 * pits[0] + 0.25 * pits[1])
    assert float(mix) == pytest.approx(expected, rel=1e-13)
    with pytest.raises(ValueError, match="weights"):
        aperture_mixture_brdf(*geom, rho=0.8, apertures=[30.0], weights=[-1.0])
    with pytest.raises(ValueError, match="psi"):
        aperture_mixture_brdf(*geom, rho=0.8, apertures=[0.0], weights=[1.0])


@pytest.mark.parametrize("psi", [5.0, 40.0, 75.0, 90.0])
def test_model_single_scattering_closed_form_equals_the_quadrature(psi):
    """``pitted`` takes F1 from the closed form (and the quadrature at the horizon
    slivers); both evaluate eq 14-15, so they agree to the quadrature's accuracy, on
    random geometries and on directions 1e-4 .. 1e-7 deg from the horizon."""
    rng = np.random.default_rng(int(psi))
    ti, tr = rng.uniform(0.0, 90.0, 400), rng.uniform(0.0, 90.0, 400)
    dphi = rng.uniform(-180.0, 180.0, 400)
    near = 90.0 - np.array([1e-4, 1e-5, 1e-6, 1e-7])
    ti = np.concatenate([ti, np.repeat(near, 4), np.full(4, 30.0)])
    tr = np.concatenate([tr, np.tile(near, 4), near])
    dphi = np.concatenate([dphi, np.tile([0.0, 90.0, 179.0, 180.0], 4), np.full(4, 180.0)])
    closed = pitted_terms(ti, 0.0, tr, dphi, psi=psi).single_scattering
    quadrature = pitted_terms(ti, 0.0, tr, dphi, psi=psi, order=48).single_scattering
    # 1e-10 absolute (the BRDF scale is 1/pi): where F1 ~ 1e-4 forward at grazing both
    # quadratures carry ~1e-8 relative
    np.testing.assert_allclose(closed, quadrature, rtol=1e-8, atol=1e-10)


def test_a_geometry_whose_quadrature_set_is_empty_evaluates():
    """Found by Hypothesis: at theta_i = 71, theta_r = 89 in the plane and a tiny aperture
    the closed form's sliver set near the horizon was empty and the quadrature reshaped an
    empty array; any geometry must evaluate (KvDDN 1999, eq 14-15: the BRDF is >= 0)."""
    value = float(PITTED(71.0, 0.0, 89.0, 0.0, rho=0.0, psi=0.01171875, coverage=1.0))
    assert value >= 0.0


def test_the_monte_carlo_error_covers_a_lit_part_no_sample_found():
    """At a grazing source no sample of 1e4 may land in the lit part of the cavity: the
    estimate is then the diffuse term alone (0.037 against the closed form's 0.286), and its
    standard error must say so instead of reading 1e-19 (benchmarks/validity_atlas.py)."""
    import gonio

    estimate = monte_carlo_brdf(89.99, 15.0, 0.0, rho=0.9, psi=45.0, coverage=1.0, samples=10_000, seed=665)
    closed = float(gonio.brdf("pitted", 89.99, 0.0, 15.0, 0.0, rho=0.9, psi=45.0, coverage=1.0))
    assert estimate.value < 0.2 * closed  # the lit part was missed ...
    assert abs(closed - estimate.value) < 3.0 * estimate.standard_error  # ... and the error bar says so


def test_parameter_columns_give_each_combination_s_values():
    """The model broadcasts its parameters (a sampler's particles in one call): columns of
    rho, psi and coverage give, row by row, the values of each combination alone, grazing
    slivers (quadrature) and flat pits (psi 1e-4 deg) included, and through the rig's
    apertures too."""
    from gonio.instrument import aperture_averaged

    ti = np.array([0.0, 30.0, 60.0, 89.999, 89.9999, 45.0])
    pi_ = np.array([0.0, 0.0, 40.0, 0.0, 0.0, 0.0])
    tr = np.array([10.0, 70.0, 30.0, 89.999, 89.9999, 89.0])
    pr = np.array([180.0, 0.0, 200.0, 0.0, 180.0, 0.0])
    rho = np.array([[0.3], [0.8], [0.95], [0.5]])
    psi = np.array([[90.0], [45.0], [1e-4], [45.0]])
    coverage = np.array([[0.4], [1.0], [0.7], [0.0]])
    for model in (PITTED, aperture_averaged(PITTED)):
        fixed = model.at(ti, pi_, tr, pr)
        together = fixed(rho=rho, psi=psi, coverage=coverage)
        alone = np.array([fixed(rho=float(r), psi=float(p), coverage=float(c))
                          for r, p, c in zip(rho[:, 0], psi[:, 0], coverage[:, 0])])
        np.testing.assert_allclose(together, alone, rtol=1e-12, atol=0)
    assert PITTED.broadcasts_params


@pytest.mark.parametrize("psi", [1e-2, 1e-4, 1.24e-6])
def test_a_shallow_pit_is_flat_to_the_measured_order(psi):
    """F1 - 1/pi = 0.25 psi^2 / (cos alpha cos beta) of 1/pi to leading order (the
    quadrature, from normal to 1e-4 rad of grazing, retro and forward), and where that is
    below SHALLOW_LIMIT the model returns 1/pi, within 1e-8 of the quadrature: a pit of
    7e-5 deg had been a sliver everywhere, 100-300 times the cost."""
    from gonio.models.pitted.model import SHALLOW_LIMIT, single_scattering
    from gonio.models.pitted.quadrature import single_scattering_factor

    alpha = np.array([0.3, 1.4, 1.5, 1.55, 1.5707 - 1e-4, 1.2])
    beta = np.array([0.5, 1.4, 1.5, 1.55, 1.5707 - 1e-4, 0.1])
    epsilon = np.array([1.0, 0.0, 0.0, np.pi, 0.0, 2.0])
    reference = single_scattering_factor(alpha, beta, epsilon, psi, 32)
    departure = reference * np.pi - 1.0
    scale = psi**2 / (np.cos(alpha) * np.cos(beta))
    assert np.all(np.abs(departure) < 0.3 * scale + 1e-12)
    model = single_scattering(alpha, beta, epsilon, psi)
    shallow = np.sin(psi) ** 2 < SHALLOW_LIMIT * np.cos(alpha) * np.cos(beta)
    assert shallow.any() == (psi < 1e-5)  # the shortcut applies to the shallowest pit only
    np.testing.assert_allclose(model, reference, rtol=1e-8)
    np.testing.assert_array_equal(model[shallow], 1.0 / np.pi)
