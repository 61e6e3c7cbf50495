"""Photometric stereo under Lambert and under a rough model, with per-pixel uncertainty
(gonio/vision/stereo.py, gonio stereo; docs/vision.md, Oren & Nayar section 6.3,
Figs 26-27)."""
from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import pytest

import gonio
from gonio import vision
from gonio.cli import main

LIGHTS = ((30.0, 0.0), (30.0, 90.0), (30.0, 180.0), (30.0, 270.0))


def lambert(rho: float):
    return lambda ti, pi, tr, pr: np.full(np.broadcast(ti, pi, tr, pr).shape, rho / np.pi)


def tabulated(sigma: float, rho: float = 0.8):
    return lambda ti, pi, tr, pr: gonio.brdf("oren-nayar-tabulated", ti, pi, tr, pr, rho=rho, sigma=sigma)


def images_of(brdf, size: int = 41, lights=LIGHTS, shape=vision.sphere_normals):
    normals, mask = shape(size)
    images = np.stack([vision.render(brdf, normals, mask, vision.direction(*light)) for light in lights])
    lit3 = mask & (np.sum(np.nan_to_num(images) > 0, axis=0) >= 3)
    return images, normals, mask, lit3


def test_lambertian_least_squares_recovers_a_lambertian_sphere_and_its_albedo_exactly():
    images, normals, mask, lit3 = images_of(lambert(0.6))
    result = vision.lambertian_stereo(images, LIGHTS, mask)
    assert np.max(vision.angular_error(result.normals, normals)[lit3]) < 1e-5  # arccos near 1: ~1e-6 deg
    np.testing.assert_allclose(result.scale[lit3], 0.6, rtol=1e-9)


def test_the_model_inversion_recovers_the_surface_it_was_given_and_lambert_does_not():
    """The inversion of the model that made the images is exact (noise-free); Lambertian
    least squares on a rough sphere errs by degrees (the paper's Fig 26(a))."""
    images, normals, mask, lit3 = images_of(tabulated(30.0))
    rough = vision.photometric_stereo(images, LIGHTS, tabulated(30.0), mask)
    flat = vision.photometric_stereo(images, LIGHTS, None, mask)
    assert np.percentile(vision.angular_error(rough.normals, normals)[lit3], 99) < 0.05
    assert np.percentile(np.abs(rough.scale[lit3] - 1.0), 99) < 1e-3  # the albedo scale of the model itself
    assert np.mean(vision.angular_error(flat.normals, normals)[lit3]) > 3.0


def test_the_rough_model_halves_lamberts_error_on_a_sphere_it_did_not_render():
    """Images of the functional model (eq 33-35) inverted with the table of the exact one:
    the issue's target, the rough model's mean error at most half of Lambert's, at
    sigma 20 and 40 deg."""
    for sigma in (20.0, 40.0):
        brdf = lambda ti, pi, tr, pr, s=sigma: gonio.brdf("oren-nayar", ti, pi, tr, pr, rho=0.8, sigma=s)  # noqa: E731
        images, normals, mask, lit3 = images_of(brdf)
        rough = vision.photometric_stereo(images, LIGHTS, tabulated(sigma), mask)
        flat = vision.lambertian_stereo(images, LIGHTS, mask)
        rough_error = np.mean(vision.angular_error(rough.normals, normals)[lit3])
        flat_error = np.mean(vision.angular_error(flat.normals, normals)[lit3])
        assert rough_error <= 0.5 * flat_error, (sigma, rough_error, flat_error)


def _coverage(images, normals, mask, lit3, model, noise_sd, stated_sd, seeds=3):
    out = []
    for seed in range(seeds):
        noisy = images + np.random.default_rng(seed).normal(0.0, noise_sd, images.shape)
        result = vision.photometric_stereo(noisy, LIGHTS, model, mask, noise_sd=stated_sd)
        out.append(np.mean(result.covers(normals)[lit3]))
    return float(np.mean(out)), result


def test_the_95_percent_regions_hold_the_true_normal_about_95_percent_of_the_time():
    images, normals, mask, lit3 = images_of(tabulated(30.0))
    sd = 0.01 * np.nanmax(images)
    coverage, result = _coverage(images, normals, mask, lit3, tabulated(30.0), sd, sd)
    assert 0.92 <= coverage <= 0.98
    assert result.variance_factor == pytest.approx(1.0, abs=0.25)  # the stated noise is the noise


def test_noise_understated_threefold_widens_the_regions_by_the_measured_factor():
    images, normals, mask, lit3 = images_of(tabulated(30.0))
    sd = 0.01 * np.nanmax(images)
    coverage, result = _coverage(images, normals, mask, lit3, tabulated(30.0), sd, sd / 3.0)
    assert result.variance_factor == pytest.approx(9.0, rel=0.25)
    assert 0.92 <= coverage <= 0.98


