"""``gonio curet``: the CUReT data (Dana, van Ginneken, Nayar & Koenderink, ACM TOG 18(1),
1999) listed, exported as a fitting CSV and fitted; the noise model; the default folder.

The fits here are least squares or tiny MCMC runs; the full MCMC study is
benchmarks/curet_fits.py (docs/curet-fits.md).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import gonio
from gonio.cli import main
from gonio.fitting.results import EXIT_INADEQUATE
from gonio.cli.curet import (
    DEFAULT_CANDIDATES,
    QUANTISATION_STEP,
    candidate_slug,
    curet_dataset,
    default_curet_dir,
    estimate_relative_noise,
    load_curet,
    select_geometries,
)
from gonio.fitting import Dataset, FitResult, fit

REPO = Path(__file__).resolve().parents[1]
HAVE_DATA = (default_curet_dir() / "abrdf.dat").is_file()
needs_data = pytest.mark.skipif(not HAVE_DATA, reason=f"CUReT files not found in {default_curet_dir()}")


@pytest.fixture(scope="module")
def curet():
    return load_curet()


# ---------------------------------------------------------------------- data folder
def test_default_folder_is_shared_data_beside_the_checkout(monkeypatch):
    monkeypatch.delenv("GONIO_CURET_DIR", raising=False)
    assert default_curet_dir() == REPO.parent / "shared" / "data" / "curet"


def test_environment_variable_overrides_the_default_folder(monkeypatch, tmp_path):
    monkeypatch.setenv("GONIO_CURET_DIR", str(tmp_path))
    assert default_curet_dir() == tmp_path


def test_missing_data_folder_is_a_one_line_error_naming_the_folder(tmp_path, capsys):
    assert main(["curet", "list", "--data", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"CUReT folder {tmp_path} lacks abrdf.dat and table.txt" in err
    assert "Traceback" not in err


# ---------------------------------------------------------------------- noise model
def _curet_like_geometry(n: int = 205, seed: int = 3):
    rng = np.random.default_rng(seed)
    return (rng.uniform(0, 84, n), rng.uniform(-180, 180, n), rng.uniform(0, 84, n), rng.uniform(-180, 180, n))


def test_noise_estimate_recovers_a_known_relative_scatter():
    """Oren-Nayar (eq 33-35, rho 0.8, sigma 20 deg) with 4 % Gaussian relative noise: the
    estimated s lies in [0.034, 0.050].  Tolerance: the statistical error of s from 175
    degrees of freedom is s / sqrt(2 x 175) = 5 % of s (0.002); the series' interpolation
    error adds up to ~0.015 in quadrature (measured 0.014 without noise on the CUReT
    geometries), which can raise s to ~0.043; the bounds leave 2-3 statistical sigma."""
    geometry = _curet_like_geometry()
    clean = gonio.brdf("oren-nayar", *geometry, rho=0.8, sigma=20.0)
    noisy = clean * (1.0 + 0.04 * np.random.default_rng(11).standard_normal(clean.size))
    estimate = estimate_relative_noise(*geometry, noisy)
    assert 0.034 < estimate.relative < 0.050
    assert estimate.method == "kvd-scatter"
    # sigma follows the smooth reference, not the noisy value: proportional to it within
    # the quantisation floor (q / (s f) < 1e-3 here, hence rtol 1e-5 on the squares).
    expected = np.sqrt((estimate.relative * estimate.smooth) ** 2 + QUANTISATION_STEP**2 / 12.0)
    np.testing.assert_allclose(estimate.sigma, expected, rtol=1e-12)
    # The smooth reference tracks the true BRDF: 1.3 % rms relative deviation measured; the
    # bound 2.5 % allows the noise carried into 30 amplitudes, 4 % x sqrt(30/205) = 1.5 %,
    # on top of the interpolation error (0.7 % without noise on these geometries).
    deviation = (estimate.smooth - clean) / clean
    assert np.sqrt(np.mean(deviation**2)) < 0.025


def test_noise_free_lambert_gives_only_the_quantisation_floor():
    """A Lambertian BRDF is the lowest KvD mode exactly (KvD eq 26-27), so the scatter is 0
    to rounding and sigma equals the rounding floor 0.001/sqrt(12) sr^-1."""
    geometry = _curet_like_geometry()
    value = np.full(205, 0.7 / np.pi)
    estimate = estimate_relative_noise(*geometry, value)
    assert estimate.relative < 1e-10
    np.testing.assert_allclose(estimate.sigma, QUANTISATION_STEP / np.sqrt(12.0), rtol=1e-8)


def test_fixed_relative_noise_and_too_few_geometries():
    geometry = _curet_like_geometry(40)
    value = gonio.brdf("lambert", *geometry, rho=0.5)
    with pytest.raises(ValueError, match="40 geometries are too few") as error:
        estimate_relative_noise(*geometry, value)
    assert "--noise relative:S" in str(error.value)
    fixed = estimate_relative_noise(*geometry, value, relative=0.05)
    assert fixed.method == "fixed" and fixed.relative == 0.05
    np.testing.assert_allclose(fixed.sigma, np.hypot(0.05 * 0.5 / np.pi, QUANTISATION_STEP / np.sqrt(12.0)), rtol=1e-6)


# ---------------------------------------------------------------------- real data
@needs_data
def test_units_are_absolute_brdf_white_plaster_is_about_rho_over_pi(curet):
    """Data README: absolute BRDF [1/sr].  A white matte sample has f ~ rho/pi: plaster_a
    (sample 10) has pi x median = 0.80 (measured 0.801), a plausible albedo for white
    plaster (Oren & Nayar fit rho = 0.90 to their wall plaster, Fig 16); a reflectance
    factor (values ~rho) or a percentage would give 0.25 or 25 here."""
    assert np.pi * np.median(curet.sample("plaster_a").brdf) == pytest.approx(0.80, abs=0.01)


@needs_data
def test_rough_samples_have_no_negative_values_and_no_saturation_plateau(curet):
    """The geometry-selection decision: nothing is dropped for samples 6, 10, 11, 30: no
    negative value, and the maximum is not repeated (a clipped detector would give a flat
    top of equal values; the values are printed to 0.001)."""
    for number in (6, 10, 11, 30):
        brdf = curet.sample(number).brdf
        assert brdf.min() > 0.05
        assert np.count_nonzero(brdf == brdf.max()) == 1


@needs_data
def test_selection_rules_drop_what_they_say(curet):
    """12 geometries lie within 15 deg of the mirror direction (checked by hand against
    the table: their lamp-camera separation is 135 or 157.5 deg); 28 values of sample 61
    are negative (gonio.curet notes)."""
    keep, dropped = select_geometries(curet.sample(6), exclude_specular=15.0)
    assert dropped == {"near_specular": 12, "negative": 0} and keep.sum() == 193
    keep, dropped = select_geometries(curet.sample(61), drop_negative=True)
    assert dropped["negative"] == 28 and (curet.sample(61).brdf[keep] >= 0).all()
    with pytest.raises(ValueError, match="exclude_specular = 95 deg is outside"):
        select_geometries(curet.sample(6), exclude_specular=95.0)


@needs_data
def test_oren_nayar_fits_plaster_a_to_its_noise_level(curet):
    """Oren & Nayar eq 33-35 with ir_weight = 1, least squares, sample 10 (plaster_a), all
    205 geometries: reduced chi-square 1.85, rho 0.840 +/- 0.0024, sigma 20.46 +/- 0.28 deg
    measured (the full MCMC study: docs/curet-fits.md).  Bounds: redchi < 2.5 (a wrong
    reader, angle convention or unit gives far more: Lambert gives 32.6); parameters to
    0.01 and 1 deg, 3 standard errors after scaling them by sqrt(redchi) = 1.36."""
    dataset, noise = curet_dataset(curet, "plaster_a")
    assert dataset.n == 205 and noise.relative == pytest.approx(0.0364, abs=0.001)
    result = fit(dataset, "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=False)
    values = result.best_values()
    assert result.least_squares.redchi < 2.5
    assert values["rho"] == pytest.approx(0.840, abs=0.01)
    assert values["sigma"] == pytest.approx(20.46, abs=1.0)
    lambert = fit(dataset, "lambert", mcmc=False)
    assert lambert.least_squares.redchi > 10.0


@needs_data
def test_reciprocal_fit_does_not_depend_on_the_angle_order(curet):
    """Oren-Nayar is reciprocal (eq 33-35 depend on max/min of the polar angles), so
    reading table.txt source-first gives the same least-squares fit (1e-6: solver
    tolerance)."""
    swapped = load_curet(angle_order="illumination-first")
    a = fit(curet_dataset(curet, 10)[0], "oren-nayar-qualitative", mcmc=False).best_values()
    b = fit(curet_dataset(swapped, 10)[0], "oren-nayar-qualitative", mcmc=False).best_values()
    for name in ("rho", "sigma"):
        assert a[name] == pytest.approx(b[name], rel=1e-6)


# ---------------------------------------------------------------------- command line
@needs_data
def test_list_names_every_sample_and_credits_the_database(capsys):
    assert main(["curet", "list"]) == 0
    out = capsys.readouterr().out
    assert "plaster_b zoomed" in out and "sandpaper" in out and "sample-61" in out
    assert "Dana, B. van Ginneken, S. K. Nayar, J. J. Koenderink" in out
    rows = [line.split() for line in out.splitlines()]
    numbers = [int(row[0]) for row in rows if len(row) in (7, 8) and row[0].isdigit() and row[-1].isdigit()]
    assert numbers == list(range(1, 62))


@needs_data
def test_export_writes_a_csv_that_gonio_fit_reads(tmp_path, capsys, curet):
    path = tmp_path / "plaster_b.csv"
    assert main(["curet", "export", "plaster_b", "--out", str(path)]) == 0
    data = Dataset.from_csv(path)
    sample = curet.sample(11)
    assert data.n == 205 and data.quantity == "brdf" and data.label == "CUReT 11 plaster_b"
    np.testing.assert_array_equal(data.value, sample.brdf)
    np.testing.assert_allclose(data.theta_i, sample.theta_i, rtol=1e-15)
    assert (data.sigma > 0).all() and "Dana" in data.metadata["source"]
    capsys.readouterr()
    # Lambert cannot explain a rough plaster: the fit is written and the exit status says so
    assert main(["fit", str(path), "--model", "lambert", "--no-mcmc", "--out", str(tmp_path / "fit")]) == 4
    lambert = FitResult.load(tmp_path / "fit")
    # Lambert rho of plaster_b: weighted mean of pi f, 0.51 measured (pi x median 0.69 is
    # pulled down by the dark grazing values, which have the smallest sigma).
    assert lambert.best_values()["rho"] == pytest.approx(0.51, abs=0.02)


@needs_data
def test_fit_command_least_squares_writes_results_and_a_comparison(tmp_path, capsys):
    out = tmp_path / "plaster_a"
    code = main(["curet", "fit", "10", "--model", "lambert", "--model", "oren-nayar:ir_weight=1",
                 "--no-mcmc", "--no-report", "--quiet", "--out", str(out)])
    # Oren-Nayar follows plaster_a within the estimated noise plus a small jitter, but an
    # order-4 reciprocal series follows it far better (lack-of-fit F = 32 on 14, 189 dof):
    # structure the model cannot follow, so the chosen model is inadequate
    assert code == EXIT_INADEQUATE
    printed = capsys.readouterr().out
    assert "chosen: oren-nayar (ir_weight=1)" in printed
    comparison = json.loads((out / "comparison.json").read_text())
    assert comparison["chosen"] == "oren-nayar (ir_weight=1)"
    assert [row["label"] for row in comparison["rows"]] == ["oren-nayar (ir_weight=1)", "lambert"]
    for slug in ("lambert", "oren-nayar.ir_weight-1"):
        assert (out / slug / "result.json").is_file()
    assert Dataset.from_csv(out / "data.csv").n == 205
    assert "Reflectance and texture of real-world surfaces" in (out / "comparison.txt").read_text()
    # the chosen model's dependence on the shape of the estimated noise, as a systematic component
    assert "Noise-model dependence of oren-nayar" in (out / "comparison.txt").read_text()
    spread = comparison["noise_models"]
    assert spread["shapes"] == ["relative", "shot", "absolute"] and spread["half_range"]["sigma"] > 0


@needs_data
def test_fit_command_with_a_short_mcmc_run_writes_the_report(tmp_path, capsys):
    out = tmp_path / "sandpaper"
    code = main(["curet", "fit", "sandpaper", "--model", "lambert", "--walkers", "8", "--max-steps", "2000",
                 "--tau-multiple", "10", "--rhat-limit", "1.05", "--quiet", "--report", "--out", str(out)])
    assert code == 4  # converged by the loose criteria asked for; Lambert cannot explain sandpaper
    result = FitResult.load(out / "lambert")
    assert result.jitter and result.mcmc is not None and set(result.free) == {"rho", "jitter"}
    assert (out / "lambert" / "report.html").stat().st_size > 50_000  # figures embedded
    # Sandpaper's forward sheen makes Lambert misfit: the jitter is clearly non-zero
    # (maximum-likelihood value 0.048 sr^-1 measured).
    assert result.posterior["p2_5"]["jitter"] > 0.01


def test_default_candidates_are_the_papers_models():
    assert DEFAULT_CANDIDATES == ("lambert", "oren-nayar-qualitative", "oren-nayar:ir_weight=1", "oren-nayar")
    assert candidate_slug("oren-nayar", {"ir_weight": 1.0}) == "oren-nayar.ir_weight-1"


@pytest.mark.parametrize(
    "argv, message",
    [
        (["curet", "export", "felt", "--out", "x.csv"], "no CUReT sample is named 'felt'"),
        (["curet", "export", "99", "--out", "x.csv"], "CUReT sample number 99 is not in the data"),
        (["curet", "export", "6", "--noise", "relative:2", "--out", "x.csv"], "must be a number in (0, 1]"),
        (["curet", "export", "6", "--noise", "poisson", "--out", "x.csv"], "expected 'kvd'"),
        (["curet", "fit", "6", "--model", "oren-nayar:sigma=120", "--out", "x"], "sigma"),
        (["curet", "fit", "6", "--model", "no-such-model", "--out", "x"], "no-such-model"),
    ],
)
@needs_data
def test_bad_input_is_reported_without_traceback(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not any(tmp_path.iterdir())  # nothing written on bad input


@needs_data
def test_fit_command_refuses_a_used_folder_and_overwrite_keeps_other_files(tmp_path, capsys):
    out = tmp_path / "plaster"
    argv = ["curet", "fit", "10", "--model", "lambert", "--no-mcmc", "--no-report", "--quiet", "--out", str(out)]
    assert main(argv) == 4  # written, and Lambert is inadequate for a rough plaster (its documented exit status)
    assert main(argv) == 2
    assert "already holds files" in capsys.readouterr().err
    (out / "notes.txt").write_text("keep me")
    (out / "lambert" / "chain.npz").write_bytes(b"stale chain of an earlier MCMC run")
    assert main(argv + ["--overwrite"]) == 4
    assert (out / "notes.txt").read_text() == "keep me"
    assert not (out / "lambert" / "chain.npz").exists()  # not part of the new (least-squares) result
    assert FitResult.load(out / "lambert").mcmc is None
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "data.csv").write_text("my own data")
    assert main(argv[:-1] + [str(foreign), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "no results of 'gonio curet fit'" in err and "Traceback" not in err
    assert (foreign / "data.csv").read_text() == "my own data"
