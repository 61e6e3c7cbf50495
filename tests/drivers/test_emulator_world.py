"""Geometry and radiometry of the emulated lab (Oren & Nayar 1995, section 5, Fig. 15)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.emulator.world import (
    Optics,
    camera_angles,
    cone_averaged_reflectance,
    cone_half_angle_deg,
    cone_quadrature,
    footprint_coverage,
    separation_deg,
    unit_vector,
)


def test_camera_side_convention():
    # docs/protocol.md: camera at polar |a1|, azimuth 0 for a1 >= 0 and 180 for a1 < 0.
    assert camera_angles(30.0) == (30.0, 0.0)
    assert camera_angles(-30.0) == (30.0, 180.0)
    assert camera_angles(0.0) == (0.0, 0.0)


def test_separation_angle():
    assert separation_deg(30.0, 30.0, 0.0) == pytest.approx(0.0, abs=1e-9)  # retro-reflection
    assert separation_deg(-30.0, 30.0, 0.0) == pytest.approx(60.0)  # mirror direction
    assert separation_deg(0.0, 45.0, 123.0) == pytest.approx(45.0)
    assert separation_deg(40.0, 40.0, 90.0) == pytest.approx(
        np.degrees(np.arccos(np.cos(np.radians(40)) ** 2)))


@settings(max_examples=40, deadline=None)
@given(theta=st.floats(0.0, 89.0), phi=st.floats(-180.0, 180.0), omega=st.sampled_from([0.0009, 0.003, 0.05]))
def test_cone_quadrature_directions_lie_in_the_cone_and_weights_sum_to_one(theta, phi, omega):
    t, p, w = cone_quadrature(theta, phi, omega)
    axis = unit_vector(theta, phi)
    angles = np.degrees(np.arccos(np.clip(unit_vector(t, p) @ axis, -1, 1)))
    assert w.sum() == pytest.approx(1.0)
    assert np.all(angles <= cone_half_angle_deg(omega) + 1e-6)


def test_cone_quadrature_mean_of_cosine_is_exact():
    # Mean of cos(beta) over a cone of half-angle a, uniform in solid angle: (1 + cos a) / 2.
    # cos(beta) = 1 - r^2 / 2 in the equal-area disk variable r: a degree-2 polynomial, which
    # the 7-point rule integrates exactly.
    omega = 0.05
    a = np.radians(cone_half_angle_deg(omega))
    t, p, w = cone_quadrature(20.0, 40.0, omega)
    cos_beta = unit_vector(t, p) @ unit_vector(20.0, 40.0)
    assert w @ cos_beta == pytest.approx((1 + np.cos(a)) / 2, rel=1e-12)


def test_lambertian_cone_average_equals_rho_cos_over_pi():
    lambert = lambda ti, pi, tr, pr: np.full(np.broadcast(ti, pi, tr, pr).shape, 0.8 / np.pi)
    for theta_i in (0.0, 30.0, 60.0):
        value = cone_averaged_reflectance(lambert, theta_i, 0.0, 20.0, 180.0)
        # Averaging cos(theta_i) over the 0.003 sr lamp cone changes it by < 3e-4 (relative).
        assert value == pytest.approx(0.8 * np.cos(np.radians(theta_i)) / np.pi, rel=3e-4)


def test_cone_average_near_the_horizon_drops_directions_below_it():
    lambert = lambda ti, pi, tr, pr: np.full(np.broadcast(ti, pi, tr, pr).shape, 1 / np.pi)
    at_horizon = cone_averaged_reflectance(lambert, 90.0, 0.0, 10.0, 0.0)
    # Half the lamp cone (half-angle R = 1.77 deg) is below the horizon. Above it cos(theta_i)
    # is the elevation; its mean over the cone is (1/2) * 4R/(3 pi) (half-disk centroid). The
    # integrand has a kink at the horizon, where the 7-point rule is not exact: 10 %.
    R = np.radians(cone_half_angle_deg(0.003))
    assert at_horizon == pytest.approx(0.5 * 4 * R / (3 * np.pi) / np.pi, rel=0.1)
    assert cone_averaged_reflectance(lambert, 30.0, 0.0, 90.0, 0.0) == pytest.approx(
        0.5 * np.cos(np.radians(30)) / np.pi, rel=0.05)  # half the camera cone sees the sample


def test_cone_average_of_a_smooth_brdf_is_close_to_its_centre_value():
    def lobe(ti, pi, tr, pr):  # smooth forward lobe
        return 0.3 + 0.2 * np.cos(np.radians(ti)) * np.cos(np.radians(tr)) ** 3 + 0.0 * pi + 0.0 * pr

    value = cone_averaged_reflectance(lobe, 40.0, 0.0, 30.0, 180.0)
    centre = lobe(40.0, 0.0, 30.0, 180.0) * np.cos(np.radians(40.0))
    assert value == pytest.approx(centre, rel=1e-3)  # second-order effect of ~1.8 deg cones


def test_paper_rig_numbers():
    o = Optics()
    assert o.sample_side_mm == pytest.approx(2 * 25.4)
    assert o.distance_mm == pytest.approx(6 * 304.8)
    assert (o.width, o.height) == (512, 480)
    assert (o.lamp_solid_angle_sr, o.camera_solid_angle_sr) == (0.003, 0.0009)
    assert o.sample_size_px == pytest.approx(50.8 * 150 / 1828.8 / 0.015)


@pytest.mark.parametrize("theta_r", [0.0, 30.0, 60.0, 85.0, 90.0])
def test_footprint_is_foreshortened_rectangle(theta_r):
    o = Optics()
    cov = footprint_coverage(o, theta_r)
    assert cov.shape == (480, 512) and cov.min() >= 0 and cov.max() <= 1
    area = o.sample_size_px**2 * np.cos(np.radians(theta_r))
    assert cov.sum() == pytest.approx(area, abs=1e-6)
    # Symmetric about the image centre (256, 240) in pixel-edge coordinates.
    assert np.allclose(cov, cov[::-1, ::-1])


def _product_cone_average(brdf, theta_i, phi_i, theta_r, phi_r, lamp_sr=0.003, camera_sr=0.0009):
    """The full 7 x 7 product of the two cone rules, written out."""
    from drivers.emulator.world import _above_horizon

    ti, pi_, wi = cone_quadrature(theta_i, phi_i, lamp_sr)
    tr, pr, wr = cone_quadrature(theta_r, phi_r, camera_sr)
    lit, seen = _above_horizon(ti), _above_horizon(tr)
    f = np.broadcast_to(brdf(ti[:, None], pi_[:, None], tr[None, :], pr[None, :]), (7, 7))
    terms = np.where((lit[:, None] > 0) & (seen[None, :] > 0), f * np.cos(np.radians(ti))[:, None], 0.0)
    return (wi * lit) @ terms @ (wr * seen)


def test_sparse_cone_average_agrees_with_the_product_where_the_integrand_is_smooth():
    from drivers.emulator.world import cone_rule_pairs

    import gonio

    exact = lambda ti, pi, tr, pr: gonio.brdf("oren-nayar-exact", ti, pi, tr, pr, rho=0.9, sigma=30.0)
    for geometry in [(75.0, 0.0, 40.0, 180.0), (60.0, 0.0, 20.0, 0.0), (45.0, 0.0, 83.6, 25.9), (30.0, 0.0, 10.0, 180.0)]:
        pairs = cone_rule_pairs(geometry[0], geometry[2], 1.771, 0.97, np.full(7, 1 / 7), np.full(7, 1 / 7))
        assert len(pairs[2]) == 13  # the sparse combination is the one used here
        assert cone_averaged_reflectance(exact, *geometry) == pytest.approx(
            _product_cone_average(exact, *geometry), rel=1e-6)


def test_sparse_cone_average_misses_only_products_of_degree_four():
    # A smooth integrand with strong terms in both cones' offsets: every term of degree <= 3
    # is integrated exactly, the error is a degree-4 cross term, ~half_l^2 half_c^2 x its size.
    smooth = lambda ti, pi, tr, pr: (1 + 0.5 * np.sin(np.radians(3 * ti + 2 * pi)) * np.cos(np.radians(4 * tr - pr)))
    value = cone_averaged_reflectance(smooth, 50.0, 10.0, 20.0, 170.0)
    product = _product_cone_average(smooth, 50.0, 10.0, 20.0, 170.0)
    assert value == pytest.approx(product, rel=1e-7)
    assert value != product  # two different rules, not one rule twice


def test_cone_average_uses_the_full_product_near_the_kink_and_the_horizon():
    import gonio

    approx = lambda ti, pi, tr, pr: gonio.brdf("oren-nayar", ti, pi, tr, pr, rho=0.9, sigma=30.0)
    # Retro-reflection (theta_i = theta_r, same azimuth): the functional form's kink lies inside
    # both cones; the sparse combination would be 5e-3 off, the product is used.
    for geometry in [(75.0, 0.0, 75.0, 0.0), (60.0, 0.0, 58.0, 180.0), (30.0, 0.0, 89.5, 180.0)]:
        assert cone_averaged_reflectance(approx, *geometry) == pytest.approx(
            _product_cone_average(approx, *geometry), rel=1e-13)
