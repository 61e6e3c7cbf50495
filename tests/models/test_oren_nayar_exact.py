"""``oren-nayar-exact`` and ``oren-nayar-numerical``: Oren & Nayar (1995) eq 8, 31-32,
footnote 10 and the features of Figures 10-14."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import gonio
from gonio.models.oren_nayar import exact as ex
from gonio.radiometry import directional_hemispherical_reflectance

EXACT = ex.EXACT
NUMERICAL = ex.NUMERICAL
MODELS = [EXACT, NUMERICAL]


def _in_plane(theta_i, signed_theta_r):
    """Angles of the plane of incidence; positive viewing angle = source side (DESIGN.md)."""
    signed = np.asarray(signed_theta_r, dtype=float)
    return theta_i, 0.0, np.abs(signed), np.where(signed >= 0, 0.0, 180.0)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_sigma_zero_is_lambert_footnote10(model):
    """Footnote 10: sigma = 0 reduces the model to Lambert, exactly."""
    rng = np.random.default_rng(1)
    angles = [rng.uniform(0, 90, 50), rng.uniform(0, 360, 50), rng.uniform(0, 90, 50), rng.uniform(0, 360, 50)]
    np.testing.assert_array_equal(model(*angles, rho=0.7, sigma=0.0), np.full(50, 0.7 / np.pi))


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_tiny_sigma_tends_to_lambert(model):
    """Eq 32 normalised over [0, 90 deg]: sigma -> 0 is continuous (no division by zero)."""
    value = model(40.0, 0.0, 70.0, 180.0, rho=1.0, sigma=1e-3)
    # deviations from Lambert are O(sigma^2) ~ 1e-10 rad^2
    assert value == pytest.approx(1 / np.pi, rel=1e-6)


@settings(max_examples=15, deadline=None)
@given(st.floats(0, 89.9), st.floats(0, 360), st.floats(0, 89.9), st.floats(0, 360), st.floats(1, 60))
def test_reciprocity_exact(ti, pi_, tr, pr, sigma):
    """Helmholtz reciprocity (section 4.3): f(i, r) = f(r, i).  The V-cavity integrand is
    reciprocal after pairing each facet with its neighbour; the quadrature nodes are not
    symmetric, so equality holds to the accuracy setting (1e-6 relative, x3 margin)."""
    forward = EXACT(ti, pi_, tr, pr, rho=0.9, sigma=sigma)
    backward = EXACT(tr, pr, ti, pi_, rho=0.9, sigma=sigma)
    assert forward == pytest.approx(backward, rel=3e-6)


@settings(max_examples=30, deadline=None)
@given(st.floats(0, 89.9), st.floats(0, 360), st.floats(0, 89.9), st.floats(0, 360), st.floats(1, 60))
def test_reciprocity_numerical(ti, pi_, tr, pr, sigma):
    """Eq 45 and 49 are symmetric in (theta_i, theta_r) and the slope panels too:
    reciprocity to rounding."""
    forward = NUMERICAL(ti, pi_, tr, pr, rho=0.9, sigma=sigma)
    backward = NUMERICAL(tr, pr, ti, pi_, rho=0.9, sigma=sigma)
    assert forward == pytest.approx(backward, rel=1e-10)


def test_default_accuracy_is_1e6_against_tightest_setting():
    """The accuracy knob: default rtol = 1e-6 vs the tightest setting (1e-7), random and
    grazing geometries, several sigma.  Measured worst: 2.1e-7 here (3e-7 over 200
    random geometries and sigma in [2, 60] deg)."""
    rng = np.random.default_rng(3)
    n = 24
    angles = [rng.uniform(0, 90, n), rng.uniform(0, 360, n), rng.uniform(0, 90, n), rng.uniform(0, 360, n)]
    angles[0][:4] = [89.5, 90.0, 0.0, 60.0]
    angles[2][:4] = [30.0, 89.9, 0.0, 60.0]
    for sigma in (10.0, 40.0):
        default = EXACT(*angles, rho=0.9, sigma=sigma)
        tight = EXACT(*angles, rho=0.9, sigma=sigma, rtol=1e-7)
        np.testing.assert_allclose(default, tight, rtol=1e-6)


def test_exact_and_numerical_direct_terms_agree_in_the_two_planes():
    """In and perpendicular to the plane of incidence eq 45 is exact (eq 40-43), so the
    direct parts (f1) of the two models differ only by quadrature error."""
    theta_r = np.array([0.0, 20.0, 50.0, 75.0, 89.0])
    for delta in (0.0, 90.0, 180.0):
        e1, _ = ex.exact_components(60.0, 0.0, theta_r, delta, 25.0)
        n1, _ = ex.numerical_components(60.0, 0.0, theta_r, delta, 25.0)
        np.testing.assert_allclose(n1, e1, rtol=2e-6)


def test_fixed_geometry_path_equals_call():
    """Model.at (prepare) and the plain call share one implementation."""
    angles = ([10.0, 60.0, 85.0], 0.0, [70.0, 30.0, 85.0], [180.0, 40.0, 0.0])
    for model in MODELS:
        fixed = model.at(*angles)
        for sigma in (15.0, 35.0, 15.0):
            np.testing.assert_array_equal(fixed(rho=0.6, sigma=sigma), model(*angles, rho=0.6, sigma=sigma))


def test_components_split_rho_linear_and_quadratic():
    """exact_components: the model is rho f1 + rho^2 f2 (Table 1 is linear in rho, eq 26 quadratic)."""
    f1, f2 = ex.exact_components(70.0, 0.0, 40.0, 180.0, 30.0)
    for rho in (0.2, 0.9):
        assert EXACT(70.0, 0.0, 40.0, 180.0, rho=rho, sigma=30.0) == pytest.approx(rho * f1 + rho**2 * f2, rel=1e-14)


def test_bad_input_names_the_parameter():
    """DESIGN 'Bad input': ValueError naming the parameter and its range."""
    with pytest.raises(ValueError, match="sigma"):
        EXACT(10.0, 0.0, 10.0, 0.0, sigma=-1.0)
    with pytest.raises(ValueError, match="rtol"):
        EXACT(10.0, 0.0, 10.0, 0.0, rtol=1e-9)
    with pytest.raises(ValueError, match="sigma"):
        ex.exact_components(10.0, 0.0, 10.0, 0.0, sigma=95.0)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_no_warnings_at_normal_grazing_and_equal_angles(model):
    """DESIGN 'Bad input': theta = 0, 90 deg and theta_i == theta_r give finite values and no
    RuntimeWarning (pytest turns them into errors); beyond the horizon the BRDF is 0."""
    theta_i = np.array([0.0, 90.0, 90.0, 45.0, 0.0, 89.999, 30.0])
    theta_r = np.array([0.0, 90.0, 0.0, 45.0, 90.0, 89.999, 95.0])
    values = model(theta_i, 0.0, theta_r, [0.0, 180.0, 0.0, 0.0, 90.0, 180.0, 0.0], rho=0.9, sigma=30.0)
    assert np.all(np.isfinite(values))
    assert np.all(values[:-1] > 0) and values[-1] == 0.0
    # continuity at the horizon: 90 deg is the limit of 89.999 deg
    assert model(90.0, 0.0, 30.0, 180.0, sigma=30.0) == pytest.approx(model(89.999, 0.0, 30.0, 180.0, sigma=30.0), rel=1e-3)


def _fig10_curves():
    signed = np.arange(-85.0, 86.0, 5.0)
    f1, f2 = ex.exact_components(*_in_plane(75.0, signed), 30.0)
    return signed, 0.9 * f1 + 0.81 * f2, 0.9 * f1


def test_fig10_radiance_rises_toward_the_source():
    """Fig 10 (sigma = 30 deg, rho = 0.9, theta_i = 75 deg): in the plane of incidence the
    radiance grows as the viewer moves from the forward side to the source."""
    signed, total, direct = _fig10_curves()
    assert np.all(np.diff(total) > 0)
    assert np.all(np.diff(direct) > 0)
    assert total[-1] / total[0] > 3.0  # measured 5.8: far from Lambert's 1


def test_fig10_cut_off_at_the_source_direction():
    """Fig 10: past theta_r = theta_i on the source side the radiance flattens ('cut off'
    by masking, at theta_r = theta_i independent of roughness)."""
    for sigma in (20.0, 30.0):
        signed = np.array([65.0, 74.0, 76.0, 85.0])
        f1, f2 = ex.exact_components(*_in_plane(75.0, signed), sigma)
        total = 0.9 * f1 + 0.81 * f2
        before = (total[1] - total[0]) / 9.0
        after = (total[3] - total[2]) / 9.0
        assert before > 3 * after  # measured ratio 5.1 (sigma = 20), 11.7 (30)


def test_fig10_interreflection_matters_most_forward():
    """Fig 10: the thin line (direct light only) departs most from the total in the forward
    direction, where most visible facets are self-shadowed."""
    signed, total, direct = _fig10_curves()
    share = 1 - direct / total
    assert signed[np.argmax(share)] < -60
    assert share.max() > 0.4 and share[-1] < 0.02  # measured 0.50 and 0.006


def test_fig12_near_lambertian_at_small_incidence_and_perpendicular_plane():
    """Fig 12 (sigma = 40 deg, rho = 0.9): (a) at theta_i ~ 0 the BRDF barely depends on the
    viewing angle, unlike theta_i = 75 deg; (b) in the plane perpendicular to the plane of
    incidence the surface is again nearly Lambertian."""
    signed = np.arange(-60.0, 61.0, 10.0)

    def spread(values):
        return values.max() / values.min() - 1

    small = EXACT(*_in_plane(5.0, signed), rho=0.9, sigma=40.0)
    large = EXACT(*_in_plane(75.0, signed), rho=0.9, sigma=40.0)
    perpendicular = EXACT(75.0, 0.0, np.abs(signed), 90.0, rho=0.9, sigma=40.0)
    # measured spreads over theta_r in [-60, 60]: 6 % (theta_i = 5), 180 % (75), 13 % (perp.)
    assert spread(small) < 0.25 * spread(large)
    assert spread(perpendicular) < 0.25 * spread(large)


def test_fig13_functional_approximation_close_to_exact_in_plane():
    """Fig 13 (sigma = 30 deg, rho = 0.9, plane of incidence): the functional approximation
    eq 33-35 follows the model.  Against oren-nayar-exact over theta_r in [-89, 89] deg the
    measured worst relative error is 6.4 % (theta_i = 30), 7.9 % (45), 10.0 % (60) and
    26 % (75, at forward grazing where interreflection dominates); bounds add ~2-4 points."""
    if "oren-nayar" not in gonio.models.available():
        pytest.skip("functional model not registered")
    signed = np.linspace(-89.0, 89.0, 90)
    for theta_i, bound in ((30.0, 0.09), (45.0, 0.10), (60.0, 0.12), (75.0, 0.30)):
        angles = _in_plane(theta_i, signed)
        exact = EXACT(*angles, rho=0.9, sigma=30.0)
        functional = gonio.brdf("oren-nayar", *angles, rho=0.9, sigma=30.0)
        assert np.max(np.abs(functional / exact - 1)) < bound


@pytest.mark.parametrize("sigma", [20.0, 60.0])
def test_energy_conservation_rho_dh_at_most_one(sigma):
    """Lambertian facets in V-cavities with two bounces cannot reflect more than they
    receive: rho_dh <= 1 for rho = 1.  Measured (order 12, rtol 1e-4): sigma = 20 deg:
    0.973-0.988, sigma = 60 deg: 0.740-0.895 for theta_i in [0, 89] deg
    (docs/oren-nayar-accuracy.md).  Quadrature error at order 8 < 1e-3."""
    rho_dh = directional_hemispherical_reflectance(
        EXACT, [0.0, 60.0, 89.0], order=8, rho=1.0, sigma=sigma, rtol=1e-3
    )
    assert np.all(rho_dh <= 1.0)
    assert np.all(rho_dh > 0.7)


def test_fig11_deviation_from_lambert_grows_with_roughness():
    """Fig 11 (theta_i = 75 deg, rho = 0.9, plane of incidence): sigma = 0 is Lambert and
    the spread of the in-plane radiance grows with sigma.  Measured max/min - 1 over
    theta_r in [-89, 89] deg: 0, 1.82, 4.18, 5.34, 5.69 for sigma = 0, 10, 20, 30, 40."""
    angles = _in_plane(75.0, np.linspace(-89.0, 89.0, 30))
    spreads = []
    for sigma in (0.0, 10.0, 20.0, 30.0, 40.0):
        values = EXACT(*angles, rho=0.9, sigma=sigma)
        spreads.append(values.max() / values.min() - 1)
    assert spreads[0] == 0.0
    assert np.all(np.diff(spreads) > 0.1)


def test_fig14_qualitative_model_on_the_source_side():
    """Fig 14a (sigma = 30 deg, rho = 0.9, theta_i = 75 deg): the qualitative model eq 36
    rises toward the source like the full model.  On the source side of the plane of
    incidence it is within 11.3 % of oren-nayar-exact (2.2 % of its direct part: eq 36
    has no interreflection); forward it lacks the interreflection the exact model has."""
    if "oren-nayar-qualitative" not in gonio.models.available():
        pytest.skip("qualitative model not registered")
    signed = np.linspace(0.0, 89.0, 45)
    angles = _in_plane(75.0, signed)
    f1, f2 = ex.exact_components(*angles, 30.0)
    qualitative = gonio.brdf("oren-nayar-qualitative", *angles, rho=0.9, sigma=30.0)
    assert np.all(np.diff(qualitative) >= 0)
    assert np.max(np.abs(qualitative / (0.9 * f1 + 0.81 * f2) - 1)) < 0.14
    assert np.max(np.abs(qualitative / (0.9 * f1) - 1)) < 0.03


def test_horizon_is_the_limit_of_grazing_angles():
    """Module notes: theta = 90 deg is evaluated at 90 deg - 1e-6 rad.  Against
    theta = 90 - 1e-4 deg the values differ by the model's own slope (measured <= 4.6e-6)
    plus quadrature error; 2e-5 bounds both with margin."""
    for theta_r, phi_r in ((40.0, 180.0), (40.0, 0.0), (70.0, 90.0), (89.0, 180.0)):
        at_horizon = EXACT(90.0, 0.0, theta_r, phi_r, sigma=30.0)
        near = EXACT(90.0 - 1e-4, 0.0, theta_r, phi_r, sigma=30.0)
        assert at_horizon == pytest.approx(near, rel=2e-5)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_grazing_retroreflection_is_large_but_finite(model):
    """Module notes: at theta_i = theta_r = 90 deg, phi_r = phi_i the V-cavity BRDF diverges
    like 1/cos(theta) (eq 33 through tan(beta)); gonio returns a large finite value, no
    warning, and values grow toward the limit."""
    values = model([80.0, 89.0, 89.9, 90.0], 0.0, [80.0, 89.0, 89.9, 90.0], 0.0, rho=0.9, sigma=30.0)
    assert np.all(np.isfinite(values))
    assert np.all(np.diff(values) > 0)
    assert values[-1] > 1e4 * values[0]


def test_interreflection_option_drops_exactly_the_rho_squared_term():
    """Fig 10 draws the radiance with and without interreflection: the option removes
    rho^2 f2 and leaves rho f1 (exact_components / numerical_components)."""
    from gonio.models.oren_nayar.exact import numerical_components

    g = (75.0, 0.0, [10.0, 40.0, 80.0], 180.0)
    f1, f2 = numerical_components(*g, sigma=30.0)
    direct = gonio.brdf("oren-nayar-numerical", *g, rho=0.9, sigma=30.0, interreflection=False)
    total = gonio.brdf("oren-nayar-numerical", *g, rho=0.9, sigma=30.0)
    np.testing.assert_allclose(direct, 0.9 * f1, rtol=1e-12)
    np.testing.assert_allclose(total - direct, 0.81 * f2, rtol=1e-9, atol=1e-15)
    assert np.all(total > direct)  # interreflection only adds light
