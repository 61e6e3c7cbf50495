"""Aperture averaging (gonio.instrument): the effective BRDF a rig with finite apertures sees."""
from __future__ import annotations

import functools
import math

import numpy as np
import pytest

import gonio
from gonio.instrument import aperture_averaged, cone_half_angle, cone_quadrature


def test_cone_half_angle_inverts_solid_angle():
    a = math.radians(cone_half_angle(0.003))
    assert 2 * math.pi * (1 - math.cos(a)) == pytest.approx(0.003, rel=1e-12)
    with pytest.raises(ValueError, match="solid angle"):
        cone_half_angle(0.0)


def test_cone_quadrature_is_centred_and_within_the_cone():
    t, p, w = cone_quadrature([0.0, 40.0], [0.0, 30.0], 0.003)
    assert w.sum() == pytest.approx(1.0, abs=1e-15)
    axis = gonio.geometry.direction(40.0, 30.0)
    dirs = gonio.geometry.direction(t[1], p[1])
    angles = np.degrees(np.arccos(np.clip(dirs @ axis, -1, 1)))
    assert angles[0] == pytest.approx(0.0, abs=1e-6)
    assert np.all(angles <= cone_half_angle(0.003) + 1e-9)
    # the mean direction of a symmetric rule is the axis
    mean = (w[:, None] * dirs).sum(axis=0)
    np.testing.assert_allclose(mean / np.linalg.norm(mean), axis, atol=1e-12)


def test_matches_the_emulators_cone_average_exactly():
    """The analysis model of the apertures equals what the emulated rig measures."""
    world = pytest.importorskip("drivers.emulator.world")
    brdf = functools.partial(gonio.brdf, "oren-nayar", rho=0.9, sigma=30.0)
    model = aperture_averaged("oren-nayar")
    halves = world.cone_half_angle_deg(0.003), world.cone_half_angle_deg(0.0009)
    weights = np.full(7, 1 / 7)
    for g in [(45, 0, 40, 0), (45, 0, 50, 0), (60, 0, 30, 180), (75, -60, 40, 0), (30, 0, 85, 180)]:
        expected = world.cone_averaged_reflectance(brdf, *g, 0.003, 0.0009) / math.cos(math.radians(g[0]))
        # near theta_i = theta_r both take the same 49-point rule: agreement to rounding; elsewhere
        # the emulator's sparse combination of the same cone rules, within its 1e-6
        product = len(world.cone_rule_pairs(g[0], g[2], *halves, weights, weights)[2]) == 49
        assert float(model(*g, rho=0.9, sigma=30.0)) == pytest.approx(expected, rel=1e-12 if product else 1e-6)


def test_lambert_is_unchanged_and_sharp_features_are_smoothed():
    lam = aperture_averaged("lambert")
    # <cos theta_i'> over the lamp cone is cos(theta_i) to second order in the half-angle
    # (1.77 deg): relative change below 5e-4 at theta_i <= 60 deg.
    np.testing.assert_allclose(lam([0, 30, 60], 0, 20, 180, rho=0.5) * np.pi, 0.5, rtol=5e-4)
    point = gonio.brdf("oren-nayar", 45, 0, 45.5, 0, rho=0.9, sigma=30)
    averaged = aperture_averaged("oren-nayar")(45, 0, 45.5, 0, rho=0.9, sigma=30)
    assert averaged < point  # the cut-off peak at theta_r = theta_i is blurred down


def test_fixed_geometry_path_and_shapes():
    model = aperture_averaged("oren-nayar")
    ti = np.array([[30.0, 45.0], [60.0, 75.0]])
    direct = model(ti, 0.0, 20.0, 180.0, rho=0.8, sigma=20.0)
    assert direct.shape == (2, 2)
    np.testing.assert_allclose(model.at(ti, 0.0, 20.0, 180.0)(rho=0.8, sigma=20.0), direct, rtol=1e-13)
    assert model(30.0, 0.0, 20.0, 180.0, rho=0.8, sigma=20.0).shape == ()


@pytest.mark.parametrize("name, params", [
    ("oren-nayar", {"rho": 0.3, "sigma": 80.0, "ir_weight": 0.2}),  # the floor at 0 acts near forward grazing
    ("oren-nayar", {"rho": 0.9, "sigma": 30.0, "ir_weight": 1.0}),
    ("oren-nayar-qualitative", {"rho": 0.7, "sigma": 20.0}),
    ("lambert", {"rho": 0.5}),
])
def test_linear_models_average_their_terms_once_and_equal_the_sub_ray_average(name, params):
    """Models with a LinearForm average its few geometry terms over the 49 sub-rays once;
    the result equals averaging the model at every sub-ray, walker arrays included, and
    where Oren-Nayar's floor at 0 can act the sub-ray average is kept."""
    from gonio.instrument import _SubRays

    rng = np.random.default_rng(1)
    n = 1500
    ti, tr = rng.uniform(0, 90, n), rng.uniform(0, 90, n)
    pi_, pr = rng.uniform(-180, 180, n), rng.uniform(-180, 180, n)
    ti[:60], tr[:60] = rng.uniform(84, 90, 60), rng.uniform(84, 90, 60)
    pr[:60] = pi_[:60] + 180.0  # forward, near grazing
    model = gonio.models.get(name)
    assert getattr(model.at(ti, pi_, tr, pr).prepared, "linear_form", None) is not None
    rays = _SubRays.of(model, *np.radians([ti, pi_, tr, pr]), 0.003, 0.0009, {})
    checked, _ = model.resolve(params)
    if params.get("sigma") == 80.0:
        sub_values = rays.fixed.unchecked(**checked)
        assert np.any(sub_values[rays.fixed._valid] == 0.0)  # the floor really acts here
    fixed = aperture_averaged(name).at(ti, pi_, tr, pr)
    np.testing.assert_allclose(fixed(**params), rays.average(checked, (n,)), rtol=1e-13, atol=0)
    walkers = np.array([[0.3], [0.6], [0.9]])
    expected = np.stack([rays.average(dict(checked, rho=float(w)), (n,)) for w in walkers[:, 0]])
    np.testing.assert_allclose(fixed(**dict(params, rho=walkers)), expected, rtol=1e-13, atol=0)


