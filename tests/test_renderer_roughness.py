"""Renderers' rough-diffuse models (Fujii's FON, EON) and the roughness conventions.

Against the papers' statements: Fujii (2012) -- the sigma' normalisation keeps the albedo
at or below rho with its maximum at grazing; Portsmouth, Kutz & Hill (2025, EON) -- the
exact FON albedo E_F, its average A (1 + c2 r), the white-furnace test of EON, the
albedo E_EON = rho E_F + rho_ms (1 - E_F); Mitsuba 0.6 roughdiffuse -- sigma = alpha/sqrt(2)
with Oren & Nayar's eq 33-35 / 36.  The hemispherical integrals are computed here by
Gauss-Legendre quadrature, independently of the closed forms they check.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import gonio
from gonio.models.eon import eon_albedo, multiple_scattering_albedo
from gonio.models.fujii import (
    FON_C1,
    FON_C2,
    fujii_a,
    fujii_albedo,
    fujii_average_albedo,
    fujii_oren_nayar_brdf,
    r_from_sigma_ratio,
)
from gonio.models.oren_nayar.functional import qualitative_a, qualitative_b
from gonio.models.roughness_conventions import (
    match_geometry,
    match_roughness,
    match_values,
    mitsuba_alpha_to_sigma,
    sigma_to_eon_r,
    sigma_to_mitsuba_alpha,
)

ROUGHNESSES = (0.0, 0.1, 0.25, 0.5, 0.75, 1.0)
INCIDENCES = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 85.0, 89.5)


def _panels(edges, order):
    x, w = np.polynomial.legendre.leggauss(order)
    edges = np.asarray(edges, float)
    lo, hi = edges[:-1, None], edges[1:, None]
    half = 0.5 * (hi - lo)
    return (lo + half * (x + 1.0)).ravel(), (half * w).ravel()


def hemispherical_albedo(name: str, theta_i: float, order: int = 40, **params) -> float:
    """int f_r(theta_i, 0; theta_r, phi_r) cos(theta_r) d omega_r over the exit hemisphere.

    Gauss-Legendre panels split where the integrands have kinks: theta_r = theta_i
    (t = max of the cosines, alpha/beta of Oren-Nayar) and phi_r = 90, 270 deg (s changes
    sign).  d omega = sin(theta) d theta d phi."""
    theta_edges = np.unique(np.clip([0.0, theta_i, 90.0], 0.0, 90.0))
    theta, w_theta = _panels(np.radians(theta_edges), order)
    phi, w_phi = _panels(np.radians([0.0, 90.0, 270.0, 360.0]), order)
    tr, pr = np.meshgrid(theta, phi, indexing="ij")
    f = gonio.brdf(name, theta_i, 0.0, np.degrees(tr), np.degrees(pr), **params)
    jacobian = np.cos(tr) * np.sin(tr)
    return float(np.sum(f * jacobian * np.outer(w_theta, w_phi)))


# ------------------------------------------------------------------ EON: white furnace
@pytest.mark.parametrize("r", ROUGHNESSES)
def test_eon_white_furnace_albedo_is_one_for_every_incidence(r):
    """EON (Portsmouth et al. 2025): with rho = 1 the directional albedo is 1 for every
    incidence and roughness.  1e-9: the panelled 40-node rule integrates these smooth
    pieces to ~1e-14 (measured; doubling the order changes the result by less than 1e-12,
    checked below); FON alone misses by up to 22 % (next tests)."""
    for theta in INCIDENCES:
        albedo = hemispherical_albedo("eon", theta, rho=1.0, r=r)
        assert abs(albedo - 1.0) < 1e-9, (r, theta, albedo)


def test_the_quadrature_has_converged():
    coarse = hemispherical_albedo("eon", 60.0, order=40, rho=0.7, r=0.8)
    fine = hemispherical_albedo("eon", 60.0, order=80, rho=0.7, r=0.8)
    assert abs(coarse - fine) < 1e-12


@pytest.mark.parametrize("rho", [0.2, 0.5, 0.9])
def test_eon_albedo_closed_form_equals_the_integral(rho):
    """E_EON = rho E_F + rho_ms (1 - E_F) (the paper's E_EON); below rho (the compensation
    returns only rho_ms <= rho of the light FON loses) and above rho E_F."""
    for r in (0.3, 1.0):
        for theta in (0.0, 40.0, 80.0):
            integral = hemispherical_albedo("eon", theta, rho=rho, r=r)
            closed = float(eon_albedo(theta, rho, r))
            assert abs(integral - closed) < 1e-9
            assert rho * float(fujii_albedo(theta, r)) < closed <= rho


def test_multiple_scattering_albedo_statements():
    """rho_ms = 1 for rho = 1 (all the light FON loses comes back); rho_ms <= rho."""
    r = np.linspace(0.01, 1.0, 12)
    np.testing.assert_allclose(multiple_scattering_albedo(1.0, r), 1.0, rtol=0, atol=1e-15)
    rho = np.linspace(0.0, 1.0, 11)[:, None]
    assert (multiple_scattering_albedo(rho, r) <= rho + 1e-15).all()


# ------------------------------------------------------------------ FON: albedo and loss
@pytest.mark.parametrize("r", ROUGHNESSES[1:])
def test_fon_exact_albedo_equals_the_integral(r):
    """The analytic FON albedo E_F = A (1 + r G/pi) (the paper's E_FON_exact) against the
    quadrature of Fujii's BRDF, to 1e-9 (quadrature accuracy, see above)."""
    for theta in INCIDENCES:
        integral = hemispherical_albedo("fujii-oren-nayar", theta, rho=1.0, r=r)
        assert abs(integral - float(fujii_albedo(theta, r))) < 1e-9, (r, theta)


def test_fon_loses_energy_most_at_normal_incidence_and_none_at_grazing():
    """Fujii: A is chosen so the albedo is exactly rho at grazing incidence, its maximum,
    so FON never reflects more than rho.  Below grazing it reflects less: at r = 1 the
    albedo is A = 1/(1 + 1/2 - 2/(3 pi)) = 0.7765 at normal incidence (22 % lost)."""
    theta = np.linspace(0.0, 90.0, 181)
    for r in ROUGHNESSES[1:]:
        e = fujii_albedo(theta, r)
        assert abs(e[-1] - 1.0) < 1e-12
        assert (np.diff(e) > 0).all()  # rises monotonically towards grazing
        assert (e[:-1] < 1.0).all()
    assert abs(float(fujii_albedo(0.0, 1.0)) - 1.0 / (1.5 - 2.0 / (3.0 * math.pi))) < 1e-15
    assert round(float(fujii_albedo(0.0, 1.0)), 4) == 0.7765
    integral = hemispherical_albedo("fujii-oren-nayar", 0.0, rho=1.0, r=1.0)
    assert abs(integral - 0.77652207) < 1e-8


def test_fon_average_albedo_and_its_loss_at_r_equal_one():
    """<E_F> = 2 int E_F(mu) mu dmu = A (1 + (2/3 - 28/(15 pi)) r) (the paper's average
    FON albedo), by quadrature of the integrated BRDF over the incidence; 0.8328 at r = 1:
    FON loses 16.7 % of uniform illumination, which EON's second lobe returns."""
    # over theta (2 int E cos sin dtheta): E_F is smooth in theta, not in mu near mu = 1
    theta, w = _panels([0.0, math.pi / 2], 24)
    for r in (0.4, 1.0):
        e = np.array([hemispherical_albedo("fujii-oren-nayar", math.degrees(t), rho=1.0, r=r) for t in theta])
        average = 2.0 * float(np.sum(w * e * np.cos(theta) * np.sin(theta)))
        # 1e-12: both quadratures converge to ~1e-15 on these smooth integrands
        assert abs(average - float(fujii_average_albedo(r))) < 1e-12
    assert round(float(fujii_average_albedo(1.0)), 4) == 0.8328
    assert abs(FON_C1 - (0.5 - 2 / (3 * math.pi))) < 1e-16 and abs(FON_C2 - (2 / 3 - 28 / (15 * math.pi))) < 1e-16


# ------------------------------------------------------------------ limits and invariants
def _random_geometry(n=400, seed=3, top=89.9):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, top, n), rng.uniform(-180, 180, n), rng.uniform(0, top, n), rng.uniform(-180, 180, n)


