"""An approximate model checked against its exact reference at the fit's own data
(gonio/fitting/validity.py; docs/validity.md, "The fitter knows the map")."""
from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import gonio
from gonio.fitting import Dataset, FitResult, fit
from gonio.fitting import validity as validity_module
from gonio.fitting.validity import BIAS_LIMIT, POINT_LIMIT

VIEWS = np.arange(-80.0, 81.0, 5.0)


def exact_plane_data(relative_noise: float, sigma_deg: float = 20.0, seed: int | None = 1,
                     theta_i: float = 45.0) -> Dataset:
    """The exact V-cavity model in the plane of incidence, with Gaussian relative noise (none
    for ``seed=None``)."""
    theta_r, phi_r = np.abs(VIEWS), np.where(VIEWS < 0, 180.0, 0.0)
    truth = gonio.brdf("oren-nayar-exact", theta_i, 0.0, theta_r, phi_r, rho=0.9, sigma=sigma_deg)
    value = truth if seed is None else truth * (1 + relative_noise * np.random.default_rng(seed).standard_normal(truth.size))
    return Dataset(theta_i, 0.0, theta_r, phi_r, value, relative_noise * truth)


def test_a_model_without_an_exact_reference_is_not_checked():
    result = fit(exact_plane_data(0.003), "oren-nayar-exact", mcmc=False)
    assert result.validity is None
    assert not any("departs from" in flag for flag in result.flags)


