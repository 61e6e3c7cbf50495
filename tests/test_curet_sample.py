"""CUReT materials as emulated samples: the KvD series (Koenderink & van Doorn 1998, eq 26-31)
of cross-validated order fitted to the 205 values of a CUReT sample (Dana et al. 1999),
floored at 0, and the ``curet:`` sample spec."""
from __future__ import annotations

import numpy as np
import pytest

import gonio
from gonio.cli import CLIError, main
from gonio.cli.samples import parse_sample_spec
from gonio.curet import CuretSample, default_directory, read_curet
from gonio.curet_sample import ORDERS, REGULARIZATION, curet_brdf, interpolate, order_table, resolve_sample
from gonio.models import kvd

CURET_DIR = default_directory()
needs_data = pytest.mark.skipif(not (CURET_DIR / "abrdf.dat").exists(), reason=f"CUReT files not found in {CURET_DIR}")


def _geometries(n: int, seed: int, max_theta: float = 84.0) -> tuple[np.ndarray, ...]:
    """Directions uniform in projected solid angle up to ``max_theta`` (CUReT's range)."""
    rng = np.random.default_rng(seed)
    lowest = np.cos(np.radians(max_theta))
    ti, tr = (np.degrees(np.arccos(np.sqrt(rng.uniform(lowest**2, 1.0, n)))) for _ in range(2))
    pi_, pr = rng.uniform(-180.0, 180.0, n), rng.uniform(-180.0, 180.0, n)
    return ti, pi_, tr, pr


def _synthetic(values, geometry) -> CuretSample:
    return CuretSample(0, "synthetic", *geometry, np.asarray(values, float))


@pytest.fixture(scope="module")
def curet():
    return read_curet(CURET_DIR)


# ---------------------------------------------------------------------- cross-validation
@pytest.mark.parametrize("regularization", [0.0, 1e-4])
def test_leave_one_out_shortcut_equals_a_refit_without_the_sample(regularization):
    """e_j = r_j / (1 - h_jj) (Hastie et al. 2009, eq 7.64) against fit_series on N - 1
    samples with the penalty rescaled to keep N lam P: equal to 1e-12 (rounding of two
    different SVDs)."""
    geometry = _geometries(80, seed=3)
    rng = np.random.default_rng(4)
    f = gonio.brdf("oren-nayar", *geometry, rho=0.8, sigma=25.0) * (1 + 0.03 * rng.standard_normal(80))
    e = kvd.leave_one_out_residuals(*geometry, f, order=4, regularization=regularization)
    n = f.size
    for j in (0, 17, 79):
        keep = np.arange(n) != j
        refit = kvd.fit_series(*(g[keep] for g in geometry), f[keep], order=4,
                               regularization=regularization * n / (n - 1))
        predicted = refit.coefficients(*(g[j] for g in geometry))
        assert e[j] == pytest.approx(f[j] - predicted, abs=1e-12)


def test_order_selection_is_deterministic_and_follows_its_rule():
    geometry = _geometries(205, seed=5)
    rng = np.random.default_rng(6)
    f = gonio.brdf("oren-nayar", *geometry, rho=0.7, sigma=30.0) * (1 + 0.04 * rng.standard_normal(205))
    first = kvd.select_order(*geometry, f, regularization=REGULARIZATION)
    second = kvd.select_order(*geometry, f, regularization=REGULARIZATION)
    assert first.chosen == second.chosen and np.array_equal(first.cv_rms, second.cv_rms)
    minimum = kvd.select_order(*geometry, f, regularization=REGULARIZATION, rule="minimum")
    assert minimum.chosen == minimum.best == int(np.argmin(minimum.cv_rms))
    # one-standard-error rule: the lowest order within one standard error of the minimum
    mse, best = first.cv_rms**2, int(np.argmin(first.cv_rms))
    se_of_mse = 2 * first.cv_rms[best] * first.cv_rms_se[best]
    within = np.flatnonzero(mse <= mse[best] + se_of_mse * (1 + 1e-9))
    assert first.chosen == first.orders[within[0]] <= first.best
    assert first.chosen > 0  # Oren-Nayar at sigma = 30 deg is not Lambertian (redchi >> 1 at order 0)
    with pytest.raises(ValueError, match="rule = 'median' is not one of"):
        kvd.select_order(*geometry, f, rule="median")


