"""A tabulated model's fit is polished with the exact model where the table's error matters
(gonio.fitting.polish): on data as precise as the idealised rig the table alone misses the
truth by many standard deviations, the polished fit covers it."""
from __future__ import annotations

import numpy as np
import pytest

from gonio.fitting import Dataset, fit
from gonio.fitting import polish as polish_module
from gonio.fitting.problem import FitProblem, predict_quantity

from .synthetic import in_plane_geometry

GEOMETRY = in_plane_geometry(incidences=(30.0, 45.0, 60.0, 75.0), views=np.arange(-80.0, 81.0, 10.0))
TRUTH = {"rho": 0.9, "sigma": 30.0}


def _exact_data(noise: float, seed: int = 0) -> Dataset:
    exact = predict_quantity("oren-nayar-exact", "brdf", *GEOMETRY, TRUTH)
    rng = np.random.default_rng(seed)
    return Dataset(*GEOMETRY, exact * (1 + noise * rng.standard_normal(exact.size)), noise * exact,
                   label="exact V-cavity model, idealised rig's noise")


def _z(result, name: str) -> float:
    return (result.least_squares.values[name] - TRUTH[name]) / result.least_squares.stderr[name]


def test_the_table_alone_misses_what_the_polished_fit_covers(monkeypatch):
    data = _exact_data(6e-5)
    monkeypatch.setattr(polish_module, "POLISH_LIMIT", float("inf"))
    table = fit(data, "oren-nayar-tabulated", mcmc=False, jitter=False)
    assert abs(_z(table, "rho")) > 5  # the table's 1e-4 error is several of the data's sigma
    monkeypatch.undo()
    polished = fit(data, "oren-nayar-tabulated", mcmc=False, jitter=False)
    assert polished.flags[0].startswith("polished with oren-nayar-exact")
    assert abs(_z(polished, "rho")) < 3 and abs(_z(polished, "sigma")) < 3
    assert polished.adequacy.verdict == "adequate"  # judged under the exact model
    assert polished.model == "oren-nayar-tabulated"


def test_a_lab_s_noise_needs_no_polish():
    result = fit(_exact_data(3e-3), "oren-nayar-tabulated", mcmc=False, jitter=False)
    assert not any(flag.startswith("polished") for flag in result.flags)


def test_the_posterior_moves_with_the_optimum():
    result = fit(_exact_data(6e-5, seed=1), "oren-nayar-tabulated", jitter=False, n_walkers=16, max_steps=4000,
                 rhat_limit=1.05)
    assert result.flags[0].startswith("polished with oren-nayar-exact")
    for name, truth in TRUTH.items():
        assert result.posterior["p2_5"][name] < truth < result.posterior["p97_5"][name], name
    assert result.posterior["median"]["rho"] == pytest.approx(result.least_squares.values["rho"], abs=2e-5)


def test_a_comparison_s_fit_is_reused_with_its_table_error(monkeypatch):
    """``fit(least_squares=...)`` takes a comparison's least squares as they are: no second
    least-squares fit, no second evaluation of the exact model for the table's error, and
    the same result as fitting again; a fit of other parameters is refused."""
    from gonio.fitting import compare_models
    from gonio.fitting import workflow

    data = _exact_data(3e-3)
    comparison = compare_models(data, ["lambert", "oren-nayar-tabulated"])
    given = comparison.fits["oren-nayar-tabulated"]
    assert given.table_error == pytest.approx(polish_module.table_error(
        FitProblem("oren-nayar-tabulated", data), FitProblem("oren-nayar-exact", data, {}, {"rtol": 1e-5}),
        given.values))
    again = fit(data, "oren-nayar-tabulated", mcmc=False, jitter=False)
    calls = []
    monkeypatch.setattr(workflow, "fit_least_squares", lambda *a, **k: calls.append("least squares"))
    monkeypatch.setattr(polish_module, "table_error", lambda *a, **k: calls.append("table error"))
    reused = fit(data, "oren-nayar-tabulated", mcmc=False, jitter=False, least_squares=given)
    assert calls == []
    for name in ("rho", "sigma"):
        assert reused.best_values()[name] == pytest.approx(again.best_values()[name], rel=1e-6)
    with pytest.raises(ValueError, match=r"least_squares: its free parameters \['rho'\] are not those"):
        fit(data, "oren-nayar-tabulated", mcmc=False, jitter=False, least_squares=comparison.fits["lambert"])


def test_the_exact_model_measures_the_table_at_its_set_accuracy():
    """The table's error is measured with the exact model at rtol 1e-5
    (polish.EXACT_OPTIONS), within 1 % of what its tightest setting measures."""
    data = _exact_data(1e-4)
    build = lambda name: FitProblem(name, data)  # noqa: E731
    measuring = polish_module.exact_problem(build, "oren-nayar-exact")
    assert measuring.options["rtol"] == 1e-5
    values = fit(data, "oren-nayar-tabulated", mcmc=False, jitter=False).least_squares.values
    tight = FitProblem("oren-nayar-exact", data, {}, {"rtol": 1e-7})
    table = FitProblem("oren-nayar-tabulated", data)
    assert polish_module.table_error(table, measuring, values) == pytest.approx(
        polish_module.table_error(table, tight, values), rel=0.01)
