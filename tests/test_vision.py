"""Rendered shapes and reflectance maps (gonio/vision.py, gonio render; docs/vision.md,
Oren & Nayar section 6)."""
from __future__ import annotations

import numpy as np
import pytest

import gonio
from gonio import vision
from gonio.cli import main


def lambert(rho: float):
    return lambda ti, pi, tr, pr: np.full(np.broadcast(ti, pi, tr, pr).shape, rho / np.pi)


def oren_nayar(sigma: float, rho: float = 0.9):
    return lambda ti, pi, tr, pr: gonio.brdf("oren-nayar-tabulated", ti, pi, tr, pr, rho=rho, sigma=sigma)


def test_a_lambertian_sphere_follows_the_cosine_law_with_its_attached_shadow():
    normals, mask = vision.sphere_normals(61)
    light = vision.direction(60.0, 0.0)
    image = vision.render(lambert(0.5), normals, mask, light)
    cosine = normals @ light
    expected = np.where(mask, 0.5 / np.pi * np.clip(cosine, 0.0, None), np.nan)
    np.testing.assert_allclose(image, expected, rtol=1e-12, atol=1e-15)
    assert np.all(image[mask & (cosine <= 0)] == 0.0)  # attached shadow
    assert np.all(np.isnan(image[~mask]))


def test_the_lambertian_reflectance_map_is_horns_cosine():
    """R(p, q) = rho/pi (1 + p ps + q qs) / (sqrt(1 + p^2 + q^2) sqrt(1 + ps^2 + qs^2)),
    the source's gradient (ps, qs) = (-tan 45 deg, 0) for a source at 45 deg towards +x."""
    p, q = np.meshgrid(np.linspace(-3, 3, 41), np.linspace(-3, 3, 41))
    ps, qs = -1.0, 0.0
    expected = 0.8 / np.pi * np.clip((1 + p * ps + q * qs) / (np.sqrt(1 + p**2 + q**2) * np.sqrt(1 + ps**2 + qs**2)),
                                     0.0, None)
    np.testing.assert_allclose(vision.reflectance_map(lambert(0.8), vision.direction(45.0, 0.0), p, q), expected,
                               rtol=1e-12, atol=1e-15)


def test_a_rough_sphere_lit_from_the_viewer_looks_flatter_than_lambert():
    """Section 6.1 and Fig 3: lit from the viewer, a rough sphere's limb stays bright, its
    centre darker than Lambert's of the same albedo; the flattening grows with roughness."""
    normals, mask = vision.sphere_normals(101)
    view = light = vision.direction(0.0)
    middle = 50
    limb_to_centre = {}
    for sigma in (0.0, 20.0, 40.0):
        image = vision.render(oren_nayar(sigma), normals, mask, light, view)
        limb_to_centre[sigma] = image[middle, middle + 45] / image[middle, middle]  # 0.9 of the radius out
    lambert_ratio = np.cos(np.arcsin(0.9))
    assert limb_to_centre[0.0] == pytest.approx(lambert_ratio, rel=0.02)
    assert lambert_ratio < limb_to_centre[20.0] < limb_to_centre[40.0]
    assert limb_to_centre[40.0] > 1.5 * lambert_ratio


def test_a_rough_patch_changes_brightness_with_the_viewpoint_and_lambert_does_not():
    """Section 6.4: the radiance of a patch seen from two views differs for a rough surface
    (stereo matching and motion estimation that assume constancy are biased), not for
    Lambert's."""
    normal = np.array([[0.0, 0.0, 1.0]])
    mask = np.array([True])
    light = vision.direction(45.0, 0.0)
    views = (vision.direction(40.0, 0.0), vision.direction(40.0, 180.0))
    rough = [vision.render(oren_nayar(30.0), normal, mask, light, v)[0] for v in views]
    flat = [vision.render(lambert(0.9), normal, mask, light, v)[0] for v in views]
    assert flat[0] == flat[1]
    assert rough[0] / rough[1] > 1.3  # brighter towards the source (backscatter)


def test_local_angles_for_a_tilted_normal():
    normal = vision.direction(30.0, 0.0)
    theta_i, theta_r, dphi = vision.local_angles(normal, vision.direction(30.0, 0.0), vision.direction(0.0))
    assert (float(theta_i), float(theta_r)) == pytest.approx((0.0, 30.0), abs=1e-9)
    theta_i, theta_r, dphi = vision.local_angles(normal, vision.direction(60.0, 0.0), vision.direction(0.0))
    assert (float(theta_i), float(theta_r), float(dphi)) == pytest.approx((30.0, 30.0, 180.0), abs=1e-9)


@pytest.mark.parametrize("size", [2, 3.5, -1])
def test_a_shape_needs_three_pixels_or_more(size):
    with pytest.raises(ValueError, match="size must be an integer >= 3"):
        vision.sphere_normals(size)


def test_gonio_render_writes_the_figure_and_the_images(tmp_path, capsys):
    assert main(["render", "oren-nayar:sigma=30,rho=0.9", "--size", "41", "--out", str(tmp_path / "sphere")]) == 0
    assert main(["render", "lambert:rho=0.5", "--shape", "map", "--light", "45,0", "--size", "31",
                 "--out", str(tmp_path / "map")]) == 0
    with np.load(tmp_path / "sphere.npz") as arrays:
        assert {"model_0", "lambert_0", "model_1", "lambert_1"} <= set(arrays.files)
        assert np.nanmax(arrays["lambert_0"]) == pytest.approx(0.9 / np.pi, rel=1e-3)  # albedo of the spec
    with np.load(tmp_path / "map.npz") as arrays:
        np.testing.assert_allclose(arrays["model"], arrays["lambert"], rtol=1e-12)  # Lambert against itself
    assert (tmp_path / "sphere.png").stat().st_size > 10_000
    assert str(tmp_path / "map.png") in capsys.readouterr().out


def test_gonio_render_draws_a_fits_posterior_band(tmp_path):
    from gonio.fitting import Dataset, fit

    theta_r = np.arange(0.0, 80.0, 10.0)
    value = gonio.brdf("oren-nayar-tabulated", 45.0, 0.0, theta_r, 0.0, rho=0.8, sigma=25.0)
    data = Dataset(45.0, 0.0, theta_r, 0.0, value * (1 + 0.01 * np.random.default_rng(1).standard_normal(8)),
                   0.01 * value)
    fit(data, "oren-nayar-tabulated", seed=1, n_walkers=16, max_steps=1500, polish_table=False).save(tmp_path / "fit")
    assert main(["render", str(tmp_path / "fit"), "--size", "31", "--draws", "10", "--light", "30,0",
                 "--out", str(tmp_path / "fitted")]) == 0
    with np.load(tmp_path / "fitted.npz") as arrays:
        low, high, model = arrays["low_0"], arrays["high_0"], arrays["model_0"]
    inside = np.isfinite(model) & (model > 0)
    assert np.all(low[inside] <= high[inside]) and np.any(high[inside] > low[inside])


@pytest.mark.parametrize("argv, words", [
    (["render", "lambert", "--light", "95,0", "--out", "x"], "expected THETA[,PHI] in degrees with 0 <= THETA < 90"),
    (["render", "no-such-model", "--out", "x"], "unknown model"),
    (["render", "lambert", "--out", "/no/such/folder/x"], "does not exist"),
    (["render", "lambert", "--size", "2", "--out", "x"], "--size 2"),
])
def test_bad_render_requests_are_refused_naming_why(argv, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    assert words in capsys.readouterr().err