def test_where_the_widening_fails_a_discrepancy_the_orientation_absorbs():
    """The limit of the Birge widening, measured: images of the functional model (eq 33-35)
    inverted with the exact model's table at sigma 40 deg and 0.2 % noise. The residuals
    show the misfit (factor 1.5), but most of the formulas' difference moves the
    normal and the albedo scale, where no residual sees it: the regions hold the truth at
    far below 95 % (docs/vision.md)."""
    brdf = lambda ti, pi, tr, pr: gonio.brdf("oren-nayar", ti, pi, tr, pr, rho=0.8, sigma=40.0)  # noqa: E731
    images, normals, mask, lit3 = images_of(brdf, size=61)
    sd = 0.002 * np.nanmax(images)
    noisy = images + np.random.default_rng(0).normal(0.0, sd, images.shape)
    result = vision.photometric_stereo(noisy, LIGHTS, tabulated(40.0), mask, noise_sd=sd)
    assert result.variance_factor > 1.3  # the misfit is seen (1.54 measured)
    assert np.mean(result.covers(normals)[lit3]) < 0.8


def test_without_stated_noise_the_variance_comes_from_the_residuals():
    images, normals, mask, lit3 = images_of(tabulated(30.0))
    sd = 0.01 * np.nanmax(images)
    noisy = images + np.random.default_rng(0).normal(0.0, sd, images.shape)
    result = vision.photometric_stereo(noisy, LIGHTS, tabulated(30.0), mask)
    assert result.variance_factor == pytest.approx(sd**2, rel=0.25)
    assert 0.9 <= np.mean(result.covers(normals)[lit3]) <= 0.99


@dataclass
class _Material:
    """A material with posterior draws of sigma (gonio.export.Material's interface)."""

    sigmas: np.ndarray
    source: str = "draws"
    model: str = "oren-nayar-tabulated"

    @property
    def draws(self):
        return self.sigmas[:, None]

    def brdf(self, ti, pi, tr, pr):
        return tabulated(float(np.median(self.sigmas)))(ti, pi, tr, pr)

    def draw_brdf(self, ti, pi, tr, pr, rows):
        return np.stack([tabulated(float(self.sigmas[k]))(ti, pi, tr, pr) for k in rows])


def test_a_models_posterior_draws_widen_the_regions():
    images, normals, mask, lit3 = images_of(tabulated(30.0), size=31)
    sd = 0.005 * np.nanmax(images)
    noisy = images + np.random.default_rng(0).normal(0.0, sd, images.shape)
    narrow = vision.photometric_stereo(noisy, LIGHTS, _Material(np.full(8, 30.0)), mask, noise_sd=sd)
    wide = vision.photometric_stereo(noisy, LIGHTS, _Material(np.linspace(15.0, 45.0, 8)), mask, noise_sd=sd)
    assert np.median(wide.cone_deg()[lit3]) > 1.2 * np.median(narrow.cone_deg()[lit3])


def test_the_vase_two_sources_albedo_known_normals_in_a_plane():
    """Section 6.3, Figs 26-27: a cylinder under sources at -10 and +10 deg, sigma 40 deg,
    rho 0.7: with the albedo known and the normals held in the horizontal plane the rough
    model recovers the profile, Lambert flattens the middle and errs by tens of degrees."""
    lights = ((10.0, 180.0), (10.0, 0.0))
    images, normals, mask, _ = images_of(tabulated(40.0, 0.7), lights=lights, shape=vision.cylinder_normals)
    options = {"albedo_known": True, "in_plane_of": (0.0, 1.0, 0.0)}
    rough = vision.photometric_stereo(images, lights, tabulated(40.0, 0.7), mask, **options)
    flat = vision.photometric_stereo(images, lights, lambert(0.7), mask, **options)
    inner = mask & (np.abs(normals[..., 0]) < 0.9)
    assert np.max(np.abs(rough.normals[..., 1][mask])) < 1e-12  # in the plane
    assert np.max(vision.angular_error(rough.normals, normals)[inner]) < 0.2
    assert np.max(vision.angular_error(flat.normals, normals)[inner]) > 20.0
    middle = images.shape[1] // 2
    truth = vision.height_profile(np.where(mask[middle][:, None], normals[middle], np.nan), 2.0 / 40)
    assert np.nanmax(np.abs(vision.height_profile(rough.normals[middle], 2.0 / 40) - truth)) < 0.01
    assert np.nanmax(np.abs(vision.height_profile(flat.normals[middle], 2.0 / 40) - truth)) > 0.1
    assert rough.dof == 1 and np.all(rough.covariance[inner][:, 1, 1] == 0.0)


def test_pixels_lit_by_too_few_sources_are_not_determined():
    images, normals, mask, lit3 = images_of(tabulated(30.0))
    sd = 0.01 * np.nanmax(images)
    noisy = images + np.random.default_rng(0).normal(0.0, sd, images.shape)
    result = vision.photometric_stereo(noisy, LIGHTS, tabulated(30.0), mask, noise_sd=sd)
    lit2 = mask & (np.sum(images > 0, axis=0) <= 2)
    assert np.any(lit2) and not np.all(result.determined[lit2])
    assert np.all(result.cone_deg()[mask & ~result.determined] == 90.0)
    assert np.all(result.covers(normals)[mask & ~result.determined])