def test_interpolant_of_noisy_oren_nayar_values_follows_the_noise_and_beats_it_on_the_truth():
    """205 Oren-Nayar values (rho 0.8, sigma 20 deg) with 4 % Gaussian noise: the residuals
    at the chosen order have chi^2 / (n - p) within [0.7, 1.4] (the 2-sigma range of a
    chi^2 with ~190 dof is 0.8-1.2, widened for the series' own interpolation error), and
    the interpolant is closer to the truth than the data are (rms < 0.03 against 0.04)."""
    geometry = _geometries(205, seed=1)
    truth = gonio.brdf("oren-nayar", *geometry, rho=0.8, sigma=20.0)
    noisy = truth * (1 + 0.04 * np.random.default_rng(2).standard_normal(205))
    sample = interpolate(_synthetic(noisy, geometry))
    p = len(sample.coefficients.modes)
    fitted = sample(*geometry)
    chi2 = np.sum(((noisy - fitted) / (0.04 * truth)) ** 2) / (205 - p)
    assert 0.7 < chi2 < 1.4
    assert np.sqrt(np.mean(((fitted - truth) / truth) ** 2)) < 0.03


# ---------------------------------------------------------------------- the sample callable
def test_interpolant_is_reciprocal_to_rounding_and_isotropic():
    geometry = _geometries(205, seed=7)
    values = gonio.brdf("oren-nayar", *geometry, rho=0.6, sigma=35.0)
    sample = interpolate(_synthetic(values, geometry))
    ti, pi_, tr, pr = _geometries(500, seed=8, max_theta=90.0)
    forward, backward = sample(ti, pi_, tr, pr), sample(tr, pr, ti, pi_)
    np.testing.assert_allclose(forward, backward, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(sample(ti, pi_ + 40.0, tr, pr + 40.0), forward, rtol=1e-12, atol=1e-15)


def test_negative_series_is_floored_at_zero_and_nan_and_horizon_rules_hold():
    """A dark sample (mean 0.002 sr^-1, noise 0.003 sr^-1, negative values kept as CUReT
    does): its series dips below 0; the sample returns exactly 0 there and the series
    elsewhere."""
    geometry = _geometries(205, seed=9)
    values = 0.002 + 0.003 * np.random.default_rng(10).standard_normal(205)
    sample = interpolate(_synthetic(values, geometry), rule="minimum")
    ti, pi_, tr, pr = _geometries(4000, seed=11, max_theta=90.0)
    series, floored = sample.series(ti, pi_, tr, pr), sample(ti, pi_, tr, pr)
    negative = series < 0
    assert negative.any() and (~negative).any()
    assert np.all(floored[negative] == 0.0)
    assert np.array_equal(floored[~negative], series[~negative])
    assert np.isnan(sample(np.nan, 0.0, 30.0, 0.0)) and np.isnan(sample(30.0, 0.0, 30.0, np.nan))
    assert sample(95.0, 0.0, 30.0, 0.0) == 0.0 and sample(30.0, 0.0, 90.5, 0.0) == 0.0


# ---------------------------------------------------------------------- real CUReT samples
#: Orders chosen by leave-one-out with the one-standard-error rule (docs/curet-samples.md).
DOCUMENTED_ORDERS = {6: 7, 10: 4, 11: 5, 30: 7}


@needs_data
@pytest.mark.parametrize("number", sorted(DOCUMENTED_ORDERS))
def test_chosen_order_is_the_documented_one_and_reproduces_the_values_within_their_noise(curet, number):
    """The interpolant's relative rms residual at the 205 geometries is at most 1.1 x the
    relative noise s of gonio's CUReT noise model (the scatter about a smooth series;
    a pure-noise residual of a p-amplitude fit is s sqrt((n - p)/n) < s, 10 % allows for
    the differing orders of the two series; measured 0.76-1.02)."""
    from gonio.cli.curet import estimate_relative_noise

    sample = curet.sample(number)
    brdf = interpolate(sample)
    assert brdf.order == DOCUMENTED_ORDERS[number]
    again = interpolate(curet.sample(number))
    assert np.array_equal(again.coefficients.values, brdf.coefficients.values)
    geometry = (sample.theta_i, sample.phi_i, sample.theta_r, sample.phi_r)
    noise = estimate_relative_noise(*geometry, sample.brdf)
    residual = sample.brdf - brdf(*geometry)
    relative_rms = np.sqrt(np.mean(residual**2) / np.mean(sample.brdf**2))
    assert relative_rms <= 1.1 * noise.relative
    assert brdf.selection.orders == ORDERS and brdf.selection.regularization == REGULARIZATION


@needs_data
def test_real_sample_is_reciprocal_and_non_negative_over_the_hemisphere(curet):
    """Sample 61 (moss, the darkest, with 28 negative values) and plaster_a."""
    ti, pi_, tr, pr = _geometries(3000, seed=12, max_theta=90.0)
    for number in (10, 61):
        brdf = curet_brdf(number, CURET_DIR)
        values = brdf(ti, pi_, tr, pr)
        assert np.all(values >= 0.0)
        np.testing.assert_allclose(values, brdf(tr, pr, ti, pi_), rtol=1e-12, atol=1e-15)
    assert np.any(curet_brdf(61, CURET_DIR).series(ti, pi_, tr, pr) < 0)  # the floor is needed there


@needs_data
def test_samples_resolve_by_number_and_by_name(curet):
    assert resolve_sample("10", curet) == resolve_sample("plaster_a", curet) == 10
    assert resolve_sample("PLASTER_B-zoomed", curet) == resolve_sample("plaster_b zoomed", curet) == 30
    assert resolve_sample("sample-12", curet) == 12
    with pytest.raises(ValueError, match="CUReT sample number 9999 is not in the data; expected a sample number 1-61"):
        resolve_sample(9999, curet)
    with pytest.raises(ValueError, match="'abc' is not a CUReT sample; expected a sample number 1-61 or a name"):
        resolve_sample("abc", curet)


@needs_data
def test_order_table_lists_samples_with_their_chosen_order(curet):
    table = order_table(curet, numbers=(9, 10)).splitlines()
    assert len(table) == 2 + 2 and table[0].startswith("| sample | name | order | amplitudes | N=0 |")
    assert table[3].startswith("| 10 | plaster_a | 4 | 14 | ")
    assert table[3].count("**") == 2  # the chosen order's cell


# ---------------------------------------------------------------------- the sample spec
@needs_data
def test_curet_spec_gives_the_interpolant_and_plain_metadata():
    sample = parse_sample_spec("curet:plaster_a")
    assert sample.model == "curet" and sample.parameters["curet_sample"] == 10
    assert sample.parameters["kvd_order"] == 4
    value = sample.brdf(30.0, 0.0, 45.0, 180.0)
    assert value == pytest.approx(float(curet_brdf(10, CURET_DIR).series(30.0, 0.0, 45.0, 180.0)), rel=1e-12)
    assert parse_sample_spec("lambert:rho=0.5").parameters == {"rho": 0.5}


@needs_data
@pytest.mark.parametrize("spec, message", [
    ("curet:9999", "sample spec 'curet:9999': CUReT sample number 9999 is not in the data; expected a sample number 1-61"),
    ("curet:abc", "sample spec 'curet:abc': 'abc' is not a CUReT sample; expected a sample number 1-61 or a name"),
    ("curet:", "expected curet:NUMBER or curet:NAME"),
])
def test_bad_curet_specs_name_what_was_wrong_and_what_was_expected(spec, message, tmp_path, capsys):
    with pytest.raises(CLIError, match=message.replace("(", r"\(")):
        parse_sample_spec(spec)
    protocol = tmp_path / "p.toml"
    protocol.write_text('[protocol]\nname = "p"\n[sample]\nlabel = "s"\n[[block]]\ntheta_i = 30\nview = [0]\n')
    assert main(["run", str(protocol), "--out", str(tmp_path / "rec"), "--sample", spec, "--quiet"]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "rec").exists() or not any((tmp_path / "rec").iterdir())


def test_curet_spec_without_the_data_names_the_folder_and_the_variable(tmp_path, monkeypatch):
    monkeypatch.setenv("GONIO_CURET_DIR", str(tmp_path))
    with pytest.raises(CLIError, match=f"the CUReT folder {tmp_path} lacks abrdf.dat and table.txt; set \\$GONIO_CURET_DIR"):
        parse_sample_spec("curet:10")


@needs_data
def test_emulator_command_builds_a_rig_with_the_curet_sample():
    from gonio.cli import build_parser
    from gonio.cli.emulator import build_rig

    args = build_parser().parse_args(["emulator", "--sample", "curet:10", "--name", "curet-build"])
    rig = build_rig(args)
    try:
        brdf = rig.scene.brdf
        expected = curet_brdf(10, CURET_DIR)
        assert brdf(30.0, 0.0, 45.0, 180.0) == pytest.approx(float(expected(30.0, 0.0, 45.0, 180.0)), rel=1e-12)
        assert brdf(30.0, 0.0, 45.0, 180.0) != pytest.approx(float(curet_brdf(11, CURET_DIR)(30.0, 0.0, 45.0, 180.0)))
    finally:
        rig.close()