@pytest.mark.parametrize("name", ["fujii-oren-nayar", "eon"])
def test_zero_roughness_is_lambert_exactly(name):
    """r = 0: B = 0, A = 1 and (EON) no compensation lobe: rho/pi everywhere."""
    geometry = _random_geometry()
    for rho in (0.0, 0.35, 1.0):
        np.testing.assert_array_equal(gonio.brdf(name, *geometry, rho=rho, r=0.0), gonio.brdf("lambert", *geometry, rho=rho))


@pytest.mark.parametrize("name", ["fujii-oren-nayar", "eon"])
def test_reciprocity(name):
    """f(i, r) = f(r, i) (Helmholtz): s, t and the product of the two albedo deficits are
    symmetric; 1e-13 relative is rounding."""
    ti, pi_, tr, pr = _random_geometry()
    for r in (0.2, 1.0):
        forward = gonio.brdf(name, ti, pi_, tr, pr, rho=0.7, r=r)
        backward = gonio.brdf(name, tr, pr, ti, pi_, rho=0.7, r=r)
        np.testing.assert_allclose(forward, backward, rtol=1e-13, atol=0)


@pytest.mark.parametrize("name", ["fujii-oren-nayar", "eon"])
def test_non_negative_everywhere_in_range(name):
    thetas = np.array([0.0, 1e-6, 20.0, 45.0, 70.0, 85.0, 89.99, 90.0])
    phis = np.linspace(0.0, 360.0, 25)
    ti, tr, pr = (a.ravel() for a in np.meshgrid(thetas, thetas, phis, indexing="ij"))
    for rho in (0.0, 0.5, 1.0):
        for r in (0.0, 0.5, 1.0):
            values = gonio.brdf(name, ti, 0.0, tr, pr, rho=rho, r=r)
            assert np.isfinite(values).all() and (values >= 0.0).all()