def test_the_compact_rule_integrates_the_disk_polynomials_it_claims():
    """The compact rule (4 points at radius sqrt(1/2) on the frame's axes, weight 1/4) has
    the unit disk's moments up to degree 3 and the quartic along either axis; not x^2 y^2
    (its rule error). The full rule's moments hold to degree 5."""
    from gonio.instrument import RULES

    def moment(a: int, b: int) -> float:  # mean of x^a y^b over the unit disk (uniform)
        if a % 2 or b % 2:
            return 0.0
        return math.gamma((a + 1) / 2) * math.gamma((b + 1) / 2) / (math.pi * (a + b + 2) / 2 * math.gamma((a + b + 2) / 2))

    for name, degree in (("compact", 3), ("full", 5)):
        r, angle, w = RULES[name]
        x, y = r * np.cos(angle), r * np.sin(angle)
        for a in range(degree + 1):
            for b in range(degree + 1 - a):
                assert float(w @ (x**a * y**b)) == pytest.approx(moment(a, b), abs=1e-15), (name, a, b)
    r, angle, w = RULES["compact"]
    x, y = r * np.cos(angle), r * np.sin(angle)
    assert float(w @ x**4) == pytest.approx(moment(4, 0), abs=1e-15)
    assert float(w @ (x**2 * y**2)) != pytest.approx(moment(2, 2), abs=1e-3)


def test_aperture_rule_keeps_the_full_rule_near_the_horizon_and_the_retro_reflection():
    from gonio.instrument import COMPACT_MAX_THETA_DEG, COMPACT_MIN_SEPARATION_DEG, aperture_rule

    assert COMPACT_MAX_THETA_DEG == 85.0 and COMPACT_MIN_SEPARATION_DEG == 3.0
    got = aperture_rule([30, 85, 85.01, 30, 60, 60, 0], [0, 0, 0, 0, 0, 0, 0],
                        [10, 10, 10, 85.01, 62.9, 63.1, 2.9], [180, 180, 180, 0, 0, 0, 45])
    assert got.tolist() == [True, True, False, False, False, True, False]


def _random_geometries(n: int, seed: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    return (rng.uniform(0, 89.9, n), rng.uniform(-180, 180, n), rng.uniform(0, 89.9, n), rng.uniform(-180, 180, n))


@pytest.mark.parametrize("sigma", [10.0, 30.0, 90.0])
def test_the_compact_rule_agrees_with_the_full_one_to_a_fiftieth_of_the_rigs_noise(sigma):
    """Where aperture_rule chooses it, the compact rule's prediction of the tabulated model
    differs from the full rule's by at most 2.7e-5 relative (measured on 3,000 random
    geometries, sigma 10-90 deg; docs/fitting.md "The aperture average"): a real lab's noise
    per value is 0.15-0.6 %, so 5e-5 (a third of a tenth of the smallest) is the bound.
    Elsewhere (grazing axes, the retro-reflection) the auto rule is the full one exactly."""
    from gonio.instrument import aperture_rule

    geometry = _random_geometries(2000, 7)
    compact = aperture_rule(*geometry)
    assert 0.5 < compact.mean() < 0.99  # both rules are exercised
    full = aperture_averaged("oren-nayar-tabulated", rule="full")(*geometry, rho=0.9, sigma=sigma)
    auto = aperture_averaged("oren-nayar-tabulated")(*geometry, rho=0.9, sigma=sigma)
    difference = np.abs(auto / full - 1.0)
    assert difference[compact].max() < 5e-5
    assert difference[compact].max() > 1e-8  # the rules really differ
    np.testing.assert_array_equal(auto[~compact], full[~compact])


def test_the_compact_rule_at_grazing_incidence_would_not_agree():
    """Why the domain stops at 85 deg: where the lamp's cone (half-angle 1.77 deg) reaches
    the horizon the compact rule misses the full one by far more than a tenth of the rig's
    noise (1.5e-4; measured 5.6e-3 and 6.9e-3 here)."""
    forced = aperture_averaged("oren-nayar-tabulated", rule="compact")
    full = aperture_averaged("oren-nayar-tabulated", rule="full")
    for g in [(88.0, 0.0, 88.0, 0.0), (89.0, 0.0, 30.0, 180.0)]:
        assert abs(float(forced(*g, rho=0.9, sigma=30.0)) / float(full(*g, rho=0.9, sigma=30.0)) - 1.0) > 1.5e-3


def test_models_outside_the_validated_list_keep_the_full_rule():
    """The compact rule was validated for smooth diffuse models only; eq 33-35 (its kink at
    theta_r = theta_i) and Torrance-Sparrow (a specular lobe) keep the full rule."""
    geometry = _random_geometries(200, 3)
    for name, params in (("oren-nayar", {"rho": 0.8, "sigma": 25.0}), ("torrance-sparrow", {})):
        np.testing.assert_array_equal(aperture_averaged(name)(*geometry, **params),
                                      aperture_averaged(name, rule="full")(*geometry, **params))
    with pytest.raises(ValueError, match="aperture rule"):
        aperture_averaged("lambert", rule="coarse")