@pytest.mark.parametrize("call, words", [
    (lambda: vision.photometric_stereo(np.zeros((4, 5)), LIGHTS, None), "shape (K, H, W)"),
    (lambda: vision.photometric_stereo(np.zeros((4, 5, 5)), LIGHTS[:3], None), "one per image"),
    (lambda: vision.photometric_stereo(np.zeros((2, 5, 5)), LIGHTS[:2], lambert(0.5)), "at least 3 images"),
    (lambda: vision.photometric_stereo(np.zeros((4, 5, 5)), LIGHTS, None, noise_sd=0.0), "noise_sd must be positive"),
    (lambda: vision.photometric_stereo(np.zeros((4, 5, 5)), LIGHTS, None, albedo_known=True), "pass Lambert's BRDF"),
    (lambda: vision.photometric_stereo(np.zeros((4, 5, 5)), LIGHTS, lambert(0.5), np.ones((4, 4), bool)),
     "mask must have the images' shape"),
    (lambda: vision.photometric_stereo(np.zeros((4, 5, 5)), LIGHTS, lambert(0.5), in_plane_of=(0, 0, 0)),
     "non-zero 3-vector"),
])
def test_bad_stereo_input_is_refused_naming_what_was_wrong(call, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
        call()


def test_gonio_stereo_renders_inverts_and_reports(tmp_path, capsys):
    out = tmp_path / "ps"
    assert main(["stereo", "oren-nayar:sigma=30,rho=0.8", "--model", "oren-nayar-tabulated:sigma=30,rho=0.8",
                 "--size", "31", "--add-noise", "0.01", "--out", str(out)]) == 0
    record = json.loads((tmp_path / "ps.json").read_text())
    lambert_result, model_result = record["results"]["Lambert"], record["results"]["model"]
    assert model_result["mean_error_deg"] < 0.5 * lambert_result["mean_error_deg"]
    assert record["noise_sd"] > 0 and 0.0 <= model_result["coverage"] <= 1.0
    with np.load(tmp_path / "ps.npz") as arrays:
        assert arrays["normals_model"].shape == (31, 31, 3)
    assert (tmp_path / "ps.png").stat().st_size > 10_000
    assert "95 % regions hold the true normal" in capsys.readouterr().out


def test_gonio_stereo_reads_the_images_gonio_render_wrote(tmp_path):
    lights = ["--light", "30,0", "--light", "30,120", "--light", "30,240"]
    assert main(["render", "oren-nayar-tabulated:sigma=20,rho=0.8", "--size", "25", *lights,
                 "--out", str(tmp_path / "sphere")]) == 0
    assert main(["stereo", str(tmp_path / "sphere.npz"), "--model", "oren-nayar-tabulated:sigma=20,rho=0.8",
                 "--out", str(tmp_path / "ps")]) == 0
    record = json.loads((tmp_path / "ps.json").read_text())
    assert record["results"]["model"]["median_error_deg"] < 0.05  # the model that rendered them


@pytest.mark.parametrize("argv, words", [
    (["stereo", "lambert", "--model", "no-such-model", "--out", "x"], "unknown model"),
    (["stereo", "lambert", "--model", "lambert", "--out", "/no/such/folder/x"], "does not exist"),
    (["stereo", "lambert", "--model", "lambert", "--add-noise", "-1", "--out", "x"], "--add-noise > 0"),
    (["stereo", "bad.npz", "--model", "lambert", "--out", "x"], "no 'lights_deg'"),
])
def test_bad_stereo_requests_are_refused_naming_why(argv, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    np.savez(tmp_path / "bad.npz", images=np.zeros((3, 4, 4)))
    assert main(argv) == 2
    assert words in capsys.readouterr().err


def test_gonio_stereo_inverts_a_fit_and_its_posterior(tmp_path):
    """A fit folder as the model: its posterior medians are inverted and its draws widen
    the regions (docs/vision.md)."""
    from gonio.fitting import Dataset, fit

    ti, tr, pr = (a.ravel() for a in np.meshgrid([0.0, 30.0, 60.0], np.arange(0.0, 81.0, 10.0), [0.0, 90.0, 180.0],
                                                  indexing="ij"))
    value = gonio.brdf("oren-nayar-tabulated", ti, 0.0, tr, pr, rho=0.8, sigma=30.0)
    data = Dataset(ti, 0.0, tr, pr, value * (1 + 0.01 * np.random.default_rng(0).standard_normal(value.size)),
                   0.01 * value)
    fit(data, "oren-nayar-tabulated", seed=0, n_walkers=16, max_steps=1500, polish_table=False).save(tmp_path / "fit")
    argv = ["stereo", "oren-nayar-tabulated:sigma=30,rho=0.8", "--model", str(tmp_path / "fit"), "--size", "25",
            "--add-noise", "0.01"]
    assert main([*argv, "--draws", "4", "--out", str(tmp_path / "with")]) == 0
    assert main([*argv, "--draws", "0", "--out", str(tmp_path / "without")]) == 0
    with_draws, without = (json.loads((tmp_path / f"{name}.json").read_text())["results"]["model"]
                           for name in ("with", "without"))
    assert with_draws["median_error_deg"] < 2.0
    assert with_draws["median_cone_deg"] >= without["median_cone_deg"]