def test_why_r_is_bounded_by_one():
    """At theta_i = theta_r = 90 deg, dphi = 180 deg, s = -1 and t = 1: FON is
    rho/pi A (1 - r), 0 at r = 1 and negative beyond -- the bound [0, 1] keeps the BRDF
    physical (and is the range OpenPBR gives base_diffuse_roughness)."""
    edge = [math.pi / 2, 0.0, math.pi / 2, math.pi]
    assert abs(float(fujii_oren_nayar_brdf(*edge, rho=1.0, r=1.0))) < 1e-16
    assert float(fujii_oren_nayar_brdf(*edge, rho=1.0, r=1.2)) < 0.0
    with pytest.raises(ValueError, match=r"r = 1.2 - is outside its valid range \[0, 1\]"):
        gonio.brdf("eon", 30, 0, 30, 180, rho=0.5, r=1.2)


def test_fon_is_the_qualitative_model_in_vector_form_on_the_backward_side():
    """Fujii: for s > 0, s/t = cos(dphi) sin(alpha) tan(beta), the geometry factor of
    Oren & Nayar eq 36, so FON with r = B/A is eq 36 up to the overall factor A_ON / A_F;
    on the forward side (s < 0) eq 36 keeps A while FON subtracts r |s|."""
    sigma, rho = 25.0, 0.8
    a_on, b_on = float(qualitative_a(sigma)), float(qualitative_b(sigma))
    r = b_on / a_on
    ti, pi_, tr, pr = _random_geometry(top=85.0)
    fon = gonio.brdf("fujii-oren-nayar", ti, pi_, tr, pr, rho=rho, r=r) * a_on / float(fujii_a(r))
    qon = gonio.brdf("oren-nayar-qualitative", ti, pi_, tr, pr, rho=rho, sigma=sigma)
    backward = np.cos(np.radians(pr - pi_)) > 0
    np.testing.assert_allclose(fon[backward], qon[backward], rtol=1e-12)
    assert (fon[~backward] < qon[~backward]).all()
    # Fujii's matched coefficients add the interreflection of eq 34 to A, so the ratio
    # is smaller than B/A of eq 36
    assert r_from_sigma_ratio(sigma, rho) < r


