"""Fit results: JSON round trip, summaries, best values; model selection."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gonio.fitting import FitResult, compare_models, fit, information_criteria

from .synthetic import synthetic_dataset

QUICK = dict(n_walkers=16, tau_multiple=20.0, max_steps=6000, rhat_limit=1.05)  # quick: not the 50 tau, 1.01 defaults


@pytest.fixture(scope="module")
def minnaert_result():
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.01, seed=3, relative=True)
    return fit(data, "minnaert", **QUICK)


def test_json_round_trip_preserves_every_number(minnaert_result, tmp_path):
    path = minnaert_result.save(tmp_path / "fit")
    assert {p.name for p in (tmp_path / "fit").iterdir()} == {"result.json", "chain.npz", "summary.txt", "posterior.nc"}
    json.loads(path.read_text())  # strict JSON (no NaN literals)
    back = FitResult.load(tmp_path / "fit")
    assert back.summary() == minnaert_result.summary()
    assert back.posterior == minnaert_result.posterior
    assert back.least_squares.values == minnaert_result.least_squares.values
    np.testing.assert_array_equal(back.mcmc.chain, minnaert_result.mcmc.chain)
    np.testing.assert_array_equal(back.dataset.value, minnaert_result.dataset.value)
    assert back.to_dict() == minnaert_result.to_dict()


def test_json_round_trip_with_undetermined_parameters(tmp_path):
    # NaN standard errors (degenerate rho and scale) are written as null and read back as NaN.
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7, scale=50.0), 0.01, quantity="radiance", relative=True)
    result = fit(data, "minnaert", mcmc=False)
    back = FitResult.load(result.save(tmp_path))
    assert math.isnan(back.least_squares.stderr["rho"]) and back.mcmc is None
    assert back.summary() == result.summary()
    assert "+/- (undetermined)" in back.summary()


def test_load_rejects_other_json(tmp_path):
    (tmp_path / "result.json").write_text('{"format": "something-else"}')
    with pytest.raises(ValueError, match="field 'format'"):
        FitResult.load(tmp_path)


def test_summary_reads_like_a_fit_report(minnaert_result):
    text = minnaert_result.summary()
    for section in ("[[Model]]", "[[Fit Statistics]]", "[[Variables]]", "[[Posterior]]", "[[Correlations]]", "[[Warnings]]"):
        assert section in text
    assert "reduced chi-square" in text and "C(rho, k)" in text


def test_best_values_and_predictive_band(minnaert_result):
    best = minnaert_result.best_values()
    assert best["k"] == minnaert_result.posterior["median"]["k"]
    band = minnaert_result.posterior_predictive(45.0, 0.0, np.array([0.0, 30.0]), 180.0, n_draws=100)
    assert band.shape == (5, 2)
    assert np.all(np.diff(band, axis=0) >= 0)  # percentiles are ordered


def test_information_criteria_formulas():
    # Akaike 1974 / Schwarz 1978 definitions with -2 ln L.
    ic = information_criteria(-12.5, 3, 40)
    assert ic["aic"] == pytest.approx(25.0 + 6.0)
    assert ic["bic"] == pytest.approx(25.0 + 3 * math.log(40))
    assert ic["aicc"] == pytest.approx(31.0 + 2 * 3 * 4 / 36)


def test_model_selection_uses_no_more_model_than_the_data_need():
    lambertian = synthetic_dataset("lambert", dict(rho=0.5), 0.003, seed=8)
    comparison = compare_models(lambertian, ["minnaert", "lambert", "lambert+phong"])
    assert comparison.chosen == "lambert"
    limb = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.003, seed=8)
    comparison = compare_models(limb, ["lambert", "minnaert"])
    assert comparison.chosen == "minnaert"
    assert "chosen: minnaert" in comparison.summary()


@pytest.mark.parametrize("quantity", ["brdf", "radiance", "normalised_radiance"])
def test_predictive_band_equals_the_draws_predicted_one_by_one(quantity):
    # The band evaluates every draw in a few broadcast model calls through the frozen
    # geometry (apertures included); the reference path predicts each draw on its own.
    import warnings

    from gonio.fitting import ConvergenceWarning, Dataset

    truth = dict(rho=0.6, k=0.7, scale=40.0) if quantity == "radiance" else dict(rho=0.6, k=0.7)
    data = synthetic_dataset("minnaert", truth, 0.01, seed=4, quantity=quantity, relative=True)
    data = Dataset(*(getattr(data, n) for n in ("theta_i", "phi_i", "theta_r", "phi_r", "value", "sigma")),
                   quantity=quantity, metadata={"aperture_sr": [0.003, 0.0009]})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        result = fit(data, "minnaert", n_walkers=8, max_steps=200, tau_multiple=5.0, rhat_limit=1.5)
    theta_r = np.array([[0.0, 20.0, 50.0], [70.0, 85.0, 89.0]])  # a 2-D geometry keeps its shape
    band = result.posterior_predictive(45.0, 0.0, theta_r, 180.0, n_draws=60, seed=7)
    samples = result.samples()
    rows = np.random.default_rng(7).choice(samples.shape[0], size=60, replace=False)
    one_by_one = [result.predict(45.0, 0.0, theta_r, 180.0, dict(result.least_squares.values, **dict(zip(result.free, row))))
                  for row in samples[rows]]
    reference = np.nanpercentile(np.array(one_by_one), (2.5, 16, 50, 84, 97.5), axis=0)
    assert band.shape == (5, 2, 3)
    # the same formula evaluated once for all draws: rounding only
    np.testing.assert_allclose(band, reference, rtol=1e-12, atol=0)


def test_a_folder_mixing_two_saves_is_refused(tmp_path):
    """An interrupted 'gonio fit --overwrite' used to leave the new result.json beside the
    old chain, and 'gonio report' rendered the mix: every file carries the save's id,
    result.json comes last, and load refuses files of another save, naming them."""
    import shutil

    import numpy as np

    from gonio.fitting import Dataset, FitResult, fit

    tr = np.arange(-70.0, 71.0, 10.0)
    data = Dataset(30, 0, np.abs(tr), np.where(tr < 0, 180.0, 0.0), 0.3 + 0.001 * np.sin(tr), 0.002)
    first = fit(data, "lambert", n_walkers=8, max_steps=2000, rhat_limit=1.1, seed=1)
    second = fit(data, "lambert", n_walkers=8, max_steps=2000, rhat_limit=1.1, seed=2)
    assert first.result_id and first.result_id != second.result_id
    first.save(tmp_path / "a")
    second.save(tmp_path / "b")
    assert FitResult.load(tmp_path / "a").result_id == first.result_id
    assert first.result_id in (tmp_path / "a" / "summary.txt").read_text()
    shutil.copy(tmp_path / "b" / "chain.npz", tmp_path / "a" / "chain.npz")  # the save cut off after its chain
    with pytest.raises(ValueError, match="belongs to another save"):
        FitResult.load(tmp_path / "a")


def test_overwrite_replaces_only_a_result_gonio_can_read_whole(tmp_path):
    """'--overwrite' trusted a format tag: a result.json that merely claimed to be a fit
    result let gonio replace and delete files beside it. A folder is a fit result only if
    FitResult.load reads it whole."""
    from gonio.cli import main

    (tmp_path / "data.csv").write_text("theta_i,phi_i,theta_r,phi_r,value,sigma\n"
                                       + "".join(f"30,0,{t},0,0.3,0.01\n" for t in range(0, 80, 10)))
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "result.json").write_text('{"format": "gonio-fit-result"}')
    (mine / "chain.npz").write_bytes(b"a user's file")
    code = main(["fit", str(tmp_path / "data.csv"), "--model", "lambert", "--no-mcmc", "--quiet",
                 "--out", str(mine), "--overwrite"])
    assert code == 2
    assert (mine / "chain.npz").read_bytes() == b"a user's file"
    assert main(["fit", str(tmp_path / "data.csv"), "--model", "lambert", "--no-mcmc", "--quiet",
                 "--out", str(tmp_path / "real")]) == 0
    assert main(["fit", str(tmp_path / "data.csv"), "--model", "lambert", "--no-mcmc", "--quiet",
                 "--out", str(tmp_path / "real"), "--overwrite"]) == 0


def test_posterior_file_thins_its_draws_to_bound_the_pointwise_groups(minnaert_result, tmp_path, monkeypatch):
    """posterior.nc grows with the data, not with draws x data: with a budget of 40 draws
    x values per pointwise group the log-likelihood and the replicated data keep at most
    that many draws (at least one step of every walker), and ArviZ reads the file."""
    import gonio.fitting.results as results_module

    n = minnaert_result.dataset.n
    monkeypatch.setattr(results_module, "POINTWISE_ELEMENTS", 40 * n)
    arrays = minnaert_result._inference_arrays()
    walkers = minnaert_result.mcmc.n_walkers
    assert arrays["log_likelihood"].shape[0] * walkers <= max(40, walkers)
    assert arrays["predictive"].shape[0] * walkers <= max(40, walkers)
    assert arrays["chain"].shape[0] == arrays["log_likelihood"].shape[0]