def test_the_linearised_shift_predicts_the_approximations_own_bias():
    """The functional model fitted to the exact one at a lab's noise (0.3 %): sigma comes out
    about 3.5 deg low; the check predicts the shift from the exact model's fit within 15 %
    and flags it, naming sigma and what to fit instead."""
    data = exact_plane_data(0.003)
    approximate = fit(data, "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=False)
    exact = fit(data, "oren-nayar-exact", mcmc=False)
    moved = approximate.best_values()["sigma"] - exact.best_values()["sigma"]
    check = approximate.validity
    assert check.reference == "oren-nayar-exact"
    assert moved < -2.0
    assert check.bias["sigma"] == pytest.approx(moved, rel=0.15)
    assert check.bias_sd["sigma"] < -BIAS_LIMIT and check.exceeded
    flag = next(flag for flag in approximate.flags if "departs from oren-nayar-exact" in flag)
    assert "moves" in flag and "sigma" in flag and "fit oren-nayar-exact" in flag


@pytest.mark.parametrize("margin, flagged", [(0.95, False), (1.05, True)])
def test_the_flag_starts_at_the_limit(margin, flagged):
    """Noise-free data: the optimum does not depend on a common factor of the
    uncertainties, while the shift in standard errors and the error in uncertainties scale
    as its inverse. Just inside the limits the fit is silent, just outside it is flagged."""
    reference = fit(exact_plane_data(0.01, seed=None), "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=False).validity
    excess = max(max(abs(b) for b in reference.bias_sd.values()) / BIAS_LIMIT,
                 reference.worst_point() / POINT_LIMIT)
    noise = 0.01 * excess / margin  # the worst of the two criteria at ``margin`` of its limit
    result = fit(exact_plane_data(noise, seed=None), "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=False)
    assert result.validity.exceeded is flagged
    assert any("departs from" in flag for flag in result.flags) is flagged


def test_wolffs_polynomial_fresnel_factor_is_checked_against_the_exact_one():
    theta_r = np.arange(0.0, 86.0, 5.0)
    truth = gonio.brdf("wolff", 30.0, 0.0, theta_r, 0.0, rho=0.8, n=1.5)
    data = Dataset(30.0, 0.0, theta_r, 0.0, truth, 1e-3 * truth)
    polynomial = fit(data, "wolff", options={"fresnel": "polynomial"}, fixed={"omega": 1.0}, mcmc=False)
    assert polynomial.validity.reference == "wolff"
    assert np.max(np.abs(polynomial.validity.relative_error)) > 0
    assert fit(data, "wolff", fixed={"omega": 1.0}, mcmc=False).validity is None  # the exact Fresnel factor: nothing to check


def test_the_check_is_saved_with_the_result(tmp_path):
    result = fit(exact_plane_data(0.003), "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=False)
    result.save(tmp_path / "fit")
    saved = json.loads((tmp_path / "fit" / "result.json").read_text())
    assert saved["validity"]["reference"] == "oren-nayar-exact"
    assert saved["validity"]["bias_limit"] == BIAS_LIMIT
    loaded = FitResult.load(tmp_path / "fit")
    assert loaded.validity == result.validity


def test_a_large_dataset_is_checked_on_a_weighted_sample(monkeypatch):
    """Above MAX_CHECKED independent values the exact model is evaluated on the most grazing
    ones and an even sample of the rest, weighted: the shift stays that of all values."""
    rng = np.random.default_rng(3)
    n = 2000
    theta_i, theta_r = rng.uniform(0, 80, n), rng.uniform(0, 80, n)
    phi_r = rng.uniform(-180, 180, n)
    truth = gonio.brdf("oren-nayar-exact", theta_i, 0.0, theta_r, phi_r, rho=0.9, sigma=25.0)
    data = Dataset(theta_i, 0.0, theta_r, phi_r, truth, 0.003 * truth)
    whole = fit(data, "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=False).validity
    monkeypatch.setattr(validity_module, "MAX_CHECKED", 1000)
    sampled = fit(data, "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=False).validity
    assert len(whole.checked) == n and len(sampled.checked) == 1000
    for name in ("rho", "sigma"):
        assert sampled.bias[name] == pytest.approx(whole.bias[name], rel=0.25)


def test_gonio_fit_prints_the_warning_and_writes_the_check(tmp_path, capsys):
    from gonio.cli import main

    data = exact_plane_data(0.003)
    data.to_csv(tmp_path / "plaster.csv")
    code = main(["fit", str(tmp_path / "plaster.csv"), "--model", "oren-nayar", "--fix", "ir_weight=1",
                 "--no-mcmc", "--out", str(tmp_path / "fit")])
    out = capsys.readouterr()
    assert code == 4  # the misfit makes the verdict "inadequate" (exit 4); the check adds why
    assert "departs from oren-nayar-exact" in out.out + out.err
    saved = json.loads((tmp_path / "fit" / "result.json").read_text())
    assert saved["validity"]["bias_sd"]["sigma"] < -BIAS_LIMIT


def test_rho_and_a_free_scale_are_flagged_with_what_to_measure():
    """Relative radiance without a standard: prediction = scale x f_r cos(theta_i), so rho
    and scale trade against each other (rho enters otherwise only through the
    interreflection's rho^2); the correlation flag says what breaks the degeneracy."""
    theta_r, phi_r = np.abs(VIEWS), np.where(VIEWS < 0, 180.0, 0.0)
    brdf = gonio.brdf("oren-nayar-tabulated", 45.0, 0.0, theta_r, phi_r, rho=0.8, sigma=25.0)
    radiance = 2.0 * brdf * np.cos(np.radians(45.0))
    noisy = radiance * (1 + 0.003 * np.random.default_rng(4).standard_normal(radiance.size))
    data = Dataset(45.0, 0.0, theta_r, phi_r, noisy, 0.003 * radiance, quantity="radiance")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a short chain: the correlation shows long before convergence
        result = fit(data, "oren-nayar-tabulated", seed=2, n_walkers=16, max_steps=1500, polish_table=False)
    flag = next(flag for flag in result.flags if "rho and scale are strongly correlated" in flag)
    assert "reference standard" in flag
    assert not any("reference standard" in other for other in result.flags if "rho and sigma" in other)


@pytest.mark.parametrize("standard, flagged", [(True, False), (False, True)])
def test_a_free_scale_without_a_standard_is_flagged_before_sampling(standard, flagged):
    """The scale axis of benchmarks/validity_fits.py: with a reference standard (a normal
    prior on scale) the fit is silent; without one it is flagged whatever the chain does."""
    from gonio.fitting.priors import Normal

    theta_r, phi_r = np.abs(VIEWS), np.where(VIEWS < 0, 180.0, 0.0)
    brdf = gonio.brdf("oren-nayar-tabulated", 45.0, 0.0, theta_r, phi_r, rho=0.8, sigma=25.0)
    radiance = brdf * np.cos(np.radians(45.0))
    data = Dataset(45.0, 0.0, theta_r, phi_r, radiance, 0.003 * radiance, quantity="radiance")
    priors = {"scale": Normal(1.0, 0.01)} if standard else None
    result = fit(data, "oren-nayar-tabulated", priors=priors, mcmc=False, polish_table=False)
    assert any("without a reference standard" in flag for flag in result.flags) is flagged