def _listing_f_eon(rho, r, wi, wo):
    """The paper's listing f_EON (exact = true) transcribed in numpy: vectors, the
    E_FON_exact formula with Si/mu and the max(1e-7, .) guards.  Independent of gonio's
    rearranged form."""
    c1, c2 = 0.5 - 2.0 / (3.0 * np.pi), 2.0 / 3.0 - 28.0 / (15.0 * np.pi)

    def e_fon(mu):
        a = 1.0 / (1.0 + c1 * r)
        si = np.sqrt(1.0 - mu * mu)
        g = si * (np.arccos(np.clip(mu, -1, 1)) - si * mu) + (2.0 / 3.0) * ((si / mu) * (1.0 - si**3) - si)
        return a + r * a / np.pi * g

    mu_i, mu_o = wi[..., 2], wo[..., 2]
    s = np.sum(wi * wo, axis=-1) - mu_i * mu_o
    s_over_t = np.where(s > 0, s / np.maximum(mu_i, mu_o), s)
    a = 1.0 / (1.0 + c1 * r)
    f_ss = rho / np.pi * a * (1.0 + r * s_over_t)
    average = a * (1.0 + c2 * r)
    rho_ms = rho * rho * average / (1.0 - rho * (1.0 - average))
    eps = 1e-7
    f_ms = rho_ms / np.pi * np.maximum(eps, 1 - e_fon(mu_o)) * np.maximum(eps, 1 - e_fon(mu_i)) / np.maximum(eps, 1 - average)
    return f_ss + f_ms


def _direction(theta, phi):
    t, p = np.radians(theta), np.radians(phi)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def test_eon_equals_the_papers_listing_where_its_guards_are_inactive():
    """gonio cancels A r between 1 - E_F and 1 - <E_F>; the listing divides instead.  Away
    from grazing (1 - E_F > 1e-7) and for r not tiny both are the same function: 1e-12
    relative is rounding of the two arrangements."""
    ti, pi_, tr, pr = _random_geometry(top=80.0)
    wi, wo = _direction(ti, pi_), _direction(tr, pr)
    for rho in (0.3, 0.9):
        for r in (0.05, 0.5, 1.0):
            ours = gonio.brdf("eon", ti, pi_, tr, pr, rho=rho, r=r)
            np.testing.assert_allclose(ours, _listing_f_eon(rho, r, wi, wo), rtol=1e-12)


def test_array_parameters_broadcast():
    ti, pi_, tr, pr = _random_geometry(n=5)
    r = np.array([0.1, 0.6, 1.0])[:, None]
    grid = gonio.brdf("eon", ti, pi_, tr, pr, rho=0.6, r=r)
    assert grid.shape == (3, 5)
    np.testing.assert_allclose(grid[1], gonio.brdf("eon", ti, pi_, tr, pr, rho=0.6, r=0.6), rtol=1e-15)


# ------------------------------------------------------------------ roughness conventions
def test_mitsuba_alpha_is_sqrt2_sigma_in_radians():
    """Mitsuba 0.6 roughdiffuse: sigma = alpha / sqrt(2) (src/bsdfs/roughdiffuse.cpp)."""
    assert abs(float(sigma_to_mitsuba_alpha(30.0)) - math.sqrt(2) * math.pi / 6) < 1e-15
    alphas = np.array([0.0, 0.001, 0.1, 0.3, 0.7, 1.5])
    np.testing.assert_allclose(sigma_to_mitsuba_alpha(mitsuba_alpha_to_sigma(alphas)), alphas, rtol=1e-15)
    # Mitsuba's documented "extremely rough" alpha = 0.7 is sigma = 28.4 deg
    assert round(float(mitsuba_alpha_to_sigma(0.7)), 1) == 28.4


