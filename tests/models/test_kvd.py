"""Koenderink-van Doorn reciprocal series (JOSA A 15(11), 1998): basis, normalisation,
projection, mirror/retroreflector truncations (Figs 4-6) and least squares."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import gonio
from gonio.models import kvd
from gonio.models.kvd.projection import product_quadrature, series_on_grid
from gonio.zernike import hemisphere_basis, zernike_radial

TABLE_2_MODES = [
    (0, 0, 0), (1, 1, 1), (2, 0, 0), (2, 2, 0), (2, 2, 2), (3, 1, 1), (3, 3, 1), (3, 3, 3),
    (4, 0, 0), (4, 2, 0), (4, 2, 2), (4, 4, 0), (4, 4, 2), (4, 4, 4),
]


def literal_eq26(n, m, l, theta_i, theta_r, dphi):
    """KvD eq 26-27 written out with the eq-3 radial polynomial (independent of design_matrix)."""
    a = 4 if (n == 0 or (n == m and l == 0)) else 2 if (n == m or l == 0) else 1
    rho_i = math.sqrt(2) * np.sin(np.radians(theta_i) / 2)
    rho_r = math.sqrt(2) * np.sin(np.radians(theta_r) / 2)
    bracket = zernike_radial(n, l, rho_i) * zernike_radial(m, l, rho_r) + zernike_radial(m, l, rho_i) * zernike_radial(n, l, rho_r)
    return math.sqrt((n + 1) * (m + 1) / a) / (2 * math.pi) * bracket * np.cos(l * np.radians(dphi))


def test_index_rules_eq30_31_give_the_14_modes_of_table_2():
    assert kvd.isotropic_indices(4) == TABLE_2_MODES
    assert [len(kvd.isotropic_indices(n)) for n in range(11)] == [1, 2, 5, 8, 14, 20, 30, 40, 55, 70, 91]


def test_normalisation_a_nml_eq27():
    assert kvd.isotropic_normalisation(0, 0, 0) == 4
    assert kvd.isotropic_normalisation(2, 2, 0) == 4
    assert kvd.isotropic_normalisation(2, 2, 2) == 2
    assert kvd.isotropic_normalisation(2, 0, 0) == 2
    assert kvd.isotropic_normalisation(3, 1, 1) == 1


def test_basis_matches_the_literal_formula_of_eq26():
    rng = np.random.default_rng(1)
    ti, tr, dp = rng.uniform(0, 90, 50), rng.uniform(0, 90, 50), rng.uniform(-180, 180, 50)
    for mode in kvd.isotropic_indices(6):
        # same polynomial by two routes (Jacobi vs factorial sum): rounding only, 1e-12.
        np.testing.assert_allclose(kvd.isotropic_basis(*mode, ti, tr, dp), literal_eq26(*mode, ti, tr, dp), atol=1e-12)


def test_isotropic_basis_is_orthonormal_under_domega_i_domega_r_eq28():
    """KvD eq 28-29 to 1e-10: the product quadrature is exact for these integrands
    (polynomials of degree <= 8 in cos theta, cos(l dphi) with l <= 8), so only rounding
    (~1e-14) remains."""
    order = 8
    q = product_quadrature(n_theta=12, n_phi=24)
    modes = kvd.isotropic_indices(order)
    mu = q.cos_nodes
    a, b, c = np.meshgrid(np.arange(mu.size), np.arange(mu.size), np.arange(q.dphi_nodes.size), indexing="ij")
    x = kvd.design_matrix(modes, mu[a.ravel()], mu[b.ravel()], q.dphi_nodes[c.ravel()])
    w = (q.cos_weights[a] * q.cos_weights[b]).ravel() * q.dphi_weight
    gram = (x * w[:, None]).T @ x
    np.testing.assert_allclose(gram, np.eye(len(modes)), atol=1e-10)


def test_reciprocal_products_h_nmkl_are_orthonormal_and_symmetric_eq20_23():
    """Full 4-d quadrature (both azimuths) up to order 2, exact as above; 1e-10."""
    x, w = np.polynomial.legendre.leggauss(4)
    mu, wmu = 0.5 * (x + 1), 0.5 * w
    phis = 360.0 * np.arange(6) / 6
    theta = np.degrees(np.arccos(mu))
    ti, pi_, tr, pr = (g.ravel() for g in np.meshgrid(theta, phis, theta, phis, indexing="ij"))
    weight = np.einsum("a,b,c,d->abcd", wmu, np.full(6, 2 * math.pi / 6), wmu, np.full(6, 2 * math.pi / 6)).ravel()
    pairs = [(n, k) for n in range(3) for k in range(-n, n + 1, 2)]
    labels = [(n, m, k, l) for i, (n, k) in enumerate(pairs) for (m, l) in pairs[i:]]
    values = np.array([kvd.reciprocal_product(n, m, k, l, ti, pi_, tr, pr) for n, m, k, l in labels])
    np.testing.assert_allclose((values * weight) @ values.T, np.eye(len(labels)), atol=1e-10)
    swapped = np.array([kvd.reciprocal_product(n, m, k, l, tr, pr, ti, pi_) for n, m, k, l in labels])
    np.testing.assert_allclose(swapped, values, atol=1e-14)


@pytest.mark.parametrize("n,l", [(0, 0), (2, 0), (2, 2), (3, 1), (4, 2), (5, 3)])
def test_isotropic_modes_collect_the_two_azimuthal_signs(n, l):
    """sum_{k=+-l} K_n^k(i) K_n^k(r) = c_l I_nnl (c_0 = 1, c_l = sqrt 2): the identity behind
    the mirror and retroreflector amplitudes (eq 32-39); rounding only, 1e-12."""
    ti, pi_, tr, pr = 33.0, 20.0, 57.0, 137.0
    total = sum(hemisphere_basis(n, k, ti, pi_) * hemisphere_basis(n, k, tr, pr) for k in {l, -l})
    c_l = 1.0 if l == 0 else math.sqrt(2)
    assert total == pytest.approx(c_l * kvd.isotropic_basis(n, n, l, ti, tr, pr - pi_), abs=1e-12)


def test_lambert_is_the_lowest_mode_alone_with_amplitude_two_rho():
    """I_000 = 1/(2 pi), so rho/pi = 2 rho I_000 (eq 26-27 with A_000 = 4)."""
    for rho in (0.2, 0.8):
        coefficients = kvd.project("lambert", 6, {"rho": rho})
        assert coefficients[(0, 0, 0)] == pytest.approx(2 * rho, abs=1e-13)  # exact quadrature
        assert np.max(np.abs(coefficients.values[1:])) < 1e-13
        series = kvd.lambert_coefficients(rho).model()
        assert series(10.0, 0.0, 80.0, 33.0) == pytest.approx(rho / math.pi, rel=1e-14)


def test_projection_of_a_series_recovers_its_coefficients_exactly():
    """Round trip: the quadrature is exact for series of order <= n_theta - 1, so
    projecting a series model returns its amplitudes to rounding (1e-12)."""
    rng = np.random.default_rng(3)
    modes = kvd.isotropic_indices(5)
    values = rng.normal(size=len(modes))
    values[0] = 2.0
    series = kvd.KvdCoefficients(tuple(modes), values)
    recovered = kvd.project(series.model(), 5, n_theta=8, n_phi=16)
    np.testing.assert_allclose(recovered.values, values, atol=1e-12)
    assert kvd.relative_l2_error(series.model(), series, n_theta=8, n_phi=16) < 1e-13


def test_series_on_grid_equals_the_design_matrix_path():
    q = product_quadrature(5, 7)
    series = kvd.mirror_coefficients(4) + kvd.lambert_coefficients(0.3)
    grid = series_on_grid(series, q)
    theta = np.degrees(np.arccos(q.cos_nodes))
    direct = series.model()(theta[:, None, None], 0.0, theta[None, :, None], np.degrees(q.dphi_nodes)[None, None, :])
    np.testing.assert_allclose(grid, direct, rtol=1e-12, atol=1e-12)


def test_projection_of_oren_nayar_converges_with_order():
    """Error vs order (docs/kvd.md lists orders 0-10).  Oren-Nayar sigma = 30 deg: the
    projected-solid-angle L2 error falls monotonically over even orders, from 0.217 at
    order 0 to 0.043 at order 8 (measured); the bounds leave 10% room."""
    params = {"rho": 0.8, "sigma": 30.0}
    errors = []
    for order in (0, 2, 4, 8):
        series = kvd.project("oren-nayar", order, params, n_theta=48, n_phi=64)
        errors.append(kvd.relative_l2_error("oren-nayar", series, params, n_theta=48, n_phi=64))
    assert all(later < earlier for earlier, later in zip(errors, errors[1:])), errors
    assert errors[0] > 0.19 and errors[-1] < 0.048, errors


def test_projection_is_converged_in_the_quadrature_size():
    """The low amplitudes of Oren-Nayar change by < 1e-3 between 48 and 96 nodes (the
    kinks of the model limit the quadrature to algebraic convergence)."""
    params = {"rho": 0.8, "sigma": 30.0}
    coarse = kvd.project("oren-nayar", 4, params, n_theta=48, n_phi=64)
    fine = kvd.project("oren-nayar", 4, params, n_theta=96, n_phi=128)
    np.testing.assert_allclose(coarse.values, fine.values, atol=1e-3)


def lobe(series, theta_i, dphi):
    theta_r = np.linspace(0.0, 90.0, 361)
    return theta_r, series(theta_i, 0.0, theta_r, dphi)


def fwhm(theta, values):
    above = theta[values >= values.max() / 2]
    return above.max() - above.min()


def test_mirror_truncation_has_a_specular_lobe_narrowing_with_order_fig4():
    """Fig 4: mirror + small Lambertian part at 45 deg incidence.  From order 4 on the
    maximum lies on the forward side (dphi = 180) near theta_r = 45 deg and the lobe
    narrows with order; abrupt truncation rings (negative side lobes)."""
    widths = []
    for order in (4, 6, 8):
        series = kvd.mirror_coefficients(order) + kvd.lambert_coefficients(0.1)
        theta, forward = lobe(series, 45.0, 180.0)
        _, backward = lobe(series, 45.0, 0.0)
        assert forward.max() > backward.max()
        # the peak sits within 6 deg of the mirror direction (measured: 50.75, 44.75, 47.0)
        assert abs(theta[forward.argmax()] - 45.0) < 6.0
        widths.append(fwhm(theta, forward))
        assert min(forward.min(), backward.min()) < 0.0  # ringing of the abrupt truncation
    assert widths[0] > widths[1] > widths[2], widths


@pytest.mark.parametrize("window", ["fejer", "lanczos"])
def test_damping_reduces_the_ringing_fig4_caption(window):
    """Gradual attenuation removes most of the negative ringing of the order-8 mirror and
    keeps the lobe at the mirror direction; a_000 is not damped."""
    raw = kvd.mirror_coefficients(8) + kvd.lambert_coefficients(0.1)
    damped = kvd.mirror_coefficients(8).damped(window) + kvd.lambert_coefficients(0.1)
    assert damped[(0, 0, 0)] == raw[(0, 0, 0)]
    for theta_i in (22.5, 45.0, 67.5):
        theta, raw_forward = lobe(raw, theta_i, 180.0)
        _, damped_forward = lobe(damped, theta_i, 180.0)
        _, damped_back = lobe(damped, theta_i, 0.0)
        _, raw_back = lobe(raw, theta_i, 0.0)
        raw_floor = min(raw_forward.min(), raw_back.min())
        damped_floor = min(damped_forward.min(), damped_back.min())
        assert damped_floor > 0.2 * raw_floor  # measured: |floor| shrinks 10-400 fold
        assert abs(theta[damped_forward.argmax()] - theta_i) < 8.0  # measured <= 5 deg


@pytest.mark.parametrize("theta_i", [22.5, 45.0, 67.5])
def test_order8_mirror_obeys_the_law_of_reflection_fig5(theta_i):
    """Fig 5: the order-8 lobe follows the incidence angle (measured peaks 24.25, 47.0,
    70.25 deg: within 3 deg of theta_i)."""
    series = kvd.mirror_coefficients(8) + kvd.lambert_coefficients(0.1)
    theta, forward = lobe(series, theta_i, 180.0)
    assert abs(theta[forward.argmax()] - theta_i) < 3.0


@pytest.mark.parametrize("theta_i", [22.5, 45.0, 67.5])
def test_order8_retroreflector_scatters_back_to_the_source_fig6(theta_i):
    """Fig 6: the lobe is on the source side (dphi = 0) at theta_r close to theta_i."""
    series = kvd.retroreflector_coefficients(8) + kvd.lambert_coefficients(0.1)
    theta, backward = lobe(series, theta_i, 0.0)
    _, forward = lobe(series, theta_i, 180.0)
    assert backward.max() > 2 * forward.max()
    assert abs(theta[backward.argmax()] - theta_i) < 3.0


def test_mirror_and_retroreflector_differ_by_the_azimuthal_parity_eq9():
    mirror, retro = kvd.mirror_coefficients(6), kvd.retroreflector_coefficients(6)
    for (n, m, l), value in mirror.as_dict().items():
        assert n == m and value == pytest.approx((-1) ** l * retro[(n, m, l)])


def test_least_squares_recovers_an_exact_series_at_curet_like_geometries():
    """Noise-free samples of an order-4 series at 205 scattered geometries determine its
    14 amplitudes: recovered to 1e-10 (conditioning of a 205 x 14 system)."""
    rng = np.random.default_rng(5)
    ti, tr = rng.uniform(0, 85, 205), rng.uniform(0, 85, 205)
    pi_, pr = rng.uniform(-180, 180, 205), rng.uniform(-180, 180, 205)
    truth = kvd.project("oren-nayar", 4, {"rho": 0.6, "sigma": 20.0}, n_theta=24, n_phi=32)
    data = truth.model()(ti, pi_, tr, pr)
    fit = kvd.fit_series(ti, pi_, tr, pr, data, 4)
    np.testing.assert_allclose(fit.coefficients.values, truth.values, atol=1e-10)
    assert fit.rms_residual < 1e-12


def test_regularisation_shrinks_high_orders_and_leaves_the_albedo_free():
    rng = np.random.default_rng(6)
    ti, tr = rng.uniform(0, 85, 120), rng.uniform(0, 85, 120)
    pi_, pr = rng.uniform(-180, 180, 120), rng.uniform(-180, 180, 120)
    data = gonio.brdf("oren-nayar", ti, pi_, tr, pr, rho=0.7, sigma=25.0) + rng.normal(0, 0.01, 120)
    plain = kvd.fit_series(ti, pi_, tr, pr, data, 6)
    damped = kvd.fit_series(ti, pi_, tr, pr, data, 6, regularization=1e-3)
    high = [j for j, (n, _, _) in enumerate(plain.coefficients.modes) if n >= 4]
    assert np.linalg.norm(damped.coefficients.values[high]) < 0.5 * np.linalg.norm(plain.coefficients.values[high])
    assert damped.rms_residual >= plain.rms_residual  # the penalty can only cost fit quality
    # a constant is unpenalised: regularised fit of Lambert data is exact
    flat = kvd.fit_series(ti, pi_, tr, pr, np.full(120, 0.5 / math.pi), 4, regularization=10.0)
    assert flat.coefficients[(0, 0, 0)] == pytest.approx(1.0, abs=1e-12)


def test_registered_kvd_model_is_the_order2_series_with_lambert_default():
    assert "kvd" in gonio.models.available()
    model = gonio.models.get("kvd")
    assert model.param_names == ("a_0_0_0", "a_1_1_1", "a_2_0_0", "a_2_2_0", "a_2_2_2")
    assert all(p.unit == "-" for p in model.params)
    assert gonio.brdf("kvd", 20.0, 0.0, 70.0, 45.0) == pytest.approx(0.8 / math.pi, rel=1e-14)
    assert model.linear_in == model.param_names and model.reciprocal and not model.energy_conserving
    series = kvd.project("oren-nayar", 2, {"rho": 0.8, "sigma": 20.0}, n_theta=32, n_phi=32)
    values = dict(zip(model.param_names, series.values))
    np.testing.assert_allclose(gonio.brdf("kvd", 30.0, 10.0, 50.0, 200.0, **values), series(30.0, 10.0, 50.0, 200.0), rtol=1e-13)


def test_negative_lowest_amplitude_is_rejected_with_its_range():
    with pytest.raises(ValueError, match=r"a_0_0_0 = -0.5 .*\[0, inf\)"):
        gonio.brdf("kvd", 30, 0, 30, 180, a_0_0_0=-0.5)


@pytest.mark.parametrize(
    "call",
    [
        lambda: kvd.isotropic_indices(-1),
        lambda: kvd.KvdCoefficients.zeros(-1),
        lambda: kvd.mirror_coefficients(-3),
        lambda: kvd.project("lambert", -1),
        lambda: kvd.fit_series(30.0, 0.0, 40.0, 180.0, 0.2, -1),
        lambda: kvd.lambert_coefficients(0.5).truncated(-1),
    ],
)
def test_negative_order_raises_value_error(call):
    with pytest.raises(ValueError, match="order = -[0-9]+ is negative"):
        call()


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: kvd.isotropic_basis(2, 1, 1, 30, 30, 0), "not an isotropic mode"),
        (lambda: kvd.isotropic_basis(2, 2, 0, 95, 30, 0), "theta_i = 95"),
        (lambda: kvd.damping_window([0], 2, "hann"), "damping window 'hann'"),
        (lambda: kvd.fit_series(30.0, 0.0, [40.0, np.nan], 180.0, 0.2, 1), r"theta_r\[1\] = nan"),
        (lambda: kvd.fit_series(30.0, 0.0, 40.0, 180.0, 0.2, 1, regularization=-1), "regularization = -1"),
        (lambda: kvd.project("lambert", 2, {"rho": 2.0}), "rho = 2 .* outside"),
        (lambda: kvd.KvdCoefficients(((0, 0, 0),), [np.nan]), "finite"),
    ],
)
def test_bad_input_messages(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_high_order_series_propagates_nan_and_is_warning_free_at_grazing_and_normal():
    from tests.conftest import special_geometries

    model = (kvd.mirror_coefficients(10) + kvd.lambert_coefficients(0.2)).model()
    ti, pi_, tr, pr = special_geometries()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        values = model(ti, pi_, tr, pr)
        edge = model([np.nan, 30.0, 95.0], 0.0, [30.0, np.nan, 30.0], 180.0)
    assert np.all(np.isfinite(values))
    assert np.isnan(edge[0]) and np.isnan(edge[1]) and edge[2] == 0.0


coefficient = st.floats(-3.0, 3.0)


@settings(max_examples=30, deadline=None)
@given(
    st.lists(coefficient, min_size=14, max_size=14),
    st.floats(0.0, 90.0), st.floats(-180.0, 180.0), st.floats(0.0, 90.0), st.floats(-180.0, 180.0),
)
def test_every_coefficient_set_is_exactly_reciprocal_and_isotropic(values, ti, pi_, tr, pr):
    """Reciprocity by construction (eq 26 is symmetric); isotropy: only phi_r - phi_i
    matters.  1e-12 relative-to-scale covers rounding of cos(l dphi) with l <= 4."""
    values[0] = abs(values[0])
    model = kvd.KvdCoefficients(tuple(TABLE_2_MODES), values).model()
    scale = 1.0 + float(np.sum(np.abs(values)))
    forward = float(model(ti, pi_, tr, pr))
    assert float(model(tr, pr, ti, pi_)) == pytest.approx(forward, abs=1e-12 * scale)
    assert float(model(ti, pi_ + 40.0, tr, pr + 40.0)) == pytest.approx(forward, abs=1e-12 * scale)


def test_cosines_of_multiples_by_recurrence_equal_numpys():
    """The design matrix's azimuthal factors cos(l dphi) by Chebyshev recurrence."""
    from gonio.models.kvd.basis import _cosines_of_multiples

    x = np.random.default_rng(6).uniform(-2 * np.pi, 2 * np.pi, 5000)
    table = _cosines_of_multiples(x, 12)
    for l, values in table.items():
        np.testing.assert_allclose(values, np.cos(l * x), rtol=0, atol=2e-14)
