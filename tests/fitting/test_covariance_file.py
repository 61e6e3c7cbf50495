"""A fit result keeps the data's covariance in covariance.npz, not in result.json
(gonio/fitting/results.py; docs/data-format.md, "A fit result folder")."""
from __future__ import annotations

import json

import numpy as np
import pytest

import gonio
from gonio.fitting import Dataset, FitResult, fit


def correlated(n: int = 40) -> Dataset:
    theta_r = np.linspace(0.0, 78.0, n)
    truth = gonio.brdf("lambert", 30.0, 0.0, theta_r, 0.0, rho=0.5)
    covariance = np.diag((0.003 * truth) ** 2) + np.outer(0.005 * truth, 0.005 * truth)
    return Dataset(30.0, 0.0, theta_r, 0.0, truth, np.sqrt(np.diag(covariance)), covariance=covariance)


def test_the_covariance_is_saved_beside_the_result_and_read_back(tmp_path):
    result = fit(correlated(), "lambert", mcmc=False)
    result.save(tmp_path / "fit")
    saved = json.loads((tmp_path / "fit" / "result.json").read_text())
    assert saved["format_version"] == 2
    assert "covariance" not in saved["dataset"] and saved["dataset"]["covariance_file"] == "covariance.npz"
    assert "covariance.npz" in result.saved_files()
    loaded = FitResult.load(tmp_path / "fit")
    np.testing.assert_array_equal(loaded.dataset.covariance, result.dataset.covariance)


def test_data_without_a_covariance_write_no_covariance_file(tmp_path):
    data = correlated()
    plain = Dataset(data.theta_i, data.phi_i, data.theta_r, data.phi_r, data.value, data.sigma)
    fit(plain, "lambert", mcmc=False).save(tmp_path / "fit")
    assert not (tmp_path / "fit" / "covariance.npz").exists()
    assert FitResult.load(tmp_path / "fit").dataset.covariance is None


def test_a_covariance_file_of_another_save_is_refused(tmp_path):
    fit(correlated(), "lambert", mcmc=False).save(tmp_path / "a")
    fit(correlated(30), "lambert", mcmc=False).save(tmp_path / "b")
    (tmp_path / "b" / "covariance.npz").replace(tmp_path / "a" / "covariance.npz")
    with pytest.raises(ValueError, match="covariance.npz"):
        FitResult.load(tmp_path / "a")


def test_a_result_of_format_1_with_the_covariance_inline_still_loads(tmp_path):
    result = fit(correlated(), "lambert", mcmc=False)
    path = result.save(tmp_path / "fit")
    record = json.loads(path.read_text())
    record["format_version"] = 1
    del record["dataset"]["covariance_file"]
    record["dataset"]["covariance"] = result.dataset.covariance.tolist()
    path.write_text(json.dumps(record))
    (tmp_path / "fit" / "covariance.npz").unlink()
    np.testing.assert_allclose(FitResult.load(tmp_path / "fit").dataset.covariance, result.dataset.covariance)