@pytest.mark.parametrize("renderer, reference", [("mitsuba-roughdiffuse", "oren-nayar"),
                                                 ("mitsuba-roughdiffuse-fast", "oren-nayar-qualitative")])
def test_the_fit_recovers_mitsubas_closed_form_alpha(renderer, reference):
    """Mitsuba evaluates eq 33-35 (eq 36) at sigma = alpha/sqrt(2): fitted to gonio's own
    closed form, the match must find alpha = sqrt(2) sigma with zero residual."""
    for sigma in (5.0, 20.0, 45.0):
        m = match_roughness(sigma, 0.7, renderer, reference=reference, order=5, azimuths=4)
        assert abs(m.value - float(sigma_to_mitsuba_alpha(sigma))) < 1e-6
        assert m.rms < 1e-7 and not m.at_bound


def test_the_fit_recovers_a_known_eon_roughness_and_albedo():
    geometry = match_geometry(6, 4)
    truth = gonio.brdf("eon", *geometry[:4], rho=0.62, r=0.37)
    m = match_values(truth, geometry, 0.62, "eon")
    assert abs(m.value - 0.37) < 1e-7 and m.rms < 1e-9
    both = match_values(truth, geometry, 0.9, "eon", fit_albedo=True)  # wrong starting albedo
    assert abs(both.value - 0.37) < 1e-6 and abs(both.rho - 0.62) < 1e-6


def test_smooth_surface_maps_to_zero_roughness():
    assert sigma_to_eon_r(0.0, 0.8, reference="oren-nayar") == 0.0
    m = match_roughness(0.0, 0.8, "mitsuba-roughdiffuse", reference="oren-nayar-exact", order=4, azimuths=3)
    assert m.value == 0.0 and m.rms < 1e-12 and m.at_bound


def test_fitted_eon_roughness_rises_with_sigma():
    values = [match_roughness(s, 0.8, "eon", reference="oren-nayar", order=6, azimuths=4).value
              for s in (10.0, 20.0, 30.0, 40.0, 50.0)]
    assert (np.diff(values) > 0).all() and 0.0 < values[0] and values[-1] <= 1.0


def test_geometry_weights_are_the_projected_solid_angle_measure():
    """sum w g = int g cos_i cos_r d omega_i d omega_r / pi^2: for g = 1 the normalised
    weights sum to 1, and for g = cos(theta_i) the integral is (2 pi / 3) pi / pi^2."""
    ti, _, tr, _, w = match_geometry(8, 5)
    assert abs(w.sum() - 1.0) < 1e-14
    assert abs(np.sum(w * np.cos(np.radians(ti))) - 2.0 / 3.0) < 1e-12


MAPPING = Path(__file__).resolve().parents[1] / "docs" / "benchmarks" / "roughness_mapping.json"


@pytest.mark.skipif(not MAPPING.is_file(), reason="benchmarks/roughness_mapping.py has not been run")
def test_the_documented_mapping_is_what_the_function_computes():
    """docs/roughness.md quotes docs/benchmarks/roughness_mapping.json; a row of it must be
    reproduced by the library's function with the same settings (one rule, one place)."""
    payload = json.loads(MAPPING.read_text())
    settings = payload["settings"]
    row = next(row for row in payload["rows"] if row["sigma"] == 20.0)
    rho = settings["rho"][0]
    m = match_roughness(20.0, rho, "eon", reference=settings["reference"], order=settings["order"],
                        azimuths=settings["azimuths"])
    recorded = row["rho"][str(rho)]["eon"]
    assert abs(m.value - recorded["value"]) < 1e-6 and abs(m.rms - recorded["rms"]) < 1e-6
